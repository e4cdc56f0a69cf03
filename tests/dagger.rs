//! The distillation baseline (`train dagger`): labels come from the teacher of
//! the terrain each env stands on, the student's imitation loss falls, β
//! anneals, and a run resumes and is read by `eval` as any policy.
use std::path::{Path, PathBuf};

use dreampolicy::baselines::dagger::{self, Dagger, DaggerConfig};
use dreampolicy::env::task::VecTask;
use dreampolicy::env::VecEnv;
use dreampolicy::rl::agent::Agent;
use dreampolicy::rl::checkpoint::{self, Checkpoint, CheckpointMeta};
use dreampolicy::rl::config::ExperimentConfig;
use dreampolicy::terrain::TerrainKind;
use rand::SeedableRng;

mod common;
use common::Scratch;

/// A teacher checkpoint for `cfg`'s env: a fresh policy of `cfg.policy` drawn
/// with torch seed `seed` (so that two teachers act differently), saved with
/// `cfg` less its `dagger:` section as its config.
fn write_teacher(cfg: &ExperimentConfig, seed: i64, path: &Path) {
    let mut tcfg = cfg.clone();
    tcfg.dagger = None;
    let env = VecEnv::new(&tcfg.env).unwrap();
    tch::manual_seed(seed);
    let agent = Agent::new(&tcfg.policy, env.dims(), env.n_envs(), true);
    // a wider output than the 0.01-gain init, so that the teachers differ clearly
    tch::no_grad(|| {
        for (name, mut t) in agent.policy.named_parameters() {
            if name.starts_with("actor") {
                let _ = t.g_add_(&(t.randn_like() * 0.3));
            }
        }
    });
    let meta = CheckpointMeta::record(&tcfg, &env, None, (0, 0, 0.0), Default::default()).unwrap();
    checkpoint::save(path, &agent, None, Vec::new(), &meta).unwrap();
}

/// configs/test/dagger_tiny.yaml with its two teachers written into `dir`.
fn setup(dir: &Scratch, sets: &[&str]) -> (ExperimentConfig, PathBuf, PathBuf) {
    let base = common::load_config("test/dagger_tiny.yaml", &[]);
    let flat = dir.0.join("teacher_flat.pt");
    let stair = dir.0.join("teacher_stair.pt");
    write_teacher(&base, 11, &flat);
    write_teacher(&base, 12, &stair);
    let mut all = vec![
        format!("dagger.teachers.flat={}", flat.display()),
        format!("dagger.teachers.stair={}", stair.display()),
    ];
    all.extend(sets.iter().map(|s| s.to_string()));
    let all: Vec<&str> = all.iter().map(|s| s.as_str()).collect();
    (
        common::load_config("test/dagger_tiny.yaml", &all),
        flat,
        stair,
    )
}

#[test]
fn labels_come_from_the_teacher_of_each_envs_terrain() {
    let dir = Scratch::new("dagger-labels");
    let (cfg, _, _) = setup(&dir, &[]);
    let mut dg = Dagger::new(&cfg, None).unwrap();
    let n = dg.env.n_envs();
    let a = dg.env.dims().action;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mut seen = [false; 2];
    for step in 0..6 {
        // the kind under each pelvis, from the map itself
        let map = dg.env.shared().scene.terrain.clone().unwrap();
        let kinds: Vec<TerrainKind> = dg
            .env
            .envs()
            .iter()
            .map(|e| {
                if e.on_plane() {
                    return TerrainKind::Flat;
                }
                let p = e.state().base_pos;
                let (_, col) = map.tile_at(p[0], p[1]).expect("the envs stand on tiles");
                map.tile_kind(col)
            })
            .collect();
        assert_eq!(dagger::env_kinds(&dg.env), kinds, "step {step}");
        let who = dg.teacher_of();
        // what every teacher would do now (frozen normalizers: preparing twice
        // in a step changes nothing)
        let acts: Vec<Vec<f32>> = dg
            .teachers
            .iter_mut()
            .map(|t| {
                t.agent.prepare(&dg.env);
                t.agent.act_mean()
            })
            .collect();
        let before = dg.data.len();
        dg.control_step(1.0, &mut rng);
        assert_eq!(dg.data.len(), before + n);
        for i in 0..n {
            let t = who[i];
            assert_eq!(dg.teachers[t].kind, kinds[i]);
            seen[t] = true;
            let (_, _, label) = dg.data.get(before + i);
            assert_eq!(label, &acts[t][i * a..(i + 1) * a], "env {i} step {step}");
            let other = &acts[1 - t][i * a..(i + 1) * a];
            let diff: f32 = label.iter().zip(other).map(|(x, y)| (x - y).abs()).sum();
            assert!(
                diff > 1e-3,
                "the two teachers act alike: the test would not see a mix-up"
            );
        }
    }
    assert!(seen[0] && seen[1], "both teachers labelled envs: {seen:?}");
}

#[test]
fn the_student_learns_its_teachers_and_beta_anneals() {
    let dir = Scratch::new("dagger-learn");
    let (cfg, _, _) = setup(&dir, &["dagger.beta_iterations=4"]);
    let d = DaggerConfig::of(&cfg).unwrap();
    assert_eq!(d.beta(0), 1.0);
    assert_eq!(d.beta(2), 0.5);
    assert_eq!(d.beta(4), 0.0);
    assert_eq!(d.beta(9), 0.0);
    let mut dg = Dagger::new(&cfg, None).unwrap();
    let mut losses = Vec::new();
    let mut errors = Vec::new();
    for it in 0..8 {
        let s = dg.iterate();
        assert_eq!(s.beta, d.beta(it));
        if it == 0 {
            assert_eq!(
                s.forced_fraction, 1.0,
                "beta 1: every action is the teacher's"
            );
        }
        if it >= 4 {
            assert_eq!(
                s.forced_fraction, 0.0,
                "beta 0: every action is the student's"
            );
        }
        assert!(s.loss.is_finite() && s.action_error.is_finite());
        losses.push(s.loss);
        errors.push(s.action_error);
    }
    assert_eq!(dg.iteration, 8);
    assert_eq!(dg.env_steps, 8 * 8 * 4);
    assert_eq!(dg.data.len(), 256, "the ring holds buffer_size transitions");
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(
        last < 0.5 * first,
        "imitation loss fell from {first} to {last} only ({losses:?})"
    );
    assert!(
        errors[7] < errors[0],
        "the student's action error on the visited states fell: {errors:?}"
    );
}

#[test]
fn a_dagger_run_resumes_and_eval_reads_its_student() {
    let dir = Scratch::new("dagger-run");
    let (cfg, _, _) = setup(&dir, &["train.iterations=2"]);
    let run = dir.0.join("run");
    let s = dagger::train(&cfg, &run, false, true).unwrap();
    assert_eq!((s.iterations, s.env_steps), (2, 64));
    let mut more = cfg.clone();
    more.train.iterations = 4;
    let s = dagger::train(&more, &run, true, true).unwrap();
    // the resume refilled the aggregate to the 64 transitions it held at 2
    // (64 env-steps, counted) before its first update, then 2 iterations
    assert_eq!((s.iterations, s.env_steps), (4, 192));
    let log = std::fs::read_to_string(run.join("log.txt")).unwrap();
    assert!(
        log.contains("refilled the aggregated dataset to 64 transitions"),
        "{log}"
    );
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let header = metrics.lines().next().unwrap();
    let names: Vec<&str> = header.split(',').collect();
    let col = |name: &str| names.iter().position(|h| *h == name).unwrap();
    let fields: Vec<&str> = metrics.lines().last().unwrap().split(',').collect();
    assert_eq!(fields[col("buffer_size")].parse::<f64>().unwrap(), 128.0);
    assert_eq!(fields[col("env_steps")].parse::<f64>().unwrap(), 192.0);
    assert!(header.contains("imitation_loss") && header.ends_with("action_error_stair"));
    assert_eq!(metrics.lines().count(), 5, "{metrics}");
    assert!(run.join("plots/training.png").exists());
    // `dreampolicy plot` redraws a DAgger run's own curves (not the PPO panels,
    // whose columns it does not have)
    std::fs::remove_file(run.join("plots/training.png")).unwrap();
    common::run_ok(
        std::process::Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
            .arg("plot")
            .arg(&run),
    );
    assert!(run.join("plots/training.png").exists());
    // the student is an ordinary G1 policy checkpoint
    let ck = Checkpoint::read(&run.join("checkpoints/latest.pt")).unwrap();
    assert_eq!(ck.meta.iteration, 4);
    let r = dreampolicy::eval::evaluate(&ck, &common::flat_eval(2)).unwrap();
    assert_eq!(r.episodes, 2);
    assert_eq!(r.checkpoint_iteration, 4);
    // train specialist refuses a dagger config
    let e = dreampolicy::rl::runner::train(&cfg, &dir.0.join("other"), false, true)
        .expect_err("a dagger config is not a specialist's");
    assert!(e.to_string().contains("train dagger"), "{e}");
}

#[test]
fn a_map_kind_without_a_teacher_is_refused() {
    let dir = Scratch::new("dagger-missing");
    let base = common::load_config("test/dagger_tiny.yaml", &[]);
    let flat = dir.0.join("teacher_flat.pt");
    write_teacher(&base, 11, &flat);
    let mut cfg = base.clone();
    let mut teachers = serde_yaml::Mapping::new();
    teachers.insert("flat".into(), flat.display().to_string().into());
    if let Some(serde_yaml::Value::Mapping(m)) = &mut cfg.dagger {
        m.insert("teachers".into(), serde_yaml::Value::Mapping(teachers));
    }
    let e = Dagger::new(&cfg, None).err().expect("stair has no teacher");
    assert!(e.to_string().contains("'stair'"), "{e}");
}

/// A teacher that reads its scandots on another grid than the student's env
/// would be fed heights at the wrong points: refused, naming the key.
#[test]
fn a_teacher_on_another_scan_grid_is_refused() {
    let dir = Scratch::new("dagger-grid");
    let base = common::load_config("test/dagger_tiny.yaml", &[]);
    let mut fine = base.clone();
    fine.env.observation.scan_grid.spacing = 0.05;
    let (flat, stair) = (
        dir.0.join("teacher_flat.pt"),
        dir.0.join("teacher_stair.pt"),
    );
    write_teacher(&base, 11, &flat);
    write_teacher(&fine, 12, &stair);
    let (f, s) = (flat.display().to_string(), stair.display().to_string());
    let sets = [
        format!("dagger.teachers.flat={f}"),
        format!("dagger.teachers.stair={s}"),
    ];
    let sets: Vec<&str> = sets.iter().map(|s| s.as_str()).collect();
    let cfg = common::load_config("test/dagger_tiny.yaml", &sets);
    let e = Dagger::new(&cfg, None)
        .err()
        .expect("the stair teacher's grid differs");
    assert!(
        e.to_string().contains("scan_grid") && e.to_string().contains("stair"),
        "{e}"
    );
}
