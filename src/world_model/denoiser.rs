//! The DiT denoiser `x0_hat = G(x^n, x_hist, n, y)`.
//!
//! Tokens: the `K` clean history states, then the `H` noisy future states, each
//! `state -> hidden` through a linear map of its own kind (history or noisy), plus
//! a learned positional embedding per token. Conditioning `c = MLP(sin/cos(n)) + W y`, with `y` the terrain
//! embedding (an MLP over the normalized scandots, `terrain_dim` wide) or the
//! learned null embedding (classifier-free guidance). `L` DiT blocks with
//! adaLN-Zero (shift, scale and gate of the attention and MLP branches from `c`,
//! zero-initialized so that every block starts as the identity), multi-head
//! self-attention over all `K + H` tokens, a final adaLN and a linear map back
//! to the state on the `H` future tokens (zero-initialized: the first prediction
//! is the normalized mean). With `history_skip`, a linear map of the flattened
//! history (zero-initialized) is added to that prediction. Works in normalized
//! units ([`Normalizer`]).
use tch::nn::{self, Init, LinearConfig, Module};
use tch::{Device, Kind, Tensor};

use crate::data::DatasetStats;
use crate::world_model::config::ModelConfig;

/// Per-dimension mean/std of states and scandots as tensors; a dimension with
/// zero spread gets std 1 (it is constant: normalizing leaves it at 0).
#[derive(Debug)]
pub struct Normalizer {
    pub state_mean: Tensor,
    pub state_std: Tensor,
    pub scan_mean: Tensor,
    pub scan_std: Tensor,
}

impl Clone for Normalizer {
    fn clone(&self) -> Self {
        Normalizer {
            state_mean: self.state_mean.copy(),
            state_std: self.state_std.copy(),
            scan_mean: self.scan_mean.copy(),
            scan_std: self.scan_std.copy(),
        }
    }
}

impl Normalizer {
    pub fn from_stats(s: &DatasetStats, device: Device) -> Normalizer {
        let t = |v: &[f64], std: bool| {
            let f: Vec<f32> = v
                .iter()
                .map(|&x| {
                    if std && (x.is_nan() || x <= 1e-8) {
                        1.0
                    } else {
                        x as f32
                    }
                })
                .collect();
            Tensor::from_slice(&f).to_device(device)
        };
        Normalizer {
            state_mean: t(&s.state.mean, false),
            state_std: t(&s.state.std, true),
            scan_mean: t(&s.scan.mean, false),
            scan_std: t(&s.scan.std, true),
        }
    }

    /// Named tensors for a checkpoint (`norm.<name>`).
    pub fn named(&self) -> Vec<(String, Tensor)> {
        [
            ("state_mean", &self.state_mean),
            ("state_std", &self.state_std),
            ("scan_mean", &self.scan_mean),
            ("scan_std", &self.scan_std),
        ]
        .into_iter()
        .map(|(n, t)| (format!("norm.{n}"), t.shallow_clone()))
        .collect()
    }

    /// States `[..., S]` to normalized units.
    pub fn states(&self, x: &Tensor) -> Tensor {
        (x - &self.state_mean) / &self.state_std
    }

    /// Normalized states back to raw units.
    pub fn unstates(&self, z: &Tensor) -> Tensor {
        z * &self.state_std + &self.state_mean
    }

    /// Scandots `[..., C]` to normalized units.
    pub fn scans(&self, x: &Tensor) -> Tensor {
        (x - &self.scan_mean) / &self.scan_std
    }
}

fn zero_linear(p: nn::Path, i: i64, o: i64) -> nn::Linear {
    nn::linear(
        p,
        i,
        o,
        LinearConfig {
            ws_init: Init::Const(0.0),
            bs_init: Some(Init::Const(0.0)),
            bias: true,
        },
    )
}

fn layer_norm(x: &Tensor, d: i64) -> Tensor {
    x.layer_norm([d], None::<Tensor>, None::<Tensor>, 1e-6, false)
}

/// `x * (1 + scale) + shift`, with `[B, d]` modulation broadcast over tokens.
fn modulate(x: &Tensor, shift: &Tensor, scale: &Tensor) -> Tensor {
    x * (scale.unsqueeze(1) + 1.0) + shift.unsqueeze(1)
}

/// One DiT block with adaLN-Zero.
#[derive(Debug)]
struct Block {
    ada: nn::Linear,
    qkv: nn::Linear,
    proj: nn::Linear,
    fc1: nn::Linear,
    fc2: nn::Linear,
    hidden: i64,
    heads: i64,
}

impl Block {
    fn new(p: nn::Path, hidden: i64, heads: i64, mlp_ratio: i64) -> Block {
        Block {
            ada: zero_linear(&p / "ada", hidden, 6 * hidden),
            qkv: nn::linear(&p / "qkv", hidden, 3 * hidden, Default::default()),
            proj: nn::linear(&p / "proj", hidden, hidden, Default::default()),
            fc1: nn::linear(&p / "fc1", hidden, mlp_ratio * hidden, Default::default()),
            fc2: nn::linear(&p / "fc2", mlp_ratio * hidden, hidden, Default::default()),
            hidden,
            heads,
        }
    }

    /// `x`: `[B, T, d]`; `c_act`: `SiLU(c)`, `[B, d]`.
    fn forward(&self, x: &Tensor, c_act: &Tensor) -> Tensor {
        // no batch size read from the input: a traced export keeps any batch
        let (t, d, h) = (x.size()[1], self.hidden, self.heads);
        let m = self.ada.forward(c_act).chunk(6, -1);
        let a = modulate(&layer_norm(x, d), &m[0], &m[1]);
        let qkv = self
            .qkv
            .forward(&a)
            .view([-1, t, 3, h, d / h])
            .permute([2, 0, 3, 1, 4]);
        let att = Tensor::scaled_dot_product_attention(
            &qkv.get(0),
            &qkv.get(1),
            &qkv.get(2),
            None::<Tensor>,
            0.0,
            false,
            None,
            false,
        )
        .transpose(1, 2)
        .reshape([-1, t, d]);
        let x = x + m[2].unsqueeze(1) * self.proj.forward(&att);
        let a = modulate(&layer_norm(&x, d), &m[3], &m[4]);
        let f = self.fc2.forward(&self.fc1.forward(&a).gelu("tanh"));
        x + m[5].unsqueeze(1) * f
    }
}

/// The denoiser and the variables it owns (one [`nn::VarStore`]).
#[derive(Debug)]
pub struct Denoiser {
    pub vs: nn::VarStore,
    cfg: ModelConfig,
    state_dim: i64,
    scan_dim: i64,
    embed: nn::Linear,
    embed_hist: nn::Linear,
    pos: Tensor,
    skip: Option<nn::Linear>,
    step1: nn::Linear,
    step2: nn::Linear,
    terrain: Vec<nn::Linear>,
    null_terrain: Tensor,
    terrain_proj: nn::Linear,
    blocks: Vec<Block>,
    final_ada: nn::Linear,
    out: nn::Linear,
}

impl Denoiser {
    /// A fresh denoiser for states of `state_dim` and scandots of `scan_dim`
    /// (initialized from libtorch's global RNG: seed it first).
    pub fn new(cfg: &ModelConfig, state_dim: usize, scan_dim: usize, device: Device) -> Denoiser {
        let vs = nn::VarStore::new(device);
        let root = vs.root();
        let (s, c, d) = (state_dim as i64, scan_dim as i64, cfg.hidden);
        let tokens = (cfg.history + cfg.horizon) as i64;
        let std = Init::Randn {
            mean: 0.0,
            stdev: 0.02,
        };
        let mut terrain = Vec::new();
        let mut last = c;
        for (i, &h) in cfg.terrain_hidden.iter().enumerate() {
            terrain.push(nn::linear(
                &root / format!("terrain{i}"),
                last,
                h,
                Default::default(),
            ));
            last = h;
        }
        terrain.push(nn::linear(
            &root / "terrain_out",
            last,
            cfg.terrain_dim,
            Default::default(),
        ));
        Denoiser {
            embed: nn::linear(&root / "embed", s, d, Default::default()),
            embed_hist: nn::linear(&root / "embed_hist", s, d, Default::default()),
            pos: root.var("pos", &[tokens, d], std),
            skip: cfg.history_skip.then(|| {
                let (k, h) = (cfg.history as i64, cfg.horizon as i64);
                zero_linear(&root / "skip", k * s, h * s)
            }),
            step1: nn::linear(&root / "step1", cfg.step_features, d, Default::default()),
            step2: nn::linear(&root / "step2", d, d, Default::default()),
            terrain,
            null_terrain: root.var("null_terrain", &[cfg.terrain_dim], std),
            terrain_proj: nn::linear(
                &root / "terrain_proj",
                cfg.terrain_dim,
                d,
                Default::default(),
            ),
            blocks: (0..cfg.layers)
                .map(|i| Block::new(&root / format!("block{i}"), d, cfg.heads, cfg.mlp_ratio))
                .collect(),
            final_ada: zero_linear(&root / "final_ada", d, 2 * d),
            out: zero_linear(&root / "out", d, s),
            cfg: cfg.clone(),
            state_dim: s,
            scan_dim: c,
            vs,
        }
    }

    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }

    pub fn device(&self) -> Device {
        self.vs.device()
    }

    /// `(state, scan)` dims.
    pub fn dims(&self) -> (usize, usize) {
        (self.state_dim as usize, self.scan_dim as usize)
    }

    /// Parameters by name, in a fixed (sorted) order.
    pub fn named_parameters(&self) -> Vec<(String, Tensor)> {
        let mut v: Vec<(String, Tensor)> = self.vs.variables().into_iter().collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    pub fn num_parameters(&self) -> i64 {
        self.vs
            .trainable_variables()
            .iter()
            .map(|t| t.numel() as i64)
            .sum()
    }

    /// Set the history skip to the least-squares map from the flattened
    /// normalized histories `hist [N, K, S]` to the first horizon chunk
    /// `future [N, H, S]` (ridge `lambda` times the mean squared input on the
    /// diagonal, bias unpenalized, solved in double precision). Nothing
    /// without a skip (`history_skip: false`).
    pub fn fit_skip(&self, hist: &Tensor, future: &Tensor, lambda: f64) {
        let Some(skip) = self.skip.as_ref() else {
            return;
        };
        tch::no_grad(|| {
            let n = hist.size()[0];
            let x = hist.flatten(1, -1).to_kind(Kind::Double);
            let y = future.flatten(1, -1).to_kind(Kind::Double);
            let xa = Tensor::cat(&[&x, &Tensor::ones([n, 1], (Kind::Double, x.device()))], 1);
            let d = xa.size()[1];
            let mut a = xa.transpose(0, 1).matmul(&xa);
            let ridge = lambda * x.square().mean(Kind::Double).double_value(&[]) * n as f64;
            let eye = Tensor::ones([d], (Kind::Double, x.device()));
            let _ = eye.narrow(0, d - 1, 1).fill_(0.0);
            a += Tensor::diag_embed(&(eye * ridge), 0, -2, -1);
            let w = Tensor::linalg_solve(&a, &xa.transpose(0, 1).matmul(&y), true);
            let ws = w.narrow(0, 0, d - 1).transpose(0, 1).to_kind(Kind::Float);
            let bs = w.get(d - 1).to_kind(Kind::Float);
            let mut sw = skip.ws.shallow_clone();
            sw.copy_(&ws);
            if let Some(b) = &skip.bs {
                let mut b = b.shallow_clone();
                b.copy_(&bs);
            }
        })
    }

    /// Copy every parameter of `other` (same architecture) into this one.
    pub fn copy_from(&mut self, other: &Denoiser) -> Result<(), tch::TchError> {
        self.vs.copy(&other.vs)
    }

    /// `ema = decay * ema + (1 - decay) * live`, parameter by parameter.
    pub fn ema_update(&self, live: &Denoiser, decay: f64) {
        let src = live.named_parameters();
        tch::no_grad(|| {
            for ((_, mut e), (_, p)) in self.named_parameters().into_iter().zip(src) {
                let _ = e.g_mul_scalar_(decay).g_add_(&(p * (1.0 - decay)));
            }
        });
    }

    /// Terrain embedding `y = MLP(scan)` of normalized scandots `[B, C]`.
    pub fn terrain_embedding(&self, scan: &Tensor) -> Tensor {
        let n = self.terrain.len();
        let mut x = scan.shallow_clone();
        for (i, l) in self.terrain.iter().enumerate() {
            x = l.forward(&x);
            if i + 1 < n {
                x = x.silu();
            }
        }
        x
    }

    /// The learned null embedding, `[B, terrain_dim]`.
    pub fn null_embedding(&self, batch: i64) -> Tensor {
        self.null_terrain
            .unsqueeze(0)
            .expand([batch, self.cfg.terrain_dim], false)
    }

    /// `y` with the rows where `drop` (bool `[B]`) is true replaced by the null
    /// embedding.
    pub fn drop_terrain(&self, y: &Tensor, drop: &Tensor) -> Tensor {
        let b = y.size()[0];
        self.null_embedding(b).where_self(&drop.unsqueeze(1), y)
    }

    /// Sinusoidal features of the step numbers `n` (`[B]` float).
    fn step_features(&self, n: &Tensor) -> Tensor {
        let half = self.cfg.step_features / 2;
        let freqs = (Tensor::arange(half, (Kind::Float, n.device()))
            * (-(10_000f64.ln()) / half as f64))
            .exp();
        let args = n.unsqueeze(1) * freqs.unsqueeze(0);
        Tensor::cat(&[args.cos(), args.sin()], 1)
    }

    /// `x0_hat [B, H, S]` from the noisy future `x_n [B, H, S]`, the clean
    /// history `hist [B, K, S]` (normalized), the step numbers `n [B]` (float)
    /// and the terrain (or null) embedding `y [B, terrain_dim]`.
    pub fn forward(&self, x_n: &Tensor, hist: &Tensor, n: &Tensor, y: &Tensor) -> Tensor {
        let d = self.cfg.hidden;
        let k = self.cfg.history as i64;
        let h = self.cfg.horizon as i64;
        let tokens = Tensor::cat(&[self.embed_hist.forward(hist), self.embed.forward(x_n)], 1)
            + self.pos.unsqueeze(0);
        let step = self
            .step2
            .forward(&self.step1.forward(&self.step_features(n)).silu());
        let c = step + self.terrain_proj.forward(y);
        let c_act = c.silu();
        let mut x = tokens;
        for b in &self.blocks {
            x = b.forward(&x, &c_act);
        }
        let m = self.final_ada.forward(&c_act).chunk(2, -1);
        let x = modulate(&layer_norm(&x.narrow(1, k, h), d), &m[0], &m[1]);
        let out = self.out.forward(&x);
        match &self.skip {
            Some(skip) => {
                out + skip
                    .forward(&hist.flatten(1, -1))
                    .view([-1, h, self.state_dim])
            }
            None => out,
        }
    }

    /// Forward FLOPs of the matrix products for one sample (2 per multiply-add):
    /// token and output maps, every block's qkv, attention, projection and MLP,
    /// and the per-sample conditioning maps.
    pub fn flops_per_sample(&self) -> f64 {
        let c = &self.cfg;
        let d = c.hidden as f64;
        let t = (c.history + c.horizon) as f64;
        let s = self.state_dim as f64;
        let per_block_tokens =
            t * (3.0 * d * d + d * d + 2.0 * c.mlp_ratio as f64 * d * d) + 2.0 * t * t * d;
        let per_block_cond = 6.0 * d * d;
        let mut terrain = 0.0;
        let mut last = self.scan_dim as f64;
        for &h in &c.terrain_hidden {
            terrain += last * h as f64;
            last = h as f64;
        }
        terrain += last * c.terrain_dim as f64;
        let cond = c.step_features as f64 * d + d * d + c.terrain_dim as f64 * d + 2.0 * d * d;
        let skip = if c.history_skip {
            (c.history * c.horizon) as f64 * s * s
        } else {
            0.0
        };
        2.0 * (t * s * d
            + skip
            + c.layers as f64 * (per_block_tokens + per_block_cond)
            + c.horizon as f64 * d * s
            + terrain
            + cond)
    }
}
