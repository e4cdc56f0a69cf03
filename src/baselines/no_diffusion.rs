//! The ablation without the diffusion world model (the paper's "Ablation on
//! Diffusion World Model"): "due to the lack of motion guidance, we train the
//! discriminator using the standard implementation of AMP, in which we sample
//! transitions from offline trajectories collected from specialized policies".
//!
//! [`NoDiffusionTask`] is the G1 env as a [`VecTask`] with a standard AMP
//! discriminator (the unified policy's [`Discriminator`]: LSGAN, gradient
//! penalty, style reward `max(0, 1 − 0.25 (D − 1)²)`) whose real transitions
//! `(s_t, s_{t+1})` are consecutive frames of one episode in the expert
//! dataset, loaded once, and whose fake ones are the policy's. There is no
//! world model and so no plan and no body-space tracking: the policy reads its
//! state, history and the scandots (the specialists' interface), and the
//! task reward is the env's reward table: the unified policy's regularization
//! and safety terms plus the command-tracking terms standard AMP pairs with
//! its style reward (`configs/baselines/no_diffusion.yaml`). The policy's
//! transitions are taken from the critic rows' noise-free state, as the
//! dataset recorded its states without observation noise.
//!
//! `train no-diffusion` is the PPO runner on this task: the run directory,
//! metrics (the discriminator's columns added), checkpoints (the
//! discriminator in them) and resume of every trainer. The checkpoint is read
//! by `eval`, `play`, `render`, `export` and `benchmark` as an ordinary policy.
use std::collections::HashMap;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use tch::{Device, Tensor};

use crate::config::ConfigError;
use crate::data::{Dataset, Dims, ReadOptions};
use crate::env::obs::OBS_DIM;
use crate::env::task::{TaskDims, VecTask};
use crate::env::{Outcome, StepInfo, VecEnv};
use crate::rl::config::{ExperimentConfig, TaskKind};
use crate::rl::runner::{train_task, TrainSummary};
use crate::rl::RlError;
use crate::terrain::TerrainKind;
use crate::unified::amp::{AmpConfig, Discriminator, AMP_DIM};

/// The `no_diffusion:` section of a `task: no_diffusion` config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoDiffusionConfig {
    /// The expert dataset (a directory of MCAP shards, `collect`'s output).
    pub dataset: String,
    /// Terrain kinds whose episodes give real transitions (default: all).
    #[serde(default)]
    pub kinds: Vec<String>,
    /// At most this many real transitions are loaded, drawn uniformly from all
    /// of the dataset's (seeded by `seed`).
    #[serde(default = "default_max")]
    pub max_transitions: usize,
    #[serde(default)]
    pub amp: AmpConfig,
    /// Weight of the style reward (the unified policy's 0.25).
    #[serde(default = "default_style")]
    pub style_weight: f64,
    /// Seed of the discriminator's batch draws and of the draw of real
    /// transitions when the dataset holds more than `max_transitions`.
    #[serde(default)]
    pub seed: u64,
}

fn default_max() -> usize {
    500_000
}

fn default_style() -> f64 {
    0.25
}

impl NoDiffusionConfig {
    /// The `no_diffusion:` section of `cfg` (`task: no_diffusion`), parsed and checked.
    pub fn of(cfg: &ExperimentConfig) -> Result<NoDiffusionConfig, ConfigError> {
        if cfg.task != TaskKind::NoDiffusion {
            return Err(ConfigError::Invalid(
                "not a w/o-diffusion config: set `task: no_diffusion` and a `no_diffusion:` section"
                    .into(),
            ));
        }
        let c: NoDiffusionConfig = crate::rl::config::parse_section(
            &cfg.no_diffusion,
            "no_diffusion",
            "task: no_diffusion needs a `no_diffusion:` section",
        )?;
        let bad = |why: String| Err(ConfigError::Invalid(format!("no_diffusion.{why}")));
        if c.dataset.trim().is_empty() {
            return bad("dataset names no directory".into());
        }
        for k in &c.kinds {
            TerrainKind::from_name(k)
                .map_err(|e| ConfigError::Invalid(format!("no_diffusion.kinds: {e}")))?;
        }
        if c.max_transitions == 0 {
            return bad("max_transitions must be at least 1".into());
        }
        if !c.style_weight.is_finite() {
            return bad("style_weight must be finite".into());
        }
        c.amp
            .check()
            .map_err(|why| ConfigError::Invalid(format!("no_diffusion.amp: {why}")))?;
        Ok(c)
    }
}

/// The real transitions of a dataset: `Φ(s_t) ‖ Φ(s_{t+1})` rows
/// ([`Discriminator::features`]) of every pair of consecutive frames of one
/// episode (same episode id, step `t` then `t + 1`) whose terrain is in
/// `kinds` (all when empty). When there are more than `max`, `max` of them
/// drawn uniformly from the whole dataset (reservoir sampling, seeded by
/// `seed`), not the first ones in file order: `collect` writes a specialist's
/// shards one after another, so the first rows of a large dataset are all one
/// terrain's. Returns the rows (in no particular order) and the number of
/// episodes they came from.
pub fn dataset_transitions(
    path: &Path,
    kinds: &[TerrainKind],
    max: usize,
    seed: u64,
) -> Result<(Vec<f32>, usize), RlError> {
    let ds = Dataset::open(
        path,
        ReadOptions {
            expected: Dims::G1,
            ..Default::default()
        },
    )
    .map_err(|e| RlError::Invalid(format!("no_diffusion.dataset: {e}")))?;
    let row = 2 * AMP_DIM;
    let mut out = Vec::new();
    // the episode of each kept row
    let mut owner: Vec<u64> = Vec::new();
    // transitions seen so far (Algorithm R's count)
    let mut seen = 0usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_DA7A);
    // each open episode's last frame: (step, state)
    let mut last: HashMap<u64, (u32, Vec<f32>)> = HashMap::new();
    for item in ds.frames() {
        let (_, f) = item.map_err(|e| RlError::Invalid(format!("no_diffusion.dataset: {e}")))?;
        if !kinds.is_empty() && !kinds.contains(&f.terrain) {
            continue;
        }
        if let Some((step, prev)) = last.get(&f.episode) {
            if f.step == step + 1 {
                seen += 1;
                if owner.len() < max {
                    out.extend(Discriminator::features(prev, &f.state, OBS_DIM));
                    owner.push(f.episode);
                } else {
                    // keep this one with probability max / seen, in a uniform slot
                    let j = rng.random_range(0..seen);
                    if j < max {
                        let feats = Discriminator::features(prev, &f.state, OBS_DIM);
                        out[j * row..(j + 1) * row].copy_from_slice(&feats);
                        owner[j] = f.episode;
                    }
                }
            }
        }
        if f.terminated || f.truncated {
            last.remove(&f.episode);
        } else {
            last.insert(f.episode, (f.step, f.state.clone()));
        }
    }
    if out.is_empty() {
        return Err(RlError::Invalid(format!(
            "no_diffusion.dataset {}: no two consecutive frames of one episode{}",
            path.display(),
            if kinds.is_empty() {
                String::new()
            } else {
                " on the kinds asked for".to_string()
            }
        )));
    }
    let episodes: std::collections::HashSet<u64> = owner.into_iter().collect();
    Ok((out, episodes.len()))
}

/// Names of the task's own metrics (`metrics.csv`).
pub const METRICS: [&str; 7] = [
    "amp_loss",
    "amp_grad_penalty",
    "amp_d_real",
    "amp_d_fake",
    "amp_accuracy",
    "style_reward",
    "real_transitions",
];

/// The G1 env with a standard AMP discriminator on the dataset's transitions.
pub struct NoDiffusionTask {
    env: VecEnv,
    pub cfg: NoDiffusionConfig,
    pub disc: Discriminator,
    dt: f64,
    /// The dataset's transitions (feature rows), loaded once, never added to.
    real: Vec<f32>,
    /// This iteration's policy transitions (feature rows).
    fake: Vec<f32>,
    prev: Vec<f32>,
    outcomes: Vec<Outcome>,
    style: (f64, usize),
}

impl NoDiffusionTask {
    /// The env of `cfg.env` and the discriminator of `cfg.no_diffusion`, its
    /// real transitions read from the dataset.
    pub fn new(cfg: &ExperimentConfig) -> Result<NoDiffusionTask, RlError> {
        let c = NoDiffusionConfig::of(cfg)?;
        let kinds = c
            .kinds
            .iter()
            .map(|k| TerrainKind::from_name(k))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| RlError::Invalid(format!("no_diffusion.kinds: {e}")))?;
        let (real, _) =
            dataset_transitions(Path::new(&c.dataset), &kinds, c.max_transitions, c.seed)?;
        let env = VecEnv::new(&cfg.env)?;
        tch::manual_seed(cfg.train.seed as i64 ^ 0x00A1_1CE5);
        let disc = Discriminator::new(&c.amp, Device::Cpu);
        let n = env.n_envs();
        let mut t = NoDiffusionTask {
            dt: env.shared().dt,
            prev: vec![0.0; n * OBS_DIM],
            outcomes: vec![Outcome::default(); n],
            env,
            cfg: c,
            disc,
            real,
            fake: Vec::new(),
            style: (0.0, 0),
        };
        t.remember_states();
        Ok(t)
    }

    /// The env underneath.
    pub fn env(&self) -> &VecEnv {
        &self.env
    }

    /// The dataset's transitions the discriminator takes as real (feature rows).
    pub fn real(&self) -> &[f32] {
        &self.real
    }

    /// This iteration's policy transitions so far (feature rows).
    pub fn fake(&self) -> &[f32] {
        &self.fake
    }

    /// The noise-free actor state of every env (the critic rows' first
    /// [`OBS_DIM`] floats) as the start of the next transitions.
    fn remember_states(&mut self) {
        let c = crate::env::obs::CRITIC_DIM;
        for i in 0..self.env.n_envs() {
            self.prev[i * OBS_DIM..(i + 1) * OBS_DIM]
                .copy_from_slice(&self.env.critic[i * c..i * c + OBS_DIM]);
        }
    }
}

impl VecTask for NoDiffusionTask {
    crate::env::task::delegate_to_env!(env);
    fn dims(&self) -> TaskDims {
        VecTask::dims(&self.env)
    }
    fn scan(&self) -> &[f32] {
        &self.env.scan
    }
    fn final_scan(&self) -> &[f32] {
        &self.env.final_scan
    }
    fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }
    fn step(&mut self, actions: &[f32]) -> StepInfo {
        let mut info = self.env.step(actions);
        self.outcomes.copy_from_slice(&self.env.outcomes);
        let c = crate::env::obs::CRITIC_DIM;
        let live: Vec<usize> = (0..self.env.n_envs())
            .filter(|&i| !self.outcomes[i].episode_done)
            .collect();
        if !live.is_empty() {
            let mut s = Vec::with_capacity(live.len() * OBS_DIM);
            let mut s2 = Vec::with_capacity(live.len() * OBS_DIM);
            for &i in &live {
                s.extend_from_slice(&self.prev[i * OBS_DIM..(i + 1) * OBS_DIM]);
                s2.extend_from_slice(&self.env.critic[i * c..i * c + OBS_DIM]);
            }
            let rows = Discriminator::features(&s, &s2, OBS_DIM);
            let style = self.disc.style_reward(&rows);
            for (&i, &r) in live.iter().zip(&style) {
                self.outcomes[i].reward += (self.cfg.style_weight * f64::from(r) * self.dt) as f32;
                self.style.0 += f64::from(r);
            }
            self.style.1 += style.len();
            self.fake.extend(rows);
        }
        self.remember_states();
        let n = self.env.n_envs() as f64;
        info.mean_reward = self
            .outcomes
            .iter()
            .map(|o| f64::from(o.reward))
            .sum::<f64>()
            / n;
        info
    }
    fn reset_all(&mut self) {
        self.env.reset_all();
        self.remember_states();
        self.fake.clear();
        self.style = (0.0, 0);
    }
    fn mirror(&self) -> Option<crate::env::mirror::Mirror> {
        VecTask::mirror(&self.env)
    }
    fn extra_metric_names(&self) -> Vec<&'static str> {
        METRICS.to_vec()
    }
    fn after_rollout(&mut self) -> Result<Vec<f64>, String> {
        let s = self.disc.train_on(&self.real, &self.fake, self.cfg.seed);
        self.fake.clear();
        let (sum, count) = std::mem::take(&mut self.style);
        Ok(vec![
            s.loss,
            s.grad_penalty,
            s.d_real,
            s.d_fake,
            s.accuracy,
            if count > 0 {
                sum / count as f64
            } else {
                f64::NAN
            },
            (self.real.len() / (2 * AMP_DIM)) as f64,
        ])
    }
    fn state_tensors(&self) -> Vec<(String, Tensor)> {
        self.disc.named_tensors()
    }
    fn load_state_tensors(&mut self, get: &dyn Fn(&str) -> Option<Tensor>) -> Result<(), String> {
        self.disc.load_named(get)
    }
}

/// `train no-diffusion`: PPO on [`NoDiffusionTask`] in `run_dir`, fresh or resumed.
pub fn train(
    cfg: &ExperimentConfig,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    tch::set_num_threads(cfg.train.torch_threads as i32);
    let mut task = NoDiffusionTask::new(cfg)?;
    train_task(cfg, &mut task, run_dir, resume, quiet)
}
