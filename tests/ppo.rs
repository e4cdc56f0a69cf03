//! PPO end to end: it balances the MuJoCo cart-pole, a resumed run is
//! bit-identical to an uninterrupted one (cart-pole and the G1), a kill -9 while
//! checkpointing leaves a loadable checkpoint, and the pieces (GAE, storage,
//! normalizer, checkpoint errors) on hand-made data.
mod common;

use std::process::{Command, Stdio};

use common::{load_config, metrics_column as column, Scratch};
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::normalizer::RunningNorm;
use dreampolicy::rl::runner::{self, latest_checkpoint};
use dreampolicy::rl::storage::{RolloutStorage, Transition};

/// Training seeds libtorch's global generator and sets its thread count: the
/// tests that train take turns.
static TORCH: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn torch_lock() -> std::sync::MutexGuard<'static, ()> {
    TORCH.lock().unwrap_or_else(|e| e.into_inner())
}

fn metrics(dir: &std::path::Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    // everything but the timing columns
    let keep: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !h.contains("time") && !h.contains("per_s"))
        .map(|(i, _)| i)
        .collect();
    lines
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| v[i].to_string()).collect()
        })
        .collect()
}

#[test]
fn ppo_balances_the_cartpole() {
    let _t = torch_lock();
    let dir = Scratch::new("cartpole");
    let cfg = load_config("test/cartpole.yaml", &[]);
    let s = runner::train(&cfg, &dir.0, false, true).unwrap();
    assert_eq!(s.iterations, 60);
    let ret = column(&dir.0, "mean_return");
    let first = ret.iter().copied().find(|r| r.is_finite()).unwrap();
    // the best return is 200 (the episode's length); random actions fall in ~30 steps
    assert!(first < 80.0, "first return {first}");
    assert!(
        s.mean_return > 150.0,
        "return after 60 iterations: {}",
        s.mean_return
    );
    // the checkpoint reloads into a policy that balances on its own, deterministically
    let ck = Checkpoint::read(&s.checkpoint).unwrap();
    assert_eq!(ck.meta.iteration, 60);
    assert_eq!(ck.meta.env_steps, 60 * 32 * 16);
}

fn resume_matches(config: &str) {
    let _t = torch_lock();
    let (a, b) = (Scratch::new("full"), Scratch::new("resumed"));
    let cfg = load_config(config, &[]);
    let total = cfg.train.iterations;
    runner::train(&cfg, &a.0, false, true).unwrap();
    // stop at a checkpoint of the full run (every save_interval), then resume
    let mut half = cfg.clone();
    half.train.iterations = cfg.train.save_interval;
    assert!(half.train.iterations < total);
    runner::train(&half, &b.0, false, true).unwrap();
    assert_eq!(metrics(&b.0).len(), half.train.iterations);
    runner::train(&cfg, &b.0, true, true).unwrap();
    let (ma, mb) = (metrics(&a.0), metrics(&b.0));
    assert_eq!(ma.len(), total);
    assert_eq!(mb.len(), total);
    if let Some(i) = (0..total).find(|&i| ma[i] != mb[i]) {
        panic!(
            "the resumed run differs from the uninterrupted one at row {}:\n{:?}\n{:?}",
            i + 1,
            ma[i],
            mb[i]
        );
    }
    let (ca, cb) = (
        Checkpoint::read(&latest_checkpoint(&a.0)).unwrap(),
        Checkpoint::read(&latest_checkpoint(&b.0)).unwrap(),
    );
    assert_eq!(ca.meta.snapshots, cb.meta.snapshots);
    assert_eq!(ca.meta.adam_step, cb.meta.adam_step);
}

#[test]
fn resumed_cartpole_run_is_bit_identical() {
    resume_matches("test/cartpole.yaml");
}

#[test]
fn resumed_g1_run_is_bit_identical() {
    resume_matches("test/g1_tiny.yaml");
}

/// A term added on resume adds its column: the rows before the resume are
/// rewritten under the new header (`nan` in the new column), so that the table
/// still reads and plots.
#[test]
fn resume_with_a_new_reward_term_rewrites_the_metrics_header() {
    let _t = torch_lock();
    let dir = Scratch::new("newterm");
    let cfg = load_config("test/g1_tiny.yaml", &["train.iterations=2"]);
    runner::train(&cfg, &dir.0, false, true).unwrap();
    let more = load_config(
        "test/g1_tiny.yaml",
        &["train.iterations=3", "env.rewards.terms.termination=-1.0"],
    );
    runner::train(&more, &dir.0, true, true).unwrap();
    let term = column(&dir.0, "rew_termination");
    assert_eq!(term.len(), 3);
    assert!(term[..2].iter().all(|v| v.is_nan()), "{term:?}");
    // the resumed row has the term as every other term: a value once an
    // episode ended in it
    let alive = column(&dir.0, "rew_alive");
    assert_eq!(term[2].is_nan(), alive[2].is_nan(), "{term:?} {alive:?}");
    assert_eq!(column(&dir.0, "iteration"), [1.0, 2.0, 3.0]);
}

#[test]
fn kill_9_while_checkpointing_leaves_a_loadable_checkpoint() {
    let dir = Scratch::new("kill9");
    let run = dir.0.join("run");
    let bin = env!("CARGO_BIN_EXE_dreampolicy");
    let config =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/test/cartpole.yaml");
    let ck = latest_checkpoint(&run);
    let modified = |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    for (attempt, extra_ms) in [0u64, 7, 13, 29, 41].into_iter().enumerate() {
        let mut cmd = Command::new(bin);
        cmd.args([
            "train",
            "specialist",
            "--quiet",
            "--set",
            "train.save_interval=1",
        ])
        .args(["--set", "train.iterations=100000"])
        .stdout(Stdio::null())
        .stderr(Stdio::null());
        if attempt == 0 {
            cmd.arg("--config").arg(&config).arg("--out").arg(&run);
        } else {
            cmd.arg("--resume").arg(&run);
        }
        let before = modified(&ck);
        let mut child = cmd.spawn().unwrap();
        // wait until this process has written a checkpoint (one per iteration),
        // then kill it at an arbitrary moment of the next ones
        let start = std::time::Instant::now();
        while modified(&ck) == before {
            assert!(start.elapsed().as_secs() < 120, "no checkpoint written");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        std::thread::sleep(std::time::Duration::from_millis(extra_ms));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        let c = Checkpoint::read(&ck).unwrap_or_else(|e| panic!("after kill {}: {e}", attempt + 1));
        assert!(c.meta.iteration >= 1);
    }
    // checkpoints were written (one per iteration) and the last one resumes
    let c = Checkpoint::read(&latest_checkpoint(&run)).unwrap();
    assert!(c.meta.iteration > 1, "iteration {}", c.meta.iteration);
}

#[test]
fn broken_checkpoints_are_clear_errors() {
    let dir = Scratch::new("badck");
    let missing = Checkpoint::read(&dir.0.join("none.pt"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        missing.contains("none.pt") && missing.contains("no such file"),
        "{missing}"
    );
    let junk = dir.write("junk.pt", "not a checkpoint");
    let e = Checkpoint::read(&junk).err().unwrap().to_string();
    assert!(
        e.contains("junk.pt") && e.contains("not a checkpoint") && !e.contains('\n'),
        "{e}"
    );
    // a checkpoint cut in half
    let _t = torch_lock();
    let cfg = load_config("test/cartpole.yaml", &["train.iterations=2"]);
    let run = dir.0.join("run");
    runner::train(&cfg, &run, false, true).unwrap();
    let bytes = std::fs::read(latest_checkpoint(&run)).unwrap();
    let cut = dir.0.join("cut.pt");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = Checkpoint::read(&cut).err().unwrap().to_string();
    assert!(e.contains("cut.pt"), "{e}");
}

#[test]
fn gae_matches_a_hand_computation() {
    // 1 env, 3 steps, gamma 0.5, lambda 0.5; the episode ends after step 1
    let mut st = RolloutStorage::new(3, 1, [1, 1, 0, 1]);
    let (r, v, d) = (
        [1.0f32, 2.0, 3.0, 0.0],
        [0.5f32, 1.0, 2.0, 0.0],
        [0.0f32, 1.0, 0.0, 0.0],
    );
    let step = |k: usize| Transition {
        actor_in: &[0.0],
        critic_in: &[0.0],
        scan: &[],
        actions: &[0.0],
        log_probs: &[0.0],
        values: &v[k..k + 1],
        mean: &[0.0],
        rewards: &r[k..k + 1],
        dones: &d[k..k + 1],
    };
    for k in 0..3 {
        st.add(&step(k)).unwrap();
    }
    assert!(
        st.add(&step(3)).is_err(),
        "a full storage refuses more steps"
    );
    st.compute_returns(&[4.0], 0.5, 0.5);
    // step 2: delta = 3 + 0.5*4 - 2 = 3; A = 3
    // step 1 (done): delta = 2 - 1 = 1; A = 1
    // step 0: delta = 1 + 0.5*1 - 0.5 = 1; A = 1 + 0.25*1 = 1.25
    let close = |a: f32, b: f32| (a - b).abs() < 1e-6;
    assert!(
        close(st.advantages[2], 3.0)
            && close(st.advantages[1], 1.0)
            && close(st.advantages[0], 1.25),
        "{:?}",
        st.advantages
    );
    assert!(close(st.returns[0], 1.75) && close(st.returns[1], 2.0) && close(st.returns[2], 5.0));
}

#[test]
fn normalizer_tracks_mean_and_variance_across_batches() {
    let mut n = RunningNorm::new(2);
    let data: Vec<f32> = (0..200)
        .flat_map(|i| [i as f32, 3.0 - 0.5 * i as f32])
        .collect();
    n.update(&data[..100]);
    n.update(&data[100..]);
    let mean0 = (0..200).map(|i| i as f64).sum::<f64>() / 200.0;
    let var0 = (0..200).map(|i| (i as f64 - mean0).powi(2)).sum::<f64>() / 200.0;
    assert!((n.mean[0] - mean0).abs() < 1e-9 && (n.var[0] - var0).abs() < 1e-6);
    assert!(
        (n.mean[1] - (3.0 - 0.5 * mean0)).abs() < 1e-9 && (n.var[1] - 0.25 * var0).abs() < 1e-6
    );
    let mut out = [0.0f32; 2];
    n.apply(&[mean0 as f32, (3.0 - 0.5 * mean0) as f32], &mut out);
    assert!(out.iter().all(|v| v.abs() < 1e-5));
    let back = RunningNorm::from_vec(2, &n.to_vec()).unwrap();
    assert_eq!(back.mean, n.mean);
}

#[test]
fn symmetry_augmentation_trains_the_g1_and_is_refused_for_the_cartpole() {
    let _t = torch_lock();
    let dir = Scratch::new("sym");
    let cfg = load_config(
        "test/g1_tiny.yaml",
        &[
            "ppo.symmetry=true",
            "ppo.mirror_loss_coef=1.0",
            "train.iterations=2",
        ],
    );
    let s = runner::train(&cfg, &dir.0.join("g1"), false, true).unwrap();
    assert_eq!(s.iterations, 2);
    let kl = column(&dir.0.join("g1"), "kl");
    assert!(kl.iter().all(|k| k.is_finite()), "{kl:?}");
    let cp = load_config("test/cartpole.yaml", &["ppo.symmetry=true"]);
    let e = runner::train(&cp, &dir.0.join("cp"), false, true)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("symmetry"), "{e}");
}

/// One PPO iteration fine-tuning the committed walker (8 envs x 8 steps, one
/// minibatch, fixed rate) with `sets` on top, in `dir/name`: the first row's
/// `col`.
fn walker_iteration(dir: &Scratch, name: &str, sets: &[&str], col: &str) -> f64 {
    let init = format!("train.init_checkpoint={}", common::walker_path().display());
    let mut all = vec![
        init.as_str(),
        "env.n_envs=8",
        "ppo.num_steps=8",
        "ppo.num_minibatches=1",
        "train.iterations=1",
        "ppo.schedule=fixed",
        // MuJoCo 2.2.2 (CI) has no implicitfast
        "env.sim.integrator=implicit",
    ];
    all.extend_from_slice(sets);
    let cfg = load_config("specialist/flat.yaml", &all);
    let out = dir.0.join(name);
    runner::train(&cfg, &out, false, true).unwrap();
    column(&out, col)[0]
}

#[test]
fn symmetry_augmentation_measures_kl_on_the_original_samples() {
    // The committed walker is not left/right symmetric: its mirrored actions are
    // far from the mirror of its old means. The KL that steers the learning
    // rate is measured on the original samples (rsl_rl), so fine-tuning it with
    // symmetry reads the same small KL as without; measured over the mirrored
    // half too it read ~100 and the adaptive rate fell to its floor.
    let _t = torch_lock();
    let dir = Scratch::new("sym_kl");
    let kls: Vec<f64> = ["false", "true"]
        .iter()
        .map(|sym| {
            let sym = format!("ppo.symmetry={sym}");
            walker_iteration(&dir, &sym, &[&sym, "ppo.num_epochs=2"], "kl")
        })
        .collect();
    assert!(kls.iter().all(|k| k.is_finite()), "{kls:?}");
    assert!(
        kls[1] < 2.0 * kls[0] + 0.05,
        "without, with symmetry: {kls:?}"
    );
}

#[test]
fn mirrored_samples_start_at_ratio_one_with_the_policy_symmetry_ratio() {
    // One epoch of one minibatch: the clip fraction is measured before any
    // step. With `symmetry_ratio: policy` every sample, mirrored or not, starts
    // at ratio 1 (none clipped); with rsl_rl's `behavior` the committed walker,
    // which is not left/right symmetric, has its mirrored half far outside the
    // clip range.
    let _t = torch_lock();
    let dir = Scratch::new("sym_ratio");
    let clipped: Vec<f64> = ["behavior", "policy"]
        .iter()
        .map(|ratio| {
            let set = format!("ppo.symmetry_ratio={ratio}");
            walker_iteration(
                &dir,
                ratio,
                &[&set, "ppo.symmetry=true", "ppo.num_epochs=1"],
                "clip_fraction",
            )
        })
        .collect();
    assert!(clipped[0] > 0.2, "behavior: {clipped:?}");
    assert_eq!(clipped[1], 0.0, "policy: {clipped:?}");
}

#[test]
fn dual_clip_bounds_the_loss_of_negative_advantages_by_hand() {
    use dreampolicy::rl::ppo::surrogate_per_sample;
    let v = |t: &tch::Tensor| Vec::<f32>::try_from(t).unwrap();
    // log-ratios: ln 2 (ratio 2), 30 (a mirrored sample far in the policy's
    // tail), ln 0.5; advantages +1, -1, -1
    let lr = tch::Tensor::from_slice(&[2f32.ln(), 30.0, 0.5f32.ln()]);
    let adv = tch::Tensor::from_slice(&[1.0f32, -1.0, -1.0]);
    let (plain, _) = surrogate_per_sample(&lr, &adv, 0.2, None);
    let plain = v(&plain);
    // A > 0, r = 2: max(-2, -1.2) = -1.2; A < 0, r = e^30: max(e^30, 1.2)
    assert!((plain[0] + 1.2).abs() < 1e-6, "{plain:?}");
    assert!(plain[1] > 1e12, "{plain:?}");
    // A < 0, r = 0.5: max(0.5, 0.8) = 0.8
    assert!((plain[2] - 0.8).abs() < 1e-6, "{plain:?}");
    let (dual, ratio) = surrogate_per_sample(&lr, &adv, 0.2, Some(3.0));
    let dual = v(&dual);
    assert!((dual[0] + 1.2).abs() < 1e-6, "{dual:?}");
    assert!((dual[1] - 3.0).abs() < 1e-6, "the bound -c A: {dual:?}");
    assert!((dual[2] - 0.8).abs() < 1e-6, "{dual:?}");
    // log-ratios are clamped to +-20 before exp
    assert!((v(&ratio)[1] - 20f32.exp()).abs() / 20f32.exp() < 1e-5);
    // the bound is a number above 1
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/specialist/flat.yaml");
    // (implicit: MuJoCo 2.2.2, in CI, has no implicitfast)
    let sets = [
        "ppo.dual_clip=0.5".into(),
        "env.sim.integrator=implicit".into(),
    ];
    let e = dreampolicy::rl::config::load(&path, &sets)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ppo.dual_clip"), "{e}");
}

#[test]
fn walker_transfers_into_a_scan_encoder_policy_acting_the_same() {
    use dreampolicy::env::VecEnv;
    use dreampolicy::rl::{Agent, VecTask};
    let _t = torch_lock();
    let dir = Scratch::new("transfer");
    let walker_cfg = load_config("test/g1_tiny.yaml", &["train.iterations=2"]);
    let walker = runner::train(&walker_cfg, &dir.0.join("walker"), false, true).unwrap();
    let ck = Checkpoint::read(&walker.checkpoint).unwrap();
    let init = format!("train.init_checkpoint={}", walker.checkpoint.display());
    let sets = [
        "train.iterations=1",
        "policy.scan_encoder.enabled=true",
        "policy.scan_encoder.dims=[16,8]",
        "env.terrain.mode=map",
        "env.terrain.map.num_levels=3",
        "env.terrain.map.num_cols=2",
        "env.terrain.map.kinds={uneven: 1.0}",
        init.as_str(),
    ];
    let spec_cfg = load_config("test/g1_tiny.yaml", &sets);

    // on the same (terrain) states, the transferred policy acts as the walker does
    let mut env = VecEnv::new(&spec_cfg.env).unwrap();
    let n = env.n_envs();
    let mut old = Agent::new(&walker_cfg.policy, env.dims(), n, true);
    ck.load_agent(&mut old).unwrap();
    let mut new = Agent::new(&spec_cfg.policy, env.dims(), n, true);
    let t = ck.transfer_agent(&mut new).unwrap();
    assert_eq!(t.widened, ["actor.0.weight", "critic.0.weight"]);
    assert_eq!(t.fresh.len(), 8, "{t}");
    assert!(new.policy.uses_scan() && !old.policy.uses_scan());
    common::assert_acts_alike(&mut old, &mut new, &mut env, 3);

    // a training run starts from it and says so
    let run = dir.0.join("specialist");
    runner::train(&spec_cfg, &run, false, true).unwrap();
    let log = std::fs::read_to_string(run.join("log.txt")).unwrap();
    assert!(
        log.contains("widened for the scan latent: [actor.0.weight, critic.0.weight]"),
        "{log}"
    );

    // train.init_std resets the copied std, so that a fine-tune explores again
    let mut explore = spec_cfg.clone();
    explore.train.init_std = Some(0.9);
    let run = runner::train(&explore, &dir.0.join("explore"), false, true).unwrap();
    let mut agent = Agent::new(&explore.policy, env.dims(), n, true);
    Checkpoint::read(&run.checkpoint)
        .unwrap()
        .load_agent(&mut agent)
        .unwrap();
    let std = agent.policy.std().mean(tch::Kind::Float).double_value(&[]);
    assert!(
        (std - 0.9).abs() < 0.05,
        "std {std} after one iteration from 0.9"
    );
    let mut bad = spec_cfg.clone();
    bad.train.init_checkpoint = None;
    bad.train.init_std = Some(0.9);
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("train.init_std"));

    // wider hidden layers of the actor and critic (Net2Net): the old units
    // copied, the new ones silent, so that the wider policy acts the same
    let wide = load_config(
        "test/g1_tiny.yaml",
        &[
            "policy.actor_hidden=[48,40]",
            "policy.critic_hidden=[64,32]",
        ],
    );
    let mut grown = Agent::new(&wide.policy, env.dims(), n, true);
    let t = ck.transfer_agent(&mut grown).unwrap();
    let mut names = t.grown.clone();
    names.sort();
    assert_eq!(
        names,
        [
            "actor.0.bias",
            "actor.0.weight",
            "actor.1.bias",
            "actor.1.weight",
            "actor.2.weight",
            "critic.0.bias",
            "critic.0.weight",
            "critic.1.weight"
        ],
        "{t}"
    );
    let mut walker_env = VecEnv::new(&walker_cfg.env).unwrap();
    common::assert_acts_alike(&mut old, &mut grown, &mut walker_env, 3);
    // ... and values alike: the critic's new units start silent too
    common::assert_values_alike(&old, &grown, &walker_env);

    // a specialist's scan encoders grow too, their latent included: the new
    // latent units enter the actor and critic through zero columns
    let spec_ck = Checkpoint::read(&run.checkpoint).unwrap();
    let mut spec = Agent::new(&explore.policy, env.dims(), n, true);
    spec_ck.load_agent(&mut spec).unwrap();
    let mut sets_wide: Vec<&str> = sets.to_vec();
    sets_wide.push("policy.scan_encoder.dims=[24,12]");
    sets_wide.push("policy.actor_hidden=[48,40]");
    let wide_scan = load_config("test/g1_tiny.yaml", &sets_wide);
    let mut grown = Agent::new(&wide_scan.policy, env.dims(), n, true);
    let t = spec_ck.transfer_agent(&mut grown).unwrap();
    for name in [
        "actor.0.weight",
        "critic.0.weight",
        "scan_actor.0.weight",
        "scan_actor.1.weight",
        "scan_critic.1.bias",
    ] {
        assert!(t.grown.iter().any(|g| g == name), "{name}: {t}");
    }
    common::assert_acts_alike(&mut spec, &mut grown, &mut env, 3);
    common::assert_values_alike(&spec, &grown, &env);

    // a longer MLP history (oldest first): the older states enter through
    // zero columns, so the policy still acts on its last states alone
    let k = spec.policy.history_len();
    assert!(k > 0, "g1_tiny has an MLP history");
    let longer = format!("policy.history.length={}", 3 * k);
    let mut sets_long: Vec<&str> = sets.to_vec();
    sets_long.push(&longer);
    let long_cfg = load_config("test/g1_tiny.yaml", &sets_long);
    let mut long = Agent::new(&long_cfg.policy, env.dims(), n, true);
    let t = spec_ck.transfer_agent(&mut long).unwrap();
    assert!(t.grown.iter().any(|g| g == "hist.0.weight"), "{t}");
    assert_eq!(long.policy.history_len(), 3 * k);
    common::assert_acts_alike(&mut spec, &mut long, &mut env, 3);

    // other architecture changes are refused, naming the tensor
    let narrow = load_config("test/g1_tiny.yaml", &["policy.actor_hidden=[16,32]"]);
    let mut agent = Agent::new(&narrow.policy, env.dims(), n, true);
    let e = ck.transfer_agent(&mut agent).err().unwrap().to_string();
    assert!(
        e.contains("'actor.0.") && e.contains("only the scan encoders"),
        "{e}"
    );
}

/// `policy.estimator` (the paper's privileged-information estimator): added to
/// a policy that lacks it, it starts silent (fresh weights, zero columns into
/// the actor's first layer: the policy acts as its source); trained beside
/// PPO, its regression of the critic's base velocity falls; the ONNX and
/// NumPy exporters refuse it, and so does a task without the G1 critic.
#[test]
fn estimator_starts_silent_and_learns_the_base_velocity() {
    use dreampolicy::env::VecEnv;
    use dreampolicy::rl::{Agent, VecTask};
    let _t = torch_lock();
    let dir = Scratch::new("estimator");
    let walker_cfg = load_config("test/g1_tiny.yaml", &["train.iterations=2"]);
    let walker = runner::train(&walker_cfg, &dir.0.join("walker"), false, true).unwrap();
    let ck = Checkpoint::read(&walker.checkpoint).unwrap();

    let init = format!("train.init_checkpoint={}", walker.checkpoint.display());
    let sets = [
        init.as_str(),
        "policy.estimator={dims: [32, 16]}",
        "ppo.schedule=fixed",
        "ppo.learning_rate=1e-3",
        "env.n_envs=8",
        "ppo.num_steps=16",
        "train.iterations=30",
        "train.save_interval=30",
    ];
    let cfg = load_config("test/g1_tiny.yaml", &sets);
    let mut env = VecEnv::new(&cfg.env).unwrap();
    let n = env.n_envs();
    let mut old = Agent::new(&walker_cfg.policy, env.dims(), n, true);
    ck.load_agent(&mut old).unwrap();
    let mut new = Agent::new(&cfg.policy, env.dims(), n, true);
    let t = ck.transfer_agent(&mut new).unwrap();
    assert!(new.policy.has_estimator());
    assert_eq!(t.grown, ["actor.0.weight"], "{t}");
    let mut fresh = t.fresh.clone();
    fresh.sort();
    assert_eq!(
        fresh,
        [
            "est.0.bias",
            "est.0.weight",
            "est.1.bias",
            "est.1.weight",
            "est.2.bias",
            "est.2.weight"
        ],
        "{t}"
    );
    common::assert_acts_alike(&mut old, &mut new, &mut env, 3);
    // a scan encoder and the estimator added at once (a terrain line started
    // from a flat foundation): both enter the actor through zero columns
    let both = load_config(
        "test/g1_tiny.yaml",
        &[
            init.as_str(),
            "policy.estimator={dims: [32, 16]}",
            "policy.scan_encoder.enabled=true",
            "env.n_envs=8",
        ],
    );
    let mut grown = Agent::new(&both.policy, env.dims(), n, true);
    let t = ck.transfer_agent(&mut grown).unwrap();
    assert!(grown.policy.has_estimator() && grown.policy.uses_scan());
    assert!(t.widened.iter().any(|w| w == "actor.0.weight"), "{t}");
    common::assert_acts_alike(&mut old, &mut grown, &mut env, 3);

    // trained beside PPO, the regression falls
    let run = dir.0.join("est");
    let s = runner::train(&cfg, &run, false, true).unwrap();
    let loss = column(&run, "estimator_loss");
    assert_eq!(loss.len(), 30);
    assert!(loss.iter().all(|l| l.is_finite() && *l >= 0.0), "{loss:?}");
    let (first, last) = (
        loss[..5].iter().sum::<f64>() / 5.0,
        loss[25..].iter().sum::<f64>() / 5.0,
    );
    assert!(last < 0.5 * first, "estimator loss {first} -> {last}");
    // without the estimator the column is not there
    assert!(!std::fs::read_to_string(dir.0.join("walker/metrics.csv"))
        .unwrap()
        .contains("estimator_loss"));
    // the curves draw the regression in the losses panel when the column is
    // there, and without it when it is not
    for r in [&run, &dir.0.join("walker")] {
        let png = runner::plot_run(r).unwrap();
        assert!(std::fs::metadata(&png).unwrap().len() > 10_000, "{png:?}");
    }

    // the exporters that rebuild the network refuse it; TorchScript traces it
    let est_ck = Checkpoint::read(&s.checkpoint).unwrap();
    let e = dreampolicy::rl::onnx::export_onnx(&est_ck, &dir.0.join("p.onnx"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("estimator") && e.contains("--file-only"), "{e}");
    let e = dreampolicy::rl::export::export_npz(&est_ck, &dir.0.join("p.npz"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("estimator"), "{e}");

    // a task without the G1 critic, and a bad loss weight, are refused
    let cp = load_config("test/cartpole.yaml", &["policy.estimator={}"]);
    let e = runner::train(&cp, &dir.0.join("cp"), false, true)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("policy.estimator"), "{e}");
    let mut bad = cfg.clone();
    bad.policy.estimator.as_mut().unwrap().loss_coef = -1.0;
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("policy.estimator.loss_coef"));
}

/// `checkpoint average`: the networks and normalizers of two kept checkpoints
/// of one run are averaged element-wise; Adam's moments and the record are the
/// last file's, which names both; a file of another network layout is refused.
#[test]
fn averaged_checkpoint_holds_the_mean_of_the_networks() {
    use dreampolicy::checkpoint::NamedTensors;
    use dreampolicy::rl::checkpoint::{average, CheckpointMeta};
    let _t = torch_lock();
    let dir = Scratch::new("average");
    let cfg = load_config(
        "test/cartpole.yaml",
        &[
            "train.iterations=10",
            "train.save_interval=5",
            "train.keep_interval=5",
        ],
    );
    runner::train(&cfg, &dir.0, false, true).unwrap();
    let a = dir.0.join("checkpoints/iter_000005.pt");
    let b = dir.0.join("checkpoints/iter_000010.pt");
    let out = dir.0.join("mean.pt");
    let meta = average(&[a.clone(), b.clone()], &out).unwrap();
    assert_eq!(meta.iteration, 10);
    let read = |p: &std::path::Path| NamedTensors::<CheckpointMeta>::read(p).unwrap();
    let (fa, fb, fm) = (read(&a), read(&b), read(&out));
    assert_eq!(
        fm.meta.averaged_from,
        [a.display().to_string(), b.display().to_string()]
    );
    assert_eq!(fm.names(), fb.names());
    let mut policy_tensors = 0;
    for name in fm.names().into_iter().filter(|n| *n != "meta") {
        let (ta, tb, tm) = (
            fa.tensor(name).unwrap(),
            fb.tensor(name).unwrap(),
            fm.tensor(name).unwrap(),
        );
        let expect = if name.starts_with("policy.") || name.starts_with("norm.") {
            policy_tensors += 1;
            // the two checkpoints are 5 updates apart: their weights differ
            if name.starts_with("policy.") {
                assert!(ta != tb, "{name} did not change in 5 iterations");
            }
            (ta.to_kind(tch::Kind::Double) + tb.to_kind(tch::Kind::Double)) / 2.0
        } else {
            tb.to_kind(tch::Kind::Double)
        };
        let diff = (tm.to_kind(tch::Kind::Double) - expect)
            .abs()
            .max()
            .double_value(&[]);
        assert!(diff < 1e-6, "{name}: off by {diff}");
    }
    assert!(policy_tensors >= 6, "{policy_tensors} averaged tensors");
    // the result reads as a checkpoint of the run
    assert_eq!(
        Checkpoint::read(&out).unwrap().meta.env_steps,
        meta.env_steps
    );
    // another layout is refused, naming the file
    let g1 = Scratch::new("average_g1");
    let g1_cfg = load_config("test/g1_tiny.yaml", &["train.iterations=1"]);
    runner::train(&g1_cfg, &g1.0, false, true).unwrap();
    let other = latest_checkpoint(&g1.0);
    let e = average(&[a, other.clone()], &g1.0.join("bad.pt"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("network layout"), "{e}");
    assert!(!g1.0.join("bad.pt").exists());
}
