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

/// Result of `bench env`.
#[derive(Debug, Clone, Serialize)]
pub struct EnvBench {
    pub mujoco_version: String,
    pub config: String,
    pub n_envs: usize,
    pub control_steps: usize,
    pub decimation: usize,
    /// Raw `mj_step` on the same envs' models and states, one thread (the baseline).
    pub raw_physics_steps_per_s: f64,
    /// VecEnv env-steps/s x decimation.
    pub env_physics_steps_per_s_1t: f64,
    pub env_physics_steps_per_s_2t: f64,
    /// env (1 thread) / raw; goal >= 0.90.
    pub ratio_1t: f64,
    /// 2 threads / 1 thread; goal >= 1.85.
    pub scaling_2t: f64,
    pub scan_points_per_s_direct: f64,
    pub scan_points_per_s_ray: f64,
    /// direct / mj_ray; goal >= 20.
    pub scan_speedup: f64,
    /// Mean number of active contacts per env at the end of the env run.
    pub contacts_per_env: f64,
}

/// Measure the env against raw physics on the same scene and terrain: the
/// config's batch (threads forced to 1, then 2), zero actions (the robots stand
/// at their spawn points, as in the baseline), alternating rounds, best of each.
pub fn env(
    cfg: &crate::env::config::EnvConfig,
    label: &str,
    control_steps: usize,
    rounds: usize,
) -> Result<EnvBench, crate::env::EnvError> {
    use crate::env::{obs, VecEnv};
    let mut c1 = cfg.clone();
    c1.threads = 1;
    let mut c2 = cfg.clone();
    c2.threads = 2;
    let mut v1 = VecEnv::new(&c1)?;
    let mut v2 = VecEnv::new(&c2)?;
    let n = v1.n_envs();
    let zeros = vec![0.0f32; n * robot::NUM_JOINTS];
    let dec = cfg.sim.decimation;
    let (mut raw, mut e1, mut e2) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut contacts = 0.0;
    for _ in 0..rounds.max(1) {
        v1.reset_all();
        let t = Instant::now();
        v1.raw_physics_baseline(control_steps);
        raw = raw.min(t.elapsed().as_secs_f64());

        v1.reset_all();
        let t = Instant::now();
        for _ in 0..control_steps {
            v1.step(&zeros);
        }
        e1 = e1.min(t.elapsed().as_secs_f64());
        contacts = v1
            .envs()
            .iter()
            .map(|e| e.data().contacts().len() as f64)
            .sum::<f64>()
            / n as f64;

        v2.reset_all();
        let t = Instant::now();
        for _ in 0..control_steps {
            v2.step(&zeros);
        }
        e2 = e2.min(t.elapsed().as_secs_f64());
    }
    let physics = (n * control_steps * dec) as f64;

    // scandots: direct lookup vs one mj_ray per point, over the same points, on
    // an env that stands on the heightfield (if any; Flat-column envs use a plane)
    let env0 = v1
        .envs()
        .iter()
        .find(|e| !e.on_plane())
        .unwrap_or(&v1.envs()[0]);
    let data = env0.data();
    let base = env0.state().base_pos;
    let points: Vec<(f64, f64)> = (0..200 * obs::SCAN_DIM)
        .map(|k| {
            let (px, py) = obs::scan_point(k % obs::SCAN_DIM);
            let jitter = (k / obs::SCAN_DIM) as f64 * 0.013;
            (base[0] + px + jitter, base[1] + py - jitter)
        })
        .collect();
    let scene = &v1.shared().scene;
    let t = Instant::now();
    let mut acc = 0.0;
    for _ in 0..20 {
        for &(x, y) in &points {
            acc += scene.ground(x, y);
        }
    }
    let direct = (20 * points.len()) as f64 / t.elapsed().as_secs_f64();
    let only_ground = [1u8, 0, 0, 0, 0, 0];
    let t = Instant::now();
    for &(x, y) in &points {
        if let Some((d, _)) = data.ray(
            [x, y, base[2] + 5.0],
            [0.0, 0.0, -1.0],
            Some(&only_ground),
            true,
            None,
        ) {
            acc += d;
        }
    }
    let ray = points.len() as f64 / t.elapsed().as_secs_f64();
    std::hint::black_box(acc);

    let raw_rate = physics / raw;
    let r1 = physics / e1;
    let r2 = physics / e2;
    Ok(EnvBench {
        mujoco_version: sim::mujoco_version(),
        config: label.to_string(),
        n_envs: n,
        control_steps,
        decimation: dec,
        raw_physics_steps_per_s: raw_rate,
        env_physics_steps_per_s_1t: r1,
        env_physics_steps_per_s_2t: r2,
        ratio_1t: r1 / raw_rate,
        scaling_2t: r2 / r1,
        scan_points_per_s_direct: direct,
        scan_points_per_s_ray: ray,
        scan_speedup: direct / ray,
        contacts_per_env: contacts,
    })
}
pub mod data;
pub mod ppo;
pub mod unified;
pub mod world_model;
