//! Deployment: the bundle `export` writes (`bundle.rs`: a TorchScript policy and
//! `deploy.yaml`, the observation and action contract), a controller that runs
//! it from a robot's measurements alone (`controller.rs`), and `deploy-sim`,
//! that controller in a MuJoCo scene with no access to the training env
//! (`sim.rs`). `scripts/deploy_mujoco.py` is the same deployer in stock Python
//! MuJoCo.
pub mod bundle;
pub mod controller;
pub mod sim;

use std::path::PathBuf;

pub use bundle::{write_bundle, Bundle, BundleInfo};
pub use controller::{Controller, Sensors};
pub use sim::{deploy_sim, DeploySimOptions, DeploySummary};

/// Errors of bundles and deployers: one line a person can act on.
#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("bundle {path}: {message}", path = .path.display())]
    Bundle { path: PathBuf, message: String },
    #[error(transparent)]
    Rl(#[from] crate::rl::RlError),
    #[error("env: {0}")]
    Env(String),
    #[error("{0}")]
    Invalid(String),
}
