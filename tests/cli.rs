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
