//! The terrain-aware autoregressive diffusion world model (stage 2): given `K`
//! history states and the local terrain, sample the next `H` states; chain calls
//! for any length.
//!
//! * [`schedule`]: the forward process `q(x^n | x^0)` (linear or cosine
//!   variance schedule over `N` steps) and the scheduled-sampling probability
//!   `p(iter)` of the paper's Algorithm 1.
//! * [`denoiser`]: the DiT denoiser `G(x^n, x_hist, n, y)` predicting `x^0`
//!   (adaLN-Zero on the step and terrain embeddings, self-attention over the
//!   `K + H` tokens, a learned null terrain embedding for classifier-free
//!   guidance), its EMA copy, and the state/scandot normalization.
//! * [`sampler`]: DDPM (ancestral, the paper's) and DDIM (`k` steps, eta = 0)
//!   from the x0 prediction, with classifier-free guidance; seeded noise.
//! * [`rollout`]: [`WorldModel`] (a trained checkpoint's EMA denoiser) and the
//!   autoregressive rollout API over a [`TerrainSource`].
//! * [`map_terrain`]: [`MapTerrain`], the scandots of a terrain map read along
//!   the path a rollout predicts.
//! * [`sequences`]: training sequences (`K + T H` frames of one episode, the
//!   scandots at each chunk's anchor) drawn from the dataset, epoch by epoch,
//!   with a position that a checkpoint restores exactly.
//! * [`checkpoint`]: the checkpoint record and reader (shared file format).
//! * [`trainer`]: the scheduled training loop (Algorithm 2), validation,
//!   checkpoints and the run directory.
//! * [`eval`]: `dreampolicy eval world-model`: one-call error per horizon step,
//!   autoregressive drift, guidance, terrain sensitivity, samplers, and a PNG.
use std::path::PathBuf;

pub mod checkpoint;
pub mod config;
pub mod denoiser;
pub mod eval;
pub mod map_terrain;
pub mod rollout;
pub mod sampler;
pub mod schedule;
pub mod sequences;
pub mod trainer;

pub use checkpoint::WmCheckpoint;
pub use denoiser::{Denoiser, Normalizer};
pub use eval::{evaluate, WmEvalOptions, WmEvalReport};
pub use map_terrain::{MapTerrain, Pose};
pub use rollout::{FixedTerrain, TerrainSource, WorldModel};
pub use sampler::{sample, Noise};
pub use schedule::{rollout_probability, NoiseSchedule};
pub use trainer::{train, WmTrainer};

/// Errors of the world model, its trainer and its checkpoints.
#[derive(Debug, thiserror::Error)]
pub enum WmError {
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    #[error(transparent)]
    Checkpoint(#[from] crate::checkpoint::CheckpointFileError),
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("training diverged: {0}")]
    NonFinite(String),
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    #[error("{0}")]
    Invalid(String),
}
