//! Reverse-process samplers from the x0 prediction, with classifier-free
//! guidance, and seeded Gaussian noise.
//!
//! Guidance (the paper's Eq. for `G_omega`): `x0 = x0_uncond + omega (x0_cond -
//! x0_uncond)`. `omega = 0` runs the unconditional model only and `omega = 1` the
//! conditional model only (exactly those models, one forward pass each); any
//! other `omega` runs both in one batch of `2B`.
//!
//! * DDPM (ancestral, all `N` steps): `x^{n-1} ~ N(c1 x0_hat + c2 x^n, beta~_n I)`
//!   with `c1 = sqrt(alpha_bar_{n-1}) beta_n / (1 - alpha_bar_n)`, `c2 =
//!   sqrt(alpha_n) (1 - alpha_bar_{n-1}) / (1 - alpha_bar_n)`, `beta~_n = beta_n
//!   (1 - alpha_bar_{n-1}) / (1 - alpha_bar_n)`; the last step returns `x0_hat`.
//! * DDIM (eta = 0, `k` steps [`NoiseSchedule::ddim_steps`]): `eps_hat = (x^n -
//!   sqrt(alpha_bar_n) x0_hat) / sqrt(1 - alpha_bar_n)`, `x^m = sqrt(alpha_bar_m)
//!   x0_hat + sqrt(1 - alpha_bar_m) eps_hat` for the next visited step `m`
//!   (`alpha_bar_0 = 1`: the last step returns `x0_hat`).
//!
//! Noise comes from a [`Noise`] (ChaCha8, seeded), never from libtorch's global
//! generator: a fixed seed gives the same samples whatever else ran before.
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use tch::{Device, Tensor};

use super::denoiser::Denoiser;
use super::schedule::NoiseSchedule;
use crate::world_model::config::{SamplerKind, SamplingConfig};

/// A seeded source of standard-normal tensors (and uniform draws).
pub struct Noise {
    pub rng: ChaCha8Rng,
}

impl Noise {
    pub fn new(seed: u64) -> Noise {
        Noise {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// `N(0, I)` of `shape` on `device`.
    pub fn randn(&mut self, shape: &[i64], device: Device) -> Tensor {
        let n: i64 = shape.iter().product();
        let v: Vec<f32> = (0..n)
            .map(|_| StandardNormal.sample(&mut self.rng))
            .collect();
        Tensor::from_slice(&v).view(shape).to_device(device)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        rand::Rng::random::<f64>(&mut self.rng)
    }

    /// Uniform integer in `lo..=hi`.
    pub fn int(&mut self, lo: usize, hi: usize) -> usize {
        rand::Rng::random_range(&mut self.rng, lo..=hi)
    }
}

/// The guided x0 prediction at step `n` for every row.
/// `y` is the conditional terrain embedding `[B, terrain_dim]`.
pub fn guided_x0(
    net: &Denoiser,
    x_n: &Tensor,
    hist: &Tensor,
    n: usize,
    y: &Tensor,
    guidance: f64,
) -> Tensor {
    let b = x_n.size()[0];
    let steps = NoiseSchedule::step_tensor(&vec![n; b as usize], x_n.device());
    if guidance == 1.0 {
        return net.forward(x_n, hist, &steps, y);
    }
    let null = net.null_embedding(b);
    if guidance == 0.0 {
        return net.forward(x_n, hist, &steps, &null);
    }
    let both = net.forward(
        &Tensor::cat(&[x_n, x_n], 0),
        &Tensor::cat(&[hist, hist], 0),
        &Tensor::cat(&[&steps, &steps], 0),
        &Tensor::cat(&[y, &null], 0),
    );
    let cond = both.narrow(0, 0, b);
    let uncond = both.narrow(0, b, b);
    &uncond + (cond - &uncond) * guidance
}

/// Sample `[B, H, S]` normalized future states given the normalized history
/// `hist [B, K, S]` and the conditional terrain embedding `y`, starting from
/// `x_start` (pure noise at inference; the training rollouts start from the
/// ground truth noised to step `N`, as the paper's Algorithm 2). No gradients.
pub fn sample_from(
    net: &Denoiser,
    sched: &NoiseSchedule,
    cfg: &SamplingConfig,
    hist: &Tensor,
    y: &Tensor,
    x_start: Tensor,
    noise: &mut Noise,
) -> Tensor {
    tch::no_grad(|| {
        let mut x = x_start;
        let dev = x.device();
        match cfg.sampler {
            SamplerKind::Ddpm => {
                for n in (1..=sched.steps()).rev() {
                    let x0 = guided_x0(net, &x, hist, n, y, cfg.guidance);
                    if n == 1 {
                        x = x0;
                        break;
                    }
                    let (ab, ab_prev, beta) =
                        (sched.alpha_bar(n), sched.alpha_bar(n - 1), sched.beta(n));
                    let c1 = ab_prev.sqrt() * beta / (1.0 - ab);
                    let c2 = (1.0 - beta).sqrt() * (1.0 - ab_prev) / (1.0 - ab);
                    let var = beta * (1.0 - ab_prev) / (1.0 - ab);
                    let z = noise.randn(&x.size(), dev);
                    x = x0 * c1 + &x * c2 + z * var.sqrt();
                }
            }
            SamplerKind::Ddim => {
                let steps = sched.ddim_steps(cfg.ddim_steps);
                for (i, &n) in steps.iter().enumerate() {
                    let x0 = guided_x0(net, &x, hist, n, y, cfg.guidance);
                    let m = steps.get(i + 1).copied().unwrap_or(0);
                    if m == 0 {
                        x = x0;
                        break;
                    }
                    let ab = sched.alpha_bar(n);
                    let eps = (&x - &x0 * ab.sqrt()) / (1.0 - ab).sqrt();
                    let ab_m = sched.alpha_bar(m);
                    x = x0 * ab_m.sqrt() + eps * (1.0 - ab_m).sqrt();
                }
            }
        }
        x
    })
}

/// [`sample_from`] starting from pure noise drawn from `noise`.
pub fn sample(
    net: &Denoiser,
    sched: &NoiseSchedule,
    cfg: &SamplingConfig,
    hist: &Tensor,
    y: &Tensor,
    noise: &mut Noise,
) -> Tensor {
    let sz = hist.size();
    let (b, s) = (sz[0], sz[sz.len() - 1]);
    let h = net.config().horizon as i64;
    let x = noise.randn(&[b, h, s], hist.device());
    sample_from(net, sched, cfg, hist, y, x, noise)
}
