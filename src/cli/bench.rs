//! `dreampolicy bench ...`: speed measurements, as ratios against a baseline
//! measured in the same run.
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;

use dreampolicy::bench;
use dreampolicy::data::WindowSpec;
use dreampolicy::rl::config;
use dreampolicy::world_model::config::load_world_model;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Window reads of the expert dataset vs a raw sequential read of the same shards.
    Data(BenchDataArgs),
    /// Time shares of PPO iterations (physics, inference, update) and inference
    /// against bare GEMMs, for the config's network and the paper's sizes.
    Ppo(PpoArgs),
    /// World-model sampling latency at batch 1 (DDPM, DDIM 5/10/20) against the
    /// control period, and the denoiser's forward against bare GEMMs of its shapes.
    WorldModel(WorldModelArgs),
    /// PPO iterations with the world model in the loop (a `task: unified`
    /// config): env-steps/s and `share_world_model`, beside the bare env's.
    Unified(UnifiedArgs),
    /// Raw mj_step vs our safe Data::step on the standing G1.
    Sim(SimArgs),
    /// Raw physics vs VecEnv at 1 and 2 threads, scandots direct vs mj_ray.
    Env(EnvArgs),
}

/// Arguments of `bench data`.
#[derive(clap::Args)]
pub struct BenchDataArgs {
    #[arg(long)]
    json: bool,
    /// Dataset directory to read (default: synthetic shards written to a temporary directory).
    #[arg(long, conflicts_with = "out")]
    dir: Option<PathBuf>,
    /// Write the synthetic shards into this directory and keep them.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Frames of the synthetic dataset.
    #[arg(long, default_value_t = 200_000)]
    frames: u32,
    /// Window history K (frames up to and including the anchor).
    #[arg(long, default_value_t = 8)]
    history: usize,
    /// Window horizon H (frames after the anchor).
    #[arg(long, default_value_t = 8)]
    horizon: usize,
    /// Shuffle buffer capacity (windows).
    #[arg(long, default_value_t = 1024)]
    shuffle: usize,
    /// Alternating rounds (raw, file, windows); the best of each counts.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// World-model config whose trainer the reader is set against (`headroom`).
    #[arg(long, default_value = "configs/world_model/small.yaml")]
    wm_config: PathBuf,
    /// Skip the headroom measurement.
    #[arg(long)]
    no_headroom: bool,
}

/// Arguments of `bench ppo`.
#[derive(clap::Args)]
pub struct PpoArgs {
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
}

/// Arguments of `bench unified`.
#[derive(clap::Args)]
pub struct UnifiedArgs {
    #[arg(long)]
    json: bool,
    #[arg(long, default_value = "configs/unified/small.yaml")]
    config: PathBuf,
    #[arg(long = "set")]
    sets: Vec<String>,
    /// Iterations measured (after `--warmup`).
    #[arg(long, default_value_t = 3)]
    iterations: usize,
    #[arg(long, default_value_t = 1)]
    warmup: usize,
}

/// Arguments of `bench world-model`.
#[derive(clap::Args)]
pub struct WorldModelArgs {
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
}

/// Arguments of `bench sim`.
#[derive(clap::Args)]
pub struct SimArgs {
    #[arg(long)]
    json: bool,
    /// Physics steps per round.
    #[arg(long, default_value_t = 20_000)]
    steps: usize,
    /// Alternating rounds of raw and safe stepping.
    #[arg(long, default_value_t = 5)]
    rounds: usize,
}

/// Arguments of `bench env`.
#[derive(clap::Args)]
pub struct EnvArgs {
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
}

pub fn run(which: BenchCommand) -> Result<()> {
    match which {
        BenchCommand::Data(a) => data(a),
        BenchCommand::Ppo(a) => ppo(a),
        BenchCommand::WorldModel(a) => world_model(a),
        BenchCommand::Unified(a) => unified(a),
        BenchCommand::Sim(a) => sim(a),
        BenchCommand::Env(a) => env(a),
    }
}

fn unified(a: UnifiedArgs) -> Result<()> {
    let cfg = config::load(&a.config, &a.sets)?;
    tch::set_num_threads(cfg.train.torch_threads as i32);
    let b = dreampolicy::bench::unified::bench_unified(
        &cfg,
        &a.config.display().to_string(),
        a.warmup,
        a.iterations.max(1),
    )?;
    if a.json {
        println!("{}", serde_json::to_string(&b)?);
    } else {
        println!("{}", serde_json::to_string_pretty(&b)?);
    }
    Ok(())
}

fn ppo(a: PpoArgs) -> Result<()> {
    let cfg = config::load(&a.config, &a.sets)?;
    let label = a.config.display().to_string();
    let r = bench::ppo::ppo(&cfg, &label, 1, a.iterations.max(1), !a.config_only)
        .context("bench ppo")?;
    if a.json {
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

fn world_model(a: WorldModelArgs) -> Result<()> {
    let cfg = load_world_model(&a.config, &a.sets)?;
    let paper = if a.config_only {
        None
    } else {
        Some(load_world_model(&a.paper_config, &[])?)
    };
    tch::set_num_threads(cfg.train.torch_threads as i32);
    let r = bench::world_model::world_model(
        &cfg,
        paper.as_ref().map(|p| (p, a.paper_batch.max(1))),
        a.rounds,
    );
    if a.json {
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

fn sim(a: SimArgs) -> Result<()> {
    let r = bench::sim(a.steps, a.rounds).context("bench sim")?;
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "MuJoCo {}: raw mj_step {:.0} steps/s, Data::step {:.0} steps/s, ratio {:.3}",
            r.mujoco_version, r.raw_steps_per_s, r.safe_steps_per_s, r.ratio
        );
    }
    Ok(())
}

fn env(a: EnvArgs) -> Result<()> {
    let cfg = config::load(&a.config, &a.sets)?;
    let r = bench::env(&cfg.env, &a.config.display().to_string(), a.steps, a.rounds)
        .context("bench env")?;
    if a.json {
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

fn data(a: BenchDataArgs) -> Result<()> {
    let spec = WindowSpec::new(a.history, a.horizon)?;
    let wm = if a.no_headroom {
        None
    } else {
        let cfg = load_world_model(&a.wm_config, &[])
            .with_context(|| "the headroom needs a world-model config (--no-headroom skips it)")?;
        tch::set_num_threads(cfg.train.torch_threads as i32);
        Some(cfg)
    };
    let r = bench::data::data(
        a.dir.as_deref(),
        a.out.as_deref(),
        a.frames,
        spec,
        a.shuffle,
        a.rounds,
        wm.as_ref(),
    )
    .context("bench data")?;
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "{} frames in {} shards ({:.0} bytes/frame on disk, {} raw): windows K={} H={} {:.0}/s ({:.0} frames/s) vs raw MCAP read {:.0} frames/s: read_vs_raw {:.2}; plain file read {:.0} MB/s (read_vs_file {:.3})",
            r.frames, r.shards, r.bytes_per_frame_on_disk, r.frame_bytes, r.history, r.horizon,
            r.windows_per_s, r.window_frames_per_s, r.raw_frames_per_s, r.read_vs_raw,
            r.file_mb_per_s, r.read_vs_file
        );
        if let (Some(h), Some(rd), Some(tr)) = (
            r.headroom,
            r.reader_sequences_per_s,
            r.trainer_sequences_per_s,
        ) {
            println!(
                "headroom {h:.0}: the reader gives {rd:.0} sequences/s at the world-model trainer's spec, the trainer takes {tr:.1}/s"
            );
        }
    }
    Ok(())
}
