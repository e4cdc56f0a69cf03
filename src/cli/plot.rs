//! `dreampolicy plot`: a run directory's training curves from its metrics.csv.
use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `plot`.
#[derive(clap::Args)]
pub struct PlotArgs {
    /// Run directory.
    run: PathBuf,
}

pub fn run(a: PlotArgs) -> Result<()> {
    let out = dreampolicy::rl::runner::plot_run(&a.run)
        .with_context(|| format!("plotting {}", a.run.display()))?;
    println!("{}", out.display());
    Ok(())
}
