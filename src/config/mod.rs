//! The machinery every config file kind shares: YAML parsing with `--set
//! key.path=value` overrides applied first, and [`ConfigError`], the one error
//! type whose message names the file, the override or the bad value.
//!
//! The file kinds themselves live with the stage they configure, each with its
//! own loader and validation: `rl::config` (an env plus PPO:
//! `configs/specialist/`; its `env` section is `env::config`, its reward table
//! `env::rewards`) and `world_model::config` (a dataset plus the diffusion
//! world model: `configs/world_model/`). All structs use `deny_unknown_fields`.
//! This module sits below all of them and imports none of them (only the
//! leaf [`crate::seal`], whose seal a run directory's `config.yaml` carries).
//!
//! A trainer config (`rl::config`, `world_model::config`) may be written as
//! another one changed: `base: <file>` and `set: [key.path=value, ...]`, the
//! overrides `--set` would give, applied to the base in order (the file's
//! `--set` arguments after them). See [`parse_inheriting`].
use std::path::{Path, PathBuf};

/// Everything that can go wrong reading a config.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("config {path}: {message}")]
    Parse { path: String, message: String },
    #[error("--set {arg}: {message}")]
    Override { arg: String, message: String },
    #[error(
        "config {path} is corrupt: its SHA-256 does not match the seal on its last line \
         (`# dreampolicy-sha256: ...`, written with the run): a damaged copy or a hand edit. \
         Restore it, pass changes with --set, or accept an edit with \
         `dreampolicy checkpoint seal {path}`",
        path = .path.display()
    )]
    Corrupt { path: PathBuf },
    #[error(
        "config {path} carries no seal (written before run configs were sealed, or by hand): \
         a run directory's config.yaml is trusted only sealed; if you trust it, seal it with \
         `dreampolicy checkpoint seal {path}`",
        path = .path.display()
    )]
    Unsealed { path: PathBuf },
    #[error("config: {0}")]
    Invalid(String),
}

/// Parse YAML `text` into `T` after applying `--set` overrides (no validation);
/// shared by every config file kind.
pub fn parse<T: serde::de::DeserializeOwned>(
    text: &str,
    label: &str,
    overrides: &[String],
) -> Result<T, ConfigError> {
    parse_value(yaml_value(text, label)?, label, overrides)
}

/// The YAML value of a config's text; a syntax error names `label`.
fn yaml_value(text: &str, label: &str) -> Result<serde_yaml::Value, ConfigError> {
    serde_yaml::from_str(text).map_err(|e| ConfigError::Parse {
        path: label.to_string(),
        message: e.to_string(),
    })
}

/// How deep `base:` files may nest before a loop is assumed.
const MAX_BASE_DEPTH: usize = 8;

/// Like [`parse`], for a trainer config that may be another one changed: a
/// file whose top level is `base: <path>` (relative to the working
/// directory, like every path in a config) and `set:` (a list of
/// `key.path=value`, exactly as `--set` takes them, each replacing the value
/// at its path) is its base file's config (itself possibly a `base:` file)
/// with those overrides; nothing else may stand beside them, so that what a
/// derived config changes is always a list of replacements, never a merge of
/// two mappings. `overrides` (the command line's `--set`) come last.
pub fn parse_inheriting<T: serde::de::DeserializeOwned>(
    text: &str,
    label: &str,
    overrides: &[String],
) -> Result<T, ConfigError> {
    let value = resolve_base(text, label, 0)?;
    parse_value(value, label, overrides)
}

/// The YAML value of a config's text with its `base:` chain applied.
fn resolve_base(text: &str, label: &str, depth: usize) -> Result<serde_yaml::Value, ConfigError> {
    let bad = |message: String| ConfigError::Parse {
        path: label.to_string(),
        message,
    };
    let mut value = yaml_value(text, label)?;
    let Some(map) = value.as_mapping_mut() else {
        return Ok(value);
    };
    let Some(base) = map.remove("base") else {
        return Ok(value);
    };
    let base = base
        .as_str()
        .ok_or_else(|| bad("`base:` must be a path (a string)".into()))?
        .to_string();
    let sets = match map.remove("set") {
        None => Vec::new(),
        Some(serde_yaml::Value::Sequence(items)) => items
            .into_iter()
            .map(|v| match v {
                serde_yaml::Value::String(s) => Ok(s),
                _ => Err(bad(
                    "`set:` items must be strings `key.path=value` (quote them)".into(),
                )),
            })
            .collect::<Result<Vec<_>, _>>()?,
        Some(_) => return Err(bad("`set:` must be a list of `key.path=value`".into())),
    };
    if let Some(k) = map.keys().next() {
        let k = k.as_str().unwrap_or("key");
        return Err(bad(format!(
            "a config with `base:` holds only `set:` beside it, found `{k}`: write the change as \
             a `set:` item (`{k}=...`)"
        )));
    }
    if depth >= MAX_BASE_DEPTH {
        return Err(bad(format!(
            "`base:` files nest deeper than {MAX_BASE_DEPTH} (a loop?) at {base}"
        )));
    }
    let path = Path::new(&base);
    let base_text = read(path)?;
    let mut value = resolve_base(&base_text, &path.display().to_string(), depth + 1)?;
    for arg in &sets {
        apply_override(&mut value, arg).map_err(|e| bad(format!("in `set:`: {e}")))?;
    }
    Ok(value)
}

/// [`parse`] from a YAML value (e.g. a config already in memory, serialized).
pub fn parse_value<T: serde::de::DeserializeOwned>(
    mut value: serde_yaml::Value,
    label: &str,
    overrides: &[String],
) -> Result<T, ConfigError> {
    for arg in overrides {
        apply_override(&mut value, arg)?;
    }
    serde_yaml::from_value(value).map_err(|e| ConfigError::Parse {
        path: label.to_string(),
        message: e.to_string(),
    })
}

/// Read a file's text for a loader. A file that ends in a seal line (a run
/// directory's `config.yaml`, [`crate::seal::seal_yaml`]) must match it; a file
/// without one (a config a person wrote) is read as it is.
pub fn read(path: &Path) -> Result<String, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    if crate::seal::check_yaml(&text) == Err(crate::seal::SealError::Mismatch) {
        return Err(ConfigError::Corrupt {
            path: path.to_path_buf(),
        });
    }
    Ok(text)
}

/// Check that the file at `path` carries an intact seal: a run directory's
/// `config.yaml`, which `--resume` trusts, must (a copy cut short loses its
/// seal line and could still parse).
pub fn require_seal(path: &Path) -> Result<(), ConfigError> {
    let text = read(path)?;
    match crate::seal::check_yaml(&text) {
        Ok(()) => Ok(()),
        Err(crate::seal::SealError::Missing) => Err(ConfigError::Unsealed {
            path: path.to_path_buf(),
        }),
        Err(_) => Err(ConfigError::Corrupt {
            path: path.to_path_buf(),
        }),
    }
}

/// `a.b.c=value`: set a nested key (created if missing); the value is parsed as YAML.
pub fn apply_override(root: &mut serde_yaml::Value, arg: &str) -> Result<(), ConfigError> {
    let err = |message: &str| ConfigError::Override {
        arg: arg.to_string(),
        message: message.to_string(),
    };
    let (key, raw) = arg
        .split_once('=')
        .ok_or_else(|| err("expected key.path=value"))?;
    let value: serde_yaml::Value =
        serde_yaml::from_str(raw).map_err(|e| err(&format!("value is not YAML: {e}")))?;
    let mut node = root;
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err("empty key segment"));
    }
    for (i, part) in parts.iter().enumerate() {
        let map = node
            .as_mapping_mut()
            .ok_or_else(|| err(&format!("'{}' is not a mapping", parts[..i].join("."))))?;
        let k = serde_yaml::Value::String(part.to_string());
        if i + 1 == parts.len() {
            map.insert(k, value);
            return Ok(());
        }
        node = map
            .entry(k)
            .or_insert_with(|| serde_yaml::Value::Mapping(Default::default()));
    }
    unreachable!("the loop returns at the last segment")
}
