//! The observation layouts, in one place.
//!
//! Actor state `s_t` (98 floats), in this order:
//!
//! | slice      | size | content                                   | scale          |
//! |------------|------|-------------------------------------------|----------------|
//! | 0..3       | 3    | base angular velocity (pelvis frame)      | `ang_vel`      |
//! | 3..6       | 3    | projected gravity (pelvis frame)          | 1              |
//! | 6..35      | 29   | joint positions − default pose            | `dof_pos`      |
//! | 35..64     | 29   | joint velocities                          | `dof_vel`      |
//! | 64..67     | 3    | command `[vx, vy, yaw_rate]`              | `commands`     |
//! | 67..96     | 29   | last action                               | 1              |
//! | 96..98     | 2    | gait phase `[sin, cos]`                   | 1              |
//!
//! Critic observation = actor state without noise, then the privileged block
//! ([`PRIV_DIM`] floats): base linear velocity (pelvis frame, `lin_vel` scale, 3),
//! pelvis height above the terrain (1), left/right foot contact force in the world
//! frame / robot weight (6), friction (1), added pelvis mass in kg (1), motor
//! strength (1), action latency in control steps (1).
//!
//! Scandots ([`SCAN_DIM`] = 17 x 11): terrain height minus pelvis height (m) at
//! `x` in -0.6..=1.0 and `y` in -0.5..=0.5, 0.1 m apart, in the yaw-aligned pelvis
//! frame; index = `ix * 11 + iy` (x-major, x from back to front, y from right to left).
use crate::robot::NUM_JOINTS;

pub const ANG_VEL: std::ops::Range<usize> = 0..3;
pub const GRAVITY: std::ops::Range<usize> = 3..6;
pub const DOF_POS: std::ops::Range<usize> = 6..6 + NUM_JOINTS;
pub const DOF_VEL: std::ops::Range<usize> = DOF_POS.end..DOF_POS.end + NUM_JOINTS;
pub const COMMAND: std::ops::Range<usize> = DOF_VEL.end..DOF_VEL.end + 3;
pub const LAST_ACTION: std::ops::Range<usize> = COMMAND.end..COMMAND.end + NUM_JOINTS;
pub const PHASE: std::ops::Range<usize> = LAST_ACTION.end..LAST_ACTION.end + 2;
/// Size of the actor state `s_t`.
pub const OBS_DIM: usize = PHASE.end;

/// Privileged block appended for the critic.
pub const PRIV_DIM: usize = 3 + 1 + 6 + 4;
pub const CRITIC_DIM: usize = OBS_DIM + PRIV_DIM;

pub const SCAN_NX: usize = 17;
pub const SCAN_NY: usize = 11;
pub const SCAN_DIM: usize = SCAN_NX * SCAN_NY;
pub const SCAN_SPACING: f64 = 0.1;
pub const SCAN_X0: f64 = -0.6;
pub const SCAN_Y0: f64 = -0.5;

/// Scan point `k` in the yaw-aligned pelvis frame.
#[inline]
pub fn scan_point(k: usize) -> (f64, f64) {
    let (ix, iy) = (k / SCAN_NY, k % SCAN_NY);
    (
        SCAN_X0 + SCAN_SPACING * ix as f64,
        SCAN_Y0 + SCAN_SPACING * iy as f64,
    )
}

const _: () = assert!(OBS_DIM == 98, "the paper's state is 98 floats");
const _: () = assert!(SCAN_DIM == 187, "the paper's scandots are 187 floats");
