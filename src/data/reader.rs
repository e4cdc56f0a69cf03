//! Reading shards: [`ShardReader`] streams the frames of one shard (MCAP records
//! through `mcap`'s sans-io reader, chunk CRCs checked before a chunk's frames are
//! given out, so a truncated shard yields exactly the frames of its complete
//! chunks); [`Dataset`] lists a directory's `*.mcap` in name order and chains them.
//! What to do with a truncated shard is [`OnTruncated`]; what was skipped is kept
//! as [`DataWarning`]s for the caller to print.
use std::fmt;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mcap::records::op;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::frame::{Dims, Frame};
use super::meta::{ShardMeta, FORMAT, METADATA_KEY, METADATA_NAME, TOPIC};
use super::DataError;
use crate::terrain::TerrainKind;

/// Bytes of an MCAP message record before its data: channel id, sequence, two times.
const MESSAGE_HEADER_BYTES: usize = 2 + 4 + 8 + 8;

/// What a reader does with a shard that ends without its footer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OnTruncated {
    /// Keep the frames of its complete chunks and record a [`DataWarning`].
    #[default]
    Warn,
    /// Fail with [`DataError::Truncated`] naming the shard.
    Fail,
}

/// How a dataset is read.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReadOptions {
    /// The dims the consumer expects; a shard with others is refused.
    pub expected: Dims,
    pub on_truncated: OnTruncated,
}

/// Something skipped while reading, for the caller to print.
#[derive(Debug, Clone, PartialEq)]
pub enum DataWarning {
    /// A shard without footer, read up to its last complete chunk.
    Truncated { path: PathBuf, frames: u64 },
    /// An unfinished `.mcap.tmp` in a dataset directory, not read.
    Leftover { path: PathBuf },
}

impl fmt::Display for DataWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DataWarning::Truncated { path, frames } => write!(
                f,
                "{}: truncated (no MCAP footer); read its {frames} frames up to the last complete chunk",
                path.display()
            ),
            DataWarning::Leftover { path } => write!(
                f,
                "{}: unfinished shard (its writer was interrupted or is still running); skipped",
                path.display()
            ),
        }
    }
}

enum Event {
    Meta(mcap::records::Metadata),
    Frame(Result<Frame, String>),
}

/// Which episodes a reader gives out; the others are skipped before their
/// frames are decoded (a validation split reads a tenth of the frames without
/// building the other nine tenths).
pub type EpisodeFilter = Arc<dyn Fn(u64) -> bool + Send + Sync>;

/// The frames of one shard, in file order.
pub struct ShardReader {
    path: PathBuf,
    file: BufReader<File>,
    reader: LinearReader,
    meta: ShardMeta,
    kinds: Vec<TerrainKind>,
    channel: Option<u16>,
    frames: u64,
    finished: bool,
    filter: Option<EpisodeFilter>,
}

impl ShardReader {
    /// Open a shard and read its metadata; its dims must be `expected`.
    pub fn open(path: &Path, expected: Dims) -> Result<ShardReader, DataError> {
        let file = File::open(path).map_err(|e| DataError::io(path, e))?;
        let mut r = ShardReader {
            path: path.to_path_buf(),
            file: BufReader::with_capacity(1 << 18, file),
            reader: LinearReader::new_with_options(
                LinearReaderOptions::default()
                    .with_prevalidate_chunk_crcs(true)
                    .with_record_length_limit(1 << 30),
            ),
            meta: ShardMeta::new(0, expected, Default::default()),
            kinds: Vec::new(),
            channel: None,
            frames: 0,
            finished: false,
            filter: None,
        };
        let not_shard = |why: &str| DataError::NotAShard {
            path: path.to_path_buf(),
            why: why.to_string(),
        };
        let meta = loop {
            match r.pump()? {
                None => return Err(not_shard("no dreampolicy.dataset metadata record")),
                Some(Event::Frame(_)) => {
                    return Err(not_shard(
                        "a message before the dreampolicy.dataset metadata",
                    ))
                }
                Some(Event::Meta(m)) if m.name == METADATA_NAME => break m,
                Some(Event::Meta(_)) => {}
            }
        };
        let json = meta
            .metadata
            .get(METADATA_KEY)
            .ok_or_else(|| not_shard("metadata record without its json key"))?;
        let meta: ShardMeta =
            serde_json::from_str(json).map_err(|e| not_shard(&format!("metadata JSON: {e}")))?;
        r.kinds = meta.kinds().map_err(|e| not_shard(&e))?;
        if meta.dims != expected {
            return Err(DataError::DimMismatch {
                path: path.to_path_buf(),
                found: meta.dims,
                expected,
            });
        }
        r.meta = meta;
        Ok(r)
    }

    /// Give out only the frames of episodes `keep` accepts (by episode id, read
    /// from the message before anything else is decoded).
    pub fn with_filter(mut self, keep: EpisodeFilter) -> ShardReader {
        self.filter = Some(keep);
        self
    }

    pub fn meta(&self) -> &ShardMeta {
        &self.meta
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames given out so far.
    pub fn frames_read(&self) -> u64 {
        self.frames
    }

    /// The next metadata record or frame; `None` at a clean end (footer and magic).
    fn pump(&mut self) -> Result<Option<Event>, DataError> {
        loop {
            let event = match self.reader.next_event() {
                None => return Ok(None),
                Some(Err(mcap::McapError::UnexpectedEof)) => {
                    return Err(DataError::Truncated {
                        path: self.path.clone(),
                        frames: self.frames,
                    })
                }
                Some(Err(source)) => {
                    return Err(DataError::Mcap {
                        path: self.path.clone(),
                        source,
                    })
                }
                Some(Ok(e)) => e,
            };
            match event {
                LinearReadEvent::ReadRequest(n) => {
                    let got = read_some(&mut self.file, self.reader.insert(n))
                        .map_err(|e| DataError::io(&self.path, e))?;
                    self.reader.notify_read(got);
                }
                LinearReadEvent::Record { opcode, data } => match opcode {
                    op::MESSAGE => {
                        if data.len() < MESSAGE_HEADER_BYTES {
                            return Err(DataError::BadFrame {
                                path: self.path.clone(),
                                index: self.frames,
                                why: "short MCAP message record".into(),
                            });
                        }
                        let channel = u16::from_le_bytes([data[0], data[1]]);
                        if Some(channel) != self.channel {
                            continue;
                        }
                        let payload = &data[MESSAGE_HEADER_BYTES..];
                        if let (Some(keep), Some(id)) = (&self.filter, payload.get(..8)) {
                            let mut b = [0u8; 8];
                            b.copy_from_slice(id);
                            if !keep(u64::from_le_bytes(b)) {
                                continue;
                            }
                        }
                        let frame = Frame::decode(
                            &data[MESSAGE_HEADER_BYTES..],
                            self.meta.dims,
                            &self.kinds,
                        );
                        return Ok(Some(Event::Frame(frame)));
                    }
                    op::METADATA | op::CHANNEL => {
                        let record =
                            mcap::parse_record(opcode, data).map_err(|source| DataError::Mcap {
                                path: self.path.clone(),
                                source,
                            })?;
                        match record {
                            mcap::records::Record::Metadata(m) => return Ok(Some(Event::Meta(m))),
                            mcap::records::Record::Channel(c)
                                if c.topic == TOPIC && c.message_encoding == FORMAT =>
                            {
                                self.channel = Some(c.id);
                            }
                            _ => {}
                        }
                    }
                    _ => {}
                },
            }
        }
    }
}

/// `read` that retries on interruption; 0 only at the end of the file.
fn read_some(file: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match file.read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            r => return r,
        }
    }
}

impl Iterator for ShardReader {
    type Item = Result<Frame, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        loop {
            match self.pump() {
                Ok(None) => {
                    self.finished = true;
                    return None;
                }
                Ok(Some(Event::Meta(_))) => {}
                Ok(Some(Event::Frame(Ok(f)))) => {
                    self.frames += 1;
                    return Some(Ok(f));
                }
                Ok(Some(Event::Frame(Err(why)))) => {
                    self.finished = true;
                    return Some(Err(DataError::BadFrame {
                        path: self.path.clone(),
                        index: self.frames,
                        why,
                    }));
                }
                Err(e) => {
                    self.finished = true;
                    return Some(Err(e));
                }
            }
        }
    }
}

/// The shards of a directory (or one shard file), read in name order.
pub struct Dataset {
    path: PathBuf,
    shards: Vec<PathBuf>,
    leftovers: Vec<PathBuf>,
    opts: ReadOptions,
    warnings: Arc<Mutex<Vec<DataWarning>>>,
}

impl Dataset {
    /// A directory's `*.mcap` files (its `*.mcap.tmp` are skipped with a warning;
    /// none at all is [`DataError::Empty`]), or one named file (a `.mcap.tmp` named
    /// explicitly is read like a truncated shard).
    pub fn open(path: &Path, opts: ReadOptions) -> Result<Dataset, DataError> {
        let md = std::fs::metadata(path).map_err(|e| DataError::io(path, e))?;
        let (mut shards, mut leftovers) = (Vec::new(), Vec::new());
        if md.is_dir() {
            for entry in std::fs::read_dir(path).map_err(|e| DataError::io(path, e))? {
                let p = entry.map_err(|e| DataError::io(path, e))?.path();
                let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
                if name.ends_with(".mcap") && p.is_file() {
                    shards.push(p);
                } else if name.ends_with(".mcap.tmp") {
                    leftovers.push(p);
                }
            }
            shards.sort();
            leftovers.sort();
            if shards.is_empty() {
                return Err(DataError::Empty {
                    dir: path.to_path_buf(),
                    leftovers: leftovers.len(),
                });
            }
        } else {
            shards.push(path.to_path_buf());
        }
        let warnings = leftovers
            .iter()
            .map(|p| DataWarning::Leftover { path: p.clone() })
            .collect();
        Ok(Dataset {
            path: path.to_path_buf(),
            shards,
            leftovers,
            opts,
            warnings: Arc::new(Mutex::new(warnings)),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The shard files, in reading order.
    pub fn shards(&self) -> &[PathBuf] {
        &self.shards
    }

    /// Unfinished `.mcap.tmp` files of the directory (never read).
    pub fn leftovers(&self) -> &[PathBuf] {
        &self.leftovers
    }

    pub fn options(&self) -> ReadOptions {
        self.opts
    }

    /// The dims every shard has (the expected ones).
    pub fn dims(&self) -> Dims {
        self.opts.expected
    }

    /// The metadata of the first shard.
    pub fn first_meta(&self) -> Result<ShardMeta, DataError> {
        Ok(ShardReader::open(&self.shards[0], self.opts.expected)?
            .meta()
            .clone())
    }

    /// Warnings so far (leftovers at open, truncated shards as they are read).
    pub fn warnings(&self) -> Vec<DataWarning> {
        self.warnings.lock().map(|w| w.clone()).unwrap_or_default()
    }

    /// Every frame of every shard, each with the index of its shard. An error ends
    /// the stream.
    pub fn frames(&self) -> Frames {
        Frames {
            shards: self.shards.clone(),
            base: 0,
            next: 0,
            current: None,
            opts: self.opts,
            warnings: self.warnings.clone(),
            failed: false,
            filter: None,
        }
    }

    /// The frames of the episodes `keep` accepts; the others are skipped
    /// undecoded.
    pub fn frames_where(&self, keep: EpisodeFilter) -> Frames {
        Frames {
            filter: Some(keep),
            ..self.frames()
        }
    }

    /// The frames of shard `i` alone (those of the episodes `keep` accepts,
    /// all with `None`), each with its index `i` in the dataset.
    pub fn shard_frames(&self, i: usize, keep: Option<EpisodeFilter>) -> Frames {
        Frames {
            shards: self.shards.get(i).cloned().into_iter().collect(),
            base: i,
            filter: keep,
            ..self.frames()
        }
    }
}

/// Iterator over a dataset's frames: `(shard index, frame)`.
pub struct Frames {
    shards: Vec<PathBuf>,
    /// Index in the dataset of `shards[0]`.
    base: usize,
    next: usize,
    current: Option<(usize, ShardReader)>,
    opts: ReadOptions,
    warnings: Arc<Mutex<Vec<DataWarning>>>,
    failed: bool,
    filter: Option<EpisodeFilter>,
}

impl Frames {
    /// Under [`OnTruncated::Warn`], turn a truncation into a warning (`None`).
    fn absorb(&mut self, e: DataError) -> Option<DataError> {
        match e {
            DataError::Truncated { path, frames }
                if self.opts.on_truncated == OnTruncated::Warn =>
            {
                if let Ok(mut w) = self.warnings.lock() {
                    w.push(DataWarning::Truncated { path, frames });
                }
                None
            }
            e => Some(e),
        }
    }
}

impl Iterator for Frames {
    type Item = Result<(usize, Frame), DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.failed {
            if let Some((i, reader)) = &mut self.current {
                let i = *i;
                match reader.next() {
                    Some(Ok(f)) => return Some(Ok((i, f))),
                    None => self.current = None,
                    Some(Err(e)) => {
                        self.current = None;
                        if let Some(e) = self.absorb(e) {
                            self.failed = true;
                            return Some(Err(e));
                        }
                    }
                }
                continue;
            }
            if self.next >= self.shards.len() {
                return None;
            }
            let i = self.next;
            self.next += 1;
            match ShardReader::open(&self.shards[i], self.opts.expected) {
                Ok(r) => {
                    let r = match &self.filter {
                        Some(keep) => r.with_filter(keep.clone()),
                        None => r,
                    };
                    self.current = Some((self.base + i, r))
                }
                Err(e) => {
                    if let Some(e) = self.absorb(e) {
                        self.failed = true;
                        return Some(Err(e));
                    }
                }
            }
        }
        None
    }
}
