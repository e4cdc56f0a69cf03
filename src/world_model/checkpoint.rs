//! World-model checkpoints in the shared [`crate::checkpoint`] format: the live
//! denoiser (`model.*`), its EMA (`ema.*`), Adam's moments (`adam_m.*`,
//! `adam_v.*`), the normalization (`norm.*`) and a JSON record with the step,
//! the data position, the resolved config and the versions.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use tch::Device;

use super::denoiser::{Denoiser, Normalizer};
use super::WmError;
use crate::checkpoint::NamedTensors;
use crate::data::Dims;
use crate::world_model::config::WorldModelConfig;

/// Bumped when the layout changes.
pub const FORMAT: u32 = 1;
/// The `kind` of a world-model checkpoint's record.
pub const KIND: &str = "world_model";

/// The JSON record of a world-model checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WmCheckpointMeta {
    pub format: u32,
    pub kind: String,
    /// Gradient steps done.
    pub iteration: usize,
    /// Training sequences drawn.
    pub sequences: u64,
    /// Data position: epochs completed, sequences consumed in the current one.
    pub epoch: u64,
    pub consumed: u64,
    pub adam_step: i64,
    pub learning_rate: f64,
    pub wall_time_s: f64,
    pub dims: Dims,
    /// The resolved world-model config (YAML).
    pub config: String,
    pub libtorch_version: String,
    /// Validation x0 loss at save time (None before the first validation).
    pub val_loss: Option<f64>,
    /// An inference copy (`checkpoint strip`): the EMA denoiser and the
    /// normalization only, no live model nor Adam moments; it plans, evaluates
    /// and exports like its source but cannot resume training.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub inference_only: bool,
}

/// A world-model checkpoint read from disk.
pub struct WmCheckpoint {
    pub file: NamedTensors<WmCheckpointMeta>,
}

impl WmCheckpoint {
    /// Read a checkpoint; a missing, truncated or foreign file (a PPO checkpoint
    /// included) is one clear error.
    pub fn read(path: &Path) -> Result<WmCheckpoint, WmError> {
        let file = NamedTensors::<WmCheckpointMeta>::read(path)?;
        if file.meta.kind != KIND || file.meta.format != FORMAT {
            return Err(file
                .error(format!(
                    "a {} checkpoint of format {} (this build reads {KIND} format {FORMAT})",
                    file.meta.kind, file.meta.format
                ))
                .into());
        }
        Ok(WmCheckpoint { file })
    }

    pub fn meta(&self) -> &WmCheckpointMeta {
        &self.file.meta
    }

    pub fn path(&self) -> &PathBuf {
        &self.file.path
    }

    /// The resolved config stored in the checkpoint.
    pub fn config(&self) -> Result<WorldModelConfig, WmError> {
        Ok(crate::world_model::config::world_model_from_str(
            &self.meta().config,
            &format!("{} (stored config)", self.path().display()),
            &[],
        )?)
    }

    /// Copy `prefix.*` (`model` or `ema`) into `net`.
    pub fn load_net(&self, prefix: &str, net: &Denoiser) -> Result<(), WmError> {
        Ok(self.file.copy_into(prefix, net.named_parameters())?)
    }

    /// Write the inference copy of this checkpoint to `out` (sealed): the
    /// `ema.*` and `norm.*` tensors and the record marked `inference_only`, a
    /// quarter of a training checkpoint's size. What reads a world model for
    /// planning (`WorldModel::load`, the unified policy, `eval world-model`,
    /// `export`) reads it as its source.
    pub fn write_inference_copy(&self, out: &Path) -> Result<(), WmError> {
        let named: Vec<(String, tch::Tensor)> = self
            .file
            .names()
            .into_iter()
            .filter(|n| n.starts_with("ema.") || n.starts_with("norm."))
            .map(|n| Ok((n.to_string(), self.file.tensor(n)?.shallow_clone())))
            .collect::<Result<_, WmError>>()?;
        let mut meta = self.meta().clone();
        meta.inference_only = true;
        Ok(crate::checkpoint::save_named(out, named, &meta)?)
    }

    /// The saved normalization.
    pub fn normalizer(&self, device: Device) -> Result<Normalizer, WmError> {
        let t = |n: &str| -> Result<tch::Tensor, WmError> {
            Ok(self.file.tensor(&format!("norm.{n}"))?.to_device(device))
        };
        Ok(Normalizer {
            state_mean: t("state_mean")?,
            state_std: t("state_std")?,
            scan_mean: t("scan_mean")?,
            scan_std: t("scan_std")?,
        })
    }
}
