//! `dreampolicy benchmark`: Wilson intervals by hand, the cells a config asks
//! for (per-terrain checkpoints, combined lanes by their first kind), bad
//! files refused, and a small benchmark of the committed walker run, cut short
//! and resumed (the cells measured are kept, the missing ones measured, a
//! changed episode count measures again), with its report: the paper's
//! published rows beside ours, heatmaps and bar charts.
mod common;

use std::path::Path;
use std::process::Command;

use common::Scratch;
use dreampolicy::benchmark::{self, read_results, wilson, BenchmarkConfig, Table};

#[test]
fn wilson_intervals_match_the_formula_by_hand() {
    // p = 0.5, n = 10: centre 0.5, half-width z sqrt(0.025 + z^2/400) / (1 + z^2/10)
    let (lo, hi) = wilson(0.5, 10);
    assert!(
        (lo - 0.236_593).abs() < 1e-5 && (hi - 0.763_407).abs() < 1e-5,
        "{lo} {hi}"
    );
    // all failures and all successes: one-sided, inside [0, 1]
    let (lo, hi) = wilson(0.0, 10);
    assert_eq!(lo, 0.0);
    assert!((hi - 0.277_533).abs() < 1e-5, "{hi}");
    let (lo, hi) = wilson(1.0, 10);
    assert!((lo - 0.722_467).abs() < 1e-5 && hi == 1.0, "{lo}");
    // more episodes, a narrower interval around the same rate
    let (a, b) = wilson(0.8, 20);
    let (c, d) = wilson(0.8, 200);
    assert!(c > a && d < b && c < 0.8 && d > 0.8);
    assert!(wilson(0.5, 0).0.is_nan());
}

fn write_config(dir: &Scratch, body: &str) -> std::path::PathBuf {
    dir.write("bench.yaml", body)
}

fn walker() -> String {
    common::walker_path().display().to_string()
}

/// A benchmark file of `body` (`{w}` standing for the committed walker),
/// written into a scratch directory of `name` and loaded.
fn load_with_walker(name: &str, body: &str) -> (Scratch, BenchmarkConfig) {
    let dir = Scratch::new(name);
    let f = write_config(&dir, &body.replace("{w}", &walker()));
    let c = BenchmarkConfig::load(&f, &[]).unwrap();
    (dir, c)
}

#[test]
fn cells_follow_the_methods_checkpoints_and_the_tables() {
    let (_dir, c) = load_with_walker(
        "bench-cells",
        "episodes: 3\nlevels: [0, 2]\nmethods:\n  - name: spec\n    checkpoints: {flat: {w}, bridge: {w}}\n  - name: one\n    checkpoint: {w}\n",
    );
    let cells = c.cells();
    let of = |m: &str, t: Table| {
        cells
            .iter()
            .filter(|c| c.method == m && c.table == t && c.level == 0)
            .map(|c| c.lane())
            .collect::<Vec<_>>()
    };
    assert_eq!(of("spec", Table::Single), ["flat", "bridge"]);
    assert!(of("spec", Table::Unseen).is_empty());
    assert_eq!(of("spec", Table::Combined), ["bridge&uneven", "bridge&gap"]);
    assert_eq!(
        of("one", Table::Unseen),
        ["slope_bridge", "balancing_beam", "wave", "slope"]
    );
    assert_eq!(of("one", Table::Combined).len(), 5);
    // two levels of each
    assert_eq!(cells.len(), 2 * (2 + 2 + 5 + 4 + 5));
}

#[test]
fn bad_benchmark_files_are_refused_with_the_reason() {
    let dir = Scratch::new("bench-bad");
    let cases = [
        ("episodes: 3\nmethods: []\n", "`methods` is empty"),
        (
            "episodes: 3\nmethods:\n  - {name: a, checkpoint: x.pt}\n  - {name: a, checkpoint: y.pt}\n",
            "distinct",
        ),
        ("episodes: 3\nmethods:\n  - {name: a}\n", "no `checkpoint`"),
        (
            "episodes: 3\nmethods:\n  - {name: a, checkpoints: {lava: x.pt}}\n",
            "lava",
        ),
        (
            "episodes: 0\nmethods:\n  - {name: a, checkpoint: x.pt}\n",
            "at least 1",
        ),
        (
            "episodes: 3\nmethod:\n  - {name: a, checkpoint: x.pt}\n",
            "unknown field",
        ),
        (
            "episodes: 3\ntables: [hard]\nmethods:\n  - {name: a, checkpoint: x.pt}\n",
            "hard",
        ),
    ];
    for (body, why) in cases {
        let f = write_config(&dir, body);
        let e = BenchmarkConfig::load(&f, &[]).expect_err(body).to_string();
        assert!(e.contains(why), "{body}: {e}");
    }
}

fn dreampolicy() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

fn run_cli(config: &Path, out: &Path, sets: &[&str]) -> serde_json::Value {
    let mut cmd = dreampolicy();
    cmd.args(["benchmark", "--config"])
        .arg(config)
        .arg("--out")
        .arg(out)
        .arg("--json");
    for s in sets {
        cmd.args(["--set", s]);
    }
    serde_json::from_str(common::run_ok(&mut cmd).trim()).unwrap()
}

#[test]
fn a_small_benchmark_runs_resumes_and_reports() {
    let dir = Scratch::new("bench-run");
    let f = write_config(
        &dir,
        &format!(
            "name: test\nepisodes: 2\ntables: [single, combined]\nmethods:\n  - name: walker\n    checkpoints: {{flat: {w}, stair: {w}}}\n    paper: distillation\n",
            w = walker()
        ),
    );
    let out = dir.0.join("out");
    let s = run_cli(&f, &out, &[]);
    assert_eq!(
        (s["cells"].as_u64(), s["measured"].as_u64()),
        (Some(5), Some(5)),
        "{s}"
    );
    let rows = read_results(&out.join("results.csv")).unwrap();
    let lanes: Vec<&str> = rows.iter().map(|r| r.lane.as_str()).collect();
    assert_eq!(
        lanes,
        ["flat", "stair", "stair&uneven", "stair&gap", "stair&bridge"]
    );
    let flat = &rows[0];
    // the committed walker walks every flat lane
    assert_eq!((flat.success_rate, flat.episodes), (1.0, 2));
    // results.csv keeps 6 decimals
    let (lo, hi) = wilson(1.0, 2);
    assert!(
        (flat.success_lo - lo).abs() < 1e-6 && flat.success_hi == hi,
        "{flat:?}"
    );
    for r in &rows {
        assert!(
            r.success_lo <= r.success_rate && r.success_rate <= r.success_hi,
            "{r:?}"
        );
        assert!(
            r.completion_lo <= r.completion_rate && r.completion_rate <= r.completion_hi,
            "{r:?}"
        );
        assert!(r.full_collision && r.seed == 0);
    }
    // it was never trained on stairs: the stair lanes end in falls
    assert!(
        rows[1].falls > 0 && rows[1].success_rate < 1.0,
        "{:?}",
        rows[1]
    );

    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("## combined terrains, level 0"), "{md}");
    assert!(md.contains("| walker | 100 ["), "{md}");
    // the paper's published rows in their own table, ours named beside its row
    assert!(
        md.contains("| Distillation (ours: walker) | 50.5 · 76.5"),
        "{md}"
    );
    assert!(md.contains("| DreamPolicy | 88.5 · "), "{md}");
    for png in [
        "single_success.png",
        "single_bars.png",
        "combined_success.png",
        "combined_bars.png",
    ] {
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{png}");
    }

    // the same run again keeps every cell
    let again = run_cli(&f, &out, &[]);
    assert_eq!(
        (again["measured"].as_u64(), again["kept"].as_u64()),
        (Some(0), Some(5))
    );
    assert_eq!(read_results(&out.join("results.csv")).unwrap(), rows);

    // a run cut short after three cells measures the last two
    let csv = out.join("results.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let cut: Vec<&str> = text.lines().take(4).collect();
    std::fs::write(&csv, cut.join("\n") + "\n").unwrap();
    let resumed = run_cli(&f, &out, &[]);
    assert_eq!(
        (resumed["measured"].as_u64(), resumed["kept"].as_u64()),
        (Some(2), Some(3))
    );
    // the measurement is deterministic: the same numbers as the first time
    let back = read_results(&csv).unwrap();
    for (a, b) in back.iter().zip(&rows) {
        assert_eq!(
            (a.success_rate, a.completion_rate, a.falls),
            (b.success_rate, b.completion_rate, b.falls),
            "{}",
            a.lane
        );
    }

    // another episode count is another measurement
    let more = run_cli(&f, &out, &["episodes=3", "tables=[single]"]);
    assert_eq!(
        (more["measured"].as_u64(), more["kept"].as_u64()),
        (Some(2), Some(0))
    );
}

#[test]
fn benchmark_errors_name_the_file() {
    let dir = Scratch::new("bench-err");
    let f = write_config(
        &dir,
        "episodes: 1\ntables: [single]\nmethods:\n  - {name: a, checkpoints: {flat: no/such.pt}}\n",
    );
    let o = dreampolicy()
        .args(["benchmark", "--config"])
        .arg(&f)
        .arg("--out")
        .arg(dir.0.join("out"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("no/such.pt"), "{e}");
    assert!(e.lines().count() <= 3, "{e}");
    // a directory holding another CSV is refused, not overwritten
    let other = dir.0.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(other.join("results.csv"), "a,b\n1,2\n").unwrap();
    let e = benchmark::read_results(&other.join("results.csv"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("another --out"), "{e}");
}

/// A row of `results.csv` with the success rate and interval given.
fn row(table: Table, method: &str, lane: &str, s: (f64, f64, f64)) -> benchmark::Row {
    benchmark::Row {
        table,
        method: method.into(),
        lane: lane.into(),
        level: 0,
        checkpoint: "x.pt".into(),
        checkpoint_iteration: 1,
        checkpoint_env_steps: 1,
        episodes: 10,
        seed: 0,
        full_collision: true,
        success_rate: s.0,
        success_lo: s.1,
        success_hi: s.2,
        completion_rate: s.0,
        completion_lo: s.1,
        completion_hi: s.2,
        falls: 0,
        mean_forward_speed: 0.5,
        wall_s: 1.0,
    }
}

#[test]
fn the_papers_orders_are_checked_against_our_intervals() {
    use benchmark::report::{orderings, Verdict};
    use benchmark::PaperMethod;
    let (_dir, c) = load_with_walker(
        "bench-order",
        "episodes: 10\ntables: [unseen, combined]\nmethods:\n  - name: mine\n    checkpoint: {w}\n    paper: ours\n  - name: student\n    checkpoint: {w}\n    paper: distillation\n  - name: other\n    checkpoint: {w}\n",
    );
    let (u, cb) = (Table::Unseen, Table::Combined);
    let rows = vec![
        // slope_bridge: the paper 92.8 > 65.5; ours apart the same way
        row(u, "mine", "slope_bridge", (0.9, 0.6, 0.98)),
        row(u, "student", "slope_bridge", (0.1, 0.02, 0.4)),
        // balancing_beam: the paper 96.3 > 74.4; ours apart the other way
        row(u, "mine", "balancing_beam", (0.1, 0.02, 0.4)),
        row(u, "student", "balancing_beam", (0.9, 0.6, 0.98)),
        // wave: 100 and 100 in the paper, no order to check
        row(u, "mine", "wave", (0.0, 0.0, 0.28)),
        row(u, "student", "wave", (1.0, 0.72, 1.0)),
        // a combined lane whose intervals overlap
        row(cb, "mine", "stair&uneven", (0.6, 0.31, 0.83)),
        row(cb, "student", "stair&uneven", (0.4, 0.17, 0.69)),
        // a method without a paper row takes no part
        row(cb, "other", "stair&gap", (1.0, 0.72, 1.0)),
    ];
    let checks = orderings(&c, &rows);
    let got: Vec<(&str, Verdict)> = checks
        .iter()
        .map(|c| (c.lane.as_str(), c.verdict))
        .collect();
    assert_eq!(
        got,
        [
            ("slope_bridge", Verdict::Holds),
            ("balancing_beam", Verdict::Reversed),
            ("stair&uneven", Verdict::Open),
        ]
    );
    let b = &checks[1];
    assert_eq!(
        (b.better, b.worse),
        (PaperMethod::Ours, PaperMethod::Distillation)
    );
    assert_eq!(
        (b.ours_better.as_str(), b.ours_worse.as_str()),
        ("mine", "student")
    );
    assert!((b.paper.0 - 96.35).abs() < 1e-9 && (b.paper.1 - 74.36).abs() < 1e-9);
    assert_eq!(b.ours, (10.0, 90.0));
    let md = benchmark::report::markdown(&c, &rows);
    assert!(
        md.contains("| slope_bridge | DreamPolicy > Distillation | 92.8 > 65.5 | mine 90 vs student 10 | holds |"),
        "{md}"
    );
    assert!(md.contains("holds: 1, reversed: 1, open: 0."), "{md}");
    assert!(md.contains("holds: 0, reversed: 0, open: 1."), "{md}");
}
