//! `dreampolicy export` of a unified checkpoint: the paper's inference loop as
//! a bundle a deployment loop runs without this crate.
//!
//! A directory with
//! * `policy.pt`: the actor, TorchScript, `forward(obs [B, 98], history
//!   [B, K_p, 98], plan [B, F * 98]) -> action mean [B, 29]` on raw inputs
//!   (the same contract as a specialist's `policy.pt`, the plan where a
//!   specialist reads scandots: the first `F` predicted states, raw, then,
//!   for a policy trained with `unified.scandots`, the env's 187 scandots as
//!   the denoiser reads them: `policy.scandots` in `unified.json`);
//! * `denoiser.pt`: the world model's guided x0 prediction, TorchScript,
//!   `forward(x_n [B, H, 98] normalized, history [B, K, 98] raw, n [B] float,
//!   scandots [B, 187] raw) -> x0 [B, H, 98] normalized`, with the state and
//!   scandot normalization, the terrain encoder and classifier-free guidance
//!   (the config's ω) inside;
//! * `unified.json` (sealed: its first key `sha256` is the digest of the rest,
//!   and it holds the two files' SHA-256): the sizes, the sampler (the step
//!   numbers and `ᾱ` of the noise schedule), the state statistics that turn
//!   the sample back into raw states, the re-planning period, and the loop in
//!   words ([`LOOP`]).
use std::path::Path;

use serde::Serialize;
use tch::{Device, Kind, Tensor};

use super::config::UnifiedConfig;
use crate::rl::checkpoint::Checkpoint;
use crate::rl::config::TaskKind;
use crate::rl::{Agent, RlError};
use crate::world_model::config::SamplerKind;
use crate::world_model::WorldModel;

/// File names inside a unified bundle.
pub const POLICY_FILE: &str = "policy.pt";
pub const DENOISER_FILE: &str = "denoiser.pt";
pub const SPEC_FILE: &str = "unified.json";
/// `format` of `unified.json`.
pub const FORMAT: &str = "dreampolicy-unified-bundle/1";

/// The inference loop the bundle's parts make, in words (also in `unified.json`).
pub const LOOP: &str = "Keep the last K states (actor-state layout, raw; after a reset all K are \
the first state). Every replan_every control steps: x = standard normal noise [1, H, 98]; for \
i, n in enumerate(sampler.steps): x0 = denoiser(x, history, [n], scandots); if n is the last \
step, x = x0; else with m = sampler.steps[i + 1]: DDIM: eps = (x - sqrt(ab[n]) x0) / \
sqrt(1 - ab[n]), x = sqrt(ab[m]) x0 + sqrt(1 - ab[m]) eps; DDPM (m = n - 1): x = \
sqrt(ab[m]) beta[n] / (1 - ab[n]) x0 + sqrt(1 - beta[n]) (1 - ab[m]) / (1 - ab[n]) x + \
sqrt(beta[n] (1 - ab[m]) / (1 - ab[n])) z, z standard normal. The plan is x * state_std + \
state_mean, its first state the next one. Between re-plans the plan drops its first state each \
control step and repeats its last. The policy's third input is the plan's first plan_states \
states, flattened, followed, when policy.scandots is true, by the scandots (the same 187 values \
the denoiser reads).";

/// The policy part of `unified.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PolicySpec {
    pub file: String,
    pub sha256: String,
    pub obs_dim: usize,
    /// `K_p`: states before the current one the policy reads.
    pub history_len: usize,
    /// `F`: predicted states the policy reads.
    pub plan_states: usize,
    /// Whether the policy's third input ends with the scandots (`unified.scandots`).
    pub scandots: bool,
    pub action_dim: usize,
}

/// The world-model part of `unified.json`.
#[derive(Debug, Clone, Serialize)]
pub struct WorldModelSpec {
    pub file: String,
    pub sha256: String,
    /// The checkpoint it was traced from.
    pub checkpoint: String,
    /// `K`, `H`, state and scandot sizes.
    pub history: usize,
    pub horizon: usize,
    pub state_dim: usize,
    pub scan_dim: usize,
    /// Classifier-free guidance ω, inside `denoiser.pt`.
    pub guidance: f64,
    pub state_mean: Vec<f64>,
    pub state_std: Vec<f64>,
}

/// The sampler part of `unified.json`.
#[derive(Debug, Clone, Serialize)]
pub struct SamplerSpec {
    /// `ddim` or `ddpm`.
    pub kind: String,
    /// The step numbers `n` the loop visits, in order (largest first).
    pub steps: Vec<usize>,
    /// `ᾱ_n` for `n = 0..=N` (`ᾱ_0 = 1`).
    pub alpha_bar: Vec<f64>,
    /// `β_n` for `n = 0..=N` (`β_0 = 0`).
    pub beta: Vec<f64>,
}

/// `unified.json` (less its seal).
#[derive(Debug, Clone, Serialize)]
pub struct UnifiedSpec {
    pub format: String,
    pub checkpoint: String,
    pub checkpoint_iteration: usize,
    pub checkpoint_env_steps: u64,
    /// Control period (s).
    pub control_dt: f64,
    pub replan_every: usize,
    pub policy: PolicySpec,
    pub world_model: WorldModelSpec,
    pub sampler: SamplerSpec,
    #[serde(rename = "loop")]
    pub inference_loop: String,
}

/// What a unified export wrote.
#[derive(Debug, Clone, Serialize)]
pub struct UnifiedBundleInfo {
    pub dir: String,
    pub files: Vec<String>,
    pub history_len: usize,
    pub plan_states: usize,
    /// The policy reads the scandots after the plan.
    pub scandots: bool,
    pub world_model_history: usize,
    pub horizon: usize,
    pub replan_every: usize,
}

/// Write the unified checkpoint `ck` as a bundle in `dir` (created only once
/// the checkpoint and its world model have loaded).
pub fn write_bundle(ck: &Checkpoint, dir: &Path) -> Result<UnifiedBundleInfo, RlError> {
    let cfg = ck.config()?;
    if cfg.task != TaskKind::Unified {
        return Err(RlError::Invalid(format!(
            "{}: not a unified policy (task: unified); `export` writes a specialist's bundle",
            ck.path.display()
        )));
    }
    let u = UnifiedConfig::of(&cfg)?;
    let mut wm = WorldModel::load(Path::new(&u.world_model), Device::Cpu)
        .map_err(|e| RlError::Invalid(format!("unified.world_model: {e}")))?;
    let mut agent = Agent::new(&cfg.policy, ck.meta.dims, 1, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent)?;
    let (s, c) = wm.net.dims();
    let (k, h) = (wm.history(), wm.horizon());
    // the policy's scan slot: F predicted states, then the scandots if it reads them
    let plan_dims = ck
        .meta
        .dims
        .scan
        .saturating_sub(if u.scandots { c } else { 0 });
    if plan_dims == 0 || plan_dims % s != 0 {
        return Err(RlError::Invalid(format!(
            "{}: the policy's plan input ({} floats) is not a whole number of the world \
             model's {s}-float states",
            ck.path.display(),
            ck.meta.dims.scan
        )));
    }
    let plan_states = plan_dims / s;

    std::fs::create_dir_all(dir).map_err(|source| RlError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let policy = crate::rl::export::trace_actor(&mut agent, &dir.join(POLICY_FILE))?;
    trace_denoiser(&mut wm, u.sampling.guidance, &dir.join(DENOISER_FILE))?;

    let sha = |f: &str| {
        let p = dir.join(f);
        crate::seal::file_sha256(&p).map_err(|source| RlError::Io { path: p, source })
    };
    let sched = &wm.sched;
    let n = sched.steps();
    let steps = match u.sampling.sampler {
        SamplerKind::Ddim => sched.ddim_steps(u.sampling.ddim_steps),
        SamplerKind::Ddpm => (1..=n).rev().collect(),
    };
    let vec = |t: &Tensor| -> Vec<f64> {
        Vec::<f64>::try_from(t.to_kind(Kind::Double).flatten(0, -1)).unwrap_or_default()
    };
    let spec = UnifiedSpec {
        format: FORMAT.into(),
        checkpoint: ck.path.display().to_string(),
        checkpoint_iteration: ck.meta.iteration,
        checkpoint_env_steps: ck.meta.env_steps,
        control_dt: cfg.env.sim.control_dt(),
        replan_every: u.replan_every,
        policy: PolicySpec {
            file: POLICY_FILE.into(),
            sha256: sha(POLICY_FILE)?,
            obs_dim: policy.obs_dim,
            history_len: policy.history_len,
            plan_states,
            scandots: u.scandots,
            action_dim: policy.action_dim,
        },
        world_model: WorldModelSpec {
            file: DENOISER_FILE.into(),
            sha256: sha(DENOISER_FILE)?,
            checkpoint: u.world_model.clone(),
            history: k,
            horizon: h,
            state_dim: s,
            scan_dim: c,
            guidance: u.sampling.guidance,
            state_mean: vec(&wm.norm.state_mean),
            state_std: vec(&wm.norm.state_std),
        },
        sampler: SamplerSpec {
            kind: match u.sampling.sampler {
                SamplerKind::Ddim => "ddim".into(),
                SamplerKind::Ddpm => "ddpm".into(),
            },
            steps,
            alpha_bar: (0..=n).map(|i| sched.alpha_bar(i)).collect(),
            beta: (0..=n)
                .map(|i| if i == 0 { 0.0 } else { sched.beta(i) })
                .collect(),
        },
        inference_loop: LOOP.into(),
    };
    let text = serde_json::to_string_pretty(&spec)
        .map_err(|e| RlError::Invalid(format!("encoding {SPEC_FILE}: {e}")))?;
    let sealed = crate::seal::seal_json(&text)
        .map_err(|e| RlError::Invalid(format!("sealing {SPEC_FILE}: {e}")))?;
    let spec_path = dir.join(SPEC_FILE);
    std::fs::write(&spec_path, sealed).map_err(|source| RlError::Io {
        path: spec_path,
        source,
    })?;
    Ok(UnifiedBundleInfo {
        dir: dir.display().to_string(),
        files: vec![POLICY_FILE.into(), DENOISER_FILE.into(), SPEC_FILE.into()],
        history_len: policy.history_len,
        plan_states,
        scandots: u.scandots,
        world_model_history: k,
        horizon: h,
        replan_every: u.replan_every,
    })
}

/// Trace the world model's guided x0 prediction (normalization, terrain
/// encoder and guidance `omega` inside) into `out`. Its weights stop
/// requiring gradients (traced weights become constants of the graph).
pub fn trace_denoiser(wm: &mut WorldModel, omega: f64, out: &Path) -> Result<(), RlError> {
    wm.net.vs.freeze();
    let (s, c) = wm.net.dims();
    let (k, h) = (wm.history() as i64, wm.horizon() as i64);
    let f = (Kind::Float, Device::Cpu);
    let inputs = [
        Tensor::zeros([2, h, s as i64], f),
        Tensor::zeros([2, k, s as i64], f),
        Tensor::ones([2], f),
        Tensor::zeros([2, c as i64], f),
    ];
    let net = &wm.net;
    // one row of the null embedding, broadcast: no batch size in the graph
    let null = net.null_embedding(1).detach();
    let module = tch::no_grad(|| {
        tch::CModule::create_by_tracing("DreamPolicyDenoiser", "forward", &inputs, &mut |x| {
            let (x_n, steps) = (&x[0], &x[2]);
            let hist = wm.norm.states(&x[1]);
            let y = net.terrain_embedding(&wm.norm.scans(&x[3]));
            let out = if omega == 1.0 {
                net.forward(x_n, &hist, steps, &y)
            } else {
                let y_null = y.zeros_like() + &null;
                if omega == 0.0 {
                    net.forward(x_n, &hist, steps, &y_null)
                } else {
                    let both = net.forward(
                        &Tensor::cat(&[x_n, x_n], 0),
                        &Tensor::cat(&[&hist, &hist], 0),
                        &Tensor::cat(&[steps, steps], 0),
                        &Tensor::cat(&[&y, &y_null], 0),
                    );
                    let parts = both.chunk(2, 0);
                    &parts[1] + (&parts[0] - &parts[1]) * omega
                }
            };
            vec![out]
        })
    })?;
    module.save(out)?;
    Ok(())
}
