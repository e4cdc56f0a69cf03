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

/// Trace the checkpoint's actor into a TorchScript file at `out`.
pub fn export(ck: &Checkpoint, out: &Path) -> Result<ExportInfo, RlError> {
    let cfg = ck.config()?;
    let mut agent = Agent::new(&cfg.policy, ck.meta.dims, 1, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent)?;
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
