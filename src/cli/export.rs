//! `dreampolicy export`: a checkpoint's actor as TorchScript.
use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `export`.
#[derive(clap::Args)]
pub struct ExportArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: ExportArgs) -> Result<()> {
    let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&a.checkpoint)?;
    let info = dreampolicy::rl::export::export(&ck, &a.out).context("export")?;
    println!("{}", serde_json::to_string(&info)?);
    Ok(())
}
