//! The actor-critic of the paper's specialists:
//! `a_t = F(E_hist(o_hist), E_scan(scandots), o_t)` and
//! `v_t = C(E_scan'(scandots), o_t^critic)`, a Gaussian policy with a
//! state-independent standard deviation bounded below by `min_std`.
//!
//! With `policy.estimator`, the actor also reads its privileged-information
//! estimator's base-velocity estimate (detached) between the scan latent and
//! `o_t`.
//!
//! Inputs are already normalized. The actor input row is the `K` past states then
//! the current one (`(K + 1) x obs` floats, oldest first); the critic reads the
//! privileged critic observation (no history: it sees the base velocity the
//! history would estimate) and has its own scan encoder.
use tch::nn::{self, Module, RNN};
use tch::{Kind, Tensor};

use crate::rl::config::{Activation, HistoryKind, PolicyConfig, ScanEncoderKind, ESTIMATE_DIM};

use crate::env::task::TaskDims;

/// The networks and the variable store that owns them.
pub struct ActorCritic {
    pub vs: nn::VarStore,
    pub cfg: PolicyConfig,
    pub dims: TaskDims,
    hist: HistEncoder,
    scan_actor: Option<SeqEncoder>,
    scan_critic: Option<SeqEncoder>,
    actor: nn::Sequential,
    critic: nn::Sequential,
    log_std: Tensor,
    /// The privileged-information estimator (`policy.estimator`).
    est: Option<nn::Sequential>,
}

enum HistEncoder {
    None,
    Mlp(nn::Sequential),
    Gru(nn::GRU),
}

/// The scan (or future) encoder: an MLP over the whole input, or a GRU over
/// its `steps` steps of `step` floats.
enum SeqEncoder {
    Mlp(nn::Sequential),
    Gru {
        gru: nn::GRU,
        steps: i64,
        step: i64,
        hidden: i64,
    },
}

impl SeqEncoder {
    fn new(p: nn::Path, input: i64, cfg: &PolicyConfig) -> SeqEncoder {
        let se = &cfg.scan_encoder;
        match se.kind {
            ScanEncoderKind::Mlp => SeqEncoder::Mlp(mlp(p, input, &se.dims, None, cfg.activation)),
            ScanEncoderKind::Gru => {
                let step = se.step.max(1) as i64;
                let c = nn::RNNConfig {
                    batch_first: true,
                    ..Default::default()
                };
                SeqEncoder::Gru {
                    gru: nn::gru(p, step, se.gru_hidden, c),
                    steps: input / step,
                    step,
                    hidden: se.gru_hidden,
                }
            }
        }
    }

    fn forward(&self, x: &Tensor) -> Tensor {
        match self {
            SeqEncoder::Mlp(m) => m.forward(x),
            SeqEncoder::Gru {
                gru,
                steps,
                step,
                hidden,
            } => gru_last(gru, &x.reshape([-1, *steps, *step]), *hidden),
        }
    }
}

/// The last hidden state of `gru` over `seq` `[B, T, in]` from a zero state
/// shaped from the input, so that a traced (exported) policy keeps a free batch
/// size.
fn gru_last(gru: &nn::GRU, seq: &Tensor, hidden: i64) -> Tensor {
    let h0 = seq
        .select(1, 0)
        .narrow(1, 0, 1)
        .zeros_like()
        .repeat([1, hidden])
        .unsqueeze(0);
    let t = seq.size()[1];
    let (out, _) = gru.seq_init(seq, &nn::GRUState(h0));
    out.select(1, t - 1)
}

fn act(a: Activation) -> impl Fn(&Tensor) -> Tensor + Send {
    move |x: &Tensor| match a {
        Activation::Elu => x.elu(),
        Activation::Relu => x.relu(),
        Activation::Tanh => x.tanh(),
    }
}

/// MLP `input -> hidden... -> out` (activation after every hidden layer, and after
/// the last one when `out` is None: an encoder). The output layer's weights are
/// scaled by `out_gain`.
fn mlp(
    p: nn::Path,
    input: i64,
    hidden: &[i64],
    out: Option<(i64, f64)>,
    a: Activation,
) -> nn::Sequential {
    let mut seq = nn::seq();
    let mut d = input;
    for (i, &h) in hidden.iter().enumerate() {
        seq = seq
            .add(nn::linear(&p / i, d, h, Default::default()))
            .add_fn(act(a));
        d = h;
    }
    if let Some((o, gain)) = out {
        let lin = nn::linear(&p / hidden.len(), d, o, Default::default());
        tch::no_grad(|| {
            let _ = lin.ws.shallow_clone().g_mul_scalar_(gain);
            if let Some(b) = &lin.bs {
                let _ = b.shallow_clone().zero_();
            }
        });
        seq = seq.add(lin);
    }
    seq
}

impl ActorCritic {
    /// Build on `device` with fresh weights (seed torch first for reproducibility).
    pub fn new(cfg: &PolicyConfig, dims: TaskDims, device: tch::Device) -> ActorCritic {
        let vs = nn::VarStore::new(device);
        let root = vs.root();
        let a = cfg.activation;
        let k = cfg.history.length as i64;
        let obs = dims.obs as i64;
        let (hist, hist_out) = match cfg.history.kind {
            HistoryKind::None => (HistEncoder::None, 0),
            HistoryKind::Mlp => {
                let d = &cfg.history.mlp_dims;
                (
                    HistEncoder::Mlp(mlp(&root / "hist", k * obs, d, None, a)),
                    *d.last().unwrap_or(&0),
                )
            }
            HistoryKind::Gru => {
                let h = cfg.history.gru_hidden;
                let c = nn::RNNConfig {
                    batch_first: true,
                    ..Default::default()
                };
                (HistEncoder::Gru(nn::gru(&root / "hist", obs, h, c)), h)
            }
        };
        let use_scan = cfg.scan_encoder.enabled && dims.scan > 0;
        let scan_out = if use_scan {
            cfg.scan_encoder.latent()
        } else {
            0
        };
        let scan = dims.scan as i64;
        let scan_actor = use_scan.then(|| SeqEncoder::new(&root / "scan_actor", scan, cfg));
        let scan_critic = use_scan.then(|| SeqEncoder::new(&root / "scan_critic", scan, cfg));
        let est_out = if cfg.estimator.is_some() {
            ESTIMATE_DIM as i64
        } else {
            0
        };
        let actor = mlp(
            &root / "actor",
            hist_out + scan_out + est_out + obs,
            &cfg.actor_hidden,
            Some((dims.action as i64, 0.01)),
            a,
        );
        let critic = mlp(
            &root / "critic",
            scan_out + dims.critic as i64,
            &cfg.critic_hidden,
            Some((1, 1.0)),
            a,
        );
        let log_std = root.var_copy(
            "log_std",
            &Tensor::full(
                [dims.action as i64],
                cfg.init_std.ln(),
                (Kind::Float, device),
            ),
        );
        // made last, so that the other layers draw the same initial weights
        // with and without it
        let est = cfg.estimator.as_ref().map(|e| {
            mlp(
                &root / "est",
                (k + 1) * obs,
                &e.dims,
                Some((ESTIMATE_DIM as i64, 1.0)),
                a,
            )
        });
        ActorCritic {
            vs,
            cfg: cfg.clone(),
            dims,
            hist,
            scan_actor,
            scan_critic,
            actor,
            critic,
            log_std,
            est,
        }
    }

    /// Floats per actor input row: `(K + 1) x obs` with a history encoder, else `obs`.
    pub fn actor_input_dim(&self) -> usize {
        self.history_len() * self.dims.obs + self.dims.obs
    }

    /// Past states the actor sees (0 without a history encoder).
    pub fn history_len(&self) -> usize {
        match self.hist {
            HistEncoder::None => 0,
            _ => self.cfg.history.length,
        }
    }

    /// Whether the networks read scandots.
    pub fn uses_scan(&self) -> bool {
        self.scan_actor.is_some()
    }

    /// Mean action `[B, action]` from actor rows `[B, (K+1) obs]` and scandots `[B, scan]`.
    pub fn actor_mean(&self, actor_in: &Tensor, scan: Option<&Tensor>) -> Tensor {
        let obs = self.dims.obs as i64;
        let k = self.history_len() as i64;
        let cur = actor_in.narrow(1, k * obs, obs);
        let mut parts = Vec::with_capacity(3);
        match &self.hist {
            HistEncoder::None => {}
            HistEncoder::Mlp(m) => parts.push(m.forward(&actor_in.narrow(1, 0, k * obs))),
            HistEncoder::Gru(g) => {
                let seq = actor_in.narrow(1, 0, k * obs).reshape([-1, k, obs]);
                parts.push(gru_last(g, &seq, self.cfg.history.gru_hidden));
            }
        }
        if let (Some(enc), Some(s)) = (&self.scan_actor, scan) {
            parts.push(enc.forward(s));
        }
        if let Some(e) = &self.est {
            parts.push(e.forward(actor_in).detach());
        }
        parts.push(cur);
        self.actor.forward(&Tensor::cat(&parts, 1))
    }

    /// The estimator's base linear velocity `[B, 3]` (normalized units, with
    /// its gradient) from actor rows, None without `policy.estimator`.
    pub fn estimate(&self, actor_in: &Tensor) -> Option<Tensor> {
        self.est.as_ref().map(|e| e.forward(actor_in))
    }

    /// Whether the policy has the privileged-information estimator.
    pub fn has_estimator(&self) -> bool {
        self.est.is_some()
    }

    /// The actor's scan (or future) latent of normalized scan rows `[B, scan]`
    /// (None without a scan encoder).
    pub fn scan_latent(&self, scan: &Tensor) -> Option<Tensor> {
        self.scan_actor.as_ref().map(|e| e.forward(scan))
    }

    /// Value `[B]` from critic rows and scandots.
    pub fn value(&self, critic_in: &Tensor, scan: Option<&Tensor>) -> Tensor {
        let x = match (&self.scan_critic, scan) {
            (Some(enc), Some(s)) => Tensor::cat(&[enc.forward(s), critic_in.shallow_clone()], 1),
            _ => critic_in.shallow_clone(),
        };
        self.critic.forward(&x).squeeze_dim(1)
    }

    /// Set every action dimension's standard deviation to `std`.
    pub fn set_std(&mut self, std: f64) {
        tch::no_grad(|| {
            let _ = self.log_std.fill_(std.ln());
        });
    }

    /// Action standard deviation `[action]`, bounded below by `min_std`.
    pub fn std(&self) -> Tensor {
        self.log_std.exp().clamp_min(self.cfg.min_std)
    }

    /// Log-density of `actions` under N(mean, std), summed over the action dims.
    pub fn log_prob(mean: &Tensor, std: &Tensor, actions: &Tensor) -> Tensor {
        let z = (actions - mean) / std;
        (z.square() * -0.5 - std.log() - 0.5 * (2.0 * std::f64::consts::PI).ln()).sum_dim_intlist(
            -1,
            false,
            Kind::Float,
        )
    }

    /// Entropy of N(·, std) summed over the action dims (a scalar).
    pub fn entropy(std: &Tensor) -> Tensor {
        (std.log() + 0.5 + 0.5 * (2.0 * std::f64::consts::PI).ln()).sum(Kind::Float)
    }

    /// Learnable variables sorted by name (optimizer and checkpoint order).
    pub fn named_parameters(&self) -> Vec<(String, Tensor)> {
        let mut v: Vec<(String, Tensor)> = self.vs.variables().into_iter().collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    /// Number of learnable floats.
    pub fn num_parameters(&self) -> i64 {
        self.named_parameters()
            .iter()
            .map(|(_, t)| t.numel() as i64)
            .sum()
    }
}
