//! The serde records of `eval world-model`'s report (see the parent module for
//! what each measurement is).
use std::collections::BTreeMap;

use serde::Serialize;

use crate::world_model::config::{SamplerKind, SamplingConfig};

/// The validation side of the split, as read.
#[derive(Debug, Clone, Serialize)]
pub struct ValidationInfo {
    pub val_fraction: f64,
    pub split_seed: u64,
    pub episodes: usize,
    /// Runs of consecutive frames (an episode cut by a shard or a gap is several).
    pub segments: usize,
    pub frames: u64,
    pub longest_segment: usize,
    /// Kinds whose `max_frames_per_kind` budget was reached.
    pub capped_kinds: Vec<String>,
}

/// One-call error of one sampler or guidance.
#[derive(Debug, Clone, Serialize)]
pub struct OneCall {
    /// Over all `H` steps (normalized).
    pub rmse: f64,
    /// At step `H` (normalized).
    pub rmse_last: f64,
    /// Joint positions over all `H` steps (raw, rad); null for a non-G1 state.
    pub joint_pos_rmse: Option<f64>,
}

/// Guidance `omega`: error and how much the terrain moves the prediction.
#[derive(Debug, Clone, Serialize)]
pub struct GuidanceScore {
    pub guidance: f64,
    #[serde(flatten)]
    pub error: OneCall,
    /// RMS between predictions with real and shuffled scandots, same noise.
    pub terrain_distance: f64,
}

/// A sampler: error and wall time.
#[derive(Debug, Clone, Serialize)]
pub struct SamplerScore {
    pub sampler: SamplerKind,
    /// Denoiser evaluations per call (each of `2B` rows when guidance is not 0 or 1).
    pub steps: usize,
    pub guidance: f64,
    #[serde(flatten)]
    pub error: OneCall,
    /// One call on all the windows (ms).
    pub batch_ms: f64,
    /// One call on one window, best of 3 (ms).
    pub batch1_ms: f64,
}

/// Real against shuffled scandots, for the windows of one terrain kind.
#[derive(Debug, Clone, Serialize)]
pub struct Sensitivity {
    pub windows: usize,
    /// Where the shuffled scandots come from: `other kinds` or `same kind`.
    pub donor: String,
    /// RMS difference of the real and shuffled scandots (raw, m).
    pub scan_distance_m: f64,
    /// RMS between the two predictions (same noise, normalized).
    pub distance: f64,
    /// RMS between two predictions with the real scandots and different noise.
    pub seed_spread: f64,
    /// `distance / seed_spread` (null when the spread is 0).
    pub ratio: Option<f64>,
    pub rmse_real: f64,
    pub rmse_shuffled: f64,
    /// The anchor state held over the horizon, on these windows (normalized).
    pub hold_rmse: f64,
    /// One call with the real scandots at each guidance of `guidance`
    /// (`"0"`, `"1"`, `"5"`), the config's sampler, on these windows.
    pub rmse_by_guidance: BTreeMap<String, f64>,
}

/// Errors of an autoregressive rollout against the real frames.
#[derive(Debug, Clone, Serialize)]
pub struct DriftMetrics {
    /// At the last frame (normalized).
    pub rmse_final: f64,
    /// Over all frames (normalized).
    pub rmse_mean: f64,
    /// Joint positions at the last frame (raw, rad).
    pub joint_pos_rmse_final: Option<f64>,
    /// Baseline: the anchor state held, at the last frame and over all frames.
    pub hold_rmse_final: f64,
    pub hold_rmse_mean: f64,
    /// Baseline: the dataset's mean state at every frame (over all frames).
    pub mean_state_rmse: f64,
    /// RMSE over the frames of each call, in order (normalized).
    pub per_call_rmse: Vec<f64>,
}

/// One rollout length.
#[derive(Debug, Clone, Serialize)]
pub struct Drift {
    pub frames: usize,
    /// Validation segments with at least `K + frames` frames.
    pub eligible_segments: usize,
    pub windows: usize,
    pub metrics: Option<DriftMetrics>,
    /// Why `metrics` is null.
    pub reason: Option<String>,
}

/// Everything `eval world-model` measures.
#[derive(Debug, Clone, Serialize)]
pub struct WmEvalReport {
    pub checkpoint: String,
    /// Gradient steps of the checkpoint.
    pub iteration: usize,
    pub dataset: String,
    pub history: usize,
    pub horizon: usize,
    pub diffusion_steps: usize,
    pub seed: u64,
    pub torch_threads: i64,
    pub validation: ValidationInfo,
    /// Windows of the one-call measurements, and per terrain kind.
    pub windows: usize,
    pub windows_per_kind: BTreeMap<String, usize>,
    /// The checkpoint's sampling config: the default sampler.
    pub sampling: SamplingConfig,
    /// One-call RMSE at `h = 1..=H` (normalized).
    pub horizon_rmse: Vec<f64>,
    /// The same per state block (raw units; empty for a non-G1 state).
    pub horizon_rmse_raw: BTreeMap<String, Vec<f64>>,
    /// Baseline: the anchor state held (normalized).
    pub hold_rmse: Vec<f64>,
    /// The same per state block (raw units).
    pub hold_rmse_raw: BTreeMap<String, Vec<f64>>,
    /// Baseline: the dataset's mean state at every step (normalized, over all `H`).
    pub mean_state_rmse: f64,
    /// Keyed by `omega` (`"0"`, `"1"`, `"5"`).
    pub guidance: BTreeMap<String, GuidanceScore>,
    /// Keyed `ddpm`, `ddim1`, `ddim2`, `ddim5`, `ddim10`, `ddim20`.
    pub samplers: BTreeMap<String, SamplerScore>,
    /// Keyed by terrain kind.
    pub terrain_sensitivity: BTreeMap<String, Sensitivity>,
    /// Keyed by frames (`"50"`, `"250"`).
    pub drift: BTreeMap<String, Drift>,
    /// What steers the plan's turning: the yaw-rate command in the history or
    /// the yaw rate the history measured (G1 states only).
    pub yaw_response: Option<YawResponse>,
    /// How the terrain of shuffles and rollouts was chosen.
    pub notes: Vec<String>,
    pub plot: Option<String>,
    pub wall_time_s: f64,
}

/// The plan's yaw rate when one input of the history is set to each of a few
/// yaw rates in every history state (the rest of each window as it was, the
/// same noise): the command's yaw rate, or the measured one (gyro z). Rates in
/// rad/s, read through the default observation scales.
#[derive(Debug, Clone, Serialize)]
pub struct YawResponse {
    pub windows: usize,
    /// The yaw rates written (rad/s).
    pub set_to: Vec<f64>,
    /// Mean predicted yaw rate over the horizon with the command set to each.
    pub predicted_by_command: Vec<f64>,
    /// The same with the measured yaw rate set to each (the command as it was).
    pub predicted_by_measured: Vec<f64>,
    /// Least-squares slope of predicted on set (1: the plan turns at the rate
    /// written; 0: it ignores that input).
    pub command_slope: f64,
    pub measured_slope: f64,
    /// The windows as they are: their mean commanded yaw rate in the history,
    /// the mean real and predicted yaw rate over the horizon, and the slope of
    /// the real yaw rate on the commanded one across windows (how closely the
    /// dataset's robots follow the command).
    pub history_command: f64,
    /// Spread (std over windows) of the windows' commanded and real yaw rates.
    pub history_command_std: f64,
    pub real_std: f64,
    pub real: f64,
    pub predicted: f64,
    pub dataset_slope: f64,
}
