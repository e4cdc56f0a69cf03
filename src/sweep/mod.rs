//! Config-driven sweeps: a sweep file names a base experiment config, axes over
//! any of its keys (a grid, zipped lists, or random draws with a seed), seeds,
//! an optional evaluation and the resources of one run. [`Sweep::runs`] expands
//! it into runs, each a set of `--set` overrides with its own run directory
//! under the sweep's directory; [`run_task`] trains one of them (fresh, or
//! resumed from its directory's checkpoint), evaluates it and writes its
//! `result.json`; [`collect`] gathers every result into one CSV and a PNG of a
//! metric against the swept axis; [`slurm_script`] writes an `sbatch` array with
//! one task per run. `dreampolicy sweep run|task|slurm|collect` (src/cli/sweep.rs)
//! drives them; a local `sweep run` and a Slurm array run the same task body.
//!
//! The sweep directory holds `sweep.yaml` (the sweep file as expanded, so that
//! tasks and `collect` never depend on the file it was made from), `runs.json`
//! (the runs, in index order), `logs/` and one run directory per run.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::config::ConfigError;

/// Everything that can go wrong in a sweep.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("sweep {path}: {message}")]
    Invalid { path: String, message: String },
    #[error("sweep run {run}: {source}")]
    RunConfig {
        run: String,
        #[source]
        source: ConfigError,
    },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("training {run}: {message}")]
    Train { run: String, message: String },
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SweepError + '_ {
    move |source| SweepError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Which trainer a sweep's runs use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Trainer {
    /// `train specialist`: PPO on the G1 env (or the cart-pole), `rl::config`.
    #[default]
    Specialist,
    /// `train world-model`: the diffusion world model, `world_model::config`.
    WorldModel,
    /// `train unified`: the unified policy (`task: unified`), e.g. one run per
    /// world model of the scaling analysis (an axis over `unified.world_model`).
    Unified,
    /// `train dagger`: the distillation baseline (a `dagger:` section).
    Dagger,
    /// `train no-diffusion`: the w/o-diffusion baseline (`task: no_diffusion`).
    NoDiffusion,
}

impl Trainer {
    /// The config keys `--threads` sets (as `train` does).
    fn thread_keys(self) -> &'static [&'static str] {
        match self {
            Trainer::WorldModel => &["train.torch_threads"],
            _ => &["env.threads", "train.torch_threads"],
        }
    }

    /// Whether its runs are policies (an experiment config; `eval` applies).
    fn trains_a_policy(self) -> bool {
        self != Trainer::WorldModel
    }
}

/// The config file kind's loader (`rl::config::load`, `load_world_model`).
type Loader<C> = fn(&Path, &[String]) -> Result<C, ConfigError>;

/// How the axes combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Every combination of the axes' values.
    #[default]
    Grid,
    /// The i-th run takes the i-th value of every axis (all axes as long).
    List,
    /// `samples` draws, each axis from its `values` (uniformly) or its `range`
    /// (uniform, or log-uniform with `log: true`), seeded by `random_seed`.
    Random,
}

/// One swept config key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// A dotted config key, as `--set` takes it (`ppo.learning_rate`).
    pub key: String,
    /// The values (any YAML: numbers, strings, lists).
    #[serde(default)]
    pub values: Vec<serde_yaml::Value>,
    /// `[lo, hi]` for random draws (random mode only).
    #[serde(default)]
    pub range: Option<[f64; 2]>,
    /// Draw from `range` log-uniformly.
    #[serde(default)]
    pub log: bool,
    /// Short label in run names, tables and plots (default: the key's last part).
    #[serde(default)]
    pub name: Option<String>,
    /// What each value is called in run names, in `values`' order (default:
    /// the values themselves; for long ones such as checkpoint paths).
    #[serde(default)]
    pub labels: Vec<String>,
}

impl Axis {
    /// Value `v`'s part of a run name: its label, else the value made safe.
    fn value_name(&self, v: &serde_yaml::Value) -> String {
        match self.values.iter().position(|x| x == v) {
            Some(i) if i < self.labels.len() => {
                name_part(&serde_yaml::Value::from(self.labels[i].as_str()))
            }
            _ => name_part(v),
        }
    }

    /// The label of this axis in run names, tables and plots.
    pub fn label(&self) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| self.key.rsplit('.').next().unwrap_or(&self.key).to_string())
    }
}

/// After training, each run's latest checkpoint is evaluated on lanes
/// (`dreampolicy eval`'s lanes; specialist sweeps of the G1 only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SweepEval {
    /// Terrain of the lanes (`flat`, `stair`, ...).
    pub terrain: String,
    /// Several terrains instead of `terrain` (e.g. the four unseen ones): each
    /// evaluated on its own lanes; `eval.json` then holds their mean
    /// `success_rate` and `completion_rate` and each report under
    /// `per_terrain.<kind>` (a metric such as `eval.per_terrain.wave.success_rate`).
    pub terrains: Vec<String>,
    pub episodes: usize,
    /// Lane level (default: the config's `eval.level`).
    pub level: Option<usize>,
    /// The project's default full-collision scene instead of the training scene.
    pub full_collision: bool,
    pub seed: u64,
}

impl Default for SweepEval {
    fn default() -> Self {
        SweepEval {
            terrain: "flat".into(),
            terrains: Vec::new(),
            episodes: 20,
            level: None,
            full_collision: true,
            seed: 0,
        }
    }
}

impl SweepEval {
    /// The terrains evaluated: `terrains`, or `terrain` alone.
    pub fn kinds(&self) -> Vec<String> {
        if self.terrains.is_empty() {
            vec![self.terrain.clone()]
        } else {
            self.terrains.clone()
        }
    }
}

/// One panel of a sweep's figure (`figure:`): the metric of chosen
/// combinations against x values of the sweep's own choosing, e.g. a list
/// sweep's runs 0-2 against their dataset size and runs 3-6 and 2 against
/// their number of terrain kinds (the paper's scaling figure). Without
/// `figure`, `collect` plots the metric against the first axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FigurePanel {
    pub title: String,
    pub x_label: String,
    /// Combination indices (the runs' order before seeds: in list mode, the
    /// i-th value of every axis); each seed of a combination is its own line.
    pub runs: Vec<usize>,
    /// x of each of `runs`, as long.
    pub x: Vec<f64>,
}

/// What one run needs: the threads it gets locally, and its Slurm request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Resources {
    /// CPU cores per run (`--cpus-per-task`; also the run's torch and physics
    /// threads on Slurm).
    pub cpus_per_task: usize,
    /// Memory per run (`--mem`, e.g. `8G`).
    pub mem: String,
    /// Time limit per array task (`--time`); a task near it is requeued and
    /// resumes from its run directory's checkpoint.
    pub time: String,
    pub partition: Option<String>,
    pub account: Option<String>,
    /// GPUs per run (`--gres=gpu:N`; 0 for none).
    pub gpus: usize,
    /// At most this many array tasks at once (`--array=...%N`).
    pub max_parallel: Option<usize>,
    /// Seconds before the time limit at which the task is told to requeue.
    pub requeue_signal_s: u64,
    /// More `#SBATCH` lines, verbatim (e.g. `--qos=normal`).
    pub extra_sbatch: Vec<String>,
}

impl Default for Resources {
    fn default() -> Self {
        Resources {
            cpus_per_task: 2,
            mem: "8G".into(),
            time: "04:00:00".into(),
            partition: None,
            account: None,
            gpus: 0,
            max_parallel: None,
            requeue_signal_s: 120,
            extra_sbatch: Vec::new(),
        }
    }
}

/// A sweep file (`configs/sweeps/*.yaml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sweep {
    /// The sweep's name (default: the file's stem); its directory is
    /// `runs/sweeps/<name>` unless `--out` says otherwise.
    #[serde(default)]
    pub name: Option<String>,
    /// The base experiment config (relative to the working directory, like
    /// every path in a config).
    pub base: PathBuf,
    #[serde(default)]
    pub trainer: Trainer,
    /// Overrides every run gets, before the axes' (`key=value`, as `--set`).
    #[serde(default)]
    pub set: Vec<String>,
    #[serde(default)]
    pub mode: Mode,
    /// Draws of random mode.
    #[serde(default)]
    pub samples: usize,
    /// Seed of random mode's draws.
    #[serde(default)]
    pub random_seed: u64,
    pub axes: Vec<Axis>,
    /// Every combination runs once per seed (`train.seed`; the env's seed is
    /// left to the base config). Empty: the base config's seed, once.
    #[serde(default)]
    pub seeds: Vec<u64>,
    #[serde(default)]
    pub eval: Option<SweepEval>,
    /// Panels of `summary.png` (default: the metric against the first axis).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub figure: Vec<FigurePanel>,
    #[serde(default)]
    pub resources: Resources,
    /// Columns of `metrics.csv` (and `eval.*` fields) that `collect` tabulates
    /// and plots; the first is the plot's metric. Default: a trainer's headline
    /// columns.
    #[serde(default)]
    pub metrics: Vec<String>,
    /// `collect` averages each metric over this many last rows of a run's
    /// metrics.csv (its final figure, less noisy than the last row).
    #[serde(default = "default_window")]
    pub final_window: usize,
}

fn default_window() -> usize {
    10
}

/// One expanded run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    pub index: usize,
    /// Its directory's name under the sweep directory.
    pub name: String,
    /// `(axis label, config key, value)` of every axis.
    pub values: Vec<(String, String, serde_yaml::Value)>,
    /// `train.seed`, when the sweep lists seeds.
    pub seed: Option<u64>,
    /// Every override of this run, in order: the sweep's `set`, the axes', the seed.
    pub sets: Vec<String>,
}

/// A YAML value as one flow-style token (JSON is YAML): `0.5`, `[0.3,1.2]`, `"x"`.
pub fn value_text(v: &serde_yaml::Value) -> String {
    match v {
        serde_yaml::Value::String(s) => s.clone(),
        other => serde_json::to_string(other).unwrap_or_else(|_| format!("{other:?}")),
    }
}

/// `value_text` made safe for a directory name; a list's items joined by `+`
/// (`[flat, uneven]` names a run `kinds=flat+uneven`).
fn name_part(v: &serde_yaml::Value) -> String {
    let safe = |t: String| -> String {
        t.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    };
    match v {
        serde_yaml::Value::Sequence(items) => items
            .iter()
            .map(|i| safe(value_text(i)))
            .collect::<Vec<_>>()
            .join("+"),
        other => safe(value_text(other)),
    }
}

impl Sweep {
    /// Read and check a sweep file.
    pub fn load(path: &Path) -> Result<Sweep, SweepError> {
        let text = crate::config::read(path)?;
        let mut s: Sweep = crate::config::parse(&text, &path.display().to_string(), &[])?;
        if s.name.is_none() {
            s.name = path.file_stem().map(|n| n.to_string_lossy().into_owned());
        }
        s.check(&path.display().to_string())?;
        Ok(s)
    }

    /// The sweep's name.
    pub fn name(&self) -> String {
        self.name.clone().unwrap_or_else(|| "sweep".into())
    }

    fn check(&self, path: &str) -> Result<(), SweepError> {
        let bad = |message: String| {
            Err(SweepError::Invalid {
                path: path.to_string(),
                message,
            })
        };
        if self.axes.is_empty() {
            return bad("`axes` is empty: a sweep needs at least one axis".into());
        }
        let mut labels = Vec::new();
        for a in &self.axes {
            if a.key.is_empty() || a.key.split('.').any(str::is_empty) {
                return bad(format!("axis key '{}' is not a dotted config key", a.key));
            }
            if labels.contains(&a.label()) {
                return bad(format!(
                    "two axes are labelled '{}': give one a `name`",
                    a.label()
                ));
            }
            labels.push(a.label());
            match (self.mode, a.values.is_empty(), a.range) {
                (Mode::Random, true, None) => {
                    return bad(format!(
                        "axis {}: random mode needs `values` or `range`",
                        a.key
                    ))
                }
                (Mode::Random, _, Some([lo, hi])) => {
                    if !(lo.is_finite() && hi.is_finite() && lo <= hi) || (a.log && lo <= 0.0) {
                        return bad(format!(
                            "axis {}: range [{lo}, {hi}] must be finite, lo <= hi (and lo > 0 with log)",
                            a.key
                        ));
                    }
                }
                (Mode::Random, false, None) => {}
                (_, true, _) => {
                    return bad(format!(
                        "axis {}: `values` is empty (`range` is for random mode)",
                        a.key
                    ))
                }
                (_, false, Some(_)) => {
                    return bad(format!(
                        "axis {}: `range` is for random mode; grid and list take `values`",
                        a.key
                    ))
                }
                (_, false, None) => {}
            }
        }
        if self.mode == Mode::List {
            let n = self.axes[0].values.len();
            if let Some(a) = self.axes.iter().find(|a| a.values.len() != n) {
                return bad(format!(
                    "list mode zips the axes, but {} has {} values and {} has {n}",
                    a.key,
                    a.values.len(),
                    self.axes[0].key
                ));
            }
        }
        if let Some(a) = self
            .axes
            .iter()
            .find(|a| !a.labels.is_empty() && a.labels.len() != a.values.len())
        {
            return bad(format!(
                "axis {}: {} labels for {} values",
                a.key,
                a.labels.len(),
                a.values.len()
            ));
        }
        if self.mode == Mode::Random && self.samples == 0 {
            return bad("random mode needs `samples` >= 1".into());
        }
        if self.resources.cpus_per_task == 0 {
            return bad("resources.cpus_per_task must be >= 1".into());
        }
        if self.final_window == 0 {
            return bad("final_window must be >= 1".into());
        }
        if let Some(e) = &self.eval {
            for k in e.kinds() {
                if let Err(err) = crate::terrain::TerrainKind::from_name(&k) {
                    return bad(format!("eval: {err}"));
                }
            }
        }
        let combinations = self.combinations().len();
        for p in &self.figure {
            if p.runs.is_empty() || p.runs.len() != p.x.len() {
                return bad(format!(
                    "figure panel '{}': {} runs and {} x values (one x per run, at least one)",
                    p.title,
                    p.runs.len(),
                    p.x.len()
                ));
            }
            if let Some(&i) = p.runs.iter().find(|&&i| i >= combinations) {
                return bad(format!(
                    "figure panel '{}': run {i}, but the sweep has {combinations} combinations (0..{})",
                    p.title,
                    combinations.saturating_sub(1)
                ));
            }
            if p.x.iter().any(|x| !x.is_finite()) {
                return bad(format!("figure panel '{}': x must be finite", p.title));
            }
        }
        if self.eval.is_some() && !self.trainer.trains_a_policy() {
            return bad(
                "`eval` evaluates policies: it needs a policy's trainer (specialist, unified, dagger, no_diffusion)"
                    .into(),
            );
        }
        Ok(())
    }

    /// The combinations of axis values, before seeds.
    fn combinations(&self) -> Vec<Vec<serde_yaml::Value>> {
        match self.mode {
            Mode::Grid => {
                let mut out: Vec<Vec<serde_yaml::Value>> = vec![Vec::new()];
                for a in &self.axes {
                    out = out
                        .into_iter()
                        .flat_map(|prefix| {
                            a.values.iter().map(move |v| {
                                let mut p = prefix.clone();
                                p.push(v.clone());
                                p
                            })
                        })
                        .collect();
                }
                out
            }
            Mode::List => (0..self.axes[0].values.len())
                .map(|i| self.axes.iter().map(|a| a.values[i].clone()).collect())
                .collect(),
            Mode::Random => {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.random_seed);
                (0..self.samples)
                    .map(|_| {
                        self.axes
                            .iter()
                            .map(|a| match a.range {
                                Some([lo, hi]) => {
                                    let u: f64 = rng.random();
                                    let x = if a.log {
                                        (lo.ln() + u * (hi.ln() - lo.ln())).exp()
                                    } else {
                                        lo + u * (hi - lo)
                                    };
                                    // four significant digits: readable names
                                    let x = format!("{x:.4e}").parse::<f64>().unwrap_or(x);
                                    serde_yaml::Value::from(x)
                                }
                                None => a.values[rng.random_range(0..a.values.len())].clone(),
                            })
                            .collect()
                    })
                    .collect()
            }
        }
    }

    /// The seeds each combination runs with, in order (None: the base
    /// config's seed, once).
    fn run_seeds(&self) -> Vec<Option<u64>> {
        if self.seeds.is_empty() {
            vec![None]
        } else {
            self.seeds.iter().copied().map(Some).collect()
        }
    }

    /// Every run of the sweep, in index order: the combinations, each once per seed.
    pub fn runs(&self) -> Vec<RunSpec> {
        let seeds = self.run_seeds();
        let mut out = Vec::new();
        for combo in self.combinations() {
            for &seed in &seeds {
                let index = out.len();
                let values: Vec<(String, String, serde_yaml::Value)> = self
                    .axes
                    .iter()
                    .zip(&combo)
                    .map(|(a, v)| (a.label(), a.key.clone(), v.clone()))
                    .collect();
                let mut name = format!("{index:03}");
                for ((label, _, v), a) in values.iter().zip(&self.axes) {
                    name.push_str(&format!("-{label}={}", a.value_name(v)));
                }
                let mut sets = self.set.clone();
                sets.extend(values.iter().map(|(_, k, v)| {
                    format!("{k}={}", serde_json::to_string(v).unwrap_or_default())
                }));
                if let Some(s) = seed {
                    name.push_str(&format!("-seed={s}"));
                    sets.push(format!("train.seed={s}"));
                }
                out.push(RunSpec {
                    index,
                    name,
                    values,
                    seed,
                    sets,
                });
            }
        }
        out
    }

    /// Load every run's config, so that a mistyped key or a bad value stops the
    /// sweep before any run starts (every config struct denies unknown fields).
    pub fn validate_runs(&self) -> Result<(), SweepError> {
        for r in self.runs() {
            match self.trainer {
                Trainer::WorldModel => self
                    .run_config(&r, &[], crate::world_model::config::load_world_model)
                    .map(drop),
                _ => self.run_config(&r, &[], crate::rl::config::load).map(drop),
            }?;
        }
        Ok(())
    }

    /// Run `r`'s config: the base config with the run's overrides, then `extra`
    /// (a task's threads); an error names the run.
    fn run_config<C>(
        &self,
        r: &RunSpec,
        extra: &[String],
        load: Loader<C>,
    ) -> Result<C, SweepError> {
        let mut sets = r.sets.clone();
        sets.extend_from_slice(extra);
        load(&self.base, &sets).map_err(|source| SweepError::RunConfig {
            run: r.name.clone(),
            source,
        })
    }

    /// The config run `r` trains with in `run_dir`: the run directory's own
    /// `config.yaml` when it resumes, else [`Sweep::run_config`]; `threads` sets
    /// the trainer's thread keys either way.
    fn task_config<C>(
        &self,
        r: &RunSpec,
        run_dir: &Path,
        resume: bool,
        threads: usize,
        load: Loader<C>,
    ) -> Result<C, SweepError> {
        let thread_sets: Vec<String> = self
            .trainer
            .thread_keys()
            .iter()
            .map(|k| format!("{k}={threads}"))
            .collect();
        if resume {
            let path = run_dir.join("config.yaml");
            crate::config::require_seal(&path)?;
            Ok(load(&path, &thread_sets)?)
        } else {
            self.run_config(r, &thread_sets, load)
        }
    }

    /// The metrics `collect` reports: the sweep's, or the trainer's headline ones.
    pub fn metric_names(&self) -> Vec<String> {
        if !self.metrics.is_empty() {
            return self.metrics.clone();
        }
        let mut m: Vec<&str> = match self.trainer {
            Trainer::WorldModel => vec!["loss", "val_loss"],
            Trainer::Dagger => vec![
                "imitation_loss",
                "action_error",
                "mean_episode_length",
                "fall_fraction",
            ],
            _ => vec![
                "mean_return",
                "mean_episode_length",
                "vel_error_xy",
                "fall_fraction",
            ],
        };
        if self.eval.is_some() {
            m.splice(0..0, ["eval.success_rate", "eval.completion_rate"]);
        }
        m.into_iter().map(String::from).collect()
    }
}

/// The files of a sweep directory.
#[derive(Debug, Clone)]
pub struct SweepDir {
    pub path: PathBuf,
}

impl SweepDir {
    pub fn new(path: &Path) -> SweepDir {
        SweepDir { path: path.into() }
    }

    pub fn sweep_file(&self) -> PathBuf {
        self.path.join("sweep.yaml")
    }

    pub fn runs_file(&self) -> PathBuf {
        self.path.join("runs.json")
    }

    pub fn run_dir(&self, r: &RunSpec) -> PathBuf {
        self.path.join(&r.name)
    }

    pub fn log_file(&self, r: &RunSpec) -> PathBuf {
        self.path.join("logs").join(format!("{}.log", r.name))
    }

    /// Write the expanded sweep and its runs. A directory made from a different
    /// sweep is refused: its runs would mix with these. A sweep may grow at its
    /// end (list mode: values appended to every axis): the runs already there
    /// keep their index, name and directory.
    pub fn prepare(&self, sweep: &Sweep) -> Result<Vec<RunSpec>, SweepError> {
        let runs = sweep.runs();
        if self.sweep_file().exists() {
            let old = Sweep::load(&self.sweep_file())?;
            let old_runs = old.runs();
            let extends = old_runs.len() <= runs.len() && runs[..old_runs.len()] == old_runs[..];
            if !extends || old.base != sweep.base || old.trainer != sweep.trainer {
                return Err(SweepError::Invalid {
                    path: self.path.display().to_string(),
                    message:
                        "this directory holds a different sweep (other runs, base or trainer; \
                         only runs appended at the end may be added): choose another --out, or delete it"
                            .into(),
                });
            }
        }
        std::fs::create_dir_all(self.path.join("logs")).map_err(io(&self.path))?;
        let yaml = serde_yaml::to_string(sweep).map_err(|e| SweepError::Parse {
            path: self.sweep_file(),
            message: e.to_string(),
        })?;
        write_atomic(&self.sweep_file(), yaml.as_bytes())?;
        let json = serde_json::to_string_pretty(&runs).map_err(|e| SweepError::Parse {
            path: self.runs_file(),
            message: e.to_string(),
        })?;
        write_atomic(&self.runs_file(), json.as_bytes())?;
        Ok(runs)
    }

    /// The sweep and runs written by [`SweepDir::prepare`].
    pub fn open(&self) -> Result<(Sweep, Vec<RunSpec>), SweepError> {
        if !self.sweep_file().exists() {
            return Err(SweepError::Invalid {
                path: self.path.display().to_string(),
                message:
                    "no sweep.yaml: not a sweep directory (`sweep run` or `sweep slurm` makes one)"
                        .into(),
            });
        }
        let sweep = Sweep::load(&self.sweep_file())?;
        let runs = sweep.runs();
        Ok((sweep, runs))
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    crate::run::write_atomic(path, bytes).map_err(|(path, source)| SweepError::Io { path, source })
}

/// Where a run stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunState {
    /// Nothing yet.
    Fresh,
    /// A checkpoint and no result: resumed.
    Interrupted,
    /// `result.json` is written: skipped.
    Finished,
}

pub fn run_state(run_dir: &Path) -> RunState {
    if run_dir.join("result.json").exists() {
        RunState::Finished
    } else if crate::run::latest_checkpoint(run_dir).exists() {
        RunState::Interrupted
    } else {
        RunState::Fresh
    }
}

/// What a finished run wrote (`<run>/result.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    pub index: usize,
    pub name: String,
    /// Axis label -> value.
    pub values: BTreeMap<String, serde_yaml::Value>,
    pub seed: Option<u64>,
    pub iterations: usize,
    /// Env-steps (PPO) or training sequences (world model).
    pub samples: u64,
    pub wall_time_s: f64,
    /// Every metrics.csv column, averaged over the last `final_window` rows
    /// (NaN cells skipped; a column with none left out).
    pub final_metrics: BTreeMap<String, f64>,
    /// The lane evaluation's report, when the sweep has `eval`.
    pub eval: Option<serde_json::Value>,
}

/// The mean of each column over the last `window` rows (NaN cells skipped,
/// columns without a number left out).
pub fn final_metrics(
    metrics_csv: &Path,
    window: usize,
) -> Result<BTreeMap<String, f64>, SweepError> {
    let t = crate::plot::MetricsTable::read(metrics_csv)?;
    let mut out = BTreeMap::new();
    for (name, col) in t.names.iter().zip(&t.columns) {
        let tail = &col[col.len().saturating_sub(window)..];
        let vals: Vec<f64> = tail.iter().copied().filter(|v| v.is_finite()).collect();
        // a column without a number (JSON has no NaN) is left out
        if !vals.is_empty() {
            out.insert(name.clone(), vals.iter().sum::<f64>() / vals.len() as f64);
        }
    }
    Ok(out)
}

/// Train run `r` of `sweep` in `dir` (fresh, or resumed from its checkpoint),
/// evaluate it if the sweep says so, and write its `result.json`. A finished run
/// is returned as it is. `threads` sets the run's torch and physics threads.
pub fn run_task(
    sweep: &Sweep,
    dir: &SweepDir,
    r: &RunSpec,
    threads: usize,
    quiet: bool,
) -> Result<RunResult, SweepError> {
    let run_dir = dir.run_dir(r);
    let result_path = run_dir.join("result.json");
    let state = run_state(&run_dir);
    if state == RunState::Finished {
        return read_result(&result_path);
    }
    let resume = state == RunState::Interrupted;
    let train_err = |message: String| SweepError::Train {
        run: r.name.clone(),
        message,
    };
    let (iterations, samples, wall) = match sweep.trainer {
        Trainer::Specialist | Trainer::Unified | Trainer::Dagger | Trainer::NoDiffusion => {
            let cfg = sweep.task_config(r, &run_dir, resume, threads, crate::rl::config::load)?;
            let s = match sweep.trainer {
                Trainer::Unified => crate::unified::train(&cfg, &run_dir, resume, quiet),
                Trainer::Dagger => crate::baselines::dagger::train(&cfg, &run_dir, resume, quiet),
                Trainer::NoDiffusion => {
                    crate::baselines::no_diffusion::train(&cfg, &run_dir, resume, quiet)
                }
                _ => crate::rl::runner::train(&cfg, &run_dir, resume, quiet),
            }
            .map_err(|e| train_err(e.to_string()))?;
            (s.iterations, s.env_steps, s.wall_time_s)
        }
        Trainer::WorldModel => {
            let load = crate::world_model::config::load_world_model;
            let cfg = sweep.task_config(r, &run_dir, resume, threads, load)?;
            let s = crate::world_model::train(&cfg, &run_dir, resume, quiet)
                .map_err(|e| train_err(e.to_string()))?;
            (s.iterations, s.sequences, s.wall_time_s)
        }
    };
    let eval = match &sweep.eval {
        Some(e) => Some(evaluate_run(&run_dir, e, threads).map_err(train_err)?),
        None => None,
    };
    let result = RunResult {
        index: r.index,
        name: r.name.clone(),
        values: r
            .values
            .iter()
            .map(|(label, _, v)| (label.clone(), v.clone()))
            .collect(),
        seed: r.seed,
        iterations,
        samples,
        wall_time_s: wall,
        final_metrics: final_metrics(&run_dir.join("metrics.csv"), sweep.final_window)?,
        eval,
    };
    let json = serde_json::to_string_pretty(&result).map_err(|e| SweepError::Parse {
        path: result_path.clone(),
        message: e.to_string(),
    })?;
    write_atomic(&result_path, json.as_bytes())?;
    Ok(result)
}

fn evaluate_run(
    run_dir: &Path,
    e: &SweepEval,
    threads: usize,
) -> Result<serde_json::Value, String> {
    let ck = crate::rl::checkpoint::Checkpoint::read(&crate::run::latest_checkpoint(run_dir))
        .map_err(|err| format!("eval: {err}"))?;
    let kinds = e.kinds();
    let mut reports = serde_json::Map::new();
    let (mut success, mut completion) = (0.0, 0.0);
    for name in &kinds {
        let terrain =
            crate::terrain::TerrainKind::from_name(name).map_err(|err| format!("eval: {err}"))?;
        let report = crate::eval::evaluate(
            &ck,
            &crate::eval::EvalOptions {
                terrain,
                then: None,
                episodes: e.episodes,
                full_collision: e.full_collision,
                seed: e.seed,
                threads,
                level: e.level,
                table: crate::eval::EvalTable::Eval,
                lane_lookahead: None,
            },
        )
        .map_err(|err| format!("eval on {name}: {err}"))?;
        success += report.success_rate;
        completion += report.completion_rate;
        let json = serde_json::to_value(&report).map_err(|err| err.to_string())?;
        reports.insert(name.clone(), json);
    }
    let json = if kinds.len() == 1 {
        reports
            .into_iter()
            .next()
            .map(|(_, v)| v)
            .unwrap_or_default()
    } else {
        let n = kinds.len() as f64;
        serde_json::json!({
            "terrains": kinds,
            "success_rate": success / n,
            "completion_rate": completion / n,
            "per_terrain": reports,
        })
    };
    std::fs::write(
        run_dir.join("eval.json"),
        serde_json::to_string_pretty(&json).unwrap_or_default(),
    )
    .map_err(|err| format!("writing eval.json: {err}"))?;
    Ok(json)
}

pub fn read_result(path: &Path) -> Result<RunResult, SweepError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|e| SweepError::Parse {
        path: path.into(),
        message: e.to_string(),
    })
}

impl RunResult {
    /// A metric by name: a metrics.csv column, or `eval.<field>` (a dotted
    /// path into the report, `eval.per_terrain.wave.success_rate`); NaN if absent.
    pub fn metric(&self, name: &str) -> f64 {
        if let Some(path) = name.strip_prefix("eval.") {
            let mut v = self.eval.as_ref();
            for key in path.split('.') {
                v = v.and_then(|x| x.get(key));
            }
            return v.and_then(serde_json::Value::as_f64).unwrap_or(f64::NAN);
        }
        self.final_metrics.get(name).copied().unwrap_or(f64::NAN)
    }
}

/// A run and its result, None until it has finished.
type RunEntry = (RunSpec, Option<RunResult>);

/// What `collect` found.
#[derive(Debug, Clone)]
pub struct Collected {
    pub sweep: Sweep,
    /// Every run's result, None where it has not finished.
    pub results: Vec<(RunSpec, Option<RunResult>)>,
    pub csv: PathBuf,
    pub png: Option<PathBuf>,
    pub markdown: String,
}

/// Gather every finished run of the sweep in `dir` into `summary.csv` (one row
/// per run: axes, seed, iterations, samples, wall time, metrics) and
/// `summary.png` (the first metric, or `metric`, against the first axis: one
/// line per seed and their mean, one panel per combination of the other axes);
/// returns the per-combination Markdown table (mean and spread over seeds).
pub fn collect(dir: &SweepDir, metric: Option<&str>) -> Result<Collected, SweepError> {
    let (sweep, runs) = dir.open()?;
    let mut metrics = sweep.metric_names();
    if let Some(m) = metric {
        metrics.retain(|x| x != m);
        metrics.insert(0, m.to_string());
    }
    let results: Vec<(RunSpec, Option<RunResult>)> = runs
        .into_iter()
        .map(|r| {
            let p = dir.run_dir(&r).join("result.json");
            let res = if p.exists() {
                Some(read_result(&p)?)
            } else {
                None
            };
            Ok((r, res))
        })
        .collect::<Result<_, SweepError>>()?;

    // the CSV: one row per run
    let labels: Vec<String> = sweep.axes.iter().map(Axis::label).collect();
    let mut csv = String::new();
    let mut head = vec!["index".to_string(), "name".into()];
    head.extend(labels.iter().cloned());
    head.extend(["seed", "finished", "iterations", "samples", "wall_time_s"].map(String::from));
    head.extend(metrics.iter().cloned());
    csv.push_str(&head.join(","));
    csv.push('\n');
    for (r, res) in &results {
        let mut row = vec![r.index.to_string(), r.name.clone()];
        row.extend(r.values.iter().map(|(_, _, v)| csv_cell(&value_text(v))));
        row.push(r.seed.map(|s| s.to_string()).unwrap_or_default());
        match res {
            Some(x) => {
                row.push("1".into());
                row.push(x.iterations.to_string());
                row.push(x.samples.to_string());
                row.push(format!("{:.1}", x.wall_time_s));
                row.extend(metrics.iter().map(|m| fmt_num(x.metric(m))));
            }
            None => {
                row.push("0".into());
                row.extend(std::iter::repeat_n(String::new(), 3 + metrics.len()));
            }
        }
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    let csv_path = dir.path.join("summary.csv");
    write_atomic(&csv_path, csv.as_bytes())?;

    // combinations: mean and spread over seeds
    let mut groups: Vec<(Vec<String>, Vec<&RunResult>)> = Vec::new();
    for (r, res) in &results {
        let key: Vec<String> = r.values.iter().map(|(_, _, v)| value_text(v)).collect();
        let pos = match groups.iter().position(|g| g.0 == key) {
            Some(p) => p,
            None => {
                groups.push((key, Vec::new()));
                groups.len() - 1
            }
        };
        if let Some(x) = res {
            groups[pos].1.push(x);
        }
    }
    let mut md = format!("| {} | runs |", labels.join(" | "));
    for m in &metrics {
        md.push_str(&format!(" {m} |"));
    }
    md.push('\n');
    md.push_str(&"|---".repeat(labels.len() + 1 + metrics.len()));
    md.push_str("|\n");
    for (key, rs) in &groups {
        md.push_str(&format!("| {} | {} |", key.join(" | "), rs.len()));
        for m in &metrics {
            let v: Vec<f64> = rs
                .iter()
                .map(|x| x.metric(m))
                .filter(|v| v.is_finite())
                .collect();
            md.push_str(&format!(" {} |", mean_spread(&v)));
        }
        md.push('\n');
    }

    let png = plot_collected(dir, &sweep, &results, &metrics[0])?;
    Ok(Collected {
        sweep,
        results,
        csv: csv_path,
        png,
        markdown: md,
    })
}

fn csv_cell(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn fmt_num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.6}")
    } else {
        String::new()
    }
}

/// `mean ± half the range` of seeds' values (`mean` alone for one seed).
fn mean_spread(v: &[f64]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    if v.len() == 1 {
        return format!("{mean:.4}");
    }
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!("{mean:.4} ± {:.4}", (hi - lo) / 2.0)
}

/// The first axis on x (its values, or their index where they are not
/// numbers), `metric` on y: a line per seed and their mean, a panel per
/// combination of the other axes. None when no run has finished.
fn plot_collected(
    dir: &SweepDir,
    sweep: &Sweep,
    results: &[(RunSpec, Option<RunResult>)],
    metric: &str,
) -> Result<Option<PathBuf>, SweepError> {
    if results.iter().all(|(_, r)| r.is_none()) {
        return Ok(None);
    }
    let png = dir.path.join("summary.png");
    if !sweep.figure.is_empty() {
        let series = figure_series(sweep, results, metric);
        crate::plot::plot_series(&png, &format!("sweep {}: {metric}", sweep.name()), &series)?;
        return Ok(Some(png));
    }
    let axis = &sweep.axes[0];
    // x positions: the first axis' distinct values in order of appearance
    let mut xs_text: Vec<String> = Vec::new();
    for (r, _) in results {
        let t = value_text(&r.values[0].2);
        if !xs_text.contains(&t) {
            xs_text.push(t);
        }
    }
    let numeric: Option<Vec<f64>> = xs_text.iter().map(|t| t.parse::<f64>().ok()).collect();
    let (mut order, x_label): (Vec<usize>, String) = match &numeric {
        Some(_) => ((0..xs_text.len()).collect(), axis.label()),
        None => (
            (0..xs_text.len()).collect(),
            format!("{} (index of {})", axis.label(), xs_text.join(", ")),
        ),
    };
    if let Some(v) = &numeric {
        order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    }
    let x: Vec<f64> = order
        .iter()
        .map(|&i| numeric.as_ref().map(|v| v[i]).unwrap_or(i as f64))
        .collect();
    // panels: combinations of the other axes
    let mut panels: Vec<(String, Vec<&RunEntry>)> = Vec::new();
    for item in results {
        let rest: Vec<String> = item.0.values[1..]
            .iter()
            .map(|(l, _, v)| format!("{l}={}", value_text(v)))
            .collect();
        let title = if rest.is_empty() {
            format!("{metric} against {}", axis.label())
        } else {
            rest.join(", ")
        };
        match panels.iter_mut().find(|p| p.0 == title) {
            Some(p) => p.1.push(item),
            None => panels.push((title, vec![item])),
        }
    }
    let seeds: Vec<Option<u64>> = {
        let mut s: Vec<Option<u64>> = Vec::new();
        for (r, _) in results {
            if !s.contains(&r.seed) {
                s.push(r.seed);
            }
        }
        s
    };
    let series: Vec<crate::plot::SeriesPanel> = panels
        .iter()
        .map(|(title, items)| {
            let at = |seed: Option<u64>, xi: usize| -> f64 {
                items
                    .iter()
                    .find(|(r, _)| r.seed == seed && value_text(&r.values[0].2) == xs_text[xi])
                    .and_then(|(_, res)| res.as_ref())
                    .map(|res| res.metric(metric))
                    .unwrap_or(f64::NAN)
            };
            let mut lines: Vec<(String, Vec<f64>)> = seeds
                .iter()
                .map(|&s| {
                    let name = s
                        .map(|s| format!("seed {s}"))
                        .unwrap_or_else(|| "run".into());
                    (name, order.iter().map(|&xi| at(s, xi)).collect())
                })
                .collect();
            if seeds.len() > 1 {
                let mean: Vec<f64> = order
                    .iter()
                    .map(|&xi| finite_mean(seeds.iter().map(|&s| at(s, xi))))
                    .collect();
                lines.push(("mean".into(), mean));
            }
            crate::plot::SeriesPanel {
                title: title.clone(),
                x_label: x_label.clone(),
                x: x.clone(),
                lines,
            }
        })
        .collect();
    crate::plot::plot_series(&png, &format!("sweep {}: {metric}", sweep.name()), &series)?;
    Ok(Some(png))
}

/// The mean of the finite values (seeds' figures, unfinished runs' NaN left
/// out); NaN when there is none.
fn finite_mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// The panels of a sweep's `figure`: for each, `metric` of its combinations
/// at its x values, a line per seed (NaN where a run has not finished) and
/// their mean when there are several seeds.
pub fn figure_series(
    sweep: &Sweep,
    results: &[(RunSpec, Option<RunResult>)],
    metric: &str,
) -> Vec<crate::plot::SeriesPanel> {
    let seeds = sweep.run_seeds();
    let n_seeds = seeds.len();
    let at = |combination: usize, seed: Option<u64>| -> f64 {
        results
            .iter()
            .find(|(r, _)| r.index / n_seeds == combination && r.seed == seed)
            .and_then(|(_, res)| res.as_ref())
            .map_or(f64::NAN, |res| res.metric(metric))
    };
    sweep
        .figure
        .iter()
        .map(|p| {
            // points in order of x
            let mut order: Vec<usize> = (0..p.runs.len()).collect();
            order.sort_by(|&a, &b| p.x[a].total_cmp(&p.x[b]));
            let mut lines: Vec<(String, Vec<f64>)> = seeds
                .iter()
                .map(|&s| {
                    let name = s.map_or_else(|| "run".into(), |s| format!("seed {s}"));
                    (name, order.iter().map(|&i| at(p.runs[i], s)).collect())
                })
                .collect();
            if seeds.len() > 1 {
                let mean = order
                    .iter()
                    .map(|&i| finite_mean(seeds.iter().map(|&s| at(p.runs[i], s))))
                    .collect();
                lines.push(("mean".into(), mean));
            }
            crate::plot::SeriesPanel {
                title: format!("{}: {metric}", p.title),
                x_label: p.x_label.clone(),
                x: order.iter().map(|&i| p.x[i]).collect(),
                lines,
            }
        })
        .collect()
}

/// The `sbatch` array script of the sweep in `dir`: one task per run, each
/// running `<binary> sweep task --dir <dir> --index $SLURM_ARRAY_TASK_ID`
/// from `workdir` (where the sweep's relative paths resolve). Near its time
/// limit a task is signalled, stops its run and requeues itself; the requeued
/// task resumes from the run directory's checkpoint, and a finished run is
/// skipped.
pub fn slurm_script(
    sweep: &Sweep,
    dir: &Path,
    n_runs: usize,
    workdir: &Path,
    binary: &Path,
) -> String {
    let r = &sweep.resources;
    let q = |p: &Path| shell_quote(&p.display().to_string());
    let mut s = String::new();
    s.push_str("#!/bin/bash\n");
    s.push_str(&format!(
        "# Written by `dreampolicy sweep slurm` for sweep {} ({n_runs} runs).\n\
         # Submit with: sbatch {}\n\
         # Each array task trains one run (resumed from its checkpoint after a\n\
         # requeue; skipped when finished); `dreampolicy sweep collect {}` gathers them.\n",
        sweep.name(),
        q(&dir.join("sweep.sbatch")),
        q(dir)
    ));
    s.push_str(&format!("#SBATCH --job-name=dp-{}\n", sweep.name()));
    let mut array = format!("0-{}", n_runs.saturating_sub(1));
    if let Some(m) = r.max_parallel {
        array.push_str(&format!("%{m}"));
    }
    s.push_str(&format!("#SBATCH --array={array}\n"));
    s.push_str(&format!("#SBATCH --cpus-per-task={}\n", r.cpus_per_task));
    s.push_str(&format!("#SBATCH --mem={}\n", r.mem));
    s.push_str(&format!("#SBATCH --time={}\n", r.time));
    if let Some(p) = &r.partition {
        s.push_str(&format!("#SBATCH --partition={p}\n"));
    }
    if let Some(a) = &r.account {
        s.push_str(&format!("#SBATCH --account={a}\n"));
    }
    if r.gpus > 0 {
        s.push_str(&format!("#SBATCH --gres=gpu:{}\n", r.gpus));
    }
    s.push_str(&format!(
        "#SBATCH --output={}/logs/slurm-%A_%a.out\n",
        dir.display()
    ));
    s.push_str("#SBATCH --open-mode=append\n#SBATCH --requeue\n");
    s.push_str(&format!("#SBATCH --signal=B:USR1@{}\n", r.requeue_signal_s));
    for e in &r.extra_sbatch {
        s.push_str(&format!("#SBATCH {e}\n"));
    }
    s.push_str(&format!(
        r#"set -uo pipefail
cd {workdir} || exit 1
DREAMPOLICY="${{DREAMPOLICY:-{binary}}}"
TASK="${{SLURM_ARRAY_TASK_ID:?run this script with sbatch, or set SLURM_ARRAY_TASK_ID to a run index}}"
THREADS="${{SLURM_CPUS_PER_TASK:-{cpus}}}"
child=""
requeue() {{
  echo "task $TASK: time limit near, stopping the run and requeueing it"
  [ -n "$child" ] && kill -TERM "$child" 2>/dev/null && wait "$child"
  scontrol requeue "${{SLURM_ARRAY_JOB_ID}}_${{TASK}}"
  exit 0
}}
trap requeue USR1
"$DREAMPOLICY" sweep task --dir {dir} --index "$TASK" --threads "$THREADS" --quiet &
child=$!
wait "$child"
"#,
        workdir = q(workdir),
        binary = q(binary),
        cpus = r.cpus_per_task,
        dir = q(dir),
    ));
    s
}

fn shell_quote(s: &str) -> String {
    if s.chars()
        .all(|c| c.is_ascii_alphanumeric() || "/._-+=:,".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}
