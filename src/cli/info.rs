//! `dreampolicy info`: MuJoCo and libtorch versions, device, threads, and the
//! G1 model's sizes.
use std::sync::Arc;

use anyhow::{Context, Result};

use dreampolicy::{robot, sim};

/// Arguments of `info`.
#[derive(clap::Args)]
pub struct InfoArgs {
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run(a: InfoArgs) -> Result<()> {
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
    if a.json {
        println!("{value}");
    } else {
        for (k, v) in value.as_object().into_iter().flatten() {
            println!("{k:>22}: {}", v.to_string().trim_matches('"'));
        }
    }
    Ok(())
}
