//! Left/right mirror maps of the G1's observations and actions, for symmetry
//! augmentation (rsl_rl's data augmentation): the mirrored buffer is
//! `out[i] = sign[i] * x[perm[i]]`.
//!
//! Mirroring swaps left and right joints and negates roll and yaw joints (the
//! waist's included); angular velocity `[-wx, wy, -wz]`, gravity and linear
//! velocity negate `y`, the command `[vx, -vy, -wz]`, the gait clock moves by
//! half a period (`[sin, cos] -> [-sin, -cos]`: the legs swap phases), the feet
//! forces swap feet with `y` negated, and the scandot grid flips across `y`.
//! `tests/mirror.rs` checks the maps against the physics.
use super::obs::{
    ANG_VEL, COMMAND, CRITIC_DIM, DOF_POS, DOF_VEL, GRAVITY, LAST_ACTION, OBS_DIM, PHASE, SCAN_DIM,
    SCAN_NX, SCAN_NY,
};
use crate::robot::{JOINT_NAMES, NUM_JOINTS};

/// A signed permutation of a buffer's floats.
#[derive(Debug, Clone, PartialEq)]
pub struct SignedPerm {
    pub perm: Vec<usize>,
    pub sign: Vec<f32>,
}

impl SignedPerm {
    fn identity(n: usize) -> SignedPerm {
        SignedPerm {
            perm: (0..n).collect(),
            sign: vec![1.0; n],
        }
    }

    /// Mirror one row.
    pub fn apply(&self, x: &[f32], out: &mut [f32]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.sign[i] * x[self.perm[i]];
        }
    }

    /// The same map over `k` consecutive blocks of this size.
    pub fn tiled(&self, k: usize) -> SignedPerm {
        let n = self.perm.len();
        let mut t = SignedPerm {
            perm: Vec::with_capacity(n * k),
            sign: Vec::with_capacity(n * k),
        };
        for b in 0..k {
            t.perm.extend(self.perm.iter().map(|p| p + b * n));
            t.sign.extend(&self.sign);
        }
        t
    }

    fn set(&mut self, i: usize, from: usize, sign: f32) {
        self.perm[i] = from;
        self.sign[i] = sign;
    }
}

/// The mirror maps of every buffer of the G1 env.
#[derive(Debug, Clone, PartialEq)]
pub struct Mirror {
    pub obs: SignedPerm,
    pub critic: SignedPerm,
    pub scan: SignedPerm,
    pub action: SignedPerm,
}

/// Joints: the mirror partner of each and whether its angle flips sign.
pub fn joints() -> SignedPerm {
    let mut m = SignedPerm::identity(NUM_JOINTS);
    for (i, name) in JOINT_NAMES.iter().enumerate() {
        let partner = if let Some(rest) = name.strip_prefix("left_") {
            format!("right_{rest}")
        } else if let Some(rest) = name.strip_prefix("right_") {
            format!("left_{rest}")
        } else {
            name.to_string()
        };
        let j = JOINT_NAMES
            .iter()
            .position(|n| *n == partner)
            .expect("every G1 joint has a mirror partner");
        let flips = name.contains("roll") || name.contains("yaw");
        m.set(i, j, if flips { -1.0 } else { 1.0 });
    }
    m
}

impl Mirror {
    pub fn g1() -> Mirror {
        let j = joints();
        let mut obs = SignedPerm::identity(OBS_DIM);
        let vec3 = |m: &mut SignedPerm, at: usize, s: [f32; 3]| {
            for a in 0..3 {
                m.set(at + a, at + a, s[a]);
            }
        };
        vec3(&mut obs, ANG_VEL.start, [-1.0, 1.0, -1.0]);
        vec3(&mut obs, GRAVITY.start, [1.0, -1.0, 1.0]);
        vec3(&mut obs, COMMAND.start, [1.0, -1.0, -1.0]);
        for r in [DOF_POS, DOF_VEL, LAST_ACTION] {
            for i in 0..NUM_JOINTS {
                obs.set(r.start + i, r.start + j.perm[i], j.sign[i]);
            }
        }
        obs.set(PHASE.start, PHASE.start, -1.0);
        obs.set(PHASE.start + 1, PHASE.start + 1, -1.0);

        let mut critic = SignedPerm::identity(CRITIC_DIM);
        critic.perm[..OBS_DIM].copy_from_slice(&obs.perm);
        critic.sign[..OBS_DIM].copy_from_slice(&obs.sign);
        let p = OBS_DIM;
        vec3(&mut critic, p, [1.0, -1.0, 1.0]); // base linear velocity
        for a in 0..3 {
            let s = if a == 1 { -1.0 } else { 1.0 };
            critic.set(p + 4 + a, p + 7 + a, s); // left foot <- right foot
            critic.set(p + 7 + a, p + 4 + a, s);
        }

        let mut scan = SignedPerm::identity(SCAN_DIM);
        for ix in 0..SCAN_NX {
            for iy in 0..SCAN_NY {
                scan.set(ix * SCAN_NY + iy, ix * SCAN_NY + (SCAN_NY - 1 - iy), 1.0);
            }
        }
        Mirror {
            obs,
            critic,
            scan,
            action: j,
        }
    }
}
