//! `dreampolicy eval`: checkpoints on 10 m lanes, one evaluation, the
//! cross-terrain matrix (table, JSON, heatmap) or the level sweep (JSON, plot).
//! `eval world-model` is in `eval_wm`.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Subcommand;

use dreampolicy::eval;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::terrain::TerrainKind;

use super::eval_wm::EvalWmArgs;

/// Arguments of `eval` (`which` is its optional `world-model` subcommand).
#[derive(clap::Args)]
pub struct EvalArgs {
    #[command(subcommand)]
    pub which: Option<EvalCommand>,
    /// Checkpoint to evaluate; repeat (or give a comma-separated list) for a matrix.
    #[arg(long, required = true, value_delimiter = ',')]
    checkpoint: Vec<PathBuf>,
    /// Terrain(s) of the lanes, comma-separated (flat, uneven, stair, gap, bridge, ...).
    #[arg(
        long,
        visible_alias = "terrains",
        default_value = "flat",
        value_delimiter = ','
    )]
    terrain: Vec<String>,
    /// Combined lanes (the paper's Table 2): each --terrain kind in the first
    /// half of the 10 m walk, this kind in the second (e.g. `--terrain stair
    /// --then gap`).
    #[arg(long, conflicts_with = "levels")]
    then: Option<String>,
    /// Episodes per checkpoint and terrain.
    #[arg(long, default_value_t = 100)]
    episodes: usize,
    /// Evaluate on the project's default scene (full collisions, MuJoCo's
    /// default solver) instead of the checkpoint's training scene.
    #[arg(long)]
    full_collision: bool,
    /// Lane difficulty level (0 = easiest) instead of the config's
    /// `eval.level`.
    #[arg(long, conflicts_with = "levels")]
    level: Option<usize>,
    /// A level sweep: every checkpoint at each of these levels (`0-9`,
    /// `0,3,5`) on its terrain (one --terrain for all, or one per
    /// checkpoint, paired in order). --out writes the JSON, --plot the
    /// success-rate curves (a line per checkpoint).
    #[arg(long)]
    levels: Option<String>,
    /// The level sweep's PNG (success and completion rate against level).
    #[arg(long, requires = "levels")]
    plot: Option<PathBuf>,
    /// The table the lanes come from.
    #[arg(long, value_enum, default_value_t = eval::EvalTable::Eval)]
    table: eval::EvalTable,
    /// Lane keeping: steer the heading command at the lane's centre line this
    /// many metres ahead (pure pursuit) instead of holding it along the lane.
    #[arg(long, value_parser = positive_metres)]
    lane_lookahead: Option<f64>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Change the evaluation protocol stored in each checkpoint's config
    /// (`eval.*` keys), e.g. `--set eval.terrain.uneven.heights=full`
    /// (the uneven lanes as scored before 2026-12-04) or `--set
    /// eval.time_limit_s=40` (repeatable). A unified policy also takes its
    /// inference keys: `unified.sampling.guidance=5`,
    /// `unified.sampling.ddim_steps=10`, `unified.sampling.sampler=ddpm`,
    /// `unified.replan_every=1`, `unified.plan=hold` (the current state held
    /// over the horizon instead of the world model's plan: what the plan adds).
    #[arg(long = "set", value_name = "eval.KEY=VALUE")]
    set: Vec<String>,
    /// A unified policy's plans from this world-model checkpoint instead of
    /// the one its config names (`--set unified.world_model=F`).
    #[arg(long)]
    world_model: Option<PathBuf>,
    /// Also write the JSON report (one evaluation) or matrix to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Draw the success rates as a heatmap PNG (checkpoints x terrains).
    #[arg(long)]
    heatmap: Option<PathBuf>,
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
pub enum EvalCommand {
    /// A world-model checkpoint on the validation split of its dataset: error per
    /// horizon step of one call, autoregressive drift over 50 and 250 steps,
    /// guidance 0/1/5, terrain sensitivity (real vs shuffled scandots), DDPM vs
    /// DDIM, and a PNG of real and predicted joint trajectories.
    WorldModel(EvalWmArgs),
}

impl EvalArgs {
    /// The options of one evaluation on `kind` lanes at `level`.
    fn options(
        &self,
        kind: TerrainKind,
        then: Option<TerrainKind>,
        level: Option<usize>,
    ) -> eval::EvalOptions {
        eval::EvalOptions {
            terrain: kind,
            then,
            episodes: self.episodes,
            full_collision: self.full_collision,
            seed: self.seed,
            threads: self.threads.max(1),
            level,
            table: self.table,
            lane_lookahead: self.lane_lookahead,
        }
    }
}

/// A checkpoint's short name: the run directory of `<run>/checkpoints/<file>.pt`,
/// else the file stem.
pub(super) fn checkpoint_name(path: &Path) -> String {
    let parent = path.parent();
    if parent
        .and_then(|p| p.file_name())
        .is_some_and(|n| n == "checkpoints")
    {
        if let Some(run) = parent.and_then(|p| p.parent()).and_then(|p| p.file_name()) {
            return run.to_string_lossy().into_owned();
        }
    }
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

pub fn run(a: EvalArgs) -> Result<()> {
    // libtorch's own default is a thread per core, whose spinning OpenMP team
    // made two 100-walk evaluations side by side at `--threads 1` take more
    // than 20 min each on a 2-core machine, against 2.3 min with one thread
    tch::set_num_threads(a.threads.max(1) as i32);
    let kinds = a
        .terrain
        .iter()
        .map(|t| TerrainKind::from_name(t.trim()))
        .collect::<Result<Vec<_>, _>>()?;
    let cks = a
        .checkpoint
        .iter()
        .map(|p| {
            let mut ck = Checkpoint::read(p)?;
            ck.set_eval(&dreampolicy::rl::checkpoint::with_world_model(
                &a.set,
                a.world_model.as_deref(),
            ))?;
            Ok(ck)
        })
        .collect::<Result<Vec<_>, dreampolicy::rl::RlError>>()?;
    let then = a
        .then
        .as_deref()
        .map(|t| TerrainKind::from_name(t.trim()))
        .transpose()?;
    let lanes: Vec<String> = kinds.iter().map(|&k| eval::lane_name(k, then)).collect();
    let names: Vec<String> = a.checkpoint.iter().map(|p| checkpoint_name(p)).collect();
    if let Some(levels) = &a.levels {
        return eval_sweep(&a, levels, &kinds, &cks, &names);
    }
    let mut reports = Vec::with_capacity(cks.len());
    for (ck, name) in cks.iter().zip(&names) {
        let mut row = Vec::with_capacity(kinds.len());
        for (&kind, lane) in kinds.iter().zip(&lanes) {
            let opts = a.options(kind, then, a.level);
            let r = eval::evaluate(ck, &opts)
                .with_context(|| format!("evaluating {name} on {lane}"))?;
            if !a.json {
                println!(
                    "{name}: {} walks of {:.0} m{} ({}{}): success {:.3}, completion {:.3}, velocity error {:.3} m/s, {} falls, {} time-outs, mean speed {:.2} m/s (commanded {:.2}), ankle {:.3} m at the top of a swing, {:.3} m in stance, swing rise {:.3} m",
                    r.episodes, r.lane_length,
                    r.lanes.map(|n| format!(" on {n} lanes")).unwrap_or_default(),
                    r.terrain,
                    r.level.map(|l| format!(", level {l}")).unwrap_or_default(),
                    r.success_rate, r.completion_rate,
                    r.vel_tracking_error, r.falls, r.timeouts, r.mean_forward_speed, r.mean_commanded_speed,
                    r.swing_peak_height, r.stance_foot_height, r.swing_rise
                );
            }
            row.push(r);
        }
        reports.push(row);
    }
    let single = reports.len() == 1 && kinds.len() == 1;
    let value = if single {
        serde_json::to_value(&reports[0][0])?
    } else {
        serde_json::json!({
            "checkpoints": names,
            "terrains": lanes,
            "success_rate": reports.iter().map(|r| r.iter().map(|e| e.success_rate).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "completion_rate": reports.iter().map(|r| r.iter().map(|e| e.completion_rate).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "reports": reports,
        })
    };
    if let Some(path) = &a.out {
        std::fs::write(path, format!("{}\n", serde_json::to_string_pretty(&value)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &a.heatmap {
        let cols = lanes.clone();
        let values: Vec<Vec<f64>> = reports
            .iter()
            .map(|r| r.iter().map(|e| e.success_rate).collect())
            .collect();
        dreampolicy::plot::heatmap(
            path,
            &format!(
                "Success rate over {} walks of 10 m (rows: policy, columns: terrain)",
                a.episodes
            ),
            &names,
            &cols,
            &values,
        )?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&value)?);
    } else if !single {
        let mut t = format!("| policy | {} |\n|---|", lanes.join(" | "));
        t.push_str(&"---|".repeat(kinds.len()));
        for (name, row) in names.iter().zip(&reports) {
            t.push_str(&format!("\n| {name} |"));
            for r in row {
                t.push_str(&format!(
                    " {:.2} ({:.2}) |",
                    r.success_rate, r.completion_rate
                ));
            }
        }
        println!("\nsuccess rate (completion rate):\n{t}");
    }
    Ok(())
}

/// `eval --levels`: each checkpoint on its terrain at each level.
fn eval_sweep(
    a: &EvalArgs,
    levels: &str,
    kinds: &[TerrainKind],
    cks: &[Checkpoint],
    names: &[String],
) -> Result<()> {
    let levels = eval::parse_levels(levels).map_err(anyhow::Error::msg)?;
    if kinds.len() != 1 && kinds.len() != cks.len() {
        anyhow::bail!(
            "a level sweep takes one --terrain for every checkpoint or one per checkpoint; got {} terrains for {} checkpoints",
            kinds.len(),
            cks.len()
        );
    }
    let mut curves = Vec::with_capacity(cks.len());
    // (legend, success rates, completion rates) of each checkpoint
    let mut lines: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::with_capacity(cks.len());
    for (i, (ck, name)) in cks.iter().zip(names).enumerate() {
        let kind = kinds[i.min(kinds.len() - 1)];
        let opts = a.options(kind, None, None);
        let rs = eval::level_sweep(ck, &opts, &levels)
            .with_context(|| format!("sweeping {name} over {} levels", kind.name()))?;
        if !a.json {
            for r in &rs {
                println!(
                    "{name}: {} level {}: success {:.3}, completion {:.3}, {} falls, {} time-outs",
                    r.terrain,
                    r.level.unwrap_or_default(),
                    r.success_rate,
                    r.completion_rate,
                    r.falls,
                    r.timeouts
                );
            }
        }
        let success: Vec<f64> = rs.iter().map(|r| r.success_rate).collect();
        let completion: Vec<f64> = rs.iter().map(|r| r.completion_rate).collect();
        curves.push(serde_json::json!({
            "checkpoint": name,
            "terrain": kind.name(),
            "success_rate": success,
            "completion_rate": completion,
            "reports": rs,
        }));
        lines.push((format!("{name} on {}", kind.name()), success, completion));
    }
    let value = serde_json::json!({
        "levels": levels,
        "episodes": a.episodes,
        "full_collision": a.full_collision,
        "curves": curves,
    });
    if let Some(path) = &a.out {
        std::fs::write(path, format!("{}\n", serde_json::to_string_pretty(&value)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &a.plot {
        let x: Vec<f64> = levels.iter().map(|&l| l as f64).collect();
        let panel = |completion: bool, title: &str| dreampolicy::plot::SeriesPanel {
            title: title.into(),
            x_label: "level".into(),
            x: x.clone(),
            lines: lines
                .iter()
                .map(|(name, s, c)| (name.clone(), if completion { c } else { s }.clone()))
                .collect(),
        };
        dreampolicy::plot::plot_series(
            path,
            &format!("Level sweep: {} lanes of 10 m per level", a.episodes),
            &[panel(false, "success rate"), panel(true, "completion rate")],
        )?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&value)?);
    }
    Ok(())
}

/// A positive length in metres (clap value parser).
pub(super) fn positive_metres(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!(
            "expected a positive length in metres, got {text:?}"
        )),
    }
}
