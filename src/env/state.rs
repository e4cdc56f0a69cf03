//! `EnvState`: what one control step knows about one robot, derived once from the
//! MuJoCo state, and read by the reward terms, terminations and observations.
use crate::robot::NUM_JOINTS;

/// Derived state of one env after a control step. Plain data, so reward terms
/// can be unit-tested on hand-built states.
#[derive(Debug, Clone, Default)]
pub struct EnvState {
    /// Control period (s).
    pub dt: f64,
    pub base_pos: [f64; 3],
    /// Pelvis rotation, row-major, body to world (MuJoCo's `xmat`).
    pub base_rot: [f64; 9],
    /// Pelvis linear velocity in the world frame and in the pelvis frame.
    pub base_lin_vel_world: [f64; 3],
    pub base_lin_vel: [f64; 3],
    /// Pelvis angular velocity in the pelvis frame.
    pub base_ang_vel: [f64; 3],
    /// Gravity direction in the pelvis frame (`[0, 0, -1]` when upright).
    pub gravity: [f64; 3],
    pub yaw: f64,
    /// Pelvis height above the terrain under it.
    pub base_height: f64,
    pub q: [f64; NUM_JOINTS],
    pub default_q: [f64; NUM_JOINTS],
    pub q_range: [[f64; 2]; NUM_JOINTS],
    /// Joint speed limits (rad/s) and effort limits (N m); 0 = none (the
    /// limit terms skip the joint).
    pub qd_limit: [f64; NUM_JOINTS],
    pub tau_limit: [f64; NUM_JOINTS],
    pub qd: [f64; NUM_JOINTS],
    pub last_qd: [f64; NUM_JOINTS],
    pub torque: [f64; NUM_JOINTS],
    pub last_torque: [f64; NUM_JOINTS],
    /// The policy's (clipped) actions at t, t-1, t-2.
    pub action: [f64; NUM_JOINTS],
    pub last_action: [f64; NUM_JOINTS],
    pub last_last_action: [f64; NUM_JOINTS],
    /// `[vx, vy, yaw_rate]`.
    pub command: [f64; 3],
    /// Target heading in heading mode (else None).
    pub heading_target: Option<f64>,
    /// Left, right.
    pub feet_pos: [[f64; 3]; 2],
    /// Foot roll/pitch/yaw in the world frame.
    pub feet_rpy: [[f64; 3]; 2],
    /// Terrain height under each foot.
    pub feet_ground: [f64; 2],
    /// The ground the swing terms measure a foot's height from: the highest
    /// support surface from under the foot to `swing_lookahead` ahead of it
    /// along the heading (`feet_ground` when the lookahead is 0).
    pub feet_swing_ground: [f64; 2],
    /// Summed ground contact force on each foot, world frame.
    pub feet_force: [[f64; 3]; 2],
    pub feet_contact: [bool; 2],
    /// Time since each foot left the ground (reset at touchdown).
    pub feet_air_time: [f64; 2],
    /// Time since each foot touched down (reset at lift-off).
    pub feet_contact_time: [f64; 2],
    /// Air time at the moment of touchdown this step (0 if no touchdown).
    pub feet_touchdown_air_time: [f64; 2],
    pub feet_first_contact: [bool; 2],
    /// Foot on a terrain edge.
    pub feet_on_edge: [bool; 2],
    /// Heel or toe over a pit: the support surface more than
    /// `feet_gap_depth` above the terrain there (`feet_gap`).
    pub feet_over_pit: [bool; 2],
    /// The terrain under the sole's four corners spans more than
    /// `straddle_height`: the foot is across a step's edge (`feet_straddle`).
    pub feet_straddle: [bool; 2],
    pub knees_pos: [[f64; 3]; 2],
    /// Feet linear velocity (world), from their positions one control step apart.
    pub feet_vel: [[f64; 3]; 2],
    /// Gait clock in [0, 1): time in the episode / gait period (the left leg's
    /// phase; the right leg is half a period later).
    pub gait_phase: f64,
    /// Non-foot robot bodies touching the ground with more than the collision force.
    pub collisions: u32,
    /// The episode ends by a fall this step (not a time-out).
    pub terminated: bool,
    /// The robot crossed its tile's goal line this step.
    pub reached_goal: bool,
    pub terrain_level: usize,
}

impl EnvState {
    /// Fresh state with joint facts filled in.
    pub fn new(dt: f64, default_q: [f64; NUM_JOINTS], q_range: [[f64; 2]; NUM_JOINTS]) -> Self {
        EnvState {
            dt,
            default_q,
            q_range,
            q: default_q,
            gravity: [0.0, 0.0, -1.0],
            base_rot: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            ..Default::default()
        }
    }

    /// A vector from the world frame into the yaw-aligned base frame (xy only).
    #[inline]
    pub fn world_to_heading_xy(&self, v: [f64; 3]) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [c * v[0] + s * v[1], -s * v[0] + c * v[1]]
    }
}

/// `R^T v` for a row-major rotation `R` (world to body).
#[inline]
pub fn rotate_inv(r: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        r[0] * v[0] + r[3] * v[1] + r[6] * v[2],
        r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
        r[2] * v[0] + r[5] * v[1] + r[8] * v[2],
    ]
}

/// Roll, pitch, yaw (ZYX) of a row-major rotation matrix.
#[inline]
pub fn rpy(r: &[f64; 9]) -> [f64; 3] {
    [
        r[7].atan2(r[8]),
        (-r[6]).clamp(-1.0, 1.0).asin(),
        r[3].atan2(r[0]),
    ]
}

pub use crate::sim::wrap_angle;
