//! `dreampolicy checkpoint verify|seal|average|strip`: the integrity seals of the files a
//! later run trusts. By kind: a checkpoint (`*.pt`: a SHA-256 in the archive's
//! zip comment, `dreampolicy::checkpoint`), a run's `config.yaml` (a seal line,
//! `dreampolicy::seal`), a dataset's `stats.json` (a `"sha256"` first key), an
//! export bundle's directory (`deploy.yaml` with the digests of its policy files).
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use dreampolicy::seal::{self, SealError};

#[derive(Subcommand)]
pub enum CheckpointCommand {
    /// Check the seals of checkpoints (PPO and world model), run configs
    /// (`config.yaml`), dataset statistics (`stats.json`) and bundle
    /// directories: one `ok` or `BAD` line per file; exits non-zero naming the
    /// bad ones.
    Verify {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Seal files written before they were sealed, or a run config or bundle
    /// you edited on purpose. Only for files you trust: nothing can tell whether
    /// their bytes are the ones that were saved. A sealed checkpoint is refused.
    Seal {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Write the mean of PPO checkpoints of one network layout (weights and
    /// observation normalizers, element-wise; stochastic weight averaging).
    /// The record, optimizer state and env state are the last file's, so the
    /// result evaluates, plays and resumes like it; its `averaged_from` (and
    /// every eval report of it) names the files.
    Average {
        /// The file to write (a sealed checkpoint).
        #[arg(long)]
        out: PathBuf,
        #[arg(required = true, num_args = 2..)]
        files: Vec<PathBuf>,
    },
    /// Write the inference copy of a finished world model: the EMA denoiser
    /// and the normalization, without the live model and Adam's moments (a
    /// quarter of the size). It plans, evaluates and exports as its source;
    /// training refuses to resume from it.
    Strip {
        /// The file to write (a sealed checkpoint).
        #[arg(long)]
        out: PathBuf,
        /// A world-model checkpoint.
        file: PathBuf,
        /// When FILE is already an inference copy, copy it to --out as it
        /// is (its seal intact) instead of refusing: what a script packaging
        /// finished and already-stripped runs alike wants.
        #[arg(long)]
        if_needed: bool,
    },
}

/// What kind of sealed file a path is.
enum Kind {
    Checkpoint,
    Yaml,
    Json,
    Bundle,
}

fn kind(path: &Path) -> Kind {
    if path.is_dir() {
        return Kind::Bundle;
    }
    match path.extension().and_then(|e| e.to_str()) {
        Some("yaml" | "yml") => Kind::Yaml,
        Some("json") => Kind::Json,
        _ => Kind::Checkpoint,
    }
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))
}

fn verify_one(path: &Path) -> Result<()> {
    let named = |e: SealError| anyhow::anyhow!("{} {e}", path.display());
    match kind(path) {
        Kind::Checkpoint => dreampolicy::checkpoint::verify_file(path)?,
        Kind::Yaml => seal::check_yaml(&read_text(path)?).map_err(named)?,
        Kind::Json => seal::check_json(&read_text(path)?).map_err(named)?,
        Kind::Bundle => {
            dreampolicy::deploy::Bundle::read(path)?;
        }
    }
    Ok(())
}

fn seal_one(path: &Path) -> Result<()> {
    match kind(path) {
        Kind::Checkpoint => dreampolicy::checkpoint::seal_file(path)?,
        Kind::Yaml => {
            let text = read_text(path)?;
            serde_yaml::from_str::<serde_yaml::Value>(&text)
                .with_context(|| format!("{} is not YAML", path.display()))?;
            dreampolicy::run::write_atomic(path, seal::seal_yaml(&text).as_bytes())
                .map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))?;
        }
        Kind::Json => {
            let text = read_text(path)?;
            let mut value: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{} is not JSON", path.display()))?;
            if seal::check_json(&text).is_ok() {
                bail!("{} {}", path.display(), SealError::AlreadySealed);
            }
            if let Some(o) = value.as_object_mut() {
                o.remove("sha256"); // a damaged seal's key
            }
            let pretty = serde_json::to_string_pretty(&value)?;
            let sealed =
                seal::seal_json(&pretty).map_err(|e| anyhow::anyhow!("{} {e}", path.display()))?;
            dreampolicy::run::write_atomic(path, sealed.as_bytes())
                .map_err(|(p, e)| anyhow::anyhow!("{}: {e}", p.display()))?;
        }
        Kind::Bundle => dreampolicy::deploy::Bundle::seal_dir(path)?,
    }
    Ok(())
}

pub fn run(which: CheckpointCommand) -> Result<()> {
    match which {
        CheckpointCommand::Verify { files } => {
            let mut bad = Vec::new();
            for f in &files {
                match verify_one(f) {
                    Ok(()) => println!("ok   {}", f.display()),
                    Err(e) => {
                        println!("BAD  {e}");
                        bad.push(f.display().to_string());
                    }
                }
            }
            if !bad.is_empty() {
                bail!(
                    "{} of {} files failed: {}",
                    bad.len(),
                    files.len(),
                    bad.join(", ")
                );
            }
            Ok(())
        }
        CheckpointCommand::Average { out, files } => {
            if files.contains(&out) {
                bail!("--out {} is one of the files to average", out.display());
            }
            let meta = dreampolicy::rl::checkpoint::average(&files, &out)?;
            println!(
                "wrote {}: the mean of {} checkpoints (record of iteration {}, {} env-steps)",
                out.display(),
                files.len(),
                meta.iteration,
                meta.env_steps
            );
            Ok(())
        }
        CheckpointCommand::Strip {
            out,
            file,
            if_needed,
        } => {
            if out == file {
                bail!(
                    "--out {} is the file to strip: write the copy elsewhere",
                    out.display()
                );
            }
            let ck = dreampolicy::world_model::checkpoint::WmCheckpoint::read(&file)?;
            if ck.meta().inference_only {
                if !if_needed {
                    bail!(
                        "{} is already an inference copy (--if-needed copies it as it is)",
                        file.display()
                    );
                }
                std::fs::copy(&file, &out).with_context(|| {
                    format!("cannot copy {} to {}", file.display(), out.display())
                })?;
                println!(
                    "copied {} to {}: already an inference copy (step {})",
                    file.display(),
                    out.display(),
                    ck.meta().iteration
                );
                return Ok(());
            }
            ck.write_inference_copy(&out)?;
            let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
            println!(
                "wrote {}: the EMA weights of {} (step {}), {:.1} MB of {:.1} MB",
                out.display(),
                file.display(),
                ck.meta().iteration,
                size(&out) as f64 / 1e6,
                size(&file) as f64 / 1e6
            );
            Ok(())
        }
        CheckpointCommand::Seal { files } => {
            for f in &files {
                seal_one(f)?;
                eprintln!(
                    "warning: sealed {} as it is; its contents were not checked against anything",
                    f.display()
                );
            }
            Ok(())
        }
    }
}
