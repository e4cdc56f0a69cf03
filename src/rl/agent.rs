//! `Agent`: the policy with everything that turns a task's raw buffers into
//! network inputs: running normalizers (actor state, critic observation,
//! scandots) and each env's history of past states. Training, evaluation,
//! rollouts for the dataset and export all act through it, so they see the same
//! inputs.
use tch::{Device, Kind, Tensor};

use super::normalizer::RunningNorm;
use super::policy::ActorCritic;
use crate::env::task::{TaskDims, VecTask};
use crate::rl::config::PolicyConfig;

/// Policy, normalizers and per-env history.
pub struct Agent {
    pub policy: ActorCritic,
    pub obs_norm: RunningNorm,
    pub critic_norm: RunningNorm,
    pub scan_norm: RunningNorm,
    /// Normalize inputs (else the normalizers are identity).
    pub normalize: bool,
    n: usize,
    /// Raw past states `[n, K, obs]`, oldest first.
    history: Vec<f32>,
    /// Network inputs of the current step.
    pub actor_in: Vec<f32>,
    pub critic_in: Vec<f32>,
    pub scan_in: Vec<f32>,
    /// Raw actor state used for the current inputs (pushed into the history after the step).
    cur_obs: Vec<f32>,
}

/// What the policy did for one batch.
pub struct Act {
    pub actions: Vec<f32>,
    pub log_probs: Vec<f32>,
    pub values: Vec<f32>,
    pub mean: Vec<f32>,
}

fn to_vec(t: &Tensor) -> Vec<f32> {
    let t = t.to_kind(Kind::Float).contiguous().view([-1]);
    Vec::<f32>::try_from(&t).expect("f32 tensor to Vec")
}

impl Agent {
    pub fn new(cfg: &PolicyConfig, dims: TaskDims, n_envs: usize, normalize: bool) -> Agent {
        let policy = ActorCritic::new(cfg, dims, Device::Cpu);
        Agent::with_policy(policy, n_envs, normalize)
    }

    pub fn with_policy(policy: ActorCritic, n: usize, normalize: bool) -> Agent {
        let d = policy.dims;
        let k = policy.history_len();
        let a_in = policy.actor_input_dim();
        Agent {
            obs_norm: RunningNorm::new(d.obs),
            critic_norm: RunningNorm::new(d.critic),
            scan_norm: RunningNorm::new(d.scan),
            normalize,
            n,
            history: vec![0.0; n * k * d.obs],
            actor_in: vec![0.0; n * a_in],
            critic_in: vec![0.0; n * d.critic],
            scan_in: vec![0.0; n * d.scan],
            cur_obs: vec![0.0; n * d.obs],
            policy,
        }
    }

    pub fn dims(&self) -> TaskDims {
        self.policy.dims
    }

    /// Check that a task matches the policy's sizes.
    pub fn check_task(&self, task: &dyn VecTask) -> Result<(), String> {
        if task.dims() != self.dims() || task.n_envs() != self.n {
            return Err(format!(
                "the policy expects {} envs of {:?}, the task has {} of {:?}",
                self.n,
                self.dims(),
                task.n_envs(),
                task.dims()
            ));
        }
        Ok(())
    }

    /// Raw past states `[n, K, obs]`, oldest first (what an exported policy takes).
    pub fn history(&self) -> &[f32] {
        &self.history
    }

    /// Freeze or unfreeze the normalizers' statistics.
    pub fn set_frozen(&mut self, frozen: bool) {
        self.obs_norm.frozen = frozen;
        self.critic_norm.frozen = frozen;
        self.scan_norm.frozen = frozen;
    }

    /// Fill every env's history with its current state (after a reset of all envs).
    pub fn reset_history(&mut self, task: &dyn VecTask) {
        for i in 0..self.n {
            self.reset_history_of(i, task.obs());
        }
    }

    /// Fill env `i`'s history with its current state from `obs` (`[n, obs]`),
    /// after that env alone was reset.
    pub fn reset_history_env(&mut self, i: usize, obs: &[f32]) {
        self.reset_history_of(i, obs);
    }

    fn reset_history_of(&mut self, i: usize, obs: &[f32]) {
        let d = self.policy.dims.obs;
        let k = self.policy.history_len();
        let row = &obs[i * d..(i + 1) * d];
        for j in 0..k {
            let at = (i * k + j) * d;
            self.history[at..at + d].copy_from_slice(row);
        }
    }

    /// After a step: push the state the policy acted on into each env's history,
    /// or refill the history of an env whose episode ended with its first state.
    pub fn after_step(&mut self, task: &dyn VecTask) {
        let d = self.policy.dims.obs;
        let k = self.policy.history_len();
        if k == 0 {
            return;
        }
        for (i, o) in task.outcomes().iter().enumerate() {
            if o.episode_done {
                self.reset_history_of(i, task.obs());
            } else {
                let h = &mut self.history[i * k * d..(i + 1) * k * d];
                h.copy_within(d.., 0);
                h[(k - 1) * d..].copy_from_slice(&self.cur_obs[i * d..(i + 1) * d]);
            }
        }
    }

    /// Update the normalizers with the task's current buffers (training) and write
    /// the normalized network inputs of this step.
    pub fn prepare(&mut self, task: &dyn VecTask) {
        let d = self.policy.dims;
        if self.normalize {
            self.obs_norm.update(task.obs());
            self.critic_norm.update(task.critic());
            if self.policy.uses_scan() {
                self.scan_norm.update(task.scan());
            }
        }
        self.cur_obs.copy_from_slice(task.obs());
        let k = self.policy.history_len();
        let a_in = self.policy.actor_input_dim();
        for i in 0..self.n {
            let row = &mut self.actor_in[i * a_in..(i + 1) * a_in];
            for j in 0..k {
                let at = (i * k + j) * d.obs;
                norm(
                    &self.obs_norm,
                    self.normalize,
                    &self.history[at..at + d.obs],
                    &mut row[j * d.obs..(j + 1) * d.obs],
                );
            }
            norm(
                &self.obs_norm,
                self.normalize,
                &task.obs()[i * d.obs..(i + 1) * d.obs],
                &mut row[k * d.obs..],
            );
        }
        self.normalize_critic(task.critic(), task.scan());
    }

    /// Normalize critic rows and scandots into `critic_in` / `scan_in`.
    fn normalize_critic(&mut self, critic: &[f32], scan: &[f32]) {
        let (mut c, mut s) = (
            std::mem::take(&mut self.critic_in),
            std::mem::take(&mut self.scan_in),
        );
        self.normalize_critic_into(critic, scan, &mut c, &mut s);
        self.critic_in = c;
        self.scan_in = s;
    }

    fn normalize_critic_into(&self, critic: &[f32], scan: &[f32], c: &mut [f32], s: &mut [f32]) {
        let d = self.policy.dims;
        for i in 0..self.n {
            let (rc, rs) = (
                i * d.critic..(i + 1) * d.critic,
                i * d.scan..(i + 1) * d.scan,
            );
            norm(
                &self.critic_norm,
                self.normalize,
                &critic[rc.clone()],
                &mut c[rc],
            );
            norm(
                &self.scan_norm,
                self.normalize,
                &scan[rs.clone()],
                &mut s[rs],
            );
        }
    }

    fn tensors(&self) -> (Tensor, Tensor, Option<Tensor>) {
        let n = self.n as i64;
        let d = self.policy.dims;
        let a = Tensor::from_slice(&self.actor_in).view([n, -1]);
        let c = Tensor::from_slice(&self.critic_in).view([n, d.critic as i64]);
        let s = self
            .policy
            .uses_scan()
            .then(|| Tensor::from_slice(&self.scan_in).view([n, d.scan as i64]));
        (a, c, s)
    }

    /// Act on the prepared inputs: sampled actions (`stochastic`) or the mean.
    pub fn act(&self, stochastic: bool) -> Act {
        tch::no_grad(|| {
            let (a, c, s) = self.tensors();
            let mean = self.policy.actor_mean(&a, s.as_ref());
            let std = self.policy.std();
            let actions = if stochastic {
                &mean + mean.randn_like() * &std
            } else {
                mean.shallow_clone()
            };
            let logp = ActorCritic::log_prob(&mean, &std, &actions);
            let values = self.policy.value(&c, s.as_ref());
            Act {
                actions: to_vec(&actions),
                log_probs: to_vec(&logp),
                values: to_vec(&values),
                mean: to_vec(&mean),
            }
        })
    }

    /// Mean actions only (evaluation); cheaper than [`Agent::act`].
    pub fn act_mean(&self) -> Vec<f32> {
        tch::no_grad(|| {
            let (a, _, s) = self.tensors();
            to_vec(&self.policy.actor_mean(&a, s.as_ref()))
        })
    }

    /// One deterministic control step of `task` (evaluation, rollouts): inputs,
    /// mean actions, the env step, then the history update.
    pub fn step_mean(&mut self, task: &mut dyn VecTask) -> crate::env::StepInfo {
        self.prepare(&*task);
        let actions = self.act_mean();
        let info = task.step(&actions);
        self.after_step(&*task);
        info
    }

    /// Values of raw critic rows and scandots of every env (e.g. the final
    /// observations of truncated episodes), normalized with the current statistics.
    pub fn values_of(&self, critic: &[f32], scan: &[f32]) -> Vec<f32> {
        let d = self.policy.dims;
        let (mut c, mut s) = (vec![0.0; self.n * d.critic], vec![0.0; self.n * d.scan]);
        self.normalize_critic_into(critic, scan, &mut c, &mut s);
        let n = self.n as i64;
        tch::no_grad(|| {
            let ct = Tensor::from_slice(&c).view([n, d.critic as i64]);
            let st = self
                .policy
                .uses_scan()
                .then(|| Tensor::from_slice(&s).view([n, d.scan as i64]));
            to_vec(&self.policy.value(&ct, st.as_ref()))
        })
    }
}

#[inline]
fn norm(n: &RunningNorm, on: bool, src: &[f32], dst: &mut [f32]) {
    if on {
        n.apply(src, dst);
    } else {
        dst.copy_from_slice(src);
    }
}
