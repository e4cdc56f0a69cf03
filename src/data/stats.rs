//! Per-dimension mean and standard deviation (population, f64 accumulators,
//! Welford) of the states, actions and scandots of a set of frames, saved as
//! `stats.json` ([`STATS_FILE`]) next to the shards and loaded back with a dims
//! check.
use std::collections::HashSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::frame::{Dims, Frame};
use super::DataError;

/// File name of the saved statistics.
pub const STATS_FILE: &str = "stats.json";

/// Mean and standard deviation of each dimension.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DimStats {
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
}

/// Statistics of a dataset (or of one side of its split).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetStats {
    pub dims: Dims,
    pub frames: u64,
    pub episodes: u64,
    pub state: DimStats,
    pub action: DimStats,
    pub scan: DimStats,
}

/// Welford accumulator over `n` dimensions.
#[derive(Debug, Clone)]
struct Welford {
    count: u64,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Welford {
    fn new(n: usize) -> Welford {
        Welford {
            count: 0,
            mean: vec![0.0; n],
            m2: vec![0.0; n],
        }
    }

    fn push(&mut self, x: &[f32]) {
        self.count += 1;
        let inv = 1.0 / self.count as f64;
        for ((m, s), &v) in self.mean.iter_mut().zip(&mut self.m2).zip(x) {
            let v = f64::from(v);
            let d = v - *m;
            *m += d * inv;
            *s += d * (v - *m);
        }
    }

    fn finish(self) -> DimStats {
        let n = self.count.max(1) as f64;
        DimStats {
            std: self.m2.iter().map(|s| (s / n).sqrt()).collect(),
            mean: self.mean,
        }
    }
}

/// Accumulates [`DatasetStats`] frame by frame.
pub struct StatsBuilder {
    dims: Dims,
    episodes: HashSet<(usize, u64)>,
    state: Welford,
    action: Welford,
    scan: Welford,
}

impl StatsBuilder {
    pub fn new(dims: Dims) -> StatsBuilder {
        StatsBuilder {
            dims,
            episodes: HashSet::new(),
            state: Welford::new(dims.state),
            action: Welford::new(dims.action),
            scan: Welford::new(dims.scan),
        }
    }

    /// Add a frame of shard `shard`.
    pub fn push(&mut self, shard: usize, f: &Frame) {
        self.episodes.insert((shard, f.episode));
        self.state.push(&f.state);
        self.action.push(&f.action);
        self.scan.push(&f.scan);
    }

    pub fn finish(self) -> DatasetStats {
        DatasetStats {
            dims: self.dims,
            frames: self.state.count,
            episodes: self.episodes.len() as u64,
            state: self.state.finish(),
            action: self.action.finish(),
            scan: self.scan.finish(),
        }
    }
}

impl DatasetStats {
    /// Statistics of every frame of a stream.
    pub fn compute<I>(frames: I, dims: Dims) -> Result<DatasetStats, DataError>
    where
        I: Iterator<Item = Result<(usize, Frame), DataError>>,
    {
        let mut b = StatsBuilder::new(dims);
        for item in frames {
            let (shard, f) = item?;
            b.push(shard, &f);
        }
        if b.state.count == 0 {
            return Err(DataError::Invalid(
                "no frames to compute statistics from".into(),
            ));
        }
        Ok(b.finish())
    }

    /// Write `dir/stats.json`, sealed ([`crate::seal::seal_json`]: its first key
    /// `"sha256"` is the digest of the rest), through a temporary name.
    pub fn save(&self, dir: &Path) -> Result<(), DataError> {
        let path = dir.join(STATS_FILE);
        let json_err = |why: String| DataError::Json {
            path: path.clone(),
            why,
        };
        let text = serde_json::to_string_pretty(self).map_err(|e| json_err(e.to_string()))?;
        let sealed = crate::seal::seal_json(&text).map_err(|e| json_err(e.to_string()))?;
        crate::run::write_atomic(&path, sealed.as_bytes()).map_err(|(p, e)| DataError::io(&p, e))
    }

    /// Read `dir/stats.json`, check its seal; its dims must be `expected`.
    pub fn load(dir: &Path, expected: Dims) -> Result<DatasetStats, DataError> {
        let path = dir.join(STATS_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, e))?;
        if let Err(e) = crate::seal::check_json(&text) {
            return Err(DataError::Json {
                path,
                why: format!(
                    "{e}. Recompute it from the shards with `dreampolicy data inspect {} \
                     --save-stats`",
                    dir.display()
                ),
            });
        }
        // the seal's key, checked above, is not part of the statistics
        let s = serde_json::from_str::<serde_json::Value>(&text)
            .and_then(|mut v| {
                if let Some(o) = v.as_object_mut() {
                    o.remove("sha256");
                }
                serde_json::from_value::<DatasetStats>(v)
            })
            .map_err(|e| DataError::Json {
                path: path.clone(),
                why: e.to_string(),
            })?;
        if s.dims != expected {
            return Err(DataError::DimMismatch {
                path,
                found: s.dims,
                expected,
            });
        }
        for (what, d, n) in [
            ("state", &s.state, expected.state),
            ("action", &s.action, expected.action),
            ("scan", &s.scan, expected.scan),
        ] {
            if d.mean.len() != n || d.std.len() != n {
                return Err(DataError::Json {
                    path,
                    why: format!(
                        "{what} statistics have {} means and {} stds, the dims say {n}",
                        d.mean.len(),
                        d.std.len()
                    ),
                });
            }
        }
        Ok(s)
    }
}
