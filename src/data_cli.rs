//! `dreampolicy data ...` and `dreampolicy bench data`: the expert dataset's
//! inspection, verification and read benchmark on the command line.
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Subcommand;

use dreampolicy::bench;
use dreampolicy::data::{self, inspect, Dims, ReadOptions, WindowSpec};

#[derive(Subcommand)]
pub enum DataCommand {
    /// Frames and episodes per terrain, an episode-length histogram and state
    /// statistics of a shard or a dataset directory.
    Inspect {
        /// A shard (`.mcap`, or an unfinished `.mcap.tmp`) or a dataset directory.
        path: PathBuf,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Also write the statistics as stats.json in the directory.
        #[arg(long)]
        save_stats: bool,
    },
    /// Read every shard of a dataset directory to its end; non-zero exit if any is bad.
    Verify {
        dir: PathBuf,
        #[arg(long)]
        json: bool,
    },
}

/// Arguments of `bench data`.
#[derive(clap::Args)]
pub struct BenchDataArgs {
    #[arg(long)]
    json: bool,
    /// Dataset directory to read (default: synthetic shards written to a temporary directory).
    #[arg(long, conflicts_with = "out")]
    dir: Option<PathBuf>,
    /// Write the synthetic shards into this directory and keep them.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Frames of the synthetic dataset.
    #[arg(long, default_value_t = 200_000)]
    frames: u32,
    /// Window history K (frames up to and including the anchor).
    #[arg(long, default_value_t = 8)]
    history: usize,
    /// Window horizon H (frames after the anchor).
    #[arg(long, default_value_t = 8)]
    horizon: usize,
    /// Shuffle buffer capacity (windows).
    #[arg(long, default_value_t = 1024)]
    shuffle: usize,
    /// Alternating rounds (raw, file, windows); the best of each counts.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// World-model config whose trainer the reader is set against (`headroom`).
    #[arg(long, default_value = "configs/world_model/small.yaml")]
    wm_config: PathBuf,
    /// Skip the headroom measurement.
    #[arg(long)]
    no_headroom: bool,
}

pub fn run(cmd: DataCommand) -> Result<()> {
    match cmd {
        DataCommand::Inspect {
            path,
            json,
            save_stats,
        } => {
            let r = inspect::inspect(&path, ReadOptions::default())
                .with_context(|| format!("inspecting {}", path.display()))?;
            for w in &r.warnings {
                eprintln!("warning: {w}");
            }
            if save_stats {
                if !path.is_dir() {
                    bail!(
                        "--save-stats needs a dataset directory, {} is a file",
                        path.display()
                    );
                }
                r.stats.save(&path)?;
                eprintln!("wrote {}", path.join(data::stats::STATS_FILE).display());
            }
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                print!("{}", r.render());
            }
            Ok(())
        }
        DataCommand::Verify { dir, json } => {
            let checks = inspect::verify(&dir, Dims::G1)
                .with_context(|| format!("verifying {}", dir.display()))?;
            let bad: Vec<_> = checks.iter().filter(|c| c.error.is_some()).collect();
            if json {
                println!("{}", serde_json::to_string(&checks)?);
            } else {
                for c in &checks {
                    match &c.error {
                        None => println!(
                            "ok   {} ({} frames, {} episodes)",
                            c.path.display(),
                            c.frames,
                            c.episodes
                        ),
                        Some(e) => println!("BAD  {}: {e}", c.path.display()),
                    }
                }
            }
            if !bad.is_empty() {
                let names: Vec<String> = bad.iter().map(|c| c.path.display().to_string()).collect();
                bail!(
                    "{} of {} shards are bad: {}",
                    bad.len(),
                    checks.len(),
                    names.join(", ")
                );
            }
            Ok(())
        }
    }
}

pub fn bench_data(a: BenchDataArgs) -> Result<()> {
    let spec = WindowSpec::new(a.history, a.horizon)?;
    let wm = if a.no_headroom {
        None
    } else {
        let cfg = dreampolicy::config::load_world_model(&a.wm_config, &[])
            .with_context(|| "the headroom needs a world-model config (--no-headroom skips it)")?;
        tch::set_num_threads(cfg.train.torch_threads as i32);
        Some(cfg)
    };
    let r = bench::data::data(
        a.dir.as_deref(),
        a.out.as_deref(),
        a.frames,
        spec,
        a.shuffle,
        a.rounds,
        wm.as_ref(),
    )
    .context("bench data")?;
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "{} frames in {} shards ({:.0} bytes/frame on disk, {} raw): windows K={} H={} {:.0}/s ({:.0} frames/s) vs raw MCAP read {:.0} frames/s: read_vs_raw {:.2}; plain file read {:.0} MB/s (read_vs_file {:.3})",
            r.frames, r.shards, r.bytes_per_frame_on_disk, r.frame_bytes, r.history, r.horizon,
            r.windows_per_s, r.window_frames_per_s, r.raw_frames_per_s, r.read_vs_raw,
            r.file_mb_per_s, r.read_vs_file
        );
        if let (Some(h), Some(rd), Some(tr)) = (
            r.headroom,
            r.reader_sequences_per_s,
            r.trainer_sequences_per_s,
        ) {
            println!(
                "headroom {h:.0}: the reader gives {rd:.0} sequences/s at the world-model trainer's spec, the trainer takes {tr:.1}/s"
            );
        }
    }
    Ok(())
}
