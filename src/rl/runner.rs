//! The learn loop (rsl_rl's `OnPolicyRunner.learn`): roll out `num_steps` per
//! env, bootstrap time-outs from their final observations, compute GAE returns,
//! update, log one CSV row, checkpoint.
//!
//! Checkpoints are taken at an episode boundary of every env: right after a
//! checkpoint is written, every env is reset (the cut episodes count as
//! time-outs, bootstrapped like any other). A checkpoint therefore needs only
//! the networks, Adam, the normalizers, and each env's RNG and curriculum level,
//! and a resumed run continues exactly as the uninterrupted one (same seed and
//! thread counts: bit-identical; tested).
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::agent::Agent;
use super::checkpoint::{self, Checkpoint, CheckpointMeta};
use super::ppo::{Losses, Ppo};
use super::storage::{RolloutStorage, Transition};
use super::RlError;
use crate::env::task::VecTask;
use crate::rl::config::ExperimentConfig;
use crate::run::{Progress, RunDir};

pub use super::metrics::{columns, plot_run, COLUMNS};

/// Where a run stands at its end.
#[derive(Debug, Clone, Serialize)]
pub struct TrainSummary {
    pub iterations: usize,
    pub env_steps: u64,
    pub wall_time_s: f64,
    pub mean_return: f64,
    pub mean_episode_length: f64,
    pub checkpoint: PathBuf,
}

/// Seconds spent per phase.
#[derive(Debug, Clone, Copy, Default)]
pub struct PhaseTimes {
    pub physics: f64,
    pub inference: f64,
    pub update: f64,
}

pub use crate::run::latest_checkpoint;

/// Episode statistics: each env's running return and length, and the window
/// of the last 100 finished episodes (what the logs and checkpoints report).
pub struct EpisodeStats {
    ret: Vec<f64>,
    len: Vec<u64>,
    window_ret: VecDeque<f64>,
    window_len: VecDeque<f64>,
}

impl EpisodeStats {
    /// `n` envs, the window empty or (resume) a checkpoint's `episode_window`.
    pub fn new(n: usize, window: Option<&(Vec<f64>, Vec<f64>)>) -> EpisodeStats {
        let (r, l) = window.cloned().unwrap_or_default();
        EpisodeStats {
            ret: vec![0.0; n],
            len: vec![0; n],
            window_ret: r.into(),
            window_len: l.into(),
        }
    }

    /// Every env starts a new episode (the window stays).
    pub fn reset(&mut self) {
        self.ret.iter_mut().for_each(|r| *r = 0.0);
        self.len.iter_mut().for_each(|l| *l = 0);
    }

    /// Env `i` got `reward` this step; `done`: its episode ended with it.
    pub fn add(&mut self, i: usize, reward: f64, done: bool) {
        self.ret[i] += reward;
        self.len[i] += 1;
        if done {
            push_window(&mut self.window_ret, self.ret[i]);
            push_window(&mut self.window_len, self.len[i] as f64);
            self.ret[i] = 0.0;
            self.len[i] = 0;
        }
    }

    /// Mean return and length over the window (NaN while it is empty).
    pub fn means(&self) -> (f64, f64) {
        (Self::mean(&self.window_ret), Self::mean(&self.window_len))
    }

    /// The window, for a checkpoint's record.
    pub fn window(&self) -> (Vec<f64>, Vec<f64>) {
        (
            self.window_ret.iter().copied().collect(),
            self.window_len.iter().copied().collect(),
        )
    }

    fn mean(v: &VecDeque<f64>) -> f64 {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    }
}

/// Everything one training run holds.
pub struct Trainer<'a, T: VecTask> {
    pub cfg: ExperimentConfig,
    pub task: &'a mut T,
    pub agent: Agent,
    pub ppo: Ppo,
    storage: RolloutStorage,
    pub iteration: usize,
    pub env_steps: u64,
    /// Wall time of earlier sessions of this run (resume).
    wall_offset: f64,
    pub times: PhaseTimes,
    stats: EpisodeStats,
    /// What a fresh run took from `train.init_checkpoint`.
    pub transfer: Option<crate::rl::checkpoint::Transfer>,
}

impl<'a, T: VecTask> Trainer<'a, T> {
    /// A fresh run (or one resumed from `resume`), seeded from `cfg.train.seed`.
    pub fn new(
        cfg: &ExperimentConfig,
        task: &'a mut T,
        resume: Option<&Checkpoint>,
    ) -> Result<Trainer<'a, T>, RlError> {
        tch::set_num_threads(cfg.train.torch_threads as i32);
        tch::manual_seed(cfg.train.seed as i64);
        let n = task.n_envs();
        cfg.policy.scan_encoder.check_input(task.dims().scan)?;
        let d = task.dims();
        if cfg.policy.estimator.is_some()
            && (d.obs != crate::env::obs::OBS_DIM || d.critic != crate::env::obs::CRITIC_DIM)
        {
            return Err(RlError::Invalid(format!(
                "policy.estimator regresses the G1 critic's base velocity (a {}-float state, a {}-float critic observation); this task has {} and {}",
                crate::env::obs::OBS_DIM,
                crate::env::obs::CRITIC_DIM,
                d.obs,
                d.critic
            )));
        }
        let mut agent = Agent::new(&cfg.policy, task.dims(), n, cfg.ppo.normalize_obs);
        let init = match (&cfg.train.init_checkpoint, resume) {
            (Some(path), None) => Some(Checkpoint::read(Path::new(path))?),
            _ => None,
        };
        let mut transfer = None;
        if let Some(ck) = &init {
            transfer = Some(ck.transfer_agent(&mut agent)?);
            if let Some(std) = cfg.train.init_std {
                agent.policy.set_std(std);
            }
        }
        let mirror = task.mirror();
        if cfg.ppo.symmetry && mirror.is_none() {
            return Err(RlError::Invalid(
                "ppo.symmetry needs a task with mirror maps (the G1 env)".into(),
            ));
        }
        let mut ppo = Ppo::new(&cfg.ppo, &agent.policy, mirror.as_ref());
        let d = task.dims();
        let (mut iteration, mut env_steps, mut wall_offset) = (0, 0, 0.0);
        if let Some(ck) = resume {
            (iteration, env_steps, wall_offset) =
                ck.resume_into(&mut *task, &mut agent, &mut ppo.opt)?;
            if cfg.ppo.schedule == crate::rl::config::LrSchedule::Fixed {
                // a fixed rate is the config's (a resume may change it)
                ppo.opt.lr = cfg.ppo.learning_rate;
            }
        }
        let stats = EpisodeStats::new(n, resume.map(|ck| &ck.meta.episode_window));
        agent.check_task(&*task).map_err(RlError::Invalid)?;
        agent.reset_history(&*task);
        let storage = RolloutStorage::new(
            cfg.ppo.num_steps,
            n,
            [agent.policy.actor_input_dim(), d.critic, d.scan, d.action],
        );
        Ok(Trainer {
            cfg: cfg.clone(),
            task,
            agent,
            ppo,
            storage,
            iteration,
            env_steps,
            wall_offset,
            times: PhaseTimes::default(),
            stats,
            transfer,
        })
    }

    /// One PPO iteration: rollout, returns, update. Returns the losses and the
    /// iteration's rollout statistics.
    pub fn iterate(&mut self) -> Result<(Losses, RolloutStats), RlError> {
        let c = self.cfg.ppo.clone();
        let seed = self.cfg.train.seed;
        tch::manual_seed(
            (seed as i64)
                .wrapping_mul(1_000_003)
                .wrapping_add(self.iteration as i64),
        );
        let n = self.task.n_envs();
        let mut rs = RolloutStats::default();
        let mut rewards = vec![0.0f32; n];
        let mut dones = vec![0.0f32; n];
        let mut term_sums: Vec<f64> = vec![0.0; self.task.reward_names().len()];
        let mut term_count = 0usize;
        self.storage.clear();
        for _ in 0..c.num_steps {
            let t0 = Instant::now();
            self.agent.prepare(&*self.task);
            let act = self.agent.act(true);
            let t1 = Instant::now();
            let info = self.task.step(&act.actions);
            let t2 = Instant::now();
            rs.blowups += info.blowups;
            rs.step_reward += info.mean_reward;
            let outcomes = self.task.outcomes();
            let any_truncated = outcomes.iter().any(|o| o.truncated);
            let boot = any_truncated.then(|| {
                self.agent
                    .values_of(self.task.final_critic(), self.task.final_scan())
            });
            for (i, o) in outcomes.iter().enumerate() {
                let mut r = o.reward;
                if o.truncated {
                    if let Some(b) = &boot {
                        r += c.gamma as f32 * b[i];
                    }
                }
                rewards[i] = r;
                dones[i] = o.episode_done as u8 as f32;
                self.stats.add(i, o.reward as f64, o.episode_done);
                if o.episode_done {
                    rs.episodes += 1;
                    rs.falls += o.terminated as usize;
                }
            }
            if let Some(terms) = self.task.finished_episode_terms() {
                let k = outcomes.iter().filter(|o| o.episode_done).count();
                for (s, (_, v)) in term_sums.iter_mut().zip(terms) {
                    *s += v * k as f64;
                }
                term_count += k;
            }
            let e = self.task.tracking_errors();
            rs.vel_error[0] += e[0];
            rs.vel_error[1] += e[1];
            self.storage
                .add(&Transition {
                    actor_in: &self.agent.actor_in,
                    critic_in: &self.agent.critic_in,
                    scan: &self.agent.scan_in,
                    actions: &act.actions,
                    log_probs: &act.log_probs,
                    values: &act.values,
                    mean: &act.mean,
                    rewards: &rewards,
                    dones: &dones,
                })
                .map_err(RlError::Invalid)?;
            self.agent.after_step(&*self.task);
            let t3 = Instant::now();
            self.times.inference += (t1 - t0).as_secs_f64() + (t3 - t2).as_secs_f64();
            self.times.physics += (t2 - t1).as_secs_f64();
        }
        rs.extra = self.task.after_rollout().map_err(RlError::Invalid)?;
        let t0 = Instant::now();
        // values of the states after the last step; `prepare` is not called here:
        // it would count these states into the normalizers a second time (the
        // next iteration's first `prepare` counts them)
        let last = self.agent.values_of(self.task.critic(), self.task.scan());
        self.storage
            .compute_returns(&last, c.gamma as f32, c.lam as f32);
        let t1 = Instant::now();
        let losses = self.ppo.update(
            &self.agent,
            &self.storage,
            seed ^ (self.iteration as u64).wrapping_mul(0x9E37_79B9),
        );
        self.times.inference += (t1 - t0).as_secs_f64();
        self.times.update += t1.elapsed().as_secs_f64();
        self.iteration += 1;
        self.env_steps += (c.num_steps * n) as u64;
        let steps = c.num_steps as f64;
        rs.vel_error = [rs.vel_error[0] / steps, rs.vel_error[1] / steps];
        rs.step_reward /= steps;
        rs.terms = term_sums
            .iter()
            .map(|s| {
                if term_count > 0 {
                    s / term_count as f64
                } else {
                    f64::NAN
                }
            })
            .collect();
        (rs.mean_return, rs.mean_length) = self.stats.means();
        rs.level = self.task.mean_level();
        rs.kind_levels = self.task.levels_by_kind().iter().map(|(_, l)| *l).collect();
        rs.penalty_scale = self.task.penalty_scale();
        if let Some(pc) = &self.cfg.env.rewards.penalty_curriculum {
            let max = self.task.max_episode_steps() as f64;
            if rs.mean_length >= pc.length_frac * max {
                let s = (rs.penalty_scale + pc.step).min(1.0);
                self.task.set_penalty_scale(s);
            }
        }
        for (what, v) in [
            ("value loss", losses.value),
            ("surrogate loss", losses.surrogate),
            ("action std", losses.mean_std),
        ] {
            if !v.is_finite() && self.cfg.train.stop_on_nan {
                return Err(RlError::NonFinite(format!(
                    "{what} is {v} at iteration {}",
                    self.iteration
                )));
            }
        }
        Ok((losses, rs))
    }

    /// Write the resume checkpoint, then start every env on a new episode (module doc).
    pub fn checkpoint(&mut self, path: &Path, wall: f64) -> Result<(), RlError> {
        let meta = CheckpointMeta::record(
            &self.cfg,
            &*self.task,
            Some(&self.ppo.opt),
            (self.iteration, self.env_steps, self.wall_offset + wall),
            self.stats.window(),
        )?;
        checkpoint::save(
            path,
            &self.agent,
            Some(&self.ppo.opt),
            self.task.state_tensors(),
            &meta,
        )?;
        self.task.reset_all();
        self.agent.reset_history(&*self.task);
        self.stats.reset();
        Ok(())
    }

    /// Wall time of the whole run so far, given this session's elapsed seconds.
    pub fn wall_time(&self, session: f64) -> f64 {
        self.wall_offset + session
    }
}

fn push_window(w: &mut VecDeque<f64>, v: f64) {
    if w.len() == 100 {
        w.pop_front();
    }
    w.push_back(v);
}

/// Whether a run checkpoints after iteration `it`: every `save_interval`
/// iterations, and at the last (`iterations`).
pub fn checkpoint_due(train: &crate::rl::config::TrainConfig, it: usize) -> bool {
    let si = train.save_interval;
    (si > 0 && it.is_multiple_of(si)) || it == train.iterations
}

/// What follows a checkpoint written after iteration `it`: a kept copy every
/// `keep_interval` iterations, and the training curves drawn by `plot` (a
/// failure to draw is logged, not fatal).
pub fn after_checkpoint(
    run: &mut RunDir,
    train: &crate::rl::config::TrainConfig,
    it: usize,
    plot: impl Fn(&Path) -> Result<PathBuf, crate::plot::PlotError>,
) -> Result<(), RlError> {
    let ki = train.keep_interval;
    if ki > 0 && it.is_multiple_of(ki) {
        crate::run::keep_checkpoint(run.path(), it)?;
    }
    if let Err(e) = plot(run.path()) {
        run.log(&format!("plots not drawn: {e}"))?;
    }
    Ok(())
}

/// What one iteration's rollout saw.
#[derive(Debug, Clone, Default)]
pub struct RolloutStats {
    pub episodes: usize,
    pub falls: usize,
    pub blowups: usize,
    /// Mean over the last 100 episodes.
    pub mean_return: f64,
    pub mean_length: f64,
    pub vel_error: [f64; 2],
    pub step_reward: f64,
    pub level: f64,
    /// Per-term episode means (per second of episode), in `reward_names` order.
    pub terms: Vec<f64>,
    /// Penalty-curriculum scale during this rollout.
    pub penalty_scale: f64,
    /// The task's own metrics ([`VecTask::extra_metric_names`]).
    pub extra: Vec<f64>,
    /// Mean level per terrain kind ([`VecTask::levels_by_kind`]).
    pub kind_levels: Vec<f64>,
}

/// Train to `cfg.train.iterations` in `run`, from scratch or from `resume`;
/// metrics rows, progress, checkpoints every `save_interval`.
pub fn learn<T: VecTask>(
    cfg: &ExperimentConfig,
    task: &mut T,
    run: &mut RunDir,
    resume: Option<&Checkpoint>,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    let mut tr = Trainer::new(cfg, task, resume)?;
    let total = cfg.train.iterations;
    let ckpt = latest_checkpoint(run.path());
    let progress = Progress::new("train", total as u64, quiet);
    let start = Instant::now();
    let first = tr.iteration;
    run.log(&format!(
        "start at iteration {first} of {total}: {} envs x {} steps, {} parameters",
        tr.task.n_envs(),
        cfg.ppo.num_steps,
        tr.agent.policy.num_parameters()
    ))?;
    if let (Some(t), Some(path)) = (&tr.transfer, &cfg.train.init_checkpoint) {
        run.log(&format!("initialized from {path}: {t}"))?;
        if let Some(std) = cfg.train.init_std {
            run.log(&format!("action std set to {std} (train.init_std)"))?;
        }
    }
    let mut last = (f64::NAN, f64::NAN);
    while tr.iteration < total {
        let it_start = Instant::now();
        let before = tr.times;
        let (l, rs) = tr.iterate()?;
        let dt = it_start.elapsed().as_secs_f64();
        let n_steps = (cfg.ppo.num_steps * tr.task.n_envs()) as f64;
        let wall = tr.wall_time(start.elapsed().as_secs_f64());
        let mut row = vec![
            tr.iteration as f64,
            tr.env_steps as f64,
            wall,
            rs.mean_return,
            rs.mean_length,
            rs.episodes as f64,
            if rs.episodes > 0 {
                rs.falls as f64 / rs.episodes as f64
            } else {
                f64::NAN
            },
            rs.vel_error[0],
            rs.vel_error[1],
            l.value,
            l.surrogate,
            l.entropy,
            l.kl,
            l.clip_fraction,
            l.explained_variance,
            l.learning_rate,
            l.mean_std,
            l.grad_norm,
            n_steps / dt,
            tr.times.physics - before.physics,
            tr.times.inference - before.inference,
            tr.times.update - before.update,
            rs.level,
            rs.blowups as f64,
            rs.step_reward,
            rs.penalty_scale,
        ];
        row.extend(&rs.terms);
        row.extend(&rs.extra);
        row.extend(&rs.kind_levels);
        if cfg.policy.estimator.is_some() {
            row.push(l.estimator);
        }
        run.metrics_row(&row)?;
        last = (rs.mean_return, rs.mean_length);
        progress.set(
            (tr.iteration) as u64,
            &format!(
                "return {:.2} len {:.0} {:.0} steps/s [phys {:.2}s inf {:.2}s upd {:.2}s]",
                rs.mean_return,
                rs.mean_length,
                n_steps / dt,
                tr.times.physics - before.physics,
                tr.times.inference - before.inference,
                tr.times.update - before.update
            ),
        );
        if checkpoint_due(&cfg.train, tr.iteration) {
            tr.checkpoint(&ckpt, start.elapsed().as_secs_f64())?;
            after_checkpoint(run, &cfg.train, tr.iteration, plot_run)?;
            run.log(&format!(
                "iteration {} env_steps {} wall {:.0}s return {:.3} length {:.1}: checkpoint {}",
                tr.iteration,
                tr.env_steps,
                wall,
                rs.mean_return,
                rs.mean_length,
                ckpt.display()
            ))?;
        }
    }
    progress.finish();
    let t = tr.times;
    run.log(&format!(
        "done: {} iterations this session, physics {:.1}s inference {:.1}s update {:.1}s",
        tr.iteration - first,
        t.physics,
        t.inference,
        t.update
    ))?;
    Ok(TrainSummary {
        iterations: tr.iteration,
        env_steps: tr.env_steps,
        wall_time_s: tr.wall_time(start.elapsed().as_secs_f64()),
        mean_return: last.0,
        mean_episode_length: last.1,
        checkpoint: ckpt,
    })
}

/// Build the config's task and train it in `run_dir` (fresh, or resumed from the
/// run's latest checkpoint when `resume`). The G1 env or the cart-pole.
pub fn train(
    cfg: &ExperimentConfig,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    use crate::rl::config::TaskKind;
    match cfg.task {
        TaskKind::G1 if cfg.dagger.is_some() => Err(RlError::Invalid(
            "a config with a `dagger:` section trains with `dreampolicy train dagger`".into(),
        )),
        TaskKind::G1 => {
            let mut env = crate::env::VecEnv::new(&cfg.env)?;
            train_task(cfg, &mut env, run_dir, resume, quiet)
        }
        TaskKind::Cartpole => {
            let (n, _) = cfg.env.counts();
            let mut env = crate::env::cartpole::CartPole::new(n, cfg.env.seed)?;
            train_task(cfg, &mut env, run_dir, resume, quiet)
        }
        TaskKind::Unified => Err(RlError::Invalid(
            "task: unified trains with `dreampolicy train unified`".into(),
        )),
        TaskKind::NoGcrl => Err(RlError::Invalid(
            "task: no_gcrl is written by `dreampolicy train no-gcrl`".into(),
        )),
        TaskKind::NoDiffusion => Err(RlError::Invalid(
            "task: no_diffusion trains with `dreampolicy train no-diffusion`".into(),
        )),
    }
}

/// Train `task` in `run_dir` (fresh, or resumed from the run's latest
/// checkpoint when `resume`): the run directory, metrics (`metrics.csv` and the
/// TensorBoard event file), checkpoints and summary every trainer shares.
pub fn train_task<T: VecTask>(
    cfg: &ExperimentConfig,
    task: &mut T,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    let mut cols = columns(task);
    if cfg.policy.estimator.is_some() {
        cols.push("estimator_loss".into());
    }
    let cols: Vec<&str> = cols.iter().map(|s| s.as_str()).collect();
    let (mut run, ck) = if resume {
        let ck = Checkpoint::read(&latest_checkpoint(run_dir))?;
        let run = RunDir::resume(run_dir, cfg, &cols, ck.meta.iteration as f64)?;
        (run, Some(ck))
    } else {
        (RunDir::create(run_dir, cfg, &cols)?, None)
    };
    let events = run.start_tensorboard()?;
    run.log(&format!("tensorboard: {}", events.display()))?;
    let s = learn(cfg, task, &mut run, ck.as_ref(), quiet)?;
    run.log(&format!(
        "summary {}",
        serde_json::to_string(&s).unwrap_or_default()
    ))?;
    Ok(s)
}
