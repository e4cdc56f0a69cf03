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
//! the points of `env.observation.scan_grid` in the yaw-aligned pelvis frame:
//! `x = x0 + spacing * ix`, `y = y0 + spacing * iy`, index = `ix * 11 + iy`
//! (x-major, x from back to front, y from right to left). The default grid
//! ([`ScanGrid::default`]) spans `x` in -0.6..=1.0 and `y` in -0.5..=0.5, 0.1 m
//! apart; the count is fixed, the spacing and origin are the config's.
use rand::Rng;

use super::scene::BucketParams;
use super::state::EnvState;
use crate::env::config::ObservationConfig;
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
pub use crate::env::config::ScanGrid;

impl ScanGrid {
    /// Scan point `k` in the yaw-aligned pelvis frame.
    #[inline]
    pub fn point(&self, k: usize) -> (f64, f64) {
        let (ix, iy) = (k / SCAN_NY, k % SCAN_NY);
        (
            self.x0 + self.spacing * ix as f64,
            self.y0 + self.spacing * iy as f64,
        )
    }

    /// The grid's far corner `(x, y)`: `x0 + 16 spacing`, `y0 + 10 spacing`.
    pub fn far_corner(&self) -> (f64, f64) {
        self.point(SCAN_DIM - 1)
    }
}

/// Scan point `k` of the default grid, in the yaw-aligned pelvis frame.
#[inline]
pub fn scan_point(k: usize) -> (f64, f64) {
    ScanGrid::default().point(k)
}

/// Scandot `k` of `grid` without noise or scale: the ground height at the
/// point's world position minus the pelvis height (m), clipped to `+-clip`. The
/// pelvis is at `base_pos` with yaw `(sin, cos)`.
pub fn scan_height(
    ground: &dyn Fn(f64, f64) -> f64,
    grid: &ScanGrid,
    base_pos: [f64; 3],
    (sy, cy): (f64, f64),
    k: usize,
    clip: f64,
) -> f64 {
    let (px, py) = grid.point(k);
    let x = base_pos[0] + cy * px - sy * py;
    let y = base_pos[1] + sy * px + cy * py;
    (ground(x, y) - base_pos[2]).clamp(-clip, clip)
}

/// The noise-free scandots of `grid` into `out` ([`SCAN_DIM`]), times `scale`:
/// [`scan_height`] at every point (what `collect` records and the world model's
/// map terrain conditions on).
pub fn scan_row(
    ground: &dyn Fn(f64, f64) -> f64,
    grid: &ScanGrid,
    base_pos: [f64; 3],
    yaw: (f64, f64),
    clip: f64,
    scale: f64,
    out: &mut [f32],
) {
    for (k, v) in out.iter_mut().enumerate() {
        *v = (scan_height(ground, grid, base_pos, yaw, k, clip) * scale) as f32;
    }
}

const _: () = assert!(OBS_DIM == 98, "the paper's state is 98 floats");
const _: () = assert!(SCAN_DIM == 187, "the paper's scandots are 187 floats");

/// What [`write`] reads for one env.
pub struct ObsContext<'a> {
    pub state: &'a EnvState,
    pub cfg: &'a ObservationConfig,
    /// Time since the episode started (s), for the gait phase.
    pub time: f64,
    /// Robot weight (N) that normalizes the feet forces.
    pub robot_weight: f64,
    pub bucket: BucketParams,
    pub latency: usize,
    /// Ground height at a world point, as this env's physics sees it.
    pub ground: &'a dyn Fn(f64, f64) -> f64,
}

/// Write one env's actor observation (`OBS_DIM`, with noise), critic observation
/// (`CRITIC_DIM`, noise-free state + privileged block) and scandots (`SCAN_DIM`), in
/// the layout of this module's doc. Every value is clipped; nothing allocates.
pub fn write(
    ctx: &ObsContext<'_>,
    rng: &mut impl Rng,
    obs: &mut [f32],
    critic: &mut [f32],
    scan: &mut [f32],
) {
    let (s, oc) = (ctx.state, ctx.cfg);
    let sc = &oc.scales;
    let clip = oc.clip;
    let put = |buf: &mut [f32], i: usize, v: f64| buf[i] = v.clamp(-clip, clip) as f32;
    // the noise-free state, into the critic's first OBS_DIM entries
    for a in 0..3 {
        put(critic, ANG_VEL.start + a, s.base_ang_vel[a] * sc.ang_vel);
        put(critic, GRAVITY.start + a, s.gravity[a]);
        put(critic, COMMAND.start + a, s.command[a] * sc.commands[a]);
    }
    for j in 0..NUM_JOINTS {
        put(
            critic,
            DOF_POS.start + j,
            (s.q[j] - s.default_q[j]) * sc.dof_pos,
        );
        put(critic, DOF_VEL.start + j, s.qd[j] * sc.dof_vel);
        put(critic, LAST_ACTION.start + j, s.action[j]);
    }
    let phase = 2.0 * std::f64::consts::PI * (ctx.time / oc.gait_period_s).fract();
    put(critic, PHASE.start, phase.sin());
    put(critic, PHASE.start + 1, phase.cos());
    // the privileged block
    let p = OBS_DIM;
    for a in 0..3 {
        put(critic, p + a, s.base_lin_vel[a] * sc.lin_vel);
    }
    put(critic, p + 3, s.base_height);
    for k in 0..2 {
        for a in 0..3 {
            put(
                critic,
                p + 4 + 3 * k + a,
                s.feet_force[k][a] / ctx.robot_weight,
            );
        }
    }
    put(critic, p + 10, ctx.bucket.friction);
    put(critic, p + 11, ctx.bucket.added_mass);
    put(critic, p + 12, ctx.bucket.motor_strength);
    put(critic, p + 13, ctx.latency as f64);
    debug_assert_eq!(p + 14, CRITIC_DIM);

    // the actor: the critic's state plus noise
    obs.copy_from_slice(&critic[..OBS_DIM]);
    if oc.add_noise {
        let (n, lvl) = (&oc.noise, oc.noise_level);
        let mut add = |r: std::ops::Range<usize>, width: f64| {
            for i in r {
                let e = rng.random_range(-1.0..=1.0) * width * lvl;
                obs[i] = (obs[i] as f64 + e).clamp(-clip, clip) as f32;
            }
        };
        add(ANG_VEL, n.ang_vel * sc.ang_vel);
        add(GRAVITY, n.gravity);
        add(DOF_POS, n.dof_pos * sc.dof_pos);
        add(DOF_VEL, n.dof_vel * sc.dof_vel);
    }

    // scandots in the yaw-aligned frame
    let yaw = s.yaw.sin_cos();
    let noise = if oc.add_noise {
        oc.noise.scan * oc.noise_level
    } else {
        0.0
    };
    for (k, out) in scan.iter_mut().enumerate().take(SCAN_DIM) {
        let rel = scan_height(ctx.ground, &oc.scan_grid, s.base_pos, yaw, k, oc.scan_clip);
        let e = if noise > 0.0 {
            rng.random_range(-noise..=noise)
        } else {
            0.0
        };
        *out = ((rel + e) * sc.scan) as f32;
    }
}
