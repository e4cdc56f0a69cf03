//! Checkpoint files shared by every trainer: one libtorch archive of named
//! tensors plus a `meta` entry holding a JSON record (the trainer's own type).
//! [`save_named`] writes to `<name>.pt.tmp`, fsyncs it and renames it over the
//! target ([`crate::run::write_atomic`]), so a kill at any moment leaves the previous checkpoint loadable;
//! [`NamedTensors::read`] turns a missing, truncated or foreign file into one
//! [`CheckpointFileError`] naming it.
//!
//! Every file is sealed: the archive's zip comment (the last bytes of the file,
//! which libtorch and Python's `torch.load` ignore) holds
//! `dreampolicy-sha256:<hex>`, the SHA-256 of the file as libtorch wrote it
//! (with an empty comment). [`verify`] recomputes it before every load, so a
//! flipped byte anywhere, in a tensor, the JSON record or the zip structure, is
//! refused instead of loading altered weights; a file without a seal is refused
//! too ([`seal_file`] is the explicit way to trust one, `dreampolicy checkpoint seal`).
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

/// The seal's prefix in the zip comment.
const SEAL_TAG: &[u8] = b"dreampolicy-sha256:";
/// Tag + 64 hex digits.
const SEAL_LEN: usize = SEAL_TAG.len() + 64;
/// The zip end-of-central-directory record: signature, and its size without comment.
const EOCD_SIG: &[u8] = b"PK\x05\x06";
const EOCD_LEN: usize = 22;

use crate::seal::hex;
pub use crate::seal::SealError;

/// True for a zip archive as libtorch writes one: its end record last, with an
/// empty comment.
fn is_unsealed_archive(bytes: &[u8]) -> bool {
    let n = bytes.len();
    n >= EOCD_LEN && &bytes[n - EOCD_LEN..n - EOCD_LEN + 4] == EOCD_SIG && bytes[n - 2..] == [0, 0]
}

/// Check a sealed file's bytes: the digest in its zip comment against the
/// SHA-256 of the file without it.
pub fn verify(bytes: &[u8]) -> Result<(), SealError> {
    use sha2::{Digest, Sha256};
    let n = bytes.len();
    if n < EOCD_LEN + SEAL_LEN || &bytes[n - SEAL_LEN..n - 64] != SEAL_TAG {
        let damaged_seal = bytes
            .windows(SEAL_TAG.len())
            .rev()
            .take(2 * SEAL_LEN)
            .any(|w| w == SEAL_TAG);
        return Err(if is_unsealed_archive(bytes) {
            SealError::Missing
        } else if damaged_seal {
            SealError::Mismatch
        } else {
            SealError::NotAnArchive
        });
    }
    let eocd = n - SEAL_LEN - EOCD_LEN;
    let comment_len = u16::from_le_bytes([bytes[n - SEAL_LEN - 2], bytes[n - SEAL_LEN - 1]]);
    if &bytes[eocd..eocd + 4] != EOCD_SIG || comment_len as usize != SEAL_LEN {
        return Err(SealError::Mismatch);
    }
    let mut h = Sha256::new();
    h.update(&bytes[..n - SEAL_LEN - 2]);
    h.update([0u8, 0u8]);
    if hex(&h.finalize()) == String::from_utf8_lossy(&bytes[n - 64..]) {
        Ok(())
    } else {
        Err(SealError::Mismatch)
    }
}

/// The sealed form of an unsealed archive's bytes.
pub fn seal_bytes(mut bytes: Vec<u8>) -> Result<Vec<u8>, SealError> {
    use sha2::{Digest, Sha256};
    let n = bytes.len();
    if verify(&bytes).is_ok() {
        return Err(SealError::AlreadySealed);
    }
    if !is_unsealed_archive(&bytes) {
        return Err(SealError::NotAnArchive);
    }
    let digest = hex(&Sha256::digest(&bytes));
    bytes[n - 2..].copy_from_slice(&(SEAL_LEN as u16).to_le_bytes());
    bytes.extend_from_slice(SEAL_TAG);
    bytes.extend_from_slice(digest.as_bytes());
    Ok(bytes)
}

/// Seal the archive at `path` in place (through a temporary file and a rename).
/// For a file written before checkpoints were sealed that you trust: a sealed
/// file is refused, and nothing checks that the weights are the ones you meant.
pub fn seal_file(path: &Path) -> Result<(), CheckpointFileError> {
    let bytes = read_bytes(path)?;
    let sealed = seal_bytes(bytes).map_err(|e| invalid(path, e.to_string()))?;
    write_atomic(path, &sealed)
}

/// Check the seal of the file at `path`.
pub fn verify_file(path: &Path) -> Result<(), CheckpointFileError> {
    read_verified(path).map(|_| ())
}

/// The bytes of the file at `path`, once its seal is checked.
fn read_verified(path: &Path) -> Result<Vec<u8>, CheckpointFileError> {
    let bytes = read_bytes(path)?;
    verify(&bytes).map_err(|e| invalid(path, e.to_string()))?;
    Ok(bytes)
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, CheckpointFileError> {
    if !path.is_file() {
        return Err(invalid(path, "no such file"));
    }
    std::fs::read(path).map_err(|source| CheckpointFileError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CheckpointFileError> {
    crate::run::write_atomic(path, bytes)
        .map_err(|(path, source)| CheckpointFileError::Io { path, source })
}

/// The first line of a libtorch message: its C++ backtrace stays out of ours.
pub fn first_line(text: &str) -> &str {
    text.lines().next().unwrap_or("").trim_end()
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
    let mut bytes = Vec::new();
    Tensor::save_multi_to_stream(&named, &mut bytes)
        .map_err(|e| invalid(path, format!("saving: {}", first_line(&e.to_string()))))?;
    let sealed = seal_bytes(bytes).map_err(|e| invalid(path, format!("sealing: {e}")))?;
    write_atomic(path, &sealed)
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
        // one read: the bytes whose seal was checked are the ones loaded
        let bytes = read_verified(path)?;
        let list = Tensor::load_multi_from_stream(std::io::Cursor::new(bytes)).map_err(|e| {
            invalid(
                path,
                format!("not a readable checkpoint ({})", first_line(&e.to_string())),
            )
        })?;
        let tensors: HashMap<String, Tensor> = list.into_iter().collect();
        let meta_t = tensors
            .get("meta")
            .ok_or_else(|| invalid(path, "no 'meta' record: not a dreampolicy checkpoint"))?;
        let bytes = Vec::<u8>::try_from(&meta_t.to_kind(Kind::Uint8))
            .map_err(|e| invalid(path, e.to_string()))?;
        let meta: M = serde_json::from_slice(&bytes).map_err(|e| {
            invalid(
                path,
                match foreign_kind(&bytes) {
                    Some(kind) => format!(
                        "this is a {kind} checkpoint, not the kind this command reads \
                         (its meta record: {e})"
                    ),
                    None => format!("bad meta record: {e}"),
                },
            )
        })?;
        Ok(NamedTensors {
            path: path.to_path_buf(),
            meta,
            tensors,
        })
    }
}

/// What kind of checkpoint a meta record that did not parse belongs to, when
/// it says: its `kind` field (world models, datasets), or "policy" for a
/// trainer's record (it counts `env_steps`).
fn foreign_kind(meta: &[u8]) -> Option<String> {
    let v: serde_json::Value = serde_json::from_slice(meta).ok()?;
    if let Some(kind) = v.get("kind").and_then(|k| k.as_str()) {
        return Some(kind.replace('_', " "));
    }
    v.get("env_steps").map(|_| "policy".to_string())
}

impl<M> NamedTensors<M> {
    /// Every tensor's name (the `meta` record's included), sorted.
    pub fn names(&self) -> Vec<&str> {
        let mut v: Vec<&str> = self.tensors.keys().map(String::as_str).collect();
        v.sort_unstable();
        v
    }

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
