//! `dreampolicy checkpoint verify|seal`: the integrity seal of checkpoint files
//! (`dreampolicy::checkpoint`: a SHA-256 in the archive's zip comment, checked
//! at every load).
use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Subcommand;

#[derive(Subcommand)]
pub enum CheckpointCommand {
    /// Check the seal of checkpoint files (PPO and world model): one `ok` or
    /// `BAD` line per file; exits non-zero naming the bad ones.
    Verify {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Seal checkpoint files written before checkpoints were sealed. Only for
    /// files you trust: nothing can tell whether their bytes are the ones that
    /// were saved. A sealed file is refused.
    Seal {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
}

pub fn run(which: CheckpointCommand) -> Result<()> {
    match which {
        CheckpointCommand::Verify { files } => {
            let mut bad = Vec::new();
            for f in &files {
                match dreampolicy::checkpoint::verify_file(f) {
                    Ok(()) => println!("ok   {}", f.display()),
                    Err(e) => {
                        println!("BAD  {e}");
                        bad.push(f.display().to_string());
                    }
                }
            }
            if !bad.is_empty() {
                bail!(
                    "{} of {} files failed: {}",
                    bad.len(),
                    files.len(),
                    bad.join(", ")
                );
            }
            Ok(())
        }
        CheckpointCommand::Seal { files } => {
            for f in &files {
                dreampolicy::checkpoint::seal_file(f)?;
                eprintln!(
                    "warning: sealed {} as it is; its weights were not checked against anything",
                    f.display()
                );
            }
            Ok(())
        }
    }
}
