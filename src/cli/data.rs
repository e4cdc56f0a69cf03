//! `dreampolicy data ...`: the expert dataset's inspection and verification
//! on the command line.
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Subcommand;

use dreampolicy::data::{self, inspect, Dims, ReadOptions};

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
