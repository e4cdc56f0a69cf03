//! Integrity seals for the text files a later run trusts: a SHA-256 written
//! inside the file, in a form its other readers ignore, and checked at every
//! load.
//!
//! * YAML (a run directory's `config.yaml`, a bundle's `deploy.yaml`): the last
//!   line is the comment `# dreampolicy-sha256: <hex>`, the digest of every byte
//!   before it ([`seal_yaml`], [`check_yaml`]).
//! * JSON (a dataset's `stats.json`): the first key is `"sha256": "<hex>"` on
//!   its own line, the digest of the file without that line ([`seal_json`],
//!   [`check_json`]); readers that do not know it see one more key.
//! * Any file a sealed file names (a bundle's `policy.pt`, `policy.npz`): its
//!   digest is written in the sealed file ([`file_sha256`]).
//!
//! Checkpoints (libtorch zip archives) carry their seal in the zip comment
//! (`crate::checkpoint`); [`SealError`] is shared by both. This module imports
//! nothing of the crate, so the config layer can use it.
use std::path::Path;

use sha2::{Digest, Sha256};

/// What is wrong with a file's seal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SealError {
    /// No seal: written before files were sealed, or not by dreampolicy.
    Missing,
    /// The digest does not match the bytes: the file changed after it was written.
    Mismatch,
    /// Not a zip archive as libtorch writes one (no end record at its end).
    NotAnArchive,
    /// Sealing a file that already carries a seal.
    AlreadySealed,
}

impl std::fmt::Display for SealError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SealError::Missing => {
                "has no integrity seal (written before files were sealed, or not by \
                 dreampolicy); if you trust it, seal it with `dreampolicy checkpoint seal FILE`"
            }
            SealError::Mismatch => {
                "is corrupt: its SHA-256 does not match the seal written with it (the file \
                 changed after it was saved: a damaged copy or disk, or a hand edit); \
                 restore it from its source"
            }
            SealError::NotAnArchive => {
                "is damaged or not a checkpoint: it does not end as a sealed libtorch archive \
                 does (cut short, or another kind of file)"
            }
            SealError::AlreadySealed => "is already sealed",
        })
    }
}

impl std::error::Error for SealError {}

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of `bytes`, as 64 hex digits.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// SHA-256 of the file at `path`, as 64 hex digits.
pub fn file_sha256(path: &Path) -> std::io::Result<String> {
    Ok(sha256_hex(&std::fs::read(path)?))
}

/// The comment that ends a sealed YAML file.
pub const YAML_SEAL_PREFIX: &str = "# dreampolicy-sha256: ";
/// The first key of a sealed JSON file.
const JSON_SEAL_KEY: &str = "  \"sha256\": \"";

fn is_digest(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
}

/// `text` (a YAML document) with its seal line appended; a missing final
/// newline is added first. A text that already ends in a seal is resealed.
pub fn seal_yaml(text: &str) -> String {
    let mut body = match split_yaml(text) {
        Some((body, _)) => body.to_string(),
        None => text.to_string(),
    };
    if !body.is_empty() && !body.ends_with('\n') {
        body.push('\n');
    }
    let digest = sha256_hex(body.as_bytes());
    format!("{body}{YAML_SEAL_PREFIX}{digest}\n")
}

/// The body before a seal line and the line's digest field, when the last
/// line of `text` is one (possibly damaged).
fn split_yaml(text: &str) -> Option<(&str, &str)> {
    let trimmed = text.strip_suffix('\n').unwrap_or(text);
    let start = trimmed.rfind('\n').map_or(0, |i| i + 1);
    let last = &trimmed[start..];
    last.strip_prefix(YAML_SEAL_PREFIX)
        .map(|digest| (&text[..start], digest))
}

/// Check a YAML text's seal line: `Ok` when it matches the bytes before it,
/// [`SealError::Missing`] when the last line is not a seal (a file a person
/// wrote), [`SealError::Mismatch`] when it is and does not match. A seal line
/// that survives anywhere but last (the file was cut or appended to) is a
/// mismatch too.
pub fn check_yaml(text: &str) -> Result<(), SealError> {
    match split_yaml(text) {
        Some((body, digest)) => {
            if is_digest(digest) && sha256_hex(body.as_bytes()) == digest {
                Ok(())
            } else {
                Err(SealError::Mismatch)
            }
        }
        None if text.contains(YAML_SEAL_PREFIX.trim_end()) => Err(SealError::Mismatch),
        None => Err(SealError::Missing),
    }
}

/// `text` (pretty JSON of an object, as `serde_json::to_string_pretty` writes
/// it: `{` then one key per line, two spaces in) with `"sha256"` as its first
/// key: the digest of `text` itself.
pub fn seal_json(text: &str) -> Result<String, SealError> {
    let rest = text.strip_prefix("{\n").ok_or(SealError::NotAnArchive)?;
    if rest.starts_with(JSON_SEAL_KEY) {
        return Err(SealError::AlreadySealed);
    }
    let digest = sha256_hex(text.as_bytes());
    Ok(format!("{{\n{JSON_SEAL_KEY}{digest}\",\n{rest}"))
}

/// Check a JSON text sealed by [`seal_json`]: [`SealError::Missing`] when its
/// first key is not the seal, [`SealError::Mismatch`] when the digest does not
/// match the text without it.
pub fn check_json(text: &str) -> Result<(), SealError> {
    // no seal where it belongs: a damaged one if its key survives elsewhere
    let Some(line) = text
        .strip_prefix("{\n")
        .and_then(|rest| rest.strip_prefix(JSON_SEAL_KEY))
    else {
        return Err(if text.contains("\"sha256\"") {
            SealError::Mismatch
        } else {
            SealError::Missing
        });
    };
    let (digest, tail) = line.split_at(line.find('"').unwrap_or(line.len()));
    let Some(body) = tail.strip_prefix("\",\n") else {
        return Err(SealError::Mismatch);
    };
    if is_digest(digest) && sha256_hex(format!("{{\n{body}").as_bytes()) == digest {
        Ok(())
    } else {
        Err(SealError::Mismatch)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_round_trip_and_damage() {
        let text = "a: 1\nb: [2, 3]\n";
        let sealed = seal_yaml(text);
        assert!(sealed.starts_with(text));
        assert_eq!(check_yaml(&sealed), Ok(()));
        assert_eq!(seal_yaml(&sealed), sealed);
        assert_eq!(check_yaml(text), Err(SealError::Missing));
        let flipped = sealed.replacen("1", "7", 1);
        assert_eq!(check_yaml(&flipped), Err(SealError::Mismatch));
        let appended = format!("{sealed}c: 4\n");
        assert_eq!(check_yaml(&appended), Err(SealError::Mismatch));
        assert_eq!(check_yaml(&seal_yaml("a: 1")), Ok(()));
    }

    #[test]
    fn json_round_trip_and_damage() {
        let v = serde_json::json!({"frames": 3, "mean": [1.0, 2.5]});
        let text = serde_json::to_string_pretty(&v).unwrap();
        let sealed = seal_json(&text).unwrap();
        assert_eq!(check_json(&sealed), Ok(()));
        let back: serde_json::Value = serde_json::from_str(&sealed).unwrap();
        assert_eq!(back["frames"], 3);
        assert_eq!(seal_json(&sealed), Err(SealError::AlreadySealed));
        assert_eq!(check_json(&text), Err(SealError::Missing));
        let flipped = sealed.replacen("2.5", "2.6", 1);
        assert_eq!(check_json(&flipped), Err(SealError::Mismatch));
    }
}
