//! `dreampolicy render`: a checkpoint's rollout on one lane as a video (MP4 or
//! GIF), drawn headless by MuJoCo's renderer and encoded by ffmpeg.
use std::path::PathBuf;

use anyhow::{Context, Result};

use dreampolicy::play::video::{self, RenderOptions};

use super::play::{describe, LaneArgs};

/// Arguments of `render`.
#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    lane: LaneArgs,
    /// The video to write: .mp4 (H.264) or .gif (replaced if it exists).
    #[arg(long)]
    out: PathBuf,
    /// Frame width and height in pixels (even for an MP4).
    #[arg(long, default_value_t = 640)]
    width: usize,
    #[arg(long, default_value_t = 360)]
    height: usize,
    /// Frames a second (the video plays in real time at 50 / round(50 / fps)).
    #[arg(long, default_value_t = 25.0)]
    fps: f64,
    /// Camera distance from the pelvis (m).
    #[arg(long, default_value_t = RenderOptions::default().distance)]
    distance: f64,
    /// Camera azimuth (degrees about +z; 90 looks at the robot from its right side).
    #[arg(long, default_value_t = RenderOptions::default().azimuth, allow_negative_numbers = true)]
    azimuth: f64,
    /// Camera elevation (degrees; negative looks down).
    #[arg(long, default_value_t = RenderOptions::default().elevation, allow_negative_numbers = true)]
    elevation: f64,
    /// Draw shadows (2-3x slower in the software renderer).
    #[arg(long)]
    shadows: bool,
    /// Also save one frame as a PNG (the frame at --still-at).
    #[arg(long)]
    still: Option<PathBuf>,
    /// Time of the still (s; the last frame if the rollout ends earlier).
    #[arg(long, default_value_t = 2.0)]
    still_at: f64,
    /// Also write the rollout as `play`'s MCAP file.
    #[arg(long)]
    mcap: Option<PathBuf>,
    /// The ffmpeg program.
    #[arg(long, default_value = "ffmpeg")]
    ffmpeg: String,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run(a: RenderArgs) -> Result<()> {
    let (ck, opts) = a.lane.options(a.out.clone())?;
    let r = RenderOptions {
        width: a.width,
        height: a.height,
        fps: a.fps,
        distance: a.distance,
        azimuth: a.azimuth,
        elevation: a.elevation,
        shadows: a.shadows,
        still: a.still.clone().map(|p| (p, a.still_at)),
        mcap: a.mcap.clone(),
        ffmpeg: a.ffmpeg.clone(),
    };
    let s = video::render(&ck, &opts, &r)
        .with_context(|| format!("rendering into {}", a.out.display()))?;
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    let p = &s.rollout;
    let (ending, lane) = describe(p);
    println!(
        "{}: {} ({}{lane}), {:.2} m at {:.2} m/s, {ending}; {} frames {}x{} at {} fps, {:.2} MB, {:.1} ms a frame ({})",
        s.video,
        p.terrain,
        if p.full_collision { "full collision" } else { "training scene" },
        p.distance,
        p.mean_forward_speed,
        s.frames,
        s.width,
        s.height,
        s.fps,
        s.video_bytes as f64 / 1e6,
        s.ms_per_frame,
        s.gl
    );
    if let (Some(still), Some(t)) = (&s.still, s.still_time) {
        println!("still: {still} (t = {t:.2} s)");
    }
    Ok(())
}
