//! `dreampolicy sim2sim`: one checkpoint across the sim-to-sim matrix of a
//! config (`configs/sim2sim/*.yaml`): the cells in this build, the same cells
//! in every other MuJoCo build the config names (their binaries run with
//! `--this-build-only`), and the stock Python deployer on the exported bundle.
//! Writes `sim2sim.json`, `sim2sim.md` and `sim2sim.png` (success heatmap).
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use dreampolicy::eval::sim2sim::{self, CellResult, Sim2SimConfig, Sim2SimReport};
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::config::ExperimentConfig;
use dreampolicy::terrain::TerrainKind;

/// Arguments of `sim2sim`.
#[derive(clap::Args)]
pub struct Sim2SimArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    /// The matrix: cells of env overrides, other builds, the stock deployer.
    #[arg(long)]
    config: PathBuf,
    /// Output directory (default: runs/sim2sim/<run>_<config name>).
    #[arg(long)]
    out: Option<PathBuf>,
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Run the cells in this build only and print their results as JSON (what
    /// the other builds are asked for).
    #[arg(long)]
    this_build_only: bool,
    /// Leave out the other builds and the stock deployer.
    #[arg(long)]
    no_external: bool,
    /// Print the report as one JSON object.
    #[arg(long)]
    json: bool,
    /// Lanes of this terrain instead of the config's `terrain` (a specialist on
    /// its own terrain: `--terrain bridge`).
    #[arg(long)]
    terrain: Option<String>,
    /// Lane level instead of the config's `level` (default: the checkpoint's
    /// `eval.level`).
    #[arg(long)]
    level: Option<usize>,
    /// Episodes per cell instead of the config's `episodes`.
    #[arg(long)]
    episodes: Option<usize>,
    /// Change the evaluation protocol of every cell, as in `eval` (`eval.*`
    /// keys only: `--set eval.lanes=1000` walks every episode on its own lane
    /// for a checkpoint whose config stores fewer lanes).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
}

/// The command line's overrides of the matrix file, as flags for another
/// build's binary.
fn override_flags(a: &Sim2SimArgs) -> Vec<String> {
    let mut f = Vec::new();
    if let Some(t) = &a.terrain {
        f.extend(["--terrain".to_string(), t.clone()]);
    }
    if let Some(l) = a.level {
        f.extend(["--level".to_string(), l.to_string()]);
    }
    if let Some(n) = a.episodes {
        f.extend(["--episodes".to_string(), n.to_string()]);
    }
    for s in &a.sets {
        f.extend(["--set".to_string(), s.clone()]);
    }
    f
}

/// The matrix file with the command line's overrides, checked again.
fn matrix(a: &Sim2SimArgs) -> Result<Sim2SimConfig> {
    let mut c = sim2sim::load(&a.config)?;
    if let Some(t) = &a.terrain {
        c.terrain = t.clone();
    }
    if a.level.is_some() {
        c.level = a.level;
    }
    if let Some(n) = a.episodes {
        c.episodes = n;
    }
    c.validate()
        .with_context(|| format!("{} with the command line's overrides", a.config.display()))?;
    Ok(c)
}

pub fn run(a: Sim2SimArgs) -> Result<()> {
    tch::set_num_threads(a.threads.max(1) as i32);
    let c = matrix(&a)?;
    let mut ck = Checkpoint::read(&a.checkpoint)?;
    ck.set_eval(&a.sets)?;
    let cfg = ck.config()?;
    let quiet = a.this_build_only || a.json;
    let cells = sim2sim::run_cells(&ck, &cfg, &c, a.threads.max(1), |i, n, name| {
        if !quiet {
            eprintln!("[{}/{n}] {} {name}", i + 1, sim2sim::this_build());
        }
    })?;
    if a.this_build_only {
        println!("{}", serde_json::to_string(&cells)?);
        return Ok(());
    }
    let out = out_dir(&a);
    let mut builds = vec![sim2sim::this_build()];
    let mut all = cells;
    if !a.no_external {
        for b in &c.builds {
            let (name, mut rs) = other_build(&a, b, &c);
            builds.push(name);
            all.append(&mut rs);
        }
        if let Some(sd) = &c.stock_deployer {
            let (name, r) = stock_deployer(&ck, &cfg, &c, sd, &out)?;
            builds.push(name);
            all.push(r);
        }
    }
    let report = Sim2SimReport {
        checkpoint: a.checkpoint.display().to_string(),
        config: a.config.display().to_string(),
        terrain: c.terrain.clone(),
        level: (c.kind() != TerrainKind::Flat).then(|| c.level.unwrap_or(cfg.eval.level)),
        episodes: c.episodes,
        builds,
        cells: all,
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let md = report.markdown();
    std::fs::write(
        out.join("sim2sim.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    std::fs::write(out.join("sim2sim.md"), &md)?;
    let rows = report.cell_names();
    let values: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            report
                .builds
                .iter()
                .map(|b| {
                    report
                        .get(r, b)
                        .and_then(|x| x.success_rate)
                        .unwrap_or(f64::NAN)
                })
                .collect()
        })
        .collect();
    // short labels: the cell's name before any parenthesis, the build's
    // version without "MuJoCo"
    let short_rows: Vec<String> = rows
        .iter()
        .map(|r| r.split(" (").next().unwrap_or(r).to_string())
        .collect();
    let short_cols: Vec<String> = report
        .builds
        .iter()
        .map(|b| {
            b.replace("stock Python MuJoCo", "Python")
                .replace("MuJoCo ", "")
        })
        .collect();
    dreampolicy::plot::heatmap(
        &out.join("sim2sim.png"),
        &format!(
            "sim-to-sim success rate: {}",
            super::eval::checkpoint_name(&a.checkpoint)
        ),
        &short_rows,
        &short_cols,
        &values,
    )?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{md}");
        println!("wrote {}/sim2sim.{{json,md,png}}", out.display());
    }
    Ok(())
}

fn out_dir(a: &Sim2SimArgs) -> PathBuf {
    a.out.clone().unwrap_or_else(|| {
        let cfg = a.config.file_stem().unwrap_or_default().to_string_lossy();
        PathBuf::from(format!(
            "runs/sim2sim/{}_{cfg}",
            super::eval::checkpoint_name(&a.checkpoint)
        ))
    })
}

/// The cells in another build: its binary with `--this-build-only`, or a note
/// on every cell saying why not.
fn other_build(
    a: &Sim2SimArgs,
    b: &sim2sim::Build,
    c: &Sim2SimConfig,
) -> (String, Vec<CellResult>) {
    let missing = |note: String| -> Vec<CellResult> {
        c.cells
            .iter()
            .map(|cell| CellResult::missing(&cell.name, &b.name, &cell.set, note.clone()))
            .collect()
    };
    if !Path::new(&b.binary).is_file() {
        let how = b
            .build_command
            .as_deref()
            .map(|h| format!("; build it with `{h}`"))
            .unwrap_or_default();
        return (
            b.name.clone(),
            missing(format!("{} is not built{how}", b.binary)),
        );
    }
    eprintln!("running the cells in {} ({})", b.name, b.binary);
    let out = Command::new(&b.binary)
        .arg("sim2sim")
        .arg("--checkpoint")
        .arg(&a.checkpoint)
        .arg("--config")
        .arg(&a.config)
        .arg("--threads")
        .arg(a.threads.to_string())
        .arg("--this-build-only")
        .args(override_flags(a))
        .stderr(std::process::Stdio::inherit())
        .output();
    let parsed = out.map_err(|e| e.to_string()).and_then(|o| {
        if o.status.success() {
            serde_json::from_slice::<Vec<CellResult>>(&o.stdout).map_err(|e| e.to_string())
        } else {
            Err(format!("exited with {}", o.status))
        }
    });
    match parsed {
        Ok(rs) => {
            let name = rs.first().map_or(b.name.clone(), |r| r.build.clone());
            (name, rs)
        }
        Err(e) => (b.name.clone(), missing(format!("{} failed: {e}", b.binary))),
    }
}

/// The stock Python deployer on the exported bundle: the reference cell's
/// flat lanes, speeds spread over `eval.lin_vel_x`, observation noise on
/// (noise seed = episode), for the eval's time limit.
fn stock_deployer(
    ck: &Checkpoint,
    cfg: &ExperimentConfig,
    c: &Sim2SimConfig,
    sd: &sim2sim::StockDeployer,
    out: &Path,
) -> Result<(String, CellResult)> {
    let reference = &c.cells[0];
    let name = "stock Python deployer".to_string();
    if c.kind() != TerrainKind::Flat {
        let note = "the stock deployer feeds flat scandots: flat lanes only".to_string();
        return Ok((
            name.clone(),
            CellResult::missing(&reference.name, &name, &reference.set, note),
        ));
    }
    if !Path::new(&sd.python).is_file() {
        let note = format!("{} not found (scripts/setup.sh makes it)", sd.python);
        return Ok((
            name.clone(),
            CellResult::missing(&reference.name, &name, &reference.set, note),
        ));
    }
    let bundle = out.join("bundle");
    dreampolicy::deploy::write_bundle(ck, &bundle, false).context("exporting the bundle")?;
    let (lo, hi) = (cfg.eval.lin_vel_x[0], cfg.eval.lin_vel_x[1]);
    let length = cfg.eval.lane_length;
    let n = sd.episodes.max(1);
    let (mut ok, mut comp, mut speed, mut err, mut falls, mut version) =
        (0usize, 0.0, 0.0, 0.0, 0usize, String::new());
    for i in 0..n {
        let v = lo + (hi - lo) * (i as f64 + 0.5) / n as f64;
        eprintln!("[stock deployer {}/{n}] {v:.2} m/s", i + 1);
        let o = Command::new(&sd.python)
            .arg("scripts/deploy_mujoco.py")
            .arg("--bundle")
            .arg(&bundle)
            .arg("--seconds")
            .arg(cfg.eval.time_limit_s.to_string())
            .arg("--speed")
            .arg(v.to_string())
            .arg("--noise-seed")
            .arg(i.to_string())
            .output()
            .with_context(|| format!("running {} scripts/deploy_mujoco.py", sd.python))?;
        if !o.status.success() {
            bail!(
                "scripts/deploy_mujoco.py failed: {}",
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
        }
        let text = String::from_utf8_lossy(&o.stdout);
        let line = text.lines().last().unwrap_or("");
        let j: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("reading the deployer's report {line:?}"))?;
        let dist = j["distance_m"].as_f64().unwrap_or(0.0);
        let fell = j["fell"].as_bool().unwrap_or(true);
        ok += usize::from(!fell && dist >= length);
        falls += usize::from(fell);
        comp += (dist / length).clamp(0.0, 1.0);
        speed += j["mean_forward_speed"].as_f64().unwrap_or(f64::NAN);
        err += j["vel_tracking_error"].as_f64().unwrap_or(f64::NAN);
        version = j["mujoco_version"].as_str().unwrap_or("").to_string();
    }
    let nf = n as f64;
    let name = format!("stock Python MuJoCo {version}");
    let r = CellResult {
        cell: reference.name.clone(),
        build: name.clone(),
        set: reference.set.clone(),
        success_rate: Some(ok as f64 / nf),
        completion_rate: Some(comp / nf),
        mean_forward_speed: Some(speed / nf),
        vel_tracking_error: Some(err / nf),
        // the stock deployer holds heading 0 and does not report yaw rates
        yaw_rate_tracking_error: None,
        mean_yaw_rate: None,
        falls: Some(falls),
        episodes: n,
        note: None,
    };
    Ok((name, r))
}
