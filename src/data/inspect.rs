//! What `dreampolicy data inspect` and `dreampolicy data verify` report:
//! [`inspect`] (frames and episodes per terrain, episode lengths, statistics) with
//! its text rendering, and [`verify`] (every shard read to its footer, frame by
//! frame, with the episode invariants checked).
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::frame::Dims;
use super::reader::{DataWarning, Dataset, OnTruncated, ReadOptions, ShardReader};
use super::stats::{DatasetStats, StatsBuilder};
use super::DataError;
use crate::env::obs;

/// Frames and episodes of one terrain kind.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct TerrainCount {
    pub frames: u64,
    pub episodes: u64,
}

/// Summary of a dataset.
#[derive(Debug, Clone, Serialize)]
pub struct Inspection {
    pub path: PathBuf,
    pub shards: usize,
    pub bytes: u64,
    pub frames: u64,
    pub terrains: BTreeMap<String, TerrainCount>,
    /// Lengths (frames) of the episodes that end with a done flag.
    pub episode_lengths: Vec<u32>,
    /// Episodes cut by the end of their shard (no done flag).
    pub open_episodes: u64,
    pub terminated: u64,
    pub truncated: u64,
    pub stats: DatasetStats,
    #[serde(skip)]
    pub warnings: Vec<DataWarning>,
}

/// Read a dataset (directory or file) once.
pub fn inspect(path: &Path, opts: ReadOptions) -> Result<Inspection, DataError> {
    let ds = Dataset::open(path, opts)?;
    let bytes = ds
        .shards()
        .iter()
        .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
        .sum();
    let mut stats = StatsBuilder::new(opts.expected);
    let mut terrains: BTreeMap<String, TerrainCount> = BTreeMap::new();
    let mut running: HashMap<(usize, u64), u32> = HashMap::new();
    let (mut lengths, mut frames, mut terminated, mut truncated) = (Vec::new(), 0u64, 0, 0);
    for item in ds.frames() {
        let (shard, f) = item?;
        frames += 1;
        stats.push(shard, &f);
        let t = terrains.entry(f.terrain.name().to_string()).or_default();
        t.frames += 1;
        let len = running.entry((shard, f.episode)).or_insert_with(|| {
            t.episodes += 1;
            0
        });
        *len += 1;
        if f.done() {
            lengths.push(*len);
            running.remove(&(shard, f.episode));
            terminated += f.terminated as u64;
            truncated += (f.truncated && !f.terminated) as u64;
        }
    }
    if frames == 0 {
        return Err(DataError::Invalid(format!("{}: no frames", path.display())));
    }
    Ok(Inspection {
        path: path.to_path_buf(),
        shards: ds.shards().len(),
        bytes,
        frames,
        terrains,
        episode_lengths: lengths,
        open_episodes: running.len() as u64,
        terminated,
        truncated,
        stats: stats.finish(),
        warnings: ds.warnings(),
    })
}

/// `bins` equal-width bins over `0..=max`: `(low, high, count)`.
pub fn histogram(values: &[u32], bins: usize) -> Vec<(u32, u32, u64)> {
    let Some(&max) = values.iter().max() else {
        return Vec::new();
    };
    let bins = bins.max(1);
    let width = (max as usize / bins + 1) as u32;
    let mut counts = vec![0u64; bins];
    for &v in values {
        counts[((v / width) as usize).min(bins - 1)] += 1;
    }
    counts
        .into_iter()
        .enumerate()
        .map(|(i, c)| (i as u32 * width, (i as u32 + 1) * width - 1, c))
        .collect()
}

impl Inspection {
    /// The report as text.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let bpf = self.bytes as f64 / self.frames.max(1) as f64;
        let _ = writeln!(
            s,
            "{}: {} shards, {} frames, {} episodes ended ({} terminated, {} truncated), {} cut by a shard end; {:.1} MB on disk, {:.0} bytes/frame (raw frame {} bytes)",
            self.path.display(),
            self.shards,
            self.frames,
            self.episode_lengths.len(),
            self.terminated,
            self.truncated,
            self.open_episodes,
            self.bytes as f64 / 1e6,
            bpf,
            self.stats.dims.frame_bytes()
        );
        let _ = writeln!(s, "\n{:<16} {:>12} {:>10}", "terrain", "frames", "episodes");
        for (name, c) in &self.terrains {
            let _ = writeln!(s, "{name:<16} {:>12} {:>10}", c.frames, c.episodes);
        }
        let _ = writeln!(s, "\nepisode length (frames, ended episodes)");
        let hist = histogram(&self.episode_lengths, 10);
        if hist.is_empty() {
            let _ = writeln!(s, "(no episode ended inside its shard)");
        }
        let top = hist.iter().map(|h| h.2).max().unwrap_or(0).max(1);
        for (lo, hi, c) in &hist {
            let bar = "#".repeat(((*c as f64 / top as f64) * 40.0).round() as usize);
            let _ = writeln!(s, "{lo:>6}-{hi:<6} {c:>8} {bar}");
        }
        let _ = writeln!(
            s,
            "\nstate statistics (per block: mean of the means, mean / min / max std)"
        );
        let blocks = [
            ("ang_vel", obs::ANG_VEL),
            ("gravity", obs::GRAVITY),
            ("dof_pos", obs::DOF_POS),
            ("dof_vel", obs::DOF_VEL),
            ("command", obs::COMMAND),
            ("last_action", obs::LAST_ACTION),
            ("phase", obs::PHASE),
        ];
        let st = &self.stats;
        let mut rows: Vec<(String, &[f64], &[f64])> = Vec::new();
        if st.dims == Dims::G1 {
            for (name, r) in blocks {
                rows.push((name.into(), &st.state.mean[r.clone()], &st.state.std[r]));
            }
        } else {
            rows.push(("state".into(), &st.state.mean, &st.state.std));
        }
        rows.push(("action".into(), &st.action.mean, &st.action.std));
        rows.push(("scandots".into(), &st.scan.mean, &st.scan.std));
        let _ = writeln!(
            s,
            "{:<12} {:>10} {:>10} {:>10} {:>10}",
            "block", "mean", "std", "min std", "max std"
        );
        for (name, mean, std) in rows {
            let avg = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
            let min = std.iter().copied().fold(f64::INFINITY, f64::min);
            let max = std.iter().copied().fold(0.0, f64::max);
            let _ = writeln!(
                s,
                "{name:<12} {:>10.4} {:>10.4} {:>10.4} {:>10.4}",
                avg(mean),
                avg(std),
                min,
                max
            );
        }
        s
    }
}

/// One file's verdict.
#[derive(Debug, Clone, Serialize)]
pub struct ShardCheck {
    pub path: PathBuf,
    pub frames: u64,
    pub episodes: u64,
    /// `None` when the shard is good.
    pub error: Option<String>,
}

/// Read every shard of `dir` to its footer (truncation is an error here) and
/// check that the frames of each episode are consecutive steps of one env and
/// that nothing follows a done frame. Unfinished `.mcap.tmp` files are bad shards.
pub fn verify(dir: &Path, expected: Dims) -> Result<Vec<ShardCheck>, DataError> {
    let opts = ReadOptions {
        expected,
        on_truncated: OnTruncated::Fail,
    };
    let ds = Dataset::open(dir, opts)?;
    let mut out: Vec<ShardCheck> = ds
        .shards()
        .iter()
        .map(|p| check_shard(p, expected))
        .collect();
    for p in ds.leftovers() {
        out.push(ShardCheck {
            path: p.clone(),
            frames: 0,
            episodes: 0,
            error: Some(
                "unfinished shard (.mcap.tmp): its writer was interrupted or is still running"
                    .into(),
            ),
        });
    }
    Ok(out)
}

fn check_shard(path: &Path, expected: Dims) -> ShardCheck {
    let mut check = ShardCheck {
        path: path.to_path_buf(),
        frames: 0,
        episodes: 0,
        error: None,
    };
    let reader = match ShardReader::open(path, expected) {
        Ok(r) => r,
        Err(e) => {
            check.error = Some(e.to_string());
            return check;
        }
    };
    // episode -> (env, last step, ended)
    let mut seen: HashMap<u64, (u32, u32, bool)> = HashMap::new();
    for item in reader {
        let f = match item {
            Ok(f) => f,
            Err(e) => {
                check.error = Some(e.to_string());
                return check;
            }
        };
        let index = check.frames;
        check.frames += 1;
        let problem = match seen.get(&f.episode) {
            None => None,
            Some(&(env, _, _)) if env != f.env => Some(format!(
                "episode {} moves from env {env} to env {}",
                f.episode, f.env
            )),
            Some(&(_, _, true)) => Some(format!(
                "episode {} continues after its done frame",
                f.episode
            )),
            Some(&(_, last, _)) if last.wrapping_add(1) != f.step => Some(format!(
                "episode {} jumps from step {last} to step {}",
                f.episode, f.step
            )),
            _ => None,
        };
        if let Some(p) = problem {
            check.error = Some(format!("frame {index}: {p}"));
            return check;
        }
        seen.insert(f.episode, (f.env, f.step, f.done()));
    }
    check.episodes = seen.len() as u64;
    check
}
