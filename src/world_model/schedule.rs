//! The forward process and the scheduled-sampling probability.
//!
//! Steps are numbered `n = 1..=N` as in the paper; `alpha_bar(0) = 1` (the clean
//! sample). `q(x^n | x^0) = N(sqrt(alpha_bar_n) x^0, (1 - alpha_bar_n) I)`.
use tch::{Kind, Tensor};

use crate::world_model::config::{DiffusionConfig, ScheduleKind};

/// Betas, alphas and their cumulative products for `N` steps.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseSchedule {
    /// `beta_n` for `n = 1..=N` (index `n - 1`).
    pub betas: Vec<f64>,
    /// `alpha_bar_n = prod_{i <= n} (1 - beta_i)` (index `n - 1`).
    pub alpha_bar: Vec<f64>,
}

impl NoiseSchedule {
    /// The config's schedule. The linear betas are given for `N = 1000` (Ho et
    /// al.'s 1e-4..0.02) and scaled by `1000 / N`, so that a short chain still
    /// ends near pure noise; the cosine schedule is Nichol & Dhariwal's (`s =
    /// 0.008`, betas clipped at 0.999).
    pub fn new(cfg: &DiffusionConfig) -> NoiseSchedule {
        let n = cfg.steps;
        let betas: Vec<f64> = match cfg.schedule {
            ScheduleKind::Linear => {
                let scale = 1000.0 / n as f64;
                let (b0, b1) = (cfg.beta_start * scale, (cfg.beta_end * scale).min(0.999));
                (0..n)
                    .map(|i| {
                        if n == 1 {
                            b1
                        } else {
                            b0 + (b1 - b0) * i as f64 / (n - 1) as f64
                        }
                    })
                    .collect()
            }
            ScheduleKind::Cosine => {
                let s = 0.008;
                let f = |t: f64| {
                    (((t / n as f64) + s) / (1.0 + s) * std::f64::consts::FRAC_PI_2)
                        .cos()
                        .powi(2)
                };
                (1..=n)
                    .map(|i| (1.0 - f(i as f64) / f((i - 1) as f64)).clamp(0.0, 0.999))
                    .collect()
            }
        };
        let mut alpha_bar = Vec::with_capacity(n);
        let mut acc = 1.0;
        for b in &betas {
            acc *= 1.0 - b;
            alpha_bar.push(acc);
        }
        NoiseSchedule { betas, alpha_bar }
    }

    /// `N`.
    pub fn steps(&self) -> usize {
        self.betas.len()
    }

    /// `alpha_bar_n` for `n = 0..=N` (1 at `n = 0`).
    pub fn alpha_bar(&self, n: usize) -> f64 {
        if n == 0 {
            1.0
        } else {
            self.alpha_bar[n - 1]
        }
    }

    /// `beta_n` for `n = 1..=N`.
    pub fn beta(&self, n: usize) -> f64 {
        self.betas[n - 1]
    }

    /// `x^n = sqrt(alpha_bar_n) x^0 + sqrt(1 - alpha_bar_n) eps` with one step per
    /// batch row: `x0`, `eps` are `[B, ...]`, `steps` has `B` entries in `1..=N`.
    pub fn q_sample(&self, x0: &Tensor, steps: &[usize], eps: &Tensor) -> Tensor {
        let (a, b): (Vec<f32>, Vec<f32>) = steps
            .iter()
            .map(|&n| {
                let ab = self.alpha_bar(n);
                (ab.sqrt() as f32, (1.0 - ab).sqrt() as f32)
            })
            .unzip();
        let mut shape = vec![steps.len() as i64];
        shape.extend(std::iter::repeat_n(1, x0.dim() - 1));
        let dev = x0.device();
        let a = Tensor::from_slice(&a).to_device(dev).view(shape.as_slice());
        let b = Tensor::from_slice(&b).to_device(dev).view(shape.as_slice());
        x0 * a + eps * b
    }

    /// The `k` steps DDIM visits, descending from `N` to the smallest: `n_i =
    /// round(N * (k - i) / k)` for `i = 0..k` (so `N` first, then evenly spaced).
    pub fn ddim_steps(&self, k: usize) -> Vec<usize> {
        let n = self.steps();
        let k = k.clamp(1, n);
        let mut out: Vec<usize> = (0..k)
            .map(|i| ((n * (k - i)) as f64 / k as f64).round().max(1.0) as usize)
            .collect();
        out.dedup();
        out
    }

    /// Step numbers as the float tensor the denoiser embeds.
    pub fn step_tensor(steps: &[usize], device: tch::Device) -> Tensor {
        let v: Vec<f32> = steps.iter().map(|&n| n as f32).collect();
        Tensor::from_slice(&v)
            .to_kind(Kind::Float)
            .to_device(device)
    }
}

/// The paper's `Schedule_probability(iter, I_1, I_2)` (Algorithm 1): the
/// probability that a history comes from the model's own rollout. 0 while `iter
/// <= I_1` (fully supervised), 1 once `iter > I_1 + I_2` (rollout training),
/// `(iter - I_1) / I_2` in between (scheduled training). `iter` counts the steps
/// done before this one (from 0).
pub fn rollout_probability(iter: usize, i1: usize, i2: usize) -> f64 {
    if iter <= i1 {
        0.0
    } else if iter > i1 + i2 {
        1.0
    } else {
        (iter - i1) as f64 / i2 as f64
    }
}
