//! What a PPO run logs: the `metrics.csv` columns (the fixed ones, then one
//! `rew_<term>` per reward term; the event file's tags are
//! `crate::run::tensorboard::tag` of them) and the panels of `plots/training.png`.
use std::path::{Path, PathBuf};

use crate::env::task::VecTask;

/// Columns of `metrics.csv` before the per-term rewards (`rew_<term>`).
pub const COLUMNS: [&str; 26] = [
    "iteration",
    "env_steps",
    "wall_time_s",
    "mean_return",
    "mean_episode_length",
    "episodes",
    "fall_fraction",
    "vel_error_xy",
    "vel_error_yaw",
    "value_loss",
    "surrogate_loss",
    "entropy",
    "kl",
    "clip_fraction",
    "explained_variance",
    "learning_rate",
    "mean_std",
    "grad_norm",
    "env_steps_per_s",
    "time_physics_s",
    "time_inference_s",
    "time_update_s",
    "terrain_level",
    "blowups",
    "mean_step_reward",
    "penalty_scale",
];

/// Draw `plots/training.png` from the run's `metrics.csv`.
pub fn plot_run(run_dir: &Path) -> Result<PathBuf, crate::plot::PlotError> {
    use crate::plot::Panel;
    let x = "env_steps";
    // the estimator's regression error joins the losses when the run has one
    // (`policy.estimator`; the column exists only then)
    let csv = run_dir.join("metrics.csv");
    let header = crate::plot::MetricsTable::header(&csv)
        .map_err(|source| crate::plot::PlotError::Io { path: csv, source })?;
    let has_estimator = header.iter().any(|c| c == "estimator_loss");
    let losses: &[&str] = if has_estimator {
        &["value_loss", "surrogate_loss", "estimator_loss"]
    } else {
        &["value_loss", "surrogate_loss"]
    };
    // the curve per kind beside the mean on a mixed map (`level_<kind>`)
    let levels: Vec<&str> = std::iter::once("terrain_level")
        .chain(
            header
                .iter()
                .filter(|c| c.starts_with("level_"))
                .map(|c| c.as_str()),
        )
        .collect();
    let panels = [
        Panel::new("episode return (last 100)", x, &["mean_return"]),
        Panel::new("episode length (steps)", x, &["mean_episode_length"]),
        Panel::new("tracking error", x, &["vel_error_xy", "vel_error_yaw"]),
        Panel::new("losses", x, losses),
        Panel::new("policy", x, &["mean_std", "kl", "clip_fraction"]),
        Panel::new(
            "falls and penalty scale",
            x,
            &["fall_fraction", "penalty_scale"],
        ),
        Panel::new("env-steps/s", x, &["env_steps_per_s"]),
        Panel::new(
            "seconds per iteration",
            x,
            &["time_physics_s", "time_inference_s", "time_update_s"],
        ),
        Panel::new("mean terrain level", x, &levels),
    ];
    crate::run::plot_training(run_dir, &panels)
}

/// Metrics columns of a task: [`COLUMNS`], `rew_<term>`, the task's own
/// metrics, then `level_<kind>` per kind of a mixed map with a curriculum.
pub fn columns(task: &dyn VecTask) -> Vec<String> {
    COLUMNS
        .iter()
        .map(|c| c.to_string())
        .chain(task.reward_names().iter().map(|n| format!("rew_{n}")))
        .chain(task.extra_metric_names().iter().map(|n| n.to_string()))
        .chain(
            task.levels_by_kind()
                .iter()
                .map(|(k, _)| format!("level_{}", k.name())),
        )
        .collect()
}
