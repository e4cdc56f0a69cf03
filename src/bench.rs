//! `dreampolicy bench ...`: speed measured as ratios against a baseline taken in
//! the same run, on the same scene (never asserted in tests).
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use crate::robot;
use crate::sim::{self, Data, SimError};

/// Result of `bench sim`.
#[derive(Debug, Clone, Serialize)]
pub struct SimBench {
    pub mujoco_version: String,
    pub scene: String,
    pub steps_per_round: usize,
    pub rounds: usize,
    /// Raw `mj_step` through the FFI, no checks (the baseline).
    pub raw_steps_per_s: f64,
    /// Our `Data::step`: `mj_step` + instability check.
    pub safe_steps_per_s: f64,
    /// safe / raw; the goal is >= 0.98.
    pub ratio: f64,
}

/// Step the standing G1 on flat ground `steps` times per round, alternating the
/// raw loop and the safe loop for `rounds` rounds (so drift in machine load hits
/// both), each round starting from the same keyframe. Rates use the best round
/// of each, the usual way to take the noise of a shared machine out.
pub fn sim(steps: usize, rounds: usize) -> Result<SimBench, SimError> {
    let model = Arc::new(robot::load_flat()?);
    let g1 = robot::G1::resolve(&model)?;
    let mut data = Data::new(model.clone())?;
    let (mut best_raw, mut best_safe) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..rounds.max(1) {
        data.reset_keyframe(g1.stand_key)?;
        let (m, d) = data.as_raw_ptrs();
        let t = Instant::now();
        for _ in 0..steps {
            // SAFETY: m and d belong together and outlive the loop.
            unsafe { mujoco_sys::mj_step(m, d) };
        }
        best_raw = best_raw.min(t.elapsed().as_secs_f64());

        data.reset_keyframe(g1.stand_key)?;
        let t = Instant::now();
        for _ in 0..steps {
            data.step()?;
        }
        best_safe = best_safe.min(t.elapsed().as_secs_f64());
    }
    let raw = steps as f64 / best_raw;
    let safe = steps as f64 / best_safe;
    Ok(SimBench {
        mujoco_version: sim::mujoco_version(),
        scene: model.source().to_string(),
        steps_per_round: steps,
        rounds,
        raw_steps_per_s: raw,
        safe_steps_per_s: safe,
        ratio: safe / raw,
    })
}
