//! The w/o-GCRL baseline (`train no-gcrl`): the controller executes exactly the
//! action slot of the world model's predicted next state, re-plans on its
//! schedule, and its controller checkpoint is run by `eval` (and refused by
//! what reads policies).
use dreampolicy::baselines::no_gcrl::{self, WmController};
use dreampolicy::env::obs::{LAST_ACTION, OBS_DIM, SCAN_DIM};
use dreampolicy::env::task::VecTask;
use dreampolicy::env::VecEnv;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::world_model::sampler::Noise;
use dreampolicy::world_model::WorldModel;
use tch::{Device, Kind, Tensor};

mod common;

fn cfg(sets: &[&str]) -> dreampolicy::rl::config::ExperimentConfig {
    common::load_config("test/no_gcrl_tiny.yaml", sets)
}

#[test]
fn the_controller_executes_the_action_slot_of_the_predicted_next_state() {
    let c = cfg(&[]);
    tch::set_num_threads(1);
    let mut env = VecEnv::new(&c.env).unwrap();
    let n = env.n_envs();
    let mut ctl = WmController::new(&c, n).unwrap();
    ctl.reset_all(&env);
    // the same prediction made apart: the same world model, noise seed and input
    let wm = WorldModel::load(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("models/checkpoints/world_model_expert/checkpoints/latest.pt")
            .as_path(),
        Device::Cpu,
    )
    .unwrap();
    let (k, h) = (wm.history(), wm.horizon());
    let mut hist = Vec::new();
    for i in 0..n {
        for _ in 0..k {
            hist.extend_from_slice(&env.obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
        }
    }
    let pred = wm
        .predict(
            &Tensor::from_slice(&hist).view([n as i64, k as i64, OBS_DIM as i64]),
            &Tensor::from_slice(&env.scan).view([n as i64, SCAN_DIM as i64]),
            &ctl.cfg.sampling,
            &mut Noise::new(ctl.cfg.seed),
        )
        .unwrap();
    let pred = Vec::<f32>::try_from(pred.to_kind(Kind::Float).flatten(0, -1)).unwrap();
    let actions = ctl.actions(&env);
    assert_eq!(ctl.predictions, n);
    let a = LAST_ACTION.len();
    for i in 0..n {
        let next = &pred[i * h * OBS_DIM..i * h * OBS_DIM + OBS_DIM];
        assert_eq!(
            ctl.predicted_next(i),
            next,
            "env {i}: the controller's prediction"
        );
        assert_eq!(&actions[i * a..(i + 1) * a], &next[LAST_ACTION], "env {i}");
        assert!(
            next[LAST_ACTION].iter().any(|&v| v != 0.0),
            "a real prediction"
        );
    }
    // the env executes them: its next state's last-action slot (no noise, no
    // clipping at these magnitudes) holds them
    env.step(&actions);
    ctl.after_step(&env);
    for i in 0..n {
        if env.outcomes[i].episode_done {
            continue;
        }
        let got = &env.obs[i * OBS_DIM..(i + 1) * OBS_DIM][LAST_ACTION];
        for (g, want) in got.iter().zip(&actions[i * a..(i + 1) * a]) {
            assert!(
                (g - want).abs() < 1e-6,
                "env {i}: executed {g}, predicted {want}"
            );
        }
    }
    // every step predicts anew (replan_every: 1)
    let _ = ctl.actions(&env);
    assert_eq!(ctl.predictions, 2 * n);
}

#[test]
fn between_predictions_the_plans_later_actions_run_in_order() {
    let c = cfg(&["no_gcrl.replan_every=2"]);
    tch::set_num_threads(1);
    let mut env = VecEnv::new(&c.env).unwrap();
    let n = env.n_envs();
    let mut ctl = WmController::new(&c, n).unwrap();
    ctl.reset_all(&env);
    let first = ctl.actions(&env);
    // the plan's second state, before it moves on
    let a = LAST_ACTION.len();
    env.step(&first);
    ctl.after_step(&env);
    let second_planned: Vec<Vec<f32>> = (0..n)
        .map(|i| ctl.predicted_next(i)[LAST_ACTION].to_vec())
        .collect();
    let second = ctl.actions(&env);
    assert_eq!(
        ctl.predictions, n,
        "no new prediction at the plan's second step"
    );
    for i in 0..n {
        if env.outcomes[i].episode_done {
            continue;
        }
        assert_eq!(&second[i * a..(i + 1) * a], second_planned[i].as_slice());
        assert_ne!(&second[i * a..(i + 1) * a], &first[i * a..(i + 1) * a]);
    }
    env.step(&second);
    ctl.after_step(&env);
    let _ = ctl.actions(&env);
    assert_eq!(ctl.predictions, 2 * n, "a new prediction every second step");
}

#[test]
fn eval_runs_the_controller_checkpoint_and_policy_readers_refuse_it() {
    let dir = common::Scratch::new("no-gcrl");
    let c = cfg(&[]);
    let meta = no_gcrl::train(&c, &dir.0).unwrap();
    assert_eq!((meta.iteration, meta.env_steps), (0, 0));
    assert!(dir.0.join("config.yaml").exists());
    let log = std::fs::read_to_string(dir.0.join("log.txt")).unwrap();
    assert!(log.contains("nothing to learn"), "{log}");
    let ck = Checkpoint::read(&dir.0.join("checkpoints/latest.pt")).unwrap();
    let r = dreampolicy::eval::evaluate(&ck, &common::flat_eval(2)).unwrap();
    assert_eq!(r.episodes, 2);
    assert!((0.0..=1.0).contains(&r.completion_rate));
    let cfg = ck.config().unwrap();
    let env = VecEnv::new(&cfg.env).unwrap();
    let mut agent = dreampolicy::rl::agent::Agent::new(&cfg.policy, env.dims(), env.n_envs(), true);
    let e = ck.load_agent(&mut agent).expect_err("no policy to load");
    assert!(e.to_string().contains("holds no policy"), "{e}");
    // a no_gcrl config is not trained by train specialist
    let e = dreampolicy::rl::runner::train(&c, &dir.0.join("x"), false, true)
        .err()
        .unwrap();
    assert!(e.to_string().contains("train no-gcrl"), "{e}");
}
