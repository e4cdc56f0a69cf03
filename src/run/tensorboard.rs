//! TensorBoard event files: the scalars of `metrics.csv`, written beside it.
//!
//! A file `events.out.tfevents.<unix seconds>.<hostname>` is a sequence of
//! TFRecords (`u64` length LE, masked CRC32C of those 8 bytes, the data, masked
//! CRC32C of the data; mask = `((crc >> 15) | (crc << 17)) + 0xa282ead8`), each
//! holding one protobuf `Event`: first one with `file_version: "brain.Event:2"`,
//! then one per metrics row with `wall_time` (field 1, double), `step` (field 2,
//! int64) and a `summary` (field 5) of `Summary.Value`s (field 1), each a `tag`
//! (field 1) and a `simple_value` (field 2, float). Writer and reader are written
//! here by hand, with no dependency: the framing, a table CRC32C and the three
//! messages fit in this file.
//!
//! * **Tags**: [`tag`] maps a `metrics.csv` column to rsl_rl's groups (`Train/`,
//!   `Loss/`, `Policy/`, `Perf/`, `Episode/`; README, "TensorBoard").
//! * **Step**: a row's first column (`iteration`: the PPO iteration, as rsl_rl
//!   logs; the world model's optimizer step). A NaN cell (no value in that row,
//!   e.g. `val_loss` between validations) is not logged.
//! * **Resume**: [`super::RunDir::start_tensorboard`] writes a new file from the
//!   rows `metrics.csv` holds (after a resume: the rows up to the checkpoint),
//!   keeping the wall times the old files gave those steps (a row no old file
//!   holds is placed its `wall_time_s` before now), then deletes the old files:
//!   every step is in exactly one file, once.
use std::collections::HashMap;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::RunError;

/// The first event of every file.
pub const FILE_VERSION: &str = "brain.Event:2";
/// What the name of every event file starts with.
pub const FILE_PREFIX: &str = "events.out.tfevents.";

/// Columns that take rsl_rl's tag names; every other column is `<group>/<column>`
/// (see [`tag`]).
pub const RSL_RL_TAGS: [(&str, &str); 9] = [
    ("mean_return", "Train/mean_reward"),
    ("mean_episode_length", "Train/mean_episode_length"),
    ("value_loss", "Loss/value_function"),
    ("surrogate_loss", "Loss/surrogate"),
    ("entropy", "Loss/entropy"),
    ("learning_rate", "Loss/learning_rate"),
    ("mean_std", "Policy/mean_noise_std"),
    ("env_steps_per_s", "Perf/total_fps"),
    ("time_update_s", "Perf/learning_time"),
];

/// The TensorBoard tag of a `metrics.csv` column: rsl_rl's name for the columns
/// of [`RSL_RL_TAGS`], else `<group>/<column>` with the group
/// * `Episode/`: what the env reports per episode or step: `rew_*`, `track_*`,
///   `vel_error_*`, `fall_fraction`, `terrain_level`, `level_*`, `penalty_scale`,
///   `style_reward`;
/// * `Loss/`: a name holding `loss` or `grad_`, ending in `_mse`, or
///   `explained_variance`;
/// * `Policy/`: `kl`, `clip_fraction`;
/// * `Perf/`: throughput and seconds: `*_per_s`, `time_*`, `*_time_s`;
/// * `Train/`: everything else (counts, curriculum and schedule values, and any
///   new column).
pub fn tag(column: &str) -> String {
    if let Some((_, t)) = RSL_RL_TAGS.iter().find(|(c, _)| *c == column) {
        return t.to_string();
    }
    let starts = |p: &[&str]| p.iter().any(|p| column.starts_with(p));
    let group = if starts(&["rew_", "track_", "vel_error_", "level_"])
        || matches!(
            column,
            "fall_fraction" | "terrain_level" | "penalty_scale" | "style_reward"
        ) {
        "Episode"
    } else if column.contains("loss")
        || column.contains("grad_")
        || column.ends_with("_mse")
        || column == "explained_variance"
    {
        "Loss"
    } else if matches!(column, "kl" | "clip_fraction") {
        "Policy"
    } else if column.ends_with("_per_s")
        || column.starts_with("time_")
        || column.ends_with("_time_s")
    {
        "Perf"
    } else {
        "Train"
    };
    format!("{group}/{column}")
}

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), as TFRecords use.
pub fn crc32c(data: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0x82F6_3B78
                } else {
                    c >> 1
                };
            }
            *e = c;
        }
        t
    });
    !data.iter().fold(!0u32, |c, &b| {
        table[((c ^ b as u32) & 0xff) as usize] ^ (c >> 8)
    })
}

/// The masked CRC32C a TFRecord stores.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let c = crc32c(data);
    c.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// `data` framed as one TFRecord.
pub fn record(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc32c(&len).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc32c(data).to_le_bytes());
    out
}

/// One `Event`: the file-version event or a row of scalars.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub wall_time: f64,
    pub step: i64,
    pub file_version: Option<String>,
    /// `(tag, simple_value)` of the summary's values, in order.
    pub scalars: Vec<(String, f32)>,
}

fn varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn bytes_field(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    varint(out, (field << 3) | 2);
    varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

impl Event {
    /// The protobuf encoding of the event.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.push((1 << 3) | 1); // wall_time: double
        out.extend_from_slice(&self.wall_time.to_le_bytes());
        if self.step != 0 {
            varint(&mut out, 2 << 3); // step: int64 (two's complement varint)
            varint(&mut out, self.step as u64);
        }
        if let Some(v) = &self.file_version {
            bytes_field(&mut out, 3, v.as_bytes());
        }
        if !self.scalars.is_empty() {
            let mut summary = Vec::new();
            for (tag, value) in &self.scalars {
                let mut val = Vec::new();
                bytes_field(&mut val, 1, tag.as_bytes());
                val.push((2 << 3) | 5); // simple_value: float
                val.extend_from_slice(&value.to_le_bytes());
                bytes_field(&mut summary, 1, &val);
            }
            bytes_field(&mut out, 5, &summary);
        }
        out
    }

    /// Decode an `Event`; fields other than the ones above are skipped.
    pub fn decode(data: &[u8]) -> Result<Event, String> {
        let mut e = Event {
            wall_time: 0.0,
            step: 0,
            file_version: None,
            scalars: Vec::new(),
        };
        for (field, value) in Fields(data) {
            match (field?, value) {
                (1, Value::Fixed64(v)) => e.wall_time = f64::from_le_bytes(v),
                (2, Value::Varint(v)) => e.step = v as i64,
                (3, Value::Bytes(b)) => {
                    let s = std::str::from_utf8(b).map_err(|_| "file_version: not UTF-8")?;
                    e.file_version = Some(s.to_string());
                }
                (5, Value::Bytes(summary)) => {
                    for (f, v) in Fields(summary) {
                        if let (1, Value::Bytes(val)) = (f?, v) {
                            e.scalars.extend(decode_value(val)?);
                        }
                    }
                }
                (1 | 2 | 3 | 5, _) => return Err("an Event field has the wrong wire type".into()),
                _ => {}
            }
        }
        Ok(e)
    }
}

/// `(tag, simple_value)` of a `Summary.Value`, if it has a simple value.
fn decode_value(data: &[u8]) -> Result<Option<(String, f32)>, String> {
    let (mut tag, mut value) = (None, None);
    for (f, v) in Fields(data) {
        match (f?, v) {
            (1, Value::Bytes(b)) => {
                tag = Some(
                    std::str::from_utf8(b)
                        .map_err(|_| "Summary.Value.tag: not UTF-8")?
                        .to_string(),
                )
            }
            (2, Value::Fixed32(b)) => value = Some(f32::from_le_bytes(b)),
            _ => {}
        }
    }
    Ok(tag.zip(value))
}

enum Value<'a> {
    Varint(u64),
    Fixed64([u8; 8]),
    Bytes(&'a [u8]),
    Fixed32([u8; 4]),
}

/// The fields of a protobuf message: `(Ok(field number) | Err(why), value)`;
/// iteration stops after the first error.
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn varint(&mut self) -> Result<u64, String> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let (&b, rest) = self.0.split_first().ok_or("truncated varint")?;
            self.0 = rest;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err("varint longer than 10 bytes".into())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if self.0.len() < n {
            return Err("truncated field".into());
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Ok(a)
    }

    fn field(&mut self) -> Result<(u64, Value<'a>), String> {
        let key = self.varint()?;
        let value = match key & 7 {
            0 => Value::Varint(self.varint()?),
            1 => Value::Fixed64(self.take(8)?.try_into().map_err(|_| "fixed64")?),
            2 => {
                let n = self.varint()?;
                Value::Bytes(self.take(usize::try_from(n).map_err(|_| "length")?)?)
            }
            5 => Value::Fixed32(self.take(4)?.try_into().map_err(|_| "fixed32")?),
            w => return Err(format!("wire type {w} of field {}", key >> 3)),
        };
        Ok((key >> 3, value))
    }
}

impl<'a> Iterator for Fields<'a> {
    type Item = (Result<u64, String>, Value<'a>);
    fn next(&mut self) -> Option<Self::Item> {
        if self.0.is_empty() {
            return None;
        }
        match self.field() {
            Ok((f, v)) => Some((Ok(f), v)),
            Err(e) => {
                self.0 = &[];
                Some((Err(e), Value::Varint(0)))
            }
        }
    }
}

/// Errors of reading an event file.
#[derive(Debug, thiserror::Error)]
pub enum EventFileError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: record at byte {offset} is cut short (the file ends inside it)")]
    Truncated { path: PathBuf, offset: u64 },
    #[error("{path}: record at byte {offset}: the CRC of its {what} does not match")]
    Crc {
        path: PathBuf,
        offset: u64,
        what: &'static str,
    },
    #[error("{path}: record at byte {offset}: not an Event ({message})")]
    Proto {
        path: PathBuf,
        offset: u64,
        message: String,
    },
}

/// The events of `bytes` up to the first bad record, and that record's error
/// (`None`: every record was good).
fn parse(bytes: &[u8], path: &Path) -> (Vec<Event>, Option<EventFileError>) {
    let mut events = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        match next_record(&bytes[at..]) {
            Ok((data, len)) => match Event::decode(data) {
                Ok(e) => {
                    events.push(e);
                    at += len;
                }
                Err(message) => {
                    let e = EventFileError::Proto {
                        path: path.to_path_buf(),
                        offset: at as u64,
                        message,
                    };
                    return (events, Some(e));
                }
            },
            Err(bad) => {
                let (path, offset) = (path.to_path_buf(), at as u64);
                let e = match bad {
                    None => EventFileError::Truncated { path, offset },
                    Some(what) => EventFileError::Crc { path, offset, what },
                };
                return (events, Some(e));
            }
        }
    }
    (events, None)
}

/// The data of the record at the start of `rest` and the record's length, or
/// why not: `None` cut short, `Some(what)` the CRC of `what` is wrong.
fn next_record(rest: &[u8]) -> Result<(&[u8], usize), Option<&'static str>> {
    if rest.len() < 12 {
        return Err(None);
    }
    let (len_bytes, crc) = (&rest[..8], &rest[8..12]);
    if masked_crc32c(len_bytes).to_le_bytes() != crc {
        return Err(Some("length"));
    }
    let len = u64::from_le_bytes(len_bytes.try_into().map_err(|_| None)?);
    let end = usize::try_from(len)
        .ok()
        .and_then(|n| n.checked_add(16))
        .filter(|&n| n <= rest.len())
        .ok_or(None)?;
    let data = &rest[12..end - 4];
    if masked_crc32c(data).to_le_bytes() != rest[end - 4..end] {
        return Err(Some("data"));
    }
    Ok((data, end))
}

/// Every event of the file at `path`, each record's two CRCs checked; a damaged
/// or cut record is an error naming the file and the record's offset.
pub fn read_events(path: &Path) -> Result<Vec<Event>, EventFileError> {
    let bytes = std::fs::read(path).map_err(|source| EventFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    match parse(&bytes, path) {
        (events, None) => Ok(events),
        (_, Some(e)) => Err(e),
    }
}

/// The event files of `dir` (names starting with [`FILE_PREFIX`]), sorted by name.
pub fn event_files(dir: &Path) -> Result<Vec<PathBuf>, RunError> {
    let io = |source| RunError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        if entry.file_name().to_string_lossy().starts_with(FILE_PREFIX) {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
}

/// This machine's host name for file names (`/proc/sys/kernel/hostname`, else
/// `$HOSTNAME`, else `localhost`), with anything but `[A-Za-z0-9._-]` as `_`.
fn hostname() -> String {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "localhost".into());
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn unix_time() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The open event file of a run directory.
pub(super) struct EventWriter {
    path: PathBuf,
    file: BufWriter<File>,
    /// The tag of each metrics column (the first, the step, is not logged).
    tags: Vec<String>,
}

impl EventWriter {
    /// Start the run directory's event file from its metrics rows (`rows`:
    /// `metrics.csv`'s data lines, `columns` its header) and delete every other
    /// event file of `dir` (module doc, "Resume").
    pub(super) fn start(
        dir: &Path,
        columns: &[String],
        rows: &[&str],
    ) -> Result<EventWriter, RunError> {
        let tags: Vec<String> = columns.iter().map(|c| tag(c)).collect();
        let old = event_files(dir)?;
        // wall times the old files gave each step (a damaged tail is dropped)
        let mut walls: HashMap<i64, f64> = HashMap::new();
        for f in &old {
            if let Ok(bytes) = std::fs::read(f) {
                for e in parse(&bytes, f).0 {
                    if !e.scalars.is_empty() {
                        walls.insert(e.step, e.wall_time);
                    }
                }
            }
        }
        let now = unix_time();
        // a row no old file holds (a run begun before event files existed) is
        // placed its `wall_time_s` before now (or at now without that column)
        let wall_col = columns.iter().position(|c| c == "wall_time_s");
        let cell = |line: &str, i: usize| -> f64 {
            line.split(',')
                .nth(i)
                .and_then(|v| v.trim().parse().ok())
                .unwrap_or(f64::NAN)
        };
        let last_wall = wall_col.and_then(|i| rows.last().map(|l| cell(l, i)));
        let path = dir.join(format!("{FILE_PREFIX}{}.{}", now as u64, hostname()));
        let mut bytes = record(
            &Event {
                wall_time: now,
                step: 0,
                file_version: Some(FILE_VERSION.into()),
                scalars: Vec::new(),
            }
            .encode(),
        );
        for line in rows {
            let values: Vec<f64> = line
                .split(',')
                .map(|v| v.trim().parse().unwrap_or(f64::NAN))
                .collect();
            let Some(&step) = values.first().filter(|s| s.is_finite()) else {
                continue;
            };
            let step = step as i64;
            let wall = walls.get(&step).copied().unwrap_or_else(|| {
                let ago = wall_col
                    .zip(last_wall)
                    .and_then(|(i, last)| values.get(i).map(|v| last - v));
                now - ago.filter(|a| a.is_finite() && *a >= 0.0).unwrap_or(0.0)
            });
            bytes.extend(record(&row_event(&tags, &values, step, wall).encode()));
        }
        // the new file by a name without `tfevents` (TensorBoard reads every
        // file whose name holds it), then renamed
        let tmp = dir.join("tensorboard.tmp");
        let io = |p: &Path| {
            let p = p.to_path_buf();
            move |source| RunError::Io { path: p, source }
        };
        File::create(&tmp)
            .and_then(|mut f| f.write_all(&bytes).and_then(|()| f.sync_all()))
            .map_err(io(&tmp))?;
        std::fs::rename(&tmp, &path).map_err(io(&path))?;
        for f in old.iter().filter(|f| **f != path) {
            std::fs::remove_file(f).map_err(io(f))?;
        }
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io(&path))?;
        Ok(EventWriter {
            path,
            file: BufWriter::new(file),
            tags,
        })
    }

    /// Append the event of one metrics row (its first value is the step) and flush.
    pub(super) fn row(&mut self, values: &[f64]) -> Result<(), RunError> {
        let step = values.first().copied().unwrap_or(0.0) as i64;
        let e = row_event(&self.tags, values, step, unix_time());
        let path = &self.path;
        let io = |source| RunError::Io {
            path: path.clone(),
            source,
        };
        self.file.write_all(&record(&e.encode())).map_err(io)?;
        self.file.flush().map_err(io)
    }

    pub(super) fn path(&self) -> &Path {
        &self.path
    }
}

/// The event of a metrics row: every value but the first (the step), NaN cells left out.
fn row_event(tags: &[String], values: &[f64], step: i64, wall_time: f64) -> Event {
    Event {
        wall_time,
        step,
        file_version: None,
        scalars: tags
            .iter()
            .zip(values)
            .skip(1)
            .filter(|(_, v)| !v.is_nan())
            .map(|(t, &v)| (t.clone(), v as f32))
            .collect(),
    }
}
