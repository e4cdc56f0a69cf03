//! PPO's update (clipped surrogate, clipped value loss, entropy bonus, global
//! gradient clipping, adaptive-KL learning rate as rsl_rl has it), over the
//! minibatches of one rollout.
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use tch::{Kind, Tensor};

use super::agent::Agent;
use super::optim::Adam;
use super::policy::ActorCritic;
use super::storage::RolloutStorage;
use crate::rl::config::{LrSchedule, PpoConfig, SymmetryRatio, ESTIMATE_DIM};

/// Mean losses and diagnostics of one update.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Losses {
    pub value: f64,
    pub surrogate: f64,
    pub entropy: f64,
    /// Mean KL(old || new) over the minibatches.
    pub kl: f64,
    /// Fraction of samples whose ratio left [1 - clip, 1 + clip].
    pub clip_fraction: f64,
    /// 1 - Var(returns - values) / Var(returns), on the rollout's values.
    pub explained_variance: f64,
    pub learning_rate: f64,
    pub grad_norm: f64,
    pub mean_std: f64,
    /// The privileged-information estimator's mean squared error (normalized
    /// units; 0 without `policy.estimator`).
    pub estimator: f64,
}

/// PPO: its hyperparameters and optimizer.
pub struct Ppo {
    pub cfg: PpoConfig,
    pub opt: Adam,
    /// Mirror maps as index and sign tensors (symmetry augmentation), for the
    /// actor input, critic input, scandots and actions.
    mirror: Option<[(Tensor, Tensor); 4]>,
}

fn signed_perm(sp: &crate::env::mirror::SignedPerm) -> (Tensor, Tensor) {
    let idx: Vec<i64> = sp.perm.iter().map(|&p| p as i64).collect();
    (Tensor::from_slice(&idx), Tensor::from_slice(&sp.sign))
}

/// `[x; mirror(x)]` along the batch dimension. `x` holds normalized rows;
/// with `norm` (the normalizer's mean, std and clip) the mirror is taken of
/// the raw values and normalized again: the running statistics are not
/// symmetric (a gait that leans left has other means on its left joints), so
/// mirroring normalized values would give a mirrored state the policy never
/// sees.
fn with_mirror(x: &Tensor, m: &(Tensor, Tensor), norm: Option<&(Tensor, Tensor, f64)>) -> Tensor {
    let mirrored = match norm {
        Some((mean, std, clip)) => {
            let raw = x * std + mean;
            ((raw.index_select(1, &m.0) * &m.1 - mean) / std).clamp(-clip, *clip)
        }
        None => x.index_select(1, &m.0) * &m.1,
    };
    Tensor::cat(&[x.shallow_clone(), mirrored], 0)
}

/// The normalizers of `agent` as `(mean, std, clip)` for actor inputs (the
/// observation's, tiled over the history and the current state), critic inputs
/// and scandots; `None` each when inputs are not normalized.
fn mirror_norms(agent: &Agent) -> [Option<(Tensor, Tensor, f64)>; 3] {
    if !agent.normalize {
        return [None, None, None];
    }
    let k = agent.policy.history_len() as i64 + 1;
    let (om, os) = agent.obs_norm.tensors();
    let (cm, cs) = agent.critic_norm.tensors();
    let (sm, ss) = agent.scan_norm.tensors();
    [
        Some((
            om.repeat([k]),
            os.repeat([k]),
            f64::from(agent.obs_norm.clip),
        )),
        Some((cm, cs, f64::from(agent.critic_norm.clip))),
        Some((sm, ss, f64::from(agent.scan_norm.clip))),
    ]
}

/// PPO's clipped surrogate loss per sample (to minimize) and the ratios, from
/// the log-ratios `log(pi / pi_old)` and advantages `adv`: `max(-A r, -A
/// clip(r, 1 - eps, 1 + eps))`; with `dual_clip` `c`, log-ratios are clamped to
/// +-20 and a sample with `A < 0` adds at most `-c A` (dual-clip PPO).
pub fn surrogate_per_sample(
    log_ratio: &Tensor,
    adv: &Tensor,
    clip: f64,
    dual_clip: Option<f64>,
) -> (Tensor, Tensor) {
    let ratio = match dual_clip {
        Some(_) => log_ratio.clamp(-20.0, 20.0).exp(),
        None => log_ratio.exp(),
    };
    let surr = -(adv * &ratio);
    let surr_clipped = -(adv * ratio.clamp(1.0 - clip, 1.0 + clip));
    let mut per_sample = surr.max_other(&surr_clipped);
    if let Some(dc) = dual_clip {
        let bound = -(adv * dc);
        per_sample = per_sample
            .min_other(&bound)
            .where_self(&adv.lt(0.0), &per_sample);
    }
    (per_sample, ratio)
}

fn tensor(v: &[f32], rows: i64) -> Tensor {
    Tensor::from_slice(v).view([rows, -1])
}

impl Ppo {
    /// `mirror`: the task's mirror maps, used when `cfg.symmetry`.
    pub fn new(
        cfg: &PpoConfig,
        policy: &ActorCritic,
        mirror: Option<&crate::env::mirror::Mirror>,
    ) -> Ppo {
        let k = policy.history_len() + 1;
        let mirror = mirror.filter(|_| cfg.symmetry).map(|m| {
            [
                signed_perm(&m.obs.tiled(k)),
                signed_perm(&m.critic),
                signed_perm(&m.scan),
                signed_perm(&m.action),
            ]
        });
        let mut opt = Adam::new(policy.named_parameters(), cfg.learning_rate);
        if let Some(e) = &policy.cfg.estimator {
            opt.fix_lr("est.", e.learning_rate);
        }
        Ppo {
            cfg: cfg.clone(),
            opt,
            mirror,
        }
    }

    /// rsl_rl's adaptive-KL rule: lr / 1.5 when `kl` > 2x desired, x 1.5 when
    /// below half of it, within [1e-5, 1e-2].
    fn adapt_lr(&mut self, kl: f64) {
        let d = self.cfg.desired_kl;
        if !kl.is_finite() {
            return;
        }
        if kl > d * 2.0 {
            self.opt.lr = (self.opt.lr / 1.5).max(1e-5);
        } else if kl < d / 2.0 && kl > 0.0 {
            self.opt.lr = (self.opt.lr * 1.5).min(1e-2);
        }
    }

    /// Update `agent`'s policy on a full storage; `seed` orders the minibatches.
    pub fn update(&mut self, agent: &Agent, st: &RolloutStorage, seed: u64) -> Losses {
        let policy = &agent.policy;
        let c = &self.cfg.clone();
        let b = (st.filled * st.n) as i64;
        let mut actor_in = tensor(&st.actor_in, b);
        let mut critic_in = tensor(&st.critic_in, b);
        let mut scan = policy.uses_scan().then(|| tensor(&st.scan, b));
        let mut actions = tensor(&st.actions, b);
        let mut old_mean = tensor(&st.mean, b);
        let mut old_logp = Tensor::from_slice(&st.log_probs);
        let mut old_values = Tensor::from_slice(&st.values);
        let mut returns = Tensor::from_slice(&st.returns);
        let mut adv = Tensor::from_slice(&st.advantages);
        if c.normalize_advantage {
            adv = (&adv - adv.mean(Kind::Float)) / (adv.std(true) + 1e-8);
        }
        let old_std = tch::no_grad(|| policy.std());
        let explained_variance = {
            let var_r = returns.var(true).double_value(&[]);
            let var_e = (&returns - &old_values).var(true).double_value(&[]);
            if var_r > 0.0 {
                1.0 - var_e / var_r
            } else {
                f64::NAN
            }
        };

        // symmetry augmentation: the batch and its mirror image, with the same
        // advantages, returns and values (rsl_rl). The mirrored samples' old
        // log-probabilities are the originals' (`symmetry_ratio: behavior`,
        // rsl_rl's: the mirror of the old policy acted them) or the old
        // policy's own on the mirrored states and actions (`policy`: every
        // sample starts the update at ratio 1). With `behavior`, a policy that
        // is not symmetric to ~0.01 per joint puts nearly every mirrored sample
        // outside the clip range, and those with a negative advantage and a
        // large ratio dominate the gradient. The KL that steers the learning
        // rate is measured on the original samples only, as rsl_rl does.
        let b_orig = b;
        let mut b = b;
        if let Some([ma, mc, ms, mact]) = &self.mirror {
            let [na, nc, ns] = mirror_norms(agent);
            actor_in = with_mirror(&actor_in, ma, na.as_ref());
            critic_in = with_mirror(&critic_in, mc, nc.as_ref());
            scan = scan.map(|s| with_mirror(&s, ms, ns.as_ref()));
            actions = with_mirror(&actions, mact, None);
            old_mean = with_mirror(&old_mean, mact, None);
            let twice = |t: &Tensor| Tensor::cat(&[t.shallow_clone(), t.shallow_clone()], 0);
            old_logp = match c.symmetry_ratio {
                SymmetryRatio::Behavior => twice(&old_logp),
                SymmetryRatio::Policy => tch::no_grad(|| {
                    let pick = |t: &Tensor| t.narrow(0, b, b);
                    let mean =
                        policy.actor_mean(&pick(&actor_in), scan.as_ref().map(pick).as_ref());
                    let logp = ActorCritic::log_prob(&mean, &old_std, &pick(&actions));
                    Tensor::cat(&[old_logp.shallow_clone(), logp], 0)
                }),
            };
            old_values = twice(&old_values);
            returns = twice(&returns);
            adv = twice(&adv);
            b *= 2;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut order: Vec<i64> = (0..b).collect();
        let mb = (b as usize / c.num_minibatches).max(1);
        let mut l = Losses {
            explained_variance,
            ..Default::default()
        };
        let mut count = 0.0;
        for _ in 0..c.num_epochs {
            order.shuffle(&mut rng);
            for chunk in order.chunks(mb) {
                let idx = Tensor::from_slice(chunk);
                let pick = |t: &Tensor| t.index_select(0, &idx);
                let scan_mb = scan.as_ref().map(pick);
                let mean = policy.actor_mean(&pick(&actor_in), scan_mb.as_ref());
                let std = policy.std();
                let logp = ActorCritic::log_prob(&mean, &std, &pick(&actions));
                let entropy = ActorCritic::entropy(&std);
                let value = policy.value(&pick(&critic_in), scan_mb.as_ref());

                // KL(old || new) of diagonal Gaussians, and the adaptive learning rate
                let kl = tch::no_grad(|| {
                    let om = pick(&old_mean);
                    let per_sample = ((&std / &old_std).log()
                        + (old_std.square() + (om - &mean).square()) / (std.square() * 2.0)
                        - 0.5)
                        .sum_dim_intlist(-1, false, Kind::Float);
                    let original = idx.lt(b_orig).to_kind(Kind::Float);
                    let n = original.sum(Kind::Float).double_value(&[]);
                    if n > 0.0 {
                        (per_sample * &original).sum(Kind::Float).double_value(&[]) / n
                    } else {
                        0.0
                    }
                });
                if c.schedule == LrSchedule::Adaptive {
                    self.adapt_lr(kl);
                }

                let log_ratio = &logp - pick(&old_logp);
                let a = pick(&adv);
                let (per_sample, ratio) =
                    surrogate_per_sample(&log_ratio, &a, c.clip_param, c.dual_clip);
                let surrogate = per_sample.mean(Kind::Float);
                let ret = pick(&returns);
                let value_loss = if c.clip_value {
                    let ov = pick(&old_values);
                    let clipped = &ov + (&value - &ov).clamp(-c.clip_param, c.clip_param);
                    (&value - &ret)
                        .square()
                        .max_other(&(clipped - &ret).square())
                        .mean(Kind::Float)
                } else {
                    (&value - &ret).square().mean(Kind::Float)
                };
                let mut loss =
                    &surrogate + &value_loss * c.value_loss_coef - &entropy * c.entropy_coef;
                // rsl_rl's mirror loss: each sample's mean against the mirror of
                // its partner's (the same state mirrored), detached
                let mirror_for_loss = self.mirror.as_ref().filter(|_| c.mirror_loss_coef > 0.0);
                if let Some([.., mact]) = mirror_for_loss {
                    let partner = (&idx + b_orig).remainder(b);
                    let target = tch::no_grad(|| {
                        let pick_p = |t: &Tensor| t.index_select(0, &partner);
                        let m = policy
                            .actor_mean(&pick_p(&actor_in), scan.as_ref().map(pick_p).as_ref());
                        m.index_select(1, &mact.0) * &mact.1
                    });
                    let mirror_loss = (&mean - target).square().mean(Kind::Float);
                    loss += mirror_loss * c.mirror_loss_coef;
                }
                // the privileged-information estimator's regression on the
                // critic's base velocity (the same rows, mirrored ones included)
                let est_coef = policy.cfg.estimator.as_ref().map(|e| e.loss_coef);
                if let (Some(coef), Some(est)) = (est_coef, policy.estimate(&pick(&actor_in))) {
                    let target =
                        pick(&critic_in).narrow(1, policy.dims.obs as i64, ESTIMATE_DIM as i64);
                    let est_loss = (est - target).square().mean(Kind::Float);
                    l.estimator += est_loss.double_value(&[]);
                    loss += est_loss * coef;
                }
                self.opt.zero_grad();
                loss.backward();
                l.grad_norm += self.opt.clip_grad_norm(c.max_grad_norm);
                self.opt.step();

                let clipped_frac = tch::no_grad(|| {
                    (&ratio - 1.0)
                        .abs()
                        .gt(c.clip_param)
                        .to_kind(Kind::Float)
                        .mean(Kind::Float)
                        .double_value(&[])
                });
                l.value += value_loss.double_value(&[]);
                l.surrogate += surrogate.double_value(&[]);
                l.entropy += entropy.double_value(&[]);
                l.kl += kl;
                l.clip_fraction += clipped_frac;
                count += 1.0;
            }
        }
        for v in [
            &mut l.value,
            &mut l.surrogate,
            &mut l.entropy,
            &mut l.kl,
            &mut l.clip_fraction,
            &mut l.grad_norm,
            &mut l.estimator,
        ] {
            *v /= count;
        }
        if c.schedule == LrSchedule::AdaptiveIteration {
            self.adapt_lr(l.kl);
        }
        l.learning_rate = self.opt.lr;
        l.mean_std = tch::no_grad(|| policy.std().mean(Kind::Float).double_value(&[]));
        l
    }
}
