//! `eval world-model` on a tiny model trained for a few steps on a tiny synthetic
//! dataset of all five training kinds: the report's shapes and keys, finite
//! numbers, the same report for the same seed, guidance 0 exactly blind to the
//! terrain while 5 is not, a rollout longer than every episode reported null with
//! its reason, the PNG, the CLI, and clear errors for a missing checkpoint or
//! dataset.
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::Scratch;
use dreampolicy::run::latest_checkpoint;
use dreampolicy::terrain::TerrainKind;
use dreampolicy::world_model::config::world_model_from_str;
use dreampolicy::world_model::{evaluate, train, WmEvalOptions};

/// `n_envs` envs for `steps` steps; env `e`'s episodes last `40 + 10 e` steps.
/// Each episode walks one training kind (by ordinal); its states are smooth
/// signals whose frequency depends on the kind, its scandots a kind-specific
/// pattern.
fn write_dataset(dir: &Path, n_envs: u32, steps: u32) {
    common::write_synthetic_shard(
        dir,
        n_envs,
        steps,
        |env| 40 + 10 * env,
        |f, ord, _env, step| {
            let kind = (ord % 5) as usize;
            f.terrain = TerrainKind::TRAINING[kind];
            f.level = 0;
            let freq = 0.15 + 0.05 * kind as f32;
            for (j, v) in f.state.iter_mut().enumerate() {
                *v = (freq * step as f32 * (1.0 + 0.01 * j as f32) + 0.3 * ord as f32).sin();
            }
            for (j, v) in f.scan.iter_mut().enumerate() {
                *v = -0.75 + 0.1 * kind as f32 * ((j + kind) % 3) as f32;
            }
        },
    );
}

/// Train the tiny model for a few steps; its checkpoint.
fn tiny_checkpoint(dir: &Path) -> PathBuf {
    let data = dir.join("data");
    write_dataset(&data, 10, 160);
    let text = format!(
        "data: {{path: '{}', val_fraction: 0.5, shuffle: 64}}
model: {{history: 2, horizon: 4, layers: 2, hidden: 32, heads: 2, mlp_ratio: 2, terrain_hidden: [32], terrain_dim: 16, step_features: 16}}
diffusion: {{steps: 20, schedule: cosine, terrain_drop: 0.2}}
sampling: {{sampler: ddim, ddim_steps: 4, guidance: 5.0}}
train: {{iterations: 12, batch_size: 16, learning_rate: 3.0e-3, ema_decay: 0.5, rollout_windows: 2,
  supervised_iterations: 12, scheduled_iterations: 0,
  rollout_sampling: {{sampler: ddim, ddim_steps: 3, guidance: 2.0}},
  log_interval: 4, eval_interval: 0, val_sequences: 8, save_interval: 0, keep_interval: 0,
  seed: 3, torch_threads: 1}}
",
        data.display()
    );
    let cfg = world_model_from_str(&text, "tiny", &[]).unwrap();
    let run = dir.join("run");
    train(&cfg, &run, false, true).unwrap();
    latest_checkpoint(&run)
}

fn opts(seed: u64) -> WmEvalOptions {
    WmEvalOptions {
        windows: 15,
        seed,
        threads: 1,
        drift_frames: vec![10, 250],
        ..WmEvalOptions::default()
    }
}

/// The report as JSON without its wall times.
fn timeless(r: &dreampolicy::world_model::WmEvalReport) -> serde_json::Value {
    let mut v = serde_json::to_value(r).unwrap();
    v.as_object_mut().unwrap().remove("wall_time_s");
    for s in v["samplers"].as_object_mut().unwrap().values_mut() {
        let s = s.as_object_mut().unwrap();
        s.remove("batch_ms");
        s.remove("batch1_ms");
    }
    v
}

fn all_finite(v: &serde_json::Value) -> bool {
    match v {
        serde_json::Value::Number(n) => n.as_f64().is_some_and(f64::is_finite),
        serde_json::Value::Array(a) => a.iter().all(all_finite),
        serde_json::Value::Object(o) => o.values().all(all_finite),
        _ => true,
    }
}

fn keys<V>(m: &std::collections::BTreeMap<String, V>) -> Vec<&str> {
    m.keys().map(|k| k.as_str()).collect()
}

#[test]
fn eval_world_model_reports_every_measurement() {
    tch::set_num_threads(1);
    let dir = Scratch::new("wm-eval");
    let ck = tiny_checkpoint(&dir.0);
    let png = dir.0.join("traj.png");
    let mut o = opts(7);
    o.plot = Some(png.clone());
    let r = evaluate(&ck, &o).unwrap();
    // shapes and keys
    assert_eq!((r.history, r.horizon, r.diffusion_steps), (2, 4, 20));
    assert_eq!(r.horizon_rmse.len(), 4);
    assert_eq!(r.hold_rmse.len(), 4);
    assert_eq!(r.horizon_rmse_raw["joint_pos"].len(), 4);
    assert_eq!(r.horizon_rmse_raw.len(), 7);
    assert_eq!(keys(&r.guidance), ["0", "1", "5"]);
    assert_eq!(
        keys(&r.samplers),
        ["ddim1", "ddim10", "ddim2", "ddim20", "ddim5", "ddpm"]
    );
    assert_eq!(r.samplers["ddpm"].steps, 20);
    assert_eq!(keys(&r.drift), ["10", "250"]);
    // 15 windows shared over the five kinds, all present in the validation split
    assert_eq!(r.windows, 15);
    assert_eq!(r.windows_per_kind.len(), 5, "{:?}", r.windows_per_kind);
    assert!(r.windows_per_kind.values().all(|&n| n == 3));
    assert_eq!(r.terrain_sensitivity.len(), 5);
    let v = serde_json::to_value(&r).unwrap();
    assert!(all_finite(&v), "{v}");
    // the yaw response: three rates written per input, the plan's yaw rate for
    // each, and the dataset's spread (the tiny dataset's robots do turn)
    let y = r
        .yaw_response
        .as_ref()
        .expect("a G1 state has a yaw response");
    assert_eq!(y.windows, 15);
    assert_eq!(y.set_to, [-0.5, 0.0, 0.5]);
    assert_eq!(y.predicted_by_command.len(), 3);
    assert_eq!(y.predicted_by_measured.len(), 3);
    assert!(y.predicted_by_command != y.predicted_by_measured, "{y:?}");
    assert!(y.history_command_std >= 0.0 && y.real_std > 0.0, "{y:?}");
    // guidance 0 never looks at the terrain: exactly the same prediction
    assert_eq!(r.guidance["0"].terrain_distance, 0.0);
    assert!(r.guidance["1"].terrain_distance > 0.0);
    assert!(r.guidance["5"].terrain_distance > r.guidance["1"].terrain_distance);
    for (kind, s) in &r.terrain_sensitivity {
        assert_eq!(s.donor, "other kinds", "{kind}");
        assert!(s.scan_distance_m > 0.0, "{kind}");
        assert!(s.distance > 0.0 && s.seed_spread > 0.0, "{kind}: {s:?}");
        // where the default sampler's guidance is one of the three, the same prediction
        if let Some(v) = s.rmse_by_guidance.get(&r.sampling.guidance.to_string()) {
            assert!((v - s.rmse_real).abs() < 1e-9, "{kind}: {s:?}");
        }
        let keys: Vec<&str> = s.rmse_by_guidance.keys().map(String::as_str).collect();
        assert_eq!(keys, ["0", "1", "5"], "{kind}");
        assert!(s
            .rmse_by_guidance
            .values()
            .all(|v| v.is_finite() && *v > 0.0));
    }
    // the kinds' hold errors make up the whole set's (equal windows per kind)
    let per_kind = (r
        .terrain_sensitivity
        .values()
        .map(|s| s.hold_rmse.powi(2))
        .sum::<f64>()
        / r.terrain_sensitivity.len() as f64)
        .sqrt();
    let whole = (r.hold_rmse.iter().map(|h| h * h).sum::<f64>() / r.hold_rmse.len() as f64).sqrt();
    assert!(
        (per_kind - whole).abs() < 1e-4 * whole,
        "{per_kind} vs {whole}"
    );
    // drift: 10 frames = 3 calls of H = 4; no episode holds K + 250 frames
    let d = r.drift["10"].metrics.as_ref().expect("10-frame drift");
    assert_eq!(d.per_call_rmse.len(), 3);
    assert!(r.drift["10"].windows > 0);
    let long = &r.drift["250"];
    assert!(long.metrics.is_none() && long.windows == 0);
    let why = long.reason.as_deref().unwrap();
    assert!(why.contains("252") && why.contains("longest"), "{why}");
    // the PNG: 3 windows x 4 joints in the plot grid
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    let (w, h) = dreampolicy::plot::image_size(12);
    assert_eq!(&bytes[16..24], [w.to_be_bytes(), h.to_be_bytes()].concat());
    // the same seed gives the same report, another seed another one
    let mut again = timeless(&evaluate(&ck, &opts(7)).unwrap());
    again["plot"] = v["plot"].clone();
    assert_eq!(timeless(&r), again);
    let other = evaluate(&ck, &opts(8)).unwrap();
    assert_ne!(other.horizon_rmse, r.horizon_rmse);

    // the CLI: JSON on stdout, --data overrides the dataset
    let cli_json = |extra: &[&str]| -> serde_json::Value {
        let out = common::run_ok_bytes(
            Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
                .args(["eval", "world-model", "--json", "--windows", "5"])
                .args(extra)
                .arg("--checkpoint")
                .arg(&ck)
                .arg("--data")
                .arg(dir.0.join("data")),
        );
        serde_json::from_slice(&out).unwrap()
    };
    let j = cli_json(&[]);
    assert_eq!(j["windows"], 5);
    assert_eq!(j["horizon_rmse"].as_array().unwrap().len(), 4);

    // another sampling than the checkpoint's: every measurement uses it
    let j2 = cli_json(&["--guidance", "1", "--ddim-steps", "2"]);
    assert_eq!(j2["sampling"]["sampler"], "ddim");
    assert_eq!(j2["sampling"]["ddim_steps"], 2);
    assert_eq!(j2["sampling"]["guidance"], 1.0);
    assert_eq!(j2["samplers"]["ddim5"]["guidance"], 1.0);
    assert_ne!(j2["horizon_rmse"], j["horizon_rmse"]);
    let mut bad = opts(7);
    bad.ddim_steps = Some(21);
    let e = evaluate(&ck, &bad).err().unwrap().to_string();
    assert!(e.contains("--ddim-steps 21") && e.contains("20"), "{e}");

    // a missing dataset (by --data or the checkpoint's data.path) and a missing checkpoint
    let mut bad = opts(7);
    bad.data = Some(dir.0.join("nowhere"));
    let e = evaluate(&ck, &bad).err().unwrap().to_string();
    assert!(
        e.contains("nowhere") && e.contains("no such directory"),
        "{e}"
    );
    std::fs::rename(dir.0.join("data"), dir.0.join("moved")).unwrap();
    let e = evaluate(&ck, &opts(7)).err().unwrap().to_string();
    assert!(e.contains("data.path") && e.contains("--data"), "{e}");
    let e = evaluate(&dir.0.join("none.pt"), &opts(7))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("none.pt") && e.contains("no such file"), "{e}");
    let out = Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
        .args(["eval", "world-model", "--checkpoint"])
        .arg(dir.0.join("none.pt"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("none.pt") && e.contains("no such file"), "{e}");
}
