//! The scheduled training of the paper's Algorithm 2, batched.
//!
//! One drawn batch is `B` sequences of `T` consecutive windows (`train.
//! rollout_windows`, at most 4). For `t = 1..=T`, one gradient step: noise the
//! clean chunk `x_t^0` to a uniform step `n in 1..=N`, predict `x0_hat = G(x_t^n,
//! x_{t-1}, n, y_t)` (terrain dropped to the null embedding with probability
//! `diffusion.terrain_drop`), minimize `||x0_hat - x_t^0||^2`, Adam, EMA (decay
//! `min(ema_decay, (1 + s) / (10 + s))` after Adam step `s`). Then,
//! per sequence, with probability `p = rollout_probability(iter, I_1, I_2)` the
//! next window's history takes the model's own sample of chunk `t` (the
//! sampler `train.rollout_sampling` with the live weights, started from
//! `x_t^0` noised to step `N` as in the algorithm), otherwise the ground truth;
//! `iter` advances by one per step. The paper draws `rand() < p` once per
//! sample; a batch draws it per sequence. The last chunk's rollout would feed
//! nothing and is skipped.
//!
//! Everything random in a batch (timesteps, noise, terrain drops, rollout
//! choices, sampler noise) comes from a [`Noise`] seeded by `(train.seed,
//! step)`, and the data stream's position is saved, so a checkpoint (taken
//! between batches) resumes bit-identically (same thread count; tested).
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;
use tch::{Device, Kind, Tensor};

use super::checkpoint::{WmCheckpoint, WmCheckpointMeta, FORMAT, KIND};
use super::denoiser::{Denoiser, Normalizer};
use super::sampler::{sample, sample_from, Noise};
use super::schedule::{rollout_probability, NoiseSchedule};
use super::sequences::{validation_windows, SeqBatch, Sequences};
use super::WmError;
use crate::data::sample::splitmix64;
use crate::data::{Dataset, DatasetStats, Dims, ReadOptions, Split};
use crate::rl::optim::Adam;
use crate::run::{latest_checkpoint, Progress, RunDir};
use crate::world_model::config::WorldModelConfig;

/// Columns of `metrics.csv` (validation columns are empty between validations).
pub const COLUMNS: [&str; 16] = [
    "iteration",
    "sequences",
    "wall_time_s",
    "loss",
    "grad_norm",
    "rollout_p",
    "rollout_fraction",
    "learning_rate",
    "samples_per_s",
    "epoch",
    "time_data_s",
    "time_train_s",
    "time_rollout_s",
    "val_loss",
    "val_next_mse",
    "val_rollout_mse",
];

/// What one batch of `T` steps did.
#[derive(Debug, Clone, Default)]
pub struct BatchStats {
    /// x0 loss of each step.
    pub losses: Vec<f64>,
    pub grad_norms: Vec<f64>,
    /// Rollout probability of each step.
    pub probs: Vec<f64>,
    /// Histories replaced by the model's sample / histories that could be.
    pub replaced: usize,
    pub replaceable: usize,
    pub time_data: f64,
    pub time_train: f64,
    pub time_rollout: f64,
}

/// Validation of the EMA weights on the fixed validation sequences.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ValStats {
    /// x0 loss of the first chunk (ground-truth history, fixed noise).
    pub loss: f64,
    /// MSE (normalized units) of the sampled first chunk.
    pub next_mse: f64,
    /// MSE of all `T H` frames rolled out autoregressively from the first history.
    pub rollout_mse: f64,
}

/// Where a run stands at its end.
#[derive(Debug, Clone, Serialize)]
pub struct WmSummary {
    pub iterations: usize,
    pub sequences: u64,
    pub wall_time_s: f64,
    /// Mean x0 loss of the last logged interval.
    pub loss: f64,
    pub val: Option<ValStats>,
    pub checkpoint: PathBuf,
}

/// Everything one training run holds.
pub struct WmTrainer {
    pub cfg: WorldModelConfig,
    pub net: Denoiser,
    pub ema: Denoiser,
    pub opt: Adam,
    pub sched: NoiseSchedule,
    pub norm: Normalizer,
    pub data: Sequences,
    val: Option<SeqBatch>,
    pub dims: Dims,
    /// Gradient steps done.
    pub iteration: usize,
    /// Sequences drawn.
    pub sequences: u64,
    wall_offset: f64,
    pub last_val: Option<ValStats>,
}

fn device() -> Device {
    Device::cuda_if_available()
}

/// The statistics a fresh run normalizes with: the dataset directory's
/// `stats.json` when present, else computed over the train split.
pub fn dataset_stats(dataset: &Dataset, cfg: &WorldModelConfig) -> Result<DatasetStats, WmError> {
    let dir = dataset.path();
    if dir.is_dir() && dir.join(crate::data::stats::STATS_FILE).is_file() {
        return Ok(DatasetStats::load(dir, dataset.dims())?);
    }
    let kinds = cfg
        .data
        .kinds()
        .map_err(|e| WmError::Invalid(e.to_string()))?;
    Ok(DatasetStats::compute(
        dataset.split_frames_of(Some((cfg.data.split()?, Split::Train)), &kinds),
        dataset.dims(),
    )?)
}

impl WmTrainer {
    /// A fresh run (or one resumed from `resume`) on the config's dataset.
    pub fn new(
        cfg: &WorldModelConfig,
        resume: Option<&WmCheckpoint>,
    ) -> Result<WmTrainer, WmError> {
        tch::set_num_threads(cfg.train.torch_threads as i32);
        tch::manual_seed(cfg.train.seed as i64);
        let path = Path::new(&cfg.data.path);
        if !path.exists() {
            return Err(WmError::Invalid(format!(
                "data.path {}: no such dataset (a directory of MCAP shards: `dreampolicy bench data --out DIR` writes a synthetic one)",
                path.display()
            )));
        }
        let dataset = Dataset::open(path, ReadOptions::default())?;
        let dims = dataset.dims();
        let dev = device();
        let norm = match resume {
            Some(ck) => ck.normalizer(dev)?,
            None => Normalizer::from_stats(&dataset_stats(&dataset, cfg)?, dev),
        };
        let spec = Sequences::spec(cfg)?;
        let net = Denoiser::new(&cfg.model, dims.state, dims.scan, dev);
        if resume.is_none() && cfg.model.history_skip && cfg.model.history_skip_fit > 0 {
            // a stream of its own over the train split (the training stream
            // starts at its beginning as without the fit)
            let mut seqs = Sequences::new(Dataset::open(path, ReadOptions::default())?, cfg)?;
            let windows = seqs.next_windows(cfg.model.history_skip_fit)?;
            let b = SeqBatch::from_windows(&windows, spec, &norm, dev);
            let h = cfg.model.horizon as i64;
            net.fit_skip(&b.history, &b.future.narrow(1, 0, h), 1e-3);
        }
        let mut ema = Denoiser::new(&cfg.model, dims.state, dims.scan, dev);
        ema.copy_from(&net)?;
        let mut opt = Adam::new(net.named_parameters(), cfg.train.learning_rate);
        let val = validation_windows(&dataset, cfg, cfg.train.val_sequences)?;
        let val = (!val.is_empty()).then(|| SeqBatch::from_windows(&val, spec, &norm, dev));
        let mut data = Sequences::new(dataset, cfg)?;
        let (mut iteration, mut sequences, mut wall_offset, mut last_val) = (0, 0, 0.0, None);
        if let Some(ck) = resume {
            let m = ck.meta();
            if m.inference_only {
                return Err(WmError::Invalid(format!(
                    "{}: an inference copy (`checkpoint strip`: the EMA weights alone, no \
                     live model nor optimizer state) cannot resume training; resume from \
                     the run's own checkpoint",
                    ck.path().display()
                )));
            }
            if m.dims != dims {
                return Err(WmError::Invalid(format!(
                    "{}: saved for dims ({}), the dataset has ({dims})",
                    ck.path().display(),
                    m.dims
                )));
            }
            ck.load_net("model", &net)?;
            ck.load_net("ema", &ema)?;
            opt.load_moments(|name| ck.file.tensor(name))?;
            opt.step = m.adam_step;
            opt.lr = cfg.train.learning_rate;
            data.seek(m.epoch, m.consumed)?;
            (iteration, sequences, wall_offset) = (m.iteration, m.sequences, m.wall_time_s);
            last_val = m.val_loss.map(|loss| ValStats {
                loss,
                next_mse: f64::NAN,
                rollout_mse: f64::NAN,
            });
        }
        Ok(WmTrainer {
            cfg: cfg.clone(),
            sched: NoiseSchedule::new(&cfg.diffusion),
            net,
            ema,
            opt,
            norm,
            data,
            val,
            dims,
            iteration,
            sequences,
            wall_offset,
            last_val,
        })
    }

    /// Number of fixed validation sequences (0 when the split is empty).
    pub fn val_len(&self) -> i64 {
        self.val.as_ref().map_or(0, |v| v.len())
    }

    /// Draw one batch of sequences and take its `T` steps.
    pub fn train_batch(&mut self) -> Result<BatchStats, WmError> {
        let c = &self.cfg;
        let (k, h) = (c.model.history as i64, c.model.horizon as i64);
        let t_windows = c.train.rollout_windows;
        let n_steps = self.sched.steps();
        let dev = self.net.device();
        let mut st = BatchStats::default();
        let mut noise = Noise::new(splitmix64(c.train.seed ^ splitmix64(self.iteration as u64)));
        let t0 = Instant::now();
        let windows = self.data.next_windows(c.train.batch_size)?;
        let batch = SeqBatch::from_windows(&windows, self.data.window_spec(), &self.norm, dev);
        drop(windows);
        self.sequences += c.train.batch_size as u64;
        st.time_data = t0.elapsed().as_secs_f64();
        let b = batch.len();
        let s = self.dims.state as i64;
        let mut hist = batch.history.shallow_clone();
        for t in 0..t_windows {
            let t1 = Instant::now();
            let x0 = batch.future.narrow(1, t as i64 * h, h);
            let scan = batch.scans.select(1, t as i64);
            let steps: Vec<usize> = (0..b).map(|_| noise.int(1, n_steps)).collect();
            let eps = noise.randn(&[b, h, s], dev);
            let x_n = self.sched.q_sample(&x0, &steps, &eps);
            let drop: Vec<bool> = (0..b)
                .map(|_| noise.uniform() < c.diffusion.terrain_drop)
                .collect();
            let drop = Tensor::from_slice(&drop).to_device(dev);
            let y = self
                .net
                .drop_terrain(&self.net.terrain_embedding(&scan), &drop);
            let n_t = NoiseSchedule::step_tensor(&steps, dev);
            let pred = self.net.forward(&x_n, &hist, &n_t, &y);
            let loss = (pred - &x0).square().mean(Kind::Float);
            let lv = loss.double_value(&[]);
            if !lv.is_finite() {
                return Err(WmError::NonFinite(format!(
                    "x0 loss is {lv} at step {}",
                    self.iteration
                )));
            }
            self.opt.zero_grad();
            loss.backward();
            let gn = if c.train.max_grad_norm > 0.0 {
                self.opt.clip_grad_norm(c.train.max_grad_norm)
            } else {
                f64::NAN
            };
            self.opt.step();
            // EMA warm-up: early on the average would still be mostly the init
            let done = self.opt.step as f64;
            let decay = c.train.ema_decay.min((1.0 + done) / (10.0 + done));
            self.ema.ema_update(&self.net, decay);
            let p = rollout_probability(
                self.iteration,
                c.train.supervised_iterations,
                c.train.scheduled_iterations,
            );
            self.iteration += 1;
            st.losses.push(lv);
            st.grad_norms.push(gn);
            st.probs.push(p);
            st.time_train += t1.elapsed().as_secs_f64();
            if t + 1 == t_windows {
                break;
            }
            let t2 = Instant::now();
            let chosen: Vec<i64> = (0..b).filter(|_| noise.uniform() < p).collect();
            st.replaceable += b as usize;
            st.replaced += chosen.len();
            let next = if chosen.is_empty() {
                x0.shallow_clone()
            } else {
                let idx = Tensor::from_slice(&chosen).to_device(dev);
                let x0_sel = x0.index_select(0, &idx);
                let start_eps = noise.randn(&x0_sel.size(), dev);
                let x_start =
                    self.sched
                        .q_sample(&x0_sel, &vec![n_steps; chosen.len()], &start_eps);
                let pred = tch::no_grad(|| {
                    let y = self.net.terrain_embedding(&scan.index_select(0, &idx));
                    sample_from(
                        &self.net,
                        &self.sched,
                        &c.train.rollout_sampling,
                        &hist.index_select(0, &idx),
                        &y,
                        x_start,
                        &mut noise,
                    )
                });
                x0.index_copy(0, &idx, &pred)
            };
            hist = Tensor::cat(&[&hist, &next], 1).narrow(1, h, k);
            st.time_rollout += t2.elapsed().as_secs_f64();
        }
        Ok(st)
    }

    /// Validate the EMA weights on the fixed validation sequences (None when
    /// the validation split is empty). Fixed noise: the same weights give the
    /// same numbers.
    pub fn validate(&self) -> Option<ValStats> {
        let val = self.val.as_ref()?;
        let c = &self.cfg;
        let (k, h) = (c.model.history as i64, c.model.horizon as i64);
        let n_steps = self.sched.steps();
        let dev = self.ema.device();
        let mut noise = Noise::new(splitmix64(c.train.seed ^ 0x5EED_F7A1));
        let (mut loss, mut next, mut roll, mut rows) = (0.0, 0.0, 0.0, 0.0);
        let bs = c.train.batch_size as i64;
        tch::no_grad(|| {
            let mut start = 0;
            while start < val.len() {
                let len = bs.min(val.len() - start);
                let v = val.rows(start, len);
                let s = v.history.size()[2];
                let x0 = v.future.narrow(1, 0, h);
                let steps: Vec<usize> = (0..len).map(|_| noise.int(1, n_steps)).collect();
                let eps = noise.randn(&[len, h, s], dev);
                let x_n = self.sched.q_sample(&x0, &steps, &eps);
                let y0 = self.ema.terrain_embedding(&v.scans.select(1, 0));
                let pred = self.ema.forward(
                    &x_n,
                    &v.history,
                    &NoiseSchedule::step_tensor(&steps, dev),
                    &y0,
                );
                let w = len as f64;
                loss += w * (pred - &x0).square().mean(Kind::Float).double_value(&[]);
                let mut hist = v.history.shallow_clone();
                let mut preds = Vec::new();
                for t in 0..c.train.rollout_windows {
                    let y = self.ema.terrain_embedding(&v.scans.select(1, t as i64));
                    let p = sample(&self.ema, &self.sched, &c.sampling, &hist, &y, &mut noise);
                    hist = Tensor::cat(&[&hist, &p], 1).narrow(1, h, k);
                    preds.push(p);
                }
                next += w
                    * (&preds[0] - &x0)
                        .square()
                        .mean(Kind::Float)
                        .double_value(&[]);
                roll += w
                    * (Tensor::cat(&preds, 1) - &v.future)
                        .square()
                        .mean(Kind::Float)
                        .double_value(&[]);
                rows += w;
                start += len;
            }
        });
        Some(ValStats {
            loss: loss / rows,
            next_mse: next / rows,
            rollout_mse: roll / rows,
        })
    }

    /// Write the resume checkpoint (between batches).
    pub fn checkpoint(&self, path: &Path, session_wall: f64) -> Result<(), WmError> {
        let meta = WmCheckpointMeta {
            format: FORMAT,
            kind: KIND.into(),
            iteration: self.iteration,
            sequences: self.sequences,
            epoch: self.data.epoch,
            consumed: self.data.consumed,
            adam_step: self.opt.step,
            learning_rate: self.opt.lr,
            wall_time_s: self.wall_time(session_wall),
            dims: self.dims,
            config: serde_yaml::to_string(&self.cfg)
                .map_err(|e| WmError::Invalid(e.to_string()))?,
            libtorch_version: env!("DREAMPOLICY_LIBTORCH_VERSION").to_string(),
            val_loss: self.last_val.map(|v| v.loss),
            inference_only: false,
        };
        let mut named = Vec::new();
        for (n, t) in self.net.named_parameters() {
            named.push((format!("model.{n}"), t.detach()));
        }
        for (n, t) in self.ema.named_parameters() {
            named.push((format!("ema.{n}"), t.detach()));
        }
        named.extend(self.opt.named_moments());
        named.extend(self.norm.named());
        Ok(crate::checkpoint::save_named(path, named, &meta)?)
    }

    /// Wall time of the whole run, given this session's elapsed seconds.
    pub fn wall_time(&self, session: f64) -> f64 {
        self.wall_offset + session
    }
}

/// Means over the steps since the last metrics row.
#[derive(Default)]
struct Interval {
    loss: f64,
    grad: f64,
    p: f64,
    steps: usize,
    replaced: usize,
    replaceable: usize,
    sequences: u64,
    time: [f64; 3],
    start: Option<Instant>,
}

impl Interval {
    fn add(&mut self, s: &BatchStats, seqs: u64) {
        self.loss += s.losses.iter().sum::<f64>();
        self.grad += s.grad_norms.iter().sum::<f64>();
        self.p += s.probs.iter().sum::<f64>();
        self.steps += s.losses.len();
        self.replaced += s.replaced;
        self.replaceable += s.replaceable;
        self.sequences += seqs;
        self.time[0] += s.time_data;
        self.time[1] += s.time_train;
        self.time[2] += s.time_rollout;
    }
}

/// `prev -> now` passed a multiple of `every` (never for `every == 0`).
fn crossed(prev: usize, now: usize, every: usize) -> bool {
    every > 0 && prev / every != now / every
}

/// Train to `cfg.train.iterations` in `run`, from scratch or from `resume`:
/// metrics rows, progress, validation, checkpoints, plots.
pub fn learn(
    cfg: &WorldModelConfig,
    run: &mut RunDir,
    resume: Option<&WmCheckpoint>,
    quiet: bool,
) -> Result<WmSummary, WmError> {
    let mut tr = WmTrainer::new(cfg, resume)?;
    let t = &cfg.train;
    let total = t.iterations;
    let ckpt = latest_checkpoint(run.path());
    let progress = Progress::new("train world model", total as u64, quiet);
    let start = Instant::now();
    let first = tr.iteration;
    run.log(&format!(
        "start at step {first} of {total}: batch {} x {} windows (K {}, H {}), {} parameters, {} validation sequences, data {}",
        t.batch_size,
        t.rollout_windows,
        cfg.model.history,
        cfg.model.horizon,
        tr.net.num_parameters(),
        tr.val_len(),
        cfg.data.path
    ))?;
    let mut iv = Interval::default();
    let mut last_loss = f64::NAN;
    while tr.iteration < total {
        iv.start.get_or_insert_with(Instant::now);
        let prev = tr.iteration;
        let st = tr.train_batch()?;
        iv.add(&st, t.batch_size as u64);
        let now = tr.iteration;
        let val = if crossed(prev, now, t.eval_interval) || (now == total && t.eval_interval > 0) {
            tr.validate()
        } else {
            None
        };
        if val.is_some() {
            tr.last_val = val;
        }
        if crossed(prev, now, t.log_interval) || now == total || val.is_some() {
            let dt = iv
                .start
                .take()
                .map_or(f64::NAN, |s| s.elapsed().as_secs_f64());
            let n = iv.steps.max(1) as f64;
            let wall = tr.wall_time(start.elapsed().as_secs_f64());
            last_loss = iv.loss / n;
            let v = val.map_or([f64::NAN; 3], |v| [v.loss, v.next_mse, v.rollout_mse]);
            run.metrics_row(&[
                now as f64,
                tr.sequences as f64,
                wall,
                last_loss,
                iv.grad / n,
                iv.p / n,
                if iv.replaceable > 0 {
                    iv.replaced as f64 / iv.replaceable as f64
                } else {
                    0.0
                },
                tr.opt.lr,
                iv.sequences as f64 / dt,
                tr.data.epoch as f64,
                iv.time[0],
                iv.time[1],
                iv.time[2],
                v[0],
                v[1],
                v[2],
            ])?;
            progress.set(
                now as u64,
                &format!(
                    "loss {last_loss:.4} p {:.2} {:.0} seq/s{}",
                    iv.p / n,
                    iv.sequences as f64 / dt,
                    val.map_or(String::new(), |v| format!(
                        " val {:.4} rollout {:.4}",
                        v.loss, v.rollout_mse
                    ))
                ),
            );
            iv = Interval::default();
        }
        if crossed(prev, now, t.save_interval) || now == total {
            tr.checkpoint(&ckpt, start.elapsed().as_secs_f64())?;
            if crossed(prev, now, t.keep_interval) {
                crate::run::keep_checkpoint(run.path(), now)?;
            }
            if let Err(e) = plot_run(run.path()) {
                run.log(&format!("plots not drawn: {e}"))?;
            }
            run.log(&format!(
                "step {now} sequences {} epoch {} loss {last_loss:.5}: checkpoint {}",
                tr.sequences,
                tr.data.epoch,
                ckpt.display()
            ))?;
        }
    }
    progress.finish();
    Ok(WmSummary {
        iterations: tr.iteration,
        sequences: tr.sequences,
        wall_time_s: tr.wall_time(start.elapsed().as_secs_f64()),
        loss: last_loss,
        val: tr.last_val,
        checkpoint: ckpt,
    })
}

/// Draw `plots/training.png` from the run's `metrics.csv`.
pub fn plot_run(run_dir: &Path) -> Result<PathBuf, crate::plot::PlotError> {
    use crate::plot::Panel;
    let x = "iteration";
    let panels = [
        Panel::new("x0 loss (normalized)", x, &["loss", "val_loss"]),
        Panel::new(
            "sampled MSE (EMA, normalized)",
            x,
            &["val_next_mse", "val_rollout_mse"],
        ),
        Panel::new("scheduled sampling", x, &["rollout_p", "rollout_fraction"]),
        Panel::new("gradient norm", x, &["grad_norm"]),
        Panel::new("sequences/s", x, &["samples_per_s"]),
        Panel::new(
            "seconds per row",
            x,
            &["time_data_s", "time_train_s", "time_rollout_s"],
        ),
    ];
    crate::run::plot_training(run_dir, &panels)
}

/// Train the config in `run_dir` (fresh, or resumed from the run's latest
/// checkpoint when `resume`); `metrics.csv` rows go into a TensorBoard event
/// file too (`run::tensorboard`).
pub fn train(
    cfg: &WorldModelConfig,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<WmSummary, WmError> {
    let (mut run, ck) = if resume {
        let ck = WmCheckpoint::read(&latest_checkpoint(run_dir))?;
        let run = RunDir::resume(run_dir, cfg, &COLUMNS, ck.meta().iteration as f64)?;
        (run, Some(ck))
    } else {
        (RunDir::create(run_dir, cfg, &COLUMNS)?, None)
    };
    let events = run.start_tensorboard()?;
    run.log(&format!("tensorboard: {}", events.display()))?;
    let s = learn(cfg, &mut run, ck.as_ref(), quiet)?;
    run.log(&format!(
        "summary {}",
        serde_json::to_string(&s).unwrap_or_default()
    ))?;
    Ok(s)
}
