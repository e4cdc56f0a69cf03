//! Checkpoints: one file of named tensors (networks, Adam moments, normalizer
//! statistics) plus a JSON record (iteration, env-steps, wall time, the resolved
//! config, every env's RNG and curriculum level), through the shared
//! [`crate::checkpoint`] file format: written to a temporary name and renamed, so
//! a kill at any moment leaves the previous checkpoint loadable.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tch::{Kind, Tensor};

use super::agent::Agent;
use super::config::{HistoryKind, ScanEncoderKind, ESTIMATE_DIM};
use super::normalizer::RunningNorm;
use super::optim::Adam;
use super::RlError;
use crate::checkpoint::{save_named, NamedTensors};
use crate::env::task::{EnvSnapshot, TaskDims};

/// Bumped when the layout changes.
pub const FORMAT: u32 = 1;

/// The JSON record of a checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format: u32,
    /// PPO iterations done.
    pub iteration: usize,
    pub env_steps: u64,
    pub wall_time_s: f64,
    pub adam_step: i64,
    pub learning_rate: f64,
    pub dims: TaskDims,
    pub n_envs: usize,
    /// The resolved experiment config (YAML).
    pub config: String,
    pub snapshots: Vec<EnvSnapshot>,
    pub mujoco_version: String,
    pub libtorch_version: String,
    /// Mean episode return over the last 100 episodes at save time (None before
    /// the first episode ended).
    pub mean_return: Option<f64>,
    /// Returns and lengths of the last (up to 100) episodes, for the logs of a resumed run.
    pub episode_window: (Vec<f64>, Vec<f64>),
    /// Penalty-curriculum scale at save time.
    pub penalty_scale: f64,
    /// The files whose networks and normalizers this checkpoint holds the
    /// mean of ([`average`]); empty for a checkpoint a run saved.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub averaged_from: Vec<String>,
}

impl CheckpointMeta {
    /// The record of a run's checkpoint taken now: `cfg` (resolved), the
    /// task's sizes, env snapshots and penalty scale, Adam's step and rate
    /// (`opt`; 0 without one), the run's `iteration`, env-steps and wall time,
    /// and the window of recent episode returns and lengths (its mean return
    /// is the record's, None while it is empty).
    pub fn record(
        cfg: &crate::rl::config::ExperimentConfig,
        task: &dyn crate::env::task::VecTask,
        opt: Option<&Adam>,
        (iteration, env_steps, wall_time_s): (usize, u64, f64),
        episode_window: (Vec<f64>, Vec<f64>),
    ) -> Result<CheckpointMeta, RlError> {
        let w = &episode_window.0;
        let mean = (!w.is_empty()).then(|| w.iter().sum::<f64>() / w.len() as f64);
        Ok(CheckpointMeta {
            format: FORMAT,
            iteration,
            env_steps,
            wall_time_s,
            adam_step: opt.map_or(0, |o| o.step),
            learning_rate: opt.map_or(0.0, |o| o.lr),
            dims: task.dims(),
            n_envs: task.n_envs(),
            config: serde_yaml::to_string(cfg).map_err(|e| RlError::Invalid(e.to_string()))?,
            snapshots: task.snapshot(),
            mujoco_version: crate::sim::mujoco_version(),
            libtorch_version: env!("DREAMPOLICY_LIBTORCH_VERSION").to_string(),
            mean_return: mean.filter(|r| r.is_finite()),
            episode_window,
            penalty_scale: task.penalty_scale(),
            averaged_from: Vec::new(),
        })
    }
}

/// What [`Checkpoint::transfer_agent`] did, tensor by tensor.
#[derive(Debug, Clone, Default)]
pub struct Transfer {
    pub copied: Vec<String>,
    /// First layers that got zero columns for the scan latent.
    pub widened: Vec<String>,
    /// Scan-encoder tensors left at their fresh initialization.
    pub fresh: Vec<String>,
    /// Actor, critic and encoder layers grown to wider hidden sizes, a wider
    /// scan latent or a longer history (the old units copied, the new units'
    /// outgoing weights or new inputs' columns zero).
    pub grown: Vec<String>,
}

impl std::fmt::Display for Transfer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} tensors copied, widened for the scan latent: [{}], fresh: [{}]",
            self.copied.len(),
            self.widened.join(", "),
            self.fresh.join(", ")
        )?;
        if self.grown.is_empty() {
            return Ok(());
        }
        write!(f, ", grown to wider layers: [{}]", self.grown.join(", "))
    }
}

/// A checkpoint read from disk.
pub struct Checkpoint {
    pub path: PathBuf,
    pub meta: CheckpointMeta,
    file: NamedTensors<CheckpointMeta>,
    /// `eval.*` overrides that [`Checkpoint::config`] applies to the stored
    /// config ([`Checkpoint::set_eval`]).
    eval_sets: Vec<String>,
}

fn err(path: &Path, message: impl Into<String>) -> RlError {
    RlError::Checkpoint {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn f64_tensor(v: &[f64]) -> Tensor {
    Tensor::from_slice(v)
}

/// Write `agent` (and `opt`, and the task's own learned state `task`, saved
/// under `task.<name>`) with `meta` to `path` atomically.
pub fn save(
    path: &Path,
    agent: &Agent,
    opt: Option<&Adam>,
    task: Vec<(String, Tensor)>,
    meta: &CheckpointMeta,
) -> Result<(), RlError> {
    let mut named: Vec<(String, Tensor)> = task
        .into_iter()
        .map(|(n, t)| (format!("task.{n}"), t.detach()))
        .collect();
    for (name, t) in agent.policy.named_parameters() {
        named.push((format!("policy.{name}"), t.detach()));
    }
    if let Some(opt) = opt {
        named.extend(opt.named_moments());
    }
    named.push(("norm.obs".into(), f64_tensor(&agent.obs_norm.to_vec())));
    named.push((
        "norm.critic".into(),
        f64_tensor(&agent.critic_norm.to_vec()),
    ));
    named.push(("norm.scan".into(), f64_tensor(&agent.scan_norm.to_vec())));
    Ok(save_named(path, named, meta)?)
}

/// Tensors [`average`] takes the mean of: the networks and the observation
/// normalizers. The rest (Adam's moments, the task's own state) and the JSON
/// record come from the last file.
fn averaged(name: &str) -> bool {
    name.starts_with("policy.") || name.starts_with("norm.")
}

/// Write to `out` the checkpoint whose policy weights and normalizer
/// statistics are the element-wise mean of `paths`' (stochastic weight
/// averaging over checkpoints of one run): kept checkpoints a few hundred
/// iterations apart differ in what they score on the same lanes, and their
/// mean sits between them. The files must hold the same tensors with the same
/// shapes (one network layout); the record, Adam's moments and the task state
/// are the last file's, so the result evaluates, plays and resumes like it,
/// with `averaged_from` naming the files.
pub fn average(paths: &[PathBuf], out: &Path) -> Result<CheckpointMeta, RlError> {
    let Some(last) = paths.last() else {
        return Err(RlError::Invalid("average: no checkpoint given".into()));
    };
    // Checkpoint::read refuses another format
    let files = paths
        .iter()
        .map(|p| Checkpoint::read(p).map(|c| c.file))
        .collect::<Result<Vec<_>, _>>()?;
    let base = &files[files.len() - 1];
    let names = base.names();
    for f in &files {
        if f.names() != names {
            return Err(err(
                &f.path,
                format!(
                    "holds other tensors than {}: not the same network layout",
                    last.display()
                ),
            ));
        }
    }
    let mut named = Vec::new();
    for name in names.into_iter().filter(|n| *n != "meta") {
        let t = base.tensor(name)?;
        if !averaged(name) {
            named.push((name.to_string(), t.shallow_clone()));
            continue;
        }
        let mut sum = t.to_kind(Kind::Double);
        for f in &files[..files.len() - 1] {
            let u = f.tensor(name)?;
            if u.size() != t.size() {
                return Err(err(
                    &f.path,
                    format!(
                        "tensor '{name}' has shape {:?}, {} has {:?}",
                        u.size(),
                        last.display(),
                        t.size()
                    ),
                ));
            }
            sum += u.to_kind(Kind::Double);
        }
        named.push((
            name.to_string(),
            (sum / files.len() as f64).to_kind(t.kind()),
        ));
    }
    let mut meta = base.meta.clone();
    meta.averaged_from = paths.iter().map(|p| p.display().to_string()).collect();
    save_named(out, named, &meta)?;
    Ok(meta)
}

/// Write a controller checkpoint: `meta` (its config says how to act) and no
/// policy tensors, for a method that learns no policy of its own (the
/// w/o-GCRL baseline, whose actions come from its world model).
pub fn save_controller(path: &Path, meta: &CheckpointMeta) -> Result<(), RlError> {
    Ok(save_named(path, Vec::new(), meta)?)
}

/// The `--set` keys of a unified policy's inference that `eval`, `play` and
/// `render` may change (prefixes): the world model the plans come from, its
/// sampler, step count and guidance, the re-planning interval, and the plan's
/// source (`unified.plan=hold`, the ablation that holds the current state)
/// and the states it plans from (`unified.history`).
pub const INFERENCE_KEYS: [&str; 5] = [
    "unified.world_model=",
    "unified.sampling.",
    "unified.replan_every=",
    "unified.plan=",
    "unified.history=",
];

/// `sets` and, when given, `unified.world_model=<world_model>` after them
/// (`--world-model F` of `eval`, `play` and `render`).
pub fn with_world_model(sets: &[String], world_model: Option<&Path>) -> Vec<String> {
    let mut all = sets.to_vec();
    if let Some(w) = world_model {
        all.push(format!("unified.world_model={}", w.display()));
    }
    all
}

impl Checkpoint {
    /// Read a checkpoint; a missing, truncated or foreign file is one clear error.
    pub fn read(path: &Path) -> Result<Checkpoint, RlError> {
        let file = NamedTensors::<CheckpointMeta>::read(path)?;
        if file.meta.format != FORMAT {
            return Err(err(
                path,
                format!("format {} (this build reads {FORMAT})", file.meta.format),
            ));
        }
        Ok(Checkpoint {
            path: path.to_path_buf(),
            meta: file.meta.clone(),
            file,
            eval_sets: Vec::new(),
        })
    }

    /// The `eval.*` overrides [`Checkpoint::set_eval`] added.
    pub fn eval_sets(&self) -> &[String] {
        &self.eval_sets
    }

    /// Change the stored config's evaluation protocol (`eval.*` keys,
    /// `key=value` as `--set` takes them, e.g.
    /// `eval.terrain.uneven.heights=full`) for every later [`Checkpoint::config`].
    /// A unified policy's checkpoint also takes its inference keys
    /// ([`INFERENCE_KEYS`]: the world model, its sampler and the re-planning
    /// interval), which change the plans it reads, not its weights.
    /// Another key, or a value the config refuses, is an error and changes nothing.
    pub fn set_eval(&mut self, sets: &[String]) -> Result<(), RlError> {
        if sets.is_empty() {
            return Ok(());
        }
        let unified = self.config()?.unified.is_some();
        let allowed = |s: &str| {
            s.starts_with("eval.") || (unified && INFERENCE_KEYS.iter().any(|k| s.starts_with(k)))
        };
        if let Some(bad) = sets.iter().find(|s| !allowed(s)) {
            let also = if unified {
                format!(
                    " and the unified policy's inference keys ({})",
                    INFERENCE_KEYS.join(", ")
                )
            } else {
                String::new()
            };
            return Err(RlError::Invalid(format!(
                "--set {bad}: only eval.* keys (the evaluation protocol){also} can be changed \
                 here; the policy and its training env are the checkpoint's"
            )));
        }
        let all = [&self.eval_sets[..], sets].concat();
        let old = std::mem::replace(&mut self.eval_sets, all);
        if let Err(e) = self.config() {
            self.eval_sets = old;
            return Err(e);
        }
        Ok(())
    }

    /// The resolved config stored in the checkpoint.
    ///
    /// On a MuJoCo 2.x build a stored `implicitfast` integrator (MuJoCo 3 only)
    /// is read as `implicit`, with a note on stderr: evaluation runs on the
    /// default scene's `implicit` anyway, and this is what lets the sim-to-sim
    /// matrix's MuJoCo-build axis load 3.x-trained checkpoints.
    pub fn config(&self) -> Result<crate::rl::config::ExperimentConfig, RlError> {
        let label = format!("{} (stored config)", self.path.display());
        let mut overrides = Vec::new();
        if self.meta.config.contains("implicitfast") && mujoco_sys::MUJOCO_VERSION_HEADER < 300 {
            eprintln!(
                "note: {} was trained with the implicitfast integrator, which MuJoCo {} lacks; \
                 its training scene runs with implicit here",
                self.path.display(),
                crate::sim::mujoco_version()
            );
            overrides.push("env.sim.integrator=implicit".to_string());
        }
        overrides.extend(self.eval_sets.iter().cloned());
        Ok(crate::rl::config::from_str(
            &self.meta.config,
            &label,
            &overrides,
        )?)
    }

    /// The task's saved state tensor `name` (saved as `task.<name>`).
    pub fn task_tensor(&self, name: &str) -> Option<Tensor> {
        self.file
            .tensor(&format!("task.{name}"))
            .ok()
            .map(|t| t.shallow_clone())
    }

    fn tensor(&self, name: &str) -> Result<&Tensor, RlError> {
        Ok(self.file.tensor(name)?)
    }

    /// Copy the networks and normalizers into `agent` (same architecture).
    pub fn load_agent(&self, agent: &mut Agent) -> Result<(), RlError> {
        if self.file.tensor("norm.obs").is_err() {
            return Err(err(
                &self.path,
                "holds no policy: a controller checkpoint (task: no_gcrl, whose actions come from its world model); eval and benchmark run it, play, render and export read policies",
            ));
        }
        self.file
            .copy_into("policy", agent.policy.named_parameters())?;
        let d = agent.dims();
        for (key, dim, slot) in [
            ("norm.obs", d.obs, &mut agent.obs_norm),
            ("norm.critic", d.critic, &mut agent.critic_norm),
            ("norm.scan", d.scan, &mut agent.scan_norm),
        ] {
            let v = Vec::<f64>::try_from(&self.tensor(key)?.to_kind(Kind::Double))
                .map_err(|e| err(&self.path, e.to_string()))?;
            let frozen = slot.frozen;
            *slot = RunningNorm::from_vec(dim, &v)
                .ok_or_else(|| err(&self.path, format!("'{key}' does not fit {dim} dims")))?;
            slot.frozen = frozen;
        }
        Ok(())
    }

    /// Start `agent` from this checkpoint where the architectures differ by the
    /// scan encoders only: the flat walker (no scandots) into a terrain
    /// specialist. Tensors of the same shape are copied; the first layers of the
    /// actor and the critic get zero columns where the scan latent enters (so the
    /// new policy acts exactly as the old one until training moves them); the
    /// scan encoders keep their fresh weights, and the scandot normalizer its
    /// fresh statistics (a plane's scandots say nothing about terrain). The
    /// actor's and critic's hidden layers may also be wider than the source's
    /// (Net2Net): the old units are copied, the new units' incoming weights keep
    /// their fresh initialization and their outgoing weights start at zero, so
    /// that the wider policy too acts as the old one at first. An MLP scan
    /// encoder may grow the same way, its latent included: the new latent units
    /// enter the actor's and critic's first layers through zero columns; so may
    /// an MLP history encoder, and its history may be longer: the older states
    /// it adds enter through zero columns. A scan slot may grow at its front
    /// (a unified policy reading `[plan | scandots]` from a policy reading the
    /// scandots, MLP encoders): the new inputs enter the scan encoders' first
    /// layers through zero columns, and their normalizer statistics are the
    /// actor-state normalizer's, tiled. Any other
    /// difference is an error naming the tensor.
    pub fn transfer_agent(&self, agent: &mut Agent) -> Result<Transfer, RlError> {
        let src_cfg = self.config()?;
        let src_scan = src_cfg.policy.scan_encoder.enabled && self.meta.dims.scan > 0;
        let dims = agent.dims();
        let mlp = |k: ScanEncoderKind| k == ScanEncoderKind::Mlp;
        // a scan slot that grows at its front (MLP encoders): a unified policy
        // reading `[plan | scandots]` from a specialist or student reading the
        // scandots; the new inputs enter the encoders through zero columns
        let scan_front = (src_scan
            && agent.policy.uses_scan()
            && dims.scan > self.meta.dims.scan
            && mlp(src_cfg.policy.scan_encoder.kind)
            && mlp(agent.policy.cfg.scan_encoder.kind))
        .then(|| (dims.scan - self.meta.dims.scan) as i64);
        // a policy without scandots may go to a task whose scan slot differs
        // (the unified policy's plan): its scan encoder starts fresh
        let same = |a: TaskDims, b: TaskDims| {
            a.obs == b.obs
                && a.critic == b.critic
                && a.action == b.action
                && (!src_scan || a.scan == b.scan || scan_front.is_some())
        };
        if !same(self.meta.dims, dims) {
            return Err(err(
                &self.path,
                format!(
                    "saved for task dims {:?}, this policy has {dims:?}",
                    self.meta.dims
                ),
            ));
        }
        let scan_out = if agent.policy.uses_scan() {
            agent.policy.cfg.scan_encoder.latent()
        } else {
            0
        };
        // a scan encoder with a wider latent than the source's (MLP encoders
        // only): the new latent units enter the actor and critic through zero
        // columns at the end of the scan block
        let src_se = &src_cfg.policy.scan_encoder;
        let src_latent = if src_scan { src_se.latent() } else { 0 };
        let latent_grows = (src_scan
            && scan_out > src_latent
            && mlp(src_se.kind)
            && mlp(agent.policy.cfg.scan_encoder.kind))
        .then_some(scan_out - src_latent);
        // a policy given the privileged-information estimator its source lacks
        let src_est = src_cfg.policy.estimator.is_some();
        let est_grows = !src_est && agent.policy.has_estimator();
        let mut report = Transfer::default();
        for (name, mut var) in agent.policy.named_parameters() {
            let Some(src) = self.file.tensor(&format!("policy.{name}")).ok() else {
                if (name.starts_with("scan_") && !src_scan)
                    || (name.starts_with("est.") && !src_est)
                {
                    report.fresh.push(name);
                    continue;
                }
                return Err(err(&self.path, format!("missing tensor '{name}'")));
            };
            let (ss, ns) = (src.size(), var.size());
            if ss == ns {
                tch::no_grad(|| var.copy_(src));
                report.copied.push(name);
                continue;
            }
            // the first layer of the actor ([hist, scan, obs]) or critic ([scan,
            // critic]): where the source's scan block ends
            let offset = match name.as_str() {
                "actor.0.weight" => Some(ss.get(1).copied().unwrap_or(0) - dims.obs as i64),
                "critic.0.weight" => Some(src_latent),
                _ => None,
            };
            // an estimator added: its estimate enters the actor's first layer
            // through zero columns just before `o_t`
            if name == "actor.0.weight"
                && est_grows
                && ss.len() == 2
                && ns.len() == 2
                && ns[0] >= ss[0]
                && ns[1] == ss[1] + ESTIMATE_DIM as i64
            {
                tch::no_grad(|| {
                    var.narrow(0, 0, ss[0]).copy_(&with_zero_columns(
                        src,
                        ss[1] - dims.obs as i64,
                        ESTIMATE_DIM as i64,
                    ))
                });
                report.grown.push(name);
                continue;
            }
            // a scan slot grown at its front: the encoders' first layers take
            // the new inputs through zero columns before the old ones
            if let Some(front) = scan_front {
                if (name == "scan_actor.0.weight" || name == "scan_critic.0.weight")
                    && ss.len() == 2
                    && ns.len() == 2
                    && ns[0] == ss[0]
                    && ns[1] == ss[1] + front
                {
                    tch::no_grad(|| var.copy_(&with_zero_columns(src, 0, front)));
                    report.widened.push(name);
                    continue;
                }
            }
            // a longer MLP history: the history is oldest first, so the new
            // (older) states enter through zero columns in front of the old ones
            if name == "hist.0.weight"
                && src_cfg.policy.history.kind == HistoryKind::Mlp
                && agent.policy.cfg.history.kind == HistoryKind::Mlp
                && ss.len() == 2
                && ns.len() == 2
                && ns[0] >= ss[0]
                && ns[1] > ss[1]
                && ss[1] % dims.obs as i64 == 0
                && ns[1] % dims.obs as i64 == 0
            {
                tch::no_grad(|| {
                    var.narrow(0, 0, ss[0])
                        .copy_(&with_zero_columns(src, 0, ns[1] - ss[1]))
                });
                report.grown.push(name);
                continue;
            }
            // the first layer of a policy whose scan latent grew: zero columns
            // for the new latent units (and, if the layer is wider too, its new
            // rows fresh, as below)
            if let (Some(off), Some(d)) = (offset, latent_grows) {
                if ss.len() == 2 && ns.len() == 2 && ns[1] == ss[1] + d && ns[0] >= ss[0] {
                    tch::no_grad(|| {
                        var.narrow(0, 0, ss[0])
                            .copy_(&with_zero_columns(src, off, d))
                    });
                    report.grown.push(name);
                    continue;
                }
            }
            // a wider actor, critic or scan encoder (Net2Net): the old units
            // in the leading block, the new units' incoming weights fresh and
            // their outgoing weights zero, so that the policy acts as the old
            // one at first
            if grows(&name, &ss, &ns) {
                tch::no_grad(|| {
                    if ns.len() == 2 {
                        let _ = var.narrow(1, ss[1], ns[1] - ss[1]).zero_();
                        var.narrow(0, 0, ss[0]).narrow(1, 0, ss[1]).copy_(src);
                    } else {
                        var.narrow(0, 0, ss[0]).copy_(src);
                    }
                });
                report.grown.push(name);
                continue;
            }
            // a scan encoder added (and on the actor, with an estimator added
            // at once, its estimate too: both blocks sit just before `o_t`,
            // scan latent first, so they enter as one run of zero columns)
            let extra = scan_out
                + if name == "actor.0.weight" && est_grows {
                    ESTIMATE_DIM as i64
                } else {
                    0
                };
            let widen = offset.filter(|_| {
                !src_scan
                    && scan_out > 0
                    && ss.len() == 2
                    && ns.len() == 2
                    && ss[0] == ns[0]
                    && ns[1] == ss[1] + extra
            });
            let Some(off) = widen else {
                return Err(err(
                    &self.path,
                    format!(
                        "tensor '{name}' has shape {ss:?}, the configured policy needs {ns:?}: only the scan encoders may be added, the actor's, critic's and MLP encoders' layers widened and an MLP history lengthened"
                    ),
                ));
            };
            tch::no_grad(|| var.copy_(&with_zero_columns(src, off, extra)));
            report.widened.push(name);
        }
        let d = dims;
        for (key, dim, slot, take) in [
            ("norm.obs", d.obs, &mut agent.obs_norm, true),
            ("norm.critic", d.critic, &mut agent.critic_norm, true),
            ("norm.scan", d.scan, &mut agent.scan_norm, src_scan),
        ] {
            if !take {
                continue;
            }
            let read = |key: &str| -> Result<Vec<f64>, RlError> {
                Vec::<f64>::try_from(&self.tensor(key)?.to_kind(Kind::Double))
                    .map_err(|e| err(&self.path, e.to_string()))
            };
            let mut v = read(key)?;
            if let (Some(front), "norm.scan") = (scan_front, key) {
                v = front_grown_norm(&v, &read("norm.obs")?, front as usize, d.obs).ok_or_else(
                    || err(&self.path, "'norm.scan' or 'norm.obs' has the wrong size"),
                )?;
            }
            let frozen = slot.frozen;
            *slot = RunningNorm::from_vec(dim, &v)
                .ok_or_else(|| err(&self.path, format!("'{key}' does not fit {dim} dims")))?;
            slot.frozen = frozen;
        }
        Ok(report)
    }

    /// Continue a run from this checkpoint: `task` must have the saved env
    /// count and sizes; the agent's networks and normalizers, Adam's moments,
    /// step and rate, the envs' RNGs and levels, the task's own state and the
    /// penalty scale are restored, then every env starts a new episode (the
    /// checkpoint was taken at one). Returns the run's iteration, env-steps
    /// and wall time so far.
    pub fn resume_into(
        &self,
        task: &mut dyn crate::env::task::VecTask,
        agent: &mut Agent,
        opt: &mut Adam,
    ) -> Result<(usize, u64, f64), RlError> {
        let (m, n, d) = (&self.meta, task.n_envs(), task.dims());
        if m.n_envs != n || m.dims != d {
            return Err(RlError::Invalid(format!(
                "{}: saved for {} envs of {:?}, this run has {n} of {d:?}",
                self.path.display(),
                m.n_envs,
                m.dims
            )));
        }
        self.load_agent(agent)?;
        self.load_optimizer(opt)?;
        let here = |e: String| RlError::Invalid(format!("{}: {e}", self.path.display()));
        task.restore(&m.snapshots).map_err(here)?;
        task.load_state_tensors(&|name| self.task_tensor(name))
            .map_err(here)?;
        task.set_penalty_scale(m.penalty_scale);
        task.reset_all();
        Ok((m.iteration, m.env_steps, m.wall_time_s))
    }

    /// Restore Adam's moments and step.
    pub fn load_optimizer(&self, opt: &mut Adam) -> Result<(), RlError> {
        opt.load_moments(|name| self.file.tensor(name))?;
        opt.step = self.meta.adam_step;
        opt.lr = self.meta.learning_rate;
        Ok(())
    }
}

/// A scan normalizer's `[mean, var, count]` grown by `front` inputs before
/// the old ones: predicted states (a whole number of `obs_dim` states) take the
/// actor-state normalizer's statistics, tiled (they are states of the same
/// space), anything else mean 0 and variance 1; the count stays the source's.
fn front_grown_norm(scan: &[f64], obs: &[f64], front: usize, obs_dim: usize) -> Option<Vec<f64>> {
    if scan.len() % 2 != 1 || obs.len() != 2 * obs_dim + 1 {
        return None;
    }
    let old = scan.len() / 2;
    let (mean, var) = if front.is_multiple_of(obs_dim) {
        let tile = |v: &[f64]| v.iter().copied().cycle().take(front).collect::<Vec<f64>>();
        (tile(&obs[..obs_dim]), tile(&obs[obs_dim..2 * obs_dim]))
    } else {
        (vec![0.0; front], vec![1.0; front])
    };
    let mut out = mean;
    out.extend_from_slice(&scan[..old]);
    out.extend(var);
    out.extend_from_slice(&scan[old..2 * old]);
    out.push(scan[2 * old]);
    Some(out)
}

/// `w` (`[out, in]`) with `n` zero columns inserted before column `at`: the
/// weights of inputs added there, silent until training moves them.
fn with_zero_columns(w: &Tensor, at: i64, n: i64) -> Tensor {
    let (rows, cols) = (w.size()[0], w.size()[1]);
    let zeros = Tensor::zeros([rows, n], (w.kind(), w.device()));
    Tensor::cat(&[w.narrow(1, 0, at), zeros, w.narrow(1, at, cols - at)], 1)
}

/// Whether `name` is a layer of the actor, critic or an MLP history or scan
/// encoder that grows from `old` to `new` (as many dims, none smaller, the
/// input of a first layer unchanged).
fn grows(name: &str, old: &[i64], new: &[i64]) -> bool {
    (name.starts_with("actor.")
        || name.starts_with("critic.")
        || (name.starts_with("hist.") && name[5..].starts_with(|c: char| c.is_ascii_digit()))
        || name.starts_with("scan_actor.")
        || name.starts_with("scan_critic."))
        && old.len() == new.len()
        && !old.is_empty()
        && old.iter().zip(new).all(|(o, n)| n >= o)
        && old != new
        && !(name.ends_with(".0.weight") && old.get(1) != new.get(1))
}
