//! Procedural terrain: every terrain kind of the paper as a function of
//! `(difficulty level, params, rng)`, the legged_gym-style curriculum map (rows =
//! difficulty levels, columns = kinds), evaluation lanes (single kinds and the
//! paper's combined pairs), MuJoCo heightfield export and PNG rendering.
//!
//! * [`kinds`] — [`TerrainKind`], names, the training / unseen / combined lists
//! * [`config`] — [`TerrainConfig`] (YAML, validated) and the curriculum ranges
//! * `canvas` (private) — one tile's height grid and the shared layout helpers
//! * `shapes` (private) — the generator of each kind; it returns [`TileParams`]
//! * [`map`] — [`TerrainMap`] (heights, spawns, edge mask, MuJoCo export)
//! * [`lane`] — evaluation [`Lane`]s, single kinds and combined pairs
//! * [`render`] — top-down PNGs with a colour bar
//!
//! Conventions: heights are metres; the grid is y-major (`heights[j * nx + i]`,
//! `i` along x, `j` along y), sample `(i, j)` sits at world `(i * hs, j * hs)` with
//! the map's corner at the origin, which is also MuJoCo's heightfield layout
//! (row = y, column = x). A robot walks along +x through a tile.
pub mod config;
pub mod kinds;
pub mod lane;
pub mod map;
pub mod render;

mod canvas;
mod shapes;

use std::path::PathBuf;

pub use config::{
    BridgeParams, Curriculum, GapParams, LevelSampling, SlopeBridgeParams, SlopeParams,
    StairParams, TerrainConfig, UnevenHeights, UnevenParams, WaveParams,
};
pub use kinds::{TerrainKind, COMBINED_PAIRS};
pub use lane::{Lane, Segment};
pub use map::{tile_rng, TerrainMap, TileBounds};
pub use shapes::{TileGrid, TileParams, Wave};

/// Metres from a tile's (or lane's) start to the spawn point on its centre line.
pub const SPAWN_OFFSET: f64 = 1.0;
/// Metres between the spawn point and the first obstacle.
pub(crate) const SPAWN_CLEARANCE: f64 = 0.5;
/// Metres of plain ground kept at the end of a map tile.
pub(crate) const END_CLEARANCE: f64 = 0.5;

/// Everything the terrain module can fail with.
#[derive(Debug, thiserror::Error)]
pub enum TerrainError {
    /// A kind name that is not one of ours.
    #[error("unknown terrain kind '{name}': valid kinds are {valid}")]
    UnknownKind { name: String, valid: String },
    /// A configuration value out of range; `field` is its YAML path.
    #[error("terrain config: {field}: {message}")]
    Config { field: String, message: String },
    /// A YAML document that does not parse into a [`TerrainConfig`].
    #[error("terrain config: {0}")]
    Yaml(#[from] serde_yaml::Error),
    /// A difficulty level beyond the configured curriculum.
    #[error("terrain level {level} out of range: levels are 0..={max_level}")]
    Level { level: usize, max_level: usize },
    /// Reading a config or writing an image failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The PNG encoder refused the image.
    #[error("{path}: PNG encoding failed: {source}")]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}

impl TerrainError {
    /// A [`TerrainError::Config`] for `field`.
    pub(crate) fn config(field: impl Into<String>, message: impl Into<String>) -> TerrainError {
        TerrainError::Config {
            field: field.into(),
            message: message.into(),
        }
    }
}
