//! The world-model config file kind (`configs/world_model/*.yaml`): the dataset
//! (`data`), the DiT denoiser (`model`), the diffusion process (`diffusion`),
//! inference sampling (`sampling`) and the scheduled-sampling trainer (`train`).
//! Defaults are the paper's values where it gives them (appendix, "Details of
//! Autoregressive Diffusion World Model"); the rest are marked as ours.
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::config::{parse_inheriting, read, ConfigError};

/// A whole world-model file. Only `data.path` is required.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldModelConfig {
    pub data: DataSection,
    #[serde(default)]
    pub model: ModelConfig,
    #[serde(default)]
    pub diffusion: DiffusionConfig,
    /// How predictions are sampled at inference and in validation rollouts.
    #[serde(default)]
    pub sampling: SamplingConfig,
    #[serde(default)]
    pub train: WmTrainConfig,
}

/// The expert dataset and how windows are drawn from it.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataSection {
    /// A dataset directory of MCAP shards (e.g. `runs/dataset`); its `stats.json`
    /// is used when present, otherwise statistics are computed from the train split.
    pub path: String,
    /// Fraction of episodes held out for validation (split by episode).
    #[serde(default = "d_val_fraction")]
    pub val_fraction: f64,
    /// Seed of the split hash.
    #[serde(default)]
    pub split_seed: u64,
    /// Bounded shuffle buffer (windows).
    #[serde(default = "d_shuffle")]
    pub shuffle: usize,
    /// Train on this fraction of the train episodes (hash-chosen and nested:
    /// a smaller fraction's episodes are in every larger one's; the
    /// validation episodes do not change): the scaling analysis's dataset size.
    #[serde(default = "d_one")]
    pub train_fraction: f64,
    /// Train on these terrain kinds' episodes only (default: all); validation
    /// keeps every kind: the scaling analysis's diversity.
    #[serde(default)]
    pub kinds: Vec<String>,
}

fn d_one() -> f64 {
    1.0
}

impl DataSection {
    /// The train/validation split of this section.
    pub fn split(&self) -> Result<crate::data::SplitSpec, crate::data::DataError> {
        crate::data::SplitSpec::new(self.val_fraction, self.split_seed)?
            .with_train_fraction(self.train_fraction)
    }

    /// The kinds of `kinds` (empty: every kind).
    pub fn kinds(&self) -> Result<Vec<crate::terrain::TerrainKind>, ConfigError> {
        self.kinds
            .iter()
            .map(|k| {
                crate::terrain::TerrainKind::from_name(k)
                    .map_err(|e| ConfigError::Invalid(format!("data.kinds: {e}")))
            })
            .collect()
    }
}

fn d_val_fraction() -> f64 {
    0.05
}
fn d_shuffle() -> usize {
    4096
}

/// The DiT denoiser `G(x^n, x_hist, n, y)`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelConfig {
    /// History frames `K` (clean, the last one is the current state).
    pub history: usize,
    /// Predicted frames `H` per call.
    pub horizon: usize,
    /// DiT blocks (paper: 8).
    pub layers: usize,
    /// Token width (paper: 512).
    pub hidden: i64,
    /// Attention heads (ours; `hidden` must be a multiple).
    pub heads: i64,
    /// MLP width over `hidden`.
    pub mlp_ratio: i64,
    /// Hidden sizes of the terrain MLP over the scandots (ours).
    pub terrain_hidden: Vec<i64>,
    /// Terrain embedding `y_t` width (paper: 256).
    pub terrain_dim: i64,
    /// Width of the sinusoidal diffusion-step features fed to the step MLP.
    pub step_features: i64,
    /// Add a linear map of the flattened history to the predicted `x0` (ours,
    /// zero-initialized): the linear part of the dynamics is learned in a few
    /// hundred steps, and the transformer models what is left.
    pub history_skip: bool,
    /// Start the history skip at the least-squares fit of the first horizon
    /// chunk on this many train sequences (ridge 1e-3, in normalized units),
    /// instead of zero, at a fresh start: the first planned states begin as
    /// close as a linear map of the history gets (0.20 normalized RMSE at the
    /// first state of the turning dataset, against the zero-started model's
    /// 0.32 after training), and the transformer learns the residual. 0: zero.
    pub history_skip_fit: usize,
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            history: 4,
            horizon: 8,
            layers: 8,
            hidden: 512,
            heads: 8,
            mlp_ratio: 4,
            terrain_hidden: vec![256],
            terrain_dim: 256,
            step_features: 256,
            history_skip: true,
            history_skip_fit: 0,
        }
    }
}

/// Variance schedules of the forward process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScheduleKind {
    /// `beta_n` linear from `beta_start` to `beta_end` (Ho et al.).
    Linear,
    /// `alpha_bar` a squared cosine (Nichol & Dhariwal), betas clipped at 0.999.
    Cosine,
}

/// The forward process `q(x^n | x^{n-1}) = N(sqrt(alpha_n) x^{n-1}, (1 - alpha_n) I)`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiffusionConfig {
    /// `N` (the paper does not give it; ours).
    pub steps: usize,
    pub schedule: ScheduleKind,
    /// Linear schedule only.
    pub beta_start: f64,
    pub beta_end: f64,
    /// Probability that the terrain embedding is replaced by the learned null
    /// embedding in training (classifier-free guidance; paper: 0.1).
    pub terrain_drop: f64,
}

impl Default for DiffusionConfig {
    fn default() -> Self {
        DiffusionConfig {
            steps: 50,
            schedule: ScheduleKind::Cosine,
            beta_start: 1e-4,
            beta_end: 0.02,
            terrain_drop: 0.1,
        }
    }
}

/// Reverse-process samplers (both from the x0 prediction).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Ancestral sampling over all `N` steps (the paper's).
    Ddpm,
    /// Deterministic DDIM (eta = 0) over `ddim_steps` evenly spaced steps.
    Ddim,
}

/// A sampler and its guidance.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SamplingConfig {
    pub sampler: SamplerKind,
    /// DDIM steps `k` (1..=N).
    pub ddim_steps: usize,
    /// Classifier-free guidance scale `omega` (0 = unconditional, 1 =
    /// conditional; paper: 5).
    pub guidance: f64,
}

impl Default for SamplingConfig {
    fn default() -> Self {
        SamplingConfig {
            sampler: SamplerKind::Ddpm,
            ddim_steps: 10,
            guidance: 5.0,
        }
    }
}

/// The scheduled-sampling trainer (the paper's Algorithm "Scheduled training").
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WmTrainConfig {
    /// Gradient steps (the paper's iterations; 300K). A multiple of `rollout_windows`.
    pub iterations: usize,
    /// Sequences per step (paper: 1024).
    pub batch_size: usize,
    pub learning_rate: f64,
    /// Global gradient-norm clip (0 = none).
    pub max_grad_norm: f64,
    /// EMA of the weights used for sampling and validation (per step; warmed
    /// up: the decay after Adam step `s` is `min(ema_decay, (1 + s) / (10 + s))`).
    pub ema_decay: f64,
    /// `T`: consecutive windows per drawn sequence, one step each; the history of
    /// window `t + 1` may come from the model's own sample of window `t`
    /// (paper: at most 4).
    pub rollout_windows: usize,
    /// `I_1`: steps of the fully supervised phase (rollout probability 0).
    pub supervised_iterations: usize,
    /// `I_2`: steps of the scheduled phase (probability rising linearly to 1).
    pub scheduled_iterations: usize,
    /// The sampler `S` that produces rollout histories in training (live weights).
    pub rollout_sampling: SamplingConfig,
    /// A metrics row every this many steps.
    pub log_interval: usize,
    /// Validation (EMA x0 loss and autoregressive rollout error) every this many
    /// steps (0 = never).
    pub eval_interval: usize,
    /// Validation sequences (fixed: a seeded uniform sample of the whole
    /// validation split).
    pub val_sequences: usize,
    /// Resume checkpoint every this many steps (0 = only at the end).
    pub save_interval: usize,
    /// Numbered checkpoint copy every this many steps (0 = none).
    pub keep_interval: usize,
    pub seed: u64,
    pub torch_threads: i64,
}

impl Default for WmTrainConfig {
    fn default() -> Self {
        WmTrainConfig {
            iterations: 300_000,
            batch_size: 1024,
            learning_rate: 1e-4,
            max_grad_norm: 1.0,
            ema_decay: 0.999,
            rollout_windows: 4,
            supervised_iterations: 100_000,
            scheduled_iterations: 100_000,
            rollout_sampling: SamplingConfig::default(),
            log_interval: 100,
            eval_interval: 5_000,
            val_sequences: 1024,
            save_interval: 5_000,
            keep_interval: 50_000,
            seed: 1,
            torch_threads: 1,
        }
    }
}

/// The most consecutive rollouts per sequence the paper allows.
pub const MAX_ROLLOUT_WINDOWS: usize = 4;

impl WorldModelConfig {
    /// Check what serde cannot; every message names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        let (m, d, t) = (&self.model, &self.diffusion, &self.train);
        if self.data.path.is_empty() {
            return bad("data.path must name a dataset directory".into());
        }
        if !(self.data.train_fraction > 0.0 && self.data.train_fraction <= 1.0) {
            return bad(format!(
                "data.train_fraction must be in (0, 1], got {}",
                self.data.train_fraction
            ));
        }
        self.data.kinds()?;
        if !(0.0..1.0).contains(&self.data.val_fraction) {
            return bad(format!(
                "data.val_fraction must be in [0, 1), got {}",
                self.data.val_fraction
            ));
        }
        if m.history == 0 || m.horizon == 0 {
            return bad(format!(
                "model.history and model.horizon must be >= 1, got {} and {}",
                m.history, m.horizon
            ));
        }
        if m.layers == 0 || m.hidden <= 0 || m.heads <= 0 || m.mlp_ratio <= 0 {
            return bad(
                "model.layers, model.hidden, model.heads and model.mlp_ratio must be >= 1".into(),
            );
        }
        if m.hidden % m.heads != 0 {
            return bad(format!(
                "model.hidden ({}) must be a multiple of model.heads ({})",
                m.hidden, m.heads
            ));
        }
        if m.terrain_dim <= 0 || m.terrain_hidden.iter().any(|&h| h <= 0) {
            return bad("model.terrain_dim and model.terrain_hidden must be positive".into());
        }
        if m.step_features < 2 || m.step_features % 2 != 0 {
            return bad(format!(
                "model.step_features must be an even number >= 2, got {}",
                m.step_features
            ));
        }
        if d.steps == 0 {
            return bad("diffusion.steps must be >= 1".into());
        }
        if d.schedule == ScheduleKind::Linear
            && !(0.0 < d.beta_start && d.beta_start <= d.beta_end && d.beta_end < 1.0)
        {
            return bad(format!(
                "diffusion.beta_start and diffusion.beta_end must satisfy 0 < start <= end < 1, got {} and {}",
                d.beta_start, d.beta_end
            ));
        }
        if !(0.0..=1.0).contains(&d.terrain_drop) {
            return bad(format!(
                "diffusion.terrain_drop must be in [0, 1], got {}",
                d.terrain_drop
            ));
        }
        self.sampling.validate("sampling", d.steps)?;
        t.rollout_sampling
            .validate("train.rollout_sampling", d.steps)?;
        if t.batch_size == 0 || t.iterations == 0 {
            return bad("train.batch_size and train.iterations must be >= 1".into());
        }
        if !(1..=MAX_ROLLOUT_WINDOWS).contains(&t.rollout_windows) {
            return bad(format!(
                "train.rollout_windows must be in 1..={MAX_ROLLOUT_WINDOWS} (the paper's most consecutive rollouts), got {}",
                t.rollout_windows
            ));
        }
        if t.iterations % t.rollout_windows != 0 {
            return bad(format!(
                "train.iterations ({}) must be a multiple of train.rollout_windows ({}): one drawn sequence is {} steps",
                t.iterations, t.rollout_windows, t.rollout_windows
            ));
        }
        if !(t.learning_rate > 0.0 && t.max_grad_norm >= 0.0) {
            return bad("train.learning_rate must be > 0 and train.max_grad_norm >= 0".into());
        }
        if !(0.0..1.0).contains(&t.ema_decay) {
            return bad(format!(
                "train.ema_decay must be in [0, 1), got {}",
                t.ema_decay
            ));
        }
        if t.log_interval == 0 {
            return bad("train.log_interval must be >= 1".into());
        }
        if t.torch_threads <= 0 {
            return bad(format!(
                "train.torch_threads must be positive, got {}",
                t.torch_threads
            ));
        }
        Ok(())
    }
}

impl SamplingConfig {
    /// Refuse DDIM steps outside `1..=steps` and a non-finite guidance; `key`
    /// names the config section in the message.
    pub(crate) fn validate(&self, key: &str, steps: usize) -> Result<(), ConfigError> {
        if self.sampler == SamplerKind::Ddim && !(1..=steps).contains(&self.ddim_steps) {
            return Err(ConfigError::Invalid(format!(
                "{key}.ddim_steps must be in 1..=diffusion.steps ({steps}), got {}",
                self.ddim_steps
            )));
        }
        if !self.guidance.is_finite() {
            return Err(ConfigError::Invalid(format!(
                "{key}.guidance must be finite, got {}",
                self.guidance
            )));
        }
        Ok(())
    }
}

/// Read a world-model file, apply `--set` overrides, validate.
pub fn load_world_model(
    path: &Path,
    overrides: &[String],
) -> Result<WorldModelConfig, ConfigError> {
    world_model_from_str(&read(path)?, &path.display().to_string(), overrides)
}

/// Like [`load_world_model`], from a string; `label` names it in messages.
pub fn world_model_from_str(
    text: &str,
    label: &str,
    overrides: &[String],
) -> Result<WorldModelConfig, ConfigError> {
    let cfg: WorldModelConfig = parse_inheriting(text, label, overrides)?;
    cfg.validate()?;
    Ok(cfg)
}
