//! The world model's inputs and outputs per env, kept between control steps:
//! the history of the last `K` states ([`History`], padded with `s_0` after a
//! reset as the paper's algorithm does) and the plan `ŝ_{t+1..t+H}` ([`Plan`]),
//! made every `m` control steps for all envs that need one in one batch, and
//! shifted by one step in between (its last state held), so that the world
//! model's cost is spread over `m` steps.

/// The last `k` states of each of `n` envs, oldest first.
#[derive(Debug, Clone)]
pub struct History {
    n: usize,
    k: usize,
    dim: usize,
    buf: Vec<f32>,
}

impl History {
    pub fn new(n: usize, k: usize, dim: usize) -> History {
        assert!(k >= 1 && dim >= 1, "history of {k} states of {dim} floats");
        History {
            n,
            k,
            dim,
            buf: vec![0.0; n * k * dim],
        }
    }

    pub fn len(&self) -> usize {
        self.k
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// After env `env`'s reset: every entry is its first state `s0`.
    pub fn reset(&mut self, env: usize, s0: &[f32]) {
        let row = &mut self.buf[env * self.k * self.dim..(env + 1) * self.k * self.dim];
        for c in row.chunks_exact_mut(self.dim) {
            c.copy_from_slice(&s0[..self.dim]);
        }
    }

    /// Append env `env`'s newest state (the oldest drops out).
    pub fn push(&mut self, env: usize, s: &[f32]) {
        let (k, d) = (self.k, self.dim);
        let row = &mut self.buf[env * k * d..(env + 1) * k * d];
        row.copy_within(d.., 0);
        row[(k - 1) * d..].copy_from_slice(&s[..d]);
    }

    /// Env `env`'s `k` states, oldest first (`k * dim` floats).
    pub fn row(&self, env: usize) -> &[f32] {
        &self.buf[env * self.k * self.dim..(env + 1) * self.k * self.dim]
    }

    /// Every env's row: `[n, k * dim]`.
    pub fn rows(&self) -> &[f32] {
        &self.buf
    }

    pub fn num_envs(&self) -> usize {
        self.n
    }
}

/// Each env's plan: `h` predicted states, the first one the next state.
#[derive(Debug, Clone)]
pub struct Plan {
    h: usize,
    dim: usize,
    replan: usize,
    buf: Vec<f32>,
    /// Control steps since the env's plan was made; `None`: no plan (a reset).
    age: Vec<Option<usize>>,
}

impl Plan {
    /// Plans of `h` states of `dim` floats for `n` envs, made again every
    /// `replan` control steps (at least 1).
    pub fn new(n: usize, h: usize, dim: usize, replan: usize) -> Plan {
        assert!(h >= 1 && dim >= 1, "plans of {h} states of {dim} floats");
        Plan {
            h,
            dim,
            replan: replan.max(1),
            buf: vec![0.0; n * h * dim],
            age: vec![None; n],
        }
    }

    pub fn horizon(&self) -> usize {
        self.h
    }

    /// Envs whose plan is missing (reset) or `replan` steps old, in order.
    pub fn due(&self) -> impl Iterator<Item = usize> + '_ {
        let m = self.replan;
        self.age
            .iter()
            .enumerate()
            .filter(move |(_, a)| a.is_none_or(|a| a >= m))
            .map(|(i, _)| i)
    }

    /// Env `env`'s new plan, `h * dim` floats (`ŝ_{t+1..t+h}`).
    pub fn set(&mut self, env: usize, states: &[f32]) {
        let len = self.h * self.dim;
        self.buf[env * len..(env + 1) * len].copy_from_slice(&states[..len]);
        self.age[env] = Some(0);
    }

    /// Env `env` was reset: its plan is gone until the next [`Plan::set`].
    pub fn invalidate(&mut self, env: usize) {
        self.age[env] = None;
    }

    /// One control step passed: every plan drops its first state and holds its
    /// last one, and ages by one.
    pub fn advance(&mut self) {
        let (h, d) = (self.h, self.dim);
        for (env, age) in self.age.iter_mut().enumerate() {
            if let Some(a) = age {
                let row = &mut self.buf[env * h * d..(env + 1) * h * d];
                row.copy_within(d.., 0);
                *a += 1;
            }
        }
    }

    /// Env `env`'s plan (`h * dim` floats), and whether it has one.
    pub fn future(&self, env: usize) -> (&[f32], bool) {
        let len = self.h * self.dim;
        (
            &self.buf[env * len..(env + 1) * len],
            self.age[env].is_some(),
        )
    }

    /// Env `env`'s predicted next state `ŝ_{t+1}`.
    pub fn next(&self, env: usize) -> &[f32] {
        let len = self.h * self.dim;
        &self.buf[env * len..env * len + self.dim]
    }

    /// Every env's plan: `[n, h * dim]`.
    pub fn rows(&self) -> &[f32] {
        &self.buf
    }
}

/// One batched world-model call for the envs `due`: their histories and their
/// rows of `scan` (`[n, SCAN_DIM]` scandots) in, `due.len() * H * S` predicted
/// states out, in `due`'s order; NaN states where the call fails.
pub fn predict_due(
    wm: &crate::world_model::WorldModel,
    history: &History,
    scan: &[f32],
    due: &[usize],
    sampling: &crate::world_model::config::SamplingConfig,
    noise: &mut crate::world_model::sampler::Noise,
) -> Vec<f32> {
    use crate::env::obs::SCAN_DIM;
    let (k, d) = (history.len(), history.dim);
    let b = due.len() as i64;
    let mut hist = Vec::with_capacity(due.len() * k * d);
    let mut scans = Vec::with_capacity(due.len() * SCAN_DIM);
    for &i in due {
        hist.extend_from_slice(history.row(i));
        scans.extend_from_slice(&scan[i * SCAN_DIM..(i + 1) * SCAN_DIM]);
    }
    let hist = tch::Tensor::from_slice(&hist).view([b, k as i64, d as i64]);
    let scans = tch::Tensor::from_slice(&scans).view([b, SCAN_DIM as i64]);
    wm.predict(&hist, &scans, sampling, noise)
        .ok()
        .and_then(|p| Vec::<f32>::try_from(p.to_kind(tch::Kind::Float).flatten(0, -1)).ok())
        .unwrap_or_else(|| vec![f32::NAN; due.len() * wm.horizon() * d])
}
