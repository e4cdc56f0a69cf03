//! World-model windows: `history` consecutive frames of one episode ending at an
//! anchor step `t`, then `horizon` frames after it, never across an episode
//! boundary. An episode of `L` frames gives `max(0, L - (history + horizon) + 1)`
//! windows, one per anchor, in stream order. A step gap inside an episode (frames
//! lost to a truncation) restarts its window buffer; so does a new shard.
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::frame::{Dims, Frame};
use super::reader::{Dataset, EpisodeFilter};
use super::sample::{Split, SplitSpec};
use super::DataError;
use crate::terrain::TerrainKind;

/// History and horizon lengths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowSpec {
    /// Frames up to and including the anchor (`K >= 1`).
    pub history: usize,
    /// Frames after the anchor (`H >= 0`).
    pub horizon: usize,
    /// Also keep the scandots of every `scan_every`-th row from the anchor on
    /// (rows `K - 1 + j * scan_every` before the last row; 0 = the anchor's only):
    /// the terrain of each chunk of a sequence of consecutive world-model windows.
    pub scan_every: usize,
}

impl WindowSpec {
    pub fn new(history: usize, horizon: usize) -> Result<WindowSpec, DataError> {
        if history == 0 {
            return Err(DataError::Invalid(
                "a window needs a history of at least 1 frame".into(),
            ));
        }
        Ok(WindowSpec {
            history,
            horizon,
            scan_every: 0,
        })
    }

    /// The same spec keeping the scandots of every `stride`-th row from the anchor
    /// on (see [`WindowSpec::scan_every`]).
    pub fn with_scans_every(self, stride: usize) -> WindowSpec {
        WindowSpec {
            scan_every: stride,
            ..self
        }
    }

    /// Rows whose scandots [`Window::scans`] holds, oldest first.
    pub fn scan_rows(&self) -> impl Iterator<Item = usize> {
        let (k, h, s) = (self.history, self.horizon, self.scan_every);
        let n = if s == 0 { 0 } else { h.div_ceil(s) };
        (0..n).map(move |j| k - 1 + j * s)
    }

    /// Frames in one window.
    pub fn len(&self) -> usize {
        self.history + self.horizon
    }

    /// Never: a window holds at least its anchor.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Windows of an episode of `frames` frames.
    pub fn windows_in(&self, frames: usize) -> usize {
        (frames + 1).saturating_sub(self.len())
    }
}

/// `K + H` frames of one episode, rows oldest first: rows `0..K` are the history
/// (row `K - 1` is the anchor `t`), rows `K..K + H` the future `t + 1..=t + H`.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    pub episode: u64,
    pub env: u32,
    pub terrain: TerrainKind,
    pub level: u32,
    /// Step index of the first row.
    pub first_step: u32,
    pub spec: WindowSpec,
    pub dims: Dims,
    /// `(K + H) x state` states.
    pub states: Vec<f32>,
    /// `(K + H) x action` actions (row `i`'s action was taken at row `i`'s state).
    pub actions: Vec<f32>,
    /// Scandots at the anchor.
    pub scan: Vec<f32>,
    /// Scandots at the rows of [`WindowSpec::scan_rows`], concatenated (empty
    /// unless `spec.scan_every > 0`).
    pub scans: Vec<f32>,
    /// The last row is its episode's last frame (terminated or truncated).
    pub ends_episode: bool,
}

impl Window {
    /// Step index of the anchor.
    pub fn anchor_step(&self) -> u32 {
        self.first_step + self.spec.history as u32 - 1
    }

    /// States of the history rows.
    pub fn history_states(&self) -> &[f32] {
        &self.states[..self.spec.history * self.dims.state]
    }

    /// States of the future rows.
    pub fn future_states(&self) -> &[f32] {
        &self.states[self.spec.history * self.dims.state..]
    }

    fn from_frames(frames: &VecDeque<Frame>, spec: WindowSpec, dims: Dims) -> Window {
        let first = &frames[0];
        let anchor = &frames[spec.history - 1];
        let last = &frames[frames.len() - 1];
        let mut states = Vec::with_capacity(spec.len() * dims.state);
        let mut actions = Vec::with_capacity(spec.len() * dims.action);
        for f in frames {
            states.extend_from_slice(&f.state);
            actions.extend_from_slice(&f.action);
        }
        Window {
            episode: first.episode,
            env: first.env,
            terrain: first.terrain,
            level: first.level,
            first_step: first.step,
            spec,
            dims,
            states,
            actions,
            scan: anchor.scan.clone(),
            scans: spec
                .scan_rows()
                .flat_map(|r| frames[r].scan.iter().copied())
                .collect(),
            ends_episode: last.done(),
        }
    }
}

/// Windows of a stream of `(shard index, frame)`; errors pass through.
pub struct Windows<I> {
    frames: I,
    spec: WindowSpec,
    dims: Dims,
    open: HashMap<u64, VecDeque<Frame>>,
    shard: Option<usize>,
}

impl<I> Windows<I>
where
    I: Iterator<Item = Result<(usize, Frame), DataError>>,
{
    pub fn new(frames: I, spec: WindowSpec, dims: Dims) -> Windows<I> {
        Windows {
            frames,
            spec,
            dims,
            open: HashMap::new(),
            shard: None,
        }
    }

    /// Episodes with frames buffered (in progress).
    pub fn open_episodes(&self) -> usize {
        self.open.len()
    }
}

impl<I> Iterator for Windows<I>
where
    I: Iterator<Item = Result<(usize, Frame), DataError>>,
{
    type Item = Result<Window, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let (shard, frame) = match self.frames.next()? {
                Ok(x) => x,
                Err(e) => return Some(Err(e)),
            };
            if self.shard != Some(shard) {
                self.open.clear();
                self.shard = Some(shard);
            }
            let done = frame.done();
            let episode = frame.episode;
            let buf = self.open.entry(episode).or_default();
            if buf
                .back()
                .is_some_and(|b| b.step.wrapping_add(1) != frame.step)
            {
                buf.clear();
            }
            buf.push_back(frame);
            let mut out = None;
            if buf.len() == self.spec.len() {
                out = Some(Window::from_frames(buf, self.spec, self.dims));
                buf.pop_front();
            }
            if done {
                self.open.remove(&episode);
            }
            if let Some(w) = out {
                return Some(Ok(w));
            }
        }
    }
}

/// The episode filter of one side of a split (None: every episode).
fn split_filter(split: Option<(SplitSpec, Split)>) -> Option<EpisodeFilter> {
    split.map(|(spec, side)| -> EpisodeFilter { Arc::new(move |episode| spec.of(episode) == side) })
}

/// `frames` of `kinds`' episodes only (all when `kinds` is empty).
fn only_kinds(frames: FrameStream, kinds: &[TerrainKind]) -> FrameStream {
    if kinds.is_empty() {
        return frames;
    }
    let kinds = kinds.to_vec();
    Box::new(frames.filter(move |r| r.as_ref().map_or(true, |(_, f)| kinds.contains(&f.terrain))))
}

/// The windows of every shard of a dataset, read side by side
/// ([`Dataset::interleaved_windows_of`]); an error ends its shard's stream.
pub struct Interleaved {
    /// (weight, the shard's windows), for the shards not yet exhausted.
    streams: Vec<(f64, Windows<FrameStream>)>,
    rng: ChaCha8Rng,
}

impl Iterator for Interleaved {
    type Item = Result<Window, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.streams.is_empty() {
            let total: f64 = self.streams.iter().map(|s| s.0).sum();
            let mut x = self.rng.random::<f64>() * total;
            let mut pick = self.streams.len() - 1;
            for (i, (w, _)) in self.streams.iter().enumerate() {
                if x < *w {
                    pick = i;
                    break;
                }
                x -= w;
            }
            match self.streams[pick].1.next() {
                Some(w) => return Some(w),
                None => {
                    self.streams.remove(pick);
                }
            }
        }
        None
    }
}

/// A boxed stream of `(shard index, frame)`.
pub type FrameStream = Box<dyn Iterator<Item = Result<(usize, Frame), DataError>> + Send>;

impl Dataset {
    /// The frames of one side of a split (all frames with `None`).
    pub fn split_frames(&self, split: Option<(SplitSpec, Split)>) -> FrameStream {
        match split_filter(split) {
            None => Box::new(self.frames()),
            Some(keep) => Box::new(self.frames_where(keep)),
        }
    }

    /// [`Dataset::split_frames`], only the frames of `kinds`' episodes (all
    /// when `kinds` is empty).
    pub fn split_frames_of(
        &self,
        split: Option<(SplitSpec, Split)>,
        kinds: &[crate::terrain::TerrainKind],
    ) -> FrameStream {
        only_kinds(self.split_frames(split), kinds)
    }

    /// [`Dataset::windows_of`] with the shards read side by side instead of one
    /// after another: each window comes from a shard drawn at random (`seed`),
    /// weighted by its size on disk, so that every stretch of the stream holds
    /// every shard's terrain in proportion. `collect` writes one specialist's
    /// shards after another's and the windows of a shard by time step, so read
    /// in order a bounded shuffle holds a few thousand windows of one terrain
    /// and a trainer sees the terrains one after another, forgetting each.
    pub fn interleaved_windows_of(
        &self,
        spec: WindowSpec,
        split: Option<(SplitSpec, Split)>,
        kinds: &[crate::terrain::TerrainKind],
        seed: u64,
    ) -> Interleaved {
        let keep = split_filter(split);
        let streams = self
            .shards()
            .iter()
            .enumerate()
            .map(|(i, path)| {
                let bytes = std::fs::metadata(path).map_or(1, |m| m.len().max(1));
                let frames: FrameStream = Box::new(self.shard_frames(i, keep.clone()));
                (
                    bytes as f64,
                    Windows::new(only_kinds(frames, kinds), spec, self.dims()),
                )
            })
            .collect();
        Interleaved {
            streams,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// [`Dataset::windows`] over the episodes of `kinds` only (all when empty).
    pub fn windows_of(
        &self,
        spec: WindowSpec,
        split: Option<(SplitSpec, Split)>,
        kinds: &[crate::terrain::TerrainKind],
    ) -> Windows<FrameStream> {
        Windows::new(self.split_frames_of(split, kinds), spec, self.dims())
    }

    /// The windows of one side of a split, in stream order (wrap them in a
    /// [`super::Shuffle`] for training).
    pub fn windows(
        &self,
        spec: WindowSpec,
        split: Option<(SplitSpec, Split)>,
    ) -> Windows<FrameStream> {
        Windows::new(self.split_frames(split), spec, self.dims())
    }
}
