//! The G1's mirror maps (symmetry augmentation) against the physics: a robot
//! driven by mirrored actions from a symmetric start sees the mirror image of
//! what the original sees (while airborne: touchdown breaks exact symmetry).
mod common;

use common::load_config;
use dreampolicy::env::mirror::{joints, Mirror, SignedPerm};
use dreampolicy::env::obs::{OBS_DIM, PHASE};
use dreampolicy::env::VecEnv;
use dreampolicy::robot::NUM_JOINTS;
use rand::{Rng, SeedableRng};

fn apply(m: &SignedPerm, x: &[f32]) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    m.apply(x, &mut out);
    out
}

#[test]
fn mirroring_twice_is_the_identity() {
    let m = Mirror::g1();
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    for sp in [&m.obs, &m.critic, &m.scan, &m.action, &m.obs.tiled(4)] {
        let x: Vec<f32> = (0..sp.perm.len())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        assert_eq!(apply(sp, &apply(sp, &x)), x);
    }
    // left hip roll <-> right hip roll with a sign flip; knees swap as they are
    let j = joints();
    assert_eq!((j.perm[1], j.sign[1]), (7, -1.0));
    assert_eq!((j.perm[3], j.sign[3]), (9, 1.0));
    assert_eq!((j.perm[12], j.sign[12]), (12, -1.0)); // waist yaw
    assert_eq!((j.perm[14], j.sign[14]), (14, 1.0)); // waist pitch
}

#[test]
fn mirrored_actions_give_mirrored_observations() {
    let cfg = load_config(
        "test/g1_tiny.yaml",
        &[
            "env.n_envs=2",
            "env.init.joint_pos_noise=0.0",
            "env.domain_rand.enabled=false",
            "env.observation.add_noise=false",
            "env.commands.lin_vel_x=[0.0, 0.0]",
            "env.commands.lin_vel_y=[0.0, 0.0]",
            "env.commands.ang_vel_yaw=[0.0, 0.0]",
            "env.commands.heading_command=false",
            // dropped from 10 cm, the robot is in the air for the steps compared:
            // touchdown breaks the symmetry (the contact solver is not exactly
            // mirror-symmetric) and the difference then grows chaotically
            "env.init.height_offset=0.1",
        ],
    );
    let mut env = VecEnv::new(&cfg.env).unwrap();
    let m = Mirror::g1();
    // the default pose is its own mirror image
    let q0 = env.envs()[0].state().default_q.map(|q| q as f32);
    let mq0 = apply(&m.action, &q0);
    for i in 0..NUM_JOINTS {
        assert!((mq0[i] - q0[i]).abs() < 1e-6, "joint {i}");
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut worst = 0.0f32;
    for step in 0..6 {
        let a: Vec<f32> = (0..NUM_JOINTS)
            .map(|_| rng.random_range(-0.5..0.5))
            .collect();
        let mut both = a.clone();
        both.extend(apply(&m.action, &a));
        env.step(&both);
        assert!(env.outcomes.iter().all(|o| !o.episode_done), "step {step}");
        let (o0, o1) = (&env.obs[..OBS_DIM], &env.obs[OBS_DIM..2 * OBS_DIM]);
        let mo0 = apply(&m.obs, o0);
        for i in (0..OBS_DIM).filter(|i| !PHASE.contains(i)) {
            worst = worst.max((mo0[i] - o1[i]).abs());
            assert!(
                (mo0[i] - o1[i]).abs() < 2e-3,
                "step {step}, obs {i}: mirror of env 0 {} vs env 1 {}",
                mo0[i],
                o1[i]
            );
        }
        let c = dreampolicy::env::obs::CRITIC_DIM;
        let mc0 = apply(&m.critic, &env.critic[..c]);
        for i in (OBS_DIM..c).filter(|&i| i != OBS_DIM + 3) {
            assert!(
                (mc0[i] - env.critic[c + i]).abs() < 2e-3,
                "step {step}, critic {i}"
            );
        }
    }
    assert!(worst < 2e-3, "{worst}");
}
