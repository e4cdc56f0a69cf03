//! Sampling: the train/validation split by episode ([`SplitSpec`]: a fixed hash
//! of the episode id and a seed against a fraction, so an episode is always on
//! one side, whatever the shard order or the reader) and the bounded shuffle
//! buffer ([`Shuffle`], seeded).
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::DataError;

/// Which side of the split.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    Train,
    Validation,
    /// A train episode left out by [`SplitSpec::train_fraction`].
    Unused,
}

/// Episodes whose hash falls below `val_fraction` are validation episodes;
/// of the others, those in the first `train_fraction` of the rest of the
/// range are train episodes (a smaller fraction's train episodes are a subset
/// of a larger one's, and the validation episodes are the same for every
/// fraction: the scaling analysis's nested dataset sizes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitSpec {
    pub val_fraction: f64,
    pub seed: u64,
    pub train_fraction: f64,
}

impl SplitSpec {
    pub fn new(val_fraction: f64, seed: u64) -> Result<SplitSpec, DataError> {
        if !(0.0..=1.0).contains(&val_fraction) {
            return Err(DataError::Invalid(format!(
                "validation fraction {val_fraction} is outside 0..=1"
            )));
        }
        Ok(SplitSpec {
            val_fraction,
            seed,
            train_fraction: 1.0,
        })
    }

    /// Keep only `fraction` (in (0, 1]) of the train episodes.
    pub fn with_train_fraction(self, fraction: f64) -> Result<SplitSpec, DataError> {
        if !(fraction > 0.0 && fraction <= 1.0) {
            return Err(DataError::Invalid(format!(
                "train fraction {fraction} is outside (0, 1]"
            )));
        }
        Ok(SplitSpec {
            train_fraction: fraction,
            ..self
        })
    }

    /// The side of `episode`.
    pub fn of(&self, episode: u64) -> Split {
        let h = splitmix64(episode ^ splitmix64(self.seed));
        // top 53 bits as a uniform number in [0, 1)
        let u = (h >> 11) as f64 / (1u64 << 53) as f64;
        if u < self.val_fraction {
            Split::Validation
        } else if self.train_fraction >= 1.0
            || (u - self.val_fraction) < self.train_fraction * (1.0 - self.val_fraction)
        {
            Split::Train
        } else {
            Split::Unused
        }
    }
}

/// SplitMix64's finalizer: a fixed 64-bit mix (the same on every platform and run).
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A bounded shuffle: holds up to `capacity` items; once full, each new item
/// takes the place of one drawn uniformly from the buffer, which is given out;
/// at the end the rest comes out in random order. Errors pass through at once.
pub struct Shuffle<I, T> {
    inner: I,
    buf: Vec<T>,
    capacity: usize,
    rng: ChaCha8Rng,
    exhausted: bool,
}

impl<I, T, E> Shuffle<I, T>
where
    I: Iterator<Item = Result<T, E>>,
{
    pub fn new(inner: I, capacity: usize, seed: u64) -> Shuffle<I, T> {
        Shuffle {
            inner,
            buf: Vec::with_capacity(capacity.clamp(1, 1 << 20)),
            capacity: capacity.max(1),
            rng: ChaCha8Rng::seed_from_u64(seed),
            exhausted: false,
        }
    }
}

impl<I, T, E> Iterator for Shuffle<I, T>
where
    I: Iterator<Item = Result<T, E>>,
{
    type Item = Result<T, E>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.exhausted {
            match self.inner.next() {
                None => self.exhausted = true,
                Some(Err(e)) => return Some(Err(e)),
                Some(Ok(item)) => {
                    if self.buf.len() < self.capacity {
                        self.buf.push(item);
                        continue;
                    }
                    let j = self.rng.random_range(0..self.buf.len());
                    return Some(Ok(std::mem::replace(&mut self.buf[j], item)));
                }
            }
        }
        if self.buf.is_empty() {
            return None;
        }
        let j = self.rng.random_range(0..self.buf.len());
        Some(Ok(self.buf.swap_remove(j)))
    }
}
