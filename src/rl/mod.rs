//! Reinforcement learning on libtorch: PPO (rsl_rl's four steps: act, process a
//! step, compute returns, update), its rollout storage, the actor-critic, running
//! observation normalization, checkpoints, and the runner's learn loop.
//!
//! The runner trains any [`VecTask`]: the G1 locomotion `VecEnv`, or the small
//! cart-pole that tests PPO end to end.
pub mod agent;
pub mod checkpoint;
pub mod config;
pub mod export;
pub mod metrics;
pub mod normalizer;
pub mod onnx;
pub mod optim;
pub mod policy;
pub mod ppo;
pub mod runner;
pub mod storage;

pub use crate::env::task::{TaskDims, VecTask};
pub use agent::Agent;
pub use policy::ActorCritic;

use std::path::PathBuf;

/// Errors of training, evaluation and checkpoints.
#[derive(Debug, thiserror::Error)]
pub enum RlError {
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("checkpoint {path}: {message}")]
    Checkpoint { path: PathBuf, message: String },
    #[error(transparent)]
    Env(#[from] crate::env::EnvError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    #[error("training diverged: {0}")]
    NonFinite(String),
    #[error("{0}")]
    Invalid(String),
}

impl From<crate::checkpoint::CheckpointFileError> for RlError {
    fn from(e: crate::checkpoint::CheckpointFileError) -> RlError {
        use crate::checkpoint::CheckpointFileError as E;
        match e {
            E::Io { path, source } => RlError::Io { path, source },
            E::Torch(t) => RlError::Torch(t),
            E::Invalid { path, message } => RlError::Checkpoint { path, message },
        }
    }
}
