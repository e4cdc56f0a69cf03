//! Rollout storage: preallocated `[T, N, ...]` buffers that refuse to overflow,
//! and GAE returns (rsl_rl's `RolloutStorage`).

/// One env-step of the batch, as the runner hands it over.
pub struct Transition<'a> {
    pub actor_in: &'a [f32],
    pub critic_in: &'a [f32],
    pub scan: &'a [f32],
    pub actions: &'a [f32],
    pub log_probs: &'a [f32],
    pub values: &'a [f32],
    pub mean: &'a [f32],
    /// Rewards with time-outs already bootstrapped (`r + gamma V(s_final)`).
    pub rewards: &'a [f32],
    /// 1 where the episode ended (terminated or truncated) after this step.
    pub dones: &'a [f32],
}

/// The buffers of one iteration.
pub struct RolloutStorage {
    pub steps: usize,
    pub n: usize,
    pub dims: [usize; 4],
    pub filled: usize,
    pub actor_in: Vec<f32>,
    pub critic_in: Vec<f32>,
    pub scan: Vec<f32>,
    pub actions: Vec<f32>,
    pub log_probs: Vec<f32>,
    pub values: Vec<f32>,
    pub mean: Vec<f32>,
    pub rewards: Vec<f32>,
    pub dones: Vec<f32>,
    pub returns: Vec<f32>,
    pub advantages: Vec<f32>,
}

impl RolloutStorage {
    /// `dims` = actor input, critic input, scan, action floats per env.
    pub fn new(steps: usize, n: usize, dims: [usize; 4]) -> RolloutStorage {
        let z = |d: usize| vec![0.0f32; steps * n * d];
        RolloutStorage {
            steps,
            n,
            dims,
            filled: 0,
            actor_in: z(dims[0]),
            critic_in: z(dims[1]),
            scan: z(dims[2]),
            actions: z(dims[3]),
            log_probs: z(1),
            values: z(1),
            mean: z(dims[3]),
            rewards: z(1),
            dones: z(1),
            returns: z(1),
            advantages: z(1),
        }
    }

    pub fn is_full(&self) -> bool {
        self.filled == self.steps
    }

    /// Append one step; an error when the storage is full (call `clear` first).
    pub fn add(&mut self, t: &Transition<'_>) -> Result<(), String> {
        if self.is_full() {
            return Err(format!("rollout storage is full ({} steps)", self.steps));
        }
        let (k, n) = (self.filled, self.n);
        let put = |dst: &mut Vec<f32>, src: &[f32], d: usize| {
            dst[k * n * d..(k + 1) * n * d].copy_from_slice(&src[..n * d]);
        };
        let [da, dc, ds, dact] = self.dims;
        put(&mut self.actor_in, t.actor_in, da);
        put(&mut self.critic_in, t.critic_in, dc);
        put(&mut self.scan, t.scan, ds);
        put(&mut self.actions, t.actions, dact);
        put(&mut self.mean, t.mean, dact);
        put(&mut self.log_probs, t.log_probs, 1);
        put(&mut self.values, t.values, 1);
        put(&mut self.rewards, t.rewards, 1);
        put(&mut self.dones, t.dones, 1);
        self.filled += 1;
        Ok(())
    }

    pub fn clear(&mut self) {
        self.filled = 0;
    }

    /// GAE(lambda) advantages and returns, bootstrapped from `last_values` `[N]`.
    pub fn compute_returns(&mut self, last_values: &[f32], gamma: f32, lam: f32) {
        let n = self.n;
        let mut gae = vec![0.0f32; n];
        for k in (0..self.filled).rev() {
            for i in 0..n {
                let idx = k * n + i;
                let next_v = if k + 1 == self.filled {
                    last_values[i]
                } else {
                    self.values[idx + n]
                };
                let not_done = 1.0 - self.dones[idx];
                let delta = self.rewards[idx] + gamma * next_v * not_done - self.values[idx];
                gae[i] = delta + gamma * lam * not_done * gae[i];
                self.advantages[idx] = gae[i];
                self.returns[idx] = gae[i] + self.values[idx];
            }
        }
    }
}
