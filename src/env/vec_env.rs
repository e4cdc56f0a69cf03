//! `VecEnv`: N environments over contiguous `[n_envs, dim]` f32 buffers, stepped
//! in parallel on a fixed thread pool, with auto-reset.
//!
//! Determinism: every env owns its RNG (seeded from the batch seed and its index)
//! and its `mjData`; the shared model is read-only. An env's trajectory therefore
//! depends only on its seed and actions, not on which thread steps it: the same
//! seed gives bit-identical trajectories for any thread count.
use rayon::prelude::*;

use super::locomotion::EnvOut;
use super::obs::{CRITIC_DIM, OBS_DIM, SCAN_DIM};
use super::{EnvError, EnvShared, LocoEnv, Outcome, Scene};
use crate::env::config::EnvConfig;
use crate::robot::NUM_JOINTS;

/// The batch.
pub struct VecEnv {
    shared: EnvShared,
    envs: Vec<LocoEnv>,
    pool: rayon::ThreadPool,
    /// Actor observations `[n, OBS_DIM]` after the last step (post-reset for envs that reset).
    pub obs: Vec<f32>,
    /// Critic observations `[n, CRITIC_DIM]`.
    pub critic: Vec<f32>,
    /// Scandots `[n, SCAN_DIM]`.
    pub scan: Vec<f32>,
    /// Observations at the end of the episodes that ended this step (for bootstrapping
    /// truncated ones); rows of envs that did not end are stale.
    pub final_obs: Vec<f32>,
    pub final_critic: Vec<f32>,
    pub final_scan: Vec<f32>,
    /// Per-env outcome of the last step.
    pub outcomes: Vec<Outcome>,
    warnings_seen: u64,
}

/// Batch-level summary of one step.
#[derive(Debug, Clone, Default)]
pub struct StepInfo {
    pub blowups: usize,
    /// MuJoCo warnings raised during this step (contact buffer full, ...), all envs.
    pub warnings: u64,
    pub episodes_done: usize,
    pub mean_reward: f64,
}

impl VecEnv {
    /// Build the scene and `n_envs` envs.
    pub fn new(cfg: &EnvConfig) -> Result<VecEnv, EnvError> {
        cfg.validate()?;
        let scene = Scene::build(cfg)?;
        VecEnv::with_scene(cfg, scene)
    }

    /// Build on a prepared scene (e.g. an evaluation lane).
    pub fn with_scene(cfg: &EnvConfig, scene: Scene) -> Result<VecEnv, EnvError> {
        let (n, threads) = cfg.counts();
        let shared = EnvShared::new(cfg.clone(), scene)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| EnvError::Threads(e.to_string()))?;
        let envs = pool.install(|| {
            (0..n)
                .into_par_iter()
                .map(|i| LocoEnv::new(&shared, i, env_seed(cfg.seed, i)))
                .collect::<Result<Vec<_>, _>>()
        })?;
        let mut v = VecEnv {
            shared,
            envs,
            pool,
            obs: vec![0.0; n * OBS_DIM],
            critic: vec![0.0; n * CRITIC_DIM],
            scan: vec![0.0; n * SCAN_DIM],
            final_obs: vec![0.0; n * OBS_DIM],
            final_critic: vec![0.0; n * CRITIC_DIM],
            final_scan: vec![0.0; n * SCAN_DIM],
            outcomes: vec![Outcome::default(); n],
            warnings_seen: 0,
        };
        v.reset_all();
        Ok(v)
    }

    pub fn n_envs(&self) -> usize {
        self.envs.len()
    }

    pub fn shared(&self) -> &EnvShared {
        &self.shared
    }

    pub fn envs(&self) -> &[LocoEnv] {
        &self.envs
    }

    /// The MuJoCo state of env `i`, mutable: for perturbation tools and tests
    /// (pushing a robot, forcing a blow-up). None for an index out of range.
    pub fn data_mut(&mut self, i: usize) -> Option<&mut crate::sim::Data> {
        self.envs.get_mut(i).map(|e| e.data_mut())
    }

    /// Set the multiplier of the penalty terms (penalty curriculum).
    pub fn set_penalty_scale(&mut self, scale: f64) {
        self.shared.rewards.penalty_scale = scale;
    }

    /// RNG state and curriculum level of every env (checkpoints).
    pub fn snapshot(&self) -> Vec<super::task::EnvSnapshot> {
        self.envs.iter().map(|e| e.snapshot()).collect()
    }

    /// Restore what [`VecEnv::snapshot`] took (then [`VecEnv::reset_all`]).
    pub fn restore(&mut self, snaps: &[super::task::EnvSnapshot]) -> Result<(), String> {
        super::task::EnvSnapshot::check_count(snaps, self.envs.len())?;
        for (e, s) in self.envs.iter_mut().zip(snaps) {
            e.restore(&self.shared, s)?;
        }
        Ok(())
    }

    /// Reset env `i` now (an evaluation that ends an episode itself) and write its
    /// observation rows.
    pub fn reset_env(&mut self, i: usize) {
        let (o, c, s) = (OBS_DIM, CRITIC_DIM, SCAN_DIM);
        self.envs[i].reset_and_observe(
            &self.shared,
            &mut self.obs[i * o..(i + 1) * o],
            &mut self.critic[i * c..(i + 1) * c],
            &mut self.scan[i * s..(i + 1) * s],
        );
    }

    /// Reset every env and write the first observations.
    pub fn reset_all(&mut self) {
        let sh = &self.shared;
        self.pool.install(|| {
            self.envs
                .par_iter_mut()
                .zip(self.obs.par_chunks_mut(OBS_DIM))
                .zip(self.critic.par_chunks_mut(CRITIC_DIM))
                .zip(self.scan.par_chunks_mut(SCAN_DIM))
                .for_each(|(((env, o), c), s)| env.reset_and_observe(sh, o, c, s));
        });
    }

    /// Step every env with `actions` (`[n, 29]`); envs whose episode ended are reset.
    pub fn step(&mut self, actions: &[f32]) -> StepInfo {
        assert_eq!(
            actions.len(),
            self.envs.len() * NUM_JOINTS,
            "actions must be [n_envs, {NUM_JOINTS}]"
        );
        let sh = &self.shared;
        self.pool.install(|| {
            self.envs
                .par_iter_mut()
                .zip(actions.par_chunks(NUM_JOINTS))
                .zip(self.obs.par_chunks_mut(OBS_DIM))
                .zip(self.critic.par_chunks_mut(CRITIC_DIM))
                .zip(self.scan.par_chunks_mut(SCAN_DIM))
                .zip(self.final_obs.par_chunks_mut(OBS_DIM))
                .zip(self.final_critic.par_chunks_mut(CRITIC_DIM))
                .zip(self.final_scan.par_chunks_mut(SCAN_DIM))
                .zip(self.outcomes.par_iter_mut())
                .for_each(
                    |((((((((env, a), obs), critic), scan), fo), fc), fs), out)| {
                        *out = env.step(
                            sh,
                            a,
                            EnvOut {
                                obs,
                                critic,
                                scan,
                                final_obs: fo,
                                final_critic: fc,
                                final_scan: fs,
                            },
                        );
                    },
                );
        });
        let mut info = StepInfo::default();
        let total = self.warning_total();
        info.warnings = total - self.warnings_seen;
        self.warnings_seen = total;
        for o in &self.outcomes {
            info.blowups += o.blowup as usize;
            info.episodes_done += o.episode_done as usize;
            info.mean_reward += o.reward as f64;
        }
        info.mean_reward /= self.envs.len() as f64;
        info
    }

    /// Mean of each reward term over the episodes that ended in the last step,
    /// normalized per second of episode (legged_gym's logging); None if none ended.
    pub fn finished_episode_terms(&self) -> Option<Vec<(&'static str, f64)>> {
        let names = self.shared.rewards.names();
        let mut sums = vec![0.0; names.len()];
        let mut count = 0usize;
        for (env, o) in self.envs.iter().zip(&self.outcomes) {
            if o.episode_done {
                count += 1;
                for (s, v) in sums.iter_mut().zip(env.last_episode_sums()) {
                    *s += v / self.shared.cfg.episode_length_s;
                }
            }
        }
        (count > 0).then(|| {
            names
                .into_iter()
                .zip(sums.into_iter().map(|s| s / count as f64))
                .collect()
        })
    }

    /// Benchmark baseline: raw `mj_step` on every env's own model and state with its
    /// current controls, in the env's order (each control step, each env,
    /// `decimation` steps), on the calling thread, nothing else. Returns the physics
    /// steps done. Leaves the envs mid-episode: call [`VecEnv::reset_all`] after.
    pub fn raw_physics_baseline(&mut self, control_steps: usize) -> usize {
        let decimation = self.shared.cfg.sim.decimation;
        let ptrs: Vec<_> = self.envs.iter_mut().map(|e| e.raw_ptrs()).collect();
        for _ in 0..control_steps {
            for &(m, d) in &ptrs {
                for _ in 0..decimation {
                    // SAFETY: m and d belong to the same live env, borrowed mutably above.
                    unsafe { mujoco_sys::mj_step(m, d) };
                }
            }
        }
        control_steps * ptrs.len() * decimation
    }

    /// MuJoCo warnings counted by all envs since construction.
    pub fn warning_total(&self) -> u64 {
        self.envs
            .iter()
            .map(|e| e.data().warning_totals().iter().sum::<u64>())
            .sum()
    }

    /// Mean terrain level of the envs on each kind of a mixed map with a
    /// curriculum ([`crate::env::task::VecTask::levels_by_kind`]).
    pub fn levels_by_kind(&self) -> Vec<(crate::terrain::TerrainKind, f64)> {
        let sh = self.shared();
        let Some(map) = sh.scene.terrain.as_ref() else {
            return Vec::new();
        };
        if !sh.cfg.terrain.curriculum {
            return Vec::new();
        }
        let kinds: Vec<_> = crate::terrain::TerrainKind::ALL
            .into_iter()
            .filter(|k| (0..map.num_cols()).any(|c| map.tile_kind(c) == *k))
            .collect();
        if kinds.len() < 2 {
            return Vec::new();
        }
        kinds
            .into_iter()
            .map(|k| {
                let (sum, n) = self
                    .envs
                    .iter()
                    .filter(|e| map.tile_kind(e.column()) == k)
                    .fold((0.0, 0usize), |(s, n), e| {
                        (s + e.terrain_level() as f64, n + 1)
                    });
                (k, if n > 0 { sum / n as f64 } else { f64::NAN })
            })
            .collect()
    }

    /// Mean terrain level of the batch.
    pub fn mean_terrain_level(&self) -> f64 {
        self.envs
            .iter()
            .map(|e| e.terrain_level() as f64)
            .sum::<f64>()
            / self.envs.len() as f64
    }
}

/// Seed of env `i` of a batch seeded `seed` (splitmix64 of the pair).
pub fn env_seed(seed: u64, i: usize) -> u64 {
    let mut z = seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
