//! Training sequences: `K + T H` consecutive frames of one episode (a
//! [`crate::data::Window`] of history `K` and horizon `T H`, so never across an
//! episode) with the scandots at the anchor of each of the `T` chunks (rows `K -
//! 1 + t H`). The train split is read through the bounded shuffle, one epoch
//! after another, each epoch with its own shuffle seed; the position (epoch,
//! sequences consumed in it) is what a checkpoint saves, and [`Sequences::seek`]
//! reopens the stream there, so a resumed run sees exactly the same batches.
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Device, Tensor};

use super::denoiser::Normalizer;
use super::WmError;
use crate::data::sample::splitmix64;
use crate::data::window::Interleaved;
use crate::data::{Dataset, Shuffle, Split, SplitSpec, Window, WindowSpec};
use crate::world_model::config::WorldModelConfig;

/// A batch of sequences as normalized tensors.
pub struct SeqBatch {
    /// `[B, K, S]` the first history.
    pub history: Tensor,
    /// `[B, T H, S]` the future frames of the `T` chunks.
    pub future: Tensor,
    /// `[B, T, C]` the scandots at each chunk's anchor.
    pub scans: Tensor,
}

impl SeqBatch {
    /// Rows `idx` of every tensor.
    pub fn rows(&self, start: i64, len: i64) -> SeqBatch {
        SeqBatch {
            history: self.history.narrow(0, start, len),
            future: self.future.narrow(0, start, len),
            scans: self.scans.narrow(0, start, len),
        }
    }

    pub fn len(&self) -> i64 {
        self.history.size()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stack windows (of `spec`) into a normalized batch.
    pub fn from_windows(
        windows: &[Window],
        spec: WindowSpec,
        norm: &Normalizer,
        device: Device,
    ) -> SeqBatch {
        let b = windows.len() as i64;
        let dims = windows.first().map(|w| w.dims).unwrap_or_default();
        let (s, c) = (dims.state as i64, dims.scan as i64);
        let rows = spec.len() as i64;
        let chunks = spec.scan_rows().count() as i64;
        let mut states = Vec::with_capacity((b * rows * s) as usize);
        let mut scans = Vec::with_capacity((b * chunks * c) as usize);
        for w in windows {
            states.extend_from_slice(&w.states);
            scans.extend_from_slice(&w.scans);
        }
        let states = norm.states(
            &Tensor::from_slice(&states)
                .view([b, rows, s])
                .to_device(device),
        );
        let scans = norm.scans(
            &Tensor::from_slice(&scans)
                .view([b, chunks, c])
                .to_device(device),
        );
        let k = spec.history as i64;
        SeqBatch {
            history: states.narrow(1, 0, k),
            future: states.narrow(1, k, rows - k),
            scans,
        }
    }
}

type Stream = Shuffle<Interleaved, Window>;

/// The train split's sequences, epoch after epoch.
pub struct Sequences {
    dataset: Dataset,
    spec: WindowSpec,
    split: SplitSpec,
    /// The kinds trained on (empty: all).
    kinds: Vec<crate::terrain::TerrainKind>,
    shuffle: usize,
    seed: u64,
    /// Epochs completed.
    pub epoch: u64,
    /// Sequences given out in the current epoch.
    pub consumed: u64,
    stream: Option<Stream>,
}

impl Sequences {
    /// The spec of a config: history `K`, horizon `T H`, scandots every `H` rows.
    pub fn spec(cfg: &WorldModelConfig) -> Result<WindowSpec, WmError> {
        let (k, h, t) = (
            cfg.model.history,
            cfg.model.horizon,
            cfg.train.rollout_windows,
        );
        Ok(WindowSpec::new(k, t * h)?.with_scans_every(h))
    }

    pub fn new(dataset: Dataset, cfg: &WorldModelConfig) -> Result<Sequences, WmError> {
        Ok(Sequences {
            spec: Sequences::spec(cfg)?,
            split: cfg.data.split()?,
            kinds: cfg
                .data
                .kinds()
                .map_err(|e| WmError::Invalid(e.to_string()))?,
            shuffle: cfg.data.shuffle,
            seed: cfg.train.seed,
            epoch: 0,
            consumed: 0,
            stream: None,
            dataset,
        })
    }

    pub fn window_spec(&self) -> WindowSpec {
        self.spec
    }

    pub fn dataset(&self) -> &Dataset {
        &self.dataset
    }

    /// An epoch's stream: the shards read side by side (a stretch of the
    /// stream holds every terrain), then the bounded shuffle.
    fn open(&self) -> Stream {
        let seed = splitmix64(self.seed ^ splitmix64(self.epoch));
        let windows = self.dataset.interleaved_windows_of(
            self.spec,
            Some((self.split, Split::Train)),
            &self.kinds,
            splitmix64(seed ^ 0x5eed),
        );
        Shuffle::new(windows, self.shuffle, seed)
    }

    /// Continue at `consumed` sequences into epoch `epoch` (reads and drops the
    /// sequences before it).
    pub fn seek(&mut self, epoch: u64, consumed: u64) -> Result<(), WmError> {
        self.epoch = epoch;
        self.consumed = 0;
        let mut stream = self.open();
        while self.consumed < consumed {
            match stream.next() {
                Some(w) => {
                    w?;
                    self.consumed += 1;
                }
                None => {
                    return Err(WmError::Invalid(format!(
                        "the train split of {} has only {} sequences in an epoch, the checkpoint is {consumed} into one (was the dataset changed?)",
                        self.dataset.path().display(),
                        self.consumed
                    )))
                }
            }
        }
        self.stream = Some(stream);
        Ok(())
    }

    /// The next sequence; an exhausted epoch starts the next one.
    pub fn next_window(&mut self) -> Result<Window, WmError> {
        loop {
            if self.stream.is_none() {
                self.stream = Some(self.open());
            }
            let stream = self.stream.as_mut().expect("opened above");
            match stream.next() {
                Some(w) => {
                    self.consumed += 1;
                    return Ok(w?);
                }
                None if self.consumed == 0 => {
                    return Err(WmError::Invalid(format!(
                        "the train split of {} has no sequences of {} frames (history {} + {} rollout windows x horizon): episodes too short or the dataset too small",
                        self.dataset.path().display(),
                        self.spec.len(),
                        self.spec.history,
                        self.spec.horizon
                    )))
                }
                None => {
                    self.epoch += 1;
                    self.consumed = 0;
                    self.stream = None;
                }
            }
        }
    }

    /// The next `b` sequences.
    pub fn next_windows(&mut self, b: usize) -> Result<Vec<Window>, WmError> {
        (0..b).map(|_| self.next_window()).collect()
    }
}

/// `n` sequences drawn uniformly from the whole validation split (fewer if the
/// split has fewer; none when it is empty), in stream order: a seeded reservoir
/// sample (Algorithm R) over every validation window, so that they come from
/// every shard and terrain kind in proportion to its frames. (The first `n` in
/// stream order came from a few episodes of the first shard: on a dataset whose
/// first shards are one specialist's, validation measured that terrain only.)
pub fn validation_windows(
    dataset: &Dataset,
    cfg: &WorldModelConfig,
    n: usize,
) -> Result<Vec<Window>, WmError> {
    let spec = Sequences::spec(cfg)?;
    let split = SplitSpec::new(cfg.data.val_fraction, cfg.data.split_seed)?;
    if n == 0 {
        return Ok(Vec::new());
    }
    let mut rng = ChaCha8Rng::seed_from_u64(splitmix64(cfg.data.split_seed ^ 0x7A11_D5E7));
    let mut kept: Vec<(u64, Window)> = Vec::with_capacity(n.min(4096));
    for (i, w) in dataset
        .windows(spec, Some((split, Split::Validation)))
        .enumerate()
    {
        let w = w?;
        let i = i as u64;
        if kept.len() < n {
            kept.push((i, w));
        } else {
            let j = rng.random_range(0..=i);
            if (j as usize) < n {
                kept[j as usize] = (i, w);
            }
        }
    }
    kept.sort_by_key(|(i, _)| *i);
    Ok(kept.into_iter().map(|(_, w)| w).collect())
}
