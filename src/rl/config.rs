//! Serde structs of the training sections: the actor-critic (`policy`), PPO
//! (`ppo`), the run (`train`) and lane evaluation (`eval`). Defaults are the
//! paper's values (appendix, "Details of Specialized Policy Learning"). With
//! the `env` section ([`crate::env::config`]) they make an experiment file,
//! [`ExperimentConfig`], loaded by [`load`].
use serde::{Deserialize, Serialize};

use std::path::Path;

use crate::config::{parse_inheriting, read, ConfigError};
use crate::env::config::EnvConfig;

/// A whole experiment file. Sections other than `env` have defaults (the paper's).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// What the trainer steps: the G1 locomotion env (default) or the cart-pole.
    #[serde(default)]
    pub task: TaskKind,
    pub env: EnvConfig,
    #[serde(default)]
    pub policy: PolicyConfig,
    #[serde(default)]
    pub ppo: PpoConfig,
    #[serde(default)]
    pub train: TrainConfig,
    #[serde(default)]
    pub eval: EvalConfig,
    /// The unified task's own section (`task: unified`): the world model, the
    /// re-planning, the tracking and style rewards. Kept here as YAML so that
    /// it travels with the config into run directories and checkpoints; its
    /// layer (`unified::config`, above the world model) parses and validates it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unified: Option<serde_yaml::Value>,
    /// The distillation baseline's section (`train dagger`, a `task: g1`
    /// student): its teachers, β schedule and aggregated dataset; parsed by
    /// `baselines::dagger`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dagger: Option<serde_yaml::Value>,
    /// The w/o-GCRL baseline's section (`task: no_gcrl`): the world model
    /// whose predicted actions are executed; parsed by `baselines::no_gcrl`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_gcrl: Option<serde_yaml::Value>,
    /// The w/o-diffusion baseline's section (`task: no_diffusion`): the expert
    /// dataset and the standard AMP discriminator; parsed by
    /// `baselines::no_diffusion`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_diffusion: Option<serde_yaml::Value>,
}

/// The environment a config trains on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskKind {
    /// The G1 on a plane or a terrain map (`env` configures it).
    #[default]
    G1,
    /// MuJoCo cart-pole balancing (`env.n_envs`, `env.seed` only): tests PPO.
    Cartpole,
    /// The unified policy (the paper's stage 3): the G1 env with the world
    /// model's plan as the policy's future input and tracking and style
    /// rewards (`unified:`); trained by `train unified`.
    Unified,
    /// The ablation without goal-conditioned RL: no policy, the world model's
    /// predicted next state holds the action executed (`no_gcrl:`); written
    /// by `train no-gcrl`, run by `eval` and `benchmark`.
    NoGcrl,
    /// The ablation without the diffusion world model: the G1 env with a
    /// standard AMP discriminator whose real transitions come from the expert
    /// dataset (`no_diffusion:`); trained by `train no-diffusion`.
    NoDiffusion,
}

impl ExperimentConfig {
    /// Validate every section.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.env.validate()?;
        self.policy.validate()?;
        self.ppo.validate()?;
        self.train.validate()?;
        if self.unified.is_some() != (self.task == TaskKind::Unified) {
            return Err(ConfigError::Invalid(
                "a `unified:` section goes with `task: unified`, and only with it".into(),
            ));
        }
        if self.no_gcrl.is_some() != (self.task == TaskKind::NoGcrl) {
            return Err(ConfigError::Invalid(
                "a `no_gcrl:` section goes with `task: no_gcrl`, and only with it".into(),
            ));
        }
        if self.no_diffusion.is_some() != (self.task == TaskKind::NoDiffusion) {
            return Err(ConfigError::Invalid(
                "a `no_diffusion:` section goes with `task: no_diffusion`, and only with it".into(),
            ));
        }
        if self.dagger.is_some() && self.task != TaskKind::G1 {
            return Err(ConfigError::Invalid(
                "a `dagger:` section trains a G1 student: it goes with `task: g1`".into(),
            ));
        }
        self.eval.validate()
    }
}

/// A task's own section of an experiment file (`unified:`, `dagger:`, ...),
/// kept as YAML in [`ExperimentConfig`] and parsed by its layer: `value`
/// deserialized as `T`, errors naming the section; a missing one is the error
/// `missing` (what the section must say).
pub fn parse_section<T: serde::de::DeserializeOwned>(
    value: &Option<serde_yaml::Value>,
    name: &str,
    missing: &str,
) -> Result<T, ConfigError> {
    let value = value
        .clone()
        .ok_or_else(|| ConfigError::Invalid(missing.to_string()))?;
    serde_yaml::from_value(value).map_err(|e| ConfigError::Parse {
        path: name.into(),
        message: e.to_string(),
    })
}

/// Read `path`, apply `--set key.path=value` overrides, deserialize, validate.
pub fn load(path: &Path, overrides: &[String]) -> Result<ExperimentConfig, ConfigError> {
    from_str(&read(path)?, &path.display().to_string(), overrides)
}

/// Like [`load`], from a string; `label` names it in messages.
pub fn from_str(
    text: &str,
    label: &str,
    overrides: &[String],
) -> Result<ExperimentConfig, ConfigError> {
    let cfg: ExperimentConfig = parse_inheriting(text, label, overrides)?;
    cfg.validate()?;
    Ok(cfg)
}

/// Actor-critic structure: `a_t = F(E_hist(o_hist), E_scan(scan), o_t)` where
/// `o_t` (98 floats) holds proprioception, command and last action.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    /// Hidden sizes of the actor backbone F.
    pub actor_hidden: Vec<i64>,
    /// Hidden sizes of the critic.
    pub critic_hidden: Vec<i64>,
    pub activation: Activation,
    /// Initial action standard deviation.
    pub init_std: f64,
    /// Lower bound of the action standard deviation.
    pub min_std: f64,
    pub history: HistoryConfig,
    pub scan_encoder: ScanEncoderConfig,
    /// The privileged-information estimator (none unless given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimator: Option<EstimatorConfig>,
}

/// Extreme Parkour's privileged-information estimator, which the paper's
/// specialists use (appendix "Scenario Specialized Policy"): an MLP from the
/// actor's rows (the history and the current state) to the base linear
/// velocity the critic sees (the first [`ESTIMATE_DIM`] floats of the
/// privileged block), trained by regression beside PPO
/// (`loss_coef` x its mean squared error, in normalized units). Its estimate,
/// detached, enters the actor's first layer between the scan latent and `o_t`,
/// so that PPO's gradient does not move it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorConfig {
    /// Hidden sizes of the MLP (its output is [`ESTIMATE_DIM`] floats).
    pub dims: Vec<i64>,
    /// Weight of the regression loss in the PPO loss.
    pub loss_coef: f64,
    /// The estimator's own fixed Adam rate: PPO's adaptive rate (often
    /// 2e-5 in a fine-tune) does not steer it, and its gradient is left out
    /// of PPO's global clipping.
    pub learning_rate: f64,
}

/// Floats the estimator predicts: the base linear velocity (pelvis frame).
pub const ESTIMATE_DIM: usize = 3;

impl Default for EstimatorConfig {
    fn default() -> Self {
        EstimatorConfig {
            dims: vec![128, 64],
            loss_coef: 1.0,
            learning_rate: 5e-4,
        }
    }
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            actor_hidden: vec![512, 256, 128],
            critic_hidden: vec![512, 256, 128],
            activation: Activation::Elu,
            init_std: 1.0,
            min_std: 0.2,
            history: HistoryConfig::default(),
            scan_encoder: ScanEncoderConfig::default(),
            estimator: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    Elu,
    Relu,
    Tanh,
}

/// The history encoder `E_hist` over the last `length` actor states (before `o_t`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HistoryConfig {
    pub kind: HistoryKind,
    /// Number of past states (control steps) the encoder sees.
    pub length: usize,
    /// GRU hidden size (paper: 512, one layer).
    pub gru_hidden: i64,
    /// MLP encoder sizes; the last is the latent size.
    pub mlp_dims: Vec<i64>,
}

impl Default for HistoryConfig {
    fn default() -> Self {
        HistoryConfig {
            kind: HistoryKind::Gru,
            length: 5,
            gru_hidden: 512,
            mlp_dims: vec![256, 64],
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HistoryKind {
    /// No history encoder.
    None,
    /// MLP over the stacked past states.
    Mlp,
    /// GRU over the past states, oldest first; its last hidden state is the latent.
    Gru,
}

/// The scandot encoder `E_scan` (an MLP over the 187 heights), which is also
/// the unified policy's future encoder `E_future` (over the plan's states).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanEncoderConfig {
    pub enabled: bool,
    /// MLP sizes (`kind: mlp`); the last is the latent size.
    pub dims: Vec<i64>,
    pub kind: ScanEncoderKind,
    /// `kind: gru`: floats per step of the sequence (the input is read as
    /// `scan / step` steps of `step` floats, in order): 98 for the unified
    /// policy's plan of states, 17 for the scandots' rows.
    pub step: usize,
    /// `kind: gru`: hidden size, the latent size.
    pub gru_hidden: i64,
}

impl Default for ScanEncoderConfig {
    fn default() -> Self {
        ScanEncoderConfig {
            enabled: true,
            dims: vec![128, 64, 32],
            kind: ScanEncoderKind::Mlp,
            step: 0,
            gru_hidden: 64,
        }
    }
}

impl ScanEncoderConfig {
    /// The latent size the encoder gives the actor and the critic.
    pub fn latent(&self) -> i64 {
        match self.kind {
            ScanEncoderKind::Mlp => *self.dims.last().unwrap_or(&0),
            ScanEncoderKind::Gru => self.gru_hidden,
        }
    }

    /// Whether it reads an input of `scan` floats: a GRU's step must divide it.
    pub fn check_input(&self, scan: usize) -> Result<(), ConfigError> {
        if self.enabled
            && scan > 0
            && self.kind == ScanEncoderKind::Gru
            && !scan.is_multiple_of(self.step)
        {
            return Err(ConfigError::Invalid(format!(
                "policy.scan_encoder.step {} does not divide the task's scan input of {scan} floats \
                 (the unified policy's plan: future_states x 98; scandots: 11 rows of 17)",
                self.step
            )));
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanEncoderKind {
    /// MLP over the whole input.
    Mlp,
    /// GRU over the input's steps (the paper's RNN future encoder); its last
    /// hidden state is the latent.
    Gru,
}

/// PPO hyperparameters (paper table; rsl_rl's names).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    pub clip_param: f64,
    pub gamma: f64,
    pub lam: f64,
    pub entropy_coef: f64,
    pub value_loss_coef: f64,
    pub max_grad_norm: f64,
    pub learning_rate: f64,
    /// Environment steps per env per iteration.
    pub num_steps: usize,
    pub num_epochs: usize,
    pub num_minibatches: usize,
    /// Clip the value update around the rollout's values (rsl_rl's use_clipped_value_loss).
    pub clip_value: bool,
    pub normalize_advantage: bool,
    /// `fixed`, `adaptive` (rsl_rl: lr / 1.5 when KL > 2 desired, x 1.5 when <
    /// desired / 2, after every minibatch) or `adaptive_iteration` (the same once
    /// per iteration).
    pub schedule: LrSchedule,
    pub desired_kl: f64,
    /// Normalize actor and critic inputs with running statistics.
    pub normalize_obs: bool,
    /// Left/right symmetry augmentation: every update batch also holds its
    /// mirror image (observations, actions, old means), with the same advantages
    /// and returns (rsl_rl's data augmentation; G1 tasks only).
    pub symmetry: bool,
    /// With `symmetry`: weight of rsl_rl's mirror loss, the mean squared
    /// difference between the policy's mean on a mirrored observation and the
    /// mirror of its (detached) mean on the original. 0 leaves it out.
    #[serde(default)]
    pub mirror_loss_coef: f64,
    /// With `symmetry`: the old log-probability of a mirrored sample
    /// (`behavior`: the original's, rsl_rl's; `policy`: the old policy's own on
    /// the mirrored state and action).
    #[serde(default)]
    pub symmetry_ratio: SymmetryRatio,
    /// Dual-clip PPO's bound `c` (Ye et al. 2020; 3 in their paper): a sample
    /// with a negative advantage adds at most `-c A` to the loss, however large
    /// its ratio, and log-ratios are clamped to +-20 before `exp`. None (the
    /// default): plain PPO. A mirrored sample far in the tail of the current
    /// policy (`symmetry_ratio: policy`) can reach ratios of e^30 within one
    /// update; run uneven4 logged a gradient norm of 46 685 and then a NaN loss.
    #[serde(default)]
    pub dual_clip: Option<f64>,
}

/// How the mirrored half of a symmetry-augmented batch enters PPO's ratio.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SymmetryRatio {
    /// The original sample's old log-probability (rsl_rl: the behaviour
    /// policy of a mirrored sample is the mirror of the old policy).
    #[default]
    Behavior,
    /// The old policy's log-probability of the mirrored action in the mirrored
    /// state: each mirrored sample starts the update at ratio 1.
    Policy,
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            clip_param: 0.2,
            gamma: 0.99,
            lam: 0.95,
            entropy_coef: 0.01,
            value_loss_coef: 1.0,
            max_grad_norm: 1.0,
            learning_rate: 2e-4,
            num_steps: 24,
            num_epochs: 5,
            num_minibatches: 4,
            clip_value: true,
            normalize_advantage: true,
            schedule: LrSchedule::Fixed,
            desired_kl: 0.01,
            normalize_obs: true,
            symmetry: false,
            mirror_loss_coef: 0.0,
            symmetry_ratio: SymmetryRatio::Behavior,
            dual_clip: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LrSchedule {
    Fixed,
    /// rsl_rl's rule, after every minibatch.
    Adaptive,
    /// The same rule once per iteration, on the update's mean KL: steadier on
    /// small batches, where per-minibatch KL estimates are noisy.
    #[serde(rename = "adaptive_iteration")]
    AdaptiveIteration,
}

/// The training run.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// PPO iterations (each `num_steps` x `n_envs` env-steps).
    pub iterations: usize,
    /// Write a resume checkpoint every this many iterations (0 = only at the end).
    pub save_interval: usize,
    /// Keep a numbered copy of the checkpoint every this many iterations (0 = none).
    pub keep_interval: usize,
    /// Seed of the trainer (network init, action noise, minibatch order).
    pub seed: u64,
    /// libtorch intra-op threads.
    pub torch_threads: i64,
    /// Start from this checkpoint's networks and normalizer (a specialist from the walker).
    pub init_checkpoint: Option<String>,
    /// With `init_checkpoint`: set the action std to this instead of the
    /// checkpoint's, so that a fine-tune explores again (a gait to change).
    pub init_std: Option<f64>,
    /// Stop early when the mean episode return stays NaN or the loss is NaN.
    pub stop_on_nan: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            iterations: 1000,
            save_interval: 50,
            keep_interval: 0,
            seed: 1,
            torch_threads: 1,
            init_checkpoint: None,
            init_std: None,
            stop_on_nan: true,
        }
    }
}

/// Lane evaluation (`dreampolicy eval`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Commanded forward speed drawn per episode from `[lo, hi]` (m/s).
    pub lin_vel_x: [f64; 2],
    /// Lane length (m); the paper's is 10.
    pub lane_length: f64,
    /// Time limit per episode (s).
    pub time_limit_s: f64,
    /// Terrain level of the lanes.
    pub level: usize,
    /// Envs run in parallel.
    pub n_envs: i64,
    /// Different lanes (terrain seeds) the episodes of a non-flat evaluation
    /// are spread over (at most one per episode). The default, 1000, gives
    /// every walk its own lane: walks on one lane share its ground, so with 10
    /// lanes the rate of 100 walks swung by up to 0.16 between seeds
    /// (checkpoints stored before 2026-12-05 say 10: `--set eval.lanes=1000`).
    pub lanes: usize,
    /// The terrain table lanes are drawn from, at `level` of its levels: by
    /// default the paper's (whatever curriculum the policy trained on), so that
    /// every policy is measured on the same lanes.
    pub terrain: crate::terrain::TerrainConfig,
    /// How the robot touches the lanes' heightfield: null = the scene's own
    /// (`--full-collision`: the project's default, `surface`; otherwise the
    /// checkpoint's `env.sim.hfield_contacts`); `surface_planes` gives the
    /// contacts every heightfield figure before 2026-12-04 was measured with.
    pub hfield_contacts: Option<crate::env::config::HfieldContacts>,
    /// Act on actions sampled from the policy's Gaussian, as training does,
    /// instead of its mean (false): what the exploration noise costs on the
    /// same lanes (a generator of its own, seeded per lane from the evaluation's
    /// seed).
    pub sample_actions: bool,
}

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig {
            lin_vel_x: [0.5, 1.0],
            lane_length: 10.0,
            time_limit_s: 30.0,
            level: 5,
            n_envs: 20,
            lanes: 1000,
            terrain: Default::default(),
            hfield_contacts: None,
            sample_actions: false,
        }
    }
}

impl PolicyConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        for (what, dims) in [
            ("policy.actor_hidden", &self.actor_hidden),
            ("policy.critic_hidden", &self.critic_hidden),
            ("policy.history.mlp_dims", &self.history.mlp_dims),
            ("policy.scan_encoder.dims", &self.scan_encoder.dims),
            (
                "policy.estimator.dims",
                self.estimator
                    .as_ref()
                    .map_or(&self.actor_hidden, |e| &e.dims),
            ),
        ] {
            if dims.is_empty() || dims.iter().any(|&d| d <= 0) {
                return bad(format!(
                    "{what} must be a non-empty list of positive sizes, got {dims:?}"
                ));
            }
        }
        if self.history.kind != HistoryKind::None && self.history.length == 0 {
            return bad("policy.history.length must be >= 1 when a history encoder is used".into());
        }
        if self.history.gru_hidden <= 0 {
            return bad("policy.history.gru_hidden must be positive".into());
        }
        let se = &self.scan_encoder;
        if se.kind == ScanEncoderKind::Gru && (se.step == 0 || se.gru_hidden <= 0) {
            return bad(format!(
                "policy.scan_encoder.kind gru needs a positive step (floats per step) and gru_hidden, got {} and {}",
                se.step, se.gru_hidden
            ));
        }
        if let Some(e) = &self.estimator {
            if !(e.loss_coef.is_finite() && e.loss_coef >= 0.0) {
                return bad(format!(
                    "policy.estimator.loss_coef must be finite and >= 0, got {}",
                    e.loss_coef
                ));
            }
            if !(e.learning_rate.is_finite() && e.learning_rate > 0.0) {
                return bad(format!(
                    "policy.estimator.learning_rate must be positive, got {}",
                    e.learning_rate
                ));
            }
        }
        if !(self.init_std > 0.0 && self.min_std > 0.0 && self.min_std <= self.init_std) {
            return bad(format!(
                "policy.init_std and policy.min_std must be positive with min_std <= init_std, got {} and {}",
                self.init_std, self.min_std
            ));
        }
        Ok(())
    }
}

impl PpoConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        if self.num_steps == 0 || self.num_epochs == 0 || self.num_minibatches == 0 {
            return bad(
                "ppo.num_steps, ppo.num_epochs and ppo.num_minibatches must be >= 1".into(),
            );
        }
        if !(0.0..=1.0).contains(&self.gamma) || !(0.0..=1.0).contains(&self.lam) {
            return bad(format!(
                "ppo.gamma and ppo.lam must be in [0, 1], got {} and {}",
                self.gamma, self.lam
            ));
        }
        if !(self.learning_rate > 0.0 && self.clip_param > 0.0 && self.max_grad_norm > 0.0) {
            return bad(
                "ppo.learning_rate, ppo.clip_param and ppo.max_grad_norm must be positive".into(),
            );
        }
        if self.desired_kl.is_nan() || self.desired_kl <= 0.0 {
            return bad("ppo.desired_kl must be positive".into());
        }
        if let Some(c) = self.dual_clip {
            if !(c.is_finite() && c > 1.0) {
                return Err(ConfigError::Invalid(format!(
                    "ppo.dual_clip must be a number above 1 (dual-clip PPO's c, e.g. 3), got {c}"
                )));
            }
        }
        if self.mirror_loss_coef.is_nan()
            || self.mirror_loss_coef < 0.0
            || (self.mirror_loss_coef > 0.0 && !self.symmetry)
        {
            return bad(format!(
                "ppo.mirror_loss_coef must be >= 0 and needs ppo.symmetry: true, got {}",
                self.mirror_loss_coef
            ));
        }
        Ok(())
    }
}

impl TrainConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.torch_threads <= 0 {
            return Err(ConfigError::Invalid(format!(
                "train.torch_threads must be positive, got {}",
                self.torch_threads
            )));
        }
        if let Some(std) = self.init_std {
            if !(std.is_finite() && std > 0.0) || self.init_checkpoint.is_none() {
                return Err(ConfigError::Invalid(format!(
                    "train.init_std must be positive and needs train.init_checkpoint, got {std}"
                )));
            }
        }
        Ok(())
    }
}

impl EvalConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        let v = self.lin_vel_x;
        if v[0].is_nan() || v[1].is_nan() || v[0] > v[1] {
            return Err(ConfigError::Invalid(format!(
                "eval.lin_vel_x must be [lo, hi] with lo <= hi, got {v:?}"
            )));
        }
        if !(self.lane_length > 0.0 && self.time_limit_s > 0.0) || self.n_envs <= 0 {
            return Err(ConfigError::Invalid(
                "eval.lane_length, eval.time_limit_s and eval.n_envs must be positive".into(),
            ));
        }
        if self.lanes == 0 {
            return Err(ConfigError::Invalid("eval.lanes must be at least 1".into()));
        }
        self.terrain
            .validate()
            .map_err(|e| ConfigError::Invalid(format!("eval.terrain: {e}")))?;
        if self.level > self.terrain.max_level() {
            return Err(ConfigError::Invalid(format!(
                "eval.level {} is above eval.terrain's top level {}",
                self.level,
                self.terrain.max_level()
            )));
        }
        Ok(())
    }
}
