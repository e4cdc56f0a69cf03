//! The four body-space tracking terms of the unified policy (the paper's
//! appendix table, BeyondMimic's form): for the tracked bodies `B`,
//! `ē_s = mean_b ||e_{s,b}||²` and the score `exp(−ē_s / σ_s²)` for
//! position, orientation (`log(R_des R^T)`), linear and angular velocity, all in
//! the heading frame ([`super::fk`]).
use serde::{Deserialize, Serialize};

use super::fk::{quat_conj, quat_log, quat_mul, BodyFrames, N_TRACKED};

/// Tolerances σ of the four terms (BeyondMimic's: 0.3 m, 0.4 rad, 1.0 m/s,
/// π rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingSigmas {
    pub pos: f64,
    pub ori: f64,
    pub lin_vel: f64,
    pub ang_vel: f64,
}

impl Default for TrackingSigmas {
    fn default() -> Self {
        TrackingSigmas {
            pos: 0.3,
            ori: 0.4,
            lin_vel: 1.0,
            ang_vel: std::f64::consts::PI,
        }
    }
}

/// Mean squared errors `ē` of the four terms.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackingErrors {
    pub pos: f64,
    pub ori: f64,
    pub lin_vel: f64,
    pub ang_vel: f64,
}

fn sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum()
}

impl TrackingErrors {
    /// The errors of `actual` against the plan's `desired` bodies.
    pub fn between(desired: &BodyFrames, actual: &BodyFrames) -> TrackingErrors {
        let mut e = TrackingErrors::default();
        for b in 0..N_TRACKED {
            e.pos += sq(desired.pos[b], actual.pos[b]);
            let r = quat_log(quat_mul(desired.quat[b], quat_conj(actual.quat[b])));
            e.ori += r.iter().map(|v| v * v).sum::<f64>();
            e.lin_vel += sq(desired.lin_vel[b], actual.lin_vel[b]);
            e.ang_vel += sq(desired.ang_vel[b], actual.ang_vel[b]);
        }
        let n = N_TRACKED as f64;
        TrackingErrors {
            pos: e.pos / n,
            ori: e.ori / n,
            lin_vel: e.lin_vel / n,
            ang_vel: e.ang_vel / n,
        }
    }

    /// The four scores `exp(−ē / σ²)`: position, orientation, linear and
    /// angular velocity, each in `(0, 1]`.
    pub fn scores(&self, s: &TrackingSigmas) -> [f64; 4] {
        [
            (-self.pos / (s.pos * s.pos)).exp(),
            (-self.ori / (s.ori * s.ori)).exp(),
            (-self.lin_vel / (s.lin_vel * s.lin_vel)).exp(),
            (-self.ang_vel / (s.ang_vel * s.ang_vel)).exp(),
        ]
    }
}
