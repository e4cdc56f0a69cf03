//! The ablation without goal-conditioned RL (the paper's "Ablation on
//! Goal-conditioned RL"): no learned policy. The world model predicts the
//! future states from the robot's last `K` states and the live scandots, and
//! the action slot of the predicted next state `ŝ_{t+1}` (the state's "last
//! action", [`LAST_ACTION`]: the action taken at `t`) is executed as is.
//!
//! With `replan_every: 1` (the paper's) every control step is a new
//! prediction; with `k > 1` the envs execute the actions of a plan's first `k`
//! states in order before the next prediction (cheaper, for sweeps). A
//! prediction that is not finite executes the default pose (action 0) and is
//! counted.
//!
//! `train no-gcrl` learns nothing: the baseline's only learned part is the
//! world model (`train world-model`, whose run holds the curves). It checks
//! the world model against the env and writes a controller checkpoint (the
//! config, no policy tensors) that `eval` and `benchmark` run like any method.
use std::path::Path;

use serde::{Deserialize, Serialize};
use tch::Device;

use crate::config::ConfigError;
use crate::env::obs::{LAST_ACTION, OBS_DIM, SCAN_DIM};
use crate::env::task::VecTask;
use crate::rl::checkpoint::{self, CheckpointMeta};
use crate::rl::config::{ExperimentConfig, TaskKind};
use crate::rl::RlError;
use crate::unified::plan::{History, Plan};
use crate::world_model::config::SamplingConfig;
use crate::world_model::sampler::Noise;
use crate::world_model::WorldModel;

/// The `no_gcrl:` section of a `task: no_gcrl` config.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoGcrlConfig {
    /// The world-model checkpoint whose predicted actions are executed.
    pub world_model: String,
    /// Sampler, DDIM steps and guidance of the predictions.
    #[serde(default)]
    pub sampling: SamplingConfig,
    /// A new prediction every `replan_every` control steps (1: the paper's).
    #[serde(default = "one")]
    pub replan_every: usize,
    /// Seed of the sampling noise.
    #[serde(default)]
    pub seed: u64,
}

fn one() -> usize {
    1
}

impl NoGcrlConfig {
    /// The `no_gcrl:` section of `cfg` (`task: no_gcrl`), parsed and checked.
    pub fn of(cfg: &ExperimentConfig) -> Result<NoGcrlConfig, ConfigError> {
        if cfg.task != TaskKind::NoGcrl {
            return Err(ConfigError::Invalid(
                "not a w/o-GCRL config: set `task: no_gcrl` and a `no_gcrl:` section".into(),
            ));
        }
        let c: NoGcrlConfig = crate::rl::config::parse_section(
            &cfg.no_gcrl,
            "no_gcrl",
            "task: no_gcrl needs a `no_gcrl:` section",
        )?;
        if c.world_model.trim().is_empty() {
            return Err(ConfigError::Invalid(
                "no_gcrl.world_model names no checkpoint".into(),
            ));
        }
        if c.replan_every == 0 {
            return Err(ConfigError::Invalid(
                "no_gcrl.replan_every must be at least 1".into(),
            ));
        }
        Ok(c)
    }
}

/// The world model as a controller of `n` envs.
pub struct WmController {
    wm: WorldModel,
    pub cfg: NoGcrlConfig,
    history: History,
    plan: Plan,
    noise: Noise,
    /// Predictions made, and those that were not finite.
    pub predictions: usize,
    pub nonfinite: usize,
}

impl WmController {
    /// The controller of `cfg.no_gcrl` for `n` envs of the G1 env.
    pub fn new(cfg: &ExperimentConfig, n: usize) -> Result<WmController, RlError> {
        let c = NoGcrlConfig::of(cfg)?;
        let wm = WorldModel::load(Path::new(&c.world_model), Device::Cpu)
            .map_err(|e| RlError::Invalid(format!("no_gcrl.world_model: {e}")))?;
        let (sd, cd) = wm.net.dims();
        if sd != OBS_DIM || cd != SCAN_DIM {
            return Err(RlError::Invalid(format!(
                "no_gcrl.world_model {}: states of {sd} and scandots of {cd}, the G1 env has {OBS_DIM} and {SCAN_DIM}",
                c.world_model
            )));
        }
        let (k, h) = (wm.history(), wm.horizon());
        if c.replan_every > h {
            return Err(RlError::Invalid(format!(
                "no_gcrl.replan_every {} is more than the world model's horizon {h}",
                c.replan_every
            )));
        }
        Ok(WmController {
            history: History::new(n, k, OBS_DIM),
            plan: Plan::new(n, h, OBS_DIM, c.replan_every),
            noise: Noise::new(c.seed),
            predictions: 0,
            nonfinite: 0,
            wm,
            cfg: c,
        })
    }

    /// Every env starts from its current state: histories of `s_0`, no plans.
    pub fn reset_all(&mut self, task: &dyn VecTask) {
        for i in 0..task.n_envs() {
            self.reset_env(i, task.obs());
        }
    }

    /// Env `i` starts a new episode from its current state in `obs` (`[n, 98]`).
    pub fn reset_env(&mut self, i: usize, obs: &[f32]) {
        self.history.reset(i, &obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
        self.plan.invalidate(i);
    }

    /// Env `i`'s predicted next state `ŝ_{t+1}` (after [`WmController::actions`]).
    pub fn predicted_next(&self, i: usize) -> &[f32] {
        self.plan.next(i)
    }

    /// One batched world-model call for the envs whose plan is due.
    fn predict(&mut self, task: &dyn VecTask) {
        let due: Vec<usize> = self.plan.due().collect();
        if due.is_empty() {
            return;
        }
        let (h, d) = (self.plan.horizon(), OBS_DIM);
        let pred = crate::unified::plan::predict_due(
            &self.wm,
            &self.history,
            task.scan(),
            &due,
            &self.cfg.sampling,
            &mut self.noise,
        );
        for (j, &i) in due.iter().enumerate() {
            self.plan.set(i, &pred[j * h * d..(j + 1) * h * d]);
        }
        self.predictions += due.len();
    }

    /// The actions of this control step: the action slot of each env's
    /// predicted next state (a new prediction where one is due).
    pub fn actions(&mut self, task: &dyn VecTask) -> Vec<f32> {
        self.predict(task);
        let n = task.n_envs();
        let a = LAST_ACTION.len();
        let mut out = vec![0.0f32; n * a];
        for i in 0..n {
            let next = &self.plan.next(i)[LAST_ACTION];
            if next.iter().all(|v| v.is_finite()) {
                out[i * a..(i + 1) * a].copy_from_slice(next);
            } else {
                self.nonfinite += 1;
            }
        }
        out
    }

    /// After the env step: the plans move on by one state, each history takes
    /// the new state (an env whose episode ended starts over from its `s_0`).
    pub fn after_step(&mut self, task: &dyn VecTask) {
        self.plan.advance();
        let obs = task.obs();
        for (i, o) in task.outcomes().iter().enumerate() {
            if o.episode_done {
                self.reset_env(i, obs);
            } else {
                self.history.push(i, &obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
            }
        }
    }

    /// One control step of `task` under the controller.
    pub fn step(&mut self, task: &mut dyn VecTask) -> crate::env::StepInfo {
        let actions = self.actions(&*task);
        let info = task.step(&actions);
        self.after_step(&*task);
        info
    }
}

/// `train no-gcrl`: check that `cfg`'s world model drives its env (the
/// controller is built on one env) and write the controller checkpoint into
/// `run_dir/checkpoints/latest.pt`, with `config.yaml` and a log line. Nothing
/// is learned; the checkpoint records the world model's training env-steps
/// (the samples it saw) as 0: its own run has the curves.
pub fn train(cfg: &ExperimentConfig, run_dir: &Path) -> Result<CheckpointMeta, RlError> {
    let c = NoGcrlConfig::of(cfg)?;
    let mut one = cfg.env.clone();
    one.n_envs = 1;
    one.threads = 1;
    let env = crate::env::VecEnv::new(&one)?;
    let mut ctl = WmController::new(cfg, 1)?;
    ctl.reset_all(&env);
    let a = ctl.actions(&env);
    if a.len() != crate::robot::NUM_JOINTS {
        return Err(RlError::Invalid(format!(
            "the controller gave {} actions for one env",
            a.len()
        )));
    }
    let mut run = crate::run::RunDir::create(run_dir, cfg, &["iteration"])?;
    // the record of the one env the controller was built on
    let meta = CheckpointMeta::record(cfg, &env, None, (0, 0, 0.0), Default::default())?;
    let path = crate::run::latest_checkpoint(run_dir);
    checkpoint::save_controller(&path, &meta)?;
    run.log(&format!(
        "w/o GCRL: the world model {} ({} sampling, guidance {}, a new prediction every {} control steps) executes the action slot of its predicted next state; nothing to learn here. Controller checkpoint {}",
        c.world_model,
        format!("{:?}", c.sampling.sampler).to_lowercase(),
        c.sampling.guidance,
        c.replan_every,
        path.display()
    ))?;
    Ok(meta)
}
