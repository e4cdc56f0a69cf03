//! `dreampolicy export`: a checkpoint as a deployment bundle (TorchScript policy
//! and `deploy.yaml`), or with `--torchscript-only` the TorchScript file alone.
//! A unified policy's bundle holds the policy, the world model's denoiser and
//! `unified.json` (`dreampolicy::unified::export`).
use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `export`.
#[derive(clap::Args)]
pub struct ExportArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    /// The bundle directory (created): `policy.pt` and `deploy.yaml`; with
    /// --torchscript-only, the TorchScript file to write
    #[arg(long)]
    out: PathBuf,
    /// Write only the TorchScript file (no bundle)
    #[arg(long)]
    torchscript_only: bool,
}

pub fn run(a: ExportArgs) -> Result<()> {
    let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&a.checkpoint)?;
    if ck.config()?.task == dreampolicy::rl::config::TaskKind::Unified {
        if a.torchscript_only {
            anyhow::bail!(
                "{}: a unified policy needs its world model's plan; export it as a bundle \
                 (drop --torchscript-only): policy.pt, denoiser.pt and unified.json",
                a.checkpoint.display()
            );
        }
        let info = dreampolicy::unified::export::write_bundle(&ck, &a.out).context("export")?;
        println!("{}", serde_json::to_string(&info)?);
        return Ok(());
    }
    if a.torchscript_only {
        let info = dreampolicy::rl::export::export(&ck, &a.out).context("export")?;
        println!("{}", serde_json::to_string(&info)?);
    } else {
        let info = dreampolicy::deploy::write_bundle(&ck, &a.out).context("export")?;
        println!("{}", serde_json::to_string(&info)?);
    }
    Ok(())
}
