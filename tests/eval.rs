//! Lane evaluation and TorchScript export on a checkpoint trained for two
//! iterations of the tiny G1 config, and the CLI's messages around them.
mod common;

use std::process::Command;

use common::{load_config, Scratch};
use dreampolicy::env::VecEnv;
use dreampolicy::eval::{evaluate, EvalOptions};
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::{runner, Agent, VecTask};
use dreampolicy::terrain::TerrainKind;

fn tiny_checkpoint(dir: &Scratch, sets: &[&str]) -> Checkpoint {
    let mut all = vec!["train.iterations=2"];
    all.extend_from_slice(sets);
    let cfg = load_config("test/g1_tiny.yaml", &all);
    let run = dir.0.join("run");
    let s = runner::train(&cfg, &run, false, true).unwrap();
    Checkpoint::read(&s.checkpoint).unwrap()
}

fn opts(episodes: usize) -> EvalOptions {
    EvalOptions {
        terrain: TerrainKind::Flat,
        then: None,
        episodes,
        full_collision: true,
        seed: 3,
        threads: 1,
        level: None,
        table: dreampolicy::eval::EvalTable::Eval,
        lane_lookahead: None,
    }
}

#[test]
fn eval_reports_what_ended_the_falls() {
    // a pelvis never 2 m above the ground: every walk falls on its first step,
    // by the base-height condition (of the training scene: the full-collision
    // scene has the default terminations)
    let dir = Scratch::new("eval-falls");
    let ck = tiny_checkpoint(
        &dir,
        &["env.termination.min_base_height=2.0", "eval.n_envs=3"],
    );
    let o = EvalOptions {
        full_collision: false,
        ..opts(5)
    };
    let r = evaluate(&ck, &o).unwrap();
    assert_eq!((r.episodes, r.falls), (5, 5));
    let c = r.fall_causes;
    assert_eq!(
        (c.base_height, c.tilt, c.contact, c.blowup),
        (5, 0, 0, 0),
        "{c:?}"
    );
    assert!(
        r.falls_mean_distance.abs() < 0.05,
        "{}",
        r.falls_mean_distance
    );
    assert!((0.5..=1.0).contains(&r.falls_mean_commanded_speed), "{r:?}");
    // a first-step fall happens where the walk spawned, on the lane's centre line
    assert!(
        r.falls_mean_abs_lateral_offset < 0.05,
        "{}",
        r.falls_mean_abs_lateral_offset
    );
    // no counted step before a first-step fall: no precursor, no full window
    let p = r.fall_precursors;
    assert!((p.window_s - 1.0).abs() < 1e-9);
    for row in [p.straddle, p.stumble, p.flight] {
        assert_eq!((row.before_fall, row.second_before_fall), (0.0, 0.0));
        assert!(row.any_window.is_nan());
    }
    // walks that do not fall: no causes, NaN fall means
    let dir2 = Scratch::new("eval-falls2");
    let ck = tiny_checkpoint(&dir2, &["eval.lane_length=0.001", "eval.n_envs=2"]);
    let r = evaluate(&ck, &opts(2)).unwrap();
    assert_eq!(r.fall_causes, dreampolicy::eval::FallCauses::default());
    assert!(r.falls_mean_distance.is_nan() && r.falls_mean_commanded_speed.is_nan());
    assert!(r.falls_mean_abs_lateral_offset.is_nan());
}

#[test]
fn eval_counts_successes_time_outs_and_completion() {
    let dir = Scratch::new("eval");
    // a 1 mm lane: every episode reaches the end line on its first step
    let ck = tiny_checkpoint(&dir, &["eval.lane_length=0.001", "eval.n_envs=3"]);
    let r = evaluate(&ck, &opts(7)).unwrap();
    assert_eq!(r.episodes, 7);
    assert_eq!(r.success_rate, 1.0);
    assert_eq!(r.completion_rate, 1.0);
    assert!(r.full_collision);
    // flat walks are on the plane: no lanes to name
    assert_eq!((r.lanes, r.per_lane.len()), (None, 0));

    // a 50 m lane in 0.5 s: nobody arrives; an untrained policy stands or falls
    let dir2 = Scratch::new("eval2");
    let ck = tiny_checkpoint(
        &dir2,
        &[
            "eval.lane_length=50",
            "eval.time_limit_s=0.5",
            "eval.n_envs=4",
        ],
    );
    let r = evaluate(&ck, &opts(6)).unwrap();
    assert_eq!(r.episodes, 6);
    assert_eq!(r.success_rate, 0.0);
    assert_eq!(r.falls + r.timeouts, 6);
    assert!(
        (0.0..0.05).contains(&r.completion_rate),
        "{}",
        r.completion_rate
    );
    assert!(r.vel_tracking_error.is_finite() && r.vel_tracking_error > 0.0);
    // yaw rates: the heading controller's command is clipped to +-1 rad/s,
    // and the mean |error| bounds the |mean error|
    assert!(r.yaw_rate_tracking_error.is_finite() && r.yaw_rate_tracking_error >= 0.0);
    assert!(r.mean_commanded_yaw_rate.abs() <= 1.0, "{r:?}");
    assert!(
        r.yaw_rate_tracking_error + 1e-9 >= (r.mean_commanded_yaw_rate - r.mean_yaw_rate).abs(),
        "{r:?}"
    );
    assert!(
        (0.5..=1.0).contains(&r.mean_commanded_speed),
        "{}",
        r.mean_commanded_speed
    );
    let json = serde_json::to_value(&r).unwrap();
    for key in [
        "success_rate",
        "completion_rate",
        "episodes",
        "vel_tracking_error",
        "yaw_rate_tracking_error",
        "mean_yaw_rate",
        "mean_commanded_yaw_rate",
    ] {
        assert!(json.get(key).is_some(), "{key}");
    }
}

#[test]
fn eval_measures_the_walkers_foot_clearance() {
    // the stepping foundation on two flat lanes (full collisions); the flat
    // walker shuffles with swings of about 5 control steps, at the bound of
    // what counts as a swing, so that on some machines none counted
    let ck = Checkpoint::read(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/checkpoints/foundation_sym/checkpoints/latest.pt"
    )))
    .unwrap();
    let r = evaluate(&ck, &opts(2)).unwrap();
    assert_eq!(r.success_rate, 1.0);
    // the ankle frame sits a few cm above the sole in stance, and every swing
    // lifts it higher (by about 10 cm for this policy)
    let (top, stance) = (r.swing_peak_height, r.stance_foot_height);
    assert!((0.01..0.06).contains(&stance), "stance {stance}");
    assert!(
        top > stance + 0.01 && top < 0.2,
        "swing top {top}, stance {stance}"
    );
    // on a plane the rise over the take-off point is the clearance over the ground
    let rise = r.swing_rise;
    assert!(
        (rise - (top - stance)).abs() < 0.01,
        "rise {rise}, top {top}, stance {stance}"
    );
    let json = serde_json::to_value(&r).unwrap();
    assert!(json["swing_peak_height"].as_f64().is_some());
}

#[test]
fn foot_clearance_over_a_gap_is_measured_against_the_platforms() {
    // before: over a pit the ground under the foot was the pit's floor, and the
    // walker's swing_peak_height read 0.8-0.97 m on gap lanes
    let ck = Checkpoint::read(&common::walker_path()).unwrap();
    let o = EvalOptions {
        terrain: TerrainKind::Gap,
        then: None,
        level: Some(0),
        table: dreampolicy::eval::EvalTable::Eval,
        ..opts(2)
    };
    let r = evaluate(&ck, &o).unwrap();
    let (top, stance, rise) = (r.swing_peak_height, r.stance_foot_height, r.swing_rise);
    assert!(top.is_nan() || top < 0.3, "swing top {top} over gaps");
    assert!(stance < 0.2, "stance {stance}");
    assert!(rise.is_nan() || rise < 0.3, "swing rise {rise}");
}

#[test]
fn level_list_parses() {
    use dreampolicy::eval::parse_levels;
    assert_eq!(parse_levels("0-9").unwrap(), (0..=9).collect::<Vec<_>>());
    assert_eq!(parse_levels("5,0,3-4,3").unwrap(), vec![0, 3, 4, 5]);
    for bad in ["", "a-3", "4-2", "1,x"] {
        let e = parse_levels(bad).unwrap_err();
        assert!(e.contains("--levels"), "{bad}: {e}");
    }
}

#[test]
fn eval_cli_sweeps_levels_into_a_json_and_a_plot() {
    let dir = Scratch::new("eval-sweep");
    // a 1 mm lane: every episode ends on its first step, at any level
    let ck = tiny_checkpoint(&dir, &["eval.lane_length=0.001", "eval.n_envs=2"]);
    let (json, png) = (dir.0.join("sweep.json"), dir.0.join("sweep.png"));
    let text = common::run_ok(
        bin()
            .args(["eval", "--checkpoint"])
            .arg(&ck.path)
            .args(["--terrain", "stair", "--levels", "0-2,9", "--episodes", "2"])
            .args(["--threads", "1", "--out"])
            .arg(&json)
            .arg("--plot")
            .arg(&png),
    );
    assert!(text.contains("stair level 9: success 1.000"), "{text}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["levels"], serde_json::json!([0, 1, 2, 9]));
    let curve = &v["curves"][0];
    assert_eq!(curve["terrain"], "stair");
    assert_eq!(
        curve["success_rate"],
        serde_json::json!([1.0, 1.0, 1.0, 1.0])
    );
    assert_eq!(curve["reports"][3]["level"], 9);
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);

    // flat lanes have no levels; two terrains for one checkpoint do not pair
    for (terrains, want) in [("flat", "flat lanes"), ("stair,gap", "one per checkpoint")] {
        let out = bin()
            .args(["eval", "--checkpoint"])
            .arg(&ck.path)
            .args(["--terrain", terrains, "--levels", "0-1", "--episodes", "1"])
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && e.contains(want), "{e}");
    }
}

/// `eval --set eval.KEY=VALUE` changes the evaluation protocol stored in the
/// checkpoint, says so in the report, and refuses any other key or a bad value.
#[test]
fn eval_cli_set_changes_the_protocol_and_nothing_else() {
    let dir = Scratch::new("eval-set");
    // a 1 mm lane: every episode reaches the end line on its first step
    let ck = tiny_checkpoint(&dir, &["eval.lane_length=0.001", "eval.n_envs=2"]);
    let report = |sets: &[&str]| -> serde_json::Value {
        let mut c = bin();
        c.args(["eval", "--checkpoint"]).arg(&ck.path);
        c.args([
            "--terrain",
            "uneven",
            "--episodes",
            "2",
            "--threads",
            "1",
            "--json",
        ]);
        for s in sets {
            c.args(["--set", s]);
        }
        let text = common::run_ok(&mut c);
        serde_json::from_str(text.lines().last().unwrap()).unwrap()
    };
    let plain = report(&[]);
    assert_eq!(plain["uneven_heights"], "isaac");
    assert_eq!(plain["hfield_contacts"], "surface");
    assert!(plain.get("eval_sets").is_none(), "{plain}");
    assert_eq!(plain["success_rate"], 1.0);
    let full = report(&["eval.terrain.uneven.heights=full"]);
    assert_eq!(full["uneven_heights"], "full");
    assert_eq!(
        full["eval_sets"],
        serde_json::json!(["eval.terrain.uneven.heights=full"])
    );
    let planes = report(&["eval.hfield_contacts=surface_planes"]);
    assert_eq!(planes["hfield_contacts"], "surface_planes");
    // a 100 m lane and a 0.1 s limit: every episode times out
    let long = report(&["eval.lane_length=100", "eval.time_limit_s=0.1"]);
    assert_eq!(long["success_rate"], 0.0);
    assert_eq!(long["timeouts"], 2);
    let path = ck.path.to_str().unwrap();
    for (set, want) in [
        ("env.n_envs=3", "only eval.* keys"),
        ("eval.terrain.uneven.heights=tall", "tall"),
        ("eval.hfield_contacts=boxes", "boxes"),
        ("eval.lane_length=-1", "lane_length"),
    ] {
        let e = stderr_of(&[
            "eval",
            "--checkpoint",
            path,
            "--terrain",
            "uneven",
            "--set",
            set,
        ]);
        assert!(e.contains(want) && e.lines().count() <= 2, "{set}: {e}");
    }
}

#[test]
fn exported_torchscript_gives_the_checkpoints_actions() {
    export_matches(&[]);
}

#[test]
fn exported_gru_policy_gives_the_checkpoints_actions() {
    export_matches(&["policy.history.kind=gru", "policy.history.gru_hidden=16"]);
}

fn export_matches(sets: &[&str]) {
    let dir = Scratch::new("export");
    let ck = tiny_checkpoint(&dir, sets);
    let out = dir.0.join("policy.pt");
    let info = dreampolicy::rl::export::export(&ck, &out).unwrap();
    assert_eq!(info.history_len, 3);
    let module = tch::CModule::load(&out).unwrap();

    let cfg = ck.config().unwrap();
    let mut env = VecEnv::new(&cfg.env).unwrap();
    let n = env.n_envs();
    let mut agent = Agent::new(&cfg.policy, env.dims(), n, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent).unwrap();
    agent.set_frozen(true);
    agent.reset_history(&env);
    let d = env.dims();
    for step in 0..6 {
        agent.prepare(&env);
        let ours = agent.act_mean();
        let obs = tch::Tensor::from_slice(env.obs()).view([n as i64, d.obs as i64]);
        let hist = tch::Tensor::from_slice(agent.history()).view([n as i64, 3, d.obs as i64]);
        let scan = tch::Tensor::from_slice(VecTask::scan(&env)).view([n as i64, d.scan as i64]);
        let theirs = module.forward_ts(&[obs, hist, scan]).unwrap();
        let theirs = Vec::<f32>::try_from(theirs.contiguous().view([-1])).unwrap();
        assert_eq!(theirs.len(), ours.len());
        let max = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(max < 1e-5, "step {step}: max difference {max}");
        env.step(&ours);
        agent.after_step(&env);
    }
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

fn stderr_of(args: &[&str]) -> String {
    let out = bin().args(args).output().unwrap();
    assert!(!out.status.success(), "expected a failure for {args:?}");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn cli_errors_name_the_problem() {
    let dir = Scratch::new("cli-eval");
    let missing = dir.0.join("nothing.pt");
    let e = stderr_of(&["eval", "--checkpoint", missing.to_str().unwrap()]);
    assert!(
        e.contains("nothing.pt") && e.contains("no such file"),
        "{e}"
    );
    let e = stderr_of(&["train", "specialist", "--resume", dir.0.to_str().unwrap()]);
    assert!(e.contains("config.yaml"), "{e}");
    let e = stderr_of(&[
        "eval",
        "--checkpoint",
        missing.to_str().unwrap(),
        "--terrain",
        "lava",
    ]);
    assert!(e.contains("lava"), "{e}");
    // a second training run into the same directory is refused
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/test/cartpole.yaml");
    let run = dir.0.join("run");
    let args = [
        "train",
        "specialist",
        "--quiet",
        "--set",
        "train.iterations=1",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ];
    assert!(bin().args(args).output().unwrap().status.success());
    let e = stderr_of(&args);
    assert!(
        e.contains("already holds a run") && e.contains("--resume"),
        "{e}"
    );
}

#[test]
fn the_agent_history_holds_the_last_states() {
    let cfg = load_config("test/g1_tiny.yaml", &["env.n_envs=2"]);
    let mut env = VecEnv::new(&cfg.env).unwrap();
    let mut agent = Agent::new(&cfg.policy, env.dims(), 2, true);
    agent.reset_history(&env);
    let d = env.dims().obs;
    let k = agent.policy.history_len();
    let mut seen: Vec<Vec<f32>> = vec![env.obs.clone()];
    for _ in 0..5 {
        agent.step_mean(&mut env);
        assert!(env.outcomes.iter().all(|o| !o.episode_done));
        seen.push(env.obs.clone());
    }
    // after 5 steps the history is the states of steps 2, 3, 4 (oldest first)
    for i in 0..2 {
        for j in 0..k {
            let h = &agent.history()[(i * k + j) * d..(i * k + j + 1) * d];
            assert_eq!(h, &seen[5 - k + j][i * d..(i + 1) * d], "env {i}, slot {j}");
        }
    }
}

#[test]
fn terrain_lanes_are_walked_and_episodes_spread_over_lanes() {
    let dir = Scratch::new("eval-lanes");
    // a 1 mm lane: every episode ends on its first step, on any terrain
    let ck = tiny_checkpoint(
        &dir,
        &[
            "eval.lane_length=0.001",
            "eval.n_envs=3",
            "eval.lanes=2",
            "env.terrain.map.num_levels=3",
        ],
    );
    let o = EvalOptions {
        terrain: TerrainKind::Stair,
        then: None,
        ..opts(5)
    };
    let r = evaluate(&ck, &o).unwrap();
    assert_eq!((r.episodes, r.success_rate), (5, 1.0));
    assert_eq!(r.level, Some(5));
    assert_eq!(r.terrain, "stair");
    // the report names the lanes and what each gave: 5 walks over 2 lanes
    // (seeds `seed` and `seed + 1`), 3 on the first, 2 on the second
    assert_eq!(r.lanes, Some(2));
    let lanes: Vec<_> = r
        .per_lane
        .iter()
        .map(|l| (l.seed, l.episodes, l.successes, l.completion))
        .collect();
    assert_eq!(lanes, [(3, 3, 3, 1.0), (4, 2, 2, 1.0)]);
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["per_lane"][1]["episodes"], 2);
    // `--level` overrides eval.level; a level the table lacks is refused
    let r = evaluate(
        &ck,
        &EvalOptions {
            level: Some(0),
            ..o.clone()
        },
    )
    .unwrap();
    assert_eq!(r.level, Some(0));
    let e = evaluate(
        &ck,
        &EvalOptions {
            level: Some(10),
            ..o.clone()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("level 10") && e.contains("top level 9"), "{e}");
    assert_eq!(r.table, Some(dreampolicy::eval::EvalTable::Eval));
    // `--table training`: the lanes of the checkpoint's own curriculum (3 levels)
    let training = EvalOptions {
        table: dreampolicy::eval::EvalTable::Training,
        ..o.clone()
    };
    let e = evaluate(&ck, &training).unwrap_err().to_string();
    assert!(
        e.contains("level 5")
            && e.contains("the training curriculum's table")
            && e.contains("top level 2"),
        "{e}"
    );
    let r = evaluate(
        &ck,
        &EvalOptions {
            level: Some(2),
            ..training
        },
    )
    .unwrap();
    assert_eq!(
        (r.level, r.table),
        (Some(2), Some(dreampolicy::eval::EvalTable::Training))
    );
    assert_eq!(r.episodes, 5);

    // 50 m in 0.5 s on uneven ground: every episode is counted once, none succeeds
    let dir2 = Scratch::new("eval-lanes2");
    let ck = tiny_checkpoint(
        &dir2,
        &[
            "eval.lane_length=50",
            "eval.time_limit_s=0.5",
            "eval.n_envs=2",
            "eval.lanes=3",
        ],
    );
    let o = EvalOptions {
        terrain: TerrainKind::Uneven,
        then: None,
        ..opts(4)
    };
    let r = evaluate(&ck, &o).unwrap();
    assert_eq!(r.episodes, 4);
    assert_eq!(r.success_rate, 0.0);
    assert_eq!(r.falls + r.timeouts, 4);
    assert!(
        (0.0..0.05).contains(&r.completion_rate),
        "{}",
        r.completion_rate
    );
    // lane keeping is the evaluation's choice, not the training config's: the
    // report says which steering scored it
    assert_eq!(r.lane_lookahead, None);
    let mut cfg = ck.config().unwrap();
    cfg.env.commands.lane_lookahead = Some(0.7);
    let keep = EvalOptions {
        lane_lookahead: Some(1.0),
        ..o.clone()
    };
    use dreampolicy::eval::eval_env_config;
    assert_eq!(eval_env_config(&cfg, &o).commands.lane_lookahead, None);
    assert_eq!(
        eval_env_config(&cfg, &keep).commands.lane_lookahead,
        Some(1.0)
    );
    let r = evaluate(&ck, &keep).unwrap();
    assert_eq!((r.episodes, r.lane_lookahead), (4, Some(1.0)));

    // a level the lanes' terrain table does not have is a clear config error
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/test/g1_tiny.yaml");
    let e = dreampolicy::rl::config::load(&path, &["eval.level=12".to_string()])
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("eval.level 12") && e.contains("top level 9"),
        "{e}"
    );
}

#[test]
fn eval_cli_prints_the_cross_terrain_matrix_and_heatmap() {
    let dir = Scratch::new("eval-matrix");
    let a = tiny_checkpoint(&dir, &["eval.lane_length=0.001", "eval.n_envs=2"]);
    let dir2 = Scratch::new("eval-matrix2");
    let b = tiny_checkpoint(
        &dir2,
        &[
            "eval.lane_length=50",
            "eval.time_limit_s=0.3",
            "eval.n_envs=2",
        ],
    );
    let png = dir.0.join("matrix.png");
    let list = format!("{},{}", a.path.display(), b.path.display());
    let out = bin()
        .args([
            "eval",
            "--checkpoint",
            &list,
            "--terrains",
            "flat,gap",
            "--episodes",
            "2",
        ])
        .args([
            "--threads",
            "1",
            "--json",
            "--heatmap",
            png.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["terrains"], serde_json::json!(["flat", "gap"]));
    assert_eq!(v["checkpoints"].as_array().unwrap().len(), 2);
    assert_eq!(
        v["success_rate"],
        serde_json::json!([[1.0, 1.0], [0.0, 0.0]])
    );
    assert_eq!(v["reports"][1][1]["level"], 5);
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
}

#[test]
fn a_specialist_takes_no_inference_keys_and_is_no_world_model() {
    // the unified policy's inference keys (world model, sampler, re-planning)
    // mean nothing to a policy that reads no plan
    let mut ck = Checkpoint::read(&common::walker_path()).unwrap();
    let e = ck
        .set_eval(&["unified.sampling.guidance=5".into()])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("only eval.* keys") && !e.contains("inference"),
        "{e}"
    );
    ck.set_eval(&["eval.time_limit_s=40".into()]).unwrap();
    assert_eq!(ck.config().unwrap().eval.time_limit_s, 40.0);
    // a policy checkpoint given where a world model is read says what it is
    let e = match dreampolicy::world_model::WmCheckpoint::read(&common::walker_path()) {
        Ok(_) => panic!("a policy checkpoint read as a world model"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("this is a policy checkpoint"), "{e}");
}

/// `eval.sample_actions` walks on actions sampled from the policy's Gaussian,
/// as training acts: the same seed gives the same walks, and they are not the
/// mean's.
#[test]
fn sampled_actions_are_seeded_and_are_not_the_mean() {
    let run = |sets: &[&str]| {
        let mut ck = Checkpoint::read(&common::walker_path()).unwrap();
        let mut all = vec!["eval.lane_length=1.5".to_string(), "eval.n_envs=2".into()];
        all.extend(sets.iter().map(|s| s.to_string()));
        ck.set_eval(&all).unwrap();
        evaluate(&ck, &opts(2)).unwrap()
    };
    let mean = run(&[]);
    let a = run(&["eval.sample_actions=true"]);
    let b = run(&["eval.sample_actions=true"]);
    assert_eq!(a.vel_tracking_error, b.vel_tracking_error);
    assert_eq!(a.completion_rate, b.completion_rate);
    assert_ne!(a.vel_tracking_error, mean.vel_tracking_error);
    let mut other = Checkpoint::read(&common::walker_path()).unwrap();
    other
        .set_eval(&[
            "eval.lane_length=1.5".into(),
            "eval.n_envs=2".into(),
            "eval.sample_actions=true".into(),
        ])
        .unwrap();
    let c = evaluate(&other, &EvalOptions { seed: 4, ..opts(2) }).unwrap();
    assert_ne!(c.vel_tracking_error, a.vel_tracking_error);
}
