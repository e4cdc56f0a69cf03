//! Cart-pole balancing on MuJoCo (`models/cartpole.xml`): the small control task
//! that tests PPO end to end in seconds. Reward 1 per control step (50 Hz) while
//! the pole is within `MAX_ANGLE` of upright and the cart within `MAX_X`; a step
//! past either terminates; `EPISODE_STEPS` truncates (bootstrapped). The best
//! return is `EPISODE_STEPS`.
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::task::{EnvSnapshot, TaskDims, VecTask};
use super::{EnvError, Outcome, StepInfo};
use crate::sim::{Data, Model};

pub const OBS_DIM: usize = 5;
pub const MAX_ANGLE: f64 = 0.4;
pub const MAX_X: f64 = 2.4;
pub const EPISODE_STEPS: u64 = 200;
const DECIMATION: usize = 2;

struct Pole {
    data: Data,
    rng: ChaCha8Rng,
    steps: u64,
}

/// A batch of cart-poles.
pub struct CartPole {
    poles: Vec<Pole>,
    obs: Vec<f32>,
    final_obs: Vec<f32>,
    outcomes: Vec<Outcome>,
}

impl Pole {
    fn reset(&mut self) {
        self.data.reset();
        let q = self.data.qpos_mut();
        q[0] = self.rng.random_range(-0.2..=0.2);
        q[1] = self.rng.random_range(-0.1..=0.1);
        self.data.forward();
        self.steps = 0;
    }

    fn observe(&self, out: &mut [f32]) {
        let (q, v) = (self.data.qpos(), self.data.qvel());
        let o = [q[0], v[0], q[1].cos(), q[1].sin(), v[1]];
        for (d, s) in out.iter_mut().zip(o) {
            *d = s as f32;
        }
    }
}

impl CartPole {
    /// `n` cart-poles seeded from `seed`.
    pub fn new(n: usize, seed: u64) -> Result<CartPole, EnvError> {
        let model = Arc::new(Model::from_xml_path(
            crate::robot::models_dir().join("cartpole.xml"),
        )?);
        let poles = (0..n)
            .map(|i| {
                Ok(Pole {
                    data: Data::new(model.clone())?,
                    rng: ChaCha8Rng::seed_from_u64(super::vec_env::env_seed(seed, i)),
                    steps: 0,
                })
            })
            .collect::<Result<Vec<_>, EnvError>>()?;
        let mut c = CartPole {
            poles,
            obs: vec![0.0; n * OBS_DIM],
            final_obs: vec![0.0; n * OBS_DIM],
            outcomes: vec![Outcome::default(); n],
        };
        c.reset_all();
        Ok(c)
    }
}

impl VecTask for CartPole {
    fn dims(&self) -> TaskDims {
        TaskDims {
            obs: OBS_DIM,
            critic: OBS_DIM,
            scan: 0,
            action: 1,
        }
    }
    fn n_envs(&self) -> usize {
        self.poles.len()
    }
    fn obs(&self) -> &[f32] {
        &self.obs
    }
    fn critic(&self) -> &[f32] {
        &self.obs
    }
    fn scan(&self) -> &[f32] {
        &[]
    }
    fn final_critic(&self) -> &[f32] {
        &self.final_obs
    }
    fn final_scan(&self) -> &[f32] {
        &[]
    }
    fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }
    fn step(&mut self, actions: &[f32]) -> StepInfo {
        let mut info = StepInfo::default();
        for (i, p) in self.poles.iter_mut().enumerate() {
            let a = actions[i] as f64;
            p.data.ctrl_mut()[0] = if a.is_finite() {
                a.clamp(-1.0, 1.0)
            } else {
                0.0
            };
            let mut blowup = false;
            for _ in 0..DECIMATION {
                blowup |= p.data.step().is_err();
            }
            p.steps += 1;
            let (x, th) = (p.data.qpos()[0], p.data.qpos()[1]);
            let fell = blowup || x.abs() > MAX_X || th.cos() < MAX_ANGLE.cos();
            let truncated = !fell && p.steps >= EPISODE_STEPS;
            let reward = if fell { 0.0 } else { 1.0 };
            let row = i * OBS_DIM..(i + 1) * OBS_DIM;
            if fell || truncated {
                p.observe(&mut self.final_obs[row.clone()]);
                p.reset();
                info.episodes_done += 1;
            }
            p.observe(&mut self.obs[row]);
            info.blowups += blowup as usize;
            info.mean_reward += reward as f64;
            self.outcomes[i] = Outcome {
                reward,
                terminated: fell,
                truncated,
                blowup,
                episode_done: fell || truncated,
            };
        }
        info.mean_reward /= self.poles.len() as f64;
        info
    }
    fn reset_all(&mut self) {
        for (p, o) in self.poles.iter_mut().zip(self.obs.chunks_mut(OBS_DIM)) {
            p.reset();
            p.observe(o);
        }
    }
    fn snapshot(&self) -> Vec<EnvSnapshot> {
        self.poles
            .iter()
            .map(|p| EnvSnapshot::new(&p.rng, 0))
            .collect()
    }
    fn restore(&mut self, snaps: &[EnvSnapshot]) -> Result<(), String> {
        EnvSnapshot::check_count(snaps, self.poles.len())?;
        for (p, s) in self.poles.iter_mut().zip(snaps) {
            p.rng = s.rng();
        }
        Ok(())
    }
    fn reward_names(&self) -> Vec<&'static str> {
        vec!["upright"]
    }
    fn finished_episode_terms(&self) -> Option<Vec<(&'static str, f64)>> {
        None
    }
    fn tracking_errors(&self) -> [f64; 2] {
        [f64::NAN; 2]
    }
    fn mean_level(&self) -> f64 {
        0.0
    }
    fn max_episode_steps(&self) -> u64 {
        EPISODE_STEPS
    }
}
