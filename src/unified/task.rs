//! [`UnifiedTask`]: the G1 env with the world model in the loop, as a
//! [`VecTask`] that the PPO trainer steps like any other (the PPO loop is not
//! forked).
//!
//! Per control step:
//! 1. the env steps; its reward table holds the paper's regularization and
//!    safety terms (`env.rewards`);
//! 2. each env that did not just reset adds the four tracking scores of its
//!    body-space state against the plan's next state `ŝ_{t+1}`
//!    ([`super::track`]), and the style reward of its transition
//!    `(s_t, s_{t+1})` under the discriminator ([`super::amp`]), each times its
//!    weight and the control `dt` (the env's convention);
//! 3. the histories take `s_{t+1}` (a reset fills them with the new `s_0`),
//!    the plans shift by one, and the envs whose plan is `replan_every` steps
//!    old or gone get a new one, in one batched world-model call from their
//!    last `K` states and live scandots;
//! 4. the policy's "scan" input is the plan: the first `future_states`
//!    predicted states (the future encoder is the agent's scan encoder, an MLP),
//!    followed by the env's live scandots with `unified.scandots`.
//!
//! The world model's history holds the env's actor states (with its
//! observation noise: what a robot's sensors give), or with
//! `unified.history: clean` its noise-free states (what the world model was
//! trained on; [`HistorySource`]). Each plan made at `t` also
//! gives the discriminator a real transition `(s_t, ŝ_{t+1})`; the policy's
//! `(s_t, s_{t+1})` are the fake ones; [`VecTask::after_rollout`] updates it
//! once per iteration on both. The discriminator's `s_t` and `s_{t+1}` are the
//! noise-free states (the critic's copy): the world model predicts noise-free
//! states (the expert dataset has no observation noise), so noisy policy states
//! would give the fakes away by their noise alone (with them the discriminator
//! reached 0.998 accuracy within 800 iterations and the style reward fell from
//! 0.67 to 0.43).
use std::path::Path;

use tch::{Device, Tensor};

use super::amp::Discriminator;
use super::config::{BaseVelocity, HistorySource, UnifiedConfig};
use super::fk::BodyFk;
use super::plan::{History, Plan};
use super::track::TrackingErrors;
use crate::env::obs::{ANG_VEL, COMMAND, CRITIC_DIM, OBS_DIM, SCAN_DIM};
use crate::env::task::{TaskDims, VecTask};
use crate::env::{Outcome, StepInfo, VecEnv};
use crate::rl::config::ExperimentConfig;
use crate::rl::RlError;
use crate::world_model::sampler::Noise;
use crate::world_model::WorldModel;

/// Names of the task's own metrics (`metrics.csv`).
pub const METRICS: [&str; 13] = [
    "amp_loss",
    "amp_grad_penalty",
    "amp_d_real",
    "amp_d_fake",
    "amp_accuracy",
    "style_reward",
    "track_pos",
    "track_ori",
    "track_lin_vel",
    "track_ang_vel",
    "wm_time_s",
    "wm_plans",
    "wm_nonfinite",
];

/// Sums over the steps of a rollout, for the metrics.
#[derive(Debug, Default, Clone)]
struct Sums {
    track: [f64; 4],
    tracked: usize,
    style: f64,
    styled: usize,
    wm_time: f64,
    plans: usize,
    nonfinite: usize,
}

/// One predicted state of a plan in the world ([`UnifiedTask::plan_in_world`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedPose {
    pub pelvis: [f64; 3],
    pub left_foot: [f64; 3],
    pub right_foot: [f64; 3],
}

pub struct UnifiedTask {
    env: VecEnv,
    wm: WorldModel,
    pub cfg: UnifiedConfig,
    fk: BodyFk,
    pub disc: Discriminator,
    history: History,
    plan: Plan,
    noise: Noise,
    /// Predicted states the policy reads.
    future: usize,
    /// Whether the live scandots follow them (`unified.scandots`).
    scandots: bool,
    dt: f64,
    scan: Vec<f32>,
    final_scan: Vec<f32>,
    outcomes: Vec<Outcome>,
    /// The noise-free states before the last step (the discriminator's `s_t`).
    prev_clean: Vec<f32>,
    /// This iteration's discriminator samples: feature rows.
    real: Vec<f32>,
    fake: Vec<f32>,
    sums: Sums,
}

impl UnifiedTask {
    /// The env of `cfg.env` with the world model of `cfg.unified` (`task: unified`).
    pub fn new(cfg: &ExperimentConfig) -> Result<UnifiedTask, RlError> {
        Self::build(cfg, None)
    }
    fn build(cfg: &ExperimentConfig, env: Option<VecEnv>) -> Result<UnifiedTask, RlError> {
        let u = UnifiedConfig::of(cfg)?;
        let wm = WorldModel::load(Path::new(&u.world_model), Device::Cpu)
            .map_err(|e| RlError::Invalid(format!("unified.world_model: {e}")))?;
        let (sd, cd) = wm.net.dims();
        if sd != OBS_DIM || cd != SCAN_DIM {
            return Err(RlError::Invalid(format!(
                "unified.world_model {}: states of {sd} and scandots of {cd}, the G1 env has {OBS_DIM} and {SCAN_DIM}",
                u.world_model
            )));
        }
        if cfg.env.observation.scan_grid != crate::env::obs::ScanGrid::default() {
            return Err(RlError::Invalid(format!(
                "env.observation.scan_grid {:?}: the world model reads the dataset's scandots, \
                 which `collect` records on the default grid; leave scan_grid out",
                cfg.env.observation.scan_grid
            )));
        }
        let (k, h) = (wm.history(), wm.horizon());
        let future = u.future_states.unwrap_or(h);
        if future > h {
            return Err(RlError::Invalid(format!(
                "unified.future_states {future} is more than the world model's horizon {h}"
            )));
        }
        if u.scandots && cfg.policy.scan_encoder.kind != crate::rl::config::ScanEncoderKind::Mlp {
            return Err(RlError::Invalid(
                "unified.scandots: the future encoder then reads [plan | scandots], which \
                 only an MLP encoder takes (policy.scan_encoder.kind: mlp)"
                    .into(),
            ));
        }
        let env = match env {
            Some(env) => env,
            None => VecEnv::new(&cfg.env)?,
        };
        let n = env.n_envs();
        let model = env.envs()[0].data().model().clone();
        let fk = BodyFk::new(model, &cfg.env.observation.scales)
            .map_err(|e| RlError::Invalid(format!("tracked bodies: {e}")))?
            .with_base_velocity(u.tracking.base_velocity == BaseVelocity::Command);
        tch::manual_seed(cfg.train.seed as i64 ^ 0x00A1_1CE5);
        let disc = Discriminator::new(&u.amp, Device::Cpu);
        let dt = env.shared().dt;
        let mut t = UnifiedTask {
            history: History::new(n, k, OBS_DIM),
            plan: Plan::new(n, h, OBS_DIM, u.replan_every),
            noise: Noise::new(u.seed),
            future,
            scandots: u.scandots,
            dt,
            scan: vec![0.0; n * scan_row(future, u.scandots)],
            final_scan: vec![0.0; n * scan_row(future, u.scandots)],
            outcomes: vec![Outcome::default(); n],
            prev_clean: vec![0.0; n * OBS_DIM],
            real: Vec::new(),
            fake: Vec::new(),
            sums: Sums::default(),
            env,
            wm,
            cfg: u,
            fk,
            disc,
        };
        t.start_all();
        Ok(t)
    }

    /// The unified task around `env` (an evaluation lane's), with the world
    /// model and discriminator of `cfg.unified`.
    pub fn with_env(cfg: &ExperimentConfig, env: VecEnv) -> Result<UnifiedTask, RlError> {
        Self::build(cfg, Some(env))
    }

    /// The env underneath.
    pub fn env(&self) -> &VecEnv {
        &self.env
    }

    /// Start env `i` on a new episode (evaluation, after it reached its goal):
    /// its history restarts from the new `s_0` and it gets a new plan now.
    pub fn reset_env(&mut self, i: usize) {
        self.env.reset_env(i);
        self.history
            .reset(i, history_state(&self.env, self.cfg.history, i));
        self.plan.invalidate(i);
        self.replan();
        self.write_scan();
    }

    /// The world model's `K`.
    pub fn history_len(&self) -> usize {
        self.history.len()
    }

    /// The world model's `H`.
    pub fn horizon(&self) -> usize {
        self.plan.horizon()
    }

    /// Every env's plan, `[n, H * OBS_DIM]`.
    pub fn plans(&self) -> &[f32] {
        self.plan.rows()
    }

    /// Env `i`'s plan placed in the world, for drawing (`play`'s `/plan`): one
    /// [`PlannedPose`] per predicted state, `None` while it has no plan. A
    /// state fixes the bodies relative to the pelvis in its heading frame
    /// (forward kinematics), not where the pelvis is: the pelvis of predicted
    /// state `k` is put at the robot's pelvis now, moved along the heading by
    /// the predicted states' commanded velocities (`k` control steps of them),
    /// its heading turned by their predicted yaw rates.
    pub fn plan_in_world(&mut self, i: usize) -> Option<Vec<PlannedPose>> {
        let (plan, live) = self.plan.future(i);
        if !live {
            return None;
        }
        let plan = plan.to_vec();
        let sc = self.fk.scales().clone();
        let s = self.env.envs()[i].state();
        let mut pos = s.base_pos;
        let mut yaw = crate::env::state::rpy(&s.base_rot)[2];
        let foot = |name: &str| {
            crate::robot::TRACKED_BODIES
                .iter()
                .position(|b| *b == name)
                .expect("the ankles are tracked bodies")
        };
        let (lf, rf) = (foot("left_ankle_roll_link"), foot("right_ankle_roll_link"));
        let mut out = Vec::with_capacity(self.plan.horizon());
        for st in plan.chunks_exact(OBS_DIM) {
            let c = |a: usize| f64::from(st[COMMAND.start + a]) / sc.commands[a];
            let wz = f64::from(st[ANG_VEL.start + 2]) / sc.ang_vel;
            yaw += wz * self.dt;
            let (sy, cy) = yaw.sin_cos();
            let (vx, vy) = (c(0), c(1));
            pos[0] += (cy * vx - sy * vy) * self.dt;
            pos[1] += (sy * vx + cy * vy) * self.dt;
            let b = self.fk.from_state(st);
            let place = |r: [f64; 3]| {
                [
                    pos[0] + cy * r[0] - sy * r[1],
                    pos[1] + sy * r[0] + cy * r[1],
                    pos[2] + r[2],
                ]
            };
            out.push(PlannedPose {
                pelvis: pos,
                left_foot: place(b.pos[lf]),
                right_foot: place(b.pos[rf]),
            });
        }
        Some(out)
    }

    /// After every env was reset: histories of `s_0`, fresh plans, the sampling
    /// noise reseeded from the envs' RNG states (a resumed run restores them,
    /// so it draws the same noise), the discriminator samples and the metric
    /// sums dropped.
    fn start_all(&mut self) {
        let n = self.env.n_envs();
        for i in 0..n {
            self.history
                .reset(i, history_state(&self.env, self.cfg.history, i));
            self.plan.invalidate(i);
        }
        let mut seed = self.cfg.seed ^ 0x9E37_79B9_7F4A_7C15;
        for s in self.env.snapshot() {
            for b in s.rng_seed {
                seed = (seed ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3);
            }
            seed = (seed ^ s.rng_stream ^ s.rng_word_pos as u64).wrapping_mul(0x0100_0000_01B3);
        }
        self.noise = Noise::new(seed);
        self.real.clear();
        self.fake.clear();
        // the next rollout's sums start here (a resumed run builds the task and
        // then resets it: one start's plans count, as in an unbroken run)
        self.sums = Sums::default();
        self.replan();
        self.write_scan();
    }

    /// One batched world-model call for every env whose plan is due. A plan
    /// the world model cannot give (a non-finite state) holds the env's
    /// current state instead, and is counted (`wm_nonfinite`).
    fn replan(&mut self) {
        let due: Vec<usize> = self.plan.due().collect();
        if due.is_empty() {
            return;
        }
        let t0 = std::time::Instant::now();
        let (k, h, d) = (self.history.len(), self.plan.horizon(), OBS_DIM);
        if self.cfg.plan == super::config::PlanSource::Hold {
            // the ablation: the newest state over the whole horizon
            let mut held = vec![0.0f32; h * d];
            for &i in &due {
                hold_state(&mut held, &self.history.row(i)[(k - 1) * d..]);
                self.plan.set(i, &held);
            }
            self.sums.plans += due.len();
            return;
        }
        // the shapes were checked when the task was built
        let pred = super::plan::predict_due(
            &self.wm,
            &self.history,
            &self.env.scan,
            &due,
            &self.cfg.sampling,
            &mut self.noise,
        );
        let mut held = vec![0.0f32; h * d];
        for (j, &i) in due.iter().enumerate() {
            let newest = &self.history.row(i)[(k - 1) * d..];
            let mut row = &pred[j * h * d..(j + 1) * h * d];
            if row.iter().any(|v| !v.is_finite()) {
                hold_state(&mut held, newest);
                row = &held;
                self.sums.nonfinite += 1;
            } else {
                // a real transition for the discriminator: (s_t, ŝ_{t+1})
                let s_t = clean_state(self.env.critic(), i);
                self.real.extend(Discriminator::features(s_t, &row[..d], d));
            }
            self.plan.set(i, row);
        }
        self.sums.wm_time += t0.elapsed().as_secs_f64();
        self.sums.plans += due.len();
    }

    /// The policy's future input: the first `future` states of each plan,
    /// then (`unified.scandots`) the env's scandots.
    fn write_scan(&mut self) {
        let (w, row) = (self.future * OBS_DIM, self.scan_width());
        for i in 0..self.env.n_envs() {
            let (plan, _) = self.plan.future(i);
            let dots = &self.env.scan[i * SCAN_DIM..(i + 1) * SCAN_DIM];
            let dots = self.scandots.then_some(dots);
            write_row(&mut self.scan[i * row..(i + 1) * row], &plan[..w], dots);
        }
    }

    /// The width of one env's row of the policy's future input.
    fn scan_width(&self) -> usize {
        scan_row(self.future, self.scandots)
    }
    fn step_inner(&mut self, actions: &[f32]) -> StepInfo {
        let n = self.env.n_envs();
        for (i, c) in self.prev_clean.chunks_exact_mut(OBS_DIM).enumerate() {
            c.copy_from_slice(clean_state(self.env.critic(), i));
        }
        let mut info = self.env.step(actions);
        self.outcomes.copy_from_slice(&self.env.outcomes);
        let d = OBS_DIM;
        let (w, u) = (&self.cfg.tracking.weights, &self.cfg);
        // tracking against ŝ_{t+1}, and the policy's transitions
        let mut fake_envs = Vec::with_capacity(n);
        for i in 0..n {
            if self.outcomes[i].episode_done {
                continue;
            }
            if let (_, true) = self.plan.future(i) {
                let desired = self.fk.from_state(self.plan.next(i));
                let e = self.env.envs()[i].data();
                let actual = self.fk.from_qpos(e.qpos(), e.qvel());
                let s = TrackingErrors::between(&desired, &actual).scores(&u.tracking.sigmas);
                let r: f64 = (0..4).map(|k| w[k] * s[k]).sum();
                self.outcomes[i].reward += (r * self.dt) as f32;
                for k in 0..4 {
                    self.sums.track[k] += s[k];
                }
                self.sums.tracked += 1;
            }
            fake_envs.push(i);
        }
        if !fake_envs.is_empty() {
            let mut s = Vec::with_capacity(fake_envs.len() * d);
            let mut s2 = Vec::with_capacity(fake_envs.len() * d);
            let critic = self.env.critic();
            for &i in &fake_envs {
                s.extend_from_slice(&self.prev_clean[i * d..(i + 1) * d]);
                s2.extend_from_slice(clean_state(critic, i));
            }
            let rows = Discriminator::features(&s, &s2, d);
            let style = self.disc.style_reward(&rows);
            for (&i, &r) in fake_envs.iter().zip(&style) {
                self.outcomes[i].reward += (u.style_weight * f64::from(r) * self.dt) as f32;
                self.sums.style += f64::from(r);
            }
            self.sums.styled += style.len();
            self.fake.extend(rows);
        }
        // histories and plans
        self.plan.advance();
        let (fw, row) = (self.future * d, self.scan_width());
        for i in 0..n {
            let s = history_state(&self.env, self.cfg.history, i);
            if self.outcomes[i].episode_done {
                let (plan, _) = self.plan.future(i);
                let dots = &self.env.final_scan[i * SCAN_DIM..(i + 1) * SCAN_DIM];
                let dots = self.scandots.then_some(dots);
                write_row(
                    &mut self.final_scan[i * row..(i + 1) * row],
                    &plan[..fw],
                    dots,
                );
                self.plan.invalidate(i);
                self.history.reset(i, s);
            } else {
                self.history.push(i, s);
            }
        }
        self.replan();
        self.write_scan();
        info.mean_reward = self
            .outcomes
            .iter()
            .map(|o| f64::from(o.reward))
            .sum::<f64>()
            / n as f64;
        info
    }
}

/// One env's row of the policy's future input: `future` predicted states,
/// then the scandots when the policy reads them.
fn scan_row(future: usize, scandots: bool) -> usize {
    future * OBS_DIM + if scandots { SCAN_DIM } else { 0 }
}

/// One env's row `dst` of the policy's future input: the plan's states it
/// reads, then its scandots with `unified.scandots`.
fn write_row(dst: &mut [f32], plan: &[f32], dots: Option<&[f32]>) {
    dst[..plan.len()].copy_from_slice(plan);
    if let Some(dots) = dots {
        dst[plan.len()..].copy_from_slice(dots);
    }
}

/// Env `i`'s state as the world model's history takes it (`unified.history`):
/// its observation, or its noise-free state.
fn history_state(env: &VecEnv, source: HistorySource, i: usize) -> &[f32] {
    match source {
        HistorySource::Observed => &env.obs[i * OBS_DIM..(i + 1) * OBS_DIM],
        HistorySource::Clean => clean_state(env.critic(), i),
    }
}

/// A plan of `state` held over every horizon step of `plan` (its length a
/// multiple of `state`'s): the hold ablation's plans and a non-finite
/// plan's stand-in.
fn hold_state(plan: &mut [f32], state: &[f32]) {
    for c in plan.chunks_exact_mut(state.len()) {
        c.copy_from_slice(state);
    }
}

/// Env `i`'s noise-free state: the first `OBS_DIM` entries of its critic row.
fn clean_state(critic: &[f32], i: usize) -> &[f32] {
    &critic[i * CRITIC_DIM..i * CRITIC_DIM + OBS_DIM]
}

impl VecTask for UnifiedTask {
    crate::env::task::delegate_to_env!(env);
    fn dims(&self) -> TaskDims {
        TaskDims {
            obs: OBS_DIM,
            critic: CRITIC_DIM,
            scan: self.scan_width(),
            action: crate::robot::NUM_JOINTS,
        }
    }
    fn scan(&self) -> &[f32] {
        &self.scan
    }
    fn final_scan(&self) -> &[f32] {
        &self.final_scan
    }
    fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }
    fn step(&mut self, actions: &[f32]) -> StepInfo {
        self.step_inner(actions)
    }
    fn reset_all(&mut self) {
        self.env.reset_all();
        self.start_all();
    }
    fn extra_metric_names(&self) -> Vec<&'static str> {
        METRICS.to_vec()
    }
    fn after_rollout(&mut self) -> Result<Vec<f64>, String> {
        let mean = self.disc.train_on(&self.real, &self.fake, self.cfg.seed);
        self.real.clear();
        self.fake.clear();
        let m = |v: f64, n: usize| if n > 0 { v / n as f64 } else { f64::NAN };
        let s = std::mem::take(&mut self.sums);
        Ok(vec![
            mean.loss,
            mean.grad_penalty,
            mean.d_real,
            mean.d_fake,
            mean.accuracy,
            m(s.style, s.styled),
            m(s.track[0], s.tracked),
            m(s.track[1], s.tracked),
            m(s.track[2], s.tracked),
            m(s.track[3], s.tracked),
            s.wm_time,
            s.plans as f64,
            s.nonfinite as f64,
        ])
    }
    fn state_tensors(&self) -> Vec<(String, Tensor)> {
        self.disc.named_tensors()
    }
    fn load_state_tensors(&mut self, get: &dyn Fn(&str) -> Option<Tensor>) -> Result<(), String> {
        self.disc.load_named(get)
    }
}
