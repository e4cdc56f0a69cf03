//! The `dreampolicy` CLI: one subcommand per pipeline stage.
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

use dreampolicy::{bench, robot, sim};

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
}

#[derive(Subcommand)]
enum BenchCommand {
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
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Info { json } => info(json),
        Command::Bench { which } => match which {
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
        },
    }
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
