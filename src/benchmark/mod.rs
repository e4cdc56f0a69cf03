//! `dreampolicy benchmark`: every method checkpoint a config names on the
//! paper's lanes (issue 20): the five training terrains ("single"), the four
//! unseen ones and the five combined pairs, at the config's levels, with
//! `episodes` seeded episodes a cell through [`crate::eval::evaluate`] (its
//! VecEnv runs the episodes in parallel).
//!
//! A cell is one (method, terrain, level). Its success and completion rates
//! carry 95 % Wilson score intervals over its episodes; for the completion rate
//! (a mean of per-episode fractions in [0, 1], whose variance is at most
//! p (1 - p)) the same interval is a conservative one. Cells are written to
//! `results.csv` as they finish (rewritten whole via `.tmp` + rename), and a
//! second run of the same config keeps every cell already measured with the
//! same checkpoint, episodes, seed and scene: an interrupted benchmark resumes.
//!
//! The report ([`report`]) lays the cells out as the paper's tables (single,
//! unseen, combined) with the paper's published numbers beside ours in their
//! own column group (never mixed into ours), a heatmap of success per table and
//! a bar chart with the intervals.
pub mod report;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::eval::{EvalOptions, EvalTable};
use crate::rl::checkpoint::Checkpoint;
use crate::terrain::{TerrainKind, COMBINED_PAIRS};

/// Errors of a benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchmarkError {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Rl(#[from] crate::rl::RlError),
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}", path = .path.display())]
    Invalid { path: PathBuf, message: String },
}

impl BenchmarkError {
    fn io(path: &Path, source: std::io::Error) -> BenchmarkError {
        BenchmarkError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// The paper's tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Table {
    /// The five training terrains (the paper's radar figure).
    Single,
    /// Slope bridge, balancing beam, wave, slope (the paper's Table 1).
    Unseen,
    /// The five combined pairs (the paper's Table 2).
    Combined,
}

impl Table {
    pub const ALL: [Table; 3] = [Table::Single, Table::Unseen, Table::Combined];

    pub fn name(self) -> &'static str {
        match self {
            Table::Single => "single",
            Table::Unseen => "unseen",
            Table::Combined => "combined",
        }
    }

    /// The names of [`Table::lanes`] (`stair&gap` for a combined lane).
    pub fn lane_names(self) -> Vec<String> {
        self.lanes()
            .iter()
            .map(|(a, b)| crate::eval::lane_name(*a, *b))
            .collect()
    }

    /// The table's lanes, in the paper's column order: (first kind, second kind
    /// of a combined lane).
    pub fn lanes(self) -> Vec<(TerrainKind, Option<TerrainKind>)> {
        match self {
            Table::Single => TerrainKind::TRAINING.iter().map(|k| (*k, None)).collect(),
            Table::Unseen => [
                TerrainKind::SlopeBridge,
                TerrainKind::BalancingBeam,
                TerrainKind::Wave,
                TerrainKind::Slope,
            ]
            .iter()
            .map(|k| (*k, None))
            .collect(),
            Table::Combined => COMBINED_PAIRS.iter().map(|(a, b)| (*a, Some(*b))).collect(),
        }
    }
}

/// The paper's rows, whose published numbers sit beside a method's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PaperMethod {
    Ours,
    Distillation,
    WithoutDiffusion,
    WithoutGcrl,
}

impl PaperMethod {
    /// Every row of the paper's tables, in their order.
    pub const ALL: [PaperMethod; 4] = [
        PaperMethod::Ours,
        PaperMethod::Distillation,
        PaperMethod::WithoutDiffusion,
        PaperMethod::WithoutGcrl,
    ];
}

/// One method of the comparison.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Method {
    /// Its row name in the tables.
    pub name: String,
    /// The checkpoint for every lane...
    #[serde(default)]
    pub checkpoint: Option<PathBuf>,
    /// ...or one per terrain kind (the specialists: each on its own terrain; a
    /// combined lane takes its first kind's). Kinds without one are not measured.
    #[serde(default)]
    pub checkpoints: BTreeMap<String, PathBuf>,
    /// The paper's row to print beside it.
    #[serde(default)]
    pub paper: Option<PaperMethod>,
}

impl Method {
    /// The checkpoint of a lane starting on `kind`, if the method has one.
    pub fn checkpoint_for(&self, kind: TerrainKind) -> Option<&Path> {
        self.checkpoints
            .get(kind.name())
            .or(self.checkpoint.as_ref())
            .map(|p| p.as_path())
    }
}

/// A benchmark file (`configs/benchmark/*.yaml`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BenchmarkConfig {
    /// The report's title.
    #[serde(default)]
    pub name: Option<String>,
    pub methods: Vec<Method>,
    #[serde(default = "all_tables")]
    pub tables: Vec<Table>,
    /// Levels of each lane's table (`eval.terrain` of the checkpoint's config:
    /// the paper's table by default).
    #[serde(default = "level_zero")]
    pub levels: Vec<usize>,
    /// Episodes a cell (spread over `eval.lanes` lanes, as `eval` does).
    pub episodes: usize,
    #[serde(default)]
    pub seed: u64,
    /// The project's default scene (every collision), as `eval --full-collision`.
    #[serde(default = "yes")]
    pub full_collision: bool,
    /// Physics threads of each cell's VecEnv.
    #[serde(default = "one")]
    pub threads: usize,
}

fn all_tables() -> Vec<Table> {
    Table::ALL.to_vec()
}
fn level_zero() -> Vec<usize> {
    vec![0]
}
fn yes() -> bool {
    true
}
fn one() -> usize {
    1
}

impl BenchmarkConfig {
    /// Read and check a benchmark file, `--set` overrides applied first.
    /// Relative checkpoint paths are the caller's (the repository root).
    pub fn load(path: &Path, overrides: &[String]) -> Result<BenchmarkConfig, BenchmarkError> {
        let text = crate::config::read(path)?;
        let c: BenchmarkConfig =
            crate::config::parse(&text, &path.display().to_string(), overrides)?;
        c.check(path)?;
        Ok(c)
    }

    fn check(&self, path: &Path) -> Result<(), BenchmarkError> {
        let bad = |message: String| {
            Err(BenchmarkError::Invalid {
                path: path.to_path_buf(),
                message,
            })
        };
        if self.methods.is_empty() {
            return bad("`methods` is empty".into());
        }
        let mut names = std::collections::BTreeSet::new();
        for m in &self.methods {
            if m.name.is_empty() || m.name.contains(',') || !names.insert(&m.name) {
                return bad(format!(
                    "method names must be non-empty, without commas and distinct, got {:?}",
                    m.name
                ));
            }
            if m.checkpoint.is_none() && m.checkpoints.is_empty() {
                return bad(format!(
                    "method {} names no `checkpoint` and no `checkpoints`",
                    m.name
                ));
            }
            for k in m.checkpoints.keys() {
                if let Err(e) = TerrainKind::from_name(k) {
                    return bad(format!("method {}: {e}", m.name));
                }
            }
        }
        if self.tables.is_empty() {
            return bad("`tables` is empty".into());
        }
        if self.levels.is_empty() {
            return bad("`levels` is empty".into());
        }
        if self.episodes == 0 {
            return bad("`episodes` must be at least 1".into());
        }
        if self.threads == 0 {
            return bad("`threads` must be at least 1".into());
        }
        Ok(())
    }

    /// Every cell of the benchmark, in report order: table, method, lane, level.
    pub fn cells(&self) -> Vec<Cell> {
        let mut cells = Vec::new();
        for table in &self.tables {
            for m in &self.methods {
                for (first, then) in table.lanes() {
                    let Some(ck) = m.checkpoint_for(first) else {
                        continue;
                    };
                    for level in &self.levels {
                        cells.push(Cell {
                            table: *table,
                            method: m.name.clone(),
                            checkpoint: ck.to_path_buf(),
                            first,
                            then,
                            level: *level,
                        });
                    }
                }
            }
        }
        cells
    }
}

/// One measurement to make.
#[derive(Debug, Clone)]
pub struct Cell {
    pub table: Table,
    pub method: String,
    pub checkpoint: PathBuf,
    pub first: TerrainKind,
    pub then: Option<TerrainKind>,
    pub level: usize,
}

impl Cell {
    pub fn lane(&self) -> String {
        crate::eval::lane_name(self.first, self.then)
    }
}

/// 95 % Wilson score interval of `p` observed over `n` trials.
pub fn wilson(p: f64, n: usize) -> (f64, f64) {
    if n == 0 || !p.is_finite() {
        return (f64::NAN, f64::NAN);
    }
    let z = 1.959_963_984_540_054_f64;
    let n = n as f64;
    let p = p.clamp(0.0, 1.0);
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt() / denom;
    // at the edges the interval ends exactly at the observed rate
    let lo = if p == 0.0 {
        0.0
    } else {
        (centre - half).max(0.0)
    };
    let hi = if p == 1.0 {
        1.0
    } else {
        (centre + half).min(1.0)
    };
    (lo, hi)
}

/// One measured cell: a row of `results.csv`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    pub table: Table,
    pub method: String,
    pub lane: String,
    pub level: usize,
    pub checkpoint: String,
    pub checkpoint_iteration: usize,
    pub checkpoint_env_steps: u64,
    pub episodes: usize,
    pub seed: u64,
    pub full_collision: bool,
    pub success_rate: f64,
    pub success_lo: f64,
    pub success_hi: f64,
    pub completion_rate: f64,
    pub completion_lo: f64,
    pub completion_hi: f64,
    pub falls: usize,
    pub mean_forward_speed: f64,
    pub wall_s: f64,
}

/// The columns of `results.csv`, in order.
pub const CSV_COLUMNS: [&str; 19] = [
    "table",
    "method",
    "lane",
    "level",
    "checkpoint",
    "checkpoint_iteration",
    "checkpoint_env_steps",
    "episodes",
    "seed",
    "full_collision",
    "success_rate",
    "success_lo",
    "success_hi",
    "completion_rate",
    "completion_lo",
    "completion_hi",
    "falls",
    "mean_forward_speed",
    "wall_s",
];

impl Row {
    fn csv(&self) -> String {
        let f = |v: f64| format!("{v:.6}");
        [
            self.table.name().to_string(),
            self.method.clone(),
            self.lane.clone(),
            self.level.to_string(),
            self.checkpoint.clone(),
            self.checkpoint_iteration.to_string(),
            self.checkpoint_env_steps.to_string(),
            self.episodes.to_string(),
            self.seed.to_string(),
            self.full_collision.to_string(),
            f(self.success_rate),
            f(self.success_lo),
            f(self.success_hi),
            f(self.completion_rate),
            f(self.completion_lo),
            f(self.completion_hi),
            self.falls.to_string(),
            f(self.mean_forward_speed),
            format!("{:.1}", self.wall_s),
        ]
        .join(",")
    }

    fn parse(line: &str) -> Option<Row> {
        let v: Vec<&str> = line.split(',').collect();
        if v.len() != CSV_COLUMNS.len() {
            return None;
        }
        let table = Table::ALL.into_iter().find(|t| t.name() == v[0])?;
        Some(Row {
            table,
            method: v[1].to_string(),
            lane: v[2].to_string(),
            level: v[3].parse().ok()?,
            checkpoint: v[4].to_string(),
            checkpoint_iteration: v[5].parse().ok()?,
            checkpoint_env_steps: v[6].parse().ok()?,
            episodes: v[7].parse().ok()?,
            seed: v[8].parse().ok()?,
            full_collision: v[9].parse().ok()?,
            success_rate: v[10].parse().ok()?,
            success_lo: v[11].parse().ok()?,
            success_hi: v[12].parse().ok()?,
            completion_rate: v[13].parse().ok()?,
            completion_lo: v[14].parse().ok()?,
            completion_hi: v[15].parse().ok()?,
            falls: v[16].parse().ok()?,
            mean_forward_speed: v[17].parse().ok()?,
            wall_s: v[18].parse().ok()?,
        })
    }

    /// Whether this row measured `cell` as the config asks now.
    fn measures(&self, cell: &Cell, cfg: &BenchmarkConfig, ck: &Checkpoint) -> bool {
        self.table == cell.table
            && self.method == cell.method
            && self.lane == cell.lane()
            && self.level == cell.level
            && self.checkpoint == cell.checkpoint.display().to_string()
            && self.checkpoint_iteration == ck.meta.iteration
            && self.checkpoint_env_steps == ck.meta.env_steps
            && self.episodes == cfg.episodes
            && self.seed == cfg.seed
            && self.full_collision == cfg.full_collision
    }
}

/// Read `results.csv` (missing: no rows). Rows that do not parse are dropped
/// (a run killed mid-write leaves none: the file is replaced whole).
pub fn read_results(path: &Path) -> Result<Vec<Row>, BenchmarkError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(BenchmarkError::io(path, e)),
    };
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h == CSV_COLUMNS.join(",") => {}
        None => return Ok(Vec::new()),
        Some(_) => {
            return Err(BenchmarkError::Invalid {
                path: path.to_path_buf(),
                message: "not a benchmark results.csv (its header differs); \
                          choose another --out"
                    .into(),
            })
        }
    }
    Ok(lines.filter_map(Row::parse).collect())
}

fn write_results(path: &Path, rows: &[Row]) -> Result<(), BenchmarkError> {
    let mut text = CSV_COLUMNS.join(",");
    text.push('\n');
    for r in rows {
        text.push_str(&r.csv());
        text.push('\n');
    }
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, text).map_err(|e| BenchmarkError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| BenchmarkError::io(path, e))
}

/// What a benchmark run did.
#[derive(Debug, Clone, Serialize)]
pub struct BenchmarkSummary {
    pub out: String,
    pub cells: usize,
    /// Cells measured by this run, and kept from an earlier one.
    pub measured: usize,
    pub kept: usize,
    pub wall_s: f64,
    pub mujoco_version: String,
    pub rows: Vec<Row>,
}

/// Measure every cell of `cfg` not yet in `out/results.csv`, then write the
/// report. `progress(i, n, cell)` is called before each cell.
pub fn run(
    cfg: &BenchmarkConfig,
    out: &Path,
    mut progress: impl FnMut(usize, usize, &Cell, bool),
) -> Result<BenchmarkSummary, BenchmarkError> {
    std::fs::create_dir_all(out).map_err(|e| BenchmarkError::io(out, e))?;
    let csv = out.join("results.csv");
    let old = read_results(&csv)?;
    let cells = cfg.cells();
    let started = std::time::Instant::now();
    let mut rows: Vec<Row> = Vec::with_capacity(cells.len());
    let (mut measured, mut kept) = (0, 0);
    let mut checkpoints: BTreeMap<PathBuf, Checkpoint> = BTreeMap::new();
    for (i, cell) in cells.iter().enumerate() {
        if !checkpoints.contains_key(&cell.checkpoint) {
            let ck = Checkpoint::read(&cell.checkpoint)?;
            checkpoints.insert(cell.checkpoint.clone(), ck);
        }
        let ck = &checkpoints[&cell.checkpoint];
        if let Some(r) = old.iter().find(|r| r.measures(cell, cfg, ck)) {
            progress(i, cells.len(), cell, true);
            rows.push(r.clone());
            kept += 1;
            continue;
        }
        progress(i, cells.len(), cell, false);
        let t0 = std::time::Instant::now();
        let o = EvalOptions {
            terrain: cell.first,
            then: cell.then,
            episodes: cfg.episodes,
            full_collision: cfg.full_collision,
            seed: cfg.seed,
            threads: cfg.threads,
            level: Some(cell.level),
            table: EvalTable::Eval,
            lane_lookahead: None,
        };
        let r = crate::eval::evaluate(ck, &o)?;
        let (slo, shi) = wilson(r.success_rate, r.episodes);
        let (clo, chi) = wilson(r.completion_rate, r.episodes);
        rows.push(Row {
            table: cell.table,
            method: cell.method.clone(),
            lane: cell.lane(),
            level: cell.level,
            checkpoint: cell.checkpoint.display().to_string(),
            checkpoint_iteration: ck.meta.iteration,
            checkpoint_env_steps: ck.meta.env_steps,
            episodes: r.episodes,
            seed: cfg.seed,
            full_collision: cfg.full_collision,
            success_rate: r.success_rate,
            success_lo: slo,
            success_hi: shi,
            completion_rate: r.completion_rate,
            completion_lo: clo,
            completion_hi: chi,
            falls: r.falls,
            mean_forward_speed: r.mean_forward_speed,
            wall_s: t0.elapsed().as_secs_f64(),
        });
        measured += 1;
        // every finished cell on disk: a killed run loses at most the one it was in
        let mut all = rows.clone();
        all.extend(
            old.iter()
                .filter(|o| !rows.iter().any(|r| same_cell(r, o)))
                .cloned(),
        );
        write_results(&csv, &all)?;
    }
    write_results(&csv, &rows)?;
    report::write(cfg, &rows, out)?;
    Ok(BenchmarkSummary {
        out: out.display().to_string(),
        cells: cells.len(),
        measured,
        kept,
        wall_s: started.elapsed().as_secs_f64(),
        mujoco_version: crate::sim::mujoco_version(),
        rows,
    })
}

fn same_cell(a: &Row, b: &Row) -> bool {
    (a.table, &a.method, &a.lane, a.level) == (b.table, &b.method, &b.lane, b.level)
}
