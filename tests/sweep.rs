//! Sweeps: expansion of sweep files, a local sweep that runs, skips finished
//! runs and resumes an interrupted one, the Slurm array script's task body run
//! by hand, and `sweep collect`'s CSV and PNG. Real cart-pole PPO runs (a few
//! seconds each).
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{run_ok, Scratch};
use dreampolicy::sweep::{Mode, Sweep};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

fn cartpole() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/test/cartpole.yaml")
}

/// A cart-pole sweep: two learning rates, `seeds`, short runs.
fn cartpole_sweep(s: &Scratch, name: &str, seeds: &str, iterations: usize) -> PathBuf {
    s.write(
        &format!("{name}.yaml"),
        &format!(
            "base: {}\n\
             set: [train.iterations={iterations}, train.save_interval=5]\n\
             axes:\n  - {{key: ppo.learning_rate, name: lr, values: [3.0e-4, 1.0e-3]}}\n\
             seeds: {seeds}\n\
             resources: {{cpus_per_task: 1, time: '00:10:00', mem: 2G, max_parallel: 2}}\n\
             metrics: [mean_return, mean_episode_length]\n\
             final_window: 5\n",
            cartpole().display()
        ),
    )
}

#[test]
fn a_grid_is_every_combination_once_per_seed_with_its_overrides() {
    let s = Scratch::new("sweep-grid");
    let p = s.write(
        "g.yaml",
        &format!(
            "base: {}\n\
             set: [train.iterations=3]\n\
             axes:\n  - {{key: ppo.learning_rate, name: lr, values: [1.0e-4, 3.0e-4, 1.0e-3]}}\n  - {{key: policy.actor_hidden, values: [[16], [32, 32]]}}\n\
             seeds: [1, 2]\n",
            cartpole().display()
        ),
    );
    let sweep = Sweep::load(&p).unwrap();
    assert_eq!(sweep.name(), "g");
    let runs = sweep.runs();
    assert_eq!(runs.len(), 3 * 2 * 2);
    let mut names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), runs.len(), "run names are unique");
    let r = &runs[3];
    assert_eq!(r.index, 3);
    assert_eq!(r.name, "003-lr=0.0001-actor_hidden=32+32-seed=2");
    assert_eq!(
        r.sets,
        [
            "train.iterations=3",
            "ppo.learning_rate=0.0001",
            "policy.actor_hidden=[32,32]",
            "train.seed=2"
        ]
    );
    // every run's config loads, and carries its values
    sweep.validate_runs().unwrap();
    let cfg = dreampolicy::rl::config::load(&sweep.base, &r.sets).unwrap();
    assert_eq!(cfg.policy.actor_hidden, [32, 32]);
    assert_eq!(cfg.train.seed, 2);
    assert_eq!(cfg.train.iterations, 3);
    assert!((cfg.ppo.learning_rate - 1e-4).abs() < 1e-12);
}

#[test]
fn list_mode_zips_and_random_mode_draws_reproducibly_in_range() {
    let s = Scratch::new("sweep-modes");
    let base = cartpole();
    let list = s.write(
        "l.yaml",
        &format!(
            "base: {}\nmode: list\naxes:\n  - {{key: ppo.learning_rate, values: [1.0e-4, 1.0e-3]}}\n  - {{key: ppo.num_steps, values: [16, 32]}}\n",
            base.display()
        ),
    );
    let runs = Sweep::load(&list).unwrap().runs();
    assert_eq!(runs.len(), 2);
    assert!(runs[1].sets.contains(&"ppo.num_steps=32".to_string()));
    assert!(runs[1]
        .sets
        .contains(&"ppo.learning_rate=0.001".to_string()));

    let uneven = s.write(
        "u.yaml",
        &format!(
            "base: {}\nmode: list\naxes:\n  - {{key: ppo.learning_rate, values: [1.0e-4, 1.0e-3]}}\n  - {{key: ppo.num_steps, values: [16]}}\n",
            base.display()
        ),
    );
    let e = Sweep::load(&uneven).unwrap_err().to_string();
    assert!(e.contains("ppo.num_steps has 1 values"), "{e}");

    let random = format!(
        "base: {}\nmode: random\nsamples: 20\nrandom_seed: 7\naxes:\n  - {{key: ppo.learning_rate, range: [1.0e-5, 1.0e-2], log: true}}\n  - {{key: ppo.num_steps, values: [16, 32]}}\n",
        base.display()
    );
    let a = Sweep::load(&s.write("r1.yaml", &random)).unwrap();
    let b = Sweep::load(&s.write("r2.yaml", &random)).unwrap();
    assert_eq!(a.mode, Mode::Random);
    assert_eq!(a.runs(), b.runs(), "the same seed draws the same runs");
    let lrs: Vec<f64> = a
        .runs()
        .iter()
        .map(|r| r.values[0].2.as_f64().unwrap())
        .collect();
    assert!(lrs.iter().all(|&x| (1e-5..=1e-2).contains(&x)), "{lrs:?}");
    // log-uniform: both decades' ends are visited
    assert!(
        lrs.iter().any(|&x| x < 1e-4) && lrs.iter().any(|&x| x > 1e-3),
        "{lrs:?}"
    );
    let other = Sweep::load(&s.write(
        "r3.yaml",
        &random.replace("random_seed: 7", "random_seed: 8"),
    ))
    .unwrap();
    assert_ne!(a.runs(), other.runs());
    a.validate_runs().unwrap();
}

#[test]
fn a_mistyped_key_or_value_stops_the_sweep_before_any_run() {
    let s = Scratch::new("sweep-typo");
    let p = s.write(
        "t.yaml",
        &format!(
            "base: {}\naxes:\n  - {{key: ppo.learning_rat, values: [1.0e-4]}}\n",
            cartpole().display()
        ),
    );
    let out = bin()
        .current_dir(&s.0)
        .args(["sweep", "run"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("000-learning_rat=0.0001") && err.contains("learning_rat"),
        "{err}"
    );
    assert!(!s.0.join("runs").exists(), "nothing was started");

    let p = s.write(
        "v.yaml",
        &format!(
            "base: {}\naxes:\n  - {{key: ppo.learning_rate, values: [fast]}}\n",
            cartpole().display()
        ),
    );
    let out = bin()
        .args(["sweep", "run", "--dry-run"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("learning_rate"));
}

/// `sweep run --jobs N --threads N` of `file` into `dir`, which must succeed;
/// returns its stdout (the collected table) and stderr (the runs' states,
/// starts and resumes).
fn sweep_run_ok(dir: &Path, file: &Path, jobs: usize) -> (String, String) {
    let n = jobs.to_string();
    let out = bin()
        .args(["sweep", "run", "--jobs", &n, "--threads", &n, "--out"])
        .arg(dir)
        .arg(file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{err}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), err)
}

fn metrics_iterations(run: &Path) -> Vec<f64> {
    common::metrics_column(run, "iteration")
}

#[test]
fn a_local_sweep_runs_skips_finished_runs_resumes_an_interrupted_one_and_collects() {
    let s = Scratch::new("sweep-local");
    let file = cartpole_sweep(&s, "lr", "[1]", 30);
    let dir = s.0.join("out");
    // Interrupt run 1: start its task alone and kill it after its first checkpoint.
    // (`sweep slurm` prepares the directory without running anything)
    run_ok(bin().args(["sweep", "slurm", "--out"]).arg(&dir).arg(&file));
    let runs: Vec<dreampolicy::sweep::RunSpec> =
        serde_json::from_str(&std::fs::read_to_string(dir.join("runs.json")).unwrap()).unwrap();
    assert_eq!(runs.len(), 2);
    let run1 = dir.join(&runs[1].name);
    let mut child = bin()
        .args(["sweep", "task", "--quiet", "--index", "1", "--dir"])
        .arg(&dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !dreampolicy::run::latest_checkpoint(&run1).exists() {
        assert!(t0.elapsed().as_secs() < 120, "no checkpoint within 120 s");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        !run1.join("result.json").exists(),
        "the run was killed before it finished (make it longer if this fails)"
    );
    let killed_at =
        dreampolicy::rl::checkpoint::Checkpoint::read(&dreampolicy::run::latest_checkpoint(&run1))
            .unwrap()
            .meta
            .iteration;
    assert!(killed_at < 30);

    let (table, err) = sweep_run_ok(&dir, &file, 2);
    assert!(err.contains(&format!("starting {}", runs[0].name)), "{err}");
    assert!(err.contains(&format!("resuming {}", runs[1].name)), "{err}");
    for r in &runs {
        let res = dreampolicy::sweep::read_result(&dir.join(&r.name).join("result.json")).unwrap();
        assert_eq!(res.iterations, 30, "{}", r.name);
        assert!(res.final_metrics["mean_return"].is_finite());
        // one row per iteration: the resumed run continued, it did not restart
        let its = metrics_iterations(&dir.join(&r.name));
        assert_eq!(its.len(), 30, "{}", r.name);
        assert!(its.windows(2).all(|w| w[1] == w[0] + 1.0), "{}", r.name);
    }
    assert!(
        table.contains("| lr | runs | mean_return | mean_episode_length |"),
        "{table}"
    );

    // a second `sweep run` has nothing left to do
    let stamp = std::fs::metadata(dir.join(&runs[0].name).join("result.json"))
        .unwrap()
        .modified()
        .unwrap();
    let out = bin()
        .args(["sweep", "run", "--out"])
        .arg(&dir)
        .arg(&file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        !err.contains("starting") && !err.contains("resuming"),
        "{err}"
    );
    assert_eq!(err.matches("finished").count(), 2, "{err}");
    assert_eq!(
        std::fs::metadata(dir.join(&runs[0].name).join("result.json"))
            .unwrap()
            .modified()
            .unwrap(),
        stamp
    );

    // collect: the CSV has a row per run, the PNG is a PNG
    let csv = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "index,name,lr,seed,finished,iterations,samples,wall_time_s,mean_return,mean_episode_length"
    );
    assert_eq!(lines.len(), 3);
    assert!(
        lines[1].starts_with(&format!("0,{},0.0003,1,1,30,", runs[0].name)),
        "{}",
        lines[1]
    );
    let png = std::fs::read(dir.join("summary.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    // a directory holding another sweep is refused
    let other = cartpole_sweep(&s, "lr", "[1, 2]", 30);
    let out = bin()
        .args(["sweep", "run", "--out"])
        .arg(&dir)
        .arg(&other)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("different sweep"));
}

#[test]
fn the_slurm_array_script_runs_one_task_per_array_index() {
    let s = Scratch::new("sweep-slurm");
    let file = cartpole_sweep(&s, "slurm", "[3]", 10);
    let dir = s.0.join("sw");
    let script =
        PathBuf::from(run_ok(bin().args(["sweep", "slurm", "--out"]).arg(&dir).arg(&file)).trim());
    assert_eq!(script, dir.join("sweep.sbatch"));
    let text = std::fs::read_to_string(&script).unwrap();
    for line in [
        "#SBATCH --array=0-1%2",
        "#SBATCH --cpus-per-task=1",
        "#SBATCH --mem=2G",
        "#SBATCH --time=00:10:00",
        "#SBATCH --requeue",
        "#SBATCH --signal=B:USR1@120",
        "trap requeue USR1",
    ] {
        assert!(text.contains(line), "{line} missing from:\n{text}");
    }
    // without an array index the body refuses to guess
    let out = Command::new("bash")
        .arg(&script)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("SLURM_ARRAY_TASK_ID"));
    // the task body with the array index set by hand, as Slurm would
    let out = Command::new("bash")
        .arg(&script)
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_CPUS_PER_TASK", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let runs = Sweep::load(&dir.join("sweep.yaml")).unwrap().runs();
    assert!(dir.join(&runs[1].name).join("result.json").exists());
    assert!(!dir.join(&runs[0].name).exists());
    // run again (a requeued task): the finished run is skipped
    let out = Command::new("bash")
        .arg(&script)
        .env("SLURM_ARRAY_TASK_ID", "1")
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("finished"));
    // collect sees one of two runs
    let out = bin().args(["sweep", "collect"]).arg(&dir).output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 of 2 runs finished"));
    let csv = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().contains(",0,,,,"), "{csv}");
}

#[test]
fn a_baseline_sweep_trains_and_evaluates_its_policies() {
    // the w/o-diffusion baseline on a synthetic dataset: two style weights,
    // one iteration each, then two flat lanes
    let s = Scratch::new("sweep-baseline");
    let ds = s.0.join("dataset");
    std::fs::create_dir_all(&ds).unwrap();
    common::write_synthetic_shard(
        &ds,
        2,
        10,
        |_| 5,
        |f, ord, _, step| {
            f.state
                .iter_mut()
                .for_each(|v| *v = ord as f32 + 0.1 * step as f32);
        },
    );
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/test/no_diffusion_tiny.yaml");
    let file = s.write(
        "b.yaml",
        &format!(
            "base: {}\ntrainer: no_diffusion\nset: [train.iterations=1, no_diffusion.dataset={}]\n\
             axes:\n  - {{key: no_diffusion.style_weight, name: style, values: [0.0, 0.5]}}\n\
             eval: {{terrains: [flat, stair], episodes: 2, full_collision: false}}\n",
            base.display(),
            ds.display()
        ),
    );
    let dir = s.0.join("out");
    sweep_run_ok(&dir, &file, 1);
    for name in ["000-style=0.0", "001-style=0.5"] {
        let res = dreampolicy::sweep::read_result(&dir.join(name).join("result.json"))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(res.iterations, 1);
        // two terrains: each report under per_terrain, their mean on top
        let e = res.eval.as_ref().unwrap();
        assert_eq!(e["terrains"], serde_json::json!(["flat", "stair"]));
        for k in ["flat", "stair"] {
            assert_eq!(e["per_terrain"][k]["episodes"], 2, "{name} {k}");
            assert_eq!(e["per_terrain"][k]["terrain"], k, "{name}");
        }
        let per = |k: &str| res.metric(&format!("eval.per_terrain.{k}.completion_rate"));
        assert!(per("flat").is_finite() && per("stair").is_finite());
        assert!(
            (res.metric("eval.completion_rate") - (per("flat") + per("stair")) / 2.0).abs() < 1e-12
        );
        assert!(res.metric("eval.per_terrain.gap.success_rate").is_nan());
        let cols = std::fs::read_to_string(dir.join(name).join("metrics.csv")).unwrap();
        assert!(cols.lines().next().unwrap().contains("amp_accuracy"));
    }
    // labels name long values in run names; their count must match
    let labelled = s.write(
        "l.yaml",
        &format!(
            "base: {}\ntrainer: no_diffusion\nmode: list\naxes:\n  - {{key: no_diffusion.dataset, name: data, labels: [small, big], values: [/a/very/long/path, /another/long/path]}}\n",
            base.display()
        ),
    );
    let names: Vec<String> = Sweep::load(&labelled)
        .unwrap()
        .runs()
        .into_iter()
        .map(|r| r.name)
        .collect();
    assert_eq!(names, ["000-data=small", "001-data=big"]);
    let bad = s.write(
        "m.yaml",
        &format!(
            "base: {}\naxes:\n  - {{key: ppo.learning_rate, labels: [a], values: [1.0e-4, 1.0e-3]}}\n",
            base.display()
        ),
    );
    let e = Sweep::load(&bad).unwrap_err().to_string();
    assert!(e.contains("1 labels for 2 values"), "{e}");
}

#[test]
fn a_figure_plots_chosen_runs_against_their_own_x_and_bad_panels_are_refused() {
    // the scaling figure's shape: a list sweep, one panel over runs 0-1 (x in
    // reverse order of the runs) and one over run 2 with run 1, two seeds
    let s = Scratch::new("sweep-figure");
    let text = format!(
        "base: {}\nmode: list\nset: [train.iterations=3, train.save_interval=3]\n\
         axes:\n  - {{key: ppo.learning_rate, name: lr, values: [3.0e-4, 1.0e-3, 3.0e-3]}}\n\
         seeds: [1, 2]\nmetrics: [mean_episode_length]\nfinal_window: 1\n\
         figure:\n  - {{title: size, x_label: fraction, runs: [0, 1], x: [1.0, 0.5]}}\n  - {{title: kinds, x_label: kinds, runs: [2, 1], x: [1, 5]}}\n",
        cartpole().display()
    );
    let file = s.write("f.yaml", &text);
    let dir = s.0.join("out");
    sweep_run_ok(&dir, &file, 2);
    let c = dreampolicy::sweep::collect(&dreampolicy::sweep::SweepDir::new(&dir), None).unwrap();
    let png = std::fs::read(c.png.as_ref().unwrap()).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let series = dreampolicy::sweep::figure_series(&c.sweep, &c.results, "mean_episode_length");
    assert_eq!(series.len(), 2);
    let metric = |combination: usize, seed: u64| {
        let (_, r) = c
            .results
            .iter()
            .find(|(r, _)| r.index == combination * 2 + (seed as usize - 1))
            .unwrap();
        let r = r.as_ref().unwrap();
        assert_eq!(r.seed, Some(seed));
        r.metric("mean_episode_length")
    };
    // points sorted by x: run 1 (x 0.5) before run 0 (x 1.0)
    assert_eq!(series[0].x, [0.5, 1.0]);
    assert_eq!(series[0].title, "size: mean_episode_length");
    let names: Vec<&str> = series[0].lines.iter().map(|l| l.0.as_str()).collect();
    assert_eq!(names, ["seed 1", "seed 2", "mean"]);
    assert_eq!(series[0].lines[0].1, [metric(1, 1), metric(0, 1)]);
    assert_eq!(series[0].lines[1].1, [metric(1, 2), metric(0, 2)]);
    assert!((series[0].lines[2].1[0] - (metric(1, 1) + metric(1, 2)) / 2.0).abs() < 1e-12);
    assert_eq!(series[1].x, [1.0, 5.0]);
    assert_eq!(series[1].lines[0].1, [metric(2, 1), metric(1, 1)]);
    assert!(series
        .iter()
        .flat_map(|p| &p.lines)
        .flat_map(|l| &l.1)
        .all(|v| v.is_finite()));

    // a list sweep grown at its end keeps its runs and trains the new one only
    let grown = s.write(
        "f.yaml",
        &text.replace("3.0e-4, 1.0e-3, 3.0e-3]", "3.0e-4, 1.0e-3, 3.0e-3, 1.0e-2]"),
    );
    let (_, err) = sweep_run_ok(&dir, &grown, 2);
    assert_eq!(err.matches("starting").count(), 2, "{err}");
    assert!(
        err.contains("starting 006-lr=0.01-seed=1") && err.contains("starting 007-lr=0.01-seed=2"),
        "{err}"
    );
    assert_eq!(err.matches("to run").count(), 2, "{err}");
    assert!(!err.contains("resuming"), "{err}");
    // a run the sweep does not have, x of another length
    for (bad, msg) in [
        (
            "runs: [0, 3], x: [1, 2]",
            "run 3, but the sweep has 3 combinations",
        ),
        ("runs: [0, 1], x: [1]", "2 runs and 1 x values"),
    ] {
        let t = text.replace("runs: [2, 1], x: [1, 5]", bad);
        let e = Sweep::load(&s.write("bad.yaml", &t))
            .unwrap_err()
            .to_string();
        assert!(e.contains(msg), "{e}");
    }
    // an unknown eval terrain stops the sweep at load
    let t = format!("{text}eval: {{terrains: [flat, lava]}}\n");
    let e = Sweep::load(&s.write("lava.yaml", &t))
        .unwrap_err()
        .to_string();
    assert!(e.contains("lava"), "{e}");
}
