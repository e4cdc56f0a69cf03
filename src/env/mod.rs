//! The G1 locomotion environment of the paper and its batched, multithreaded
//! [`VecEnv`]: observations ([`obs`] holds the layout), commands, named reward
//! terms ([`rewards`]), terminations, terrain curriculum, domain randomization.
pub mod cartpole;
pub mod config;
pub mod locomotion;
pub mod mirror;
pub mod obs;
pub mod rewards;
pub mod rollout;
pub mod scene;
pub mod state;
pub mod task;
mod vec_env;

pub use locomotion::{EpisodeEnd, FallCause, LocoEnv};
pub use scene::Scene;
pub use state::EnvState;
pub use vec_env::{StepInfo, VecEnv};

use crate::env::config::EnvConfig;
use crate::sim::SimError;

/// Errors building an environment.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Terrain(#[from] crate::terrain::TerrainError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("rewards: {0}")]
    Rewards(String),
    #[error("thread pool: {0}")]
    Threads(String),
}

/// What every env of a batch shares (read-only while stepping).
pub struct EnvShared {
    pub cfg: EnvConfig,
    pub scene: Scene,
    pub rewards: rewards::RewardSet,
    /// Control period (s).
    pub dt: f64,
    pub max_episode_steps: u64,
    pub resample_steps: u64,
    /// Control steps between pushes (0 = none).
    pub push_steps: u64,
    pub cos_max_tilt: f64,
    /// `q_target = q_default + action_scale[j] * a_j` (rad per unit action).
    pub action_scale: [f64; crate::robot::NUM_JOINTS],
}

impl EnvShared {
    pub fn new(cfg: EnvConfig, scene: Scene) -> Result<EnvShared, EnvError> {
        cfg.validate()?;
        let rewards = rewards::RewardSet::new(&cfg.rewards).map_err(EnvError::Rewards)?;
        let dt = cfg.sim.control_dt();
        let steps = |s: f64| ((s / dt).round() as u64).max(1);
        let dr = &cfg.domain_rand;
        Ok(EnvShared {
            max_episode_steps: steps(cfg.episode_length_s),
            resample_steps: steps(cfg.commands.resample_time_s),
            push_steps: if dr.enabled && dr.push_interval_s > 0.0 {
                steps(dr.push_interval_s)
            } else {
                0
            },
            cos_max_tilt: cfg.termination.max_tilt_deg.to_radians().cos(),
            action_scale: std::array::from_fn(|j| {
                let c = &cfg.control;
                if c.scale_by_effort {
                    c.action_scale * scene.g1.effort_limit[j] / scene.g1.kp[j]
                } else {
                    c.action_scale
                }
            }),
            rewards,
            dt,
            scene,
            cfg,
        })
    }
}

/// How one env's step ended.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outcome {
    pub reward: f32,
    /// The episode ended by failure (fall, fatal contact, blow-up): no bootstrap.
    pub terminated: bool,
    /// The episode was cut (time-out, map edge): bootstrap from the final observation.
    pub truncated: bool,
    /// The physics blew up this step (also `terminated`).
    pub blowup: bool,
    pub episode_done: bool,
}
