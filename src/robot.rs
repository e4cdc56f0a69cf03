//! Unitree G1 (29 DOF) facts: the canonical joint order used everywhere (actions,
//! observations, datasets), motor data, body sets, and the scene files.
//!
//! Single sources: gains and effort limits live in `models/g1/g1_actuators.xml`
//! and the default pose in its keyframe `stand`; [`G1::resolve`] reads them from the
//! compiled model. Joint armature is derived here ([`Motor::armature`]) and written
//! into the scene files through `models/g1/armature.txt` (tests/g1.rs holds the two
//! equal); [`check_armature`] refuses a compiled model that disagrees. Velocity
//! limits live here, with their source.
use std::path::PathBuf;

use crate::sim::{Model, ObjType, SimError};

/// Number of actuated joints.
pub const NUM_JOINTS: usize = 29;

/// Canonical joint order: the vendor MJCF's depth-first order, which is also
/// Unitree's motor order for the 29-DOF G1.
pub const JOINT_NAMES: [&str; NUM_JOINTS] = [
    "left_hip_pitch_joint",
    "left_hip_roll_joint",
    "left_hip_yaw_joint",
    "left_knee_joint",
    "left_ankle_pitch_joint",
    "left_ankle_roll_joint",
    "right_hip_pitch_joint",
    "right_hip_roll_joint",
    "right_hip_yaw_joint",
    "right_knee_joint",
    "right_ankle_pitch_joint",
    "right_ankle_roll_joint",
    "waist_yaw_joint",
    "waist_roll_joint",
    "waist_pitch_joint",
    "left_shoulder_pitch_joint",
    "left_shoulder_roll_joint",
    "left_shoulder_yaw_joint",
    "left_elbow_joint",
    "left_wrist_roll_joint",
    "left_wrist_pitch_joint",
    "left_wrist_yaw_joint",
    "right_shoulder_pitch_joint",
    "right_shoulder_roll_joint",
    "right_shoulder_yaw_joint",
    "right_elbow_joint",
    "right_wrist_roll_joint",
    "right_wrist_pitch_joint",
    "right_wrist_yaw_joint",
];

/// The G1's motor types (Unitree's names).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motor {
    /// 5020: shoulders, elbows, wrist roll.
    M5020,
    /// 7520-14: hip pitch, hip yaw, waist yaw.
    M7520x14,
    /// 7520-22: hip roll, knees.
    M7520x22,
    /// 4010: wrist pitch and yaw.
    M4010,
    /// Two 5020s through a 4-bar linkage: ankles, waist roll and pitch.
    Dual5020,
}

impl Motor {
    /// Reflected rotor inertia (kg m^2) through the two-stage planetary gearbox:
    /// `I1 (g2 g3)^2 + I2 g3^2 + I3` with Unitree's rotor inertias and gear ratios as
    /// listed in mjlab's `g1_constants.py`; the linkage joints get twice the 5020's.
    pub fn armature(self) -> f64 {
        fn planetary(i: [f64; 3], g2: f64, g3: f64) -> f64 {
            i[0] * (g2 * g3).powi(2) + i[1] * g3.powi(2) + i[2]
        }
        let m5020 = planetary(
            [0.139e-4, 0.017e-4, 0.169e-4],
            1.0 + 46.0 / 18.0,
            1.0 + 56.0 / 16.0,
        );
        match self {
            Motor::M5020 => m5020,
            Motor::M7520x14 => planetary([0.489e-4, 0.098e-4, 0.533e-4], 4.5, 1.0 + 48.0 / 22.0),
            Motor::M7520x22 => planetary([0.489e-4, 0.109e-4, 0.738e-4], 4.5, 5.0),
            Motor::M4010 => planetary([0.068e-4, 0.0, 0.0], 5.0, 5.0),
            Motor::Dual5020 => 2.0 * m5020,
        }
    }

    /// No-load joint speed limit (rad/s), Unitree's motor specs (via mjlab).
    pub fn velocity_limit(self) -> f64 {
        match self {
            Motor::M5020 | Motor::Dual5020 => 37.0,
            Motor::M7520x14 => 32.0,
            Motor::M7520x22 => 20.0,
            Motor::M4010 => 22.0,
        }
    }
}

/// Motor of joint `i` in canonical order.
pub fn motor(i: usize) -> Motor {
    let name = JOINT_NAMES[i];
    if name.contains("ankle") || name == "waist_roll_joint" || name == "waist_pitch_joint" {
        Motor::Dual5020
    } else if name.contains("hip_roll") || name.contains("knee") {
        Motor::M7520x22
    } else if name.contains("hip") || name == "waist_yaw_joint" {
        Motor::M7520x14
    } else if name.contains("wrist_pitch") || name.contains("wrist_yaw") {
        Motor::M4010
    } else {
        Motor::M5020
    }
}

/// Root body (floating base).
pub const PELVIS: &str = "pelvis";
pub const TORSO: &str = "torso_link";
/// Feet: the ankle-roll links carry the foot collision capsules.
pub const FEET: [&str; 2] = ["left_ankle_roll_link", "right_ankle_roll_link"];
pub const KNEES: [&str; 2] = ["left_knee_link", "right_knee_link"];
/// Heel and toe of the sole along the foot's x axis, in the ankle-roll link's
/// frame (m): the foot collision capsules span -0.054..0.132.
pub const SOLE_HEEL_TOE_X: [f64; 2] = [-0.05, 0.13];
/// Half the sole's width (m): its capsules lie within y = +-0.026 of the
/// ankle-roll link's x axis.
pub const SOLE_HALF_WIDTH: f64 = 0.026;
/// Sites at the sole (vendor sites).
pub const FOOT_SITES: [&str; 2] = ["left_foot", "right_foot"];
/// IMU site on the pelvis (the observation's angular velocity is measured here).
pub const IMU_SITE: &str = "imu_in_pelvis";
/// Indices (canonical order) of the hip roll and yaw joints (hip-position reward).
pub const HIP_ROLL_YAW: [usize; 4] = [1, 2, 7, 8];
/// Offsets of hip pitch, knee and ankle pitch within a leg's six joints (the
/// left leg is joints 0-5, the right 6-11).
pub const LEG_HIP_PITCH: usize = 0;
pub const LEG_KNEE: usize = 3;
pub const LEG_ANKLE_PITCH: usize = 4;
/// Offsets of hip roll, hip yaw and ankle roll within a leg's six joints.
pub const LEG_HIP_ROLL: usize = 1;
pub const LEG_HIP_YAW: usize = 2;
pub const LEG_ANKLE_ROLL: usize = 5;
/// Waist and arm joints (canonical indices).
pub const UPPER_BODY: std::ops::Range<usize> = 12..NUM_JOINTS;
/// Bodies the unified policy's body-space tracking reward compares
/// (BeyondMimic's set for the G1: pelvis, legs, torso, arms, both wrists).
pub const TRACKED_BODIES: [&str; 14] = [
    "pelvis",
    "left_hip_roll_link",
    "left_knee_link",
    "left_ankle_roll_link",
    "right_hip_roll_link",
    "right_knee_link",
    "right_ankle_roll_link",
    "torso_link",
    "left_shoulder_roll_link",
    "left_elbow_link",
    "right_shoulder_roll_link",
    "right_elbow_link",
    "left_wrist_yaw_link",
    "right_wrist_yaw_link",
];
/// Name of the standing keyframe that holds the default pose.
pub const STAND_KEY: &str = "stand";

/// Directory of the MJCF files: `$DREAMPOLICY_MODELS_DIR`, else `models/` of this checkout.
pub fn models_dir() -> PathBuf {
    std::env::var_os("DREAMPOLICY_MODELS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models"))
}

/// The robot file (vendor G1 + our actuators and keyframe), for includes.
pub fn robot_xml() -> PathBuf {
    models_dir().join("g1").join("g1_actuators.xml")
}

/// The flat-ground scene.
pub fn flat_scene_xml() -> PathBuf {
    models_dir().join("g1").join("scene_flat.xml")
}

/// The joint armature table (joint, armature, motor) that setup writes into the
/// generated vendor copy; it must equal [`Motor::armature`] of [`motor`].
pub fn armature_table() -> PathBuf {
    models_dir().join("g1").join("armature.txt")
}

/// The vendor G1 with joint armature, generated by `scripts/setup.sh`
/// (`scripts/g1_armature.py`) and included by `g1_actuators.xml`.
pub fn armature_xml() -> PathBuf {
    models_dir().join("unitree_g1").join("g1_armature.xml")
}

/// Check that setup has unpacked the vendor description and generated its copy
/// with armature.
pub fn check_vendor_files() -> Result<(), SimError> {
    let vendor = models_dir().join("unitree_g1").join("g1.xml");
    for (path, what) in [
        (vendor, "the Unitree G1 description is missing"),
        (
            armature_xml(),
            "the G1 with joint armature is not generated",
        ),
    ] {
        if !path.is_file() {
            return Err(SimError::Load {
                path,
                message: format!("{what}; run scripts/setup.sh"),
            });
        }
    }
    Ok(())
}

/// Load a G1 scene file: the file as stock MuJoCo loads it, checked against the
/// motor table ([`check_armature`]).
pub fn load_scene(path: &std::path::Path) -> Result<Model, SimError> {
    check_vendor_files()?;
    let model = Model::from_xml_path(path)?;
    check_armature(&model)?;
    Ok(model)
}

/// Load the flat-ground scene.
pub fn load_flat() -> Result<Model, SimError> {
    load_scene(&flat_scene_xml())
}

/// Check that each joint's `dof_armature` (from the scene files) is its motor's
/// reflected inertia. A mismatch means a stale generated file (or a scene that
/// includes the vendor `g1.xml` directly) and names the joint.
pub fn check_armature(model: &Model) -> Result<(), SimError> {
    for (i, name) in JOINT_NAMES.iter().enumerate() {
        let j = model.id(ObjType::Joint, name)?;
        let found = model.dof_armature()[model.jnt_dofadr()[j] as usize];
        let expected = motor(i).armature();
        // the table holds the shortest round-trip text, so this is exact in practice
        if (found - expected).abs() > 1e-12 * expected {
            return Err(SimError::Armature {
                model: model.source().into(),
                joint: name.to_string(),
                found,
                expected,
            });
        }
    }
    Ok(())
}

/// The G1 as one compiled model sees it: every index resolved once.
#[derive(Debug, Clone)]
pub struct G1 {
    /// qpos address of each joint (canonical order).
    pub qpos_adr: [usize; NUM_JOINTS],
    /// dof address of each joint.
    pub dof_adr: [usize; NUM_JOINTS],
    /// Actuator driving each joint.
    pub actuator: [usize; NUM_JOINTS],
    /// Default joint pose = keyframe `stand` ctrl.
    pub default_pos: [f64; NUM_JOINTS],
    /// Proportional gain (N m / rad) and damping (N m s / rad) of each actuator.
    pub kp: [f64; NUM_JOINTS],
    pub kd: [f64; NUM_JOINTS],
    /// Effort limit (N m) from the actuator's forcerange.
    pub effort_limit: [f64; NUM_JOINTS],
    /// Joint speed limit (rad/s) from the motor specs.
    pub velocity_limit: [f64; NUM_JOINTS],
    /// Joint position range (rad).
    pub joint_range: [[f64; 2]; NUM_JOINTS],
    pub pelvis: usize,
    pub torso: usize,
    pub feet: [usize; 2],
    pub knees: [usize; 2],
    pub imu_site: usize,
    pub stand_key: usize,
    /// Pelvis height of the keyframe.
    pub stand_height: f64,
    /// Robot bodies (everything but the world), for contact classification.
    pub first_body: usize,
}

impl G1 {
    /// Resolve every name against `model`; fails with the missing name.
    pub fn resolve(model: &Model) -> Result<G1, SimError> {
        let mut g = G1 {
            qpos_adr: [0; NUM_JOINTS],
            dof_adr: [0; NUM_JOINTS],
            actuator: [0; NUM_JOINTS],
            default_pos: [0.0; NUM_JOINTS],
            kp: [0.0; NUM_JOINTS],
            kd: [0.0; NUM_JOINTS],
            effort_limit: [0.0; NUM_JOINTS],
            velocity_limit: [0.0; NUM_JOINTS],
            joint_range: [[0.0; 2]; NUM_JOINTS],
            pelvis: model.id(ObjType::Body, PELVIS)?,
            torso: model.id(ObjType::Body, TORSO)?,
            feet: [
                model.id(ObjType::Body, FEET[0])?,
                model.id(ObjType::Body, FEET[1])?,
            ],
            knees: [
                model.id(ObjType::Body, KNEES[0])?,
                model.id(ObjType::Body, KNEES[1])?,
            ],
            imu_site: model.id(ObjType::Site, IMU_SITE)?,
            stand_key: model.id(ObjType::Key, STAND_KEY)?,
            stand_height: 0.0,
            first_body: 1,
        };
        let ngain = mujoco_sys::mjNGAIN as usize;
        let nbias = mujoco_sys::mjNBIAS as usize;
        let key_ctrl = model.key_ctrl(g.stand_key)?;
        g.stand_height = model.key_qpos(g.stand_key)?[2];
        for (i, name) in JOINT_NAMES.iter().enumerate() {
            let j = model.id(ObjType::Joint, name)?;
            g.qpos_adr[i] = model.jnt_qposadr()[j] as usize;
            g.dof_adr[i] = model.jnt_dofadr()[j] as usize;
            g.joint_range[i] = model.jnt_range()[j];
            let a = model
                .actuator_trnid()
                .iter()
                .position(|t| t[0] == j as i32)
                .ok_or_else(|| SimError::UnknownName {
                    kind: "actuator for joint",
                    name: name.to_string(),
                    model: model.source().into(),
                })?;
            g.actuator[i] = a;
            g.kp[i] = model.actuator_gainprm()[a * ngain];
            g.kd[i] = -model.actuator_biasprm()[a * nbias + 2];
            g.effort_limit[i] = model.actuator_forcerange()[a][1];
            g.velocity_limit[i] = motor(i).velocity_limit();
            g.default_pos[i] = key_ctrl[a];
        }
        Ok(g)
    }
}
