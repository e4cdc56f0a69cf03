//! The validation episodes of the evaluation, in memory, and seeded window
//! picks over them.
//!
//! [`ValidationSet::read`] keeps the validation side of the trainer's split
//! (by episode) as [`Segment`]s: runs of consecutive steps of one episode in one
//! shard (a step gap or a new shard starts a new segment, as the trainer's
//! windows do). At most `max_frames_per_kind` frames are kept per terrain kind
//! (segments that start after a kind's budget is spent are skipped), so a large
//! dataset still fits. [`ValidationSet::pick`] draws windows (a history of `K`
//! rows and `future` rows after the anchor) stratified by terrain kind and
//! uniform over the eligible anchors of each kind, without replacement.
use std::collections::hash_map::Entry;
use std::collections::{BTreeMap, HashMap};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::Tensor;

use super::super::WmError;
use crate::data::{Dataset, Dims, Split, SplitSpec};
use crate::terrain::TerrainKind;

/// Consecutive frames of one validation episode.
#[derive(Debug, Clone)]
pub struct Segment {
    pub episode: u64,
    pub kind: TerrainKind,
    /// Step index of the first row.
    pub first_step: u32,
    /// `len x S` states, raw.
    pub states: Vec<f32>,
    /// `len x C` scandots, raw.
    pub scans: Vec<f32>,
}

impl Segment {
    pub fn len(&self, dims: Dims) -> usize {
        self.states.len() / dims.state
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }
}

/// A window of a segment: rows `anchor + 1 - K ..= anchor + future`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pick {
    pub segment: usize,
    /// Row of the anchor (the last history row) in its segment.
    pub anchor: usize,
}

/// `(segment, first anchor row, anchors)` of one segment.
type Span = (usize, usize, usize);

/// The validation episodes of a dataset.
pub struct ValidationSet {
    pub dims: Dims,
    pub segments: Vec<Segment>,
    /// Distinct validation episodes read.
    pub episodes: usize,
    /// Validation frames kept.
    pub frames: u64,
    /// Kinds whose frame budget was reached (some of their episodes skipped).
    pub capped: Vec<TerrainKind>,
}

impl ValidationSet {
    /// Read the validation side of `split` from `dataset`.
    pub fn read(
        dataset: &Dataset,
        split: SplitSpec,
        max_frames_per_kind: usize,
    ) -> Result<ValidationSet, WmError> {
        let dims = dataset.dims();
        let mut open: HashMap<(usize, u64), Segment> = HashMap::new();
        let mut last_step: HashMap<(usize, u64), u32> = HashMap::new();
        let mut done: Vec<Segment> = Vec::new();
        let mut per_kind: BTreeMap<TerrainKind, usize> = BTreeMap::new();
        let mut capped = Vec::new();
        let mut episodes = std::collections::HashSet::new();
        for item in dataset.split_frames(Some((split, Split::Validation))) {
            let (shard, f) = item?;
            let key = (shard, f.episode);
            let gap = last_step
                .get(&key)
                .is_some_and(|&s| s.wrapping_add(1) != f.step);
            if gap {
                if let Some(seg) = open.remove(&key) {
                    done.push(seg);
                }
            }
            last_step.insert(key, f.step);
            let seg = match open.entry(key) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => {
                    if per_kind.get(&f.terrain).copied().unwrap_or(0) >= max_frames_per_kind {
                        if !capped.contains(&f.terrain) {
                            capped.push(f.terrain);
                        }
                        continue;
                    }
                    e.insert(Segment {
                        episode: f.episode,
                        kind: f.terrain,
                        first_step: f.step,
                        states: Vec::new(),
                        scans: Vec::new(),
                    })
                }
            };
            seg.states.extend_from_slice(&f.state);
            seg.scans.extend_from_slice(&f.scan);
            *per_kind.entry(f.terrain).or_default() += 1;
            episodes.insert(f.episode);
            if f.done() {
                done.extend(open.remove(&key));
                last_step.remove(&key);
            }
        }
        done.extend(open.into_values());
        // a fixed order whatever the hash map's
        done.sort_by_key(|s| (s.kind, s.episode, s.first_step));
        let frames = per_kind.values().sum::<usize>() as u64;
        Ok(ValidationSet {
            dims,
            segments: done,
            episodes: episodes.len(),
            frames,
            capped,
        })
    }

    /// Terrain kinds present, in order.
    pub fn kinds(&self) -> Vec<TerrainKind> {
        let mut k: Vec<TerrainKind> = self.segments.iter().map(|s| s.kind).collect();
        k.sort();
        k.dedup();
        k
    }

    /// Longest segment (frames).
    pub fn longest(&self) -> usize {
        self.segments
            .iter()
            .map(|s| s.len(self.dims))
            .max()
            .unwrap_or(0)
    }

    /// Segments with room for a window of `history + future` rows.
    pub fn eligible(&self, history: usize, future: usize) -> usize {
        self.segments
            .iter()
            .filter(|s| s.len(self.dims) >= history + future)
            .count()
    }

    /// Up to `n` windows of `history + future` rows: the `n` are shared out
    /// evenly over the kinds with eligible anchors (a kind with fewer takes all
    /// of its own and leaves the rest to the others), each kind's drawn uniformly
    /// without replacement. Ordered by kind, then as drawn.
    pub fn pick(&self, history: usize, future: usize, n: usize, seed: u64) -> Vec<Pick> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let need = history + future;
        // per kind: (segment, first anchor, anchors) of its eligible segments
        let mut by_kind: Vec<(TerrainKind, Vec<Span>)> = Vec::new();
        for kind in self.kinds() {
            let spans: Vec<Span> = self
                .segments
                .iter()
                .enumerate()
                .filter(|(_, s)| s.kind == kind && s.len(self.dims) >= need)
                .map(|(i, s)| (i, history - 1, s.len(self.dims) - need + 1))
                .collect();
            if !spans.is_empty() {
                by_kind.push((kind, spans));
            }
        }
        let totals: Vec<usize> = by_kind
            .iter()
            .map(|(_, sp)| sp.iter().map(|s| s.2).sum())
            .collect();
        // share n out: round robin over the kinds that still have anchors
        let mut quota = vec![0usize; by_kind.len()];
        let mut left = n;
        while left > 0 {
            let mut gave = false;
            for (q, &t) in quota.iter_mut().zip(&totals) {
                if left > 0 && *q < t {
                    *q += 1;
                    left -= 1;
                    gave = true;
                }
            }
            if !gave {
                break;
            }
        }
        let mut out = Vec::new();
        for ((_, spans), (&q, &total)) in by_kind.iter().zip(quota.iter().zip(&totals)) {
            for idx in rand::seq::index::sample(&mut rng, total, q) {
                let mut rest = idx;
                for &(seg, first, count) in spans {
                    if rest < count {
                        out.push(Pick {
                            segment: seg,
                            anchor: first + rest,
                        });
                        break;
                    }
                    rest -= count;
                }
            }
        }
        out
    }

    /// Raw states of rows `anchor + 1 - K ..= anchor + future` of each pick:
    /// `[B, K + future, S]`.
    pub fn states(&self, picks: &[Pick], history: usize, future: usize) -> Tensor {
        let s = self.dims.state;
        let rows = history + future;
        let mut v = Vec::with_capacity(picks.len() * rows * s);
        for p in picks {
            let start = p.anchor + 1 - history;
            v.extend_from_slice(&self.segments[p.segment].states[start * s..(start + rows) * s]);
        }
        Tensor::from_slice(&v).view([picks.len() as i64, rows as i64, s as i64])
    }

    /// Raw scandots at rows `anchor + j * stride` for `j in 0..calls`:
    /// `[B, calls, C]`.
    pub fn scans(&self, picks: &[Pick], stride: usize, calls: usize) -> Tensor {
        let c = self.dims.scan;
        let mut v = Vec::with_capacity(picks.len() * calls * c);
        for p in picks {
            let seg = &self.segments[p.segment];
            for j in 0..calls {
                let r = p.anchor + j * stride;
                v.extend_from_slice(&seg.scans[r * c..(r + 1) * c]);
            }
        }
        Tensor::from_slice(&v).view([picks.len() as i64, calls as i64, c as i64])
    }
}
