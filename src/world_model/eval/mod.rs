//! `dreampolicy eval world-model`: how well a trained world model predicts the
//! validation episodes of its dataset.
//!
//! Everything runs on the validation side of the trainer's split (the
//! checkpoint's `data.val_fraction` and `data.split_seed`), on windows drawn with
//! a fixed seed ([`episodes::ValidationSet::pick`]: up to `windows` of them,
//! shared evenly over the terrain kinds present). Errors are RMSEs in the
//! model's normalized units (per-dimension mean/std of the checkpoint: predicting
//! the dataset's mean state scores about 1) unless a name says `raw` (the
//! dataset's units, e.g. joint positions in rad).
//!
//! * **One call** (the config's `sampling`): `horizon_rmse[h - 1]` for `h = 1..=H`,
//!   the same per named state block in raw units, and two baselines:
//!   `hold_rmse` (the anchor state held for `H` steps) and `mean_state_rmse`
//!   (the dataset's mean state).
//! * **Guidance** `omega in {0, 1, 5}` (the config's sampler): one-call error,
//!   and `terrain_distance`: RMS between the predictions with the real and the
//!   shuffled scandots under the same noise (exactly 0 for `omega = 0`, which
//!   never looks at the terrain).
//! * **Terrain sensitivity** per kind (the config's sampling): real scandots
//!   against scandots taken from another window (of another terrain kind when
//!   the windows hold several kinds, else of the same kind), same noise:
//!   `distance` (RMS between the two predictions), `seed_spread` (RMS between two
//!   predictions with the real scandots and different noise) and their
//!   `ratio`, with each prediction's error and the scandots' own RMS difference.
//! * **Samplers**: DDPM over all `N` steps and DDIM with 5, 10, 20 steps (those
//!   `<= N`) at the config's guidance: one-call error and wall time of a call at
//!   the evaluation's batch and at batch 1.
//! * **Drift**: calls chained from the real history for 50 and 250 frames, the
//!   scandots of each call read from the dataset at that call's anchor; windows
//!   only from episodes long enough (none: `metrics` null and a `reason`).
//! * **Yaw response** (G1 states, the config's sampling): the command's yaw
//!   rate, then the measured one, set to -0.5, 0 and 0.5 rad/s in every history
//!   state, the same noise: the plan's mean yaw rate for each and the slope
//!   (1: the plan turns as that input says; 0: it ignores it), beside how
//!   closely the dataset's own robots follow their command.
//! * **Plot** (`--plot`): real and predicted joint positions of a few windows.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor};

use super::checkpoint::WmCheckpoint;
use super::rollout::WorldModel;
use super::sampler::Noise;
use super::WmError;
use crate::data::sample::splitmix64;
use crate::data::{Dataset, ReadOptions, SplitSpec};
use crate::env::obs;
use crate::world_model::config::{SamplerKind, SamplingConfig};

pub mod episodes;
mod plot;
mod report;

pub use report::{
    Drift, DriftMetrics, GuidanceScore, OneCall, SamplerScore, Sensitivity, ValidationInfo,
    WmEvalReport, YawResponse,
};

use episodes::{Pick, ValidationSet};

/// The guidance scales compared.
pub const GUIDANCE: [f64; 3] = [0.0, 1.0, 5.0];
/// DDIM step counts compared with DDPM.
pub const DDIM_STEPS: [usize; 5] = [1, 2, 5, 10, 20];

/// What to evaluate on and how much.
#[derive(Debug, Clone)]
pub struct WmEvalOptions {
    /// Dataset directory (default: the checkpoint's `data.path`).
    pub data: Option<PathBuf>,
    /// Windows per measurement (one batch).
    pub windows: usize,
    pub seed: u64,
    /// libtorch threads.
    pub threads: i64,
    /// Lengths of the autoregressive rollouts (frames).
    pub drift_frames: Vec<usize>,
    /// Validation frames kept in memory per terrain kind.
    pub max_frames_per_kind: usize,
    /// Draw the trajectories PNG here.
    pub plot: Option<PathBuf>,
    /// The sampling measured instead of the checkpoint's `sampling`: its
    /// guidance ω, and DDIM with this many steps (a unified config's
    /// `unified.sampling`, say).
    pub guidance: Option<f64>,
    pub ddim_steps: Option<usize>,
}

impl Default for WmEvalOptions {
    fn default() -> Self {
        WmEvalOptions {
            data: None,
            windows: 64,
            seed: 0,
            threads: 1,
            drift_frames: vec![50, 250],
            max_frames_per_kind: 200_000,
            plot: None,
            guidance: None,
            ddim_steps: None,
        }
    }
}

/// The named blocks of the G1 state, for raw-unit errors.
pub const BLOCKS: [(&str, std::ops::Range<usize>); 7] = [
    ("ang_vel", obs::ANG_VEL),
    ("gravity", obs::GRAVITY),
    ("joint_pos", obs::DOF_POS),
    ("joint_vel", obs::DOF_VEL),
    ("command", obs::COMMAND),
    ("last_action", obs::LAST_ACTION),
    ("phase", obs::PHASE),
];

fn to_vec(t: &Tensor) -> Vec<f64> {
    let t = t.to_kind(Kind::Double).to_device(Device::Cpu).reshape([-1]);
    (0..t.size()[0]).map(|i| t.double_value(&[i])).collect()
}

/// RMS over everything.
fn rms(d: &Tensor) -> f64 {
    d.square().mean(Kind::Double).sqrt().double_value(&[])
}

/// RMS per step of `[B, T, D]` differences.
fn rms_steps(d: &Tensor) -> Vec<f64> {
    to_vec(
        &d.square()
            .mean_dim(&[0i64, 2][..], false, Kind::Double)
            .sqrt(),
    )
}

/// A G1 state's block `[.., lo..hi]` of `[B, T, S]`.
fn block(x: &Tensor, r: &std::ops::Range<usize>) -> Tensor {
    x.narrow(2, r.start as i64, (r.end - r.start) as i64)
}

struct Ctx<'a> {
    wm: &'a WorldModel,
    g1: bool,
}

impl Ctx<'_> {
    fn norm(&self, x: &Tensor) -> Tensor {
        self.wm.norm.states(x)
    }

    fn predict(
        &self,
        hist: &Tensor,
        scan: &Tensor,
        sc: &SamplingConfig,
        seed: u64,
    ) -> Result<Tensor, WmError> {
        self.wm.predict(hist, scan, sc, &mut Noise::new(seed))
    }

    fn one_call(&self, pred: &Tensor, real: &Tensor) -> OneCall {
        let d = self.norm(pred) - self.norm(real);
        let h = d.size()[1];
        OneCall {
            rmse: rms(&d),
            rmse_last: rms(&d.narrow(1, h - 1, 1)),
            joint_pos_rmse: self
                .g1
                .then(|| rms(&(block(pred, &obs::DOF_POS) - block(real, &obs::DOF_POS)))),
        }
    }
}

/// For each window, another window whose scandots it gets: one of another
/// terrain kind when there is one, else another of its own kind (itself when it
/// is alone). Also says which.
fn donors(kinds: &[String], rng: &mut ChaCha8Rng) -> (Vec<i64>, Vec<&'static str>) {
    let n = kinds.len();
    let mut idx = Vec::with_capacity(n);
    let mut how = Vec::with_capacity(n);
    for i in 0..n {
        let other: Vec<usize> = (0..n).filter(|&j| kinds[j] != kinds[i]).collect();
        let same: Vec<usize> = (0..n).filter(|&j| j != i && kinds[j] == kinds[i]).collect();
        let (pool, label) = if !other.is_empty() {
            (other, "other kinds")
        } else {
            (same, "same kind")
        };
        idx.push(if pool.is_empty() {
            i as i64
        } else {
            pool[rng.random_range(0..pool.len())] as i64
        });
        how.push(label);
    }
    (idx, how)
}

fn timed<T>(f: impl FnOnce() -> Result<T, WmError>) -> Result<(T, f64), WmError> {
    let t = Instant::now();
    let out = f()?;
    Ok((out, t.elapsed().as_secs_f64() * 1e3))
}

/// Evaluate the world-model checkpoint `checkpoint` on the validation split of
/// its dataset (or `opts.data`).
pub fn evaluate(checkpoint: &Path, opts: &WmEvalOptions) -> Result<WmEvalReport, WmError> {
    let start = Instant::now();
    if opts.windows == 0 {
        return Err(WmError::Invalid("--windows must be at least 1".into()));
    }
    tch::set_num_threads(opts.threads.max(1) as i32);
    let ck = WmCheckpoint::read(checkpoint)?;
    let cfg = ck.config()?;
    let dims = ck.meta().dims;
    let dev = Device::cuda_if_available();
    let wm = WorldModel::from_checkpoint(&ck, dev)?;
    let data_path = opts
        .data
        .clone()
        .unwrap_or_else(|| PathBuf::from(&cfg.data.path));
    if !data_path.exists() {
        return Err(WmError::Invalid(format!(
            "dataset {}: no such directory ({}; --data DIR names another)",
            data_path.display(),
            if opts.data.is_some() {
                "given by --data"
            } else {
                "the checkpoint's data.path"
            }
        )));
    }
    let read = ReadOptions {
        expected: dims,
        ..ReadOptions::default()
    };
    let dataset = Dataset::open(&data_path, read)?;
    let split = SplitSpec::new(cfg.data.val_fraction, cfg.data.split_seed)?;
    let val = ValidationSet::read(&dataset, split, opts.max_frames_per_kind)?;
    let (k, h) = (wm.history(), wm.horizon());
    let seed = opts.seed;
    let picks = val.pick(k, h, opts.windows, splitmix64(seed ^ 0x11));
    if picks.is_empty() {
        return Err(WmError::Invalid(format!(
            "the validation split of {} (val_fraction {}, split_seed {}) has no window of K + H = {} consecutive frames: {} episodes, {} frames, the longest run {} frames",
            data_path.display(),
            cfg.data.val_fraction,
            cfg.data.split_seed,
            k + h,
            val.episodes,
            val.frames,
            val.longest()
        )));
    }
    let ctx = Ctx {
        wm: &wm,
        g1: dims.state == obs::OBS_DIM,
    };
    let kinds: Vec<String> = picks
        .iter()
        .map(|p| val.segments[p.segment].kind.name().to_string())
        .collect();
    let mut windows_per_kind = BTreeMap::new();
    for kd in &kinds {
        *windows_per_kind.entry(kd.clone()).or_insert(0usize) += 1;
    }
    let states = val.states(&picks, k, h).to_device(dev);
    let hist = states.narrow(1, 0, k as i64);
    let real = states.narrow(1, k as i64, h as i64);
    let scan = val.scans(&picks, h, 1).select(1, 0).to_device(dev);
    let n_steps = wm.sched.steps();
    let mut sc = cfg.sampling.clone();
    if let Some(g) = opts.guidance {
        sc.guidance = g;
    }
    if let Some(n) = opts.ddim_steps {
        sc.sampler = SamplerKind::Ddim;
        sc.ddim_steps = n;
    }
    // the overrides meet the config's own check, named by the flags given
    let flags: Vec<String> = [
        opts.guidance.map(|g| format!("--guidance {g}")),
        opts.ddim_steps.map(|n| format!("--ddim-steps {n}")),
    ]
    .into_iter()
    .flatten()
    .collect();
    if !flags.is_empty() {
        sc.validate("sampling", n_steps)
            .map_err(|e| WmError::Invalid(format!("{}: {e}", flags.join(" "))))?;
    }
    let seed_a = splitmix64(seed ^ 0x22);
    let seed_b = splitmix64(seed ^ 0x33);

    // one call, the default sampler
    let pred = ctx.predict(&hist, &scan, &sc, seed_a)?;
    let real_n = ctx.norm(&real);
    let horizon_rmse = rms_steps(&(ctx.norm(&pred) - &real_n));
    let mut horizon_rmse_raw = BTreeMap::new();
    if ctx.g1 {
        for (name, r) in &BLOCKS {
            horizon_rmse_raw.insert(
                name.to_string(),
                rms_steps(&(block(&pred, r) - block(&real, r))),
            );
        }
    }
    let anchor = hist.narrow(1, k as i64 - 1, 1).expand_as(&real);
    let hold_rmse = rms_steps(&(ctx.norm(&anchor) - &real_n));
    let mut hold_rmse_raw = BTreeMap::new();
    if ctx.g1 {
        for (name, r) in &BLOCKS {
            hold_rmse_raw.insert(
                name.to_string(),
                rms_steps(&(block(&anchor, r) - block(&real, r))),
            );
        }
    }

    // shuffled scandots: the same noise, another window's terrain
    let mut rng = ChaCha8Rng::seed_from_u64(splitmix64(seed ^ 0x44));
    let (donor, how) = donors(&kinds, &mut rng);
    let scan_shuf = scan.index_select(0, &Tensor::from_slice(&donor).to_device(dev));

    let mut guidance = BTreeMap::new();
    let mut by_guidance = Vec::new();
    for &w in &GUIDANCE {
        let sw = SamplingConfig {
            guidance: w,
            ..sc.clone()
        };
        let p = ctx.predict(&hist, &scan, &sw, seed_a)?;
        let q = ctx.predict(&hist, &scan_shuf, &sw, seed_a)?;
        guidance.insert(
            format!("{w}"),
            GuidanceScore {
                guidance: w,
                error: ctx.one_call(&p, &real),
                terrain_distance: rms(&(ctx.norm(&p) - ctx.norm(&q))),
            },
        );
        by_guidance.push((format!("{w}"), ctx.norm(&p)));
    }
    let hold_n = ctx.norm(&anchor);

    // terrain sensitivity per kind, the default sampler
    let pred_shuf = ctx.predict(&hist, &scan_shuf, &sc, seed_a)?;
    let pred_b = ctx.predict(&hist, &scan, &sc, seed_b)?;
    let (pn, qn, bn) = (ctx.norm(&pred), ctx.norm(&pred_shuf), ctx.norm(&pred_b));
    let mut terrain_sensitivity = BTreeMap::new();
    for kd in windows_per_kind.keys() {
        let rows: Vec<i64> = (0..kinds.len())
            .filter(|&i| &kinds[i] == kd)
            .map(|i| i as i64)
            .collect();
        let idx = Tensor::from_slice(&rows).to_device(dev);
        let sel = |t: &Tensor| t.index_select(0, &idx);
        let distance = rms(&(sel(&pn) - sel(&qn)));
        let seed_spread = rms(&(sel(&pn) - sel(&bn)));
        terrain_sensitivity.insert(
            kd.clone(),
            Sensitivity {
                windows: rows.len(),
                donor: how[rows[0] as usize].to_string(),
                scan_distance_m: rms(&(sel(&scan) - sel(&scan_shuf))),
                distance,
                seed_spread,
                ratio: (seed_spread > 0.0).then(|| distance / seed_spread),
                rmse_real: rms(&(sel(&pn) - sel(&real_n))),
                rmse_shuffled: rms(&(sel(&qn) - sel(&real_n))),
                hold_rmse: rms(&(sel(&hold_n) - sel(&real_n))),
                rmse_by_guidance: by_guidance
                    .iter()
                    .map(|(w, t)| (w.clone(), rms(&(sel(t) - sel(&real_n)))))
                    .collect(),
            },
        );
    }

    // samplers
    let mut variants = vec![("ddpm".to_string(), SamplerKind::Ddpm, n_steps)];
    for s in DDIM_STEPS.into_iter().filter(|&s| s <= n_steps) {
        variants.push((format!("ddim{s}"), SamplerKind::Ddim, s));
    }
    let mut samplers = BTreeMap::new();
    let (h1, s1) = (hist.narrow(0, 0, 1), scan.narrow(0, 0, 1));
    for (name, kind, steps) in variants {
        let sv = SamplingConfig {
            sampler: kind,
            ddim_steps: steps,
            guidance: sc.guidance,
        };
        let (p, batch_ms) = timed(|| ctx.predict(&hist, &scan, &sv, seed_a))?;
        let mut batch1_ms = f64::INFINITY;
        for _ in 0..3 {
            batch1_ms = batch1_ms.min(timed(|| ctx.predict(&h1, &s1, &sv, seed_a))?.1);
        }
        samplers.insert(
            name,
            SamplerScore {
                sampler: kind,
                steps,
                guidance: sc.guidance,
                error: ctx.one_call(&p, &real),
                batch_ms,
                batch1_ms,
            },
        );
    }

    let yaw_response = if ctx.g1 {
        Some(yaw_response(&ctx, &hist, &real, &scan, &sc, seed_a)?)
    } else {
        None
    };

    // autoregressive drift
    let mut drift = BTreeMap::new();
    for &frames in &opts.drift_frames {
        drift.insert(
            frames.to_string(),
            drift_of(&ctx, &val, frames, opts.windows, &sc, seed)?,
        );
    }

    let plot = match &opts.plot {
        Some(path) => {
            plot::draw(&ctx, &val, &picks, &pred, &sc, seed, &cfg, checkpoint, path)?;
            Some(path.display().to_string())
        }
        None => None,
    };

    let notes = vec![
        "errors are RMSEs in the checkpoint's normalized units (per-dimension mean/std; the dataset's mean state scores about 1) unless the name says raw (the dataset's units: joint positions in rad)".to_string(),
        "shuffled scandots: each window takes those of another window, of another terrain kind when the windows hold several kinds, else of its own kind; real and shuffled predictions share their noise".to_string(),
        "drift: calls chained from the real history, each call's scandots read from the dataset at its anchor (the real path's terrain, not a terrain map along the predicted path)".to_string(),
    ];
    Ok(WmEvalReport {
        checkpoint: checkpoint.display().to_string(),
        iteration: ck.meta().iteration,
        dataset: data_path.display().to_string(),
        history: k,
        horizon: h,
        diffusion_steps: n_steps,
        seed,
        torch_threads: tch::get_num_threads() as i64,
        validation: ValidationInfo {
            val_fraction: cfg.data.val_fraction,
            split_seed: cfg.data.split_seed,
            episodes: val.episodes,
            segments: val.segments.len(),
            frames: val.frames,
            longest_segment: val.longest(),
            capped_kinds: val.capped.iter().map(|k| k.name().to_string()).collect(),
        },
        windows: picks.len(),
        windows_per_kind,
        sampling: sc,
        horizon_rmse,
        horizon_rmse_raw,
        hold_rmse,
        hold_rmse_raw,
        mean_state_rmse: rms(&real_n),
        guidance,
        samplers,
        terrain_sensitivity,
        drift,
        yaw_response,
        notes,
        plot,
        wall_time_s: start.elapsed().as_secs_f64(),
    })
}

/// Roll `picks` out for `frames` frames from their real history, each call's
/// scandots from the dataset at its anchor: `(real [B, K + frames, S], rollout
/// [B, frames, S])`, raw.
fn roll_out(
    ctx: &Ctx,
    val: &ValidationSet,
    picks: &[Pick],
    frames: usize,
    sc: &SamplingConfig,
    seed: u64,
) -> Result<(Tensor, Tensor), WmError> {
    let (k, h) = (ctx.wm.history(), ctx.wm.horizon());
    let dev = ctx.wm.net.device();
    let states = val.states(picks, k, frames).to_device(dev);
    let calls = frames.div_ceil(h);
    let scans = val.scans(picks, h, calls).to_device(dev);
    let mut source =
        |_: &Tensor, call: usize| -> Result<Tensor, WmError> { Ok(scans.select(1, call as i64)) };
    let roll = ctx.wm.rollout(
        &states.narrow(1, 0, k as i64),
        &mut source,
        frames,
        sc,
        seed,
    )?;
    Ok((states, roll))
}

fn drift_of(
    ctx: &Ctx,
    val: &ValidationSet,
    frames: usize,
    windows: usize,
    sc: &SamplingConfig,
    seed: u64,
) -> Result<Drift, WmError> {
    let (k, h) = (ctx.wm.history(), ctx.wm.horizon());
    let eligible = val.eligible(k, frames);
    let picks = val.pick(k, frames, windows, splitmix64(seed ^ 0x55 ^ frames as u64));
    if picks.is_empty() {
        return Ok(Drift {
            frames,
            eligible_segments: eligible,
            windows: 0,
            metrics: None,
            reason: Some(format!(
                "no validation episode has K + {frames} = {} consecutive frames (the longest has {})",
                k + frames,
                val.longest()
            )),
        });
    }
    let (states, roll) = roll_out(ctx, val, &picks, frames, sc, splitmix64(seed ^ 0x66))?;
    let real = states.narrow(1, k as i64, frames as i64);
    let real_n = ctx.norm(&real);
    let d = ctx.norm(&roll) - &real_n;
    let f = frames as i64;
    let anchor = states.narrow(1, k as i64 - 1, 1).expand_as(&real);
    let hold = ctx.norm(&anchor) - &real_n;
    let per_call_rmse = (0..frames.div_ceil(h))
        .map(|c| {
            let s = (c * h) as i64;
            rms(&d.narrow(1, s, (h as i64).min(f - s)))
        })
        .collect();
    Ok(Drift {
        frames,
        eligible_segments: eligible,
        windows: picks.len(),
        metrics: Some(DriftMetrics {
            rmse_final: rms(&d.narrow(1, f - 1, 1)),
            rmse_mean: rms(&d),
            joint_pos_rmse_final: ctx.g1.then(|| {
                let last = |t: &Tensor| block(&t.narrow(1, f - 1, 1), &obs::DOF_POS);
                rms(&(last(&roll) - last(&real)))
            }),
            hold_rmse_final: rms(&hold.narrow(1, f - 1, 1)),
            hold_rmse_mean: rms(&hold),
            mean_state_rmse: rms(&real_n),
            per_call_rmse,
        }),
        reason: None,
    })
}

/// Yaw rates written into the history by [`yaw_response`] (rad/s).
pub const YAW_RATES: [f64; 3] = [-0.5, 0.0, 0.5];

/// Mean over windows and steps of one state entry `[B, T, D]` in raw units.
fn mean_entry(x: &Tensor, i: usize, scale: f64) -> f64 {
    x.narrow(2, i as i64, 1)
        .mean(Kind::Double)
        .double_value(&[])
        / scale
}

/// Standard deviation of `x`.
fn std_of(x: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let m = x.iter().sum::<f64>() / n;
    (x.iter().map(|a| (a - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Least-squares slope of `y` on `x`.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len()) as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        f64::NAN
    }
}

/// The plan's yaw rate against the command's and the measured yaw rate in the
/// history (see [`YawResponse`]).
fn yaw_response(
    ctx: &Ctx,
    hist: &Tensor,
    real: &Tensor,
    scan: &Tensor,
    sc: &SamplingConfig,
    seed: u64,
) -> Result<YawResponse, WmError> {
    let sc_obs = crate::env::config::ObsScales::default();
    let (cmd_i, gyro_i) = (obs::COMMAND.start + 2, obs::ANG_VEL.start + 2);
    let (cmd_s, gyro_s) = (sc_obs.commands[2], sc_obs.ang_vel);
    let by = |i: usize, scale: f64| -> Result<Vec<f64>, WmError> {
        YAW_RATES
            .iter()
            .map(|&w| {
                let h = hist.copy();
                let _ = h.narrow(2, i as i64, 1).fill_(w * scale);
                let p = ctx.predict(&h, scan, sc, seed)?;
                Ok(mean_entry(&p, gyro_i, gyro_s))
            })
            .collect()
    };
    let predicted_by_command = by(cmd_i, cmd_s)?;
    let predicted_by_measured = by(gyro_i, gyro_s)?;
    let pred = ctx.predict(hist, scan, sc, seed)?;
    // per window: commanded (history mean) against real (horizon mean)
    let per = |x: &Tensor, i: usize, s: f64| -> Vec<f64> {
        let v = x
            .narrow(2, i as i64, 1)
            .mean_dim([1i64, 2].as_slice(), false, Kind::Double);
        to_vec(&v).into_iter().map(|a| a / s).collect()
    };
    let (cmd, rl) = (per(hist, cmd_i, cmd_s), per(real, gyro_i, gyro_s));
    Ok(YawResponse {
        windows: hist.size()[0] as usize,
        set_to: YAW_RATES.to_vec(),
        command_slope: slope(&YAW_RATES, &predicted_by_command),
        measured_slope: slope(&YAW_RATES, &predicted_by_measured),
        predicted_by_command,
        predicted_by_measured,
        history_command: mean_entry(hist, cmd_i, cmd_s),
        history_command_std: std_of(&cmd),
        real_std: std_of(&rl),
        real: mean_entry(real, gyro_i, gyro_s),
        predicted: mean_entry(&pred, gyro_i, gyro_s),
        dataset_slope: slope(&cmd, &rl),
    })
}
