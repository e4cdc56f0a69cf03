//! The G1 scene: it loads, its joint order is ours, it stands under zero action
//! and falls without gains, and the scene file alone (as stock MuJoCo loads it)
//! carries the motor table's armature and stands too.
use std::sync::Arc;

use dreampolicy::robot::{self, G1, JOINT_NAMES, NUM_JOINTS};
use dreampolicy::sim::{Data, Model, ObjType};

fn flat() -> (Arc<Model>, G1) {
    let model = robot::load_flat().expect("G1 flat scene loads (run scripts/setup.sh)");
    let g1 = G1::resolve(&model).unwrap();
    (Arc::new(model), g1)
}

#[test]
fn scene_has_the_g1_sizes() {
    let (m, _) = flat();
    assert_eq!(m.nq(), 7 + NUM_JOINTS);
    assert_eq!(m.nv(), 6 + NUM_JOINTS);
    assert_eq!(m.nu(), NUM_JOINTS);
    assert_eq!(m.njnt(), 1 + NUM_JOINTS);
}

#[test]
fn joint_and_actuator_order_is_canonical() {
    let (m, g1) = flat();
    for (i, name) in JOINT_NAMES.iter().enumerate() {
        // joint i+1 in the model (0 is the free joint), actuator i drives it
        assert_eq!(m.id2name(ObjType::Joint, i + 1), Some(*name), "joint {i}");
        assert_eq!(g1.qpos_adr[i], 7 + i);
        assert_eq!(g1.dof_adr[i], 6 + i);
        assert_eq!(g1.actuator[i], i, "actuator order = joint order");
        assert_eq!(m.actuator_trnid()[i][0] as usize, i + 1);
    }
}

#[test]
fn robot_facts_are_consistent() {
    let (m, g1) = flat();
    for i in 0..NUM_JOINTS {
        let [lo, hi] = g1.joint_range[i];
        assert!(
            lo < g1.default_pos[i] && g1.default_pos[i] < hi,
            "{}",
            JOINT_NAMES[i]
        );
        assert!(g1.kp[i] > 0.0 && g1.kd[i] > 0.0 && g1.effort_limit[i] > 0.0);
        // armature from the scene files (generated vendor copy) = the motor table
        let a = m.dof_armature()[g1.dof_adr[i]];
        assert_eq!(a, robot::motor(i).armature());
        assert!(a > 1e-3 && a < 0.05, "{} armature {a}", JOINT_NAMES[i]);
    }
    // mjlab's numbers for the 7520-22 (hip roll, knee): 0.0251019 kg m^2
    assert!((robot::Motor::M7520x22.armature() - 0.025_101_925).abs() < 1e-9);
    // key ctrl and qpos hold the same pose
    let kq = m.key_qpos(g1.stand_key).unwrap();
    for i in 0..NUM_JOINTS {
        assert_eq!(kq[g1.qpos_adr[i]], g1.default_pos[i]);
    }
    let total: f64 = m.body_subtreemass()[g1.pelvis];
    assert!((30.0..40.0).contains(&total), "G1 mass {total} kg");
}

fn stand(m: &Arc<Model>, g1: &G1, seconds: f64) -> Vec<f64> {
    let mut d = Data::new(m.clone()).unwrap();
    d.reset_keyframe(g1.stand_key).unwrap();
    for i in 0..NUM_JOINTS {
        d.ctrl_mut()[g1.actuator[i]] = g1.default_pos[i];
    }
    let steps = (seconds / m.timestep()).round() as usize;
    let mut heights = Vec::with_capacity(steps);
    for _ in 0..steps {
        d.step().unwrap();
        heights.push(d.xpos()[g1.pelvis][2]);
    }
    heights
}

#[test]
fn stands_for_ten_seconds_with_zero_action() {
    let (m, g1) = flat();
    let h = stand(&m, &g1, 10.0);
    let start = g1.stand_height;
    let worst = h.iter().map(|z| (z - start).abs()).fold(0.0, f64::max);
    assert!(worst < 0.05, "pelvis left {start:.3} m by {worst:.3} m");
}

#[test]
fn falls_with_zero_gains() {
    let model = robot::load_flat().unwrap();
    let g1 = G1::resolve(&model).unwrap();
    let mut model = model;
    let (ng, nb) = (mujoco_sys::mjNGAIN as usize, mujoco_sys::mjNBIAS as usize);
    for a in 0..model.nu() {
        model.actuator_gainprm_mut()[a * ng] = 0.0;
        model.actuator_biasprm_mut()[a * nb + 1] = 0.0;
        model.actuator_biasprm_mut()[a * nb + 2] = 0.0;
    }
    let h = stand(&Arc::new(model), &g1, 3.0);
    let end = *h.last().unwrap();
    assert!(end < 0.4, "pelvis still at {end:.3} m without gains");
}

/// The scene file as stock MuJoCo loads it: no loader, no check.
fn stock_flat() -> (Arc<Model>, G1) {
    robot::check_vendor_files().expect("run scripts/setup.sh");
    let model = Model::from_xml_path(robot::flat_scene_xml()).unwrap();
    let g1 = G1::resolve(&model).unwrap();
    (Arc::new(model), g1)
}

#[test]
fn scene_file_alone_stands_for_ten_seconds() {
    let (m, g1) = stock_flat();
    // hold the keyframe's own ctrl
    let mut d = Data::new(m.clone()).unwrap();
    d.reset_keyframe(g1.stand_key).unwrap();
    let key_ctrl = m.key_ctrl(g1.stand_key).unwrap().to_vec();
    d.forward();
    let start = d.xpos()[g1.pelvis];
    assert_eq!(start[2], g1.stand_height);
    let steps = (10.0 / m.timestep()).round() as usize;
    let (mut worst_z, mut worst_xy) = (0.0f64, 0.0f64);
    for _ in 0..steps {
        d.ctrl_mut().copy_from_slice(&key_ctrl);
        d.step().unwrap();
        let p = d.xpos()[g1.pelvis];
        worst_z = worst_z.max((p[2] - start[2]).abs());
        worst_xy = worst_xy.max((p[0] - start[0]).hypot(p[1] - start[1]));
    }
    // height as in stands_for_ten_seconds_with_zero_action; horizontally the pose
    // leans forward by up to ~4.9 cm in the first second, then settles at ~2.7 cm
    assert!(worst_z < 0.05, "pelvis height moved {worst_z:.3} m");
    assert!(worst_xy < 0.10, "pelvis moved {worst_xy:.3} m horizontally");
}

#[test]
fn scene_file_without_armature_collapses() {
    // the control for the test above: what the vendor file alone gives
    let (m, g1) = stock_flat();
    let mut m = (*m).clone();
    for i in 0..NUM_JOINTS {
        m.dof_armature_mut()[g1.dof_adr[i]] = 0.0;
    }
    let h = stand(&Arc::new(m), &g1, 3.0);
    let end = *h.last().unwrap();
    assert!(end < g1.stand_height - 0.3, "pelvis still at {end:.3} m");
}

/// `models/g1/armature.txt` as (joint, armature, motor) rows.
fn armature_table() -> Vec<(String, f64, String)> {
    let text = std::fs::read_to_string(robot::armature_table()).unwrap();
    text.lines()
        .map(|l| l.split('#').next().unwrap().trim())
        .filter(|l| !l.is_empty())
        .map(|l| {
            let c: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(c.len(), 3, "row {l:?}");
            (c[0].to_string(), c[1].parse().unwrap(), c[2].to_string())
        })
        .collect()
}

#[test]
fn armature_table_and_scene_file_equal_the_motor_table() {
    let table = armature_table();
    let expected: Vec<(String, f64, String)> = (0..NUM_JOINTS)
        .map(|i| {
            let mot = robot::motor(i);
            (
                JOINT_NAMES[i].to_string(),
                mot.armature(),
                format!("{mot:?}"),
            )
        })
        .collect();
    let rows: String = expected
        .iter()
        .map(|(j, a, mot)| format!("{j} {a} {mot}\n"))
        .collect();
    assert_eq!(table, expected, "models/g1/armature.txt must read:\n{rows}");

    // bit for bit in the compiled scene file, without any loader
    let (m, g1) = stock_flat();
    for i in 0..NUM_JOINTS {
        let a = m.dof_armature()[g1.dof_adr[i]];
        assert_eq!(a, robot::motor(i).armature(), "{}", JOINT_NAMES[i]);
    }
    // nothing else has armature (the free joint's dofs)
    assert!(m.dof_armature()[..6].iter().all(|&a| a == 0.0));
    robot::check_armature(&m).unwrap();
}

#[test]
fn check_armature_names_the_joint_that_differs() {
    let (m, g1) = stock_flat();
    let mut m = (*m).clone();
    m.dof_armature_mut()[g1.dof_adr[3]] *= 1.01;
    let err = robot::check_armature(&m).unwrap_err().to_string();
    assert!(err.contains(JOINT_NAMES[3]), "{err}");
    assert!(err.contains("scripts/setup.sh"), "{err}");
}

/// `ref_stance_roll` narrows the reference pose's stance (hip roll in, ankle
/// roll back): on the G1 the ankles come in by about 0.65 m x r each and the
/// soles stay level, so the sign convention of the roll axes is right.
#[test]
fn stance_roll_narrows_the_feet_and_keeps_the_soles_level() {
    use dreampolicy::env::rewards::{reference_leg_pose, RewardParams};
    use dreampolicy::env::EnvState;
    let (m, g1) = flat();
    let mut d = Data::new(m.clone()).unwrap();
    let feet_at = |d: &mut Data, r: f64| {
        d.reset_keyframe(g1.stand_key).unwrap();
        let mut s = EnvState::new(0.02, g1.default_pos, g1.joint_range);
        s.gait_phase = 0.0; // both legs in the clock's stance (the right one is at 0.5)
        let p = RewardParams {
            ref_stance_roll: r,
            ..Default::default()
        };
        let q = reference_leg_pose(&s, &p);
        for (i, q) in q.iter().enumerate() {
            d.qpos_mut()[g1.qpos_adr[i]] = *q;
        }
        d.kinematics();
        let [l, r] = g1.feet.map(|b| (d.xpos()[b], d.xmat()[b]));
        (l, r)
    };
    let (l0, r0) = feet_at(&mut d, 0.0);
    let (l1, r1) = feet_at(&mut d, 0.06);
    let (w0, w1) = (l0.0[1] - r0.0[1], l1.0[1] - r1.0[1]);
    assert!(w0 > 0.2 && w0 < 0.26, "default stance {w0} m");
    let narrowed = w0 - w1;
    assert!(
        (0.06..0.1).contains(&narrowed),
        "0.06 rad of stance roll narrows by {narrowed} m ({w0} -> {w1})"
    );
    // the soles' normals (the ankle roll bodies' z axes) stay as level as in the default pose
    for (a, b) in [(l0.1, l1.1), (r0.1, r1.1)] {
        assert!((a[8] - b[8]).abs() < 1e-3, "sole tilt {} vs {}", a[8], b[8]);
    }
}
