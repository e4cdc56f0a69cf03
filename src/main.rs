//! The `dreampolicy` CLI: one subcommand per pipeline stage.
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

use dreampolicy::{bench, config, robot, sim};

mod data_cli;
mod play_cli;

#[derive(Parser)]
#[command(
    name = "dreampolicy",
    version,
    about = "DreamPolicy for the Unitree G1 on MuJoCo"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// MuJoCo and libtorch versions, device, threads, and the G1 model's sizes.
    Info {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Speed measurements, as ratios against a baseline measured in the same run.
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
    /// Drive the env with a fixed policy (zero or random actions) and report
    /// per-term episode rewards, falls, time-outs, blow-ups and terrain levels.
    Rollout {
        #[arg(long, default_value = "configs/terrain_small.yaml")]
        config: PathBuf,
        #[arg(long = "set")]
        sets: Vec<String>,
        /// Batch steps (each steps every env once, 0.02 s).
        #[arg(long, default_value_t = 500)]
        steps: usize,
        #[arg(long, value_enum, default_value_t = dreampolicy::env::rollout::FixedPolicy::Zero)]
        policy: dreampolicy::env::rollout::FixedPolicy,
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
    },
    /// Train a policy.
    Train {
        #[command(subcommand)]
        which: TrainCommand,
    },
    /// Roll out every terrain specialist on its terrain and write the expert
    /// dataset (MCAP shards, one per specialist and round; existing shards are
    /// kept and skipped, so the same command resumes a crashed collection).
    Collect {
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
    },
    /// Evaluate checkpoints on 10 m lanes: success and completion rates,
    /// velocity-tracking error, falls. Several checkpoints and terrains give the
    /// cross-terrain matrix (a table, JSON and a heatmap PNG). `eval world-model`
    /// evaluates a world-model checkpoint on its validation split instead.
    #[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
    Eval {
        #[command(subcommand)]
        which: Option<EvalCommand>,
        /// Checkpoint to evaluate; repeat (or give a comma-separated list) for a matrix.
        #[arg(long, required = true, value_delimiter = ',')]
        checkpoint: Vec<PathBuf>,
        /// Terrain(s) of the lanes, comma-separated (flat, uneven, stair, gap, bridge, ...).
        #[arg(
            long,
            visible_alias = "terrains",
            default_value = "flat",
            value_delimiter = ','
        )]
        terrain: Vec<String>,
        /// Episodes per checkpoint and terrain.
        #[arg(long, default_value_t = 100)]
        episodes: usize,
        /// Evaluate on the project's default scene (full collisions, MuJoCo's
        /// default solver) instead of the checkpoint's training scene.
        #[arg(long)]
        full_collision: bool,
        /// Lane difficulty level (0 = easiest) instead of the config's
        /// `eval.level`.
        #[arg(long, conflicts_with = "levels")]
        level: Option<usize>,
        /// A level sweep: every checkpoint at each of these levels (`0-9`,
        /// `0,3,5`) on its terrain (one --terrain for all, or one per
        /// checkpoint, paired in order). --out writes the JSON, --plot the
        /// success-rate curves (a line per checkpoint).
        #[arg(long)]
        levels: Option<String>,
        /// The level sweep's PNG (success and completion rate against level).
        #[arg(long, requires = "levels")]
        plot: Option<PathBuf>,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Also write the JSON report (one evaluation) or matrix to this file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Draw the success rates as a heatmap PNG (checkpoints x terrains).
        #[arg(long)]
        heatmap: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Roll a checkpoint's policy out on one lane and write the rollout as an
    /// MCAP file for Foxglove (transforms, robot, terrain, command, state, reward).
    Play(play_cli::PlayArgs),
    /// Draw a run directory's training curves (plots/training.png) from its metrics.csv.
    Plot {
        /// Run directory.
        run: PathBuf,
    },
    /// Export a checkpoint's actor (normalization included) as TorchScript.
    Export {
        #[arg(long)]
        checkpoint: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Procedural terrains.
    Terrain {
        #[command(subcommand)]
        which: TerrainCommand,
    },
    /// The expert dataset (MCAP shards): inspect, verify.
    Data {
        #[command(subcommand)]
        which: data_cli::DataCommand,
    },
}

#[derive(Subcommand)]
enum EvalCommand {
    /// A world-model checkpoint on the validation split of its dataset: error per
    /// horizon step of one call, autoregressive drift over 50 and 250 steps,
    /// guidance 0/1/5, terrain sensitivity (real vs shuffled scandots), DDPM vs
    /// DDIM, and a PNG of real and predicted joint trajectories.
    WorldModel(EvalWmArgs),
}

#[derive(clap::Args)]
struct EvalWmArgs {
    /// World-model checkpoint (`<run>/checkpoints/latest.pt`).
    #[arg(long)]
    checkpoint: PathBuf,
    /// Dataset directory (default: the checkpoint's data.path).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Validation windows per measurement.
    #[arg(long, default_value_t = 64)]
    windows: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// libtorch threads.
    #[arg(long, default_value_t = 1)]
    threads: i64,
    /// Also write the JSON report to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Draw real and predicted joint trajectories of a few windows (PNG).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print the report as one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
enum TrainCommand {
    /// PPO specialist (the flat walker, a terrain specialist) on the G1 env.
    Specialist(TrainArgs),
    /// The diffusion world model on an expert dataset (configs/world_model/*.yaml).
    WorldModel(TrainArgs),
}

/// What every trainer takes.
#[derive(clap::Args)]
struct TrainArgs {
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

#[derive(Subcommand)]
enum TerrainCommand {
    /// Draw a height image with a colour bar: one kind's lane (`--kind`, optionally
    /// joined with `--then`), or the whole curriculum map (`--map`).
    Render {
        /// Terrain kind: flat, uneven, stair, gap, bridge, wave, slope, balancing_beam, slope_bridge.
        #[arg(long, required_unless_present = "map")]
        kind: Option<String>,
        /// Second kind of a combined lane (the paper's pairs, e.g. --kind stair --then gap).
        #[arg(long, requires = "kind")]
        then: Option<String>,
        /// Curriculum level (0 = easiest).
        #[arg(long, default_value_t = 5)]
        level: usize,
        /// Render the whole map of the config instead of one lane.
        #[arg(long, conflicts_with = "kind")]
        map: bool,
        /// Experiment config whose env.terrain.map is used (default: built-in terrain defaults).
        #[arg(long)]
        config: Option<PathBuf>,
        #[arg(long = "set")]
        sets: Vec<String>,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Window reads of the expert dataset vs a raw sequential read of the same shards.
    Data(data_cli::BenchDataArgs),
    /// Time shares of PPO iterations (physics, inference, update) and inference
    /// against bare GEMMs, for the config's network and the paper's sizes.
    Ppo {
        #[arg(long)]
        json: bool,
        #[arg(long, default_value = "configs/specialist/flat.yaml")]
        config: PathBuf,
        #[arg(long = "set")]
        sets: Vec<String>,
        /// Iterations measured per variant (after one warm-up iteration).
        #[arg(long, default_value_t = 5)]
        iterations: usize,
        /// Only the config's network (skip the paper-sized variants).
        #[arg(long)]
        config_only: bool,
    },
    /// World-model sampling latency at batch 1 (DDPM, DDIM 5/10/20) against the
    /// control period, and the denoiser's forward against bare GEMMs of its shapes.
    WorldModel {
        #[arg(long)]
        json: bool,
        #[arg(long, default_value = "configs/world_model/small.yaml")]
        config: PathBuf,
        #[arg(long = "set")]
        sets: Vec<String>,
        /// The paper-sized config measured beside it.
        #[arg(long, default_value = "configs/world_model/paper.yaml")]
        paper_config: PathBuf,
        /// Batch of the paper size's forward measurement (its trainer's 1024 is
        /// minutes per round on a CPU).
        #[arg(long, default_value_t = 128)]
        paper_batch: i64,
        /// Timed rounds per measurement (after one warm-up); the best counts.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Only the config's size.
        #[arg(long)]
        config_only: bool,
    },
    /// Raw mj_step vs our safe Data::step on the standing G1.
    Sim {
        #[arg(long)]
        json: bool,
        /// Physics steps per round.
        #[arg(long, default_value_t = 20_000)]
        steps: usize,
        /// Alternating rounds of raw and safe stepping.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
    },
    /// Raw physics vs VecEnv at 1 and 2 threads, scandots direct vs mj_ray.
    Env {
        #[arg(long)]
        json: bool,
        /// Experiment config whose `env` section is measured.
        #[arg(long, default_value = "configs/terrain_small.yaml")]
        config: PathBuf,
        /// Override a config value, e.g. --set env.n_envs=32 (repeatable).
        #[arg(long = "set")]
        sets: Vec<String>,
        /// Control steps per round.
        #[arg(long, default_value_t = 200)]
        steps: usize,
        /// Alternating rounds (raw, 1 thread, 2 threads); the best of each counts.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
    },
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("error: {}", error_chain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by `: ` (anyhow's `{:#}`), leaving out a
/// cause whose text the message already ends with: our typed errors print
/// their source (`path: No such file or directory`) and also expose it as the
/// source, which would otherwise be printed twice.
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.is_empty() {
            out = text;
        } else if !out.ends_with(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
    }
    out
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Rollout {
            config,
            mut sets,
            steps,
            policy,
            out,
            seed,
            threads,
            quiet,
            json,
        } => {
            if let Some(seed) = seed {
                sets.push(format!("env.seed={seed}"));
            }
            if let Some(t) = threads {
                sets.push(format!("env.threads={t}"));
            }
            let cfg = config::load(&config, &sets)?;
            let mut run_dir = out
                .as_deref()
                .map(|p| {
                    dreampolicy::run::RunDir::create(p, &cfg, &dreampolicy::env::rollout::METRICS)
                })
                .transpose()?;
            let s = dreampolicy::env::rollout::rollout(
                &cfg,
                steps,
                policy,
                run_dir.as_mut(),
                50,
                quiet,
            )?;
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
        Command::Terrain { which } => match which {
            TerrainCommand::Render {
                kind,
                then,
                level,
                map,
                config,
                sets,
                seed,
                out,
            } => terrain_render(kind, then, level, map, config, sets, seed, out),
        },
        Command::Info { json } => info(json),
        Command::Collect {
            config,
            sets,
            out,
            quiet,
            json,
        } => collect_cmd(&config, &sets, &out, quiet, json),
        Command::Eval {
            which: Some(EvalCommand::WorldModel(args)),
            ..
        } => eval_world_model(args),
        Command::Eval {
            which: None,
            checkpoint,
            terrain,
            episodes,
            full_collision,
            level,
            levels,
            plot,
            seed,
            threads,
            out,
            heatmap,
            json,
        } => eval_cmd(EvalArgs {
            checkpoints: checkpoint,
            terrains: terrain,
            episodes,
            full_collision,
            level,
            levels,
            plot,
            seed,
            threads,
            out,
            heatmap,
            json,
        }),
        Command::Play(args) => play_cli::run(args),
        Command::Plot { run } => {
            let out = dreampolicy::rl::runner::plot_run(&run)
                .with_context(|| format!("plotting {}", run.display()))?;
            println!("{}", out.display());
            Ok(())
        }
        Command::Export { checkpoint, out } => {
            let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&checkpoint)?;
            let info = dreampolicy::rl::export::export(&ck, &out).context("export")?;
            println!("{}", serde_json::to_string(&info)?);
            Ok(())
        }
        Command::Train { which } => match which {
            TrainCommand::Specialist(args) => train_specialist(args),
            TrainCommand::WorldModel(args) => train_world_model(args),
        },
        Command::Data { which } => data_cli::run(which),
        Command::Bench { which } => match which {
            BenchCommand::Data(args) => data_cli::bench_data(args),
            BenchCommand::Ppo {
                json,
                config,
                sets,
                iterations,
                config_only,
            } => {
                let cfg = config::load(&config, &sets)?;
                let label = config.display().to_string();
                let r = bench::ppo::ppo(&cfg, &label, 1, iterations.max(1), !config_only)
                    .context("bench ppo")?;
                if json {
                    println!("{}", serde_json::to_string(&r)?);
                } else {
                    println!(
                        "MuJoCo {}, {} torch threads, sgemm {:.0} GFLOP/s",
                        r.mujoco_version, r.torch_threads, r.sgemm_gflops
                    );
                    for v in &r.variants {
                        println!(
                            "{:<18} {:>8} params: {:>6.0} env-steps/s; physics {:.2} inference {:.2} update {:.2}; inference/GEMM {:.2}; update {:.0} samples/s",
                            v.name, v.parameters, v.env_steps_per_s, v.share_physics, v.share_inference,
                            v.share_update, v.inference_gemm_fraction, v.update_samples_per_s
                        );
                    }
                }
                Ok(())
            }
            BenchCommand::WorldModel {
                json,
                config,
                sets,
                paper_config,
                paper_batch,
                rounds,
                config_only,
            } => {
                let cfg = config::load_world_model(&config, &sets)?;
                let paper = if config_only {
                    None
                } else {
                    Some(config::load_world_model(&paper_config, &[])?)
                };
                tch::set_num_threads(cfg.train.torch_threads as i32);
                let r = bench::world_model::world_model(
                    &cfg,
                    paper.as_ref().map(|p| (p, paper_batch.max(1))),
                    rounds,
                );
                if json {
                    println!("{}", serde_json::to_string(&r)?);
                } else {
                    println!(
                        "{} torch threads, control period {} ms",
                        r.torch_threads, r.control_period_ms
                    );
                    for v in &r.variants {
                        let lat: Vec<String> = v
                            .batch1_ms
                            .iter()
                            .map(|(k, ms)| format!("{k} {ms:.1} ms"))
                            .collect();
                        println!(
                            "{:<7} {} x {} ({} params): batch 1 {}; DDIM10 / control period {:.2}; forward at batch {} {:.1} GFLOP/s vs GEMMs {:.1}: gemm_fraction {:.2}",
                            v.name, v.layers, v.hidden, v.parameters, lat.join(", "),
                            v.ddim10_vs_control_period, v.forward_batch, v.forward_gflops,
                            v.gemm_gflops, v.gemm_fraction
                        );
                    }
                }
                Ok(())
            }
            BenchCommand::Sim {
                json,
                steps,
                rounds,
            } => {
                let r = bench::sim(steps, rounds).context("bench sim")?;
                if json {
                    println!("{}", serde_json::to_string(&r)?);
                } else {
                    println!(
                        "MuJoCo {}: raw mj_step {:.0} steps/s, Data::step {:.0} steps/s, ratio {:.3}",
                        r.mujoco_version, r.raw_steps_per_s, r.safe_steps_per_s, r.ratio
                    );
                }
                Ok(())
            }
            BenchCommand::Env {
                json,
                config,
                sets,
                steps,
                rounds,
            } => {
                let cfg = config::load(&config, &sets)?;
                let r = bench::env(&cfg.env, &config.display().to_string(), steps, rounds)
                    .context("bench env")?;
                if json {
                    println!("{}", serde_json::to_string(&r)?);
                } else {
                    println!(
                        "MuJoCo {} ({} envs): raw {:.0} physics steps/s; env 1t {:.0} ({:.3} of raw), 2t {:.0} ({:.2}x); scandots direct {:.2e} pts/s vs mj_ray {:.2e} ({:.0}x); {:.1} contacts/env",
                        r.mujoco_version, r.n_envs, r.raw_physics_steps_per_s, r.env_physics_steps_per_s_1t,
                        r.ratio_1t, r.env_physics_steps_per_s_2t, r.scaling_2t, r.scan_points_per_s_direct,
                        r.scan_points_per_s_ray, r.scan_speedup, r.contacts_per_env
                    );
                }
                Ok(())
            }
        },
    }
}

fn train_specialist(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) =
        train_setup(&args, &["env.threads", "train.torch_threads"], config::load)?;
    let s = dreampolicy::rl::runner::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
        .with_context(|| format!("training in {}", run_path.display()))?;
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
    load: impl Fn(&std::path::Path, &[String]) -> std::result::Result<C, E>,
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
            let cfg = load(&dir.join("config.yaml"), &sets)
                .with_context(|| format!("resuming {}", dir.display()))?;
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
fn fresh_run_dir(config: &std::path::Path, out: Option<&PathBuf>) -> Result<PathBuf> {
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

fn train_world_model(args: TrainArgs) -> Result<()> {
    let (cfg, run_path) = train_setup(&args, &["train.torch_threads"], config::load_world_model)?;
    let s = dreampolicy::world_model::train(&cfg, &run_path, args.resume.is_some(), args.quiet)
        .with_context(|| format!("training the world model in {}", run_path.display()))?;
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn info(json: bool) -> Result<()> {
    let model = Arc::new(robot::load_flat().context("loading the G1 flat scene")?);
    let cuda = tch::Cuda::is_available();
    let device = if cuda {
        format!("cuda ({} devices)", tch::Cuda::device_count())
    } else {
        "cpu".to_string()
    };
    let value = serde_json::json!({
        "mujoco_version": sim::mujoco_version(),
        "mujoco_header_version": mujoco_sys::MUJOCO_VERSION_HEADER,
        "mujoco_lib_dir": mujoco_sys::MUJOCO_LIB_DIR,
        "mujoco_build": if mujoco_sys::MUJOCO_LIB_DIR.starts_with("/usr") {
            "Debian libmujoco-dev (MUJOCO_DIR=system)"
        } else {
            "MUJOCO_DIR (default: the MuJoCo 3.3.7 wheel unpacked by setup)"
        },
        "libtorch_version": env!("DREAMPOLICY_LIBTORCH_VERSION"),
        "torch_device": device,
        "torch_threads": tch::get_num_threads(),
        "cpu_threads": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "g1_scene": model.source(),
        "g1_nq": model.nq(),
        "g1_nv": model.nv(),
        "g1_nu": model.nu(),
        "g1_nbody": model.nbody(),
        "g1_ngeom": model.ngeom(),
        "timestep": model.timestep(),
    });
    if json {
        println!("{value}");
    } else {
        for (k, v) in value.as_object().into_iter().flatten() {
            println!("{k:>22}: {}", v.to_string().trim_matches('"'));
        }
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn terrain_render(
    kind: Option<String>,
    then: Option<String>,
    level: usize,
    map: bool,
    config: Option<PathBuf>,
    sets: Vec<String>,
    seed: u64,
    out: PathBuf,
) -> Result<()> {
    use dreampolicy::terrain::{render, TerrainKind, TerrainMap};
    let cfg = match config {
        Some(path) => config::load(&path, &sets)?.env.terrain.map,
        None => dreampolicy::terrain::TerrainConfig::default(),
    };
    cfg.validate()?;
    if map {
        let m = TerrainMap::generate(&cfg, seed)?;
        render::render_map(&m, &out)?;
        println!(
            "{}: {} levels x {} columns, {:.1} x {:.1} m",
            out.display(),
            m.num_levels(),
            m.num_cols(),
            m.extent()[0],
            m.extent()[1]
        );
        return Ok(());
    }
    let first = TerrainKind::from_name(kind.as_deref().unwrap_or_default())?;
    let lane = match then {
        None => render::render_kind(&cfg, first, level, seed, &out)?,
        Some(second) => {
            let second = TerrainKind::from_name(&second)?;
            let lane = TerrainMap::combined_lane(
                &cfg,
                first,
                second,
                level,
                first.default_lane_length(),
                cfg.tile_width,
                seed,
            )?;
            render::render_lane(&lane, &out)?;
            lane
        }
    };
    println!(
        "{}: level {level}, {:.1} m from spawn to goal",
        out.display(),
        lane.length()
    );
    Ok(())
}

struct EvalArgs {
    checkpoints: Vec<PathBuf>,
    terrains: Vec<String>,
    episodes: usize,
    full_collision: bool,
    level: Option<usize>,
    levels: Option<String>,
    plot: Option<PathBuf>,
    seed: u64,
    threads: usize,
    out: Option<PathBuf>,
    heatmap: Option<PathBuf>,
    json: bool,
}

impl EvalArgs {
    /// The options of one evaluation on `kind` lanes at `level`.
    fn options(
        &self,
        kind: dreampolicy::terrain::TerrainKind,
        level: Option<usize>,
    ) -> dreampolicy::eval::EvalOptions {
        dreampolicy::eval::EvalOptions {
            terrain: kind,
            episodes: self.episodes,
            full_collision: self.full_collision,
            seed: self.seed,
            threads: self.threads.max(1),
            level,
        }
    }
}

/// A checkpoint's short name: the run directory of `<run>/checkpoints/<file>.pt`,
/// else the file stem.
fn checkpoint_name(path: &std::path::Path) -> String {
    let parent = path.parent();
    if parent
        .and_then(|p| p.file_name())
        .is_some_and(|n| n == "checkpoints")
    {
        if let Some(run) = parent.and_then(|p| p.parent()).and_then(|p| p.file_name()) {
            return run.to_string_lossy().into_owned();
        }
    }
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn eval_cmd(a: EvalArgs) -> Result<()> {
    use dreampolicy::{eval, rl::checkpoint::Checkpoint, terrain::TerrainKind};
    let kinds = a
        .terrains
        .iter()
        .map(|t| TerrainKind::from_name(t.trim()))
        .collect::<Result<Vec<_>, _>>()?;
    let cks = a
        .checkpoints
        .iter()
        .map(|p| Checkpoint::read(p))
        .collect::<Result<Vec<_>, _>>()?;
    let names: Vec<String> = a.checkpoints.iter().map(|p| checkpoint_name(p)).collect();
    if let Some(levels) = &a.levels {
        return eval_sweep(&a, levels, &kinds, &cks, &names);
    }
    let mut reports = Vec::with_capacity(cks.len());
    for (ck, name) in cks.iter().zip(&names) {
        let mut row = Vec::with_capacity(kinds.len());
        for &kind in &kinds {
            let opts = a.options(kind, a.level);
            let r = eval::evaluate(ck, &opts)
                .with_context(|| format!("evaluating {name} on {}", kind.name()))?;
            if !a.json {
                println!(
                    "{name}: {} lanes of {:.0} m ({}{}): success {:.3}, completion {:.3}, velocity error {:.3} m/s, {} falls, {} time-outs, mean speed {:.2} m/s (commanded {:.2}), ankle {:.3} m at the top of a swing, {:.3} m in stance, swing rise {:.3} m",
                    r.episodes, r.lane_length, r.terrain,
                    r.level.map(|l| format!(", level {l}")).unwrap_or_default(),
                    r.success_rate, r.completion_rate,
                    r.vel_tracking_error, r.falls, r.timeouts, r.mean_forward_speed, r.mean_commanded_speed,
                    r.swing_peak_height, r.stance_foot_height, r.swing_rise
                );
            }
            row.push(r);
        }
        reports.push(row);
    }
    let single = reports.len() == 1 && kinds.len() == 1;
    let value = if single {
        serde_json::to_value(&reports[0][0])?
    } else {
        serde_json::json!({
            "checkpoints": names,
            "terrains": kinds.iter().map(|k| k.name()).collect::<Vec<_>>(),
            "success_rate": reports.iter().map(|r| r.iter().map(|e| e.success_rate).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "completion_rate": reports.iter().map(|r| r.iter().map(|e| e.completion_rate).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "reports": reports,
        })
    };
    if let Some(path) = &a.out {
        std::fs::write(path, format!("{}\n", serde_json::to_string_pretty(&value)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &a.heatmap {
        let cols: Vec<String> = kinds.iter().map(|k| k.name().to_string()).collect();
        let values: Vec<Vec<f64>> = reports
            .iter()
            .map(|r| r.iter().map(|e| e.success_rate).collect())
            .collect();
        dreampolicy::plot::heatmap(
            path,
            &format!(
                "Success rate over {} lanes of 10 m (rows: policy, columns: terrain)",
                a.episodes
            ),
            &names,
            &cols,
            &values,
        )?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&value)?);
    } else if !single {
        let mut t = format!(
            "| policy | {} |\n|---|",
            kinds
                .iter()
                .map(|k| k.name())
                .collect::<Vec<_>>()
                .join(" | ")
        );
        t.push_str(&"---|".repeat(kinds.len()));
        for (name, row) in names.iter().zip(&reports) {
            t.push_str(&format!("\n| {name} |"));
            for r in row {
                t.push_str(&format!(
                    " {:.2} ({:.2}) |",
                    r.success_rate, r.completion_rate
                ));
            }
        }
        println!("\nsuccess rate (completion rate):\n{t}");
    }
    Ok(())
}

/// `eval --levels`: each checkpoint on its terrain at each level.
fn eval_sweep(
    a: &EvalArgs,
    levels: &str,
    kinds: &[dreampolicy::terrain::TerrainKind],
    cks: &[dreampolicy::rl::checkpoint::Checkpoint],
    names: &[String],
) -> Result<()> {
    use dreampolicy::eval;
    let levels = eval::parse_levels(levels).map_err(anyhow::Error::msg)?;
    if kinds.len() != 1 && kinds.len() != cks.len() {
        anyhow::bail!(
            "a level sweep takes one --terrain for every checkpoint or one per checkpoint; got {} terrains for {} checkpoints",
            kinds.len(),
            cks.len()
        );
    }
    let mut curves = Vec::with_capacity(cks.len());
    // (legend, success rates, completion rates) of each checkpoint
    let mut lines: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::with_capacity(cks.len());
    for (i, (ck, name)) in cks.iter().zip(names).enumerate() {
        let kind = kinds[i.min(kinds.len() - 1)];
        let opts = a.options(kind, None);
        let rs = eval::level_sweep(ck, &opts, &levels)
            .with_context(|| format!("sweeping {name} over {} levels", kind.name()))?;
        if !a.json {
            for r in &rs {
                println!(
                    "{name}: {} level {}: success {:.3}, completion {:.3}, {} falls, {} time-outs",
                    r.terrain,
                    r.level.unwrap_or_default(),
                    r.success_rate,
                    r.completion_rate,
                    r.falls,
                    r.timeouts
                );
            }
        }
        let success: Vec<f64> = rs.iter().map(|r| r.success_rate).collect();
        let completion: Vec<f64> = rs.iter().map(|r| r.completion_rate).collect();
        curves.push(serde_json::json!({
            "checkpoint": name,
            "terrain": kind.name(),
            "success_rate": success,
            "completion_rate": completion,
            "reports": rs,
        }));
        lines.push((format!("{name} on {}", kind.name()), success, completion));
    }
    let value = serde_json::json!({
        "levels": levels,
        "episodes": a.episodes,
        "full_collision": a.full_collision,
        "curves": curves,
    });
    if let Some(path) = &a.out {
        std::fs::write(path, format!("{}\n", serde_json::to_string_pretty(&value)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &a.plot {
        let x: Vec<f64> = levels.iter().map(|&l| l as f64).collect();
        let panel = |completion: bool, title: &str| dreampolicy::plot::SeriesPanel {
            title: title.into(),
            x_label: "level".into(),
            x: x.clone(),
            lines: lines
                .iter()
                .map(|(name, s, c)| (name.clone(), if completion { c } else { s }.clone()))
                .collect(),
        };
        dreampolicy::plot::plot_series(
            path,
            &format!("Level sweep: {} lanes of 10 m per level", a.episodes),
            &[panel(false, "success rate"), panel(true, "completion rate")],
        )?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&value)?);
    }
    Ok(())
}

fn eval_world_model(a: EvalWmArgs) -> Result<()> {
    use dreampolicy::world_model::{evaluate, WmEvalOptions};
    let opts = WmEvalOptions {
        data: a.data,
        windows: a.windows,
        seed: a.seed,
        threads: a.threads.max(1),
        plot: a.plot,
        ..WmEvalOptions::default()
    };
    let r = evaluate(&a.checkpoint, &opts)
        .with_context(|| format!("evaluating the world model {}", a.checkpoint.display()))?;
    if let Some(path) = &a.out {
        std::fs::write(path, format!("{}\n", serde_json::to_string_pretty(&r)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    let kinds: Vec<String> = r
        .windows_per_kind
        .iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect();
    println!(
        "{} (step {}), K {} H {} N {}: {} validation windows ({}) from {} episodes / {} frames of {}; default sampler {:?} guidance {}{}",
        r.checkpoint, r.iteration, r.history, r.horizon, r.diffusion_steps, r.windows,
        kinds.join(", "), r.validation.episodes, r.validation.frames, r.dataset,
        r.sampling.sampler, r.sampling.guidance,
        if r.sampling.sampler == dreampolicy::config::SamplerKind::Ddim {
            format!(" ({} steps)", r.sampling.ddim_steps)
        } else {
            String::new()
        }
    );
    println!("\none call, RMSE per horizon step (normalized; joint_pos in rad):");
    let mut t = String::from("| h | model | hold last | joint_pos (rad) |\n|---|---|---|---|");
    let jp = r.horizon_rmse_raw.get("joint_pos");
    for (i, (m, b)) in r.horizon_rmse.iter().zip(&r.hold_rmse).enumerate() {
        let j = jp
            .and_then(|v| v.get(i))
            .map_or("-".into(), |v| format!("{v:.4}"));
        t.push_str(&format!("\n| {} | {m:.4} | {b:.4} | {j} |", i + 1));
    }
    println!("{t}");
    println!(
        "(baseline: the dataset's mean state scores {:.4})",
        r.mean_state_rmse
    );
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    println!("\nguidance (default sampler):\n| omega | RMSE | RMSE at H | joint_pos (rad) | real vs shuffled scandots |\n|---|---|---|---|---|");
    let mut gs: Vec<_> = r.guidance.values().collect();
    gs.sort_by(|a, b| a.guidance.total_cmp(&b.guidance));
    for g in gs {
        println!(
            "| {} | {:.4} | {:.4} | {} | {:.4} |",
            g.guidance,
            g.error.rmse,
            g.error.rmse_last,
            opt(g.error.joint_pos_rmse),
            g.terrain_distance
        );
    }
    println!("\nterrain sensitivity (default sampler; shuffled scandots, same noise):\n| terrain | windows | scandots differ (m) | distance | seed spread | ratio | RMSE real | RMSE shuffled |\n|---|---|---|---|---|---|---|---|");
    for (kind, s) in &r.terrain_sensitivity {
        println!(
            "| {kind} | {} | {:.3} ({}) | {:.4} | {:.4} | {} | {:.4} | {:.4} |",
            s.windows,
            s.scan_distance_m,
            s.donor,
            s.distance,
            s.seed_spread,
            s.ratio.map_or("-".into(), |v| format!("{v:.2}")),
            s.rmse_real,
            s.rmse_shuffled
        );
    }
    println!("\nsamplers (guidance {}):\n| sampler | RMSE | RMSE at H | joint_pos (rad) | ms per call ({} windows) | ms at batch 1 |\n|---|---|---|---|---|---|", r.sampling.guidance, r.windows);
    let mut ss: Vec<_> = r.samplers.iter().collect();
    ss.sort_by_key(|(_, s)| (s.sampler == dreampolicy::config::SamplerKind::Ddim, s.steps));
    for (name, s) in ss {
        println!(
            "| {name} | {:.4} | {:.4} | {} | {:.1} | {:.1} |",
            s.error.rmse,
            s.error.rmse_last,
            opt(s.error.joint_pos_rmse),
            s.batch_ms,
            s.batch1_ms
        );
    }
    println!("\nautoregressive drift (real history, the dataset's scandots at each call):\n| frames | windows | RMSE at end | RMSE mean | joint_pos at end (rad) | hold last: end, mean | mean state |\n|---|---|---|---|---|---|---|");
    let mut ds: Vec<_> = r.drift.values().collect();
    ds.sort_by_key(|d| d.frames);
    for d in ds {
        match (&d.metrics, &d.reason) {
            (Some(m), _) => println!(
                "| {} | {} | {:.4} | {:.4} | {} | {:.4}, {:.4} | {:.4} |",
                d.frames,
                d.windows,
                m.rmse_final,
                m.rmse_mean,
                opt(m.joint_pos_rmse_final),
                m.hold_rmse_final,
                m.hold_rmse_mean,
                m.mean_state_rmse
            ),
            (None, reason) => println!(
                "| {} | 0 | - | - | - | - | - |  {}",
                d.frames,
                reason.as_deref().unwrap_or_default()
            ),
        }
    }
    if let Some(p) = &r.plot {
        println!("\nplot: {p}");
    }
    println!(
        "({:.0} s, {} torch threads)",
        r.wall_time_s, r.torch_threads
    );
    Ok(())
}

fn collect_cmd(
    config: &std::path::Path,
    sets: &[String],
    out: &std::path::Path,
    quiet: bool,
    json: bool,
) -> Result<()> {
    use dreampolicy::collect::{collect, CollectConfig};
    let cfg = CollectConfig::load(config, sets)?;
    let text = serde_yaml::to_string(&cfg)?;
    let s = collect(&cfg, &text, out, quiet)
        .with_context(|| format!("collecting into {}", out.display()))?;
    let report = serde_json::to_string_pretty(&s)?;
    std::fs::write(out.join("collect.json"), format!("{report}\n"))
        .with_context(|| format!("writing {}", out.join("collect.json").display()))?;
    if json {
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
