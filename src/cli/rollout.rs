//! `dreampolicy rollout`: the env driven by a fixed policy, with per-term
//! episode rewards, falls, time-outs, blow-ups and terrain levels.
use std::path::PathBuf;

use anyhow::Result;

use dreampolicy::env::rollout::{self, FixedPolicy};

/// Arguments of `rollout`.
#[derive(clap::Args)]
pub struct RolloutArgs {
    #[arg(long, default_value = "configs/terrain_small.yaml")]
    config: PathBuf,
    #[arg(long = "set")]
    sets: Vec<String>,
    /// Batch steps (each steps every env once, 0.02 s).
    #[arg(long, default_value_t = 500)]
    steps: usize,
    #[arg(long, value_enum, default_value_t = FixedPolicy::Zero)]
    policy: FixedPolicy,
    /// Run directory for config.yaml, metrics.csv and log.txt.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overrides env.seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Overrides env.threads.
    #[arg(long)]
    threads: Option<i64>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run(a: RolloutArgs) -> Result<()> {
    let RolloutArgs {
        config,
        mut sets,
        steps,
        policy,
        out,
        seed,
        threads,
        quiet,
        json,
    } = a;
    if let Some(seed) = seed {
        sets.push(format!("env.seed={seed}"));
    }
    if let Some(t) = threads {
        sets.push(format!("env.threads={t}"));
    }
    let cfg = dreampolicy::rl::config::load(&config, &sets)?;
    let mut run_dir = out
        .as_deref()
        .map(|p| dreampolicy::run::RunDir::create(p, &cfg, &rollout::METRICS))
        .transpose()?;
    let s = rollout::rollout(&cfg.env, steps, policy, run_dir.as_mut(), 50, quiet)?;
    let text = serde_json::to_string(&s)?;
    if let Some(run) = run_dir.as_mut() {
        run.log(&format!("rollout {policy:?} {} steps: {text}", s.steps))?;
    }
    if json {
        println!("{text}");
    } else {
        println!(
            "{} envs x {} steps ({:.0} s simulated each), policy {policy:?}: {} episodes ({} falls, {} truncations), {} blow-ups, {} MuJoCo warnings",
            s.n_envs, s.steps, s.steps as f64 * 0.02, s.episodes, s.falls, s.truncations, s.blowups, s.warnings
        );
        println!(
            "reward per step {:.4}, mean terrain level {:.2}",
            s.mean_reward_per_step, s.mean_terrain_level
        );
        if s.episodes > 0 {
            println!("{:<20} {:>12}", "term", "per second");
            for (name, v) in &s.terms {
                println!("{name:<20} {v:>12.4}");
            }
        }
        if let Some(run) = &run_dir {
            println!("run directory: {}", run.path().display());
        }
    }
    Ok(())
}
