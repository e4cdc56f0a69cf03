//! The metadata record of a shard: one MCAP Metadata record named
//! [`METADATA_NAME`] whose key `json` holds [`ShardMeta`] as JSON. The writer puts
//! it right after the MCAP header, before any chunk, so that a truncated shard
//! still says what it holds.
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::frame::Dims;
use crate::terrain::TerrainKind;

/// Name of the MCAP metadata record.
pub const METADATA_NAME: &str = "dreampolicy.dataset";
/// Key of the JSON string in that record.
pub const METADATA_KEY: &str = "json";
/// The frame format this code writes and reads.
pub const FORMAT: &str = "dreampolicy.frame.v1";
/// Topic of the frame channel.
pub const TOPIC: &str = "/frames";

/// What the collector knows about its run; the writer stores it in every shard.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// The resolved collection config (YAML text).
    pub config: String,
    /// Checkpoint name (e.g. the terrain) -> SHA-256 of its file.
    pub checkpoints: BTreeMap<String, String>,
    pub mujoco_version: String,
    pub libtorch_version: String,
}

/// Everything a shard's metadata record holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardMeta {
    /// [`FORMAT`].
    pub format: String,
    pub dims: Dims,
    /// Bytes of one frame message.
    pub frame_bytes: usize,
    /// Terrain-kind names in code order (a frame's kind byte indexes this).
    pub terrain_kinds: Vec<String>,
    pub shard: u32,
    /// `dreampolicy <version>`.
    pub writer: String,
    #[serde(flatten)]
    pub info: DatasetInfo,
}

impl ShardMeta {
    pub fn new(shard: u32, dims: Dims, info: DatasetInfo) -> ShardMeta {
        ShardMeta {
            format: FORMAT.to_string(),
            dims,
            frame_bytes: dims.frame_bytes(),
            terrain_kinds: TerrainKind::ALL
                .iter()
                .map(|k| k.name().to_string())
                .collect(),
            shard,
            writer: format!("dreampolicy {}", env!("CARGO_PKG_VERSION")),
            info,
        }
    }

    /// The kind table, or why it is not one.
    pub fn kinds(&self) -> Result<Vec<TerrainKind>, String> {
        if self.format != FORMAT {
            return Err(format!(
                "format {:?}, this reader reads {FORMAT:?}",
                self.format
            ));
        }
        if self.frame_bytes != self.dims.frame_bytes() {
            return Err(format!(
                "frame_bytes {} disagrees with dims ({}) = {} bytes",
                self.frame_bytes,
                self.dims,
                self.dims.frame_bytes()
            ));
        }
        self.terrain_kinds
            .iter()
            .map(|n| TerrainKind::from_name(n).map_err(|e| e.to_string()))
            .collect()
    }
}
