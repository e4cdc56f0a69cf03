//! Reward terms by name: each a small function of the env state, registered in
//! one table. The YAML lists `name: weight`; an unknown name is a load error that
//! lists [`names`]. A step's reward is `sum(weight * term * dt)`.
//!
//! The paper's base table (orientation ... ang_vel_xy) and specialist table
//! (tracking_goal_vel ... feet_air_time) are all here, plus legged_gym's
//! velocity-tracking terms for the flat walker. Where the paper's formula is
//! ambiguous, the doc line says how it is read.
use super::state::{wrap_angle, EnvState};
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::config::ConfigError;
use crate::robot::{
    HIP_ROLL_YAW, LEG_ANKLE_PITCH, LEG_ANKLE_ROLL, LEG_HIP_PITCH, LEG_HIP_ROLL, LEG_HIP_YAW,
    LEG_KNEE, NUM_JOINTS, UPPER_BODY,
};

/// One reward term.
pub struct Term {
    pub name: &'static str,
    pub f: fn(&EnvState, &RewardParams) -> f64,
    pub doc: &'static str,
}

macro_rules! terms {
    ($($name:ident: $doc:literal;)*) => {
        /// Every term, in a fixed order (the order of the per-term logs).
        pub static TERMS: &[Term] = &[$(Term { name: stringify!($name), f: $name, doc: $doc }),*];
    };
}

terms! {
    orientation: "sum(g_x^2 + g_y^2): tilt of the pelvis";
    dof_acc: "sum(((qd_t - qd_t-1) / dt)^2)";
    collision: "number of non-foot bodies touching the ground (|F| > collision_force)";
    action_rate: "||a_t - a_t-1|| (L2 norm, as the paper writes it)";
    delta_torques: "sum((tau_t - tau_t-1)^2)";
    torques: "sum(tau^2)";
    dof_error: "sum((q - q_default)^2)";
    base_height: "(h_base - base_height_target)^2, h above the terrain";
    smoothness: "||a_t - a_t-1|| + ||a_t - 2 a_t-1 + a_t-2||";
    alive: "1 every step";
    tracking_yaw: "exp(-|yaw_target - yaw|^2 / 0.25); yaw_target = heading command (heading mode) else yaw + yaw_rate_cmd * dt";
    lin_vel_z: "v_z^2 (pelvis frame)";
    ang_vel_xy: "w_x^2 + w_y^2 (pelvis frame)";
    tracking_goal_vel: "min(v . v_cmd/|v_cmd|, |v_cmd|) / |v_cmd| over the planar command (0 when |v_cmd| < 0.05)";
    hip_pos: "sum((q_hip - q_default - stance offset)^2) over hip roll and yaw (the offset: ref_stance_roll on hip roll, 0 by default)";
    feet_stumble: "1 if a foot's horizontal contact force exceeds 4 |F_z|";
    feet_edge: "number of feet in contact on a terrain edge, when terrain level >= feet_edge_min_level";
    feet_gap: "number of feet in contact whose heel or toe is over a pit: the support surface (env.terrain.support_radius) more than feet_gap_depth above the terrain there; unlike feet_edge it sees the sole's ends, not the ankle, and applies at every level";
    feet_straddle: "number of feet in contact across a step's edge: the terrain under the sole's four corners spans more than straddle_height (a foothold half on a block or a tread)";
    feet_flight: "1 while neither foot touches the ground (a hop: the uneven specialist's falls begin with recovery hops that turn it; a walk has no flight phase)";
    feet_parallel: "sum(pitch_foot^2), foot pitch in the world frame";
    huge_step: "|x_left_ankle - x_right_ankle| in the heading frame";
    feet_yaw: "sum(wrap(yaw_foot - yaw_base)^2)";
    feet_dis: "(|y_left - y_right| - feet_distance_target)^2 in the heading frame (deviation from a stance width; the paper's literal square would pull the feet together)";
    knee_dis: "(|y_left_knee - y_right_knee| - feet_distance_target)^2 in the heading frame";
    goal: "1 on the step the robot crosses its tile's goal line";
    knee_foot: "sum over sides of (y_knee - y_ankle)^2 in the heading frame";
    foot_height: "sum over swing feet of min(z_foot - ground, foot_clearance_target)";
    feet_air_time: "sum over touchdowns of (air_time - feet_air_time_target), only when |v_cmd| > 0.1";
    tracking_lin_vel: "exp(-|v_cmd_xy - v_xy|^2 / tracking_sigma) (legged_gym)";
    tracking_ang_vel: "exp(-(w_cmd - w_z)^2 / tracking_sigma) (legged_gym)";
    termination: "1 on the step of a fall (not a time-out)";
    dof_pos_limits: "sum of how far q is outside 90% of the joint range";
    dof_vel: "sum(qd^2)";
    action_rate_l2: "sum((a_t - a_t-1)^2) (legged_gym's action_rate)";
    gait_contact: "number of feet whose contact matches the gait clock: stance while the leg's phase < gait_stance_ratio (left phase = clock, right = clock + 0.5; unitree_rl_gym's contact)";
    feet_swing_height: "sum over swing feet of (z_foot - ground - swing_height_target)^2";
    contact_no_vel: "sum over feet in contact of |v_foot|^2 (slipping)";
    upper_pose: "sum((q - q_default)^2) over the waist and arm joints";
    upright: "exp(-(g_x^2 + g_y^2) / upright_sigma): a bounded, positive orientation term (mjlab's upright)";
    feet_air_time_biped: "while exactly one foot is in contact and |v_cmd| > 0.1: min(time both feet have spent in their current mode, feet_air_time_threshold) (Isaac Lab's G1 feet_air_time_positive_biped)";
    foot_clearance: "exp(-sum_feet tanh(2 |v_xy(foot)|) (z_foot - ground - foot_clearance_target)^2 / clearance_sigma): only a foot that moves is asked to be high (Isaac Lab's velocity-weighted clearance)";
    ref_joint_pos: "exp(-2 d) - 0.2 min(d, 0.5), d = ||q_legs - q_ref|| over the 12 leg joints; q_ref is the default pose (hip and ankle roll turned by ref_stance_roll) plus, in each leg's clock swing, hip pitch -A sin(pi s), knee +2A sin(pi s), ankle pitch -A sin(pi s) (A = ref_swing_amplitude: the foot lifts and stays level; humanoid-gym's reference trajectory); ref_free_hip_yaw leaves the hip yaw joints out of d";
    stand_still: "1 while a planar command of |v_cmd| > 0.2 m/s is given and the base moves along it at less than a quarter of it: standing in front of an obstacle must not pay";
    energy: "sum((tau_j qd_j / k_j)^2), k_j the joint's effort limit (the paper's energy consumption; its k_j is read as the effort limit, 0 without one)";
    dof_vel_limits: "sum(max(0, |qd_j| - 0.9 qd_max_j)), qd_max_j the motor's no-load speed (Unitree's specs)";
    torque_limits: "sum(max(0, |tau_j| - 0.8 tau_max_j)^2), tau_max_j the actuator's force range";
    feet_slide: "sum over feet in contact of |v_xy(foot)| (the paper's feet slide: the planar speed, not squared)";
    feet_swing_clock: "sum over legs in the gait clock's swing phase of (z_foot - ground - ankle_stance_height - swing_clock_height sin(pi s))^2, s in [0, 1] the swing's progress (walk-these-ways' clock target: a foot kept down in swing pays)";
}

/// The term with this name.
pub fn lookup(name: &str) -> Option<&'static Term> {
    TERMS.iter().find(|t| t.name == name)
}

/// Every valid name, for error messages.
pub fn names() -> Vec<&'static str> {
    TERMS.iter().map(|t| t.name).collect()
}

fn sq(x: f64) -> f64 {
    x * x
}

fn norm(v: impl Iterator<Item = f64>) -> f64 {
    v.map(sq).sum::<f64>().sqrt()
}

fn orientation(s: &EnvState, _: &RewardParams) -> f64 {
    sq(s.gravity[0]) + sq(s.gravity[1])
}

fn dof_acc(s: &EnvState, _: &RewardParams) -> f64 {
    s.qd.iter()
        .zip(&s.last_qd)
        .map(|(a, b)| sq((a - b) / s.dt))
        .sum()
}

fn collision(s: &EnvState, _: &RewardParams) -> f64 {
    s.collisions as f64
}

fn action_rate(s: &EnvState, _: &RewardParams) -> f64 {
    norm(s.action.iter().zip(&s.last_action).map(|(a, b)| a - b))
}

fn delta_torques(s: &EnvState, _: &RewardParams) -> f64 {
    s.torque
        .iter()
        .zip(&s.last_torque)
        .map(|(a, b)| sq(a - b))
        .sum()
}

fn torques(s: &EnvState, _: &RewardParams) -> f64 {
    s.torque.iter().map(|t| sq(*t)).sum()
}

fn dof_error(s: &EnvState, _: &RewardParams) -> f64 {
    s.q.iter().zip(&s.default_q).map(|(q, d)| sq(q - d)).sum()
}

fn base_height(s: &EnvState, p: &RewardParams) -> f64 {
    sq(s.base_height - p.base_height_target)
}

fn smoothness(s: &EnvState, _: &RewardParams) -> f64 {
    let first = norm(s.action.iter().zip(&s.last_action).map(|(a, b)| a - b));
    let second = norm(
        (0..s.action.len()).map(|i| s.action[i] - 2.0 * s.last_action[i] + s.last_last_action[i]),
    );
    first + second
}

fn alive(_: &EnvState, _: &RewardParams) -> f64 {
    1.0
}

fn tracking_yaw(s: &EnvState, _: &RewardParams) -> f64 {
    let target = s.heading_target.unwrap_or(s.yaw + s.command[2] * s.dt);
    (-sq(wrap_angle(target - s.yaw)) / 0.25).exp()
}

fn lin_vel_z(s: &EnvState, _: &RewardParams) -> f64 {
    sq(s.base_lin_vel[2])
}

fn ang_vel_xy(s: &EnvState, _: &RewardParams) -> f64 {
    sq(s.base_ang_vel[0]) + sq(s.base_ang_vel[1])
}

fn tracking_goal_vel(s: &EnvState, _: &RewardParams) -> f64 {
    let cmd = (s.command[0], s.command[1]);
    let n = cmd.0.hypot(cmd.1);
    if n < 0.05 {
        return 0.0;
    }
    let along = (s.base_lin_vel[0] * cmd.0 + s.base_lin_vel[1] * cmd.1) / n;
    along.min(n) / n
}

fn hip_pos(s: &EnvState, p: &RewardParams) -> f64 {
    HIP_ROLL_YAW
        .iter()
        .map(|&i| sq(s.q[i] - s.default_q[i] - stance_roll(i, p)))
        .sum()
}

/// The reference pose's offset from the default pose at leg joint `i` (0..12)
/// that narrows the stance (`ref_stance_roll`): hip roll in, ankle roll back.
fn stance_roll(i: usize, p: &RewardParams) -> f64 {
    let side = if i < 6 { -1.0 } else { 1.0 };
    match i % 6 {
        LEG_HIP_ROLL => side * p.ref_stance_roll,
        LEG_ANKLE_ROLL => -side * p.ref_stance_roll,
        _ => 0.0,
    }
}

/// A foot's horizontal contact force is above 4 times its vertical one (a toe
/// against a riser or a block's side): `feet_stumble`'s condition.
pub fn stumbling(s: &EnvState) -> bool {
    s.feet_force
        .iter()
        .any(|f| f[0].hypot(f[1]) > 4.0 * f[2].abs())
}

/// Feet in contact across a step's edge: `feet_straddle`'s count.
pub fn feet_straddling(s: &EnvState) -> usize {
    (0..2)
        .filter(|&i| s.feet_contact[i] && s.feet_straddle[i])
        .count()
}

/// Neither foot on the ground: `feet_flight`'s condition.
pub fn in_flight(s: &EnvState) -> bool {
    !s.feet_contact[0] && !s.feet_contact[1]
}

fn feet_stumble(s: &EnvState, _: &RewardParams) -> f64 {
    stumbling(s) as u8 as f64
}

fn feet_edge(s: &EnvState, p: &RewardParams) -> f64 {
    if s.terrain_level < p.feet_edge_min_level {
        return 0.0;
    }
    (0..2)
        .filter(|&i| s.feet_contact[i] && s.feet_on_edge[i])
        .count() as f64
}

fn feet_gap(s: &EnvState, _: &RewardParams) -> f64 {
    (0..2)
        .filter(|&i| s.feet_contact[i] && s.feet_over_pit[i])
        .count() as f64
}

fn feet_straddle(s: &EnvState, _: &RewardParams) -> f64 {
    feet_straddling(s) as f64
}

fn feet_flight(s: &EnvState, _: &RewardParams) -> f64 {
    in_flight(s) as u8 as f64
}

fn feet_parallel(s: &EnvState, _: &RewardParams) -> f64 {
    s.feet_rpy.iter().map(|r| sq(r[1])).sum()
}

/// Feet in the heading frame relative to the pelvis.
fn feet_local(s: &EnvState) -> [[f64; 2]; 2] {
    s.feet_pos
        .map(|f| s.world_to_heading_xy([f[0] - s.base_pos[0], f[1] - s.base_pos[1], 0.0]))
}

fn knees_local(s: &EnvState) -> [[f64; 2]; 2] {
    s.knees_pos
        .map(|k| s.world_to_heading_xy([k[0] - s.base_pos[0], k[1] - s.base_pos[1], 0.0]))
}

fn huge_step(s: &EnvState, _: &RewardParams) -> f64 {
    let f = feet_local(s);
    (f[0][0] - f[1][0]).abs()
}

fn feet_yaw(s: &EnvState, _: &RewardParams) -> f64 {
    s.feet_rpy
        .iter()
        .map(|r| sq(wrap_angle(r[2] - s.yaw)))
        .sum()
}

fn feet_dis(s: &EnvState, p: &RewardParams) -> f64 {
    let f = feet_local(s);
    sq((f[0][1] - f[1][1]).abs() - p.feet_distance_target)
}

fn knee_dis(s: &EnvState, p: &RewardParams) -> f64 {
    let k = knees_local(s);
    sq((k[0][1] - k[1][1]).abs() - p.feet_distance_target)
}

fn goal(s: &EnvState, _: &RewardParams) -> f64 {
    s.reached_goal as u8 as f64
}

fn knee_foot(s: &EnvState, _: &RewardParams) -> f64 {
    let (f, k) = (feet_local(s), knees_local(s));
    sq(k[0][1] - f[0][1]) + sq(k[1][1] - f[1][1])
}

fn foot_height(s: &EnvState, p: &RewardParams) -> f64 {
    (0..2)
        .filter(|&i| !s.feet_contact[i])
        .map(|i| (s.feet_pos[i][2] - s.feet_swing_ground[i]).min(p.foot_clearance_target))
        .sum()
}

fn feet_air_time(s: &EnvState, p: &RewardParams) -> f64 {
    if s.command[0].hypot(s.command[1]) <= 0.1 {
        return 0.0;
    }
    (0..2)
        .filter(|&i| s.feet_first_contact[i])
        .map(|i| s.feet_touchdown_air_time[i] - p.feet_air_time_target)
        .sum()
}

fn tracking_lin_vel(s: &EnvState, p: &RewardParams) -> f64 {
    let e = sq(s.command[0] - s.base_lin_vel[0]) + sq(s.command[1] - s.base_lin_vel[1]);
    (-e / p.tracking_sigma).exp()
}

fn tracking_ang_vel(s: &EnvState, p: &RewardParams) -> f64 {
    (-sq(s.command[2] - s.base_ang_vel[2]) / p.tracking_sigma).exp()
}

fn termination(s: &EnvState, _: &RewardParams) -> f64 {
    s.terminated as u8 as f64
}

fn dof_pos_limits(s: &EnvState, _: &RewardParams) -> f64 {
    s.q.iter()
        .zip(&s.q_range)
        .map(|(q, [lo, hi])| {
            let (mid, half) = ((lo + hi) / 2.0, 0.45 * (hi - lo));
            ((mid - half) - q).max(0.0) + (q - (mid + half)).max(0.0)
        })
        .sum()
}

fn dof_vel(s: &EnvState, _: &RewardParams) -> f64 {
    s.qd.iter().map(|v| sq(*v)).sum()
}

fn action_rate_l2(s: &EnvState, _: &RewardParams) -> f64 {
    s.action
        .iter()
        .zip(&s.last_action)
        .map(|(a, b)| sq(a - b))
        .sum()
}

/// Leg `k`'s own phase at gait clock `phase` (the right leg half a period later).
fn leg_phase(phase: f64, k: usize) -> f64 {
    (phase + 0.5 * k as f64).fract()
}

/// Whether leg `k` (0 left, 1 right) should be in stance at gait clock `phase`.
pub fn leg_in_stance(phase: f64, k: usize, stance_ratio: f64) -> bool {
    leg_phase(phase, k) < stance_ratio
}

/// `sin(pi s)` of leg `k`'s swing progress `s` in [0, 1] at gait clock `phase`
/// (0 at lift-off and touchdown, 1 at mid-swing), or None in the clock's stance:
/// the shape of the clock's swing targets.
fn swing_lift(phase: f64, k: usize, stance_ratio: f64) -> Option<f64> {
    let leg = leg_phase(phase, k);
    (leg >= stance_ratio).then(|| {
        let progress = (leg - stance_ratio) / (1.0 - stance_ratio);
        (std::f64::consts::PI * progress).sin()
    })
}

fn gait_contact(s: &EnvState, p: &RewardParams) -> f64 {
    (0..2)
        .filter(|&k| s.feet_contact[k] == leg_in_stance(s.gait_phase, k, p.gait_stance_ratio))
        .count() as f64
}

fn feet_swing_height(s: &EnvState, p: &RewardParams) -> f64 {
    (0..2)
        .filter(|&k| !s.feet_contact[k])
        .map(|k| sq(s.feet_pos[k][2] - s.feet_swing_ground[k] - p.swing_height_target))
        .sum()
}

fn contact_no_vel(s: &EnvState, _: &RewardParams) -> f64 {
    (0..2)
        .filter(|&k| s.feet_contact[k])
        .map(|k| s.feet_vel[k].iter().map(|v| sq(*v)).sum::<f64>())
        .sum()
}

fn energy(s: &EnvState, _: &RewardParams) -> f64 {
    (0..NUM_JOINTS)
        .filter(|&j| s.tau_limit[j] > 0.0)
        .map(|j| sq(s.torque[j] * s.qd[j] / s.tau_limit[j]))
        .sum()
}

fn dof_vel_limits(s: &EnvState, _: &RewardParams) -> f64 {
    (0..NUM_JOINTS)
        .filter(|&j| s.qd_limit[j] > 0.0)
        .map(|j| (s.qd[j].abs() - 0.9 * s.qd_limit[j]).max(0.0))
        .sum()
}

fn torque_limits(s: &EnvState, _: &RewardParams) -> f64 {
    (0..NUM_JOINTS)
        .filter(|&j| s.tau_limit[j] > 0.0)
        .map(|j| sq((s.torque[j].abs() - 0.8 * s.tau_limit[j]).max(0.0)))
        .sum()
}

fn feet_slide(s: &EnvState, _: &RewardParams) -> f64 {
    (0..2)
        .filter(|&k| s.feet_contact[k])
        .map(|k| s.feet_vel[k][0].hypot(s.feet_vel[k][1]))
        .sum()
}

fn upper_pose(s: &EnvState, _: &RewardParams) -> f64 {
    UPPER_BODY.map(|i| sq(s.q[i] - s.default_q[i])).sum()
}

fn upright(s: &EnvState, p: &RewardParams) -> f64 {
    (-(sq(s.gravity[0]) + sq(s.gravity[1])) / p.upright_sigma).exp()
}

fn feet_air_time_biped(s: &EnvState, p: &RewardParams) -> f64 {
    if s.command[0].hypot(s.command[1]) <= 0.1 || s.feet_contact[0] == s.feet_contact[1] {
        return 0.0;
    }
    let mode_time = |k: usize| {
        if s.feet_contact[k] {
            s.feet_contact_time[k]
        } else {
            s.feet_air_time[k]
        }
    };
    mode_time(0)
        .min(mode_time(1))
        .min(p.feet_air_time_threshold)
}

fn foot_clearance(s: &EnvState, p: &RewardParams) -> f64 {
    let err: f64 = (0..2)
        .map(|k| {
            let speed = s.feet_vel[k][0].hypot(s.feet_vel[k][1]);
            (2.0 * speed).tanh()
                * sq(s.feet_pos[k][2] - s.feet_swing_ground[k] - p.foot_clearance_target)
        })
        .sum();
    (-err / p.clearance_sigma).exp()
}

/// The clock's swing-height target of leg `k` at gait clock `phase` (ankle
/// height above the ground), or None while the clock has the leg in stance.
pub fn swing_clock_target(phase: f64, k: usize, p: &RewardParams) -> Option<f64> {
    swing_lift(phase, k, p.gait_stance_ratio)
        .map(|lift| p.ankle_stance_height + p.swing_clock_height * lift)
}

fn feet_swing_clock(s: &EnvState, p: &RewardParams) -> f64 {
    (0..2)
        .filter_map(|k| {
            swing_clock_target(s.gait_phase, k, p)
                .map(|z| sq(s.feet_pos[k][2] - s.feet_swing_ground[k] - z))
        })
        .sum()
}

/// The reference pose of the 12 leg joints at gait clock `phase`: the default
/// pose, with each leg in its clock swing flexing hip pitch, knee and ankle pitch
/// along a half sine (`ref_joint_pos`).
pub fn reference_leg_pose(s: &EnvState, p: &RewardParams) -> [f64; 12] {
    let mut q = [0.0; 12];
    for (i, q) in q.iter_mut().enumerate() {
        *q = s.default_q[i] + stance_roll(i, p);
    }
    for k in 0..2 {
        if let Some(lift) = swing_lift(s.gait_phase, k, p.gait_stance_ratio) {
            let a = p.ref_swing_amplitude * lift;
            let base = 6 * k;
            q[base + LEG_HIP_PITCH] -= a;
            q[base + LEG_KNEE] += 2.0 * a;
            q[base + LEG_ANKLE_PITCH] -= a;
        }
    }
    q
}

fn ref_joint_pos(s: &EnvState, p: &RewardParams) -> f64 {
    let q_ref = reference_leg_pose(s, p);
    let d = norm(
        q_ref
            .iter()
            .zip(&s.q[..12])
            .enumerate()
            .filter(|(i, _)| !(p.ref_free_hip_yaw && i % 6 == LEG_HIP_YAW))
            .map(|(_, (r, q))| q - r),
    );
    (-2.0 * d).exp() - 0.2 * d.min(0.5)
}

fn stand_still(s: &EnvState, _: &RewardParams) -> f64 {
    let cmd = s.command[0].hypot(s.command[1]);
    if cmd <= 0.2 {
        return 0.0;
    }
    let along = (s.base_lin_vel[0] * s.command[0] + s.base_lin_vel[1] * s.command[1]) / cmd;
    (along < 0.25 * cmd) as u8 as f64
}

/// The configured terms resolved to functions once, with per-term episode sums.
#[derive(Clone)]
pub struct RewardSet {
    terms: Vec<(&'static Term, f64)>,
    pub params: RewardParams,
    pub only_positive: bool,
    /// Multiplier of the negative-weight terms (penalty curriculum; 1 without one).
    pub penalty_scale: f64,
}

impl RewardSet {
    /// Resolve `name: weight` pairs; the config was validated, but this checks again.
    pub fn new(cfg: &RewardConfig) -> Result<RewardSet, String> {
        let terms = cfg
            .terms
            .iter()
            .map(|(name, &w)| {
                lookup(name).map(|t| (t, w)).ok_or_else(|| {
                    format!(
                        "unknown reward term '{name}'; valid: {}",
                        names().join(", ")
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(RewardSet {
            terms,
            params: cfg.params.clone(),
            only_positive: cfg.only_positive,
            penalty_scale: cfg.penalty_curriculum.as_ref().map_or(1.0, |p| p.initial),
        })
    }

    pub fn len(&self) -> usize {
        self.terms.len()
    }

    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    pub fn names(&self) -> Vec<&'static str> {
        self.terms.iter().map(|(t, _)| t.name).collect()
    }

    /// Total reward of one step; adds each weighted term into `sums` (same order as `names`).
    #[inline]
    pub fn compute(&self, s: &EnvState, sums: &mut [f64]) -> f64 {
        let mut total = 0.0;
        for (i, (term, w)) in self.terms.iter().enumerate() {
            let w = if *w < 0.0 { w * self.penalty_scale } else { *w };
            let r = (term.f)(s, &self.params) * w * s.dt;
            sums[i] += r;
            total += r;
        }
        if self.only_positive {
            total.max(0.0)
        } else {
            total
        }
    }
}

/// Reward terms by name with their weights, and the parameters they share.
/// Every term's value is multiplied by `weight * dt` (legged_gym / mjlab).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RewardConfig {
    /// `name: weight`; an unknown name is a load error that lists the valid ones.
    pub terms: BTreeMap<String, f64>,
    #[serde(default)]
    pub params: RewardParams,
    /// Clip the per-step total at zero from below (legged_gym's only_positive_rewards).
    #[serde(default)]
    pub only_positive: bool,
    /// Scale the penalties (negative weights) up as the policy learns to stay up.
    #[serde(default)]
    pub penalty_curriculum: Option<PenaltyCurriculum>,
}

/// Penalty curriculum: every negative-weight term is multiplied by a scale that
/// starts at `initial` and rises by `step` (up to 1) after each PPO iteration
/// whose mean episode length reaches `length_frac` of the time limit. Early on,
/// a random policy's joint-velocity, acceleration and tumbling penalties outweigh
/// every positive term, so ending the episode fast is what pays; a small scale
/// makes staying up pay first.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PenaltyCurriculum {
    pub initial: f64,
    pub step: f64,
    pub length_frac: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RewardParams {
    /// Width of the exp kernels of the tracking terms.
    pub tracking_sigma: f64,
    /// Pelvis height above the terrain that `base_height` aims for (m).
    pub base_height_target: f64,
    /// Air time (s) at touchdown that `feet_air_time` rewards above.
    pub feet_air_time_target: f64,
    /// Contact force (N) above which a body counts as colliding.
    pub collision_force: f64,
    /// Target lateral distance between the feet / knees (m).
    pub feet_distance_target: f64,
    /// Swing-foot clearance target (m) for `foot_height`.
    pub foot_clearance_target: f64,
    /// Terrain level from which `feet_edge` applies (the paper's "level > 3").
    pub feet_edge_min_level: usize,
    /// Depth (m) of the support surface above the terrain under a heel or toe
    /// from which `feet_gap` counts the foot as over a pit.
    pub feet_gap_depth: f64,
    /// Height span (m) of the terrain under the sole's corners from which
    /// `feet_straddle` counts the foot as across an edge.
    pub straddle_height: f64,
    /// How far ahead of a foot along the heading (m) the swing terms
    /// (`foot_height`, `feet_swing_height`, `foot_clearance`,
    /// `feet_swing_clock`) look for the ground they measure its height from:
    /// the highest support surface within it, so that a foot swinging at a
    /// raised block is asked to clear the block's top, not the floor it left
    /// (0: the ground under the foot).
    pub swing_lookahead: f64,
    /// Fraction of the gait period a leg is in stance (`gait_contact`).
    pub gait_stance_ratio: f64,
    /// Swing-foot height above the ground that `feet_swing_height` aims for (m).
    pub swing_height_target: f64,
    /// Width of the `upright` kernel.
    pub upright_sigma: f64,
    /// Cap (s) of the single-support time that `feet_air_time_biped` pays.
    pub feet_air_time_threshold: f64,
    /// Width of the `foot_clearance` kernel (m^2 s^-0; Isaac Lab's Spot: 0.05).
    pub clearance_sigma: f64,
    /// Ankle height above the ground in stance (m): the base of `feet_swing_clock`'s
    /// target (the G1's ankle sits 0.036 m above the sole, `eval`'s stance_foot_height).
    pub ankle_stance_height: f64,
    /// Sole clearance at mid-swing that `feet_swing_clock` asks for (m).
    pub swing_clock_height: f64,
    /// Hip-pitch flexion at mid-swing of `ref_joint_pos`'s reference (rad; the
    /// knee flexes twice this, the ankle pitch as much as the hip).
    pub ref_swing_amplitude: f64,
    /// Stance narrowing of the reference pose (rad): `ref_joint_pos`'s reference
    /// and `hip_pos`'s target adduct each hip roll by this much (left -r, right
    /// +r; the G1's roll axes point forward) and roll each ankle back by as much,
    /// so the sole stays level. The feet come in by about 0.65 m x r each (0:
    /// the default pose's 0.24 m between the ankles).
    pub ref_stance_roll: f64,
    /// Leave the hip yaw joints out of `ref_joint_pos`'s distance. A turn
    /// rotates the pelvis over a planted foot, so the stance hip yaw drifts by
    /// the turn rate times the stance time (0.44 rad a stance at 1 rad/s and a
    /// 0.8 s gait): a reference that holds it at the default pose pays against
    /// every turn (`hip_pos` still keeps it near the default).
    pub ref_free_hip_yaw: bool,
}

impl Default for RewardParams {
    fn default() -> Self {
        RewardParams {
            tracking_sigma: 0.25,
            base_height_target: 0.78,
            feet_air_time_target: 0.5,
            collision_force: 0.1,
            feet_distance_target: 0.22,
            foot_clearance_target: 0.08,
            feet_edge_min_level: 3,
            feet_gap_depth: 0.02,
            straddle_height: 0.02,
            swing_lookahead: 0.0,
            gait_stance_ratio: 0.55,
            swing_height_target: 0.08,
            upright_sigma: 0.2,
            feet_air_time_threshold: 0.4,
            clearance_sigma: 0.05,
            ankle_stance_height: 0.036,
            swing_clock_height: 0.10,
            ref_swing_amplitude: 0.3,
            ref_stance_roll: 0.0,
            ref_free_hip_yaw: false,
        }
    }
}

impl RewardConfig {
    /// Known term names and a sane penalty curriculum.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        for name in self.terms.keys() {
            if lookup(name).is_none() {
                return bad(format!(
                    "unknown reward term '{name}' in env.rewards.terms; valid terms: {}",
                    names().join(", ")
                ));
            }
        }
        if let Some(pc) = &self.penalty_curriculum {
            if !(0.0..=1.0).contains(&pc.initial)
                || pc.step.is_nan()
                || pc.step < 0.0
                || !(0.0..=1.0).contains(&pc.length_frac)
            {
                return bad(format!(
                    "env.rewards.penalty_curriculum needs initial and length_frac in [0, 1] and step >= 0, got {pc:?}"
                ));
            }
        }
        Ok(())
    }
}
