//! The `dreampolicy` command line: the top-level parser, one variant per
//! command, and the dispatch. Each command's arguments and body live in its own
//! module below.
use anyhow::Result;
use clap::{Parser, Subcommand};

mod bench;
mod benchmark;
mod checkpoint;
mod collect;
mod data;
mod deploy;
mod eval;
mod eval_wm;
mod export;
mod info;
mod play;
mod plot;
mod render;
mod rollout;
mod sim2sim;
mod sweep;
mod terrain;
mod train;

#[derive(Parser)]
#[command(
    name = "dreampolicy",
    version,
    about = "DreamPolicy for the Unitree G1 on MuJoCo"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// MuJoCo and libtorch versions, device, threads, and the G1 model's sizes.
    Info(info::InfoArgs),
    /// Speed measurements, as ratios against a baseline measured in the same run.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Drive the env with a fixed policy (zero or random actions) and report
    /// per-term episode rewards, falls, time-outs, blow-ups and terrain levels.
    Rollout(rollout::RolloutArgs),
    /// Train a policy.
    #[command(subcommand)]
    Train(train::TrainCommand),
    /// The paper's comparison: every method checkpoint of a benchmark file on
    /// the single, unseen and combined lanes, with 95 % intervals; a report
    /// laid out as the paper's tables, heatmaps and bar charts; resumable.
    Benchmark(benchmark::BenchmarkArgs),
    /// Roll out every terrain specialist on its terrain and write the expert
    /// dataset (MCAP shards, one per specialist and round; existing shards are
    /// kept and skipped, so the same command resumes a crashed collection).
    Collect(collect::CollectArgs),
    /// Evaluate checkpoints on 10 m lanes: success and completion rates,
    /// velocity-tracking error, falls. Several checkpoints and terrains give the
    /// cross-terrain matrix (a table, JSON and a heatmap PNG). `eval world-model`
    /// evaluates a world-model checkpoint on its validation split instead.
    #[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
    Eval(eval::EvalArgs),
    /// Roll a checkpoint's policy out on one lane and write the rollout as an
    /// MCAP file for Foxglove (transforms, robot, terrain, command, state, reward).
    Play(play::PlayArgs),
    /// Roll a checkpoint's policy out on one lane and write it as a video (MP4
    /// or GIF): MuJoCo's own renderer, headless (OSMesa), a camera that follows
    /// the robot, frames encoded by ffmpeg.
    Render(render::RenderArgs),
    /// Draw a run directory's training curves (plots/training.png) from its metrics.csv.
    Plot(plot::PlotArgs),
    /// Export a checkpoint as a deployment bundle: the actor (normalization
    /// included) as TorchScript and deploy.yaml, the observation and action
    /// contract a controller needs
    Export(export::ExportArgs),
    /// Walk a deployment bundle in a MuJoCo scene through the bundle alone (no
    /// training env): sensors in, joint targets out
    DeploySim(deploy::DeploySimArgs),
    /// Evaluate a checkpoint across a sim-to-sim matrix (configs/sim2sim/):
    /// timestep, integrator, solver, collisions, friction, mass, motors,
    /// latency, noise, other MuJoCo builds and the stock Python deployer;
    /// writes JSON, a Markdown table and a heatmap PNG
    Sim2sim(sim2sim::Sim2SimArgs),
    /// Config-driven sweeps: axes over any config key, seeds, resources; run
    /// here (`sweep run --jobs N`, resumable), as a Slurm array (`sweep
    /// slurm`), and gathered into a CSV and a plot (`sweep collect`).
    #[command(subcommand)]
    Sweep(sweep::SweepCommand),
    /// Checkpoint files' integrity seals: verify them, or seal files written
    /// before checkpoints were sealed.
    #[command(subcommand)]
    Checkpoint(checkpoint::CheckpointCommand),
    /// Procedural terrains.
    #[command(subcommand)]
    Terrain(terrain::TerrainCommand),
    /// The expert dataset (MCAP shards): inspect, verify.
    #[command(subcommand)]
    Data(data::DataCommand),
}

/// Runs the parsed command.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Bench(which) => bench::run(which),
        Command::Rollout(a) => rollout::run(a),
        Command::Train(which) => train::run(which),
        Command::Benchmark(a) => benchmark::run(a),
        Command::Collect(a) => collect::run(a),
        Command::Eval(eval::EvalArgs {
            which: Some(eval::EvalCommand::WorldModel(a)),
            ..
        }) => eval_wm::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Play(a) => play::run(a),
        Command::Render(a) => render::run(a),
        Command::Plot(a) => plot::run(a),
        Command::Export(a) => export::run(a),
        Command::DeploySim(a) => deploy::run(a),
        Command::Sim2sim(a) => sim2sim::run(a),
        Command::Sweep(which) => sweep::run(which),
        Command::Checkpoint(which) => checkpoint::run(which),
        Command::Terrain(which) => terrain::run(which),
        Command::Data(which) => data::run(which),
    }
}
