//! `dreampolicy sweep run|task|slurm|collect`: config-driven sweeps on this
//! machine (a pool of `sweep task` processes) or as a Slurm array
//! (`dreampolicy::sweep` holds the sweep file, its expansion and the task body).
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use dreampolicy::sweep::{self, run_state, RunSpec, RunState, Sweep, SweepDir};

#[derive(Subcommand)]
pub enum SweepCommand {
    /// Run a sweep's runs on this machine, at most --jobs at once (the threads
    /// split between them), each in its own run directory under the sweep's
    /// directory. Resumable: finished runs are skipped, interrupted ones resume
    /// from their checkpoint. Ends with `sweep collect`'s table.
    Run(RunArgs),
    /// Train (or resume), evaluate and record one run of a sweep directory:
    /// what `sweep run` starts per run and each Slurm array task executes.
    Task(TaskArgs),
    /// Write an sbatch array script (one task per run, the sweep's resources,
    /// requeued near its time limit and resumed from the run's checkpoint).
    Slurm(SlurmArgs),
    /// Gather every finished run into summary.csv and summary.png (a metric
    /// against the first axis) and print the table of means over seeds.
    Collect(CollectArgs),
}

#[derive(clap::Args)]
pub struct RunArgs {
    /// The sweep file (configs/sweeps/*.yaml).
    sweep: PathBuf,
    /// Runs at once.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// The sweep directory (default runs/sweeps/<sweep name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Threads for all runs together (default: this machine's cores), split
    /// evenly between the --jobs runs.
    #[arg(long)]
    threads: Option<usize>,
    /// List the runs and where each stands; run and write nothing.
    #[arg(long)]
    dry_run: bool,
}

#[derive(clap::Args)]
pub struct TaskArgs {
    /// The sweep directory (`sweep run` or `sweep slurm` wrote it).
    #[arg(long)]
    dir: PathBuf,
    /// The run's index (runs.json; a Slurm array task's SLURM_ARRAY_TASK_ID).
    #[arg(long)]
    index: usize,
    /// Torch and physics threads of the run.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Plain log lines instead of a progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(clap::Args)]
pub struct SlurmArgs {
    /// The sweep file.
    sweep: PathBuf,
    /// The sweep directory, where sweep.sbatch is written (default
    /// runs/sweeps/<sweep name>); it must be on storage every node sees.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The dreampolicy binary the tasks run (default: this one; the script's
    /// DREAMPOLICY variable overrides it at submit time).
    #[arg(long)]
    binary: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct CollectArgs {
    /// The sweep directory.
    dir: PathBuf,
    /// The metric plotted against the first axis (a metrics.csv column or
    /// `eval.<field>`; default: the sweep's first metric).
    #[arg(long)]
    metric: Option<String>,
    /// Print the results as JSON instead of the table.
    #[arg(long)]
    json: bool,
}

pub fn run(which: SweepCommand) -> Result<()> {
    match which {
        SweepCommand::Run(a) => run_local(a),
        SweepCommand::Task(a) => task(a),
        SweepCommand::Slurm(a) => slurm(a),
        SweepCommand::Collect(a) => collect(a),
    }
}

/// The sweep file, checked, with every run's config loaded once.
fn load_checked(path: &Path) -> Result<Sweep> {
    let s = Sweep::load(path)?;
    s.validate_runs()?;
    Ok(s)
}

fn sweep_dir(s: &Sweep, out: Option<&PathBuf>) -> SweepDir {
    SweepDir::new(
        &out.cloned()
            .unwrap_or_else(|| PathBuf::from("runs/sweeps").join(s.name())),
    )
}

fn state_word(s: RunState) -> &'static str {
    match s {
        RunState::Fresh => "to run",
        RunState::Interrupted => "to resume",
        RunState::Finished => "finished",
    }
}

fn run_local(a: RunArgs) -> Result<()> {
    if a.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    let s = load_checked(&a.sweep)?;
    let dir = sweep_dir(&s, a.out.as_ref());
    let runs = if a.dry_run {
        s.runs()
    } else {
        dir.prepare(&s)?
    };
    let total_threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let per_run = (total_threads / a.jobs).max(1);
    eprintln!(
        "sweep {}: {} runs in {} ({} at once, {per_run} thread(s) each)",
        s.name(),
        runs.len(),
        dir.path.display(),
        a.jobs
    );
    for r in &runs {
        eprintln!(
            "  {:<60} {}",
            r.name,
            state_word(run_state(&dir.run_dir(r)))
        );
    }
    if a.dry_run {
        return Ok(());
    }
    let pending: Vec<&RunSpec> = runs
        .iter()
        .filter(|r| run_state(&dir.run_dir(r)) != RunState::Finished)
        .collect();
    let exe = std::env::current_exe().context("finding the dreampolicy binary")?;
    let bar = indicatif::ProgressBar::new(runs.len() as u64);
    if std::io::stderr().is_terminal() {
        bar.set_style(
            indicatif::ProgressStyle::with_template("sweep [{bar:30}] {pos}/{len} runs {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
    } else {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar.set_position((runs.len() - pending.len()) as u64);
    let say = |line: String| {
        if bar.is_hidden() {
            eprintln!("{line}");
        } else {
            bar.println(line);
        }
    };
    let mut queue = pending.into_iter();
    let mut running: Vec<(&RunSpec, Child, Instant)> = Vec::new();
    let mut failed: Vec<String> = Vec::new();
    loop {
        while running.len() < a.jobs {
            let Some(r) = queue.next() else { break };
            let log_path = dir.log_file(r);
            let log = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&log_path)
                .with_context(|| format!("opening {}", log_path.display()))?;
            let child = Command::new(&exe)
                .args(["sweep", "task", "--quiet", "--dir"])
                .arg(&dir.path)
                .args(["--index", &r.index.to_string()])
                .args(["--threads", &per_run.to_string()])
                .stdin(Stdio::null())
                .stdout(log.try_clone()?)
                .stderr(log)
                .spawn()
                .with_context(|| format!("starting run {}", r.name))?;
            say(format!(
                "{} {} (log {})",
                match run_state(&dir.run_dir(r)) {
                    RunState::Interrupted => "resuming",
                    _ => "starting",
                },
                r.name,
                log_path.display()
            ));
            running.push((r, child, Instant::now()));
        }
        if running.is_empty() {
            break;
        }
        bar.set_message(
            running
                .iter()
                .map(|(r, _, _)| format!("#{}", r.index))
                .collect::<Vec<_>>()
                .join(" "),
        );
        std::thread::sleep(Duration::from_millis(200));
        let mut i = 0;
        while i < running.len() {
            match running[i].1.try_wait()? {
                Some(status) => {
                    let (r, _, t0) = running.remove(i);
                    let secs = t0.elapsed().as_secs_f64();
                    if status.success() {
                        say(format!("finished {} in {secs:.0} s", r.name));
                    } else {
                        say(format!(
                            "FAILED {} ({status}) after {secs:.0} s: see {}",
                            r.name,
                            dir.log_file(r).display()
                        ));
                        failed.push(r.name.clone());
                    }
                    bar.inc(1);
                }
                None => i += 1,
            }
        }
    }
    bar.finish_and_clear();
    let c = sweep::collect(&dir, None)?;
    println!("{}", c.markdown);
    eprintln!("wrote {}", c.csv.display());
    if let Some(p) = &c.png {
        eprintln!("wrote {}", p.display());
    }
    if !failed.is_empty() {
        bail!(
            "{} of {} runs failed ({}); `sweep run` again resumes them",
            failed.len(),
            runs.len(),
            failed.join(", ")
        );
    }
    Ok(())
}

fn task(a: TaskArgs) -> Result<()> {
    let dir = SweepDir::new(&a.dir);
    let (s, runs) = dir.open()?;
    let Some(r) = runs.get(a.index) else {
        bail!(
            "run index {} is out of range: the sweep in {} has runs 0-{}",
            a.index,
            a.dir.display(),
            runs.len().saturating_sub(1)
        );
    };
    let state = run_state(&dir.run_dir(r));
    eprintln!(
        "sweep {} run {} ({}): {}",
        s.name(),
        r.index,
        r.name,
        state_word(state)
    );
    let res = sweep::run_task(&s, &dir, r, a.threads.max(1), a.quiet)?;
    println!("{}", serde_json::to_string(&res)?);
    Ok(())
}

fn slurm(a: SlurmArgs) -> Result<()> {
    let s = load_checked(&a.sweep)?;
    let dir = sweep_dir(&s, a.out.as_ref());
    let runs = dir.prepare(&s)?;
    let abs = |p: &Path| -> Result<PathBuf> {
        std::path::absolute(p).with_context(|| format!("resolving {}", p.display()))
    };
    let binary = match &a.binary {
        Some(b) => abs(b)?,
        None => std::env::current_exe().context("finding the dreampolicy binary")?,
    };
    let workdir = std::env::current_dir()?;
    let script = sweep::slurm_script(&s, &abs(&dir.path)?, runs.len(), &workdir, &binary);
    let path = dir.path.join("sweep.sbatch");
    std::fs::write(&path, script).with_context(|| format!("writing {}", path.display()))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
    }
    println!("{}", path.display());
    eprintln!(
        "{} array tasks; submit with `sbatch {}`, then `dreampolicy sweep collect {}`",
        runs.len(),
        path.display(),
        dir.path.display()
    );
    Ok(())
}

fn collect(a: CollectArgs) -> Result<()> {
    let c = sweep::collect(&SweepDir::new(&a.dir), a.metric.as_deref())?;
    let done = c.results.iter().filter(|(_, r)| r.is_some()).count();
    if a.json {
        let rows: Vec<_> = c.results.iter().filter_map(|(_, r)| r.clone()).collect();
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        println!("{}", c.markdown);
    }
    eprintln!(
        "{done} of {} runs finished; wrote {}{}",
        c.results.len(),
        c.csv.display(),
        c.png
            .as_ref()
            .map(|p| format!(" and {}", p.display()))
            .unwrap_or_default()
    );
    Ok(())
}
