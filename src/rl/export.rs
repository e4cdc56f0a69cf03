//! TorchScript export of a checkpoint's deterministic actor, normalization
//! included: `forward(obs [B, 98], history [B, K, 98], scan [B, 187]) -> action
//! mean [B, 29]` on raw (unnormalized) inputs, oldest history state first. `K`
//! is the policy's history length (inputs it does not use are ignored, but
//! always passed). Load it with `torch.jit.load` or tch's `CModule::load`.
use std::path::Path;

use serde::Serialize;
use tch::{Kind, Tensor};

use super::agent::Agent;
use super::checkpoint::Checkpoint;
use super::config::ExperimentConfig;
use super::RlError;

/// What an export wrote.
#[derive(Debug, Clone, Serialize)]
pub struct ExportInfo {
    pub path: String,
    pub obs_dim: usize,
    pub history_len: usize,
    pub scan_dim: usize,
    pub action_dim: usize,
    pub uses_scan: bool,
}

/// Normalize like `RunningNorm::apply`: `(x - mean) / std`, clipped.
fn normalize(x: &Tensor, mean: &Tensor, std: &Tensor, clip: f64, on: bool) -> Tensor {
    if on {
        ((x - mean) / std).clamp(-clip, clip)
    } else {
        x.shallow_clone()
    }
}

/// The checkpoint's config and its agent (one env's buffers), weights and
/// normalizers loaded: what both exports read.
pub(crate) fn checkpoint_agent(ck: &Checkpoint) -> Result<(ExperimentConfig, Agent), RlError> {
    let cfg = ck.config()?;
    if cfg.task == crate::rl::config::TaskKind::Unified {
        return Err(RlError::Invalid(format!(
            "{}: a unified policy (task: unified) reads the world model's plan where a \
             specialist reads scandots; export it as a bundle (`export --out DIR`: \
             the policy, the world model's denoiser and the sampling loop)",
            ck.path.display()
        )));
    }
    let mut agent = Agent::new(&cfg.policy, ck.meta.dims, 1, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent)?;
    Ok((cfg, agent))
}

/// Trace the checkpoint's actor into a TorchScript file at `out`.
pub fn export(ck: &Checkpoint, out: &Path) -> Result<ExportInfo, RlError> {
    let (_, mut agent) = checkpoint_agent(ck)?;
    trace_actor(&mut agent, out)
}

/// Trace `agent`'s deterministic actor (normalization included) into a
/// TorchScript file at `out`: `forward(obs, history, scan)` on raw inputs, as
/// [`export`] writes it (a unified policy's "scan" is its plan).
pub fn trace_actor(agent: &mut Agent, out: &Path) -> Result<ExportInfo, RlError> {
    // traced weights become constants of the graph: they must not require grad
    agent.policy.vs.freeze();
    let d = agent.dims();
    let k = agent.policy.history_len();
    let (om, os) = agent.obs_norm.tensors();
    let (sm, ss) = agent.scan_norm.tensors();
    let (oc, sc) = (agent.obs_norm.clip as f64, agent.scan_norm.clip as f64);
    let on = agent.normalize;
    let uses_scan = agent.policy.uses_scan();
    let inputs = [
        Tensor::zeros([2, d.obs as i64], (Kind::Float, tch::Device::Cpu)),
        Tensor::zeros([2, k as i64, d.obs as i64], (Kind::Float, tch::Device::Cpu)),
        Tensor::zeros([2, d.scan as i64], (Kind::Float, tch::Device::Cpu)),
    ];
    let policy = &agent.policy;
    let module = tch::no_grad(|| {
        tch::CModule::create_by_tracing("DreamPolicyActor", "forward", &inputs, &mut |x| {
            // no sizes read from the inputs: tracing would freeze the batch size
            let obs = normalize(&x[0], &om, &os, oc, on);
            let hist = normalize(&x[1], &om, &os, oc, on).flatten(1, -1);
            let actor_in = Tensor::cat(&[hist, obs], 1);
            let scan = uses_scan.then(|| normalize(&x[2], &sm, &ss, sc, on));
            vec![policy.actor_mean(&actor_in, scan.as_ref())]
        })
    })?;
    if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| RlError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    module.save(out)?;
    Ok(ExportInfo {
        path: out.display().to_string(),
        obs_dim: d.obs,
        history_len: k,
        scan_dim: d.scan,
        action_dim: d.action,
        uses_scan,
    })
}

/// What [`export_npz`] wrote: the actor's layers for a NumPy forward pass.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NpzPolicy {
    /// File name of the `.npz` (beside `deploy.yaml`).
    pub file: String,
    /// `elu`, `relu` or `tanh`, after every hidden layer and every encoder layer.
    pub activation: String,
    /// `none`, `mlp` or `gru` (the NumPy deployer runs `none` and `mlp`).
    pub history: String,
    /// Linear layers `<name>.<i>.weight` `[out, in]` and `.bias` of the history
    /// encoder (`hist`), the scan encoder (`scan_actor`) and the actor (`actor`):
    /// how many each has. The actor's input is `[hist(history flattened),
    /// scan_actor(scan), obs]`; its last layer has no activation.
    pub hist_layers: usize,
    pub scan_layers: usize,
    /// `mlp` or `gru` (the NumPy deployer runs `mlp`; a GRU scan encoder's
    /// weights are `scan_actor.{weight,bias}_{ih,hh}_l0`).
    #[serde(default = "mlp_name")]
    pub scan_encoder: String,
    pub actor_layers: usize,
    /// Inputs are normalized as `clip((x - mean) / std, -clip, clip)` with the
    /// arrays `obs_mean`, `obs_std` (history entries too) and `scan_mean`,
    /// `scan_std`, when `normalize` is true.
    pub normalize: bool,
    pub obs_clip: f64,
    pub scan_clip: f64,
}

fn mlp_name() -> String {
    "mlp".into()
}

/// Write the checkpoint's actor as NumPy arrays (`.npz`), for deployers without
/// libtorch. Same function as [`export`]'s TorchScript.
pub fn export_npz(ck: &Checkpoint, out: &Path) -> Result<NpzPolicy, RlError> {
    let (cfg, agent) = checkpoint_agent(ck)?;
    if agent.policy.has_estimator() {
        return Err(RlError::Invalid(format!(
            "{}: the policy has a privileged-information estimator (policy.estimator), which the NumPy deployer does not run yet: export its TorchScript file alone (`export --file-only`)",
            ck.path.display()
        )));
    }
    let (om, os) = agent.obs_norm.tensors();
    let (sm, ss) = agent.scan_norm.tensors();
    let mut named: Vec<(String, Tensor)> = vec![
        ("obs_mean".into(), om),
        ("obs_std".into(), os),
        ("scan_mean".into(), sm),
        ("scan_std".into(), ss),
    ];
    let vars = agent.policy.vs.variables();
    let count = |prefix: &str| {
        vars.keys()
            .filter(|k| k.starts_with(prefix) && k.ends_with(".weight"))
            .count()
    };
    let (hist_layers, scan_layers, actor_layers) =
        (count("hist."), count("scan_actor."), count("actor."));
    let mut keys: Vec<&String> = vars
        .keys()
        .filter(|k| {
            k.starts_with("hist.") || k.starts_with("scan_actor.") || k.starts_with("actor.")
        })
        .collect();
    keys.sort();
    for k in keys {
        named.push((k.clone(), vars[k].detach()));
    }
    let named: Vec<(String, Tensor)> = named
        .into_iter()
        .map(|(n, t)| (n, t.to_kind(Kind::Float).contiguous()))
        .collect();
    Tensor::write_npz(&named, out)?;
    let pc = &cfg.policy;
    let uses_scan = agent.policy.uses_scan();
    Ok(NpzPolicy {
        file: out
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        activation: format!("{:?}", pc.activation).to_lowercase(),
        history: if agent.policy.history_len() == 0 {
            "none".into()
        } else {
            format!("{:?}", pc.history.kind).to_lowercase()
        },
        hist_layers,
        scan_layers: if uses_scan { scan_layers } else { 0 },
        scan_encoder: format!("{:?}", pc.scan_encoder.kind).to_lowercase(),
        actor_layers,
        normalize: agent.normalize,
        obs_clip: agent.obs_norm.clip as f64,
        scan_clip: agent.scan_norm.clip as f64,
    })
}
