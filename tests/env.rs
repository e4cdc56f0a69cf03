//! The locomotion env and VecEnv on a plane: layout, standing, determinism,
//! blow-up recovery, config errors.
use dreampolicy::env::obs::{self, CRITIC_DIM, OBS_DIM, SCAN_DIM};
use dreampolicy::env::VecEnv;
use dreampolicy::rl::config::ExperimentConfig;
use dreampolicy::robot::NUM_JOINTS;

mod common;

fn cfg(sets: &[&str]) -> ExperimentConfig {
    common::load_config("flat_small.yaml", sets)
}

#[test]
fn standing_env_survives_zero_actions() {
    let c = cfg(&[
        "env.n_envs=4",
        "env.domain_rand.enabled=false",
        "env.observation.add_noise=false",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let a = vec![0.0f32; 4 * NUM_JOINTS];
    for _ in 0..100 {
        let info = v.step(&a);
        assert_eq!(info.blowups, 0);
        assert_eq!(info.episodes_done, 0, "fell while standing");
    }
    assert_eq!(v.obs.len(), 4 * OBS_DIM);
    assert_eq!(v.critic.len(), 4 * CRITIC_DIM);
    assert_eq!(v.scan.len(), 4 * SCAN_DIM);
    // upright: projected gravity ~ (0, 0, -1); flat plane: scandots ~ -pelvis height
    let o = &v.obs[..OBS_DIM];
    assert!((o[obs::GRAVITY.start + 2] + 1.0).abs() < 0.02);
    let s = &v.scan[..SCAN_DIM];
    assert!(s.iter().all(|h| (-0.85..-0.65).contains(h)), "{s:?}");
}

fn rollout(c: &ExperimentConfig, steps: usize) -> (Vec<f32>, Vec<f32>, Vec<u8>) {
    let mut v = VecEnv::new(&c.env).unwrap();
    let n = v.n_envs();
    let mut rewards = Vec::new();
    let mut dones = Vec::new();
    for t in 0..steps {
        // a deterministic, env-dependent action pattern
        let a: Vec<f32> = (0..n * NUM_JOINTS)
            .map(|i| 0.3 * ((i * 7 + t * 13) % 17) as f32 / 17.0 - 0.15)
            .collect();
        v.step(&a);
        rewards.extend(v.outcomes.iter().map(|o| o.reward));
        dones.extend(v.outcomes.iter().map(|o| o.episode_done as u8));
    }
    let mut state = v.obs.clone();
    state.extend(&v.critic);
    state.extend(&v.scan);
    (state, rewards, dones)
}

#[test]
fn same_seed_same_trajectory_for_any_thread_count() {
    let a = cfg(&["env.n_envs=6", "env.threads=1", "env.seed=5"]);
    let b = cfg(&["env.n_envs=6", "env.threads=2", "env.seed=5"]);
    let c = cfg(&["env.n_envs=6", "env.threads=1", "env.seed=6"]);
    let ra = rollout(&a, 60);
    assert_eq!(
        ra,
        rollout(&a, 60),
        "same seed, same threads: bit-identical"
    );
    assert_eq!(
        ra,
        rollout(&b, 60),
        "1 and 2 threads: bit-identical (per-env RNG and state)"
    );
    assert_ne!(ra.0, rollout(&c, 60).0, "another seed differs");
}

#[test]
fn forced_blowup_resets_the_env_and_never_leaks_nan() {
    let c = cfg(&["env.n_envs=3", "env.domain_rand.enabled=false"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let a = vec![0.0f32; 3 * NUM_JOINTS];
    v.step(&a);
    let d = v.data_mut(1).unwrap();
    d.qvel_mut()[7] = f64::NAN;
    let info = v.step(&a);
    assert_eq!(info.blowups, 1);
    assert!(v.outcomes[1].blowup && v.outcomes[1].terminated && v.outcomes[1].episode_done);
    assert!(!v.outcomes[0].blowup && !v.outcomes[2].blowup);
    for buf in [
        &v.obs,
        &v.critic,
        &v.scan,
        &v.final_obs,
        &v.final_critic,
        &v.final_scan,
    ] {
        assert!(buf.iter().all(|x| x.is_finite()));
    }
    // the env runs on after its reset
    for _ in 0..10 {
        assert_eq!(v.step(&a).blowups, 0);
    }
    // a velocity bound below what standing needs is a blow-up every step, handled the same way
    let c = cfg(&[
        "env.n_envs=2",
        "env.sim.max_qvel=1e-9",
        "env.domain_rand.enabled=false",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let info = v.step(&vec![0.5f32; 2 * NUM_JOINTS]);
    assert_eq!(info.blowups, 2);
    assert!(v.obs.iter().all(|x| x.is_finite()));
}

#[test]
fn observation_layout_and_scales() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.domain_rand.enabled=false",
        "env.observation.add_noise=false",
        "env.commands.heading_command=false",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let a: Vec<f32> = (0..NUM_JOINTS).map(|j| 0.01 * j as f32).collect();
    v.step(&a);
    let st = v.envs()[0].state().clone();
    let o = &v.obs[..OBS_DIM];
    let sc = &c.env.observation.scales;
    for k in 0..3 {
        assert!((o[obs::ANG_VEL.start + k] as f64 - st.base_ang_vel[k] * sc.ang_vel).abs() < 1e-5);
        assert!((o[obs::GRAVITY.start + k] as f64 - st.gravity[k]).abs() < 1e-6);
        assert!((o[obs::COMMAND.start + k] as f64 - st.command[k] * sc.commands[k]).abs() < 1e-6);
    }
    for j in 0..NUM_JOINTS {
        let q = (st.q[j] - st.default_q[j]) * sc.dof_pos;
        assert!((o[obs::DOF_POS.start + j] as f64 - q).abs() < 1e-5);
        assert!((o[obs::DOF_VEL.start + j] as f64 - st.qd[j] * sc.dof_vel).abs() < 1e-5);
        assert_eq!(
            o[obs::LAST_ACTION.start + j],
            a[j],
            "last action = the action just applied"
        );
    }
    let (s, co) = (o[obs::PHASE.start], o[obs::PHASE.start + 1]);
    assert!((s * s + co * co - 1.0).abs() < 1e-5);
    // one control step of 0.02 s into a 0.8 s gait period
    assert!((s as f64 - (2.0 * std::f64::consts::PI * 0.02 / 0.8).sin()).abs() < 1e-5);
    // the critic starts with the noise-free state, then the privileged block
    assert_eq!(&v.critic[..OBS_DIM], o);
    assert!((v.critic[OBS_DIM + 3] as f64 - st.base_height).abs() < 1e-5);
    // after landing, the feet carry the robot's weight
    for _ in 0..20 {
        v.step(&[0.0; NUM_JOINTS]);
    }
    let weight_share = v.critic[OBS_DIM + 6] + v.critic[OBS_DIM + 9];
    assert!(
        (0.5..1.5).contains(&weight_share),
        "feet carry the robot: {weight_share}"
    );
    assert_eq!(
        v.critic[OBS_DIM + 10],
        1.0,
        "nominal friction without randomization"
    );
}

#[test]
fn noise_is_added_to_the_actor_only() {
    let c = cfg(&["env.n_envs=1", "env.domain_rand.enabled=false"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&[0.0; NUM_JOINTS]);
    let diff: f32 = v.obs[obs::DOF_VEL]
        .iter()
        .zip(&v.critic[obs::DOF_VEL])
        .map(|(a, b)| (a - b).abs())
        .sum();
    assert!(diff > 0.0);
    assert_eq!(v.obs[obs::LAST_ACTION], v.critic[obs::LAST_ACTION]);
}

#[test]
fn bad_configs_give_one_clear_message() {
    let base = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/flat_small.yaml"),
    )
    .unwrap();
    let err = |sets: &[&str]| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        dreampolicy::rl::config::from_str(&base, "flat_small.yaml", &sets)
            .unwrap_err()
            .to_string()
    };
    let m = err(&["env.rewards.terms.walk_nicely=1.0"]);
    assert!(
        m.contains("unknown reward term 'walk_nicely'") && m.contains("tracking_lin_vel"),
        "{m}"
    );
    let m = err(&["env.n_envs=-4"]);
    assert_eq!(m, "config: env.n_envs must be positive, got -4");
    let m = err(&["env.threads=0"]);
    assert_eq!(m, "config: env.threads must be positive, got 0");
    let m = err(&["env.sim.timestepp=0.01"]);
    assert!(m.contains("unknown field `timestepp`"), "{m}");
    let m = err(&["env.commands.lin_vel_x=[1.0, -1.0]"]);
    assert!(m.contains("lin_vel_x") && m.contains("lo <= hi"), "{m}");
    let m = err(&["env.terrain.mode=lava"]);
    assert!(m.contains("unknown variant `lava`"), "{m}");
    if mujoco_sys::MUJOCO_VERSION_HEADER < 300 {
        let m = err(&["env.sim.integrator=implicitfast"]);
        assert!(m.contains("implicitfast needs MuJoCo 3.x"), "{m}");
    } else {
        dreampolicy::rl::config::from_str(&base, "x", &["env.sim.integrator=implicitfast".into()])
            .unwrap();
    }
    let m = err(&["novalue"]);
    assert!(m.contains("expected key.path=value"), "{m}");
}
