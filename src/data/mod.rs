//! The expert dataset: per-step frames of the specialists' rollouts in MCAP shards.
//!
//! * [`frame`]: the [`Frame`] record and its fixed little-endian byte layout
//!   (the table is in that module's doc and in the README).
//! * [`meta`]: the JSON metadata record of every shard (dims, terrain-kind table,
//!   config, checkpoint hashes, MuJoCo and libtorch versions).
//! * [`writer`]: [`ShardWriter`], one `shard-NNNNN.mcap` per call, zstd chunks,
//!   written as `.mcap.tmp` and renamed when closed.
//! * [`reader`]: [`Dataset`] (the shards of a directory, in order) and
//!   [`ShardReader`] (the frames of one shard, streamed; a truncated shard reads up
//!   to its last complete chunk).
//! * [`window`]: history/horizon windows that never cross an episode boundary.
//! * [`sample`]: train/validation split by episode and the bounded shuffle buffer.
//! * [`stats`]: per-dimension mean/std, saved as `stats.json` next to the shards.
//! * [`inspect`]: what `dreampolicy data inspect` and `data verify` report.
use std::fmt;
use std::path::PathBuf;

pub mod frame;
pub mod inspect;
pub mod meta;
pub mod reader;
pub mod sample;
pub mod stats;
pub mod window;
pub mod writer;

pub use frame::{Dims, Frame};
pub use meta::{DatasetInfo, ShardMeta};
pub use reader::{DataWarning, Dataset, EpisodeFilter, OnTruncated, ReadOptions, ShardReader};
pub use sample::{Shuffle, Split, SplitSpec};
pub use stats::{DatasetStats, DimStats};
pub use window::{Interleaved, Window, WindowSpec, Windows};
pub use writer::{episode_id, shard_file_name, ShardWriter, WriterOptions};

/// Everything that can go wrong reading or writing a dataset; every variant that
/// concerns a file names it.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: MCAP error: {source}", path = .path.display())]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("{path}: not a dreampolicy dataset shard: {why}", path = .path.display())]
    NotAShard { path: PathBuf, why: String },
    #[error(
        "{path}: truncated after {frames} complete frames (no MCAP footer: the writer was killed mid-write or the copy was cut)",
        path = .path.display()
    )]
    Truncated { path: PathBuf, frames: u64 },
    #[error(
        "{path}: dataset dimensions ({found}) do not match the expected ({expected})",
        path = .path.display()
    )]
    DimMismatch {
        path: PathBuf,
        found: Dims,
        expected: Dims,
    },
    #[error("{path}: bad frame {index}: {why}", path = .path.display())]
    BadFrame {
        path: PathBuf,
        index: u64,
        why: String,
    },
    #[error("{dir}: no dataset shards (*.mcap){extra}", dir = .dir.display(), extra = leftover_note(.leftovers))]
    Empty { dir: PathBuf, leftovers: usize },
    #[error("frame has {got} {what} values, the shard's dims say {want}")]
    FrameShape {
        what: &'static str,
        got: usize,
        want: usize,
    },
    #[error("{path}: {why}", path = .path.display())]
    Json { path: PathBuf, why: String },
    #[error("invalid dataset option: {0}")]
    Invalid(String),
}

fn leftover_note(leftovers: &usize) -> String {
    match leftovers {
        0 => String::new(),
        n => format!(" (only {n} unfinished *.mcap.tmp left by an interrupted writer)"),
    }
}

impl DataError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> DataError {
        DataError::Io {
            path: path.into(),
            source,
        }
    }
}

impl fmt::Display for Dims {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "state {}, action {}, scandots {}",
            self.state, self.action, self.scan
        )
    }
}
