//! The deployment bundle: a controller that reads only `deploy.yaml` and the
//! TorchScript file builds the training env's observation from a robot's
//! measurements and takes the training agent's actions; the committed walker's
//! bundle walks in `deploy-sim`; broken bundles are one-line errors.
mod common;

use std::process::Command;

use common::{run_ok, walker_path, Scratch};
use dreampolicy::deploy::{
    deploy_sim, write_bundle, Bundle, Controller, DeploySimOptions, Sensors,
};
use dreampolicy::env::VecEnv;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::{Agent, VecTask};
use dreampolicy::sim::ObjType;

fn walker_bundle(dir: &Scratch) -> std::path::PathBuf {
    let ck = Checkpoint::read(&walker_path()).unwrap();
    let out = dir.0.join("bundle");
    let info = write_bundle(&ck, &out, false).unwrap();
    assert_eq!(info.history_len, 5);
    assert!(!info.uses_scan);
    out
}

#[test]
fn the_bundles_controller_sees_and_acts_as_the_training_env_and_agent() {
    let dir = Scratch::new("deploy-obs");
    let bundle_dir = walker_bundle(&dir);
    let mut c = Controller::load(&bundle_dir, None).unwrap();
    let b = c.bundle.clone();
    assert_eq!(b.joints.len(), 29);
    assert_eq!(b.observation.dim, 98);
    assert_eq!(b.joints[3].name, "left_knee_joint");

    // the walker's env as eval runs it, without observation noise
    let ck = Checkpoint::read(&walker_path()).unwrap();
    let cfg = ck.config().unwrap();
    let mut env_cfg = cfg.env.clone();
    env_cfg.n_envs = 1;
    env_cfg.threads = 1;
    env_cfg.observation.add_noise = false;
    env_cfg.domain_rand.enabled = false;
    env_cfg.init.yaw = [0.3, 0.3];
    env_cfg.commands.heading = [0.0, 0.0];
    env_cfg.commands.lin_vel_x = [0.7, 0.7];
    env_cfg.commands.lin_vel_y = [0.0, 0.0];
    let mut env = VecEnv::new(&env_cfg).unwrap();
    let mut agent = Agent::new(&cfg.policy, env.dims(), 1, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent).unwrap();
    agent.set_frozen(true);
    agent.reset_history(&env);

    // the bundle's joints found by name, as a deployer finds them
    let model = env.envs()[0].data().model().clone();
    let (qpos, dof): (Vec<usize>, Vec<usize>) = b
        .joints
        .iter()
        .map(|j| {
            let id = model.name2id(ObjType::Joint, &j.name).unwrap();
            (
                model.jnt_qposadr()[id] as usize,
                model.jnt_dofadr()[id] as usize,
            )
        })
        .unzip();
    let scan = vec![0.0f32; b.scan.dim];
    let mut worst_obs = 0.0f32;
    let mut worst_action = 0.0f32;
    for step in 0..120 {
        let d = env.envs()[0].data();
        let (p, v) = (d.qpos(), d.qvel());
        let s = Sensors {
            quat: [p[3], p[4], p[5], p[6]],
            gyro: [v[3], v[4], v[5]],
            q: qpos.iter().map(|&a| p[a]).collect(),
            qd: dof.iter().map(|&a| v[a]).collect(),
        };
        // the heading rule gives the env's command (heading 0, yaw starts at 0.3)
        let cmd = c.heading_command(s.quat, 0.7, 0.0, 0.0);
        let env_cmd = env.envs()[0].state().command;
        for a in 0..3 {
            assert!(
                (cmd[a] - env_cmd[a]).abs() < 1e-9,
                "step {step}: command {cmd:?} vs the env's {env_cmd:?}"
            );
        }
        let (targets, obs) = c.act(&s, cmd, &scan).unwrap();
        for (i, (a, e)) in obs.iter().zip(env.obs()).enumerate() {
            let diff = (a - e).abs();
            assert!(diff < 1e-4, "step {step}: obs[{i}] {a} vs the env's {e}");
            worst_obs = worst_obs.max(diff);
        }
        agent.prepare(&env);
        let ours = agent.act_mean();
        for (a, e) in c.last_action().iter().zip(&ours) {
            worst_action = worst_action.max((a - e.clamp(-10.0, 10.0)).abs());
        }
        // the targets are default + scale * action
        let j = 3;
        let t = b.joints[j].default_pos + b.joints[j].action_scale * c.last_action()[j] as f64;
        assert!((targets[j] - t).abs() < 1e-12);
        let info = env.step(&ours);
        assert_eq!(info.episodes_done, 0, "the walker fell at {step}");
        agent.after_step(&env);
    }
    assert!(worst_action < 1e-3, "actions differ by {worst_action}");
    // the yaw was steered toward the heading
    let yaw = env.envs()[0].state().yaw;
    assert!(yaw.abs() < 0.25, "yaw {yaw}");
    eprintln!("worst observation difference {worst_obs}, action {worst_action}");
}

#[test]
fn the_walkers_bundle_walks_in_deploy_sim() {
    let dir = Scratch::new("deploy-sim");
    let bundle_dir = walker_bundle(&dir);
    let o = DeploySimOptions {
        scene: None,
        seconds: 8.0,
        speed: 0.75,
        noise_seed: Some(1),
    };
    let s = deploy_sim(&bundle_dir, &o).unwrap();
    assert!(!s.fell, "{s:?}");
    assert_eq!(s.steps, 400);
    assert!(s.distance_m > 3.0, "{s:?}");
    assert!(s.final_yaw_deg.abs() < 15.0, "{s:?}");
    assert!(s.observation_noise);
    // the CLI prints the same run as JSON
    let out = run_ok(
        Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
            .args(["deploy-sim", "--bundle"])
            .arg(&bundle_dir)
            .args(["--seconds", "1", "--json"]),
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["steps"], 50);
    assert_eq!(v["fell"], false);
}

#[test]
fn broken_bundles_are_one_line_errors() {
    let dir = Scratch::new("deploy-bad");
    let bundle_dir = walker_bundle(&dir);
    let text = std::fs::read_to_string(bundle_dir.join("deploy.yaml")).unwrap();
    let b: Bundle = serde_yaml::from_str(&text).unwrap();
    assert_eq!(b.policy.file, "policy.pt");
    assert!(b.eval.is_some(), "the walker's eval.json is in the bundle");

    // the CLI writes the same bundle, or the TorchScript file alone
    let cli = dir.0.join("cli-bundle");
    let out = run_ok(
        Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
            .arg("export")
            .arg("--checkpoint")
            .arg(walker_path())
            .arg("--out")
            .arg(&cli),
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["history_len"], 5);
    for f in ["deploy.yaml", "policy.pt", "policy.npz"] {
        assert!(cli.join(f).is_file(), "{f} missing");
    }
    let alone = dir.0.join("alone.pt");
    run_ok(
        Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
            .arg("export")
            .arg("--checkpoint")
            .arg(walker_path())
            .arg("--out")
            .arg(&alone)
            .arg("--torchscript-only"),
    );
    assert!(tch::CModule::load(&alone).is_ok());

    let err = |d: &std::path::Path| Controller::load(d, None).err().unwrap().to_string();
    // no bundle there
    let e = err(&dir.0.join("nowhere"));
    assert!(
        e.contains("deploy.yaml") && e.contains("No such file"),
        "{e}"
    );
    // another format
    let other = dir.0.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(
        other.join("deploy.yaml"),
        dreampolicy::seal::seal_yaml(&text.replace("dreampolicy-deploy/1", "dreampolicy-deploy/9")),
    )
    .unwrap();
    let e = err(&other);
    assert!(e.contains("format") && e.contains("deploy/9"), "{e}");
    // a truncated policy file: one line, no C++ backtrace
    let cut = dir.0.join("cut");
    std::fs::create_dir_all(&cut).unwrap();
    std::fs::write(cut.join("deploy.yaml"), &text).unwrap();
    let policy = std::fs::read(bundle_dir.join("policy.pt")).unwrap();
    std::fs::write(cut.join("policy.pt"), &policy[..policy.len() / 3]).unwrap();
    let e = err(&cut);
    assert!(e.contains("policy.pt") && e.contains("corrupt"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
    // the CLI says so in one line and exits 1
    let out = Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
        .args(["deploy-sim", "--bundle"])
        .arg(&cut)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("policy.pt"), "{stderr}");
    assert!(stderr.lines().count() <= 3, "{stderr}");
}

#[test]
fn the_stock_mujoco_deployer_computes_the_policys_actions_and_walks() {
    let Some(py) = common::pyenv("mujoco, numpy, yaml") else {
        return;
    };
    let dir = Scratch::new("deploy-py");
    let bundle_dir = walker_bundle(&dir);
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/deploy_mujoco.py");
    // the NumPy actor against the TorchScript one on random inputs
    let module = tch::CModule::load(bundle_dir.join("policy.pt")).unwrap();
    tch::manual_seed(3);
    let mut cases = vec![];
    for _ in 0..4 {
        let obs = tch::Tensor::randn([1, 98], (tch::Kind::Float, tch::Device::Cpu));
        let hist = tch::Tensor::randn([1, 5, 98], (tch::Kind::Float, tch::Device::Cpu));
        let scan = tch::Tensor::randn([1, 187], (tch::Kind::Float, tch::Device::Cpu)) * 0.1;
        let act = module.forward_ts(&[&obs, &hist, &scan]).unwrap();
        let v = |t: &tch::Tensor| Vec::<f32>::try_from(t.contiguous().view([-1])).unwrap();
        let h = v(&hist);
        cases.push(serde_json::json!({
            "obs": v(&obs),
            "history": h.chunks(98).collect::<Vec<_>>(),
            "scan": v(&scan),
            "action": v(&act),
        }));
    }
    let case_file = dir.write("cases.json", &serde_json::to_string(&cases).unwrap());
    let deployer = |args: &[&str]| {
        run_ok(
            Command::new(&py)
                .arg(&script)
                .arg("--bundle")
                .arg(&bundle_dir)
                .args(args),
        )
    };
    let checked: serde_json::Value =
        serde_json::from_str(&deployer(&["--check-actions", case_file.to_str().unwrap()])).unwrap();
    assert_eq!(checked["cases"], 4);
    assert!(
        checked["max_abs_diff"].as_f64().unwrap() < 1e-4,
        "{checked}"
    );
    // and it walks 4 s on the plane with noisy observations
    let v: serde_json::Value =
        serde_json::from_str(&deployer(&["--seconds", "4", "--noise-seed", "0"])).unwrap();
    assert_eq!(v["fell"], false, "{v}");
    assert!(v["distance_m"].as_f64().unwrap() > 1.2, "{v}");
    assert_eq!(v["mujoco_version"], "3.3.7");
}
