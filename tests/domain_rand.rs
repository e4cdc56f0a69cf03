//! Domain randomization and commands do what the config says.
use dreampolicy::env::obs::OBS_DIM;
use dreampolicy::env::{Scene, VecEnv};
use dreampolicy::rl::config::ExperimentConfig;
use dreampolicy::robot::NUM_JOINTS;

mod common;

fn cfg(sets: &[&str]) -> ExperimentConfig {
    common::load_config("flat_small.yaml", sets)
}

#[test]
fn buckets_carry_friction_mass_and_motor_strength() {
    let nominal = Scene::build(&cfg(&["env.domain_rand.enabled=false"]).env).unwrap();
    let c = cfg(&[
        "env.domain_rand.model_buckets=4",
        "env.domain_rand.friction=[0.3, 0.4]",
        "env.domain_rand.added_mass=[2.0, 3.0]",
        "env.domain_rand.motor_strength=[0.8, 0.9]",
    ]);
    let scene = Scene::build(&c.env).unwrap();
    assert_eq!(scene.models.len(), 4);
    let g1 = &scene.g1;
    let nm = &nominal.models[0];
    let (ng, nb) = (mujoco_sys::mjNGAIN as usize, mujoco_sys::mjNBIAS as usize);
    for (m, b) in scene.models.iter().zip(&scene.buckets) {
        assert!((0.3..=0.4).contains(&b.friction));
        assert!((2.0..=3.0).contains(&b.added_mass));
        assert!((0.8..=0.9).contains(&b.motor_strength));
        assert!(m.geom_friction().iter().all(|f| f[0] == b.friction));
        let dm = m.body_mass()[g1.pelvis] - nm.body_mass()[g1.pelvis];
        assert!((dm - b.added_mass).abs() < 1e-12);
        // subtree masses were recomputed (mj_setConst)
        let dt = m.body_subtreemass()[g1.pelvis] - nm.body_subtreemass()[g1.pelvis];
        assert!((dt - b.added_mass).abs() < 1e-9);
        for &a in &g1.actuator {
            let kp = m.actuator_gainprm()[a * ng];
            assert!((kp - nm.actuator_gainprm()[a * ng] * b.motor_strength).abs() < 1e-9);
            let kd = m.actuator_biasprm()[a * nb + 2];
            assert!((kd - nm.actuator_biasprm()[a * nb + 2] * b.motor_strength).abs() < 1e-9);
        }
    }
    let distinct: std::collections::BTreeSet<u64> =
        scene.buckets.iter().map(|b| b.friction.to_bits()).collect();
    assert_eq!(distinct.len(), 4);

    // each env sees its bucket's parameters in the critic's privileged block
    let v = VecEnv::new(&c.env).unwrap();
    for (i, env) in v.envs().iter().enumerate() {
        let b = v.shared().scene.buckets[env.bucket()];
        let row = &v.critic[i * dreampolicy::env::obs::CRITIC_DIM..];
        assert_eq!(row[OBS_DIM + 10], b.friction as f32);
        assert_eq!(row[OBS_DIM + 11], b.added_mass as f32);
        assert_eq!(row[OBS_DIM + 12], b.motor_strength as f32);
    }
}

#[test]
fn action_latency_delays_the_targets() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.domain_rand.action_latency=[1, 1]",
        "env.domain_rand.push_interval_s=0",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    assert_eq!(v.envs()[0].latency(), 1);
    let g1 = v.shared().scene.g1.clone();
    let scale = c.env.control.action_scale;
    let a: Vec<f32> = (0..NUM_JOINTS).map(|j| 0.02 * j as f32).collect();
    v.step(&a);
    let ctrl = v.envs()[0].data().ctrl().to_vec();
    for j in 0..NUM_JOINTS {
        assert_eq!(
            ctrl[g1.actuator[j]], g1.default_pos[j],
            "first step applies the zero action"
        );
    }
    v.step(&[0.0; NUM_JOINTS]);
    let ctrl = v.envs()[0].data().ctrl().to_vec();
    for j in 0..NUM_JOINTS {
        let want = g1.default_pos[j] + scale * a[j] as f64;
        assert!((ctrl[g1.actuator[j]] - want).abs() < 1e-12, "joint {j}");
    }
}

#[test]
fn pushes_kick_the_pelvis_on_their_timer() {
    let base = [
        "env.n_envs=2",
        "env.seed=3",
        "env.domain_rand.max_push_vel=1.0",
    ];
    let pushed = cfg(&[&base[..], &["env.domain_rand.push_interval_s=0.04"]].concat());
    let calm = cfg(&[&base[..], &["env.domain_rand.push_interval_s=0"]].concat());
    let (mut p, mut q) = (
        VecEnv::new(&pushed.env).unwrap(),
        VecEnv::new(&calm.env).unwrap(),
    );
    let a = vec![0.0f32; 2 * NUM_JOINTS];
    p.step(&a);
    q.step(&a);
    let vel = |v: &VecEnv| v.envs()[0].data().qvel()[..2].to_vec();
    assert_eq!(
        vel(&p),
        vel(&q),
        "no push before the timer (2 control steps)"
    );
    p.step(&a);
    q.step(&a);
    let (vp, vq) = (vel(&p), vel(&q));
    let kick: Vec<f64> = vp.iter().zip(&vq).map(|(a, b)| a - b).collect();
    assert!(kick.iter().any(|k| k.abs() > 1e-3), "{kick:?}");
    assert!(kick.iter().all(|k| k.abs() <= 1.0 + 1e-9), "{kick:?}");
}

#[test]
fn commands_resample_on_their_timer_within_ranges() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.commands.resample_time_s=0.04",
        "env.commands.heading_command=false",
        "env.commands.lin_vel_x=[0.5, 1.0]",
        "env.commands.lin_vel_y=[-0.2, 0.2]",
        "env.commands.ang_vel_yaw=[-0.3, 0.3]",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let a = vec![0.0f32; NUM_JOINTS];
    let mut seen = Vec::new();
    for _ in 0..6 {
        v.step(&a);
        let cmd = v.envs()[0].state().command;
        assert!((0.5..=1.0).contains(&cmd[0]) && (-0.2..=0.2).contains(&cmd[1]));
        assert!((-0.3..=0.3).contains(&cmd[2]));
        seen.push(cmd);
    }
    // resampled at every second step (steps 2, 4, 6)
    assert_ne!(seen[0], seen[1]);
    assert_eq!(seen[1], seen[2]);
    assert_ne!(seen[2], seen[3]);
    assert_eq!(seen[3], seen[4]);
}

#[test]
fn heading_mode_steers_the_yaw_rate() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.commands.heading_command=true",
        "env.commands.heading=[1.0, 1.0]",
        "env.commands.heading_stiffness=0.5",
        "env.commands.ang_vel_yaw=[-1.0, 1.0]",
        "env.init.yaw=[0.0, 0.0]",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&[0.0; NUM_JOINTS]);
    let st = v.envs()[0].state();
    assert_eq!(st.heading_target, Some(1.0));
    let want = (0.5 * (1.0 - st.yaw)).clamp(-1.0, 1.0);
    assert!((st.command[2] - want).abs() < 1e-12);
}

/// Lane keeping (`commands.lane_lookahead`): the heading target turns towards
/// the centre line of the lane through the spawn point, by pure pursuit.
#[test]
fn lane_keeping_turns_the_heading_towards_the_lane() {
    use dreampolicy::env::locomotion::lane_correction;
    // 0.5 m left of the lane, 1 m lookahead: turn right by atan(0.5)
    assert!((lane_correction(0.5, 1.0) + 0.5f64.atan()).abs() < 1e-12);
    assert!((lane_correction(-0.2, 0.5) - 0.4f64.atan()).abs() < 1e-12);
    assert_eq!(lane_correction(0.0, 1.0), 0.0);
    let c = cfg(&[
        "env.n_envs=1",
        "env.commands.heading_command=true",
        "env.commands.heading=[0.4, 0.4]",
        "env.commands.heading_stiffness=0.5",
        "env.commands.ang_vel_yaw=[-1.0, 1.0]",
        "env.commands.lane_lookahead=0.5",
        "env.init.yaw=[0.0, 0.0]",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    for _ in 0..25 {
        v.step(&[0.0; NUM_JOINTS]);
    }
    let e = &v.envs()[0];
    let (st, spawn, h) = (e.state(), e.spawn(), 0.4f64);
    let (dx, dy) = (st.base_pos[0] - spawn[0], st.base_pos[1] - spawn[1]);
    let lateral = -dx * h.sin() + dy * h.cos();
    assert!(
        lateral.abs() > 1e-4,
        "the standing robot sways off its spawn point"
    );
    let target = st.heading_target.unwrap();
    assert!((target - (h + lane_correction(lateral, 0.5))).abs() < 1e-12);
    let want = (0.5 * (target - st.yaw)).clamp(-1.0, 1.0);
    assert!((st.command[2] - want).abs() < 1e-12);
    // a lookahead that is not positive is refused in one line
    let mut bad = c.env.clone();
    bad.commands.lane_lookahead = Some(0.0);
    let msg = bad.validate().unwrap_err().to_string();
    assert!(msg.contains("lane_lookahead"), "{msg}");
}
