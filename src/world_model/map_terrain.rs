//! A [`TerrainSource`] that reads each call's scandots from a terrain (a
//! [`crate::terrain::TerrainMap`], a plane, any height function) along the path
//! the rollout itself predicts.
//!
//! The 98-float state holds neither position nor linear velocity, so the path is
//! integrated from what it does hold, one control period `dt` per predicted
//! frame: the pelvis moves at that frame's commanded planar velocity `[vx, vy]`
//! in the current heading (the command block, unscaled: the policy tracks its
//! command, and the state says nothing else about speed), then the heading turns
//! at the frame's yaw rate (the pelvis-frame `z` angular velocity, unscaled,
//! which is the yaw rate while the pelvis is near upright). The pelvis keeps its
//! starting height above the ground under it. A call's scandots are those the
//! env writes at that pose (`obs::scan_height`, the config's scale and clip),
//! without noise.
use tch::{Device, Kind, Tensor};

use super::rollout::TerrainSource;
use super::WmError;
use crate::env::config::ObservationConfig;
use crate::env::obs::{scan_row, ANG_VEL, COMMAND, OBS_DIM, SCAN_DIM};

/// A planar pose: world `x`, `y` (m) and yaw (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
}

/// Scandots from `ground` along each batch row's predicted path.
pub struct MapTerrain<G> {
    ground: G,
    poses: Vec<Pose>,
    /// Pelvis height above the ground, per row, kept from the start.
    heights: Vec<f64>,
    obs: ObservationConfig,
    dt: f64,
}

impl<G: Fn(f64, f64) -> f64> MapTerrain<G> {
    /// `starts`: each batch row's pelvis position (world, m) and yaw at the
    /// anchor, the newest history state; `obs`: the observation config the
    /// states were written with (scales, scandot clip); `dt`: the control
    /// period between two states (s).
    pub fn new(ground: G, starts: &[([f64; 3], f64)], obs: &ObservationConfig, dt: f64) -> Self {
        let poses = starts
            .iter()
            .map(|&(p, yaw)| Pose {
                x: p[0],
                y: p[1],
                yaw,
            })
            .collect();
        let heights = starts
            .iter()
            .map(|&(p, _)| p[2] - ground(p[0], p[1]))
            .collect();
        MapTerrain {
            ground,
            poses,
            heights,
            obs: obs.clone(),
            dt,
        }
    }

    /// Where each row stands now.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// Frames of `t` (`[B, frames, 98]`, one row per pose), or an error naming `what`.
    fn frames(&self, t: &Tensor, what: &str) -> Result<usize, WmError> {
        let sz = t.size();
        if sz.len() != 3 || sz[0] != self.poses.len() as i64 || sz[2] != OBS_DIM as i64 {
            return Err(WmError::Invalid(format!(
                "map terrain: {what} must be [{}, frames, {OBS_DIM}], got {sz:?}",
                self.poses.len()
            )));
        }
        Ok(sz[1] as usize)
    }
}

impl<G: Fn(f64, f64) -> f64> TerrainSource for MapTerrain<G> {
    fn scandots(&mut self, states: &Tensor, _call: usize) -> Result<Tensor, WmError> {
        self.frames(states, "the history")?;
        let (clip, scale) = (self.obs.scan_clip, self.obs.scales.scan);
        let mut out = vec![0f32; self.poses.len() * SCAN_DIM];
        for (b, (pose, h)) in self.poses.iter().zip(&self.heights).enumerate() {
            let base = [pose.x, pose.y, (self.ground)(pose.x, pose.y) + h];
            let yaw = pose.yaw.sin_cos();
            let row = &mut out[b * SCAN_DIM..(b + 1) * SCAN_DIM];
            scan_row(
                &self.ground,
                &self.obs.scan_grid,
                base,
                yaw,
                clip,
                scale,
                row,
            );
        }
        Ok(Tensor::from_slice(&out)
            .view([self.poses.len() as i64, SCAN_DIM as i64])
            .to_device(states.device()))
    }

    fn advance(&mut self, predicted: &Tensor) -> Result<(), WmError> {
        let frames = self.frames(predicted, "the prediction")?;
        let p = predicted
            .to_device(Device::Cpu)
            .to_kind(Kind::Float)
            .contiguous();
        let v = Vec::<f32>::try_from(p.flatten(0, -1))?;
        let sc = &self.obs.scales;
        for (b, pose) in self.poses.iter_mut().enumerate() {
            for f in 0..frames {
                let s = &v[(b * frames + f) * OBS_DIM..][..OBS_DIM];
                let vx = s[COMMAND.start] as f64 / sc.commands[0];
                let vy = s[COMMAND.start + 1] as f64 / sc.commands[1];
                let wz = s[ANG_VEL.start + 2] as f64 / sc.ang_vel;
                let (sy, cy) = pose.yaw.sin_cos();
                pose.x += (cy * vx - sy * vy) * self.dt;
                pose.y += (sy * vx + cy * vy) * self.dt;
                pose.yaw += wz * self.dt;
            }
        }
        Ok(())
    }
}
