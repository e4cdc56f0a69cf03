//! `bench data`: the window reader (MCAP decode, frames, windows, shuffle buffer)
//! against a raw sequential read of the same shards in the same run: the MCAP
//! records streamed and decompressed with every message payload touched but not
//! decoded (`raw`), and the plain file bytes (`file`). With a world-model config,
//! also the `headroom`: the reader's sequences/s at that trainer's window spec
//! (`K + T H` frames) over the trainer's sequences/s on the same shards (its
//! fully supervised phase, the one that asks the most of the data).
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mcap::records::op;
use mcap::sans_io::{LinearReadEvent, LinearReader};
use serde::Serialize;

use crate::data::{
    episode_id, DataError, Dataset, DatasetInfo, Dims, Frame, ReadOptions, ShardWriter, Shuffle,
    WindowSpec, WriterOptions,
};
use crate::terrain::TerrainKind;

/// Result of `bench data`.
#[derive(Debug, Clone, Serialize)]
pub struct DataBench {
    pub dir: String,
    /// True when the shards were written by the bench (synthetic frames).
    pub synthetic: bool,
    pub shards: usize,
    pub frames: u64,
    pub bytes_on_disk: u64,
    pub bytes_per_frame_on_disk: f64,
    pub frame_bytes: usize,
    pub history: usize,
    pub horizon: usize,
    pub shuffle_capacity: usize,
    pub rounds: usize,
    pub windows: u64,
    /// Windows out of the shuffle buffer per second (best round).
    pub windows_per_s: f64,
    /// Frames through the window pipeline per second.
    pub window_frames_per_s: f64,
    /// Frames per second of the raw MCAP read (decompressed, payload touched).
    pub raw_frames_per_s: f64,
    /// Plain sequential file read, MB/s.
    pub file_mb_per_s: f64,
    /// window_frames_per_s / raw_frames_per_s; the goal is >= 0.5.
    pub read_vs_raw: f64,
    /// window pipeline bytes on disk per second / plain file read.
    pub read_vs_file: f64,
    /// The world-model trainer's sequences/s on these shards (None without a config).
    pub trainer_sequences_per_s: Option<f64>,
    /// The reader's sequences/s at the trainer's spec and this shuffle buffer.
    pub reader_sequences_per_s: Option<f64>,
    /// `reader_sequences_per_s / trainer_sequences_per_s`; above 1 the reader keeps up.
    pub headroom: Option<f64>,
}

/// The reader against the world-model trainer of `cfg` on the shards at `path`:
/// `(reader sequences/s, trainer sequences/s)`.
pub fn headroom(
    path: &Path,
    cfg: &crate::world_model::config::WorldModelConfig,
    shuffle_capacity: usize,
    batches: usize,
) -> Result<(f64, f64), crate::world_model::WmError> {
    let mut cfg = cfg.clone();
    cfg.data.path = path.display().to_string();
    cfg.data.shuffle = shuffle_capacity;
    let spec = crate::world_model::sequences::Sequences::spec(&cfg)?;
    let ds = Dataset::open(path, ReadOptions::default())?;
    let t = Instant::now();
    let mut count = 0u64;
    for w in Shuffle::new(ds.windows(spec, None), shuffle_capacity, 0) {
        std::hint::black_box(&w?);
        count += 1;
    }
    let reader = count as f64 / t.elapsed().as_secs_f64();
    let trainer = crate::bench::world_model::trainer_sequences_per_s(&cfg, batches, false)?;
    Ok((reader, trainer))
}

/// Synthetic episodes: `n_envs` envs in lockstep for `steps` steps, episode
/// lengths varying per env, smooth signals plus a little noise.
pub fn write_synthetic(dir: &Path, shards: u32, n_envs: u32, steps: u32) -> Result<(), DataError> {
    let dims = Dims::G1;
    let info = DatasetInfo {
        config: "bench: synthetic frames\n".into(),
        ..Default::default()
    };
    let mut f = Frame::zeros(dims);
    let mut noise = 0x2545_F491_4F6C_DD1Du64;
    for shard in 0..shards {
        let mut w = ShardWriter::create(dir, shard, dims, info.clone(), WriterOptions::default())?;
        let mut ordinal = 0u32;
        let mut ep: Vec<(u64, u32, u32)> = (0..n_envs)
            .map(|e| {
                ordinal += 1;
                (episode_id(shard, ordinal - 1), 0, 200 + 37 * (e % 23))
            })
            .collect();
        for _ in 0..steps {
            for (env, (id, step, len)) in ep.iter_mut().enumerate() {
                f.episode = *id;
                f.env = env as u32;
                f.step = *step;
                f.terrain = TerrainKind::TRAINING[env % 5];
                f.level = (env % 10) as u32;
                f.terminated = *step + 1 == *len && env % 2 == 0;
                f.truncated = *step + 1 == *len && env % 2 == 1;
                let t = *step as f32 * 0.02;
                for (i, v) in f
                    .state
                    .iter_mut()
                    .chain(&mut f.action)
                    .chain(&mut f.scan)
                    .enumerate()
                {
                    noise ^= noise << 13;
                    noise ^= noise >> 7;
                    noise ^= noise << 17;
                    *v = (t * (1.0 + i as f32 * 0.1)).sin() + (noise >> 40) as f32 * 1e-9;
                }
                f.pos = [t as f64, env as f64, 0.75];
                w.write(&f)?;
                *step += 1;
                if f.done() {
                    ordinal += 1;
                    *id = episode_id(shard, ordinal - 1);
                    *step = 0;
                }
            }
        }
        w.finish()?;
    }
    Ok(())
}

fn raw_read(shards: &[PathBuf]) -> Result<(u64, u64), DataError> {
    let (mut frames, mut touch) = (0u64, 0u64);
    let mut buf = Vec::new();
    for p in shards {
        let mut file = File::open(p).map_err(|e| DataError::io(p, e))?;
        let mut r = LinearReader::new();
        while let Some(ev) = r.next_event() {
            match ev.map_err(|source| DataError::Mcap {
                path: p.clone(),
                source,
            })? {
                LinearReadEvent::ReadRequest(n) => {
                    let got = file.read(r.insert(n)).map_err(|e| DataError::io(p, e))?;
                    r.notify_read(got);
                }
                LinearReadEvent::Record { opcode, data } if opcode == op::MESSAGE => {
                    buf.clear();
                    buf.extend_from_slice(data);
                    touch =
                        touch.wrapping_add(buf.iter().step_by(64).map(|&b| b as u64).sum::<u64>());
                    frames += 1;
                }
                _ => {}
            }
        }
    }
    Ok((frames, touch))
}

fn file_read(shards: &[PathBuf]) -> Result<u64, DataError> {
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0u64;
    for p in shards {
        let mut file = File::open(p).map_err(|e| DataError::io(p, e))?;
        loop {
            let n = file.read(&mut buf).map_err(|e| DataError::io(p, e))?;
            if n == 0 {
                break;
            }
            total += n as u64;
        }
    }
    Ok(total)
}

/// Measure on `dir` (or on synthetic shards of `frames` frames written to `out`,
/// kept, or to a temporary directory, removed, when `dir` is `None`), best of
/// `rounds` alternating rounds; with `trainer`, the [`headroom`] too.
pub fn data(
    dir: Option<&Path>,
    out: Option<&Path>,
    frames: u32,
    spec: WindowSpec,
    shuffle_capacity: usize,
    rounds: usize,
    trainer: Option<&crate::world_model::config::WorldModelConfig>,
) -> Result<DataBench, DataError> {
    let tmp = std::env::temp_dir().join(format!("dreampolicy-bench-data-{}", std::process::id()));
    let (path, synthetic) = match (dir, out) {
        (Some(d), _) => (d.to_path_buf(), false),
        (None, Some(o)) => (o.to_path_buf(), true),
        (None, None) => {
            let _ = std::fs::remove_dir_all(&tmp);
            (tmp.clone(), true)
        }
    };
    if synthetic {
        let n_envs = 64;
        write_synthetic(&path, 2, n_envs, (frames / (2 * n_envs)).max(1))?;
    }
    let mut result = measure(&path, synthetic, spec, shuffle_capacity, rounds);
    if let (Ok(r), Some(cfg)) = (&mut result, trainer) {
        match headroom(&path, cfg, shuffle_capacity, 2) {
            Ok((reader, train)) => {
                r.reader_sequences_per_s = Some(reader);
                r.trainer_sequences_per_s = Some(train);
                r.headroom = Some(reader / train);
            }
            Err(e) => result = Err(DataError::Invalid(format!("headroom: {e}"))),
        }
    }
    if synthetic && out.is_none() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn measure(
    path: &Path,
    synthetic: bool,
    spec: WindowSpec,
    shuffle_capacity: usize,
    rounds: usize,
) -> Result<DataBench, DataError> {
    let ds = Dataset::open(path, ReadOptions::default())?;
    let shards = ds.shards().to_vec();
    let bytes: u64 = shards
        .iter()
        .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
        .sum();
    let (mut best_raw, mut best_win, mut best_file) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let (mut frames, mut windows) = (0, 0);
    for _ in 0..rounds.max(1) {
        let t = Instant::now();
        let (n, touch) = raw_read(&shards)?;
        best_raw = best_raw.min(t.elapsed().as_secs_f64());
        std::hint::black_box(touch);
        frames = n;

        let t = Instant::now();
        file_read(&shards)?;
        best_file = best_file.min(t.elapsed().as_secs_f64());

        let t = Instant::now();
        let mut count = 0u64;
        for w in Shuffle::new(ds.windows(spec, None), shuffle_capacity, 0) {
            std::hint::black_box(&w?);
            count += 1;
        }
        best_win = best_win.min(t.elapsed().as_secs_f64());
        windows = count;
    }
    let raw_fps = frames as f64 / best_raw;
    let win_fps = frames as f64 / best_win;
    let file_bps = bytes as f64 / best_file;
    Ok(DataBench {
        dir: path.display().to_string(),
        synthetic,
        shards: shards.len(),
        frames,
        bytes_on_disk: bytes,
        bytes_per_frame_on_disk: bytes as f64 / frames.max(1) as f64,
        frame_bytes: ds.dims().frame_bytes(),
        history: spec.history,
        horizon: spec.horizon,
        shuffle_capacity,
        rounds: rounds.max(1),
        windows,
        windows_per_s: windows as f64 / best_win,
        window_frames_per_s: win_fps,
        raw_frames_per_s: raw_fps,
        file_mb_per_s: file_bps / 1e6,
        read_vs_raw: win_fps / raw_fps,
        read_vs_file: (bytes as f64 / best_win) / file_bps,
        trainer_sequences_per_s: None,
        reader_sequences_per_s: None,
        headroom: None,
    })
}
