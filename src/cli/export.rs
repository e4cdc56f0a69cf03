//! `dreampolicy export`: a checkpoint as a deployment bundle (TorchScript policy,
//! NumPy arrays and `deploy.yaml`; with `--format onnx` the ONNX graph too), or
//! with `--file-only` the policy file alone in the chosen format. A unified
//! policy's bundle holds the policy, the world model's denoiser and
//! `unified.json` (`dreampolicy::unified::export`).
use std::path::PathBuf;

use anyhow::{Context, Result};

/// The policy file formats.
#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum)]
pub enum Format {
    /// TorchScript (`policy.pt`), for libtorch and `torch.jit.load`
    Torchscript,
    /// ONNX opset 17 (`policy.onnx`), for onnxruntime, tract and robot-side
    /// runtimes; a bundle keeps the TorchScript file as well
    Onnx,
}

/// Arguments of `export`.
#[derive(clap::Args)]
pub struct ExportArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    /// The bundle directory (created): `policy.pt`, `policy.npz`, `deploy.yaml`
    /// (and `policy.onnx` with --format onnx); with --file-only, the policy
    /// file to write
    #[arg(long)]
    out: PathBuf,
    /// Policy file format
    #[arg(long, value_enum, default_value = "torchscript")]
    format: Format,
    /// Write only the policy file in --format (no bundle)
    #[arg(long)]
    file_only: bool,
    /// The same as --file-only --format torchscript (kept for scripts)
    #[arg(long, conflicts_with_all = ["file_only", "format"])]
    torchscript_only: bool,
}

pub fn run(a: ExportArgs) -> Result<()> {
    let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&a.checkpoint)?;
    let file_only = a.file_only || a.torchscript_only;
    if ck.config()?.task == dreampolicy::rl::config::TaskKind::Unified {
        if file_only {
            anyhow::bail!(
                "{}: a unified policy needs its world model's plan; export it as a bundle \
                 (drop --file-only): policy.pt, denoiser.pt and unified.json",
                a.checkpoint.display()
            );
        }
        if a.format == Format::Onnx {
            anyhow::bail!(
                "{}: ONNX export covers specialist and walker policies; a unified policy's \
                 bundle is TorchScript (drop --format onnx)",
                a.checkpoint.display()
            );
        }
        let info = dreampolicy::unified::export::write_bundle(&ck, &a.out).context("export")?;
        println!("{}", serde_json::to_string(&info)?);
        return Ok(());
    }
    let json = match (file_only, a.format) {
        (true, Format::Torchscript) => {
            serde_json::to_string(&dreampolicy::rl::export::export(&ck, &a.out).context("export")?)?
        }
        (true, Format::Onnx) => serde_json::to_string(
            &dreampolicy::rl::onnx::export_onnx(&ck, &a.out).context("export")?,
        )?,
        (false, f) => serde_json::to_string(
            &dreampolicy::deploy::write_bundle(&ck, &a.out, f == Format::Onnx).context("export")?,
        )?,
    };
    println!("{json}");
    Ok(())
}
