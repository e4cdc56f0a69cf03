//! `bench ppo`: where a PPO iteration's time goes on a config (physics,
//! inference, update), and how close inference comes to the GEMMs it is made of.
//!
//! Each network variant runs `warmup` + `iterations` full PPO iterations of the
//! config's env. `inference_gemm_fraction` = the time of bare matrix products of
//! the same shapes (batch x in x out for every actor and critic layer, and the
//! history encoder's) over the time of the policy's forward pass at the
//! rollout's batch, both measured here: what our layers, activations and
//! input assembly leave of the raw GEMM rate.
use std::time::Instant;

use serde::Serialize;
use tch::{Kind, Tensor};

use crate::env::VecEnv;
use crate::rl::config::{ExperimentConfig, HistoryKind};
use crate::rl::runner::Trainer;
use crate::rl::RlError;

/// One network variant's measurements.
#[derive(Debug, Clone, Serialize)]
pub struct PpoVariant {
    pub name: String,
    pub actor_hidden: Vec<i64>,
    pub history: String,
    pub parameters: i64,
    pub n_envs: usize,
    pub num_steps: usize,
    /// Env-steps per second of whole iterations (rollout + update).
    pub env_steps_per_s: f64,
    pub share_physics: f64,
    pub share_inference: f64,
    pub share_update: f64,
    /// Forward passes of the actor and critic at the rollout batch, samples/s.
    pub inference_samples_per_s: f64,
    /// Policy FLOP/s at the rollout batch over bare GEMMs of the same shapes.
    pub inference_gemm_fraction: f64,
    /// The policy's GEMM FLOP/s at the rollout batch (actor, critic, history).
    pub inference_gflops: f64,
    /// `inference_gflops` over the 512^3 sgemm of the same run.
    pub inference_vs_sgemm: f64,
    /// Update samples (epochs x batch) per second.
    pub update_samples_per_s: f64,
}

/// `bench ppo` output.
#[derive(Debug, Clone, Serialize)]
pub struct PpoBench {
    pub config: String,
    pub mujoco_version: String,
    pub torch_threads: i64,
    /// A 512^3 sgemm measured in the same run (GFLOP/s), for scale.
    pub sgemm_gflops: f64,
    pub variants: Vec<PpoVariant>,
    /// The config's own network (the first variant), repeated at the top level.
    pub env_steps_per_s: f64,
    pub share_physics: f64,
    pub share_inference: f64,
    pub share_update: f64,
    pub inference_gemm_fraction: f64,
}

fn time_best(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let t = Instant::now();
        f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    best
}

/// Layer shapes `(in, out)` of an MLP.
fn layers(input: i64, hidden: &[i64], out: i64) -> Vec<(i64, i64)> {
    let mut v = Vec::new();
    let mut d = input;
    for &h in hidden {
        v.push((d, h));
        d = h;
    }
    v.push((d, out));
    v
}

/// Time of bare `x @ W^T` products (the layers' own kernel, no bias) over `shapes` at batch `b` (GRU steps included
/// as their three gates' products, per step).
fn gemm_time(b: i64, shapes: &[(i64, i64)]) -> f64 {
    let ws: Vec<(Tensor, Tensor)> = shapes
        .iter()
        .map(|&(i, o)| {
            let opts = (Kind::Float, tch::Device::Cpu);
            (Tensor::randn([b, i], opts), Tensor::randn([o, i], opts))
        })
        .collect();
    tch::no_grad(|| {
        time_best(20, || {
            for (x, w) in &ws {
                let _ = x.linear::<&Tensor>(w, None);
            }
        })
    })
}

fn variant(
    cfg: &ExperimentConfig,
    name: &str,
    warmup: usize,
    iterations: usize,
    sgemm_gflops: f64,
) -> Result<PpoVariant, RlError> {
    let mut env = VecEnv::new(&cfg.env)?;
    let mut tr = Trainer::new(cfg, &mut env, None)?;
    for _ in 0..warmup {
        tr.iterate()?;
    }
    let (t0, wall) = (tr.times, Instant::now());
    for _ in 0..iterations {
        tr.iterate()?;
    }
    let total = wall.elapsed().as_secs_f64();
    let t = tr.times;
    let (phys, inf, upd) = (
        t.physics - t0.physics,
        t.inference - t0.inference,
        t.update - t0.update,
    );
    let n = tr.task.n_envs();
    let steps = (iterations * cfg.ppo.num_steps * n) as f64;

    // inference at the rollout batch vs bare GEMMs of the same shapes
    tr.agent.prepare(&*tr.task);
    let infer = time_best(20, || {
        let _ = tr.agent.act(true);
    });
    let p = &cfg.policy;
    let d = tr.agent.dims();
    let k = tr.agent.policy.history_len() as i64;
    let (hist_shapes, hist_out): (Vec<(i64, i64)>, i64) = match (p.history.kind, k) {
        (HistoryKind::None, _) | (_, 0) => (vec![], 0),
        (HistoryKind::Mlp, _) => {
            let dims = &p.history.mlp_dims;
            let l = layers(
                k * d.obs as i64,
                &dims[..dims.len() - 1],
                *dims.last().unwrap_or(&1),
            );
            (l, *dims.last().unwrap_or(&0))
        }
        (HistoryKind::Gru, _) => {
            let h = p.history.gru_hidden;
            let per_step = [(d.obs as i64, 3 * h), (h, 3 * h)];
            (
                per_step
                    .iter()
                    .cycle()
                    .take(2 * k as usize)
                    .copied()
                    .collect(),
                h,
            )
        }
    };
    let mut shapes = hist_shapes;
    shapes.extend(layers(
        hist_out + d.obs as i64,
        &p.actor_hidden,
        d.action as i64,
    ));
    shapes.extend(layers(d.critic as i64, &p.critic_hidden, 1));
    let gemm = gemm_time(n as i64, &shapes);
    let flops: f64 = shapes
        .iter()
        .map(|&(i, o)| 2.0 * (n as i64 * i * o) as f64)
        .sum();
    let inference_gflops = flops / infer / 1e9;
    let samples_update = (cfg.ppo.num_epochs * cfg.ppo.num_steps * n) as f64 * iterations as f64;
    Ok(PpoVariant {
        name: name.to_string(),
        actor_hidden: p.actor_hidden.clone(),
        history: format!("{:?}", p.history.kind).to_lowercase(),
        parameters: tr.agent.policy.num_parameters(),
        n_envs: n,
        num_steps: cfg.ppo.num_steps,
        env_steps_per_s: steps / total,
        share_physics: phys / total,
        share_inference: inf / total,
        share_update: upd / total,
        inference_samples_per_s: n as f64 / infer,
        inference_gemm_fraction: gemm / infer,
        inference_gflops,
        inference_vs_sgemm: inference_gflops / sgemm_gflops,
        update_samples_per_s: samples_update / upd,
    })
}

/// Measure the config's network, then the paper's sizes with an MLP and a GRU
/// history encoder, on the config's env.
pub fn ppo(
    cfg: &ExperimentConfig,
    label: &str,
    warmup: usize,
    iterations: usize,
    paper_sizes: bool,
) -> Result<PpoBench, RlError> {
    tch::set_num_threads(cfg.train.torch_threads as i32);
    let a = Tensor::randn([512, 512], (Kind::Float, tch::Device::Cpu));
    let g = tch::no_grad(|| {
        time_best(10, || {
            let _ = a.mm(&a);
        })
    });
    let sgemm_gflops = 2.0 * 512f64.powi(3) / g / 1e9;
    let mut variants = vec![variant(cfg, "config", warmup, iterations, sgemm_gflops)?];
    let paper = [
        ("paper_mlp_history", HistoryKind::Mlp),
        ("paper_gru_history", HistoryKind::Gru),
    ];
    for (name, kind) in paper.into_iter().filter(|_| paper_sizes) {
        let mut c = cfg.clone();
        c.policy.actor_hidden = vec![512, 256, 128];
        c.policy.critic_hidden = vec![512, 256, 128];
        c.policy.history.kind = kind;
        c.policy.history.mlp_dims = vec![256, 64];
        c.policy.history.gru_hidden = 512;
        variants.push(variant(&c, name, warmup, iterations, sgemm_gflops)?);
    }
    let v = variants[0].clone();
    Ok(PpoBench {
        config: label.to_string(),
        mujoco_version: crate::sim::mujoco_version(),
        torch_threads: cfg.train.torch_threads,
        sgemm_gflops,
        env_steps_per_s: v.env_steps_per_s,
        share_physics: v.share_physics,
        share_inference: v.share_inference,
        share_update: v.share_update,
        inference_gemm_fraction: v.inference_gemm_fraction,
        variants,
    })
}
