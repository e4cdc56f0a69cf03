//! `dreampolicy train ...`: the PPO specialist, the diffusion world model and
//! the unified policy, fresh or resumed.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Subcommand;

#[derive(Subcommand)]
pub enum TrainCommand {
    /// PPO specialist (the flat walker, a terrain specialist) on the G1 env.
    Specialist(TrainArgs),
    /// The diffusion world model on an expert dataset (configs/world_model/*.yaml).
    WorldModel(TrainArgs),
    /// The unified policy: PPO against the world model's plans, with body-space
    /// tracking and diffusion-AMP style rewards (configs/unified/*.yaml, `task: unified`).
    Unified(TrainArgs),
    /// The distillation baseline: a student trained online on the mixed map by
    /// supervision from the specialist of each env's terrain, with DAgger's
    /// schedule (configs/baselines/dagger*.yaml, a `dagger:` section).
    Dagger(TrainArgs),
    /// The ablation without goal-conditioned RL: checks the world model of the
    /// config's `no_gcrl:` section against its env and writes the controller
    /// checkpoint that `eval` and `benchmark` run (nothing is learned;
    /// configs/baselines/no_gcrl.yaml).
    NoGcrl(TrainArgs),
    /// The ablation without the diffusion world model: PPO with a standard AMP
    /// discriminator whose real transitions come from the expert dataset
    /// (configs/baselines/no_diffusion.yaml, `task: no_diffusion`).
    NoDiffusion(TrainArgs),
}

/// What every trainer takes.
#[derive(clap::Args)]
pub struct TrainArgs {
    /// Experiment config (YAML).
    #[arg(long, required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Override a config value, e.g. --set ppo.learning_rate=1e-4 (repeatable).
    #[arg(long = "set")]
    sets: Vec<String>,
    /// Run directory (default runs/<config name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Continue the run in this directory from its latest checkpoint (its
    /// config.yaml, plus any --set, e.g. a larger train.iterations).
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Overrides train.seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Overrides env.threads and train.torch_threads.
    #[arg(long)]
    threads: Option<i64>,
    /// Plain log lines instead of a progress bar.
    #[arg(long)]
    quiet: bool,
}

pub fn run(which: TrainCommand) -> Result<()> {
    match which {
        TrainCommand::Specialist(args) => train_specialist(args),
        TrainCommand::WorldModel(args) => train_world_model(args),
        TrainCommand::Unified(args) => train_unified(args),
        TrainCommand::Dagger(args) => train_dagger(args),
        TrainCommand::NoGcrl(args) => train_no_gcrl(args),
        TrainCommand::NoDiffusion(args) => train_no_diffusion(args),
    }
}

fn train_no_diffusion(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(
        &args,
        &["env.threads", "train.torch_threads"],
        dreampolicy::rl::config::load,
    )?;
    let s = dreampolicy::baselines::no_diffusion::train(
        &cfg,
        &run_path,
        args.resume.is_some(),
        args.quiet,
    )
    .with_context(|| {
        format!(
            "training the w/o-diffusion policy in {}",
            run_path.display()
        )
    })?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn train_no_gcrl(args: TrainArgs) -> Result<()> {
    if args.resume.is_some() {
        anyhow::bail!("train no-gcrl learns nothing, so there is nothing to resume: run it again with --config");
    }
    let (cfg, run_path) = train_setup(&args, &["env.threads"], dreampolicy::rl::config::load)?;
    let meta = dreampolicy::baselines::no_gcrl::train(&cfg, &run_path)
        .with_context(|| format!("writing the w/o-GCRL controller in {}", run_path.display()))?;
    println!(
        "{}",
        serde_json::json!({
            "checkpoint": dreampolicy::run::latest_checkpoint(&run_path),
            "iterations": meta.iteration,
            "env_steps": meta.env_steps,
        })
    );
    Ok(())
}

fn train_dagger(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(
        &args,
        &["env.threads", "train.torch_threads"],
        dreampolicy::rl::config::load,
    )?;
    let s =
        dreampolicy::baselines::dagger::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
            .with_context(|| format!("training the DAgger student in {}", run_path.display()))?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn train_unified(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(
        &args,
        &["env.threads", "train.torch_threads"],
        dreampolicy::rl::config::load,
    )?;
    let s = dreampolicy::unified::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
        .with_context(|| format!("training the unified policy in {}", run_path.display()))?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn train_specialist(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(
        &args,
        &["env.threads", "train.torch_threads"],
        dreampolicy::rl::config::load,
    )?;
    let s = dreampolicy::rl::runner::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
        .with_context(|| format!("training in {}", run_path.display()))?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn train_world_model(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(
        &args,
        &["train.torch_threads"],
        dreampolicy::world_model::config::load_world_model,
    )?;
    let s = dreampolicy::world_model::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
        .with_context(|| format!("training the world model in {}", run_path.display()))?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

/// The config and run directory of a `train` subcommand: `--resume DIR`
/// reloads `DIR/config.yaml`, else `--config` goes into a fresh run directory;
/// `--seed` sets `train.seed` and `--threads` every key of `thread_keys`
/// (appended after the `--set` overrides, as before).
fn train_setup<C, E>(
    args: &TrainArgs,
    thread_keys: &[&str],
    load: impl Fn(&Path, &[String]) -> std::result::Result<C, E>,
) -> Result<(C, PathBuf)>
where
    E: std::error::Error + Send + Sync + 'static,
{
    let mut sets = args.sets.clone();
    if let Some(seed) = args.seed {
        sets.push(format!("train.seed={seed}"));
    }
    if let Some(t) = args.threads {
        sets.extend(thread_keys.iter().map(|k| format!("{k}={t}")));
    }
    match &args.resume {
        Some(dir) => {
            let cfg_path = dir.join("config.yaml");
            dreampolicy::config::require_seal(&cfg_path)
                .with_context(|| format!("resuming {}", dir.display()))?;
            let cfg =
                load(&cfg_path, &sets).with_context(|| format!("resuming {}", dir.display()))?;
            Ok((cfg, dir.clone()))
        }
        None => {
            let path = args.config.as_ref().context("--config is required")?;
            let cfg = load(path, &sets)?;
            Ok((cfg, fresh_run_dir(path, args.out.as_ref())?))
        }
    }
}

/// The run directory of a fresh run: `--out`, or `runs/<config name>`; refused
/// when it already holds a run.
fn fresh_run_dir(config: &Path, out: Option<&PathBuf>) -> Result<PathBuf> {
    let stem = config
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "run".into());
    let out = out
        .cloned()
        .unwrap_or_else(|| PathBuf::from("runs").join(stem));
    if dreampolicy::run::latest_checkpoint(&out).exists() {
        anyhow::bail!(
            "{} already holds a run: continue it with --resume {0}, or choose another --out",
            out.display()
        );
    }
    Ok(out)
}
