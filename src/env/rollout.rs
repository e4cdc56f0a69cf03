//! `dreampolicy rollout`: drive a `VecEnv` with a fixed policy (zero actions or
//! uniform noise) and report what the env does: per-term episode rewards, episode
//! lengths, falls, time-outs, blow-ups, terrain levels. The sanity check to run
//! before training on a new config, and the main job until a trainer exists.
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::config::EnvConfig;
use super::{EnvError, VecEnv};
use crate::robot::NUM_JOINTS;
use crate::run::{Progress, RunDir, RunError};

/// The fixed policy of a rollout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FixedPolicy {
    /// All actions 0: the robot holds its default pose.
    Zero,
    /// Uniform in [-1, 1] per joint and step.
    Random,
}

/// What a rollout saw.
#[derive(Debug, Clone, Serialize)]
pub struct RolloutSummary {
    pub steps: usize,
    pub n_envs: usize,
    pub episodes: usize,
    pub falls: usize,
    pub truncations: usize,
    pub blowups: usize,
    pub warnings: u64,
    pub mean_reward_per_step: f64,
    pub mean_terrain_level: f64,
    /// Mean over finished episodes of each term's episode sum per second.
    pub terms: Vec<(String, f64)>,
}

/// Errors of a rollout.
#[derive(Debug, thiserror::Error)]
pub enum RolloutError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Run(#[from] RunError),
}

/// Run `steps` batch steps of `policy` on the env `cfg`, logging every `log_every`
/// steps to `run` (if given) and to a progress bar.
pub fn rollout(
    cfg: &EnvConfig,
    steps: usize,
    policy: FixedPolicy,
    mut run: Option<&mut RunDir>,
    log_every: usize,
    quiet: bool,
) -> Result<RolloutSummary, RolloutError> {
    let mut env = VecEnv::new(cfg)?;
    let n = env.n_envs();
    let names = env.shared().rewards.names();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5EED_F0A1);
    let mut actions = vec![0.0f32; n * NUM_JOINTS];
    let mut s = RolloutSummary {
        steps,
        n_envs: n,
        episodes: 0,
        falls: 0,
        truncations: 0,
        blowups: 0,
        warnings: 0,
        mean_reward_per_step: 0.0,
        mean_terrain_level: 0.0,
        terms: names.iter().map(|n| (n.to_string(), 0.0)).collect(),
    };
    let mut window_reward = 0.0;
    let progress = Progress::new("rollout", steps as u64, quiet);
    for t in 1..=steps {
        if policy == FixedPolicy::Random {
            actions
                .iter_mut()
                .for_each(|a| *a = rng.random_range(-1.0..=1.0));
        }
        let info = env.step(&actions);
        s.blowups += info.blowups;
        s.warnings += info.warnings;
        s.mean_reward_per_step += info.mean_reward;
        window_reward += info.mean_reward;
        for o in &env.outcomes {
            s.falls += o.terminated as usize;
            s.truncations += o.truncated as usize;
        }
        if let Some(terms) = env.finished_episode_terms() {
            let done = info.episodes_done;
            for ((_, total), (_, v)) in s.terms.iter_mut().zip(&terms) {
                *total += v * done as f64;
            }
            s.episodes += done;
        }
        if t % log_every == 0 || t == steps {
            let level = env.mean_terrain_level();
            let row = [
                t as f64,
                window_reward / log_every as f64,
                s.episodes as f64,
                s.falls as f64,
                s.blowups as f64,
                level,
            ];
            if let Some(run) = run.as_deref_mut() {
                run.metrics_row(&row)?;
            }
            progress.set(
                t as u64,
                &format!(
                    "reward/step {:.4} episodes {} level {level:.2}",
                    row[1], s.episodes
                ),
            );
            window_reward = 0.0;
        }
    }
    progress.finish();
    s.mean_reward_per_step /= steps.max(1) as f64;
    s.mean_terrain_level = env.mean_terrain_level();
    if s.episodes > 0 {
        for (_, v) in s.terms.iter_mut() {
            *v /= s.episodes as f64;
        }
    }
    Ok(s)
}

/// Columns of a rollout's `metrics.csv`.
pub const METRICS: [&str; 6] = [
    "step",
    "reward_per_step",
    "episodes",
    "falls",
    "blowups",
    "mean_level",
];
