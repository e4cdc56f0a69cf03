//! Run directories and progress: what every long job writes and shows.
//!
//! A run directory holds `config.yaml` (the resolved config), `metrics.csv` (one
//! row per logging step, header first), for a trainer the same scalars as a
//! TensorBoard event file ([`tensorboard`]), `log.txt`, `checkpoints/latest.pt` (the
//! resume checkpoint) and `checkpoints/iter_NNNNNN.pt` (kept copies). Progress is an `indicatif`
//! bar with rate and ETA on a terminal; with `--quiet` or when stderr is not a
//! terminal it falls back to plain log lines.
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};

use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

pub mod tensorboard;

/// Errors around a run directory.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write the resolved config: {0}")]
    Yaml(#[from] serde_yaml::Error),
    #[error("metrics.csv: row has {got} values for {expected} columns")]
    Columns { expected: usize, got: usize },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Write `bytes` to `<path>.tmp`, fsync it and rename it over `path`: a kill at
/// any moment leaves either the old file or the new one, never half of one.
/// On failure the error names the file it concerns.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), (PathBuf, std::io::Error)> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let written =
        File::create(&tmp).and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()));
    written.map_err(|e| (tmp.clone(), e))?;
    std::fs::rename(&tmp, path).map_err(|e| (path.to_path_buf(), e))
}

/// The latest resume checkpoint of a run directory: `checkpoints/latest.pt`.
pub fn latest_checkpoint(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoints").join("latest.pt")
}

/// Copy `checkpoints/latest.pt` to `checkpoints/iter_NNNNNN.pt` (kept checkpoints).
pub fn keep_checkpoint(run_dir: &Path, iteration: usize) -> Result<PathBuf, RunError> {
    let keep = run_dir
        .join("checkpoints")
        .join(format!("iter_{iteration:06}.pt"));
    std::fs::copy(latest_checkpoint(run_dir), &keep).map_err(io(&keep))?;
    Ok(keep)
}

/// An open run directory.
pub struct RunDir {
    path: PathBuf,
    metrics: BufWriter<File>,
    columns: Vec<String>,
    log: BufWriter<File>,
    /// The event file, once [`RunDir::start_tensorboard`] started it.
    events: Option<tensorboard::EventWriter>,
}

impl RunDir {
    /// Create `path` (and parents), write `config.yaml` from `config` (sealed:
    /// [`crate::seal::seal_yaml`], checked by every config loader), and start
    /// `metrics.csv` with `columns`. An existing `metrics.csv` is replaced.
    pub fn create(
        path: &Path,
        config: &impl Serialize,
        columns: &[&str],
    ) -> Result<RunDir, RunError> {
        std::fs::create_dir_all(path).map_err(io(path))?;
        let cfg_path = path.join("config.yaml");
        let text = crate::seal::seal_yaml(&serde_yaml::to_string(config)?);
        write_atomic(&cfg_path, text.as_bytes()).map_err(|(p, e)| io(&p)(e))?;
        let mpath = path.join("metrics.csv");
        let mut metrics = BufWriter::new(File::create(&mpath).map_err(io(&mpath))?);
        writeln!(metrics, "{}", columns.join(",")).map_err(io(&mpath))?;
        let lpath = path.join("log.txt");
        let log = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&lpath)
            .map_err(io(&lpath))?;
        Ok(RunDir {
            path: path.to_path_buf(),
            metrics,
            columns: columns.iter().map(|c| c.to_string()).collect(),
            log: BufWriter::new(log),
            events: None,
        })
    }

    /// Reopen a run directory to resume it: `config.yaml` is rewritten from
    /// `config`, and `metrics.csv` keeps the rows whose first column is at most
    /// `up_to` (rows written after the checkpoint being resumed are dropped:
    /// the resumed run writes them again), then appends. The header is
    /// `columns`; when they changed (a reward term added on resume), each kept
    /// row is rewritten under them by name, `nan` where it had no value.
    pub fn resume(
        path: &Path,
        config: &impl Serialize,
        columns: &[&str],
        up_to: f64,
    ) -> Result<RunDir, RunError> {
        let mpath = path.join("metrics.csv");
        let old = std::fs::read_to_string(&mpath).unwrap_or_default();
        let mut lines = old.lines();
        let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let same = header == columns;
        // where each new column was in the old header
        let from: Vec<Option<usize>> = columns
            .iter()
            .map(|c| header.iter().position(|h| h == c))
            .collect();
        let kept: Vec<String> = lines
            .filter(|l| {
                l.split(',')
                    .next()
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|v| v <= up_to)
            })
            .map(|l| {
                if same {
                    return l.to_string();
                }
                let values: Vec<&str> = l.split(',').collect();
                from.iter()
                    .map(|i| i.and_then(|i| values.get(i).copied()).unwrap_or("nan"))
                    .collect::<Vec<_>>()
                    .join(",")
            })
            .collect();
        let mut run = RunDir::create(path, config, columns)?;
        for l in kept {
            writeln!(run.metrics, "{l}").map_err(io(&mpath))?;
        }
        run.metrics.flush().map_err(io(&mpath))?;
        Ok(run)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Write every metrics row from now on into a TensorBoard event file as
    /// well (what every trainer does; [`tensorboard`]). The new file starts
    /// with the rows `metrics.csv` holds now (after [`RunDir::resume`]: the
    /// rows up to the checkpoint, at the wall times the old event files gave
    /// them), and replaces every older event file of the directory, so that a
    /// resumed run logs no step twice. Returns the file's path.
    pub fn start_tensorboard(&mut self) -> Result<PathBuf, RunError> {
        let mpath = self.path.join("metrics.csv");
        self.metrics.flush().map_err(io(&mpath))?;
        let text = std::fs::read_to_string(&mpath).map_err(io(&mpath))?;
        let rows: Vec<&str> = text.lines().skip(1).collect();
        let w = tensorboard::EventWriter::start(&self.path, &self.columns, &rows)?;
        let path = w.path().to_path_buf();
        self.events = Some(w);
        Ok(path)
    }

    /// Append one metrics row (same order as the columns) and flush it, and its
    /// event once [`RunDir::start_tensorboard`] was called.
    pub fn metrics_row(&mut self, values: &[f64]) -> Result<(), RunError> {
        if values.len() != self.columns.len() {
            return Err(RunError::Columns {
                expected: self.columns.len(),
                got: values.len(),
            });
        }
        let row: Vec<String> = values.iter().map(|v| format!("{v}")).collect();
        let mpath = self.path.join("metrics.csv");
        writeln!(self.metrics, "{}", row.join(",")).map_err(io(&mpath))?;
        self.metrics.flush().map_err(io(&mpath))?;
        match &mut self.events {
            Some(w) => w.row(values),
            None => Ok(()),
        }
    }

    /// Append a line to `log.txt`.
    pub fn log(&mut self, line: &str) -> Result<(), RunError> {
        let lpath = self.path.join("log.txt");
        writeln!(self.log, "{line}").map_err(io(&lpath))?;
        self.log.flush().map_err(io(&lpath))
    }
}

/// A progress bar, or plain lines every `every` steps when quiet or not a terminal.
pub struct Progress {
    bar: Option<ProgressBar>,
    total: u64,
    every: u64,
    label: String,
}

impl Progress {
    pub fn new(label: &str, total: u64, quiet: bool) -> Progress {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "{msg} [{bar:30}] {pos}/{len} {per_sec} ETA {eta} {prefix}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_message(label.to_string());
            bar
        });
        Progress {
            bar,
            total,
            every: (total / 10).max(1),
            label: label.to_string(),
        }
    }

    /// Advance to `pos`; `status` is shown beside the bar or on the plain line.
    pub fn set(&self, pos: u64, status: &str) {
        match &self.bar {
            Some(bar) => {
                bar.set_position(pos);
                bar.set_prefix(status.to_string());
            }
            None if pos.is_multiple_of(self.every) || pos == self.total => {
                eprintln!("{} {pos}/{} {status}", self.label, self.total)
            }
            None => {}
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish();
        }
    }
}

/// Draw `panels` of `run_dir/metrics.csv` into `run_dir/plots/training.png`
/// (the directory is created) and return the PNG's path: what every trainer's
/// `plot_run` does with its own panels.
pub fn plot_training(
    run_dir: &Path,
    panels: &[crate::plot::Panel],
) -> Result<PathBuf, crate::plot::PlotError> {
    let dir = run_dir.join("plots");
    std::fs::create_dir_all(&dir).map_err(|source| crate::plot::PlotError::Io {
        path: dir.clone(),
        source,
    })?;
    let out = dir.join("training.png");
    crate::plot::plot_csv(
        &run_dir.join("metrics.csv"),
        &out,
        &run_dir.display().to_string(),
        panels,
    )?;
    Ok(out)
}
