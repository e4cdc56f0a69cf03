//! The diffusion world model on a tiny synthetic dataset written with our data
//! writer: the denoiser overfits it, predicts each episode's future from its
//! history, DDPM and DDIM are deterministic for a seed,
//! guidance 0 and 1 are exactly the unconditional and conditional models, the
//! scheduled-sampling probability is the paper's function (and the trainer
//! follows it), training sequences stay inside an episode, a resumed run is
//! bit-identical to an uninterrupted one, the rollout API chains calls, a map
//! terrain source reads the scandots along the predicted path, and bad configs
//! and checkpoints are clear errors.
mod common;

use std::path::Path;

use common::Scratch;
use dreampolicy::data::{Dataset, ReadOptions};
use dreampolicy::env::config::ObservationConfig;
use dreampolicy::env::obs::{scan_point, ANG_VEL, COMMAND, SCAN_DIM};
use dreampolicy::run::latest_checkpoint;
use dreampolicy::terrain::TerrainKind;
use dreampolicy::world_model::config::{
    world_model_from_str, SamplerKind, SamplingConfig, WorldModelConfig,
};
use dreampolicy::world_model::sampler::{guided_x0, sample};
use dreampolicy::world_model::sequences::{validation_windows, Sequences};
use dreampolicy::world_model::{
    rollout_probability, train, Denoiser, FixedTerrain, MapTerrain, Noise, NoiseSchedule, Pose,
    TerrainSource, WmCheckpoint, WmError, WmTrainer, WorldModel,
};
use tch::{Device, Kind, Tensor};

static TORCH: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Tests that seed libtorch's global generator run one at a time.
fn torch_lock() -> std::sync::MutexGuard<'static, ()> {
    tch::set_num_threads(1);
    TORCH.lock().unwrap_or_else(|e| e.into_inner())
}

/// `n_envs` envs for `steps` steps; env `e`'s episodes last `20 + 5 e` steps.
/// Smooth states with a per-episode phase and frequency; state[0] = the
/// episode's ordinal, scan[0] = the step, the other scandots the episode's
/// terrain height.
fn write_dataset(dir: &Path, n_envs: u32, steps: u32) {
    common::write_synthetic_shard(
        dir,
        n_envs,
        steps,
        |env| 20 + 5 * env,
        |f, ord, _env, step| {
            f.terrain = TerrainKind::TRAINING[(ord % 5) as usize];
            f.level = ord % 3;
            let phase = ord as f32 * 0.7;
            let freq = 0.2 + 0.02 * (ord % 4) as f32;
            for (j, v) in f.state.iter_mut().enumerate() {
                *v = (freq * step as f32 * (1.0 + 0.01 * j as f32) + phase).sin();
            }
            f.state[0] = ord as f32;
            for v in f.scan.iter_mut() {
                *v = 0.1 * (ord % 3) as f32;
            }
            f.scan[0] = step as f32;
            for (j, v) in f.action.iter_mut().enumerate() {
                *v = j as f32 * 0.01;
            }
        },
    );
}

/// A tiny model on `dir`; `extra` are `--set` overrides.
fn tiny(dir: &Path, extra: &[&str]) -> WorldModelConfig {
    let text = format!(
        "data: {{path: '{}', val_fraction: 0.2, shuffle: 64}}
model: {{history: 2, horizon: 4, layers: 2, hidden: 32, heads: 2, mlp_ratio: 2, terrain_hidden: [32], terrain_dim: 16, step_features: 16}}
diffusion: {{steps: 20, schedule: cosine}}
sampling: {{sampler: ddim, ddim_steps: 4, guidance: 2.0}}
train: {{iterations: 8, batch_size: 16, learning_rate: 1.0e-3, ema_decay: 0.9, rollout_windows: 2,
  supervised_iterations: 2, scheduled_iterations: 2,
  rollout_sampling: {{sampler: ddim, ddim_steps: 3, guidance: 2.0}},
  log_interval: 2, eval_interval: 4, val_sequences: 8, save_interval: 4, keep_interval: 0,
  seed: 3, torch_threads: 1}}
",
        dir.display()
    );
    let sets: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
    world_model_from_str(&text, "tiny", &sets).unwrap()
}

/// A denoiser with every parameter drawn at random (a fresh one predicts 0:
/// its output layer starts at zero).
fn random_net(cfg: &WorldModelConfig, seed: i64) -> Denoiser {
    tch::manual_seed(seed);
    let net = Denoiser::new(&cfg.model, 98, 187, Device::Cpu);
    tch::no_grad(|| {
        for (_, mut p) in net.named_parameters() {
            let r = Tensor::randn(p.size(), (Kind::Float, Device::Cpu)) * 0.2;
            p.copy_(&r);
        }
    });
    net
}

fn inputs(cfg: &WorldModelConfig, b: i64, seed: u64) -> (Tensor, Tensor) {
    let mut n = Noise::new(seed);
    let hist = n.randn(&[b, cfg.model.history as i64, 98], Device::Cpu);
    let scan = n.randn(&[b, 187], Device::Cpu);
    (hist, scan)
}

fn equal(a: &Tensor, b: &Tensor) -> bool {
    a.size() == b.size() && a.equal(b)
}

#[test]
fn scheduled_sampling_probability_is_the_papers_function() {
    // Algorithm 1: 0 while iter <= I1, (iter - I1) / I2 up to I1 + I2, then 1
    let (i1, i2) = (100, 50);
    for iter in 0..300 {
        let want = if iter <= i1 {
            0.0
        } else if iter > i1 + i2 {
            1.0
        } else {
            (iter - i1) as f64 / i2 as f64
        };
        assert_eq!(rollout_probability(iter, i1, i2), want, "iter {iter}");
    }
    assert_eq!(rollout_probability(125, 100, 50), 0.5);
    assert_eq!(rollout_probability(150, 100, 50), 1.0);
    // no scheduled phase: a step from 0 to 1, no division by zero
    assert_eq!(rollout_probability(10, 10, 0), 0.0);
    assert_eq!(rollout_probability(11, 10, 0), 1.0);
}

#[test]
fn trainer_follows_the_schedule_and_sequences_stay_in_their_episode() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-sched");
    write_dataset(&dir.0, 6, 80);
    // I1 = 4, I2 = 4, T = 4: steps 0..4 never roll out, steps past 8 always do
    let cfg = tiny(
        &dir.0,
        &[
            "train.rollout_windows=4",
            "train.supervised_iterations=4",
            "train.scheduled_iterations=4",
            "train.iterations=16",
        ],
    );
    let mut tr = WmTrainer::new(&cfg, None).unwrap();
    let mut probs = Vec::new();
    for _ in 0..4 {
        let before = tr.iteration;
        let s = tr.train_batch().unwrap();
        assert_eq!(tr.iteration, before + 4);
        assert_eq!(s.losses.len(), 4);
        for (i, p) in s.probs.iter().enumerate() {
            assert_eq!(*p, rollout_probability(before + i, 4, 4));
        }
        // a batch's probabilities are all 0 (or all 1): nothing (everything) replaced
        if s.probs[..3].iter().all(|&p| p == 0.0) {
            assert_eq!(s.replaced, 0);
        }
        if s.probs[..3].iter().all(|&p| p == 1.0) {
            assert_eq!(s.replaced, s.replaceable);
            assert!(s.replaced > 0);
        }
        probs.extend(s.probs);
    }
    assert_eq!(probs.len(), 16);
    // the sequences: K + T H rows of one episode, scandots at each chunk's anchor
    let ds = Dataset::open(&dir.0, ReadOptions::default()).unwrap();
    let mut seqs = Sequences::new(ds, &cfg).unwrap();
    let spec = seqs.window_spec();
    assert_eq!(spec.len(), 2 + 4 * 4);
    for _ in 0..200 {
        let w = seqs.next_window().unwrap();
        let first = w.states[0];
        for r in 0..spec.len() {
            assert_eq!(w.states[r * 98], first, "row {r} left its episode");
        }
        assert_eq!(w.scans.len(), 4 * 187);
        for j in 0..4 {
            assert_eq!(w.scans[j * 187], (w.first_step + 1 + 4 * j as u32) as f32);
        }
    }
    // and the stream wrapped into later epochs without error
    assert!(seqs.epoch >= 1, "epoch {}", seqs.epoch);
}

#[test]
fn denoiser_overfits_a_tiny_dataset() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-overfit");
    write_dataset(&dir.0, 4, 60);
    let cfg = tiny(
        &dir.0,
        &[
            "train.rollout_windows=1",
            "train.iterations=800",
            "train.batch_size=32",
            "diffusion.terrain_drop=0.0",
        ],
    );
    let mut tr = WmTrainer::new(&cfg, None).unwrap();
    let mut losses = Vec::new();
    for _ in 0..800 {
        losses.extend(tr.train_batch().unwrap().losses);
    }
    let first: f64 = losses[..10].iter().sum::<f64>() / 10.0;
    let last: f64 = losses[losses.len() - 20..].iter().sum::<f64>() / 20.0;
    eprintln!("x0 loss: first 10 steps {first:.4}, last 20 steps {last:.4}");
    assert!(
        last * 10.0 < first,
        "x0 loss fell only from {first:.4} to {last:.4}"
    );
}

#[test]
fn the_model_predicts_the_future_from_its_history() {
    // each episode has its own phase and frequency: only the history tells
    // them apart, so a model that ignored it would score about the variance (1
    // in normalized units)
    let _t = torch_lock();
    let dir = Scratch::new("wm-history");
    write_dataset(&dir.0, 4, 200);
    let cfg = tiny(
        &dir.0,
        &[
            "train.rollout_windows=1",
            "train.iterations=300",
            "train.batch_size=32",
            "train.val_sequences=16",
            "train.ema_decay=0.95",
        ],
    );
    let mut tr = WmTrainer::new(&cfg, None).unwrap();
    for _ in 0..300 {
        tr.train_batch().unwrap();
    }
    let v = tr.validate().expect("a validation split");
    eprintln!(
        "sampled next window MSE {:.4} (x0 loss {:.4})",
        v.next_mse, v.loss
    );
    assert!(v.next_mse < 0.1, "next-window MSE {:.4}", v.next_mse);
}

/// `model.history_skip_fit`: at a fresh start the history skip is the
/// least-squares map of the history, so the untrained model already predicts
/// the synthetic episodes' next window far better than the zero-started one
/// (which scores about the variance) and than after the 300 steps above.
#[test]
fn the_history_skip_starts_at_the_least_squares_fit() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-skip-fit");
    write_dataset(&dir.0, 4, 200);
    let sets = [
        "train.rollout_windows=1",
        "train.val_sequences=16",
        "train.batch_size=32",
    ];
    let zero = WmTrainer::new(&tiny(&dir.0, &sets), None).unwrap();
    let mut with = sets.to_vec();
    with.push("model.history_skip_fit=400");
    let fit = WmTrainer::new(&tiny(&dir.0, &with), None).unwrap();
    let (z, f) = (zero.validate().unwrap(), fit.validate().unwrap());
    eprintln!(
        "next-window MSE at step 0: zero {:.4}, fitted {:.4}",
        z.next_mse, f.next_mse
    );
    assert!(z.next_mse > 0.5, "zero-started {:.4}", z.next_mse);
    assert!(f.next_mse < 0.05, "fitted {:.4}", f.next_mse);
    // without the skip the key changes nothing
    let mut off = with.clone();
    off.push("model.history_skip=false");
    let n = WmTrainer::new(&tiny(&dir.0, &off), None).unwrap();
    assert!(n.validate().unwrap().next_mse > 0.5);
}

#[test]
fn samplers_are_deterministic_for_a_seed() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-det");
    let cfg = tiny(&dir.0, &[]);
    let net = random_net(&cfg, 7);
    let sched = NoiseSchedule::new(&cfg.diffusion);
    let (hist, scan) = inputs(&cfg, 3, 1);
    let y = net.terrain_embedding(&scan);
    for sampler in [SamplerKind::Ddpm, SamplerKind::Ddim] {
        let sc = SamplingConfig {
            sampler,
            ddim_steps: 5,
            guidance: 2.0,
        };
        let a = sample(&net, &sched, &sc, &hist, &y, &mut Noise::new(42));
        // libtorch's global generator in between changes nothing
        let _ = Tensor::randn([100], (Kind::Float, Device::Cpu));
        let b = sample(&net, &sched, &sc, &hist, &y, &mut Noise::new(42));
        let c = sample(&net, &sched, &sc, &hist, &y, &mut Noise::new(43));
        assert_eq!(a.size(), vec![3, 4, 98]);
        assert!(equal(&a, &b), "{sampler:?} differs for one seed");
        assert!(!equal(&a, &c), "{sampler:?} ignores the seed");
        assert!(a.isfinite().all().int64_value(&[]) == 1);
    }
    // DDIM visits k evenly spaced steps from N down
    assert_eq!(sched.ddim_steps(4), vec![20, 15, 10, 5]);
    assert_eq!(sched.ddim_steps(20), (1..=20).rev().collect::<Vec<_>>());
}

#[test]
fn guidance_zero_and_one_are_the_unconditional_and_conditional_models() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-cfg");
    let cfg = tiny(&dir.0, &[]);
    let net = random_net(&cfg, 11);
    let (hist, scan) = inputs(&cfg, 4, 2);
    let mut n = Noise::new(5);
    let x_n = n.randn(&[4, 4, 98], Device::Cpu);
    let y = net.terrain_embedding(&scan);
    let null = net.null_embedding(4);
    let steps = NoiseSchedule::step_tensor(&[7; 4], Device::Cpu);
    tch::no_grad(|| {
        let cond = net.forward(&x_n, &hist, &steps, &y);
        let uncond = net.forward(&x_n, &hist, &steps, &null);
        assert!(!equal(&cond, &uncond), "the terrain changes nothing");
        assert!(equal(&guided_x0(&net, &x_n, &hist, 7, &y, 0.0), &uncond));
        assert!(equal(&guided_x0(&net, &x_n, &hist, 7, &y, 1.0), &cond));
        // any other omega: uncond + omega (cond - uncond), cond and uncond in one batch
        let g = guided_x0(&net, &x_n, &hist, 7, &y, 5.0);
        let want = &uncond + (&cond - &uncond) * 5.0;
        let err = (g - want).abs().max().double_value(&[]);
        assert!(err < 1e-4, "omega 5 off by {err}");
    });
    // whole samplers: omega 0 = the conditional sampler given the null embedding
    let sched = NoiseSchedule::new(&cfg.diffusion);
    let sc = |guidance| SamplingConfig {
        sampler: SamplerKind::Ddim,
        ddim_steps: 5,
        guidance,
    };
    let a = sample(&net, &sched, &sc(0.0), &hist, &y, &mut Noise::new(9));
    let b = sample(&net, &sched, &sc(1.0), &hist, &null, &mut Noise::new(9));
    assert!(equal(&a, &b));
}

/// The tensors of two checkpoints are identical, and their records agree.
fn assert_same_checkpoint(a: &Path, b: &Path) {
    let (ca, cb) = (
        WmCheckpoint::read(a).unwrap(),
        WmCheckpoint::read(b).unwrap(),
    );
    let (ma, mb) = (ca.meta(), cb.meta());
    assert_eq!(
        (
            ma.iteration,
            ma.sequences,
            ma.epoch,
            ma.consumed,
            ma.adam_step
        ),
        (
            mb.iteration,
            mb.sequences,
            mb.epoch,
            mb.consumed,
            mb.adam_step
        )
    );
    assert_eq!(ma.val_loss, mb.val_loss);
    let cfg = ca.config().unwrap();
    let net = Denoiser::new(&cfg.model, 98, 187, Device::Cpu);
    let names: Vec<String> = net.named_parameters().into_iter().map(|(n, _)| n).collect();
    assert!(!names.is_empty());
    for n in &names {
        for key in [
            format!("model.{n}"),
            format!("ema.{n}"),
            format!("adam_m.{n}"),
            format!("adam_v.{n}"),
        ] {
            let (x, y) = (ca.file.tensor(&key).unwrap(), cb.file.tensor(&key).unwrap());
            assert!(equal(x, y), "{key} differs after the resume");
        }
    }
}

#[test]
fn a_resumed_run_is_bit_identical() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-resume");
    let data = dir.0.join("data");
    write_dataset(&data, 3, 40);
    // 12 steps in batches of T = 2 with rollouts from step 2 on; the 3 x 40
    // frames give fewer than 96 sequences, so the data stream crosses an epoch too
    let sets = ["train.iterations=12", "train.save_interval=6"];
    let full = dir.0.join("full");
    let s = train(&tiny(&data, &sets), &full, false, true).unwrap();
    assert_eq!(s.iterations, 12);
    let half = dir.0.join("half");
    train(&tiny(&data, &["train.iterations=6"]), &half, false, true).unwrap();
    let s2 = train(&tiny(&data, &sets), &half, true, true).unwrap();
    assert_eq!(s2.iterations, 12);
    assert_same_checkpoint(&latest_checkpoint(&full), &latest_checkpoint(&half));
    let ck = WmCheckpoint::read(&latest_checkpoint(&full)).unwrap();
    assert!(ck.meta().epoch >= 1, "the test should cross an epoch");
    // the run directory: config, metrics (one header, rows up to step 12), plot
    for f in [
        "config.yaml",
        "metrics.csv",
        "log.txt",
        "plots/training.png",
    ] {
        assert!(half.join(f).is_file(), "{f} missing");
    }
    let metrics = std::fs::read_to_string(half.join("metrics.csv")).unwrap();
    let last = metrics.lines().last().unwrap();
    assert!(last.starts_with("12,"), "{last}");
    assert_eq!(
        metrics
            .lines()
            .filter(|l| l.starts_with("iteration"))
            .count(),
        1
    );
    // the config written into the run loads back as a world-model config
    dreampolicy::world_model::config::load_world_model(&half.join("config.yaml"), &[]).unwrap();
}

#[test]
fn validation_sequences_are_drawn_from_the_whole_split() {
    let dir = Scratch::new("wm-val-spread");
    let data = dir.0.join("data");
    // 4 envs x 400 steps: about 60 episodes of 20-35 frames in stream order
    write_dataset(&data, 4, 400);
    let cfg = tiny(&data, &[]);
    let ds = Dataset::open(&data, ReadOptions::default()).unwrap();
    let all = validation_windows(&ds, &cfg, usize::MAX).unwrap();
    let some = validation_windows(&ds, &cfg, 16).unwrap();
    assert_eq!(some.len(), 16);
    assert!(all.len() > 100, "{}", all.len());
    // the sample is seeded, in stream order, and spread over the split: many
    // episodes, late ones too (the first 16 windows come from two episodes)
    let again = validation_windows(&ds, &cfg, 16).unwrap();
    let ids = |w: &[dreampolicy::data::Window]| -> Vec<(u64, u32)> {
        w.iter().map(|w| (w.episode, w.first_step)).collect()
    };
    assert_eq!(ids(&some), ids(&again));
    let pos: Vec<usize> = ids(&some)
        .iter()
        .map(|id| ids(&all).iter().position(|a| a == id).unwrap())
        .collect();
    assert!(pos.windows(2).all(|p| p[0] < p[1]), "{pos:?}");
    let first: std::collections::BTreeSet<u64> = all[..16].iter().map(|w| w.episode).collect();
    let drawn: std::collections::BTreeSet<u64> = some.iter().map(|w| w.episode).collect();
    assert!(first.len() <= 3, "{first:?}");
    assert!(drawn.len() >= 6, "{drawn:?}");
    assert!(*pos.last().unwrap() > all.len() / 2, "{pos:?}");
    // more asked than there are: all of them
    assert_eq!(
        ids(&validation_windows(&ds, &cfg, all.len() + 5).unwrap()),
        ids(&all)
    );
}

/// A tiny model trained for two steps on the synthetic dataset, loaded as a
/// `WorldModel` (its checkpoint lives in a scratch directory named `name`).
fn two_step_model(name: &str) -> (WorldModel, WorldModelConfig) {
    let dir = Scratch::new(name);
    let data = dir.0.join("data");
    write_dataset(&data, 4, 40);
    let cfg = tiny(&data, &["train.iterations=2"]);
    let run = dir.0.join("run");
    train(&cfg, &run, false, true).unwrap();
    let wm = WorldModel::load(&latest_checkpoint(&run), Device::Cpu).unwrap();
    (wm, cfg)
}

#[test]
fn rollout_chains_calls_and_reads_the_terrain_per_call() {
    let _t = torch_lock();
    let (wm, cfg) = two_step_model("wm-rollout");
    let (hist, scan) = inputs(&cfg, 2, 3);
    let sc = wm.cfg.sampling.clone();
    // 10 frames = 3 calls of H = 4; the closure sees each call's history
    let mut seen = Vec::new();
    let mut source = |states: &Tensor, call: usize| -> Result<Tensor, WmError> {
        seen.push((call, states.copy()));
        Ok(scan.copy())
    };
    let out = wm.rollout(&hist, &mut source, 10, &sc, 1).unwrap();
    assert_eq!(out.size(), vec![2, 10, 98]);
    assert_eq!(seen.len(), 3);
    assert!(equal(&seen[0].1, &hist));
    // call 1's history is the last K = 2 states of call 0's prediction
    assert!(equal(&seen[1].1, &out.narrow(1, 2, 2)));
    assert!(equal(&seen[2].1, &out.narrow(1, 6, 2)));
    // fixed scandots give the same rollout, and the same seed the same rollout
    let again = wm
        .rollout(&hist, &mut FixedTerrain(scan.copy()), 10, &sc, 1)
        .unwrap();
    assert!(equal(&out, &again));
    let other = wm
        .rollout(&hist, &mut FixedTerrain(scan.copy()), 10, &sc, 2)
        .unwrap();
    assert!(!equal(&out, &other));
    // a wrong history shape is an error, not a panic
    let bad = Tensor::zeros([2, 3, 98], (Kind::Float, Device::Cpu));
    let e = wm
        .predict(&bad, &scan, &sc, &mut Noise::new(0))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("history must be"), "{e}");
}

/// Scandots `[C]` of row `b`.
fn scan_row(t: &Tensor, b: i64) -> Vec<f32> {
    Vec::<f32>::try_from(t.get(b)).unwrap()
}

#[test]
fn map_terrain_reads_the_scandots_along_the_predicted_path() {
    let _t = torch_lock();
    let obs = ObservationConfig::default();
    let (sc, dt) = (obs.scales.clone(), 0.02);
    // a 0.2 m step up at x = 0.95; the pelvis 0.78 m above the ground
    let ground = |x: f64, _y: f64| if x >= 0.95 { 0.2 } else { 0.0 };
    let start = [([0.0, 0.0, 0.78], 0.0)];
    let mut map = MapTerrain::new(ground, &start, &obs, dt);
    let hist = Tensor::zeros([1, 4, 98], (Kind::Float, Device::Cpu));
    let s0 = scan_row(&map.scandots(&hist, 0).unwrap(), 0);
    assert_eq!(s0.len(), SCAN_DIM);
    for (k, v) in s0.iter().enumerate() {
        let want = if scan_point(k).0 >= 0.95 {
            0.2 - 0.78
        } else {
            -0.78
        };
        assert!((*v as f64 - want).abs() < 1e-6, "point {k}: {v} vs {want}");
    }
    let on_step = |s: &[f32]| s.iter().filter(|v| **v > -0.7).count();
    assert_eq!(on_step(&s0), SCAN_DIM / 17); // the front column, x = 1.0

    // 8 predicted frames walking at 0.5 m/s, no turn: 0.08 m per call
    let walk = |vx: f64, wz: f64| {
        let p = Tensor::zeros([1, 8, 98], (Kind::Float, Device::Cpu));
        let _ = p
            .narrow(2, COMMAND.start as i64, 1)
            .fill_(vx * sc.commands[0]);
        let _ = p
            .narrow(2, ANG_VEL.start as i64 + 2, 1)
            .fill_(wz * sc.ang_vel);
        p
    };
    let mut seen = vec![on_step(&s0)];
    for call in 1..=5 {
        map.advance(&walk(0.5, 0.0)).unwrap();
        let x = map.poses()[0].x;
        assert!((x - 0.08 * call as f64).abs() < 1e-6, "x {x}");
        seen.push(on_step(&scan_row(&map.scandots(&hist, call).unwrap(), 0)));
    }
    // the step comes closer: more scandots read it, a column per 0.1 m
    assert!(seen.windows(2).all(|w| w[1] >= w[0]), "{seen:?}");
    assert_eq!(*seen.last().unwrap(), 5 * SCAN_DIM / 17, "{seen:?}"); // x = 0.4: 0.55..1.0 ahead
                                                                      // the same scandots as a source started where this one stands
    let here = map.poses()[0];
    let mut fresh = MapTerrain::new(ground, &[([here.x, 0.0, 0.78], 0.0)], &obs, dt);
    assert!(map
        .scandots(&hist, 6)
        .unwrap()
        .equal(&fresh.scandots(&hist, 0).unwrap()));
    // turning: 0.5 rad/s for 8 frames turns the heading by 0.08 rad
    map.advance(&walk(0.0, 0.5)).unwrap();
    let p = map.poses()[0];
    assert!(
        (p.yaw - 0.08).abs() < 1e-6 && (p.x - here.x).abs() < 1e-9,
        "{p:?}"
    );
    // a wrong batch is an error
    let e = map
        .scandots(&Tensor::zeros([2, 4, 98], (Kind::Float, Device::Cpu)), 0)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("map terrain"), "{e}");

    // in a rollout the source sees every call's prediction, in order: its pose
    // is the integration of the rollout's frames
    let (wm, cfg) = two_step_model("wm-map-terrain");
    let (hist, _) = inputs(&cfg, 2, 3);
    let starts = [([1.0, 2.0, 0.78], 0.3), ([-1.0, 0.5, 0.75], -1.0)];
    let mut map = MapTerrain::new(|_: f64, _: f64| 0.0, &starts, &obs, dt);
    let out = wm
        .rollout(&hist, &mut map, 12, &wm.cfg.sampling.clone(), 1)
        .unwrap();
    for (b, &(p0, yaw0)) in starts.iter().enumerate() {
        let mut want = Pose {
            x: p0[0],
            y: p0[1],
            yaw: yaw0,
        };
        let frames = Vec::<f32>::try_from(out.get(b as i64).flatten(0, -1)).unwrap();
        for s in frames.chunks(98) {
            let vx = s[COMMAND.start] as f64 / sc.commands[0];
            let vy = s[COMMAND.start + 1] as f64 / sc.commands[1];
            let (sy, cy) = want.yaw.sin_cos();
            want.x += (cy * vx - sy * vy) * dt;
            want.y += (sy * vx + cy * vy) * dt;
            want.yaw += s[ANG_VEL.start + 2] as f64 / sc.ang_vel * dt;
        }
        let got = map.poses()[b];
        let d = (got.x - want.x).abs() + (got.y - want.y).abs() + (got.yaw - want.yaw).abs();
        assert!(d < 1e-6, "row {b}: {got:?} vs {want:?}");
    }
}

#[test]
fn bad_configs_and_checkpoints_are_clear_errors() {
    // it builds trainers, which seed libtorch's global generator
    let _t = torch_lock();
    let dir = Scratch::new("wm-bad");
    let base = "data: {path: runs/dataset}\n";
    let err = |sets: &[&str]| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        world_model_from_str(base, "t.yaml", &sets)
            .err()
            .unwrap()
            .to_string()
    };
    let e = err(&["train.rollout_windows=5"]);
    assert!(
        e.contains("train.rollout_windows") && e.contains("4"),
        "{e}"
    );
    let e = err(&["model.heads=3"]);
    assert!(
        e.contains("model.hidden") && e.contains("model.heads"),
        "{e}"
    );
    let e = err(&["train.iterations=10"]);
    assert!(e.contains("multiple of train.rollout_windows"), "{e}");
    let e = err(&["sampling.sampler=ddim", "sampling.ddim_steps=500"]);
    assert!(e.contains("sampling.ddim_steps"), "{e}");
    let e = err(&["model.hiden=64"]);
    assert!(e.contains("hiden") && e.contains("t.yaml"), "{e}");
    let e = world_model_from_str("model: {layers: 2}\n", "t.yaml", &[])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("data"), "{e}");
    world_model_from_str(base, "t.yaml", &[]).unwrap();
    // a missing dataset names its path
    let cfg = world_model_from_str(
        &format!("data: {{path: '{}'}}\n", dir.0.join("nothing").display()),
        "t",
        &[],
    )
    .unwrap();
    let e = WmTrainer::new(&cfg, None).err().unwrap().to_string();
    assert!(e.contains("nothing"), "{e}");
    // a dataset too short for one sequence says so
    let short = dir.0.join("short");
    write_dataset(&short, 4, 8);
    let e = train(&tiny(&short, &[]), &dir.0.join("run"), false, true)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("no sequences"), "{e}");
    // junk and missing checkpoints
    let junk = dir.write("junk.pt", "not a checkpoint");
    let e = WmCheckpoint::read(&junk).err().unwrap().to_string();
    assert!(
        e.contains("junk.pt") && e.contains("not a checkpoint") && !e.contains('\n'),
        "{e}"
    );
    let e = WorldModel::load(&dir.0.join("none.pt"), Device::Cpu)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("none.pt") && e.contains("no such file"), "{e}");
}

#[test]
fn an_inference_copy_plans_as_its_source_and_cannot_resume() {
    let _t = torch_lock();
    let dir = Scratch::new("wm-strip");
    let data = dir.0.join("data");
    write_dataset(&data, 4, 40);
    let cfg = tiny(&data, &["train.iterations=4"]);
    let run = dir.0.join("run");
    train(&cfg, &run, false, true).unwrap();
    let src = latest_checkpoint(&run);
    let out = dir.0.join("wm_inference.pt");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
        .args(["checkpoint", "strip", "--out"])
        .arg(&out)
        .arg(&src)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    dreampolicy::checkpoint::verify_file(&out).unwrap();
    // the EMA and normalization only: no live model, no Adam moments
    let ck = WmCheckpoint::read(&out).unwrap();
    assert!(ck.meta().inference_only);
    assert_eq!(ck.meta().iteration, 4);
    let names = ck.file.names();
    assert!(names.iter().any(|n| n.starts_with("ema.")));
    assert!(names.iter().any(|n| n.starts_with("norm.")));
    assert!(!names
        .iter()
        .any(|n| n.starts_with("model.") || n.starts_with("adam_")));
    let size = |p: &Path| std::fs::metadata(p).unwrap().len() as f64;
    assert!(
        size(&out) < 0.4 * size(&src),
        "{} of {}",
        size(&out),
        size(&src)
    );
    // the same plans for the same history, scandots and seed
    let (a, b) = (
        WorldModel::load(&src, Device::Cpu).unwrap(),
        WorldModel::load(&out, Device::Cpu).unwrap(),
    );
    let (hist, scan) = inputs(&cfg, 3, 5);
    let sc = a.cfg.sampling.clone();
    let pa = a.predict(&hist, &scan, &sc, &mut Noise::new(9)).unwrap();
    let pb = b.predict(&hist, &scan, &sc, &mut Noise::new(9)).unwrap();
    assert!(equal(&pa, &pb));
    // training refuses to resume from it, saying why; stripping twice is refused
    std::fs::copy(&out, &src).unwrap();
    let more = tiny(&data, &["train.iterations=6"]);
    let e = train(&more, &run, true, true).err().unwrap().to_string();
    assert!(
        e.contains("inference copy") && e.contains("cannot resume"),
        "{e}"
    );
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
        .args(["checkpoint", "strip", "--out"])
        .arg(dir.0.join("again.pt"))
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("already an inference copy"));
    // unless asked to copy it as it is: the same bytes, seal and all
    let again = dir.0.join("again.pt");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
        .args(["checkpoint", "strip", "--if-needed", "--out"])
        .arg(&again)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&again).unwrap(), std::fs::read(&out).unwrap());
}
