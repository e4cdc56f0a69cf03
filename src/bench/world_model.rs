//! `bench world-model`: sampling latency of the denoiser at batch 1 (one robot
//! planning online) for DDPM over all `N` steps and DDIM with `k` in {5, 10,
//! 20}, against the 20 ms control period; and how close the denoiser's forward
//! pass at the trainer's batch comes to the bare matrix products it is made of
//! (`gemm_fraction`: achieved FLOP/s of the forward over the FLOP/s of GEMMs of
//! the same shapes, timed in the same run). The config's size and the paper's.
//! Also the trainer's throughput ([`trainer_sequences_per_s`]), which `bench
//! data` sets against the window reader (`headroom`).
use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;
use tch::{Device, Kind, Tensor};

use crate::world_model::config::{SamplerKind, SamplingConfig, WorldModelConfig};
use crate::world_model::sampler::{sample, Noise};
use crate::world_model::trainer::WmTrainer;
use crate::world_model::{Denoiser, NoiseSchedule, WmError};

/// The control period the latency is compared with (50 Hz).
pub const CONTROL_PERIOD_MS: f64 = 20.0;

/// One model size's measurements.
#[derive(Debug, Clone, Serialize)]
pub struct WmVariant {
    pub name: String,
    pub layers: usize,
    pub hidden: i64,
    pub parameters: i64,
    pub history: usize,
    pub horizon: usize,
    pub diffusion_steps: usize,
    /// Guidance of the latency runs (2 rows per forward unless 0 or 1).
    pub guidance: f64,
    /// Best-of-rounds latency of one sample at batch 1, by sampler (`ddpm<N>`,
    /// `ddim5`, `ddim10`, `ddim20`), ms.
    pub batch1_ms: BTreeMap<String, f64>,
    pub ddim10_batch1_ms: f64,
    /// `ddim10_batch1_ms` / 20 ms.
    pub ddim10_vs_control_period: f64,
    /// Batch of the forward measurement (the trainer's, capped for the paper's
    /// size on a CPU).
    pub forward_batch: i64,
    pub forward_ms: f64,
    /// Denoiser forward FLOP/s at `forward_batch` (matrix products counted).
    pub forward_gflops: f64,
    /// Bare GEMMs of the forward's shapes (every linear map, same batch), FLOP/s.
    pub gemm_gflops: f64,
    pub gemm_fraction: f64,
}

/// `bench world-model` output; the top-level keys repeat the first variant's.
#[derive(Debug, Clone, Serialize)]
pub struct WmBench {
    pub torch_threads: i64,
    pub control_period_ms: f64,
    pub rounds: usize,
    pub variants: Vec<WmVariant>,
    pub ddim10_batch1_ms: f64,
    pub ddim10_vs_control_period: f64,
    pub gemm_fraction: f64,
}

fn best_of<F: FnMut()>(rounds: usize, mut f: F) -> f64 {
    f();
    let mut best = f64::INFINITY;
    for _ in 0..rounds.max(1) {
        let t = Instant::now();
        f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    best
}

/// Best-of-rounds seconds of `f` and `g`, their rounds alternating (so drift in
/// the machine's load hits both).
fn best_of_pair<F: FnMut(), G: FnMut()>(rounds: usize, mut f: F, mut g: G) -> (f64, f64) {
    f();
    g();
    let (mut bf, mut bg) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..rounds.max(1) {
        let t = Instant::now();
        f();
        bf = bf.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        g();
        bg = bg.min(t.elapsed().as_secs_f64());
    }
    (bf, bg)
}

/// Bare GEMMs with the shapes of the denoiser's linear maps at batch `b`:
/// the operand pairs and the FLOPs of one pass over all of them.
fn gemm_operands(cfg: &WorldModelConfig, s: i64, b: i64) -> (Vec<(Tensor, Tensor)>, f64) {
    let m = &cfg.model;
    let d = m.hidden;
    let t = (m.history + m.horizon) as i64;
    let opts = (Kind::Float, Device::Cpu);
    let mut shapes: Vec<(i64, i64, i64)> = vec![(b * t, s, d)];
    for _ in 0..m.layers {
        shapes.extend([
            (b * t, d, 3 * d),
            (b * t, d, d),
            (b * t, d, m.mlp_ratio * d),
            (b * t, m.mlp_ratio * d, d),
        ]);
    }
    shapes.push((b * m.horizon as i64, d, s));
    let mats: Vec<(Tensor, Tensor)> = shapes
        .iter()
        .map(|&(r, k, n)| (Tensor::randn([r, k], opts), Tensor::randn([k, n], opts)))
        .collect();
    let flops: f64 = shapes
        .iter()
        .map(|&(r, k, n)| 2.0 * (r * k * n) as f64)
        .sum();
    (mats, flops)
}

/// Measure one model size.
pub fn variant(name: &str, cfg: &WorldModelConfig, forward_batch: i64, rounds: usize) -> WmVariant {
    let (s, c) = (98usize, 187usize);
    tch::manual_seed(0);
    let net = Denoiser::new(&cfg.model, s, c, Device::Cpu);
    let sched = NoiseSchedule::new(&cfg.diffusion);
    let guidance = cfg.sampling.guidance;
    let (k, h) = (cfg.model.history as i64, cfg.model.horizon as i64);
    let mut noise = Noise::new(1);
    let hist = noise.randn(&[1, k, s as i64], Device::Cpu);
    let y = tch::no_grad(|| net.terrain_embedding(&noise.randn(&[1, c as i64], Device::Cpu)));
    let mut batch1_ms = BTreeMap::new();
    let n = sched.steps();
    let samplers = [
        (format!("ddpm{n}"), SamplerKind::Ddpm, n),
        ("ddim5".to_string(), SamplerKind::Ddim, 5),
        ("ddim10".to_string(), SamplerKind::Ddim, 10),
        ("ddim20".to_string(), SamplerKind::Ddim, 20),
    ];
    for (key, sampler, steps) in samplers {
        let sc = SamplingConfig {
            sampler,
            ddim_steps: steps.min(n),
            guidance,
        };
        let secs = best_of(rounds, || {
            let _ = std::hint::black_box(sample(&net, &sched, &sc, &hist, &y, &mut noise));
        });
        batch1_ms.insert(key, secs * 1e3);
    }
    let b = forward_batch;
    let x = noise.randn(&[b, h, s as i64], Device::Cpu);
    let hb = noise.randn(&[b, k, s as i64], Device::Cpu);
    let yb = tch::no_grad(|| net.terrain_embedding(&noise.randn(&[b, c as i64], Device::Cpu)));
    let steps = NoiseSchedule::step_tensor(&vec![n / 2 + 1; b as usize], Device::Cpu);
    let (mats, gemm_flops) = gemm_operands(cfg, s as i64, b);
    let (fwd, gemm_s) = best_of_pair(
        rounds,
        || {
            let _ = tch::no_grad(|| std::hint::black_box(net.forward(&x, &hb, &steps, &yb)));
        },
        || {
            for (a, w) in &mats {
                let _ = std::hint::black_box(a.mm(w));
            }
        },
    );
    let forward_gflops = net.flops_per_sample() * b as f64 / fwd / 1e9;
    let gemm_gflops = gemm_flops / gemm_s / 1e9;
    let ddim10 = batch1_ms["ddim10"];
    WmVariant {
        name: name.to_string(),
        layers: cfg.model.layers,
        hidden: cfg.model.hidden,
        parameters: net.num_parameters(),
        history: cfg.model.history,
        horizon: cfg.model.horizon,
        diffusion_steps: n,
        guidance,
        batch1_ms,
        ddim10_batch1_ms: ddim10,
        ddim10_vs_control_period: ddim10 / CONTROL_PERIOD_MS,
        forward_batch: b,
        forward_ms: fwd * 1e3,
        forward_gflops,
        gemm_gflops,
        gemm_fraction: forward_gflops / gemm_gflops,
    }
}

/// The config's size (at its trainer's batch) and, unless `config_only`, the
/// paper's (`paper`, at `paper_batch`).
pub fn world_model(
    cfg: &WorldModelConfig,
    paper: Option<(&WorldModelConfig, i64)>,
    rounds: usize,
) -> WmBench {
    let mut variants = vec![variant("config", cfg, cfg.train.batch_size as i64, rounds)];
    if let Some((p, b)) = paper {
        variants.push(variant("paper", p, b, rounds));
    }
    let first = variants[0].clone();
    WmBench {
        torch_threads: tch::get_num_threads() as i64,
        control_period_ms: CONTROL_PERIOD_MS,
        rounds,
        ddim10_batch1_ms: first.ddim10_batch1_ms,
        ddim10_vs_control_period: first.ddim10_vs_control_period,
        gemm_fraction: first.gemm_fraction,
        variants,
    }
}

/// Sequences per second of the trainer of `cfg` on its dataset (`data.path`):
/// one warm-up batch, then `batches` timed batches of `T` steps each (data,
/// steps and scheduled rollouts included): the fully supervised phase, or with
/// `rollouts` the rollout phase (every history but the first sampled).
pub fn trainer_sequences_per_s(
    cfg: &WorldModelConfig,
    batches: usize,
    rollouts: bool,
) -> Result<f64, WmError> {
    let mut cfg = cfg.clone();
    let t = &mut cfg.train;
    t.iterations = t.rollout_windows * (batches + 1);
    t.val_sequences = 0;
    if rollouts {
        (t.supervised_iterations, t.scheduled_iterations) = (0, 0);
    } else {
        (t.supervised_iterations, t.scheduled_iterations) = (usize::MAX / 2, 0);
    }
    let mut tr = WmTrainer::new(&cfg, None)?;
    tr.train_batch()?;
    let start = Instant::now();
    for _ in 0..batches.max(1) {
        tr.train_batch()?;
    }
    Ok((batches.max(1) * cfg.train.batch_size) as f64 / start.elapsed().as_secs_f64())
}
