//! The online diffusion-AMP discriminator (the paper's Algorithm "Training with
//! Online Diffusion AMP"): `D(Φ(s_t), Φ(s_{t+1}))` trained with the LSGAN
//! objective, world-model transitions `(s_t, ŝ_{t+1})` as real (+1) and the
//! policy's `(s_t, s_{t+1})` as fake (−1), plus a gradient penalty on the real
//! samples (AMP's); the style reward is `max(0, 1 − 0.25 (D − 1)²)`.
//!
//! `Φ(s)` ([`AMP_FEATURES`]) is the motion part of the actor state: the pelvis's
//! angular velocity, the projected gravity, the joints' positions and
//! velocities (64 floats, scaled as in the state). The command, the last action
//! and the gait clock are left out: they say what was asked, not how the body
//! moved. Inputs are normalized by running statistics of both kinds of samples
//! (saved with the discriminator).
use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Device, Kind, Tensor};

use crate::env::obs::{ANG_VEL, DOF_VEL};
use crate::rl::normalizer::RunningNorm;
use crate::rl::optim::Adam;

/// The slice of the state that is `Φ(s)`.
pub const AMP_FEATURES: std::ops::Range<usize> = ANG_VEL.start..DOF_VEL.end;
/// `|Φ(s)|`.
pub const AMP_DIM: usize = AMP_FEATURES.end - AMP_FEATURES.start;

/// The discriminator's config (`amp:` in a unified config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AmpConfig {
    /// Hidden layers of the MLP (ReLU), AMP's [1024, 512].
    pub hidden: Vec<i64>,
    pub learning_rate: f64,
    /// Weight of the gradient penalty `E_real ||∇_x D||²` (AMP: 10).
    pub grad_penalty: f64,
    /// Weight decay of the output layer's weights (AMP's logit regularization).
    pub logit_reg: f64,
    /// Discriminator updates per PPO iteration, each on `batch` real and `batch` fake transitions.
    pub updates: usize,
    pub batch: usize,
}

impl Default for AmpConfig {
    fn default() -> Self {
        AmpConfig {
            hidden: vec![1024, 512],
            learning_rate: 1e-4,
            grad_penalty: 10.0,
            logit_reg: 0.05,
            updates: 4,
            batch: 512,
        }
    }
}

impl AmpConfig {
    /// Why the section cannot train a discriminator, if it cannot.
    pub fn check(&self) -> Result<(), String> {
        if self.updates == 0
            || self.batch == 0
            || self.hidden.is_empty()
            || self.hidden.iter().any(|&h| h < 1)
        {
            return Err("updates, batch and every hidden size must be at least 1".into());
        }
        if !(self.learning_rate > 0.0 && self.grad_penalty >= 0.0 && self.logit_reg >= 0.0) {
            return Err(
                "learning_rate must be positive, grad_penalty and logit_reg not negative".into(),
            );
        }
        Ok(())
    }
}

/// What one discriminator update measured.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AmpStats {
    /// LSGAN loss (both terms), without the penalties.
    pub loss: f64,
    pub grad_penalty: f64,
    /// Mean D on the real and on the fake samples.
    pub d_real: f64,
    pub d_fake: f64,
    /// Fraction classified right (D > 0 on real, D < 0 on fake).
    pub accuracy: f64,
}

/// `D` with its optimizer and input statistics.
pub struct Discriminator {
    pub vs: nn::VarStore,
    net: nn::Sequential,
    out: nn::Linear,
    pub adam: Adam,
    pub norm: RunningNorm,
    pub cfg: AmpConfig,
}

impl Discriminator {
    /// Fresh weights (seed torch first for reproducibility).
    pub fn new(cfg: &AmpConfig, device: Device) -> Discriminator {
        let vs = nn::VarStore::new(device);
        let p = vs.root() / "disc";
        let mut net = nn::seq();
        let mut d = 2 * AMP_DIM as i64;
        for (i, &h) in cfg.hidden.iter().enumerate() {
            net = net
                .add(nn::linear(&p / i, d, h, Default::default()))
                .add_fn(|x| x.relu());
            d = h;
        }
        let out = nn::linear(&p / "out", d, 1, Default::default());
        let params: Vec<(String, Tensor)> = {
            let mut v: Vec<_> = vs.variables().into_iter().collect();
            v.sort_by(|a, b| a.0.cmp(&b.0));
            v
        };
        Discriminator {
            adam: Adam::new(params, cfg.learning_rate),
            vs,
            net,
            out,
            norm: RunningNorm::new(2 * AMP_DIM),
            cfg: cfg.clone(),
        }
    }

    /// `Φ(s) ‖ Φ(s')` of `n` transitions given as rows of states (any width
    /// that holds [`AMP_FEATURES`]), into `[n, 2 AMP_DIM]` floats.
    pub fn features(s: &[f32], s_next: &[f32], state_dim: usize) -> Vec<f32> {
        let n = s.len() / state_dim;
        let mut out = Vec::with_capacity(n * 2 * AMP_DIM);
        for i in 0..n {
            out.extend_from_slice(&s[i * state_dim..][AMP_FEATURES]);
            out.extend_from_slice(&s_next[i * state_dim..][AMP_FEATURES]);
        }
        out
    }

    fn normalized(&self, x: &[f32]) -> Tensor {
        let n = x.len() / (2 * AMP_DIM);
        let mut y = vec![0.0f32; x.len()];
        for (row, out) in x.chunks(2 * AMP_DIM).zip(y.chunks_mut(2 * AMP_DIM)) {
            self.norm.apply(row, out);
        }
        Tensor::from_slice(&y)
            .reshape([n as i64, 2 * AMP_DIM as i64])
            .to_device(self.vs.device())
    }

    fn forward(&self, x: &Tensor) -> Tensor {
        self.out.forward(&self.net.forward(x)).squeeze_dim(-1)
    }

    /// D of `n` feature rows ([`Discriminator::features`]).
    pub fn d(&self, x: &[f32]) -> Vec<f32> {
        tch::no_grad(|| Vec::<f32>::try_from(self.forward(&self.normalized(x))).unwrap_or_default())
    }

    /// The style reward `max(0, 1 − 0.25 (D − 1)²)` of `n` feature rows.
    pub fn style_reward(&self, x: &[f32]) -> Vec<f32> {
        self.d(x)
            .into_iter()
            .map(|d| (1.0 - 0.25 * (d - 1.0) * (d - 1.0)).max(0.0))
            .collect()
    }

    /// One update on `real` (world-model transitions) and `fake` (the policy's)
    /// feature rows; the input statistics take both in first.
    pub fn update(&mut self, real: &[f32], fake: &[f32]) -> AmpStats {
        self.norm.update(real);
        self.norm.update(fake);
        let xr = self.normalized(real).set_requires_grad(true);
        let xf = self.normalized(fake);
        let dr = self.forward(&xr);
        let df = self.forward(&xf);
        let lsgan = (&dr - 1.0).square().mean(Kind::Float) + (&df + 1.0).square().mean(Kind::Float);
        let grad = Tensor::run_backward(&[dr.sum(Kind::Float)], &[&xr], true, true)
            .pop()
            .expect("one gradient");
        let gp = grad
            .square()
            .sum_dim_intlist(-1, false, Kind::Float)
            .mean(Kind::Float);
        let reg = self.out.ws.square().sum(Kind::Float);
        let loss = &lsgan + &gp * self.cfg.grad_penalty + reg * self.cfg.logit_reg;
        self.adam.zero_grad();
        loss.backward();
        self.adam.step();
        let f = |t: &Tensor| t.double_value(&[]);
        let acc = (dr.gt(0.0).to_kind(Kind::Float).mean(Kind::Float)
            + df.lt(0.0).to_kind(Kind::Float).mean(Kind::Float))
            / 2.0;
        AmpStats {
            loss: f(&lsgan),
            grad_penalty: f(&gp),
            d_real: f(&dr.mean(Kind::Float)),
            d_fake: f(&df.mean(Kind::Float)),
            accuracy: f(&acc),
        }
    }

    /// `updates` updates on batches of `batch` rows drawn uniformly (with
    /// replacement) from `real` and `fake` (feature rows), the draws seeded by
    /// `seed` and Adam's step; the mean of their [`AmpStats`], or NaNs when
    /// either side is empty.
    pub fn train_on(&mut self, real: &[f32], fake: &[f32], seed: u64) -> AmpStats {
        use rand::{Rng, SeedableRng};
        let row = 2 * AMP_DIM;
        let (nr, nf) = (real.len() / row, fake.len() / row);
        if nr == 0 || nf == 0 {
            let nan = f64::NAN;
            return AmpStats {
                loss: nan,
                grad_penalty: nan,
                d_real: nan,
                d_fake: nan,
                accuracy: nan,
            };
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
            seed ^ (self.adam.step as u64).wrapping_mul(0x9E37_79B9),
        );
        let (b, updates) = (self.cfg.batch, self.cfg.updates);
        let mut mean = AmpStats::default();
        for _ in 0..updates {
            let mut pick = |src: &[f32], n: usize| {
                let mut out = Vec::with_capacity(b * row);
                for _ in 0..b {
                    let j = rng.random_range(0..n);
                    out.extend_from_slice(&src[j * row..(j + 1) * row]);
                }
                out
            };
            let r = pick(real, nr);
            let f = pick(fake, nf);
            let s = self.update(&r, &f);
            mean.loss += s.loss;
            mean.grad_penalty += s.grad_penalty;
            mean.d_real += s.d_real;
            mean.d_fake += s.d_fake;
            mean.accuracy += s.accuracy;
        }
        let u = updates as f64;
        AmpStats {
            loss: mean.loss / u,
            grad_penalty: mean.grad_penalty / u,
            d_real: mean.d_real / u,
            d_fake: mean.d_fake / u,
            accuracy: mean.accuracy / u,
        }
    }

    /// The weights, Adam's moments and step and the input statistics, by name
    /// (`amp.<name>`: what a task saves in its checkpoint).
    pub fn named_tensors(&self) -> Vec<(String, Tensor)> {
        let mut out: Vec<(String, Tensor)> = self
            .vs
            .variables()
            .into_iter()
            .map(|(k, v)| (format!("amp.{k}"), v.detach()))
            .collect();
        for (k, v) in self.adam.named_moments() {
            out.push((format!("amp.{k}"), v));
        }
        out.push((
            "amp.adam_step".into(),
            Tensor::from_slice(&[self.adam.step]),
        ));
        out.push(("amp.norm".into(), Tensor::from_slice(&self.norm.to_vec())));
        out
    }

    /// Copy in what [`Discriminator::named_tensors`] saved, looked up by name.
    pub fn load_named(&mut self, get: &dyn Fn(&str) -> Option<Tensor>) -> Result<(), String> {
        let names: Vec<String> = self.named_tensors().into_iter().map(|(k, _)| k).collect();
        let mut saved = std::collections::HashMap::new();
        for k in names {
            let t = get(&k)
                .ok_or_else(|| format!("the checkpoint holds no '{k}' (the discriminator)"))?;
            saved.insert(k, t);
        }
        for (k, mut v) in self.vs.variables() {
            let src = &saved[&format!("amp.{k}")];
            if src.size() != v.size() {
                return Err(format!(
                    "discriminator '{k}' has shape {:?}, the config's {:?} (amp.hidden changed?)",
                    src.size(),
                    v.size()
                ));
            }
            tch::no_grad(|| v.copy_(src));
        }
        self.adam
            .load_moments(|k| saved.get(&format!("amp.{k}")).ok_or(()))
            .map_err(|()| "discriminator moments missing".to_string())?;
        self.adam.step = saved["amp.adam_step"].int64_value(&[0]);
        let v = Vec::<f64>::try_from(&saved["amp.norm"].to_kind(Kind::Double))
            .map_err(|e| e.to_string())?;
        let frozen = self.norm.frozen;
        self.norm = RunningNorm::from_vec(2 * AMP_DIM, &v)
            .ok_or("discriminator input statistics of the wrong size")?;
        self.norm.frozen = frozen;
        Ok(())
    }
}
