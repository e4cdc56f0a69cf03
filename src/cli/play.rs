//! `dreampolicy play`: a checkpoint's rollout on one lane, written as an MCAP
//! file for Foxglove.
use std::path::PathBuf;

use anyhow::{Context, Result};

use dreampolicy::play::{self, PlayOptions};
use dreampolicy::rl::checkpoint::{self, Checkpoint};
use dreampolicy::terrain::TerrainKind;

/// The rollout `play` and `render` share: checkpoint, lane, speed, seed, scene.
#[derive(clap::Args)]
pub struct LaneArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    /// Terrain of the lane: flat, uneven, stair, gap, bridge, wave, slope,
    /// balancing_beam, slope_bridge.
    #[arg(long, default_value = "flat")]
    terrain: String,
    /// Simulated seconds (the rollout stops earlier at a fall).
    #[arg(long, default_value_t = play::DEFAULT_SECONDS)]
    seconds: f64,
    /// Commanded forward speed in m/s (default: the middle of the config's eval.lin_vel_x).
    #[arg(long, allow_negative_numbers = true)]
    speed: Option<f64>,
    /// Level of the lane in the config's eval.terrain, the table `eval` scores
    /// (the paper's unless the config says otherwise; default: eval.level).
    /// With --seed k the lane is eval's k-th lane at that level.
    #[arg(long)]
    level: Option<usize>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Play on the project's default scene (full collisions, MuJoCo's default
    /// solver) instead of the checkpoint's training scene.
    #[arg(long)]
    full_collision: bool,
    /// Lane keeping: steer the heading at the lane's centre line this many
    /// metres ahead, as `eval --lane-lookahead`.
    #[arg(long, value_parser = super::eval::positive_metres)]
    lane_lookahead: Option<f64>,
    /// libtorch threads.
    #[arg(long, default_value_t = 1)]
    threads: i32,
    /// `eval.*` keys of the checkpoint's stored config, and a unified
    /// policy's inference keys (`unified.sampling.guidance=5`, ...), as
    /// `eval --set` takes them (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// A unified policy's plans from this world-model checkpoint instead of
    /// the one its config names.
    #[arg(long)]
    world_model: Option<PathBuf>,
}

impl LaneArgs {
    /// The checkpoint, read, and the rollout's options writing to `out`.
    pub fn options(&self, out: PathBuf) -> Result<(Checkpoint, PlayOptions)> {
        let terrain = TerrainKind::from_name(&self.terrain)?;
        let mut ck = Checkpoint::read(&self.checkpoint)?;
        ck.set_eval(&checkpoint::with_world_model(
            &self.set,
            self.world_model.as_deref(),
        ))?;
        tch::set_num_threads(self.threads.max(1));
        let opts = PlayOptions {
            terrain,
            level: self.level,
            seconds: self.seconds,
            speed: self.speed,
            seed: self.seed,
            full_collision: self.full_collision,
            lane_lookahead: self.lane_lookahead,
            out,
        };
        Ok((ck, opts))
    }
}

/// Arguments of `play`.
#[derive(clap::Args)]
pub struct PlayArgs {
    #[command(flatten)]
    lane: LaneArgs,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long)]
    out: PathBuf,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run(a: PlayArgs) -> Result<()> {
    let (ck, opts) = a.lane.options(a.out.clone())?;
    let s = play::play(&ck, &opts).with_context(|| format!("playing into {}", a.out.display()))?;
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    let (ending, lane) = describe(&s);
    println!(
        "{}: {} ({}{lane}), {} steps, {:.2} m at {:.2} m/s (commanded {:.2}), {ending}; {} frames, {:.2} MB",
        s.out,
        s.terrain,
        if s.full_collision { "full collision" } else { "training scene" },
        s.steps,
        s.distance,
        s.mean_forward_speed,
        s.commanded_speed,
        s.frames,
        s.file_bytes as f64 / 1e6
    );
    Ok(())
}

/// How a rollout ended and which lane it walked, in words.
pub fn describe(s: &play::PlaySummary) -> (String, String) {
    let ending = match s.ending {
        play::Ending::TimeUp => "ran its time".to_string(),
        play::Ending::Fell => format!("FELL at {:.2} s", s.seconds),
        play::Ending::BlowUp => format!("physics blew up at {:.2} s", s.seconds),
        play::Ending::LeftMap => format!("walked off the map at {:.2} s", s.seconds),
    };
    let lane = match (s.level, &s.table, s.lane_length, s.reached_goal) {
        (Some(l), Some(table), Some(len), Some(goal)) => format!(
            ", level {l} of {table} (eval's lane {}), {len:.1} m lane{}",
            s.seed,
            if goal { ", goal reached" } else { "" }
        ),
        _ => String::new(),
    };
    (ending, lane)
}
