//! Helpers shared by the integration tests.
#![allow(dead_code)]
use std::path::PathBuf;

/// A fresh scratch directory under the system temp dir, removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(tag: &str) -> Scratch {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let dir = std::env::temp_dir().join(format!(
            "dreampolicy-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Load `configs/<name>` of this checkout with `--set` overrides.
/// The committed flat walker's checkpoint.
#[allow(dead_code)]
pub fn walker_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/checkpoints/flat/checkpoints/latest.pt")
}

pub fn load_config(name: &str, sets: &[&str]) -> dreampolicy::rl::config::ExperimentConfig {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs")
        .join(name);
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    dreampolicy::rl::config::load(&path, &sets).unwrap()
}

/// Write shard 0 of a synthetic G1 dataset into `dir`: `n_envs` envs stepped
/// `steps` times, env `e` running episodes of `episode_len(e)` steps back to
/// back. Episode ordinals are `0..n_envs` for the first episodes, then count up
/// in the order episodes start. This sets the ids, the step and the done flag;
/// `fill(frame, ordinal, env, step)` writes the rest (the frame is reused, so a
/// field `fill` never writes keeps its zero).
pub fn write_synthetic_shard(
    dir: &std::path::Path,
    n_envs: u32,
    steps: u32,
    episode_len: impl Fn(u32) -> u32,
    mut fill: impl FnMut(&mut dreampolicy::data::Frame, u32, u32, u32),
) {
    use dreampolicy::data::{episode_id, DatasetInfo, Dims, Frame, ShardWriter, WriterOptions};
    let dims = Dims::G1;
    let mut w = ShardWriter::create(
        dir,
        0,
        dims,
        DatasetInfo::default(),
        WriterOptions::default(),
    )
    .unwrap();
    let mut next = n_envs;
    let mut ep: Vec<(u32, u32)> = (0..n_envs).map(|e| (e, 0)).collect();
    let mut f = Frame::zeros(dims);
    for _ in 0..steps {
        for env in 0..n_envs {
            let (ord, step) = ep[env as usize];
            f.episode = episode_id(0, ord);
            f.env = env;
            f.step = step;
            f.terminated = step + 1 == episode_len(env);
            fill(&mut f, ord, env, step);
            w.write(&f).unwrap();
            ep[env as usize] = if f.terminated {
                next += 1;
                (next - 1, 0)
            } else {
                (ord, step + 1)
            };
        }
    }
    w.finish().unwrap();
}

/// Run a command to success (else fail with its stderr) and return its stdout.
#[allow(dead_code)]
pub fn run_ok(cmd: &mut std::process::Command) -> String {
    String::from_utf8_lossy(&run_ok_bytes(cmd)).into_owned()
}

/// [`run_ok`], stdout as bytes (a decoded video).
pub fn run_ok_bytes(cmd: &mut std::process::Command) -> Vec<u8> {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// Step `task` `steps` times with `old`'s deterministic actions, checking at
/// each step that `new` (a transferred policy) acts the same to 1e-6.
pub fn assert_acts_alike(
    old: &mut dreampolicy::rl::Agent,
    new: &mut dreampolicy::rl::Agent,
    task: &mut dyn dreampolicy::rl::VecTask,
    steps: usize,
) {
    for a in [&mut *old, &mut *new] {
        a.set_frozen(true);
        a.reset_history(&*task);
    }
    for _ in 0..steps {
        old.prepare(&*task);
        new.prepare(&*task);
        let (a, b) = (old.act_mean(), new.act_mean());
        let max = max_abs_diff(&a, &b);
        assert!(max < 1e-6, "actions differ by {max}");
        task.step(&a);
        old.after_step(&*task);
        new.after_step(&*task);
    }
}

/// `old` and `new` (a transferred policy) value `task`'s current critic rows
/// and scandots alike, to 1e-5.
#[allow(dead_code)]
pub fn assert_values_alike(
    old: &dreampolicy::rl::Agent,
    new: &dreampolicy::rl::Agent,
    task: &dyn dreampolicy::rl::VecTask,
) {
    let (critic, scan) = (task.critic(), task.scan());
    let (v_old, v_new) = (old.values_of(critic, scan), new.values_of(critic, scan));
    assert!(max_abs_diff(&v_old, &v_new) < 1e-5, "{v_old:?} {v_new:?}");
}

/// The largest |a_i - b_i|.
#[allow(dead_code)]
pub fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// The unified task of `cfg` (its `unified/small.yaml` start: the foundation
/// named by `train.init_checkpoint`), the foundation as it was saved (its own
/// dims: scandots it never read) and the configured unified policy transferred
/// from it: `(task, old, new, transfer)`.
pub fn foundation_into_unified(
    cfg: &dreampolicy::rl::config::ExperimentConfig,
) -> (
    dreampolicy::unified::task::UnifiedTask,
    dreampolicy::rl::Agent,
    dreampolicy::rl::Agent,
    dreampolicy::rl::checkpoint::Transfer,
) {
    use dreampolicy::rl::checkpoint::Checkpoint;
    use dreampolicy::rl::{Agent, VecTask};
    let ck = Checkpoint::read(std::path::Path::new(
        &cfg.train.init_checkpoint.clone().unwrap(),
    ))
    .unwrap();
    let task = dreampolicy::unified::task::UnifiedTask::new(cfg).unwrap();
    let n = task.n_envs();
    let old_cfg = ck.config().unwrap();
    let old_dims = dreampolicy::rl::TaskDims {
        scan: dreampolicy::env::obs::SCAN_DIM,
        ..task.dims()
    };
    let mut old = Agent::new(&old_cfg.policy, old_dims, n, true);
    ck.load_agent(&mut old).unwrap();
    let mut new = Agent::new(&cfg.policy, task.dims(), n, true);
    let t = ck.transfer_agent(&mut new).unwrap();
    (task, old, new, t)
}

/// The venv `scripts/setup.sh` makes (`third_party/pyenv`), when it imports
/// `modules` (`"mujoco, numpy"`); else None, with a line saying the test is
/// skipped (CI always has it).
#[allow(dead_code)]
pub fn pyenv(modules: &str) -> Option<std::path::PathBuf> {
    let py = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("third_party/pyenv/bin/python");
    let ok = py.is_file()
        && std::process::Command::new(&py)
            .args(["-c", &format!("import {modules}")])
            .status()
            .is_ok_and(|s| s.success());
    if !ok {
        eprintln!("skipped: third_party/pyenv lacks {modules} (run scripts/setup.sh)");
    }
    ok.then_some(py)
}

/// `dir/metrics.csv` read by the crate's own reader (the one `plot` uses).
#[allow(dead_code)]
pub fn metrics_table(dir: &std::path::Path) -> dreampolicy::plot::MetricsTable {
    dreampolicy::plot::MetricsTable::read(&dir.join("metrics.csv")).unwrap()
}

/// Column `name` of `dir/metrics.csv`.
#[allow(dead_code)]
pub fn metrics_column(dir: &std::path::Path, name: &str) -> Vec<f64> {
    metrics_table(dir).column(name).unwrap().to_vec()
}

/// `eval`'s options for `episodes` flat lanes on the checkpoint's training
/// scene, seed 0, one thread.
pub fn flat_eval(episodes: usize) -> dreampolicy::eval::EvalOptions {
    dreampolicy::eval::EvalOptions {
        terrain: dreampolicy::terrain::TerrainKind::Flat,
        then: None,
        episodes,
        full_collision: false,
        seed: 0,
        threads: 1,
        level: None,
        table: Default::default(),
        lane_lookahead: None,
    }
}
