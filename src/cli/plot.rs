//! `dreampolicy plot`: a run directory's training curves from its metrics.csv.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// Arguments of `plot`.
#[derive(clap::Args)]
pub struct PlotArgs {
    /// Run directory (any trainer's: PPO, unified, the baselines, world model).
    run: PathBuf,
}

/// Which trainer wrote a run's `metrics.csv`, read from its columns: each
/// trainer draws its own panels.
#[derive(Debug, PartialEq, Eq)]
enum Curves {
    /// PPO: specialists, the unified policy, w/o diffusion (shared columns).
    Ppo,
    Dagger,
    WorldModel,
}

fn curves_of(run: &Path) -> Result<Curves> {
    let path = run.join("metrics.csv");
    let header = dreampolicy::plot::MetricsTable::header(&path)
        .with_context(|| format!("reading {} (is this a run directory?)", path.display()))?;
    let has = |c: &str| header.iter().any(|h| h == c);
    Ok(if has("imitation_loss") {
        Curves::Dagger
    } else if has("val_loss") {
        Curves::WorldModel
    } else {
        Curves::Ppo
    })
}

pub fn run(a: PlotArgs) -> Result<()> {
    let out = match curves_of(&a.run)? {
        Curves::Ppo => dreampolicy::rl::runner::plot_run(&a.run),
        Curves::Dagger => dreampolicy::baselines::dagger::plot_run(&a.run),
        Curves::WorldModel => dreampolicy::world_model::trainer::plot_run(&a.run),
    }
    .with_context(|| format!("plotting {}", a.run.display()))?;
    println!("{}", out.display());
    Ok(())
}
