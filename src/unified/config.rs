//! The `unified:` section of a `task: unified` config (`configs/unified/`).
use serde::{Deserialize, Serialize};

use super::amp::AmpConfig;
use super::track::TrackingSigmas;
use crate::config::ConfigError;
use crate::rl::config::{ExperimentConfig, TaskKind};
use crate::world_model::config::SamplingConfig;

/// The world model in the loop and the unified policy's own rewards.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnifiedConfig {
    /// The world-model checkpoint (`train world-model`'s `checkpoints/latest.pt`).
    pub world_model: String,
    /// Sampler, DDIM steps and guidance ω of the plans.
    #[serde(default)]
    pub sampling: SamplingConfig,
    /// A new plan every `replan_every` control steps (batched over the envs
    /// that are due); in between, the plan shifts by one state. 1 = the paper's
    /// every-step sampling.
    #[serde(default = "default_replan")]
    pub replan_every: usize,
    /// Where the plans come from ([`PlanSource`]): the world model, or, as
    /// an inference ablation of `eval`/`play` only, the env's current state
    /// held over the horizon (what the plan adds to a trained policy).
    #[serde(default, skip_serializing_if = "PlanSource::is_world_model")]
    pub plan: PlanSource,
    /// Which states fill the world model's history ([`HistorySource`]): the
    /// policy's observed ones (with the env's observation noise) or the
    /// noise-free ones the expert dataset holds.
    #[serde(default, skip_serializing_if = "HistorySource::is_observed")]
    pub history: HistorySource,
    /// Predicted states the policy's future encoder reads (the first ones of
    /// the plan); default: all `H`.
    #[serde(default)]
    pub future_states: Option<usize>,
    /// The policy also reads the live scandots, after the plan in its future
    /// encoder's input (`[plan | scandots]`), as the specialist it inherits
    /// its architecture from does (the paper's appendix: "inherited from" the
    /// specialist's network, plus the future encoder). Then a specialist or the
    /// distilled student (`train.init_checkpoint`) starts it: its scan
    /// encoder's weights carry over and the plan enters through zero columns,
    /// so iteration 0 walks the terrains that checkpoint walks. Default: the
    /// plan alone (the paper's equation).
    #[serde(default)]
    pub scandots: bool,
    #[serde(default)]
    pub tracking: TrackingConfig,
    #[serde(default)]
    pub amp: AmpConfig,
    /// Weight of the diffusion-AMP style reward (the paper's 0.25).
    #[serde(default = "default_style")]
    pub style_weight: f64,
    /// Seed of the plans' sampling noise (mixed with the envs' RNG states at
    /// every reset of the batch, so that a resumed run draws the same noise).
    #[serde(default)]
    pub seed: u64,
}

/// The source of the policy's plans.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlanSource {
    /// The world model's predicted futures (the paper's; training's only source).
    #[default]
    WorldModel,
    /// Every predicted state is the env's current state: the world model is
    /// not called. `train unified` refuses it (the discriminator would have no
    /// real transitions); `eval --set unified.plan=hold` measures how much of
    /// a trained policy's success the plans carry.
    Hold,
}

impl PlanSource {
    pub fn is_world_model(&self) -> bool {
        *self == PlanSource::WorldModel
    }
}

/// The states the world model plans from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HistorySource {
    /// The policy's observations, observation noise included (what a robot's
    /// sensors give; every run before 2026-12-08).
    #[default]
    Observed,
    /// The env's noise-free states (the critic's copy), the distribution the
    /// world model was trained on: the expert dataset is recorded without
    /// observation noise. A world model whose history skip starts at the
    /// least-squares fit (`model.history_skip_fit`) passes the history
    /// linearly into its plan, so the training noise on the joint velocities
    /// (1.5 rad/s) reaches the planned velocities: with observed histories
    /// world_model_turning_fit's plans dropped the unified policy's
    /// linear-velocity score from 0.31 to 0.04 at its first iteration.
    Clean,
}

impl HistorySource {
    pub fn is_observed(&self) -> bool {
        *self == HistorySource::Observed
    }
}

fn default_replan() -> usize {
    5
}

fn default_style() -> f64 {
    0.25
}

/// The four body-space tracking terms: weights (the paper's 1.0 each) and tolerances.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingConfig {
    /// Weights of position, orientation, linear and angular velocity.
    pub weights: [f64; 4],
    pub sigmas: TrackingSigmas,
    /// What the bodies' linear velocities are measured against
    /// ([`BaseVelocity`]); `relative` unless a config says otherwise (the
    /// runs before 2026-12-07 were trained so).
    pub base_velocity: BaseVelocity,
}

/// The frame of the linear-velocity term.
///
/// A state (98 floats) holds no base linear velocity, so a plan says how the
/// bodies move against the pelvis, not how fast the robot goes.
/// - `relative`: every body's velocity minus the pelvis's, in the heading
///   frame, for plan and robot alike. Nothing in the tracking terms then pays
///   for forward progress (unified_spec1/2 slowed from 0.64 to 0.41 m/s on the
///   plane for a commanded 0.78).
/// - `command`: heading-frame velocities with the base's own: the plan's
///   pelvis moves at the command its `ŝ_{t+1}` holds (`v_x`, `v_y`), the
///   robot's at its measured velocity, so a robot slower than its command is
///   off the plan on every body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BaseVelocity {
    #[default]
    Relative,
    Command,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        TrackingConfig {
            weights: [1.0; 4],
            sigmas: TrackingSigmas::default(),
            base_velocity: BaseVelocity::default(),
        }
    }
}

impl UnifiedConfig {
    /// The `unified:` section of `cfg`, parsed and checked; `cfg` must be a
    /// `task: unified` config.
    pub fn of(cfg: &ExperimentConfig) -> Result<UnifiedConfig, ConfigError> {
        if cfg.task != TaskKind::Unified {
            return Err(ConfigError::Invalid(
                "not a unified config: set `task: unified` and a `unified:` section".into(),
            ));
        }
        let u: UnifiedConfig = crate::rl::config::parse_section(
            &cfg.unified,
            "unified",
            "task: unified needs a `unified:` section",
        )?;
        u.validate()?;
        Ok(u)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad =
            |key: &str, why: String| Err(ConfigError::Invalid(format!("unified.{key}: {why}")));
        if self.world_model.trim().is_empty() {
            return bad("world_model", "names no checkpoint".into());
        }
        if self.replan_every == 0 {
            return bad("replan_every", "must be at least 1".into());
        }
        if self.future_states == Some(0) {
            return bad("future_states", "must be at least 1".into());
        }
        let t = &self.tracking;
        if t.weights.iter().any(|w| !w.is_finite()) {
            return bad(
                "tracking.weights",
                format!("{:?} must be finite", t.weights),
            );
        }
        let s = &t.sigmas;
        for (k, v) in [
            ("pos", s.pos),
            ("ori", s.ori),
            ("lin_vel", s.lin_vel),
            ("ang_vel", s.ang_vel),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(
                    &format!("tracking.sigmas.{k}"),
                    format!("{v} must be positive"),
                );
            }
        }
        if !self.style_weight.is_finite() {
            return bad("style_weight", "must be finite".into());
        }
        self.amp
            .check()
            .map_err(|why| ConfigError::Invalid(format!("unified.amp: {why}")))?;
        Ok(())
    }
}
