//! `dreampolicy collect`: every terrain specialist rolled out on its terrain
//! into the expert dataset's MCAP shards.
use std::path::PathBuf;

use anyhow::{Context, Result};

use dreampolicy::collect::{collect, CollectConfig};

/// Arguments of `collect`.
#[derive(clap::Args)]
pub struct CollectArgs {
    #[arg(long)]
    config: PathBuf,
    /// Override a config value: `--set n_envs=16` (repeatable).
    #[arg(long = "set")]
    sets: Vec<String>,
    /// Dataset directory.
    #[arg(long, default_value = "runs/dataset")]
    out: PathBuf,
    #[arg(long)]
    quiet: bool,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run(a: CollectArgs) -> Result<()> {
    let out = &a.out;
    let cfg = CollectConfig::load(&a.config, &a.sets)?;
    let text = serde_yaml::to_string(&cfg)?;
    let s = collect(&cfg, &text, out, a.quiet)
        .with_context(|| format!("collecting into {}", out.display()))?;
    let report = serde_json::to_string_pretty(&s)?;
    std::fs::write(out.join("collect.json"), format!("{report}\n"))
        .with_context(|| format!("writing {}", out.join("collect.json").display()))?;
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
    } else {
        for sh in &s.shards {
            if sh.skipped {
                println!(
                    "shard {:>3} {:<7} round {}: already there, skipped",
                    sh.shard, sh.terrain, sh.round
                );
            } else {
                println!(
                    "shard {:>3} {:<7} round {}: {} frames, {} episodes ({} falls), {:.1} MB in {:.0} s",
                    sh.shard, sh.terrain, sh.round, sh.frames, sh.episodes, sh.falls,
                    sh.bytes as f64 / 1e6, sh.seconds
                );
            }
        }
        println!(
            "{}: {} frames written in {:.0} s ({:.0} frames/s), {:.1} bytes/frame on disk ({} raw), {} falls in {} episodes",
            s.dir, s.frames, s.seconds, s.frames_per_s, s.bytes_per_frame, s.raw_bytes_per_frame, s.falls, s.episodes
        );
    }
    Ok(())
}
