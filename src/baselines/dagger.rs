//! The distillation baseline (the paper's "Distillation-based Method": online
//! distillation through DAgger, after Zhuang et al. 2023 and Ross et al. 2011),
//! `dreampolicy train dagger` with a `dagger:` section.
//!
//! One student with the specialists' observation interface (actor state, its
//! history, scandots: the `policy` section) learns on the mixed terrain map
//! from the specialists by supervision. Per control step:
//! 1. each env's teacher is the specialist of the terrain kind it stands on
//!    (the map tile under its pelvis; an env bound to a flat column that steps
//!    on the plane model, and every env of a plane scene, stands on `flat`);
//! 2. every teacher acts on its own normalizers and history (frozen), the
//!    student on its own (its statistics keep learning from what it visits);
//! 3. the action executed is the teacher's with probability β, else the
//!    student's mean: DAgger's mixture `β π* + (1 − β) π̂`, drawn per env and
//!    step; β falls linearly from `beta_start` to 0 at `beta_iterations`;
//! 4. the visited state (raw history, state and scandots) with the teacher's
//!    label goes into the aggregated dataset (a ring of `buffer_size`
//!    transitions).
//!
//! After each rollout of `ppo.num_steps` steps the student takes `updates`
//! Adam steps on minibatches of the dataset, minimizing the squared error of its
//! mean action to the labels (inputs normalized with its current statistics).
//! The student is saved as an ordinary policy checkpoint (`task: g1`; the
//! critic is unused and stays as initialized), so `eval`, `play`, `render`,
//! `export` and `benchmark` read it as any specialist. Checkpoints resume the
//! networks, Adam, the normalizers, the envs' RNGs and levels and β; the
//! aggregated dataset is not saved (hundreds of MB): a resume first refills it,
//! stepping the mixture of its iteration without updating the student, to as
//! many transitions as it held when the checkpoint was written
//! ([`Dagger::refill`]; the env-steps count), so that the first updates after
//! a resume do not fit a few thousand fresh states 20 times an iteration.
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use tch::{Kind, Tensor};

use crate::config::ConfigError;
use crate::env::task::VecTask;
use crate::env::VecEnv;
use crate::rl::agent::Agent;
use crate::rl::checkpoint::{self, Checkpoint, CheckpointMeta};
use crate::rl::config::{ExperimentConfig, TaskKind};
use crate::rl::optim::Adam;
use crate::rl::runner::{after_checkpoint, checkpoint_due, EpisodeStats, TrainSummary};
use crate::rl::RlError;
use crate::run::{latest_checkpoint, Progress, RunDir};
use crate::terrain::TerrainKind;

/// The `dagger:` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaggerConfig {
    /// The teacher of each terrain kind of the map (kind name -> specialist
    /// checkpoint); every kind the envs can stand on needs one.
    pub teachers: BTreeMap<String, String>,
    /// Teacher-forcing probability at iteration 0 (DAgger's β_0).
    #[serde(default = "one")]
    pub beta_start: f64,
    /// β falls linearly from `beta_start` to 0 at this iteration, then stays 0
    /// (0: the student acts from the start).
    pub beta_iterations: usize,
    /// Transitions the aggregated dataset holds (the oldest are dropped first).
    pub buffer_size: usize,
    /// Adam steps per iteration, each on `batch` transitions drawn uniformly
    /// from the dataset.
    pub updates: usize,
    pub batch: usize,
    pub learning_rate: f64,
    /// Global gradient-norm clip.
    #[serde(default = "default_clip")]
    pub max_grad_norm: f64,
}

fn one() -> f64 {
    1.0
}

fn default_clip() -> f64 {
    1.0
}

impl DaggerConfig {
    /// The `dagger:` section of `cfg` (a `task: g1` config), parsed and checked.
    pub fn of(cfg: &ExperimentConfig) -> Result<DaggerConfig, ConfigError> {
        if cfg.task != TaskKind::G1 {
            return Err(ConfigError::Invalid(
                "train dagger trains a G1 student: set `task: g1` (the default)".into(),
            ));
        }
        let d: DaggerConfig = crate::rl::config::parse_section(
            &cfg.dagger,
            "dagger",
            "train dagger needs a `dagger:` section (teachers, beta_iterations, buffer_size, updates, batch, learning_rate)",
        )?;
        d.validate()?;
        Ok(d)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad =
            |key: &str, why: String| Err(ConfigError::Invalid(format!("dagger.{key}: {why}")));
        if self.teachers.is_empty() {
            return bad("teachers", "names no specialist".into());
        }
        for (kind, path) in &self.teachers {
            TerrainKind::from_name(kind)
                .map_err(|e| ConfigError::Invalid(format!("dagger.teachers: {e}")))?;
            if path.trim().is_empty() {
                return bad(&format!("teachers.{kind}"), "names no checkpoint".into());
            }
        }
        if !(0.0..=1.0).contains(&self.beta_start) {
            return bad(
                "beta_start",
                format!("{} is not a probability", self.beta_start),
            );
        }
        if self.batch == 0 || self.updates == 0 {
            return bad("batch", "batch and updates must be at least 1".into());
        }
        if self.buffer_size < self.batch {
            return bad(
                "buffer_size",
                format!(
                    "{} is smaller than one batch ({})",
                    self.buffer_size, self.batch
                ),
            );
        }
        if !(self.learning_rate > 0.0 && self.max_grad_norm > 0.0) {
            return bad(
                "learning_rate",
                "learning_rate and max_grad_norm must be positive".into(),
            );
        }
        Ok(())
    }

    /// Teacher-forcing probability of iteration `it` (0-based).
    pub fn beta(&self, it: usize) -> f64 {
        if self.beta_iterations == 0 {
            return 0.0;
        }
        self.beta_start * (1.0 - it as f64 / self.beta_iterations as f64).max(0.0)
    }
}

/// The terrain kind each env stands on now: the kind of the map tile under its
/// pelvis (an env off the tiles, on the border, counts its own column's kind);
/// `flat` on a plane scene and for an env that steps on the plane model.
pub fn env_kinds(env: &VecEnv) -> Vec<TerrainKind> {
    let map = env.shared().scene.terrain.clone();
    env.envs()
        .iter()
        .map(|e| match &map {
            None => TerrainKind::Flat,
            Some(_) if e.on_plane() => TerrainKind::Flat,
            Some(m) => {
                let p = e.state().base_pos;
                let col = m.tile_at(p[0], p[1]).map_or(e.column(), |(_, c)| c);
                m.tile_kind(col)
            }
        })
        .collect()
}

/// A frozen specialist that labels the states of the envs on its terrain.
pub struct Teacher {
    pub kind: TerrainKind,
    pub path: String,
    pub agent: Agent,
}

impl Teacher {
    /// The specialist at `path` as the teacher of `kind`, for `env`'s envs; its
    /// actions must mean what the student's mean (same control interface and
    /// control period).
    pub fn load(
        kind: TerrainKind,
        path: &str,
        student: &ExperimentConfig,
        env: &VecEnv,
    ) -> Result<Teacher, RlError> {
        let ck = Checkpoint::read(Path::new(path))?;
        let tcfg = ck.config()?;
        let what = format!("dagger.teachers.{}: {path}", kind.name());
        if tcfg.task != TaskKind::G1 {
            return Err(RlError::Invalid(format!(
                "{what} is not a G1 specialist (task {:?})",
                tcfg.task
            )));
        }
        let yaml = |c: &crate::env::config::ControlConfig| serde_yaml::to_string(c).ok();
        if yaml(&tcfg.env.control) != yaml(&student.env.control)
            || (tcfg.env.sim.control_dt() - student.env.sim.control_dt()).abs() > 1e-12
        {
            return Err(RlError::Invalid(format!(
                "{what} acts through another control interface (env.control or the control period differ from this config's): its labels would mean other targets"
            )));
        }
        if tcfg.policy.scan_encoder.enabled
            && tcfg.env.observation.scan_grid != student.env.observation.scan_grid
        {
            return Err(RlError::Invalid(format!(
                "{what} reads its scandots on another grid ({:?}) than this config's env \
                 ({:?}): set env.observation.scan_grid to the teacher's",
                tcfg.env.observation.scan_grid, student.env.observation.scan_grid
            )));
        }
        let dims = env.dims();
        if ck.meta.dims != dims {
            return Err(RlError::Invalid(format!(
                "{what} was saved for {:?}, the env has {dims:?}",
                ck.meta.dims
            )));
        }
        let mut agent = Agent::new(&tcfg.policy, dims, env.n_envs(), tcfg.ppo.normalize_obs);
        ck.load_agent(&mut agent)?;
        agent.set_frozen(true);
        agent.reset_history(env);
        Ok(Teacher {
            kind,
            path: path.to_string(),
            agent,
        })
    }
}

/// The aggregated dataset: raw student inputs (history and state, scandots)
/// with the teachers' labels, a ring of `cap` transitions.
pub struct Aggregate {
    cap: usize,
    widths: [usize; 3],
    actor: Vec<f32>,
    scan: Vec<f32>,
    label: Vec<f32>,
    len: usize,
    next: usize,
}

impl Aggregate {
    /// Room for `cap` transitions of `actor` raw input floats, `scan`
    /// scandots and `action` label floats.
    pub fn new(cap: usize, actor: usize, scan: usize, action: usize) -> Aggregate {
        Aggregate {
            cap,
            widths: [actor, scan, action],
            actor: Vec::new(),
            scan: Vec::new(),
            label: Vec::new(),
            len: 0,
            next: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Add one transition (the oldest is overwritten once full).
    pub fn push(&mut self, actor: &[f32], scan: &[f32], label: &[f32]) {
        let [wa, ws, wl] = self.widths;
        debug_assert!(actor.len() == wa && scan.len() == ws && label.len() == wl);
        if self.len < self.cap {
            self.actor.extend_from_slice(actor);
            self.scan.extend_from_slice(scan);
            self.label.extend_from_slice(label);
            self.len += 1;
        } else {
            let j = self.next;
            self.actor[j * wa..(j + 1) * wa].copy_from_slice(actor);
            self.scan[j * ws..(j + 1) * ws].copy_from_slice(scan);
            self.label[j * wl..(j + 1) * wl].copy_from_slice(label);
        }
        self.next = (self.next + 1) % self.cap;
    }

    /// Transition `j`: raw actor input, scandots, label.
    pub fn get(&self, j: usize) -> (&[f32], &[f32], &[f32]) {
        let [wa, ws, wl] = self.widths;
        (
            &self.actor[j * wa..(j + 1) * wa],
            &self.scan[j * ws..(j + 1) * ws],
            &self.label[j * wl..(j + 1) * wl],
        )
    }
}

/// Names of the `metrics.csv` columns of `train dagger`, before the per-kind
/// action errors (`action_error_<kind>`).
pub const COLUMNS: [&str; 20] = [
    "iteration",
    "env_steps",
    "wall_time_s",
    "mean_return",
    "mean_episode_length",
    "episodes",
    "fall_fraction",
    "vel_error_xy",
    "vel_error_yaw",
    "beta",
    "teacher_forced_fraction",
    "imitation_loss",
    "action_error",
    "grad_norm",
    "buffer_size",
    "env_steps_per_s",
    "time_physics_s",
    "time_inference_s",
    "time_update_s",
    "terrain_level",
];

/// The student, its teachers, its dataset and the env they share.
pub struct Dagger {
    pub cfg: ExperimentConfig,
    pub dagger: DaggerConfig,
    pub env: VecEnv,
    pub student: Agent,
    pub teachers: Vec<Teacher>,
    pub adam: Adam,
    pub data: Aggregate,
    pub iteration: usize,
    pub env_steps: u64,
    wall_offset: f64,
    stats: EpisodeStats,
    /// What a fresh student took from `train.init_checkpoint`.
    pub transfer: Option<crate::rl::checkpoint::Transfer>,
}

/// What one DAgger iteration measured.
#[derive(Debug, Clone, Default)]
pub struct DaggerStats {
    pub beta: f64,
    pub forced_fraction: f64,
    pub loss: f64,
    pub grad_norm: f64,
    /// Mean |student mean − teacher label| over the visited states and the action dims.
    pub action_error: f64,
    /// The same per teacher (in `teachers` order; NaN where no env stood on its kind).
    pub kind_error: Vec<f64>,
    pub episodes: usize,
    pub falls: usize,
    pub vel_error: [f64; 2],
    pub level: f64,
    pub physics_s: f64,
    pub inference_s: f64,
    pub update_s: f64,
}

impl Dagger {
    /// The env of `cfg.env`, the teachers of `cfg.dagger` and a fresh student
    /// (from `train.init_checkpoint` if set), or the student of `resume`.
    pub fn new(cfg: &ExperimentConfig, resume: Option<&Checkpoint>) -> Result<Dagger, RlError> {
        let dagger = DaggerConfig::of(cfg)?;
        tch::set_num_threads(cfg.train.torch_threads as i32);
        tch::manual_seed(cfg.train.seed as i64);
        let mut env = VecEnv::new(&cfg.env)?;
        let n = env.n_envs();
        let dims = env.dims();
        cfg.policy.scan_encoder.check_input(dims.scan)?;
        // every kind the map holds needs its teacher
        let mut kinds: Vec<TerrainKind> = match &env.shared().scene.terrain {
            None => vec![TerrainKind::Flat],
            Some(m) => (0..m.num_cols()).map(|c| m.tile_kind(c)).collect(),
        };
        if env.shared().scene.terrain.is_some() && (0..n).any(|i| env.envs()[i].on_plane()) {
            kinds.push(TerrainKind::Flat);
        }
        kinds.sort_by_key(|k| k.name());
        kinds.dedup();
        for k in &kinds {
            if !dagger.teachers.contains_key(k.name()) {
                return Err(RlError::Invalid(format!(
                    "dagger.teachers names no specialist for '{}', a kind of this map",
                    k.name()
                )));
            }
        }
        let mut teachers = Vec::new();
        for (name, path) in &dagger.teachers {
            let kind = TerrainKind::from_name(name)
                .map_err(|e| RlError::Invalid(format!("dagger.teachers: {e}")))?;
            teachers.push(Teacher::load(kind, path, cfg, &env)?);
        }
        let mut student = Agent::new(&cfg.policy, dims, n, cfg.ppo.normalize_obs);
        let mut transfer = None;
        if let (Some(path), None) = (&cfg.train.init_checkpoint, resume) {
            transfer = Some(Checkpoint::read(Path::new(path))?.transfer_agent(&mut student)?);
        }
        let mut adam = Adam::new(student.policy.named_parameters(), dagger.learning_rate);
        let (mut iteration, mut env_steps, mut wall_offset) = (0, 0, 0.0);
        if let Some(ck) = resume {
            (iteration, env_steps, wall_offset) =
                ck.resume_into(&mut env, &mut student, &mut adam)?;
            // the config's rate (a resume may change it)
            adam.lr = dagger.learning_rate;
        }
        let stats = EpisodeStats::new(n, resume.map(|ck| &ck.meta.episode_window));
        student.reset_history(&env);
        for t in &mut teachers {
            t.agent.reset_history(&env);
        }
        let scan_w = if student.policy.uses_scan() {
            dims.scan
        } else {
            0
        };
        let data = Aggregate::new(
            dagger.buffer_size,
            student.policy.actor_input_dim(),
            scan_w,
            dims.action,
        );
        Ok(Dagger {
            cfg: cfg.clone(),
            dagger,
            env,
            student,
            teachers,
            adam,
            data,
            iteration,
            env_steps,
            wall_offset,
            stats,
            transfer,
        })
    }

    /// Index into `teachers` of each env's teacher now.
    pub fn teacher_of(&self) -> Vec<usize> {
        env_kinds(&self.env)
            .into_iter()
            .map(|k| {
                self.teachers
                    .iter()
                    .position(|t| t.kind == k)
                    .expect("every kind of the map has a teacher (checked at start)")
            })
            .collect()
    }

    /// One control step of the mixture with teacher-forcing probability
    /// `beta`: every env's label from its teacher into the dataset (in env
    /// order), the executed actions, the env step. Returns how many envs were
    /// teacher-forced.
    pub fn control_step(&mut self, beta: f64, rng: &mut ChaCha8Rng) -> usize {
        let mut err = vec![(0.0, 0usize); self.teachers.len()];
        self.step(beta, rng, &mut err).0
    }

    /// After a resume: step the mixture of the current iteration's β without
    /// updating the student until the aggregated dataset holds what it held
    /// when the checkpoint was written, `min(buffer_size, iteration x n_envs x
    /// num_steps)` transitions (its states are the current student's, where
    /// the uninterrupted run's oldest came from earlier students). Returns the
    /// env-steps it took, which count in `env_steps`.
    pub fn refill(&mut self) -> u64 {
        let n = self.env.n_envs();
        let target = self
            .dagger
            .buffer_size
            .min(self.iteration * n * self.cfg.ppo.num_steps);
        let beta = self.dagger.beta(self.iteration);
        let mut rng = ChaCha8Rng::seed_from_u64(
            self.cfg.train.seed ^ 0xA66E_6A7E ^ (self.iteration as u64).rotate_left(32),
        );
        let mut steps = 0u64;
        while self.data.len() < target {
            self.control_step(beta, &mut rng);
            steps += n as u64;
        }
        self.env_steps += steps;
        steps
    }

    /// [`Dagger::control_step`], adding each teacher's summed absolute action error and count to
    /// `err`; returns how many envs were teacher-forced and the seconds the
    /// env step took.
    fn step(&mut self, beta: f64, rng: &mut ChaCha8Rng, err: &mut [(f64, usize)]) -> (usize, f64) {
        let n = self.env.n_envs();
        let a = self.env.dims().action;
        let d = self.env.dims().obs;
        let who = self.teacher_of();
        self.student.prepare(&self.env);
        let own = self.student.act_mean();
        let mut labels = vec![0.0f32; n * a];
        for (ti, t) in self.teachers.iter_mut().enumerate() {
            // every teacher keeps its history, acting or not
            t.agent.prepare(&self.env);
            if !who.contains(&ti) {
                continue;
            }
            let act = t.agent.act_mean();
            for (i, _) in who.iter().enumerate().filter(|(_, &w)| w == ti) {
                labels[i * a..(i + 1) * a].copy_from_slice(&act[i * a..(i + 1) * a]);
            }
        }
        let k = self.student.policy.history_len();
        let scan_w = self.data.widths[1];
        let mut row = vec![0.0f32; (k + 1) * d];
        let mut exec = own.clone();
        let mut forced = 0;
        for i in 0..n {
            row[..k * d].copy_from_slice(&self.student.history()[i * k * d..(i + 1) * k * d]);
            row[k * d..].copy_from_slice(&self.env.obs[i * d..(i + 1) * d]);
            let scan = &self.env.scan[i * scan_w..(i + 1) * scan_w];
            let label = &labels[i * a..(i + 1) * a];
            self.data.push(&row, scan, label);
            let e: f64 = own[i * a..(i + 1) * a]
                .iter()
                .zip(label)
                .map(|(x, y)| f64::from((x - y).abs()))
                .sum::<f64>()
                / a as f64;
            err[who[i]].0 += e;
            err[who[i]].1 += 1;
            if rng.random::<f64>() < beta {
                exec[i * a..(i + 1) * a].copy_from_slice(label);
                forced += 1;
            }
        }
        let t = Instant::now();
        self.env.step(&exec);
        let physics = t.elapsed().as_secs_f64();
        self.student.after_step(&self.env);
        for t in &mut self.teachers {
            t.agent.after_step(&self.env);
        }
        (forced, physics)
    }

    /// `updates` Adam steps on minibatches of the dataset: the mean squared
    /// error of the student's mean action to the labels. Returns the mean loss
    /// and gradient norm.
    pub fn update(&mut self, rng: &mut ChaCha8Rng) -> (f64, f64) {
        if self.data.is_empty() {
            return (f64::NAN, f64::NAN);
        }
        let [wa, ws, wl] = self.data.widths;
        let d = self.env.dims().obs;
        let b = self.dagger.batch;
        let (mut loss_sum, mut gn_sum) = (0.0, 0.0);
        let norm = self.student.normalize;
        for _ in 0..self.dagger.updates {
            let mut actor = vec![0.0f32; b * wa];
            let mut scan = vec![0.0f32; b * ws];
            let mut label = Vec::with_capacity(b * wl);
            for r in 0..b {
                let j = rng.random_range(0..self.data.len());
                let (xa, xs, y) = self.data.get(j);
                let out = &mut actor[r * wa..(r + 1) * wa];
                for (src, dst) in xa.chunks_exact(d).zip(out.chunks_exact_mut(d)) {
                    if norm {
                        self.student.obs_norm.apply(src, dst);
                    } else {
                        dst.copy_from_slice(src);
                    }
                }
                if ws > 0 {
                    let out = &mut scan[r * ws..(r + 1) * ws];
                    if norm {
                        self.student.scan_norm.apply(xs, out);
                    } else {
                        out.copy_from_slice(xs);
                    }
                }
                label.extend_from_slice(y);
            }
            let bi = b as i64;
            let xa = Tensor::from_slice(&actor).view([bi, wa as i64]);
            let xs = (ws > 0).then(|| Tensor::from_slice(&scan).view([bi, ws as i64]));
            let y = Tensor::from_slice(&label).view([bi, wl as i64]);
            let mean = self.student.policy.actor_mean(&xa, xs.as_ref());
            let loss = (mean - y).square().mean(Kind::Float);
            self.adam.zero_grad();
            loss.backward();
            gn_sum += self.adam.clip_grad_norm(self.dagger.max_grad_norm);
            self.adam.step();
            loss_sum += loss.double_value(&[]);
        }
        let u = self.dagger.updates as f64;
        (loss_sum / u, gn_sum / u)
    }

    /// One iteration: `ppo.num_steps` control steps of the mixture, then the
    /// student's updates.
    pub fn iterate(&mut self) -> DaggerStats {
        let seed = self.cfg.train.seed;
        let mut rng = ChaCha8Rng::seed_from_u64(
            seed ^ (self.iteration as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        tch::manual_seed((seed as i64).wrapping_mul(1_000_003) ^ self.iteration as i64);
        let n = self.env.n_envs();
        let steps = self.cfg.ppo.num_steps;
        let beta = self.dagger.beta(self.iteration);
        let mut s = DaggerStats {
            beta,
            ..Default::default()
        };
        let mut err = vec![(0.0, 0usize); self.teachers.len()];
        let mut forced = 0usize;
        let t0 = Instant::now();
        let mut physics = 0.0;
        for _ in 0..steps {
            let (f, p) = self.step(beta, &mut rng, &mut err);
            forced += f;
            physics += p;
            let e = VecTask::tracking_errors(&self.env);
            s.vel_error[0] += e[0];
            s.vel_error[1] += e[1];
            for (i, o) in self.env.outcomes.iter().enumerate() {
                self.stats.add(i, f64::from(o.reward), o.episode_done);
                if o.episode_done {
                    s.episodes += 1;
                    s.falls += usize::from(o.terminated);
                }
            }
        }
        s.physics_s = physics;
        s.inference_s = t0.elapsed().as_secs_f64() - physics;
        let t1 = Instant::now();
        let (loss, gn) = self.update(&mut rng);
        s.update_s = t1.elapsed().as_secs_f64();
        s.loss = loss;
        s.grad_norm = gn;
        let total: usize = err.iter().map(|e| e.1).sum();
        s.action_error = err.iter().map(|e| e.0).sum::<f64>() / total.max(1) as f64;
        s.kind_error = err
            .iter()
            .map(|&(e, c)| if c > 0 { e / c as f64 } else { f64::NAN })
            .collect();
        s.forced_fraction = forced as f64 / (n * steps) as f64;
        s.vel_error = [s.vel_error[0] / steps as f64, s.vel_error[1] / steps as f64];
        s.level = self.env.mean_terrain_level();
        self.iteration += 1;
        self.env_steps += (n * steps) as u64;
        s
    }

    /// Mean return and length over the last 100 episodes.
    pub fn window_means(&self) -> (f64, f64) {
        self.stats.means()
    }

    /// Write the resume checkpoint, then start every env on a new episode (as
    /// the PPO runner does, so that the saved RNGs and levels are a start).
    pub fn checkpoint(&mut self, path: &Path, session_wall: f64) -> Result<(), RlError> {
        let meta = CheckpointMeta::record(
            &self.cfg,
            &self.env,
            Some(&self.adam),
            (
                self.iteration,
                self.env_steps,
                self.wall_offset + session_wall,
            ),
            self.stats.window(),
        )?;
        checkpoint::save(path, &self.student, Some(&self.adam), Vec::new(), &meta)?;
        self.env.reset_all();
        self.student.reset_history(&self.env);
        for t in &mut self.teachers {
            t.agent.reset_history(&self.env);
        }
        self.stats.reset();
        Ok(())
    }

    /// The run's wall time given this session's seconds.
    pub fn wall_time(&self, session: f64) -> f64 {
        self.wall_offset + session
    }
}

/// The `metrics.csv` columns of a run with `teachers`.
pub fn columns(teachers: &[Teacher]) -> Vec<String> {
    COLUMNS
        .iter()
        .map(|c| c.to_string())
        .chain(
            teachers
                .iter()
                .map(|t| format!("action_error_{}", t.kind.name())),
        )
        .collect()
}

/// Draw `plots/training.png` of a DAgger run.
pub fn plot_run(run_dir: &Path) -> Result<std::path::PathBuf, crate::plot::PlotError> {
    use crate::plot::Panel;
    let x = "env_steps";
    let panels = [
        Panel::new("episode return (last 100)", x, &["mean_return"]),
        Panel::new("episode length (steps)", x, &["mean_episode_length"]),
        Panel::new("imitation", x, &["imitation_loss", "action_error"]),
        Panel::new(
            "teacher forcing",
            x,
            &["beta", "teacher_forced_fraction", "fall_fraction"],
        ),
        Panel::new("tracking error", x, &["vel_error_xy", "vel_error_yaw"]),
        Panel::new("env-steps/s", x, &["env_steps_per_s"]),
        Panel::new("mean terrain level", x, &["terrain_level"]),
    ];
    crate::run::plot_training(run_dir, &panels)
}

/// `train dagger`: train the student of `cfg` in `run_dir` to
/// `train.iterations`, fresh or resumed from the run's latest checkpoint.
pub fn train(
    cfg: &ExperimentConfig,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    let ckpt = latest_checkpoint(run_dir);
    let ck = if resume {
        Some(Checkpoint::read(&ckpt)?)
    } else {
        None
    };
    let mut dg = Dagger::new(cfg, ck.as_ref())?;
    let cols = columns(&dg.teachers);
    let cols: Vec<&str> = cols.iter().map(|s| s.as_str()).collect();
    let mut run = match &ck {
        Some(ck) => RunDir::resume(run_dir, cfg, &cols, ck.meta.iteration as f64)?,
        None => RunDir::create(run_dir, cfg, &cols)?,
    };
    let events = run.start_tensorboard()?;
    run.log(&format!("tensorboard: {}", events.display()))?;
    let total = cfg.train.iterations;
    let first = dg.iteration;
    run.log(&format!(
        "start at iteration {first} of {total}: {} envs x {} steps, {} parameters, teachers {}",
        dg.env.n_envs(),
        cfg.ppo.num_steps,
        dg.student.policy.num_parameters(),
        dg.teachers
            .iter()
            .map(|t| format!("{}={}", t.kind.name(), t.path))
            .collect::<Vec<_>>()
            .join(", ")
    ))?;
    if let (Some(t), Some(path)) = (&dg.transfer, &cfg.train.init_checkpoint) {
        run.log(&format!("student initialized from {path}: {t}"))?;
    }
    if ck.is_some() {
        let t = Instant::now();
        let steps = dg.refill();
        run.log(&format!(
            "refilled the aggregated dataset to {} transitions before the first update: {steps} env-steps at beta {:.3}, {:.0} s",
            dg.data.len(),
            dg.dagger.beta(dg.iteration),
            t.elapsed().as_secs_f64()
        ))?;
    }
    let progress = Progress::new("dagger", total as u64, quiet);
    let start = Instant::now();
    let mut last = (f64::NAN, f64::NAN);
    while dg.iteration < total {
        let t0 = Instant::now();
        let s = dg.iterate();
        let dt = t0.elapsed().as_secs_f64();
        let wall = dg.wall_time(start.elapsed().as_secs_f64());
        let (ret, len) = dg.window_means();
        last = (ret, len);
        let n_steps = (cfg.ppo.num_steps * dg.env.n_envs()) as f64;
        let mut row = vec![
            dg.iteration as f64,
            dg.env_steps as f64,
            wall,
            ret,
            len,
            s.episodes as f64,
            if s.episodes > 0 {
                s.falls as f64 / s.episodes as f64
            } else {
                f64::NAN
            },
            s.vel_error[0],
            s.vel_error[1],
            s.beta,
            s.forced_fraction,
            s.loss,
            s.action_error,
            s.grad_norm,
            dg.data.len() as f64,
            n_steps / dt,
            s.physics_s,
            s.inference_s,
            s.update_s,
            s.level,
        ];
        row.extend(&s.kind_error);
        run.metrics_row(&row)?;
        if !s.loss.is_finite() && cfg.train.stop_on_nan && !dg.data.is_empty() {
            return Err(RlError::NonFinite(format!(
                "imitation loss is {} at iteration {}",
                s.loss, dg.iteration
            )));
        }
        progress.set(
            dg.iteration as u64,
            &format!(
                "beta {:.2} loss {:.4} err {:.3} len {:.0} {:.0} steps/s",
                s.beta,
                s.loss,
                s.action_error,
                len,
                n_steps / dt
            ),
        );
        if checkpoint_due(&cfg.train, dg.iteration) {
            dg.checkpoint(&ckpt, start.elapsed().as_secs_f64())?;
            after_checkpoint(&mut run, &cfg.train, dg.iteration, plot_run)?;
            run.log(&format!(
                "iteration {} env_steps {} wall {wall:.0}s beta {:.3} loss {:.5} action_error {:.4}: checkpoint {}",
                dg.iteration,
                dg.env_steps,
                s.beta,
                s.loss,
                s.action_error,
                ckpt.display()
            ))?;
        }
    }
    progress.finish();
    let s = TrainSummary {
        iterations: dg.iteration,
        env_steps: dg.env_steps,
        wall_time_s: dg.wall_time(start.elapsed().as_secs_f64()),
        mean_return: last.0,
        mean_episode_length: last.1,
        checkpoint: ckpt,
    };
    run.log(&format!(
        "summary {}",
        serde_json::to_string(&s).unwrap_or_default()
    ))?;
    Ok(s)
}
