//! `dreampolicy benchmark`: the paper's comparison (methods x single, unseen
//! and combined lanes x levels) into a results directory; resumable.
use std::path::PathBuf;

use anyhow::{Context, Result};

use dreampolicy::benchmark::{self, BenchmarkConfig};

/// Arguments of `benchmark`.
#[derive(clap::Args)]
pub struct BenchmarkArgs {
    /// The benchmark file (configs/benchmark/small.yaml, paper.yaml).
    #[arg(long)]
    config: PathBuf,
    /// Output directory (default runs/benchmark/<config name>); a second run
    /// into the same directory keeps the cells already measured.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Override a key of the file, e.g. --set episodes=20 (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Print the summary as one JSON object instead of the report.
    #[arg(long)]
    json: bool,
}

pub fn run(a: BenchmarkArgs) -> Result<()> {
    let cfg = BenchmarkConfig::load(&a.config, &a.sets)?;
    tch::set_num_threads(cfg.threads.max(1) as i32);
    let out = a.out.clone().unwrap_or_else(|| {
        let stem = a
            .config
            .file_stem()
            .map_or("benchmark".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("runs/benchmark").join(stem)
    });
    let quiet = a.json;
    let s = benchmark::run(&cfg, &out, |i, n, cell, kept| {
        if !quiet {
            eprintln!(
                "[{}/{n}] {} {} on {} level {}{}",
                i + 1,
                cell.table.name(),
                cell.method,
                cell.lane(),
                cell.level,
                if kept { ": kept from results.csv" } else { "" }
            );
        }
    })
    .with_context(|| format!("benchmark into {}", out.display()))?;
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    let md = std::fs::read_to_string(out.join("results.md"))?;
    println!("{md}");
    println!(
        "{} cells ({} measured, {} kept) in {:.0} s: {}/results.csv, results.md, <table>_success.png, <table>_bars.png",
        s.cells, s.measured, s.kept, s.wall_s, s.out
    );
    Ok(())
}
