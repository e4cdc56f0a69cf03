//! [`ShardWriter`]: one MCAP shard of frames. The file is written as
//! `<name>.mcap.tmp`, fsynced and renamed to `<name>.mcap` by
//! [`ShardWriter::finish`], so a crash (`kill -9`) leaves at most one
//! `.mcap.tmp` behind and every `.mcap` in a dataset directory is complete.
//! Dropping a writer without `finish` leaves its `.mcap.tmp` too.
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};

use super::frame::{Dims, Frame};
use super::meta::{DatasetInfo, ShardMeta, FORMAT, METADATA_KEY, METADATA_NAME, TOPIC};
use super::DataError;

/// `shard-00012.mcap`.
pub fn shard_file_name(shard: u32) -> String {
    format!("shard-{shard:05}.mcap")
}

/// The dataset-wide episode id of the `ordinal`-th episode started in shard
/// `shard` (counted over all its envs): `shard << 32 | ordinal`.
pub fn episode_id(shard: u32, ordinal: u32) -> u64 {
    (u64::from(shard) << 32) | u64::from(ordinal)
}

/// Chunking and compression.
#[derive(Debug, Clone, Copy)]
pub struct WriterOptions {
    /// Uncompressed bytes per chunk (a truncated shard loses at most its last chunk).
    pub chunk_bytes: u64,
    /// zstd level.
    pub zstd_level: u32,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            chunk_bytes: 1 << 20,
            zstd_level: 3,
        }
    }
}

/// Writes the frames of one shard.
pub struct ShardWriter {
    tmp: PathBuf,
    path: PathBuf,
    writer: Writer<BufWriter<File>>,
    channel: u16,
    dims: Dims,
    frames: u64,
    buf: Vec<u8>,
}

impl ShardWriter {
    /// Start `dir/shard-NNNNN.mcap.tmp` (the directory is created if missing; an
    /// existing finished shard of that number is refused).
    pub fn create(
        dir: &Path,
        shard: u32,
        dims: Dims,
        info: DatasetInfo,
        opts: WriterOptions,
    ) -> Result<ShardWriter, DataError> {
        std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
        let path = dir.join(shard_file_name(shard));
        if path.exists() {
            return Err(DataError::Invalid(format!(
                "{} already exists; a dataset shard is never overwritten",
                path.display()
            )));
        }
        let tmp = path.with_extension("mcap.tmp");
        let file = File::create(&tmp).map_err(|e| DataError::io(&tmp, e))?;
        let mcap_err = |source| DataError::Mcap {
            path: tmp.clone(),
            source,
        };
        let mut writer = WriteOptions::new()
            .profile("")
            .library(format!("dreampolicy {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(Compression::Zstd))
            .compression_level(opts.zstd_level)
            .chunk_size(Some(opts.chunk_bytes.max(1)))
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(mcap_err)?;
        let meta = ShardMeta::new(shard, dims, info);
        let json = serde_json::to_string(&meta).map_err(|e| DataError::Json {
            path: tmp.clone(),
            why: e.to_string(),
        })?;
        writer
            .write_metadata(&Metadata {
                name: METADATA_NAME.to_string(),
                metadata: BTreeMap::from([(METADATA_KEY.to_string(), json)]),
            })
            .map_err(mcap_err)?;
        let channel_meta = BTreeMap::from([
            ("frame_bytes".to_string(), dims.frame_bytes().to_string()),
            (
                "layout".to_string(),
                "see the dreampolicy README, \"Dataset format\"".to_string(),
            ),
        ]);
        let channel = writer
            .add_channel(0, TOPIC, FORMAT, &channel_meta)
            .map_err(mcap_err)?;
        Ok(ShardWriter {
            tmp,
            path,
            writer,
            channel,
            dims,
            frames: 0,
            buf: Vec::with_capacity(dims.frame_bytes()),
        })
    }

    /// Append one frame (its float blocks must have the shard's dims).
    pub fn write(&mut self, frame: &Frame) -> Result<(), DataError> {
        self.buf.clear();
        frame.encode(self.dims, &mut self.buf)?;
        let header = MessageHeader {
            channel_id: self.channel,
            sequence: self.frames as u32,
            log_time: self.frames,
            publish_time: self.frames,
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|source| DataError::Mcap {
                path: self.tmp.clone(),
                source,
            })?;
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Path of the unfinished file.
    pub fn tmp_path(&self) -> &Path {
        &self.tmp
    }

    /// Write the summary and footer, fsync, rename to `shard-NNNNN.mcap`; the
    /// final path.
    pub fn finish(mut self) -> Result<PathBuf, DataError> {
        let tmp = self.tmp.clone();
        self.writer.finish().map_err(|source| DataError::Mcap {
            path: tmp.clone(),
            source,
        })?;
        let file = self
            .writer
            .into_inner()
            .into_inner()
            .map_err(|e| DataError::io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| DataError::io(&tmp, e))?;
        drop(file);
        std::fs::rename(&tmp, &self.path).map_err(|e| DataError::io(&self.path, e))?;
        Ok(self.path)
    }
}
