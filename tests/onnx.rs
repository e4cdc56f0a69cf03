//! ONNX export (`dreampolicy export --format onnx`) checked by a runtime we did
//! not write: tract loads the graph and gives the TorchScript module's actions
//! (and the training agent's) within 1e-5, on random inputs and on the
//! observations of real rollouts, for the committed walker (MLP history, blind)
//! and for test policies with a GRU history and MLP or GRU scan encoders.
mod common;

use std::path::Path;

use common::{run_ok, walker_path, Scratch};
use dreampolicy::env::VecEnv;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::config::{HistoryKind, PolicyConfig, ScanEncoderKind};
use dreampolicy::rl::normalizer::RunningNorm;
use dreampolicy::rl::{Agent, TaskDims, VecTask};
use tch::{Kind, Tensor};
use tract_onnx::prelude::*;

const TOL: f32 = 1e-5;

/// One batch of raw actor inputs: obs `[B, 98]`, history `[B, K, 98]`, scan `[B, 187]`.
struct Batch {
    b: usize,
    k: usize,
    obs: Vec<f32>,
    hist: Vec<f32>,
    scan: Vec<f32>,
}

type Runnable = std::sync::Arc<TypedRunnableModel>;

/// The ONNX file in tract for batches of `b` rows with `k` history states.
/// The graph's batch dimension is free (`batch`); tract's GRU wants it known
/// when it builds the plan, so each batch size gets its own plan.
fn load_tract(path: &Path, b: usize, k: usize, d: TaskDims) -> Runnable {
    tract_onnx::onnx()
        .model_for_path(path)
        .unwrap()
        .with_input_fact(0, f32::fact([b, d.obs]).into())
        .unwrap()
        .with_input_fact(1, f32::fact([b, k, d.obs]).into())
        .unwrap()
        .with_input_fact(2, f32::fact([b, d.scan]).into())
        .unwrap()
        .into_optimized()
        .unwrap()
        .into_runnable()
        .unwrap()
}

fn tract_actions(m: &Runnable, x: &Batch, d: TaskDims) -> Vec<f32> {
    let t = |v: &[f32], shape: &[usize]| -> TValue {
        tract_ndarray::ArrayD::from_shape_vec(shape, v.to_vec())
            .unwrap()
            .into_tensor()
            .into()
    };
    let out = m
        .run(tvec![
            t(&x.obs, &[x.b, d.obs]),
            t(&x.hist, &[x.b, x.k, d.obs]),
            t(&x.scan, &[x.b, d.scan]),
        ])
        .unwrap();
    let a = out[0].to_plain_array_view::<f32>().unwrap();
    assert_eq!(a.shape(), [x.b, d.action]);
    a.iter().copied().collect()
}

fn torchscript_actions(m: &tch::CModule, x: &Batch, d: TaskDims) -> Vec<f32> {
    let (b, k) = (x.b as i64, x.k as i64);
    let obs = Tensor::from_slice(&x.obs).reshape([b, d.obs as i64]);
    let hist = Tensor::from_slice(&x.hist).reshape([b, k, d.obs as i64]);
    let scan = Tensor::from_slice(&x.scan).reshape([b, d.scan as i64]);
    let a = tch::no_grad(|| m.forward_ts(&[obs, hist, scan])).unwrap();
    Vec::<f32>::try_from(a.flatten(0, -1)).unwrap()
}

/// Random raw inputs on the scale of the real ones.
fn random_batch(b: usize, k: usize, d: TaskDims, seed: i64) -> Batch {
    tch::manual_seed(seed);
    let r = |n: usize| {
        Vec::<f32>::try_from(Tensor::randn([n as i64], (Kind::Float, tch::Device::Cpu)) * 1.5)
            .unwrap()
    };
    Batch {
        b,
        k,
        obs: r(b * d.obs),
        hist: r(b * k * d.obs),
        scan: r(b * d.scan),
    }
}

/// Check tract's (running the ONNX file `onnx`) and TorchScript's actions agree on `x`.
fn assert_agree(onnx: &Path, ts: &tch::CModule, x: &Batch, d: TaskDims, what: &str) {
    let a = tract_actions(&load_tract(onnx, x.b, x.k, d), x, d);
    let t = torchscript_actions(ts, x, d);
    let diff = common::max_abs_diff(&a, &t);
    let scale = t.iter().fold(0f32, |m, v| m.max(v.abs()));
    eprintln!(
        "{what}: batch {}, max |tract - torchscript| {diff:.2e}, actions up to {scale:.2}",
        x.b
    );
    assert!(
        scale > 0.05,
        "{what}: actions too small to compare ({scale})"
    );
    assert!(
        diff < TOL,
        "{what}: ONNX (tract) and TorchScript differ by {diff} (actions up to {scale})"
    );
}

/// A policy with every weight and the normalizers drawn at random (the actor's
/// last layer is initialized at gain 0.01, which would make any two graphs agree).
fn random_agent(cfg: &PolicyConfig, d: TaskDims, seed: i64) -> Agent {
    tch::manual_seed(seed);
    let mut agent = Agent::new(cfg, d, 1, true);
    tch::no_grad(|| {
        for (_, v) in agent.policy.named_parameters() {
            // N(0, 1/fan_in) weights (LeCun's scale, the actions O(1)), small biases
            let std = match v.size().as_slice() {
                [_, fan_in] => 1.0 / (*fan_in as f64).sqrt(),
                _ => 0.1,
            };
            let r = v.randn_like() * std;
            v.shallow_clone().copy_(&r);
        }
    });
    let norm = |dim: usize, seed: u64| {
        let mut v: Vec<f64> = (0..dim)
            .map(|i| ((i as u64 * 7 + seed) % 11) as f64 * 0.1 - 0.5)
            .collect();
        v.extend((0..dim).map(|i| 0.2 + ((i as u64 * 5 + seed) % 13) as f64 * 0.15));
        v.push(100.0);
        RunningNorm::from_vec(dim, &v).unwrap()
    };
    agent.obs_norm = norm(d.obs, 1);
    agent.scan_norm = norm(d.scan, 2);
    agent
}

fn dims() -> TaskDims {
    TaskDims {
        obs: dreampolicy::env::obs::OBS_DIM,
        critic: dreampolicy::env::obs::OBS_DIM + 3,
        scan: dreampolicy::env::obs::SCAN_DIM,
        action: 29,
    }
}

/// Export `agent` both ways into `dir` and compare on random inputs (batches
/// of 1 and 7: the batch size is free in both graphs).
fn check_both_ways(agent: &mut Agent, dir: &Path, what: &str) {
    let onnx = dir.join(format!("{what}.onnx"));
    let pt = dir.join(format!("{what}.pt"));
    let info = dreampolicy::rl::onnx::write_actor_onnx(agent, &[], &onnx).unwrap();
    assert_eq!(info.opset, 17);
    dreampolicy::rl::export::trace_actor(agent, &pt).unwrap();
    let ts = tch::CModule::load(&pt).unwrap();
    let d = agent.dims();
    let k = agent.policy.history_len();
    for (b, seed) in [(1, 11), (7, 12)] {
        assert_agree(&onnx, &ts, &random_batch(b, k, d, seed), d, what);
    }
}

#[test]
fn the_walkers_onnx_graph_acts_as_its_torchscript_and_agent_on_real_rollouts() {
    let dir = Scratch::new("onnx-walker");
    let ck = Checkpoint::read(&walker_path()).unwrap();
    let cfg = ck.config().unwrap();
    let onnx = dir.0.join("walker.onnx");
    let pt = dir.0.join("walker.pt");
    let info = dreampolicy::rl::onnx::export_onnx(&ck, &onnx).unwrap();
    assert_eq!((info.history_len, info.history.as_str()), (5, "mlp"));
    assert_eq!(info.scan_encoder, None);
    dreampolicy::rl::export::export(&ck, &pt).unwrap();
    let ts = tch::CModule::load(&pt).unwrap();

    // rollouts of the walker in its own env: 4 envs, 60 control steps
    let mut env_cfg = cfg.env.clone();
    env_cfg.n_envs = 4;
    env_cfg.threads = 1;
    let mut env = VecEnv::new(&env_cfg).unwrap();
    let d = env.dims();
    let m = load_tract(&onnx, 4, 5, d);
    let mut agent = Agent::new(&cfg.policy, d, 4, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent).unwrap();
    agent.set_frozen(true);
    agent.reset_history(&env);
    let mut worst = 0f32;
    for step in 0..60 {
        agent.prepare(&env);
        let mean = agent.act_mean();
        let x = Batch {
            b: 4,
            k: 5,
            obs: env.obs().to_vec(),
            hist: agent.history().to_vec(),
            scan: env.scan().to_vec(),
        };
        if step % 10 == 0 {
            assert_agree(&onnx, &ts, &x, d, "walker");
        }
        let a = tract_actions(&m, &x, d);
        worst = worst.max(common::max_abs_diff(&a, &mean));
        env.step(&mean);
        agent.after_step(&env);
    }
    assert!(
        worst < TOL,
        "ONNX (tract) and the training agent differ by {worst}"
    );
    // and off the rollouts
    assert_agree(&onnx, &ts, &random_batch(3, 5, d, 5), d, "walker, random");
}

#[test]
fn gru_and_mlp_test_policies_export_to_onnx_that_tract_runs_alike() {
    let dir = Scratch::new("onnx-test-policies");
    let d = dims();
    let base = PolicyConfig {
        actor_hidden: vec![64, 32],
        critic_hidden: vec![32],
        ..PolicyConfig::default()
    };
    let mut cases = Vec::new();
    // GRU history, MLP scan encoder (a specialist's layout, smaller)
    let mut c = base.clone();
    c.history.kind = HistoryKind::Gru;
    c.history.gru_hidden = 24;
    c.scan_encoder.enabled = true;
    c.scan_encoder.kind = ScanEncoderKind::Mlp;
    c.scan_encoder.dims = vec![32, 16];
    cases.push(("gru_hist_mlp_scan", c));
    // MLP history, GRU scan encoder over 11 rows of 17 scandots
    let mut c = base.clone();
    c.history.kind = HistoryKind::Mlp;
    c.history.length = 3;
    c.history.mlp_dims = vec![32, 16];
    c.scan_encoder.enabled = true;
    c.scan_encoder.kind = ScanEncoderKind::Gru;
    c.scan_encoder.step = 17;
    c.scan_encoder.gru_hidden = 12;
    cases.push(("mlp_hist_gru_scan", c));
    // no history, no scan, tanh
    let mut c = base.clone();
    c.history.kind = HistoryKind::None;
    c.scan_encoder.enabled = false;
    c.activation = dreampolicy::rl::config::Activation::Tanh;
    cases.push(("plain_tanh", c));
    for (i, (what, cfg)) in cases.into_iter().enumerate() {
        let mut agent = random_agent(&cfg, d, 40 + i as i64);
        check_both_ways(&mut agent, &dir.0, what);
    }
}

#[test]
fn export_format_onnx_writes_a_bundle_with_both_files_and_a_single_onnx_file() {
    let dir = Scratch::new("onnx-cli");
    let bin = env!("CARGO_BIN_EXE_dreampolicy");
    let walker = walker_path();
    let out = dir.0.join("bundle");
    let json = run_ok(
        std::process::Command::new(bin)
            .arg("export")
            .arg("--checkpoint")
            .arg(&walker)
            .arg("--out")
            .arg(&out)
            .args(["--format", "onnx"]),
    );
    assert!(json.contains("policy.onnx"), "{json}");
    for f in ["policy.pt", "policy.npz", "policy.onnx", "deploy.yaml"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let b = dreampolicy::deploy::Bundle::read(&out).unwrap();
    let o = b.onnx_policy.as_ref().unwrap();
    assert_eq!((o.file.as_str(), o.opset), ("policy.onnx", 17));
    assert!(b.files.contains_key("policy.onnx"));
    // the bundle's digest covers the ONNX file
    let mut bytes = std::fs::read(out.join("policy.onnx")).unwrap();
    let n = bytes.len();
    bytes[n - 3] ^= 0x55;
    std::fs::write(out.join("policy.onnx"), &bytes).unwrap();
    let e = dreampolicy::deploy::Bundle::read(&out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("policy.onnx") && e.contains("corrupt"), "{e}");

    let single = dir.0.join("walker.onnx");
    run_ok(
        std::process::Command::new(bin)
            .arg("export")
            .arg("--checkpoint")
            .arg(&walker)
            .arg("--out")
            .arg(&single)
            .args(["--format", "onnx", "--file-only"]),
    );
    let d = dims();
    let m = load_tract(&single, 2, 5, d);
    let a = tract_actions(&m, &random_batch(2, 5, d, 9), d);
    assert!(a.iter().all(|v| v.is_finite()));
}

#[test]
fn python_onnxruntime_gives_the_bundles_reference_actions_and_walks_the_walker() {
    let Some(py) = common::pyenv("mujoco, numpy, yaml, onnxruntime") else {
        return;
    };
    let dir = Scratch::new("onnx-python");
    let ck = Checkpoint::read(&walker_path()).unwrap();
    let out = dir.0.join("bundle");
    dreampolicy::deploy::write_bundle(&ck, &out, true).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let checked: serde_json::Value = serde_json::from_str(&run_ok(
        std::process::Command::new(&py)
            .arg(root.join("scripts/check_onnx_python.py"))
            .arg(&out),
    ))
    .unwrap();
    assert_eq!(checked["ok"], true, "{checked}");
    assert_eq!(checked["opset"], serde_json::json!([17]));
    assert_eq!(checked["rollout_rows"], 10);
    for tag in ["rollout", "random"] {
        let diff = checked[format!("{tag}_max_abs_diff")].as_f64().unwrap();
        assert!(diff < 1e-5, "{checked}");
        assert!(checked[format!("{tag}_action_abs_max")].as_f64().unwrap() > 0.5);
    }
    // the stock-MuJoCo deployer with onnxruntime as its actor walks the walker
    let v: serde_json::Value = serde_json::from_str(&run_ok(
        std::process::Command::new(&py)
            .arg(root.join("scripts/deploy_mujoco.py"))
            .arg("--bundle")
            .arg(&out)
            .args(["--runtime", "onnx", "--seconds", "4"]),
    ))
    .unwrap();
    assert_eq!(
        (v["fell"].as_bool(), v["runtime"].as_str()),
        (Some(false), Some("onnx")),
        "{v}"
    );
    assert!(v["distance_m"].as_f64().unwrap() > 1.2, "{v}");
}
