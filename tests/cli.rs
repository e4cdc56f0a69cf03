//! The `dreampolicy` binary: info, bench sim, and its error messages.
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

fn json(args: &[&str]) -> serde_json::Value {
    let out = bin().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object on stdout")
}

#[test]
fn info_reports_versions_and_the_g1() {
    let v = json(&["info", "--json"]);
    assert_eq!(v["g1_nu"], 29);
    assert_eq!(v["g1_nq"], 36);
    assert_eq!(v["g1_nv"], 35);
    assert_eq!(v["timestep"], 0.005);
    let mj = v["mujoco_version"].as_str().unwrap();
    assert!(mj.starts_with("2.") || mj.starts_with("3."), "{mj}");
    assert!(v["libtorch_version"].as_str().unwrap().starts_with("2."));
    assert!(v["torch_device"].as_str().is_some());
}

#[test]
fn bench_sim_prints_the_named_keys() {
    let v = json(&["bench", "sim", "--json", "--steps", "200", "--rounds", "1"]);
    for key in ["raw_steps_per_s", "safe_steps_per_s", "ratio"] {
        assert!(v[key].as_f64().unwrap() > 0.0, "{key}");
    }
    assert!(v["mujoco_version"].is_string());
}

#[test]
fn missing_robot_description_says_to_run_setup() {
    let out = bin()
        .args(["info"])
        .env("DREAMPOLICY_MODELS_DIR", "/nonexistent/models")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("run scripts/setup.sh"), "{err}");
}

#[test]
fn rollout_writes_a_run_directory_whose_config_loads_back() {
    let dir = std::env::temp_dir().join(format!("dreampolicy-rollout-{}", std::process::id()));
    let out = bin()
        .args([
            "rollout",
            "--config",
            concat!(env!("CARGO_MANIFEST_DIR"), "/configs/terrain_small.yaml"),
            "--set",
            "env.n_envs=4",
            "--set",
            "env.episode_length_s=0.5",
            "--steps",
            "60",
            "--policy",
            "zero",
            "--quiet",
            "--json",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["steps"], 60);
    assert_eq!(v["n_envs"], 4);
    assert_eq!(v["blowups"], 0);
    assert_eq!(v["warnings"], 0);
    // 0.5 s episodes: 25 steps each, so every env finished at least two
    assert!(v["episodes"].as_u64().unwrap() >= 8, "{v}");
    let csv = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "step,reward_per_step,episodes,falls,blowups,mean_level"
    );
    assert_eq!(lines.len(), 1 + 2, "rows at steps 50 and 60");
    // the resolved config is complete and loads back as it was run
    let back = dreampolicy::rl::config::load(&dir.join("config.yaml"), &[]).unwrap();
    assert_eq!(back.env.n_envs, 4);
    assert_eq!(back.env.episode_length_s, 0.5);
    assert!(std::fs::read_to_string(dir.join("log.txt"))
        .unwrap()
        .contains("rollout Zero 60 steps"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn rollout_reports_a_bad_config_in_one_line() {
    let out = bin()
        .args(["rollout", "--config", "/no/such.yaml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("cannot read config /no/such.yaml"), "{err}");
}

#[test]
fn an_os_error_is_printed_once() {
    let out = bin()
        .args(["data", "inspect", "/nonexistent/dreampolicy-dataset"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/dreampolicy-dataset"), "{err}");
    assert_eq!(
        err.matches("No such file or directory").count(),
        1,
        "the cause once: {err}"
    );
}

#[test]
fn eval_then_walks_combined_lanes() {
    let walker = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/checkpoints/bridge/checkpoints/latest.pt");
    let v = json(&[
        "eval",
        "--checkpoint",
        walker.to_str().unwrap(),
        "--terrain",
        "bridge",
        "--then",
        "gap",
        "--episodes",
        "2",
        "--threads",
        "1",
        "--full-collision",
        "--json",
    ]);
    assert_eq!(v["terrain"], "bridge&gap", "{v}");
    assert_eq!(v["episodes"], 2);
    assert_eq!(v["level"], 0);
    // --then and a level sweep do not mix
    let out = bin()
        .args([
            "eval",
            "--checkpoint",
            walker.to_str().unwrap(),
            "--then",
            "gap",
            "--levels",
            "0-1",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--then"));
}
