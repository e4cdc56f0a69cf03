//! `dreampolicy deploy-sim`: a deployment bundle walked in a MuJoCo scene by
//! the bundle alone.
use std::path::PathBuf;

use anyhow::Result;
use dreampolicy::deploy::{deploy_sim, DeploySimOptions};

/// Arguments of `deploy-sim`.
#[derive(clap::Args)]
pub struct DeploySimArgs {
    /// Bundle directory written by `export`
    #[arg(long)]
    bundle: PathBuf,
    /// MuJoCo scene (default: the bundle's `scene`, the G1 on a plane)
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulated seconds (stops earlier at a fall)
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// Forward speed command (m/s); the heading is held at 0
    #[arg(long, default_value_t = 0.75)]
    speed: f64,
    /// Add the training observation noise (as eval and play do) from this seed
    #[arg(long)]
    noise_seed: Option<u64>,
    /// Print the summary as one JSON object
    #[arg(long)]
    json: bool,
}

pub fn run(a: DeploySimArgs) -> Result<()> {
    let o = DeploySimOptions {
        scene: a.scene,
        seconds: a.seconds,
        speed: a.speed,
        noise_seed: a.noise_seed,
    };
    let s = deploy_sim(&a.bundle, &o)?;
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
    } else {
        let end = match s.fell_at_s {
            Some(t) => format!("FELL at {t:.2} s"),
            None => "ran its time".to_string(),
        };
        println!(
            "{}: {} (MuJoCo {}), {} steps, {:.2} m at {:.2} m/s (commanded {:.2}), tracking error {:.3} m/s, yaw {:.1} deg at the end, {end}{}",
            a.bundle.display(),
            s.scene,
            s.mujoco_version,
            s.steps,
            s.distance_m,
            s.mean_forward_speed,
            s.commanded_speed,
            s.vel_tracking_error,
            s.final_yaw_deg,
            if s.observation_noise { ", noisy observations" } else { "" }
        );
    }
    Ok(())
}
