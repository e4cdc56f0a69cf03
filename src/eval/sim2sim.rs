//! The sim-to-sim matrix: one policy evaluated on the same lanes under changed
//! physics and sensing (timestep and decimation, integrator, solver
//! iterations, collision set, friction, added mass, motor strength, action
//! latency, observation noise), each cell a list of `--set` style overrides of
//! the evaluation env, beside the reference setting (the evaluation's default
//! scene). The MuJoCo-build axis and the stock deployer are run by the CLI
//! (`dreampolicy sim2sim`), which merges their results into a [`Sim2SimReport`].
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{eval_env_config, evaluate_in, EvalOptions, EvalReport, EvalTable};
use crate::config::{parse_value, ConfigError};
use crate::env::config::EnvConfig;
use crate::rl::checkpoint::Checkpoint;
use crate::rl::config::ExperimentConfig;
use crate::rl::RlError;
use crate::terrain::TerrainKind;

/// A sim-to-sim file (`configs/sim2sim/<name>.yaml`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sim2SimConfig {
    /// Terrain of the lanes (`flat`, or a kind of the checkpoint's `eval.terrain`).
    #[serde(default = "default_terrain")]
    pub terrain: String,
    /// Level of the lanes (default: the checkpoint's `eval.level`).
    #[serde(default)]
    pub level: Option<usize>,
    /// Episodes per cell.
    #[serde(default = "default_episodes")]
    pub episodes: usize,
    #[serde(default)]
    pub seed: u64,
    /// Start from the default scene (full collisions, MuJoCo's default solver:
    /// what `eval --full-collision` scores) rather than the training scene.
    #[serde(default = "yes")]
    pub full_collision: bool,
    /// The cells; the first is the reference the others are compared with.
    pub cells: Vec<Cell>,
    /// Other MuJoCo builds of this program, each run on the same cells.
    #[serde(default)]
    pub builds: Vec<Build>,
    /// The stock Python deployer (`scripts/deploy_mujoco.py`) on the
    /// exported bundle, flat lanes only.
    #[serde(default)]
    pub stock_deployer: Option<StockDeployer>,
}

fn default_terrain() -> String {
    "flat".into()
}
fn default_episodes() -> usize {
    20
}
fn yes() -> bool {
    true
}

/// One setting: a name and overrides of the evaluation env (`sim.timestep=0.002`,
/// `domain_rand.friction=[0.5,0.5]`, ...; keys relative to `env`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cell {
    pub name: String,
    #[serde(default)]
    pub set: Vec<String>,
}

/// Another build of `dreampolicy` (e.g. linked against Debian's MuJoCo 2.2.2).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Build {
    pub name: String,
    /// Its binary, relative to the working directory.
    pub binary: String,
    /// How to build it, printed when the binary is missing.
    #[serde(default)]
    pub build_command: Option<String>,
}

/// The stock deployer column.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StockDeployer {
    /// Python interpreter (the pinned venv setup makes).
    pub python: String,
    /// Episodes (speeds spread over `eval.lin_vel_x`, noise seeds 0..n).
    #[serde(default = "default_stock_episodes")]
    pub episodes: usize,
}

fn default_stock_episodes() -> usize {
    5
}

/// Read and check a sim-to-sim file.
pub fn load(path: &Path) -> Result<Sim2SimConfig, ConfigError> {
    let text = crate::config::read(path)?;
    let c: Sim2SimConfig = crate::config::parse(&text, &path.display().to_string(), &[])?;
    c.validate()?;
    Ok(c)
}

impl Sim2SimConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        if self.cells.is_empty() {
            return bad("sim2sim: cells must hold at least the reference cell".into());
        }
        if self.episodes == 0 {
            return bad("sim2sim: episodes must be at least 1".into());
        }
        TerrainKind::from_name(&self.terrain)
            .map_err(|e| ConfigError::Invalid(format!("sim2sim: terrain: {e}")))?;
        let mut names = std::collections::HashSet::new();
        for c in &self.cells {
            if !names.insert(c.name.as_str()) {
                return bad(format!("sim2sim: cell name {:?} appears twice", c.name));
            }
        }
        Ok(())
    }

    pub fn kind(&self) -> TerrainKind {
        TerrainKind::from_name(&self.terrain).unwrap_or(TerrainKind::Flat)
    }
}

/// The evaluation env of `cell`: `base` with the cell's overrides applied
/// (through YAML, so any env key can be set) and checked.
pub fn cell_env(base: &EnvConfig, cell: &Cell) -> Result<EnvConfig, ConfigError> {
    let in_cell =
        |e: ConfigError| ConfigError::Invalid(format!("sim2sim cell {:?}: {e}", cell.name));
    let v = serde_yaml::to_value(base).map_err(|e| ConfigError::Invalid(e.to_string()))?;
    let env: EnvConfig = parse_value(v, "env", &cell.set).map_err(in_cell)?;
    env.validate().map_err(in_cell)?;
    Ok(env)
}

/// One cell's result in one build (the figures None: not run, `note` says why).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CellResult {
    pub cell: String,
    pub build: String,
    pub set: Vec<String>,
    pub success_rate: Option<f64>,
    pub completion_rate: Option<f64>,
    pub mean_forward_speed: Option<f64>,
    pub vel_tracking_error: Option<f64>,
    /// Mean |yaw-rate command - yaw rate| and mean yaw rate (rad/s; absent
    /// from builds before 2026-12-05).
    #[serde(default)]
    pub yaw_rate_tracking_error: Option<f64>,
    #[serde(default)]
    pub mean_yaw_rate: Option<f64>,
    pub falls: Option<usize>,
    pub episodes: usize,
    pub note: Option<String>,
}

impl CellResult {
    pub fn from_report(cell: &Cell, build: &str, r: &EvalReport) -> CellResult {
        CellResult {
            cell: cell.name.clone(),
            build: build.into(),
            set: cell.set.clone(),
            success_rate: Some(r.success_rate),
            completion_rate: Some(r.completion_rate),
            mean_forward_speed: Some(r.mean_forward_speed),
            vel_tracking_error: Some(r.vel_tracking_error),
            yaw_rate_tracking_error: Some(r.yaw_rate_tracking_error),
            mean_yaw_rate: Some(r.mean_yaw_rate),
            falls: Some(r.falls),
            episodes: r.episodes,
            note: None,
        }
    }

    pub fn missing(cell: &str, build: &str, set: &[String], note: String) -> CellResult {
        CellResult {
            cell: cell.into(),
            build: build.into(),
            set: set.to_vec(),
            success_rate: None,
            completion_rate: None,
            mean_forward_speed: None,
            vel_tracking_error: None,
            yaw_rate_tracking_error: None,
            mean_yaw_rate: None,
            falls: None,
            episodes: 0,
            note: Some(note),
        }
    }
}

/// The whole matrix.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sim2SimReport {
    pub checkpoint: String,
    pub config: String,
    pub terrain: String,
    pub level: Option<usize>,
    pub episodes: usize,
    /// Builds in column order (this one first).
    pub builds: Vec<String>,
    pub cells: Vec<CellResult>,
}

/// Run every cell in this build (`cfg`: the checkpoint's config), calling
/// `progress(done, total, cell)` before each.
pub fn run_cells(
    ck: &Checkpoint,
    cfg: &ExperimentConfig,
    c: &Sim2SimConfig,
    threads: usize,
    mut progress: impl FnMut(usize, usize, &str),
) -> Result<Vec<CellResult>, RlError> {
    let o = EvalOptions {
        terrain: c.kind(),
        then: None,
        episodes: c.episodes,
        full_collision: c.full_collision,
        seed: c.seed,
        threads,
        level: c.level,
        table: EvalTable::Eval,
        lane_lookahead: None,
    };
    let base = eval_env_config(cfg, &o);
    let build = this_build();
    let mut out = Vec::with_capacity(c.cells.len());
    for (i, cell) in c.cells.iter().enumerate() {
        progress(i, c.cells.len(), &cell.name);
        // a setting this build cannot run (implicitfast on MuJoCo 2.x) is a
        // note in its cell, not the end of the matrix
        match cell_env(&base, cell) {
            Ok(env) => {
                let r = evaluate_in(ck, cfg, &env, &o)?;
                out.push(CellResult::from_report(cell, &build, &r));
            }
            Err(e) => out.push(CellResult::missing(
                &cell.name,
                &build,
                &cell.set,
                e.to_string(),
            )),
        }
    }
    Ok(out)
}

/// This build's column name: `MuJoCo <version>`.
pub fn this_build() -> String {
    format!("MuJoCo {}", crate::sim::mujoco_version())
}

fn pct(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{:.0} %", 100.0 * v))
}

fn num(v: Option<f64>, d: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.d$}"))
}

impl Sim2SimReport {
    /// The result of `cell` in `build`.
    pub fn get(&self, cell: &str, build: &str) -> Option<&CellResult> {
        self.cells
            .iter()
            .find(|r| r.cell == cell && r.build == build)
    }

    /// Cell names in order of first appearance.
    pub fn cell_names(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for r in &self.cells {
            if !names.contains(&r.cell) {
                names.push(r.cell.clone());
            }
        }
        names
    }

    /// A Markdown table: a row per cell, per build its success (completion),
    /// forward speed and tracking error; then the notes of cells not run.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Sim-to-sim matrix of `{}` ({} lanes{}, {} episodes per cell; `{}`)\n\n",
            self.checkpoint,
            self.terrain,
            self.level
                .map_or(String::new(), |l| format!(" at level {l}")),
            self.episodes,
            self.config
        );
        s.push_str("| setting |");
        for b in &self.builds {
            s.push_str(&format!(
                " {b}: success (completion) | speed m/s | error m/s |"
            ));
        }
        s.push_str("\n|---|");
        for _ in &self.builds {
            s.push_str("---|---|---|");
        }
        s.push('\n');
        let mut notes = Vec::new();
        for name in self.cell_names() {
            s.push_str(&format!("| {name} |"));
            for b in &self.builds {
                match self.get(&name, b) {
                    Some(r) if r.success_rate.is_some() => s.push_str(&format!(
                        " {} ({}) | {} | {} |",
                        pct(r.success_rate),
                        pct(r.completion_rate),
                        num(r.mean_forward_speed, 2),
                        num(r.vel_tracking_error, 3)
                    )),
                    Some(r) => {
                        s.push_str(" - | - | - |");
                        if let Some(n) = &r.note {
                            notes.push(format!("{name} in {b}: {n}"));
                        }
                    }
                    None => s.push_str(" - | - | - |"),
                }
            }
            s.push('\n');
        }
        notes.dedup();
        if !notes.is_empty() {
            s.push('\n');
            for n in notes {
                s.push_str(&format!("- {n}\n"));
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_changes_only_its_keys_and_bad_keys_are_named() {
        let walker =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/specialist/flat.yaml");
        let implicit = ["env.sim.integrator=implicit".to_string()];
        let base = crate::rl::config::load(&walker, &implicit).unwrap().env;
        let cell = Cell {
            name: "dt".into(),
            set: vec!["sim.timestep=0.002".into(), "sim.decimation=10".into()],
        };
        let env = cell_env(&base, &cell).unwrap();
        assert_eq!(env.sim.timestep, 0.002);
        assert_eq!(env.sim.decimation, 10);
        assert_eq!(env.sim.iterations, base.sim.iterations);
        let bad = Cell {
            name: "typo".into(),
            set: vec!["sim.timestpe=0.002".into()],
        };
        let e = cell_env(&base, &bad).unwrap_err().to_string();
        assert!(e.contains("typo"), "{e}");
        let invalid = Cell {
            name: "zero".into(),
            set: vec!["sim.decimation=0".into()],
        };
        assert!(cell_env(&base, &invalid).is_err());
    }
}
