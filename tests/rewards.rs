//! Reward terms by hand on known states, the weighted sum, and the curriculum rule.
use std::collections::BTreeMap;

use dreampolicy::env::locomotion::next_level;
use dreampolicy::env::rewards::{lookup, names, RewardSet};
use dreampolicy::env::rewards::{RewardConfig, RewardParams};
use dreampolicy::env::EnvState;
use dreampolicy::robot::NUM_JOINTS;
use rand::SeedableRng;

fn state() -> EnvState {
    let mut s = EnvState::new(0.02, [0.1; NUM_JOINTS], [[-1.0, 1.0]; NUM_JOINTS]);
    s.base_pos = [1.0, 2.0, 0.8];
    s.base_height = 0.75;
    s
}

fn term(name: &str, s: &EnvState) -> f64 {
    (lookup(name).unwrap().f)(s, &RewardParams::default())
}

fn close(a: f64, b: f64) {
    assert!((a - b).abs() < 1e-9, "{a} != {b}");
}

#[test]
fn base_table_terms_by_hand() {
    let mut s = state();
    s.gravity = [0.1, -0.2, -0.97];
    close(term("orientation", &s), 0.05);
    s.qd[3] = 1.0;
    s.last_qd[3] = 0.8;
    close(term("dof_acc", &s), (0.2f64 / 0.02).powi(2));
    s.action[0] = 0.3;
    s.last_action[0] = 0.1;
    s.action[1] = -0.4;
    close(
        term("action_rate", &s),
        (0.2f64.powi(2) + 0.4f64.powi(2)).sqrt(),
    );
    s.last_last_action[0] = 0.2; // second difference: 0.3 - 0.2 + 0.2 = 0.3; -0.4 on joint 1
    let second = (0.3f64.powi(2) + 0.4f64.powi(2)).sqrt();
    close(
        term("smoothness", &s),
        (0.2f64.powi(2) + 0.4f64.powi(2)).sqrt() + second,
    );
    s.torque[2] = 3.0;
    s.last_torque[2] = 1.0;
    close(term("torques", &s), 9.0);
    close(term("delta_torques", &s), 4.0);
    s.q[5] = 0.4; // default 0.1
    close(term("dof_error", &s), 0.09);
    close(term("base_height", &s), (0.75f64 - 0.78).powi(2));
    s.base_lin_vel = [0.3, 0.1, -0.5];
    s.base_ang_vel = [0.2, -0.1, 0.7];
    close(term("lin_vel_z", &s), 0.25);
    close(term("ang_vel_xy", &s), 0.05);
    close(term("alive", &s), 1.0);
    s.collisions = 2;
    close(term("collision", &s), 2.0);
    s.yaw = 0.2;
    s.heading_target = Some(0.7);
    close(term("tracking_yaw", &s), (-0.25f64 / 0.25).exp());
    // heading across +-pi wraps
    s.yaw = 3.1;
    s.heading_target = Some(-3.1);
    let d = 2.0 * std::f64::consts::PI - 6.2;
    close(term("tracking_yaw", &s), (-d * d / 0.25).exp());
}

#[test]
fn specialist_terms_by_hand() {
    let mut s = state();
    s.command = [1.0, 0.0, 0.0];
    s.base_lin_vel = [2.0, 0.0, 0.0];
    close(term("tracking_goal_vel", &s), 1.0);
    s.base_lin_vel = [0.5, 0.5, 0.0];
    close(term("tracking_goal_vel", &s), 0.5);
    close(
        term("tracking_lin_vel", &s),
        (-(0.25f64 + 0.25) / 0.25).exp(),
    );
    s.q[1] = 0.3; // hip roll (default 0.1)
    s.q[8] = -0.1; // right hip yaw
    close(term("hip_pos", &s), 0.04 + 0.04);
    s.feet_force = [[0.0, 0.0, 100.0], [50.0, 0.0, 10.0]];
    close(term("feet_stumble", &s), 1.0);
    s.feet_force[1] = [30.0, 0.0, 10.0];
    close(term("feet_stumble", &s), 0.0);
    // feet in the heading frame (yaw 0): left ahead by 0.3 m and 0.25 m to the left
    s.feet_pos = [[1.2, 2.15, 0.05], [0.9, 1.9, 0.0]];
    close(term("huge_step", &s), 0.3);
    close(term("feet_dis", &s), (0.25f64 - 0.22).powi(2));
    s.knees_pos = [[1.1, 2.1, 0.4], [1.0, 1.92, 0.4]];
    close(term("knee_dis", &s), (0.18f64 - 0.22).powi(2));
    close(term("knee_foot", &s), 0.05f64.powi(2) + 0.02f64.powi(2));
    s.feet_rpy = [[0.0, 0.2, 0.1], [0.0, -0.1, -0.3]];
    close(term("feet_parallel", &s), 0.05);
    close(term("feet_yaw", &s), 0.01 + 0.09);
    // swing foot height, clipped at the clearance target (0.08)
    s.feet_contact = [false, true];
    s.feet_swing_ground = [0.0, 0.0];
    close(term("foot_height", &s), 0.05);
    s.feet_pos[0][2] = 0.3;
    close(term("foot_height", &s), 0.08);
    // touchdown after 0.7 s in the air, target 0.5
    s.feet_first_contact = [true, false];
    s.feet_touchdown_air_time = [0.7, 0.0];
    close(term("feet_air_time", &s), 0.2);
    s.command = [0.0, 0.0, 0.5];
    close(term("feet_air_time", &s), 0.0);
    // edges count only in contact and from the configured level on
    s.feet_on_edge = [true, true];
    s.feet_contact = [true, false];
    s.terrain_level = 2;
    close(term("feet_edge", &s), 0.0);
    s.terrain_level = 4;
    close(term("feet_edge", &s), 1.0);
    // feet over a pit count in contact only, at every level
    s.feet_over_pit = [true, true];
    s.terrain_level = 0;
    close(term("feet_gap", &s), 1.0);
    s.feet_over_pit = [false, true];
    close(term("feet_gap", &s), 0.0);
    s.feet_straddle = [true, false];
    close(term("feet_straddle", &s), 1.0);
    s.feet_contact = [false, true];
    close(term("feet_straddle", &s), 0.0);
    // a flight: neither foot on the ground
    close(term("feet_flight", &s), 0.0);
    s.feet_contact = [false, false];
    close(term("feet_flight", &s), 1.0);
    s.feet_contact = [true, true];
    close(term("feet_flight", &s), 0.0);
    s.reached_goal = true;
    close(term("goal", &s), 1.0);
    s.terminated = true;
    close(term("termination", &s), 1.0);
    s.q[0] = 0.95; // range [-1, 1]: soft limit at 0.9
    close(term("dof_pos_limits", &s), 0.05);
}

/// The unified policy's energy, safety-limit and feet-slide terms (the paper's
/// unified reward table).
#[test]
fn unified_table_terms_by_hand() {
    let mut s = state();
    // no limits known: the limit terms have nothing to measure
    s.qd[0] = 50.0;
    s.torque[0] = 100.0;
    close(term("energy", &s), 0.0);
    close(term("dof_vel_limits", &s), 0.0);
    close(term("torque_limits", &s), 0.0);
    s.qd_limit = [10.0; NUM_JOINTS];
    s.tau_limit = [50.0; NUM_JOINTS];
    s.qd = [0.0; NUM_JOINTS];
    s.torque = [0.0; NUM_JOINTS];
    // joint 0: 12 rad/s against 0.9 x 10; joint 1: 8 rad/s, within
    s.qd[0] = 12.0;
    s.qd[1] = -8.0;
    close(term("dof_vel_limits", &s), 3.0);
    // joint 2: 45 N m against 0.8 x 50; joint 3: -30 N m, within
    s.torque[2] = 45.0;
    s.torque[3] = -30.0;
    close(term("torque_limits", &s), 25.0);
    // power over the effort limit, squared: joints 0-3 move and push
    s.torque[0] = 10.0;
    s.torque[1] = 5.0;
    s.qd[2] = 2.0;
    s.qd[3] = 1.0;
    let want = (10.0f64 * 12.0 / 50.0).powi(2)
        + (5.0f64 * -8.0 / 50.0).powi(2)
        + (45.0f64 * 2.0 / 50.0).powi(2)
        + (-30.0f64 * 1.0 / 50.0).powi(2);
    close(term("energy", &s), want);
    // feet slide: the planar speed of a foot in contact, not squared, z left out
    s.feet_vel = [[0.3, 0.4, 2.0], [1.0, 0.0, 0.0]];
    s.feet_contact = [true, false];
    close(term("feet_slide", &s), 0.5);
    s.feet_contact = [true, true];
    close(term("feet_slide", &s), 1.5);
}

#[test]
fn weighted_sum_uses_dt_and_keeps_episode_sums() {
    let mut terms = BTreeMap::new();
    terms.insert("alive".to_string(), 2.0);
    terms.insert("orientation".to_string(), -10.0);
    let cfg = RewardConfig {
        terms,
        params: RewardParams::default(),
        only_positive: false,
        penalty_curriculum: None,
    };
    let set = RewardSet::new(&cfg).unwrap();
    assert_eq!(set.names(), vec!["alive", "orientation"]);
    let mut s = state();
    s.gravity = [0.3, 0.0, -0.95];
    let mut sums = vec![0.0; 2];
    let r = set.compute(&s, &mut sums);
    close(r, (2.0 - 10.0 * 0.09) * 0.02);
    set.compute(&s, &mut sums);
    close(sums[0], 2.0 * 2.0 * 0.02);
    close(sums[1], -2.0 * 0.9 * 0.02);
    let clipped = RewardSet::new(&RewardConfig {
        only_positive: true,
        ..cfg.clone()
    })
    .unwrap();
    s.gravity = [1.0, 0.0, 0.0];
    close(clipped.compute(&s, &mut sums), 0.0);
    // the penalty curriculum scales negative weights only
    let mut scaled = RewardSet::new(&cfg).unwrap();
    scaled.penalty_scale = 0.25;
    s.gravity = [0.3, 0.0, -0.95];
    close(
        scaled.compute(&s, &mut sums),
        (2.0 - 0.25 * 10.0 * 0.09) * 0.02,
    );

    let mut bad = cfg;
    bad.terms.insert("fly".into(), 1.0);
    let e = RewardSet::new(&bad).err().unwrap();
    assert!(e.contains("'fly'") && e.contains("orientation"));
}

#[test]
fn every_paper_term_is_registered() {
    let base = [
        "orientation",
        "dof_acc",
        "collision",
        "action_rate",
        "delta_torques",
        "torques",
        "dof_error",
        "base_height",
        "smoothness",
        "alive",
        "tracking_yaw",
        "lin_vel_z",
        "ang_vel_xy",
    ];
    let special = [
        "tracking_goal_vel",
        "hip_pos",
        "feet_stumble",
        "feet_edge",
        "feet_parallel",
        "huge_step",
        "feet_yaw",
        "feet_dis",
        "knee_dis",
        "goal",
        "knee_foot",
        "foot_height",
        "feet_air_time",
    ];
    let all = names();
    for n in base.iter().chain(&special) {
        assert!(all.contains(n), "{n} missing");
    }
}

#[test]
fn curriculum_moves_levels() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    assert_eq!(next_level(3, true, false, 10, &mut rng), 4);
    assert_eq!(next_level(3, false, true, 10, &mut rng), 2);
    assert_eq!(next_level(0, false, true, 10, &mut rng), 0);
    assert_eq!(next_level(3, false, false, 10, &mut rng), 3);
    // past the top: a random level, all of them reachable
    let seen: std::collections::BTreeSet<usize> = (0..500)
        .map(|_| next_level(9, true, false, 10, &mut rng))
        .collect();
    assert_eq!(seen.len(), 10);
}

/// The peers' foot-lifting terms (issue 16's stepping foundation), by hand.
#[test]
fn foot_lifting_terms_by_hand() {
    let p = RewardParams::default();
    let mut s = state();
    s.command = [0.8, 0.0, 0.0];
    // biped air time: exactly one foot down; the shorter of the two mode times, capped
    s.feet_contact = [true, false];
    s.feet_contact_time = [0.25, 0.0];
    s.feet_air_time = [0.0, 0.15];
    close(term("feet_air_time_biped", &s), 0.15);
    s.feet_air_time = [0.0, 0.9];
    close(term("feet_air_time_biped", &s), 0.25);
    s.feet_contact_time = [0.9, 0.0];
    close(term("feet_air_time_biped", &s), p.feet_air_time_threshold);
    s.feet_contact = [true, true];
    close(term("feet_air_time_biped", &s), 0.0);
    s.feet_contact = [false, true];
    s.command = [0.05, 0.0, 0.0];
    close(term("feet_air_time_biped", &s), 0.0);

    // velocity-weighted clearance: a still foot costs nothing at any height
    s.feet_swing_ground = [0.1, 0.1];
    s.feet_pos = [[0.0, 0.1, 0.136], [0.0, -0.1, 0.13]];
    s.feet_vel = [[0.0; 3], [0.0; 3]];
    close(term("foot_clearance", &s), 1.0);
    s.feet_vel[1] = [1.0, 0.0, 0.5];
    let err = 2f64.tanh() * (0.03f64 - p.foot_clearance_target).powi(2);
    close(term("foot_clearance", &s), (-err / p.clearance_sigma).exp());
    s.feet_pos[1][2] = 0.1 + p.foot_clearance_target;
    close(term("foot_clearance", &s), 1.0);

    // clock target: zero in the clock's stance, a sine over the swing
    let (r, h, a) = (
        p.gait_stance_ratio,
        p.swing_clock_height,
        p.ankle_stance_height,
    );
    use dreampolicy::env::rewards::swing_clock_target;
    assert_eq!(swing_clock_target(0.1, 0, &p), None);
    let mid = r + (1.0 - r) / 2.0;
    close(swing_clock_target(mid, 0, &p).unwrap(), a + h);
    close(swing_clock_target(r, 0, &p).unwrap(), a);
    // the right leg is half a period later
    close(swing_clock_target(mid - 0.5, 1, &p).unwrap(), a + h);
    s.gait_phase = mid;
    s.feet_swing_ground = [0.0, 0.0];
    s.feet_pos[0][2] = a; // left foot kept down in its swing: pays h^2
    s.feet_pos[1][2] = a; // right leg in stance by the clock: free
    s.feet_contact = [true, true];
    close(term("feet_swing_clock", &s), h * h);
    s.feet_pos[0][2] = a + h;
    close(term("feet_swing_clock", &s), 0.0);

    // reference joint trajectory: 1 at the reference, the default pose in the clock's stance
    use dreampolicy::env::rewards::reference_leg_pose;
    s.gait_phase = 0.1; // left leg in stance (phase 0.1), right in swing (0.6)
    let q_ref = reference_leg_pose(&s, &p);
    assert_eq!(&q_ref[..6], &s.default_q[..6]);
    assert!(q_ref[9] > s.default_q[9] && q_ref[6] < s.default_q[6] && q_ref[10] < s.default_q[10]);
    close(
        q_ref[6] + q_ref[9] + q_ref[10],
        s.default_q[6] + s.default_q[9] + s.default_q[10],
    );
    s.q[..12].copy_from_slice(&q_ref);
    close(term("ref_joint_pos", &s), 1.0);
    s.q[3] += 0.3;
    close(term("ref_joint_pos", &s), (-0.6f64).exp() - 0.06);

    // a narrowed stance: hip roll in (left -r, right +r), ankle roll back, and
    // hip_pos measured against the same reference
    let narrow = RewardParams {
        ref_stance_roll: 0.06,
        ..p.clone()
    };
    let q_n = reference_leg_pose(&s, &narrow);
    let q_w = reference_leg_pose(&s, &p);
    let diff: Vec<f64> = q_n.iter().zip(&q_w).map(|(a, b)| a - b).collect();
    let mut want = [0.0; 12];
    (want[1], want[5], want[7], want[11]) = (-0.06, 0.06, 0.06, -0.06);
    for (d, w) in diff.iter().zip(want) {
        close(*d, w);
    }
    s.q[..12].copy_from_slice(&q_n);
    let hip = |s: &EnvState, p: &RewardParams| (lookup("hip_pos").unwrap().f)(s, p);
    close(hip(&s, &narrow), 0.0);
    close(hip(&s, &p), 2.0 * 0.06 * 0.06);
    close((lookup("ref_joint_pos").unwrap().f)(&s, &narrow), 1.0);
    s.q[..12].copy_from_slice(&q_w);
    s.q[3] += 0.3;
    s.q[3] += 1.0;
    close(term("ref_joint_pos", &s), (-2.6f64).exp() - 0.1);

    // a turn's hip yaw: counted by default, left out with ref_free_hip_yaw
    s.q[..12].copy_from_slice(&q_w);
    s.q[2] += 0.3; // left hip yaw
    s.q[8] -= 0.4; // right hip yaw
    close(term("ref_joint_pos", &s), (-1.0f64).exp() - 0.1);
    let free_yaw = RewardParams {
        ref_free_hip_yaw: true,
        ..p.clone()
    };
    let ref_term = |s: &EnvState, p: &RewardParams| (lookup("ref_joint_pos").unwrap().f)(s, p);
    close(ref_term(&s, &free_yaw), 1.0);
    s.q[3] += 0.3; // the knee still counts
    close(ref_term(&s, &free_yaw), (-0.6f64).exp() - 0.06);

    // standing still while commanded to move
    s.command = [0.8, 0.0, 0.0];
    s.base_lin_vel = [0.1, 0.0, 0.0];
    close(term("stand_still", &s), 1.0);
    s.base_lin_vel = [0.3, 0.0, 0.0];
    close(term("stand_still", &s), 0.0);
    s.base_lin_vel = [0.0, 0.0, 0.0];
    s.command = [0.1, 0.1, 0.0];
    close(term("stand_still", &s), 0.0);
}
