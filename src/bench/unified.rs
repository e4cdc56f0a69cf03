//! `bench unified`: PPO iterations with the world model in the loop (the
//! unified task), their env-steps/s and the world model's share of them, beside
//! the same iterations of the bare G1 env measured in the same run (the same
//! env, policy sizes and PPO; the policy reads scandots instead of the plan,
//! through the config's MLP sizes when the future encoder is a GRU).
use std::time::Instant;

use serde::Serialize;

use crate::env::task::VecTask;
use crate::env::VecEnv;
use crate::rl::config::{ExperimentConfig, ScanEncoderKind, TaskKind};
use crate::rl::runner::Trainer;
use crate::rl::RlError;
use crate::unified::config::UnifiedConfig;
use crate::unified::task::{UnifiedTask, METRICS};

/// `bench unified` output.
#[derive(Debug, Clone, Serialize)]
pub struct UnifiedBench {
    pub config: String,
    pub torch_threads: i64,
    pub n_envs: usize,
    pub num_steps: usize,
    pub replan_every: usize,
    pub sampler: String,
    pub ddim_steps: usize,
    pub guidance: f64,
    pub world_model_history: usize,
    pub world_model_horizon: usize,
    /// `mlp` or `gru` (`policy.scan_encoder.kind`): the future encoder.
    pub future_encoder: String,
    pub iterations: usize,
    /// Env-steps per second of whole iterations with the world model in the loop.
    pub env_steps_per_s: f64,
    /// The world model's sampling over the iteration's wall time.
    pub share_world_model: f64,
    /// Physics and the task's own per-step work (kinematics, tracking, the
    /// discriminator's style reward), without the world model.
    pub share_physics_and_rewards: f64,
    pub share_inference: f64,
    pub share_update: f64,
    /// The discriminator's updates and the rest of the iteration.
    pub share_other: f64,
    /// World-model plans (one env each) per second of sampling.
    pub plans_per_s: f64,
    /// The same iterations on the bare env, this run.
    pub env_only_steps_per_s: f64,
    /// `env_steps_per_s / env_only_steps_per_s`.
    pub ratio_to_env_only: f64,
}

struct Timed {
    wall: f64,
    physics: f64,
    inference: f64,
    update: f64,
    wm: f64,
    plans: f64,
    steps: f64,
}

fn time_iterations<T: VecTask>(
    cfg: &ExperimentConfig,
    task: &mut T,
    warmup: usize,
    iterations: usize,
) -> Result<Timed, RlError> {
    let wm_at = |name: &str| METRICS.iter().position(|m| *m == name);
    let mut tr = Trainer::new(cfg, task, None)?;
    for _ in 0..warmup {
        tr.iterate()?;
    }
    let mut t = Timed {
        wall: 0.0,
        physics: 0.0,
        inference: 0.0,
        update: 0.0,
        wm: 0.0,
        plans: 0.0,
        steps: 0.0,
    };
    for _ in 0..iterations {
        let before = tr.times;
        let start = Instant::now();
        let (_, rs) = tr.iterate()?;
        t.wall += start.elapsed().as_secs_f64();
        t.physics += tr.times.physics - before.physics;
        t.inference += tr.times.inference - before.inference;
        t.update += tr.times.update - before.update;
        if let (Some(w), Some(p)) = (wm_at("wm_time_s"), wm_at("wm_plans")) {
            if rs.extra.len() == METRICS.len() {
                t.wm += rs.extra[w];
                t.plans += rs.extra[p];
            }
        }
        t.steps += (cfg.ppo.num_steps * tr.task.n_envs()) as f64;
    }
    Ok(t)
}

/// Measure `iterations` PPO iterations (after `warmup`) of the unified config
/// `cfg`, then of its bare env.
pub fn bench_unified(
    cfg: &ExperimentConfig,
    label: &str,
    warmup: usize,
    iterations: usize,
) -> Result<UnifiedBench, RlError> {
    let u = UnifiedConfig::of(cfg)?;
    let mut task = UnifiedTask::new(cfg)?;
    let (k, h) = (task.history_len(), task.horizon());
    let n = task.n_envs();
    let uni = time_iterations(cfg, &mut task, warmup, iterations)?;
    drop(task);
    let mut base = cfg.clone();
    base.task = TaskKind::G1;
    base.unified = None;
    base.policy.scan_encoder.kind = ScanEncoderKind::Mlp;
    let mut env = VecEnv::new(&base.env)?;
    let bare = time_iterations(&base, &mut env, warmup, iterations)?;
    let sps = uni.steps / uni.wall;
    let env_only = bare.steps / bare.wall;
    Ok(UnifiedBench {
        config: label.to_string(),
        torch_threads: cfg.train.torch_threads,
        n_envs: n,
        num_steps: cfg.ppo.num_steps,
        replan_every: u.replan_every,
        sampler: format!("{:?}", u.sampling.sampler).to_lowercase(),
        ddim_steps: u.sampling.ddim_steps,
        guidance: u.sampling.guidance,
        world_model_history: k,
        world_model_horizon: h,
        future_encoder: format!("{:?}", cfg.policy.scan_encoder.kind).to_lowercase(),
        iterations,
        env_steps_per_s: sps,
        share_world_model: uni.wm / uni.wall,
        share_physics_and_rewards: (uni.physics - uni.wm) / uni.wall,
        share_inference: uni.inference / uni.wall,
        share_update: uni.update / uni.wall,
        share_other: (uni.wall - uni.physics - uni.inference - uni.update) / uni.wall,
        plans_per_s: if uni.wm > 0.0 {
            uni.plans / uni.wm
        } else {
            f64::NAN
        },
        env_only_steps_per_s: env_only,
        ratio_to_env_only: sps / env_only,
    })
}
