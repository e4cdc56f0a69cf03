//! `dreampolicy eval world-model`: a world-model checkpoint on the validation
//! split of its dataset, printed as tables (or one JSON object).
use std::path::PathBuf;

use anyhow::{Context, Result};

use dreampolicy::world_model::config::SamplerKind;
use dreampolicy::world_model::{evaluate, WmEvalOptions};

/// Arguments of `eval world-model`.
#[derive(clap::Args)]
pub struct EvalWmArgs {
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
    /// Guidance ω instead of the checkpoint's (e.g. a unified config's `unified.sampling.guidance`).
    #[arg(long)]
    guidance: Option<f64>,
    /// DDIM with this many steps instead of the checkpoint's sampler.
    #[arg(long)]
    ddim_steps: Option<usize>,
}

pub fn run(a: EvalWmArgs) -> Result<()> {
    let opts = WmEvalOptions {
        data: a.data,
        windows: a.windows,
        seed: a.seed,
        threads: a.threads.max(1),
        plot: a.plot,
        guidance: a.guidance,
        ddim_steps: a.ddim_steps,
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
        if r.sampling.sampler == SamplerKind::Ddim {
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
    println!("\none call per terrain kind (normalized RMSE over H, real scandots, the default sampler):\n| terrain | hold last | guidance 0 | guidance 1 | guidance 5 |\n|---|---|---|---|---|");
    for (kind, s) in &r.terrain_sensitivity {
        let g = |w: &str| {
            s.rmse_by_guidance
                .get(w)
                .map_or("-".into(), |v| format!("{v:.4}"))
        };
        println!(
            "| {kind} | {:.4} | {} | {} | {} |",
            s.hold_rmse,
            g("0"),
            g("1"),
            g("5")
        );
    }
    println!("\nsamplers (guidance {}):\n| sampler | RMSE | RMSE at H | joint_pos (rad) | ms per call ({} windows) | ms at batch 1 |\n|---|---|---|---|---|---|", r.sampling.guidance, r.windows);
    let mut ss: Vec<_> = r.samplers.iter().collect();
    ss.sort_by_key(|(_, s)| (s.sampler == SamplerKind::Ddim, s.steps));
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
    if let Some(y) = &r.yaw_response {
        let row = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:+.3}"))
                .collect::<Vec<_>>()
                .join(" | ")
        };
        println!(
            "\nyaw response (rad/s; every history state's input set to {:?}, the same noise, {} windows):\n| input set | predicted yaw rate | slope |\n|---|---|---|\n| command | {} | {:.3} |\n| measured (gyro) | {} | {:.3} |\nthe windows as they are: command {:+.3} (std {:.3}), real {:+.3} (std {:.3}), predicted {:+.3}; the dataset's real on commanded yaw rate: slope {:.3}",
            y.set_to,
            y.windows,
            row(&y.predicted_by_command),
            y.command_slope,
            row(&y.predicted_by_measured),
            y.measured_slope,
            y.history_command,
            y.history_command_std,
            y.real,
            y.real_std,
            y.predicted,
            y.dataset_slope
        );
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
