//! The trajectories PNG of `eval world-model --plot`: for up to three validation
//! windows (of different terrain kinds when there are several), the left/right
//! hip pitch and knee positions (raw, rad): the real frames over the history and
//! the next 50 steps, the one-call prediction (`H` steps) and a 50-step
//! autoregressive rollout, x = steps after the anchor.
use std::path::Path;

use tch::Tensor;

use super::episodes::{Pick, ValidationSet};
use super::{roll_out, Ctx};
use crate::data::sample::splitmix64;
use crate::env::obs;
use crate::plot::{plot_series, SeriesPanel};
use crate::robot::JOINT_NAMES;
use crate::world_model::config::{SamplerKind, SamplingConfig, WorldModelConfig};
use crate::world_model::WmError;

/// Windows drawn.
const WINDOWS: usize = 3;
/// Frames of the rollout drawn (when the episodes are long enough).
const ROLLOUT: usize = 50;
/// Joints drawn.
const JOINTS: [&str; 4] = [
    "left_hip_pitch_joint",
    "left_knee_joint",
    "right_hip_pitch_joint",
    "right_knee_joint",
];

/// Up to [`WINDOWS`] of `picks` (indices) with `future` real frames after the
/// anchor, different kinds first.
fn choose(val: &ValidationSet, picks: &[Pick], future: usize) -> Vec<usize> {
    let fits = |i: &usize| {
        let p = picks[*i];
        val.segments[p.segment].len(val.dims) > p.anchor + future
    };
    let mut out: Vec<usize> = Vec::new();
    for i in (0..picks.len()).filter(fits) {
        let kind = val.segments[picks[i].segment].kind;
        if out.len() < WINDOWS
            && !out
                .iter()
                .any(|&j| val.segments[picks[j].segment].kind == kind)
        {
            out.push(i);
        }
    }
    for i in (0..picks.len()).filter(fits) {
        if out.len() < WINDOWS && !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
pub(super) fn draw(
    ctx: &Ctx,
    val: &ValidationSet,
    picks: &[Pick],
    one_call: &Tensor,
    sc: &SamplingConfig,
    seed: u64,
    cfg: &WorldModelConfig,
    checkpoint: &Path,
    out: &Path,
) -> Result<(), WmError> {
    let (k, h) = (ctx.wm.history(), ctx.wm.horizon());
    let mut future = ROLLOUT.max(h);
    let mut chosen = choose(val, picks, future);
    if chosen.is_empty() {
        future = h;
        chosen = choose(val, picks, future);
    }
    let sel: Vec<Pick> = chosen.iter().map(|&i| picks[i]).collect();
    let (real, roll) = if future > h {
        let (r, p) = roll_out(ctx, val, &sel, future, sc, splitmix64(seed ^ 0x77))?;
        (r, Some(p))
    } else {
        (val.states(&sel, k, future), None)
    };
    let idx: Vec<i64> = chosen.iter().map(|&i| i as i64).collect();
    let one = one_call.index_select(0, &Tensor::from_slice(&idx).to_device(one_call.device()));
    let dims: Vec<(String, usize)> = if ctx.g1 {
        JOINTS
            .iter()
            .map(|n| {
                let j = JOINT_NAMES.iter().position(|m| m == n).expect("a G1 joint");
                (
                    n.trim_end_matches("_joint").to_string(),
                    obs::DOF_POS.start + j,
                )
            })
            .collect()
    } else {
        (0..4.min(val.dims.state))
            .map(|i| (format!("state[{i}]"), i))
            .collect()
    };
    let x: Vec<f64> = (0..k + future)
        .map(|r| r as f64 - (k as f64 - 1.0))
        .collect();
    let value =
        |t: &Tensor, b: usize, r: usize, d: usize| t.double_value(&[b as i64, r as i64, d as i64]);
    let mut panels = Vec::new();
    for (name, d) in &dims {
        for (b, p) in sel.iter().enumerate() {
            let seg = &val.segments[p.segment];
            let real_line: Vec<f64> = (0..k + future).map(|r| value(&real, b, r, *d)).collect();
            let anchor = real_line[k - 1];
            let predicted = |t: &Tensor, len: usize| -> Vec<f64> {
                (0..k + future)
                    .map(|r| match r {
                        r if r + 1 < k => f64::NAN,
                        r if r + 1 == k => anchor,
                        r if r - k < len => value(t, b, r - k, *d),
                        _ => f64::NAN,
                    })
                    .collect()
            };
            let mut lines = vec![
                ("real".to_string(), real_line.clone()),
                (format!("one call (H = {h})"), predicted(&one, h)),
            ];
            if let Some(r) = &roll {
                lines.push((format!("rollout ({future} steps)"), predicted(r, future)));
            }
            panels.push(SeriesPanel {
                title: format!(
                    "{name}: {} ep {:x} step {}",
                    seg.kind.name(),
                    seg.episode,
                    seg.first_step as usize + p.anchor
                ),
                x_label: "steps after the anchor (0.02 s)".into(),
                x: x.clone(),
                lines,
            });
        }
    }
    let sampler = match sc.sampler {
        SamplerKind::Ddpm => format!("DDPM {}", cfg.diffusion.steps),
        SamplerKind::Ddim => format!("DDIM {}", sc.ddim_steps),
    };
    let title = format!(
        "{}: real vs predicted joint positions (rad), {sampler}, guidance {}",
        checkpoint.display(),
        sc.guidance
    );
    Ok(plot_series(out, &title, &panels)?)
}
