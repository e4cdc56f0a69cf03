//! [`PlayFile`]: the MCAP file of a rollout. Written as `<out>.tmp` (zstd chunks,
//! MCAP summary and indexes on finish), fsynced and renamed to `<out>` by
//! [`PlayFile::finish`]; dropped unfinished, it removes its temporary file.
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};
use serde::Serialize;

use super::foxglove;
use super::PlayError;

/// Schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Name of the metadata record that describes the rollout.
pub const METADATA_NAME: &str = "dreampolicy.play";

/// The channels of a play file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    Tf,
    Robot,
    Terrain,
    Command,
    State,
    Reward,
    /// A unified policy's plan (its files only).
    Plan,
}

impl Topic {
    /// The topics of every play file; a unified policy's also has [`Topic::Plan`].
    pub const ALL: [Topic; 6] = [
        Topic::Tf,
        Topic::Robot,
        Topic::Terrain,
        Topic::Command,
        Topic::State,
        Topic::Reward,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            Topic::Tf => "/tf",
            Topic::Robot => "/robot",
            Topic::Terrain => "/terrain",
            Topic::Command => "/command",
            Topic::State => "/state",
            Topic::Reward => "/reward",
            Topic::Plan => "/plan",
        }
    }

    /// Name of the topic's schema.
    pub const fn schema_name(self) -> &'static str {
        match self {
            Topic::Tf => foxglove::FRAME_TRANSFORMS,
            Topic::Robot | Topic::Terrain | Topic::Plan => foxglove::SCENE_UPDATE,
            Topic::Command => "dreampolicy.Command",
            Topic::State => "dreampolicy.State",
            Topic::Reward => "dreampolicy.Reward",
        }
    }
}

/// Fields of `/command` (name, description), as [`super::CommandMsg`] writes them.
pub const COMMAND_FIELDS: [(&str, &str); 3] = [
    ("vx", "commanded forward speed (m/s, pelvis heading frame)"),
    ("vy", "commanded sideways speed (m/s)"),
    (
        "yaw_rate",
        "commanded yaw rate (rad/s; heading mode steers it)",
    ),
];

/// Fields of `/state`, as [`super::StateMsg`] writes them.
pub const STATE_FIELDS: [(&str, &str); 18] = [
    ("step", "control step (0 = the reset state)"),
    ("time", "simulated time since the reset (s)"),
    ("x", "pelvis x, world (m)"),
    ("y", "pelvis y, world (m)"),
    ("z", "pelvis z, world (m)"),
    (
        "distance",
        "pelvis x - spawn x: distance walked along the lane (m)",
    ),
    (
        "base_height",
        "pelvis height above the terrain under it (m)",
    ),
    ("vx", "pelvis forward velocity, pelvis frame (m/s)"),
    ("vy", "pelvis sideways velocity, pelvis frame (m/s)"),
    ("vz", "pelvis vertical velocity, pelvis frame (m/s)"),
    ("vx_world", "pelvis velocity along the lane (world x, m/s)"),
    (
        "yaw_rate",
        "pelvis angular velocity about its z axis (rad/s)",
    ),
    ("roll", "pelvis roll (rad)"),
    ("pitch", "pelvis pitch (rad)"),
    ("yaw", "pelvis yaw (rad)"),
    ("left_contact", "1 when the left foot bears more than 1 N"),
    ("right_contact", "1 when the right foot bears more than 1 N"),
    (
        "feet_force",
        "sum of both feet's vertical contact force / robot weight",
    ),
];

/// Fields of `/reward`, as [`super::RewardMsg`] writes them (plus `terms`).
pub const REWARD_FIELDS: [(&str, &str); 3] = [
    ("step", "control step"),
    ("total", "this step's reward (the sum of the terms)"),
    ("return", "sum of the rewards so far"),
];

/// An MCAP file being written (or, [`PlayFile::discard`], only counted).
pub struct PlayFile {
    tmp: PathBuf,
    path: PathBuf,
    writer: Option<Writer<BufWriter<File>>>,
    /// Count the messages, write nothing (a rollout rendered to video only).
    discard: bool,
    channels: [u16; 7],
    counts: [u64; 7],
    buf: Vec<u8>,
}

impl PlayFile {
    /// Start `<path>.tmp` (parent directories are created) with its metadata
    /// record and every channel; `reward_terms` names the `/reward` terms;
    /// `plan` adds the `/plan` channel.
    pub fn create(
        path: &Path,
        metadata: BTreeMap<String, String>,
        reward_terms: &[&str],
        plan: bool,
    ) -> Result<PlayFile, PlayError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| PlayError::io(dir, e))?;
        }
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let file = File::create(&tmp).map_err(|e| PlayError::io(&tmp, e))?;
        let mut f = PlayFile {
            tmp,
            path: path.to_path_buf(),
            writer: None,
            discard: false,
            channels: [0; 7],
            counts: [0; 7],
            buf: Vec::with_capacity(1 << 16),
        };
        let mcap_err = f.mcap_err();
        let mut w = WriteOptions::new()
            .profile("")
            .library(format!("dreampolicy {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(Compression::Zstd))
            .compression_level(3)
            .chunk_size(Some(1 << 20))
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(&mcap_err)?;
        w.write_metadata(&Metadata {
            name: METADATA_NAME.to_string(),
            metadata,
        })
        .map_err(&mcap_err)?;
        let extra = plan.then_some(Topic::Plan);
        for topic in Topic::ALL.into_iter().chain(extra) {
            let k = topic as usize;
            let schema = match topic {
                Topic::Tf => foxglove::frame_transforms_schema(),
                Topic::Robot | Topic::Terrain | Topic::Plan => foxglove::scene_update_schema(),
                Topic::Command => foxglove::plain_schema(
                    topic.schema_name(),
                    "The command the policy follows: [vx, vy, yaw_rate]",
                    &COMMAND_FIELDS,
                    None,
                ),
                Topic::State => foxglove::plain_schema(
                    topic.schema_name(),
                    "The robot's measured state after each control step",
                    &STATE_FIELDS,
                    None,
                ),
                Topic::Reward => foxglove::plain_schema(
                    topic.schema_name(),
                    "The env's reward of each control step and its terms",
                    &REWARD_FIELDS,
                    Some(reward_terms),
                ),
            };
            // identical schema texts (the SceneUpdate topics) share one record
            let schema_id = w
                .add_schema(topic.schema_name(), SCHEMA_ENCODING, &schema)
                .map_err(&mcap_err)?;
            f.channels[k] = w
                .add_channel(schema_id, topic.name(), MESSAGE_ENCODING, &BTreeMap::new())
                .map_err(&mcap_err)?;
        }
        f.writer = Some(w);
        Ok(f)
    }

    /// No file: every message is counted and dropped; [`PlayFile::finish`]
    /// returns 0 bytes.
    pub fn discard() -> PlayFile {
        PlayFile {
            tmp: PathBuf::new(),
            path: PathBuf::new(),
            writer: None,
            discard: true,
            channels: [0; 7],
            counts: [0; 7],
            buf: Vec::new(),
        }
    }

    fn mcap_err(&self) -> impl Fn(mcap::McapError) -> PlayError {
        let path = self.tmp.clone();
        move |source| PlayError::Mcap {
            path: path.clone(),
            source,
        }
    }

    /// Write `msg` as JSON on `topic` at `time_ns` (log and publish time).
    pub fn write<T: Serialize>(
        &mut self,
        topic: Topic,
        time_ns: u64,
        msg: &T,
    ) -> Result<(), PlayError> {
        let k = topic as usize;
        if self.discard {
            self.counts[k] += 1;
            return Ok(());
        }
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg).map_err(|e| PlayError::Json {
            topic: topic.name(),
            why: e.to_string(),
        })?;
        let header = MessageHeader {
            channel_id: self.channels[k],
            sequence: self.counts[k] as u32,
            log_time: time_ns,
            publish_time: time_ns,
        };
        let err = self.mcap_err();
        self.writer
            .as_mut()
            .expect("the writer lives until finish")
            .write_to_known_channel(&header, &self.buf)
            .map_err(err)?;
        self.counts[k] += 1;
        Ok(())
    }

    /// Messages written on `topic` so far.
    pub fn count(&self, topic: Topic) -> u64 {
        self.counts[topic as usize]
    }

    /// Write the summary and footer, fsync, rename to the final path; its size in bytes.
    pub fn finish(mut self) -> Result<u64, PlayError> {
        if self.discard {
            return Ok(0);
        }
        let err = self.mcap_err();
        let mut w = self.writer.take().expect("the writer lives until finish");
        w.finish().map_err(&err)?;
        let file = w
            .into_inner()
            .into_inner()
            .map_err(|e| PlayError::io(&self.tmp, e.into_error()))?;
        file.sync_all().map_err(|e| PlayError::io(&self.tmp, e))?;
        let bytes = file
            .metadata()
            .map_err(|e| PlayError::io(&self.tmp, e))?
            .len();
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|e| PlayError::io(&self.path, e))?;
        Ok(bytes)
    }
}

impl Drop for PlayFile {
    /// An unfinished file is removed (finish has taken the writer).
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}
