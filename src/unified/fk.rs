//! Body-space kinematics of the tracked bodies in the **heading frame**: origin
//! at the pelvis, z up, x along the pelvis's heading (its yaw). This is the
//! paper's "body-relative frame": what the unified policy's tracking reward
//! compares, and what a predicted state `ŝ` fixes.
//!
//! A state `s` (the env's actor state, `crate::env::obs`) holds the pelvis's
//! angular velocity and projected gravity, and the joints' positions and
//! velocities; it holds neither the pelvis's position, yaw nor linear velocity,
//! and none of the heading-frame quantities depends on them:
//! * position `p_b = R_h^T (x_b − x_pelvis)`;
//! * orientation `R_b` relative to the heading frame (`q_h^{-1} ⊗ q_b`);
//! * linear velocity `v_b = R_h^T (ẋ_b − ẋ_pelvis)` (of the body's origin),
//!   or with [`BodyFk::with_base_velocity`] `v_b = R_h^T ẋ_b`, where a state's
//!   pelvis moves at the command `(v_x, v_y, 0)` it holds
//!   (`unified.tracking.base_velocity: command`);
//! * angular velocity `ω_b = R_h^T ω_b^world`.
//!
//! [`BodyFk::from_state`] decodes `s` into a configuration with the pelvis at
//! the origin, yaw 0, roll and pitch from the projected gravity, zero linear
//! velocity, and runs MuJoCo's kinematics (`mj_kinematics`, `mj_comPos`,
//! `mj_comVel`) on a scratch `Data`; [`BodyFk::from_qpos`] does the same from a
//! simulated robot's `qpos`/`qvel`. The two agree for the same robot state
//! (`tests/unified.rs`), so the tracking reward is at its maximum exactly when
//! the robot is on the plan.
use std::sync::Arc;

use crate::env::config::ObsScales;
use crate::env::obs::{ANG_VEL, COMMAND, DOF_POS, DOF_VEL, GRAVITY, OBS_DIM};
use crate::robot::{G1, NUM_JOINTS, TRACKED_BODIES};
use crate::sim::{Data, Model, ObjType, SimError};

/// Number of tracked bodies ([`TRACKED_BODIES`]).
pub const N_TRACKED: usize = TRACKED_BODIES.len();

/// Quaternion product `a ⊗ b` (w, x, y, z).
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// The conjugate (the inverse of a unit quaternion).
pub fn quat_conj(q: [f64; 4]) -> [f64; 4] {
    [q[0], -q[1], -q[2], -q[3]]
}

/// The rotation vector of a unit quaternion (the log map: axis × angle, the
/// angle in `[0, π]`).
pub fn quat_log(q: [f64; 4]) -> [f64; 3] {
    // the shorter of q and -q
    let q = if q[0] < 0.0 { q.map(|v| -v) } else { q };
    let s = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if s < 1e-12 {
        return [2.0 * q[1], 2.0 * q[2], 2.0 * q[3]];
    }
    let angle = 2.0 * s.atan2(q[0]);
    [q[1] / s * angle, q[2] / s * angle, q[3] / s * angle]
}

/// Yaw (ZYX) of a unit quaternion.
pub fn quat_yaw(q: [f64; 4]) -> f64 {
    (2.0 * (q[0] * q[3] + q[1] * q[2])).atan2(1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]))
}

/// `v` rotated by `-yaw` about z (world into the heading frame).
fn unyaw((s, c): (f64, f64), v: [f64; 3]) -> [f64; 3] {
    [c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The pelvis orientation with yaw 0 whose projected gravity `R^T (0, 0, −1)`
/// is `g` (normalized; a zero vector reads as upright).
pub fn quat_from_gravity(g: [f64; 3]) -> [f64; 4] {
    let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    let g = if n > 1e-9 {
        g.map(|v| v / n)
    } else {
        [0.0, 0.0, -1.0]
    };
    // R = R_y(pitch) R_x(roll): R^T e_z = (-sin p, cos p sin r, cos p cos r) = -g
    let pitch = g[0].clamp(-1.0, 1.0).asin();
    let roll = (-g[1]).atan2(-g[2]);
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sr, cr) = (roll / 2.0).sin_cos();
    quat_mul([cp, 0.0, sp, 0.0], [cr, sr, 0.0, 0.0])
}

/// Heading-frame poses and twists of the tracked bodies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyFrames {
    pub pos: [[f64; 3]; N_TRACKED],
    pub quat: [[f64; 4]; N_TRACKED],
    pub lin_vel: [[f64; 3]; N_TRACKED],
    pub ang_vel: [[f64; 3]; N_TRACKED],
}

impl Default for BodyFrames {
    fn default() -> Self {
        BodyFrames {
            pos: [[0.0; 3]; N_TRACKED],
            quat: [[1.0, 0.0, 0.0, 0.0]; N_TRACKED],
            lin_vel: [[0.0; 3]; N_TRACKED],
            ang_vel: [[0.0; 3]; N_TRACKED],
        }
    }
}

/// Forward kinematics of the G1 on a scratch `Data`.
pub struct BodyFk {
    data: Data,
    g1: G1,
    bodies: [usize; N_TRACKED],
    scales: ObsScales,
    /// Heading-frame velocities with the base's own (`true`), or against the
    /// pelvis (`false`, the default); see `unified.tracking.base_velocity`.
    with_base_velocity: bool,
}

impl BodyFk {
    /// Kinematics on `model` (any scene with the G1), decoding states with the
    /// observation `scales` they were written with.
    pub fn new(model: Arc<Model>, scales: &ObsScales) -> Result<BodyFk, SimError> {
        let g1 = G1::resolve(&model)?;
        let mut bodies = [0; N_TRACKED];
        for (b, name) in bodies.iter_mut().zip(TRACKED_BODIES) {
            *b = model.id(ObjType::Body, name)?;
        }
        Ok(BodyFk {
            data: Data::new(model)?,
            g1,
            bodies,
            scales: scales.clone(),
            with_base_velocity: false,
        })
    }

    /// Measure linear velocities in the heading frame with the base's own
    /// (a state's base then moves at the command it holds) instead of against
    /// the pelvis.
    pub fn with_base_velocity(mut self, on: bool) -> BodyFk {
        self.with_base_velocity = on;
        self
    }

    /// The observation scales states are decoded with.
    pub fn scales(&self) -> &ObsScales {
        &self.scales
    }

    /// The heading-frame bodies of a simulated robot's `qpos` and `qvel`.
    pub fn from_qpos(&mut self, qpos: &[f64], qvel: &[f64]) -> BodyFrames {
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.frames()
    }

    /// The heading-frame bodies a state `s` (`OBS_DIM` floats, the actor-state
    /// layout, noise-free or predicted) fixes.
    pub fn from_state(&mut self, s: &[f32]) -> BodyFrames {
        debug_assert!(s.len() >= OBS_DIM);
        let sc = &self.scales;
        let f = |i: usize| f64::from(s[i]);
        let quat =
            quat_from_gravity([f(GRAVITY.start), f(GRAVITY.start + 1), f(GRAVITY.start + 2)]);
        {
            // the free joint first: position, then orientation
            let qpos = self.data.qpos_mut();
            qpos[..3].copy_from_slice(&[0.0, 0.0, 0.0]);
            qpos[3..7].copy_from_slice(&quat);
            for j in 0..NUM_JOINTS {
                qpos[self.g1.qpos_adr[j]] =
                    self.g1.default_pos[j] + f(DOF_POS.start + j) / sc.dof_pos;
            }
        }
        // the base's linear velocity: none, or the commanded one (the state's
        // heading frame is the world's here: its yaw is 0)
        let base = if self.with_base_velocity {
            [
                f(COMMAND.start) / sc.commands[0],
                f(COMMAND.start + 1) / sc.commands[1],
                0.0,
            ]
        } else {
            [0.0; 3]
        };
        let qvel = self.data.qvel_mut();
        qvel[..3].copy_from_slice(&base);
        for a in 0..3 {
            qvel[3 + a] = f(ANG_VEL.start + a) / sc.ang_vel;
        }
        for j in 0..NUM_JOINTS {
            qvel[self.g1.dof_adr[j]] = f(DOF_VEL.start + j) / sc.dof_vel;
        }
        self.frames()
    }

    fn frames(&mut self) -> BodyFrames {
        self.data.kinematics();
        self.data.com_vel();
        let d = &self.data;
        let (xpos, xquat, cvel) = (d.xpos(), d.xquat(), d.cvel());
        let pelvis = self.g1.pelvis;
        let com = d.subtree_com()[pelvis];
        // the velocity of body b's origin: cvel is [ω, v] at the tree's COM
        let point_vel = |b: usize| {
            let w = [cvel[b][0], cvel[b][1], cvel[b][2]];
            let v = [cvel[b][3], cvel[b][4], cvel[b][5]];
            let r = cross(w, sub(xpos[b], com));
            [v[0] + r[0], v[1] + r[1], v[2] + r[2]]
        };
        let yaw = quat_yaw(xquat[pelvis]);
        let sc = yaw.sin_cos();
        let q_h_inv = [(yaw / 2.0).cos(), 0.0, 0.0, -(yaw / 2.0).sin()];
        let vp = if self.with_base_velocity {
            [0.0; 3]
        } else {
            point_vel(pelvis)
        };
        let mut out = BodyFrames::default();
        for (k, &b) in self.bodies.iter().enumerate() {
            out.pos[k] = unyaw(sc, sub(xpos[b], xpos[pelvis]));
            out.quat[k] = quat_mul(q_h_inv, xquat[b]);
            out.lin_vel[k] = unyaw(sc, sub(point_vel(b), vp));
            out.ang_vel[k] = unyaw(sc, [cvel[b][0], cvel[b][1], cvel[b][2]]);
        }
        out
    }
}
