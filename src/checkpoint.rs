//! Checkpoint files shared by every trainer: one libtorch archive of named
//! tensors plus a `meta` entry holding a JSON record (the trainer's own type).
//! [`save_named`] writes to `<name>.pt.tmp`, fsyncs it and renames it over the
//! target, so a kill at any moment leaves the previous checkpoint loadable;
//! [`NamedTensors::read`] turns a missing, truncated or foreign file into one
//! [`CheckpointFileError`] naming it.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::Serialize;
use tch::{Kind, Tensor};

/// A checkpoint file that cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointFileError {
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    #[error("checkpoint {path}: {message}", path = .path.display())]
    Invalid { path: PathBuf, message: String },
}

fn invalid(path: &Path, message: impl Into<String>) -> CheckpointFileError {
    CheckpointFileError::Invalid {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Write `named` and `meta` (as JSON under the name `meta`) to `path` atomically;
/// the parent directory is created if missing.
pub fn save_named(
    path: &Path,
    mut named: Vec<(String, Tensor)>,
    meta: &impl Serialize,
) -> Result<(), CheckpointFileError> {
    let json = serde_json::to_vec(meta).map_err(|e| invalid(path, e.to_string()))?;
    named.push(("meta".into(), Tensor::from_slice(&json)));
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| CheckpointFileError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    let tmp = path.with_extension("pt.tmp");
    Tensor::save_multi(&named, &tmp)?;
    // flush the data before the rename makes it the checkpoint
    std::fs::File::open(&tmp)
        .and_then(|f| f.sync_all())
        .map_err(|source| CheckpointFileError::Io {
            path: tmp.clone(),
            source,
        })?;
    std::fs::rename(&tmp, path).map_err(|source| CheckpointFileError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The tensors of a checkpoint file, by name, with its JSON record decoded.
pub struct NamedTensors<M> {
    pub path: PathBuf,
    pub meta: M,
    tensors: HashMap<String, Tensor>,
}

impl<M: DeserializeOwned> NamedTensors<M> {
    /// Read `path`; a missing, truncated or foreign file is one clear error.
    pub fn read(path: &Path) -> Result<NamedTensors<M>, CheckpointFileError> {
        if !path.is_file() {
            return Err(invalid(path, "no such file"));
        }
        let list = Tensor::load_multi(path)
            .map_err(|e| invalid(path, format!("not a readable checkpoint ({e})")))?;
        let tensors: HashMap<String, Tensor> = list.into_iter().collect();
        let meta_t = tensors
            .get("meta")
            .ok_or_else(|| invalid(path, "no 'meta' record: not a dreampolicy checkpoint"))?;
        let bytes = Vec::<u8>::try_from(&meta_t.to_kind(Kind::Uint8))
            .map_err(|e| invalid(path, e.to_string()))?;
        let meta: M = serde_json::from_slice(&bytes)
            .map_err(|e| invalid(path, format!("bad meta record: {e}")))?;
        Ok(NamedTensors {
            path: path.to_path_buf(),
            meta,
            tensors,
        })
    }
}

impl<M> NamedTensors<M> {
    /// The tensor `name`, or an error naming the file and the tensor.
    pub fn tensor(&self, name: &str) -> Result<&Tensor, CheckpointFileError> {
        self.tensors
            .get(name)
            .ok_or_else(|| invalid(&self.path, format!("missing tensor '{name}'")))
    }

    /// Copy the tensors `prefix.<name>` into `vars` (same shapes) without
    /// recording gradients.
    pub fn copy_into(
        &self,
        prefix: &str,
        vars: impl IntoIterator<Item = (String, Tensor)>,
    ) -> Result<(), CheckpointFileError> {
        for (name, mut var) in vars {
            let src = self.tensor(&format!("{prefix}.{name}"))?;
            if src.size() != var.size() {
                return Err(invalid(
                    &self.path,
                    format!(
                        "tensor '{prefix}.{name}' has shape {:?}, the configured network needs {:?}",
                        src.size(),
                        var.size()
                    ),
                ));
            }
            tch::no_grad(|| var.copy_(src));
        }
        Ok(())
    }

    /// An error about this file.
    pub fn error(&self, message: impl Into<String>) -> CheckpointFileError {
        invalid(&self.path, message)
    }
}
