//! `VecTask`: what the PPO runner needs from a batch of environments. The G1
//! `VecEnv` implements it; so does the cart-pole of `env::cartpole`.
use serde::{Deserialize, Serialize};

use super::{Outcome, StepInfo, VecEnv};

/// Sizes of a task's buffers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TaskDims {
    /// Actor observation per env.
    pub obs: usize,
    /// Critic observation per env.
    pub critic: usize,
    /// Scandots per env (0 when the task has none).
    pub scan: usize,
    pub action: usize,
}

/// What a checkpoint keeps of one env to restart it exactly: its RNG and its
/// curriculum level. Checkpoints are taken at an episode boundary of every env
/// (the runner resets them all right after saving), so nothing else is needed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvSnapshot {
    pub rng_seed: [u8; 32],
    pub rng_stream: u64,
    pub rng_word_pos: u128,
    pub level: usize,
}

impl EnvSnapshot {
    /// The snapshot of an env's RNG and level.
    pub fn new(rng: &rand_chacha::ChaCha8Rng, level: usize) -> EnvSnapshot {
        EnvSnapshot {
            rng_seed: rng.get_seed(),
            rng_stream: rng.get_stream(),
            rng_word_pos: rng.get_word_pos(),
            level,
        }
    }

    /// The RNG, exactly where it was.
    pub fn rng(&self) -> rand_chacha::ChaCha8Rng {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::from_seed(self.rng_seed);
        rng.set_stream(self.rng_stream);
        rng.set_word_pos(self.rng_word_pos);
        rng
    }

    /// Check that `snaps` holds one snapshot per env of a batch of `n`.
    pub fn check_count(snaps: &[EnvSnapshot], n: usize) -> Result<(), String> {
        if snaps.len() == n {
            Ok(())
        } else {
            Err(format!(
                "snapshot of {} envs for a batch of {n}",
                snaps.len()
            ))
        }
    }
}

/// A batch of environments over contiguous `[n, dim]` f32 buffers with auto-reset.
pub trait VecTask {
    fn dims(&self) -> TaskDims;
    fn n_envs(&self) -> usize;
    /// Actor observations `[n, obs]` after the last step.
    fn obs(&self) -> &[f32];
    fn critic(&self) -> &[f32];
    /// Scandots `[n, scan]` (empty when `dims().scan == 0`).
    fn scan(&self) -> &[f32];
    /// Critic observations and scandots at the end of the episodes that ended in
    /// the last step (for bootstrapping truncations); other rows are stale.
    fn final_critic(&self) -> &[f32];
    fn final_scan(&self) -> &[f32];
    fn outcomes(&self) -> &[Outcome];
    fn step(&mut self, actions: &[f32]) -> StepInfo;
    /// Reset every env and write first observations.
    fn reset_all(&mut self);
    fn snapshot(&self) -> Vec<EnvSnapshot>;
    /// Restore RNGs and levels (then call [`VecTask::reset_all`]).
    fn restore(&mut self, snaps: &[EnvSnapshot]) -> Result<(), String>;
    /// Names of the logged reward terms.
    fn reward_names(&self) -> Vec<&'static str>;
    /// Per-term means over the episodes that ended in the last step (per second).
    fn finished_episode_terms(&self) -> Option<Vec<(&'static str, f64)>>;
    /// Mean planar velocity and yaw-rate tracking errors of the batch now (NaN if none).
    fn tracking_errors(&self) -> [f64; 2];
    fn mean_level(&self) -> f64;
    /// Mean curriculum level of the envs on each terrain kind of a mixed map
    /// with a curriculum (the `level_<kind>` columns of `metrics.csv`), the
    /// kinds in [`TerrainKind::ALL`]'s order, NaN for a kind no env stands on
    /// at the moment; empty on a plane, a single-kind map or without a
    /// curriculum. The kinds are the scene's, fixed for a run.
    ///
    /// [`TerrainKind::ALL`]: crate::terrain::TerrainKind::ALL
    fn levels_by_kind(&self) -> Vec<(crate::terrain::TerrainKind, f64)> {
        Vec::new()
    }
    /// Multiplier of the penalty terms (penalty curriculum); 1 for tasks without.
    fn penalty_scale(&self) -> f64 {
        1.0
    }
    fn set_penalty_scale(&mut self, _scale: f64) {}
    /// Control steps of the episode time limit.
    fn max_episode_steps(&self) -> u64;
    /// Left/right mirror maps of the task's buffers (symmetry augmentation).
    fn mirror(&self) -> Option<crate::env::mirror::Mirror> {
        None
    }
    /// Names of the task's own metrics (`metrics.csv` columns after the reward
    /// terms): the unified task's discriminator and world model.
    fn extra_metric_names(&self) -> Vec<&'static str> {
        Vec::new()
    }
    /// Called by the trainer once per iteration, after the rollout: the task's
    /// own learning (the unified task's discriminator updates); returns the
    /// values of [`VecTask::extra_metric_names`].
    fn after_rollout(&mut self) -> Result<Vec<f64>, String> {
        Ok(Vec::new())
    }
    /// The task's learned state (named tensors) that a checkpoint keeps.
    fn state_tensors(&self) -> Vec<(String, tch::Tensor)> {
        Vec::new()
    }
    /// Restore [`VecTask::state_tensors`] from a checkpoint (`get` returns a
    /// saved tensor by name).
    fn load_state_tensors(
        &mut self,
        _get: &dyn Fn(&str) -> Option<tch::Tensor>,
    ) -> Result<(), String> {
        Ok(())
    }
}

/// Inside `impl VecTask for T`, where `T` wraps the G1 env in its field
/// `$env` (a [`VecEnv`]): the methods that pass through to it unchanged
/// (sizes, the actor state and critic rows, snapshots, reward terms, tracking
/// errors, curriculum level, penalty scale, episode length). The wrapper
/// writes the rest: dims, scan rows, outcomes, step, reset and its own state.
macro_rules! delegate_to_env {
    ($env:ident) => {
        fn n_envs(&self) -> usize {
            self.$env.n_envs()
        }
        fn obs(&self) -> &[f32] {
            &self.$env.obs
        }
        fn critic(&self) -> &[f32] {
            &self.$env.critic
        }
        fn final_critic(&self) -> &[f32] {
            &self.$env.final_critic
        }
        fn snapshot(&self) -> Vec<$crate::env::task::EnvSnapshot> {
            self.$env.snapshot()
        }
        fn restore(&mut self, snaps: &[$crate::env::task::EnvSnapshot]) -> Result<(), String> {
            self.$env.restore(snaps)
        }
        fn reward_names(&self) -> Vec<&'static str> {
            $crate::env::task::VecTask::reward_names(&self.$env)
        }
        fn finished_episode_terms(&self) -> Option<Vec<(&'static str, f64)>> {
            $crate::env::task::VecTask::finished_episode_terms(&self.$env)
        }
        fn tracking_errors(&self) -> [f64; 2] {
            $crate::env::task::VecTask::tracking_errors(&self.$env)
        }
        fn mean_level(&self) -> f64 {
            self.$env.mean_terrain_level()
        }
        fn levels_by_kind(&self) -> Vec<($crate::terrain::TerrainKind, f64)> {
            self.$env.levels_by_kind()
        }
        fn penalty_scale(&self) -> f64 {
            $crate::env::task::VecTask::penalty_scale(&self.$env)
        }
        fn set_penalty_scale(&mut self, scale: f64) {
            self.$env.set_penalty_scale(scale)
        }
        fn max_episode_steps(&self) -> u64 {
            self.$env.shared().max_episode_steps
        }
    };
}
pub(crate) use delegate_to_env;

impl VecTask for VecEnv {
    fn dims(&self) -> TaskDims {
        use crate::env::obs::{CRITIC_DIM, OBS_DIM, SCAN_DIM};
        TaskDims {
            obs: OBS_DIM,
            critic: CRITIC_DIM,
            scan: SCAN_DIM,
            action: crate::robot::NUM_JOINTS,
        }
    }
    fn n_envs(&self) -> usize {
        VecEnv::n_envs(self)
    }
    fn obs(&self) -> &[f32] {
        &self.obs
    }
    fn critic(&self) -> &[f32] {
        &self.critic
    }
    fn scan(&self) -> &[f32] {
        &self.scan
    }
    fn final_critic(&self) -> &[f32] {
        &self.final_critic
    }
    fn final_scan(&self) -> &[f32] {
        &self.final_scan
    }
    fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }
    fn step(&mut self, actions: &[f32]) -> StepInfo {
        VecEnv::step(self, actions)
    }
    fn reset_all(&mut self) {
        VecEnv::reset_all(self)
    }
    fn snapshot(&self) -> Vec<EnvSnapshot> {
        VecEnv::snapshot(self)
    }
    fn restore(&mut self, snaps: &[EnvSnapshot]) -> Result<(), String> {
        VecEnv::restore(self, snaps)
    }
    fn reward_names(&self) -> Vec<&'static str> {
        self.shared().rewards.names()
    }
    fn finished_episode_terms(&self) -> Option<Vec<(&'static str, f64)>> {
        VecEnv::finished_episode_terms(self)
    }
    fn tracking_errors(&self) -> [f64; 2] {
        let n = self.envs().len() as f64;
        let mut e = [0.0; 2];
        for env in self.envs() {
            let s = env.state();
            e[0] += (s.command[0] - s.base_lin_vel[0]).hypot(s.command[1] - s.base_lin_vel[1]);
            e[1] += (s.command[2] - s.base_ang_vel[2]).abs();
        }
        [e[0] / n, e[1] / n]
    }
    fn mean_level(&self) -> f64 {
        self.mean_terrain_level()
    }
    fn levels_by_kind(&self) -> Vec<(crate::terrain::TerrainKind, f64)> {
        VecEnv::levels_by_kind(self)
    }
    fn penalty_scale(&self) -> f64 {
        self.shared().rewards.penalty_scale
    }
    fn set_penalty_scale(&mut self, scale: f64) {
        VecEnv::set_penalty_scale(self, scale)
    }
    fn max_episode_steps(&self) -> u64 {
        self.shared().max_episode_steps
    }
    fn mirror(&self) -> Option<crate::env::mirror::Mirror> {
        Some(crate::env::mirror::Mirror::g1())
    }
}
