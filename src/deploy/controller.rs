//! A controller that runs a bundle's policy from what a robot measures (the
//! pelvis IMU's quaternion and gyro, the joint encoders) and a command, with no
//! access to the training env: every rule it follows is read from `deploy.yaml`.
use std::f64::consts::PI;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{CModule, Kind, Tensor};

use super::bundle::{Bundle, ObsField};
use super::DeployError;
pub use crate::sim::{quat_to_mat, wrap_angle};

/// One control step's measurements.
#[derive(Debug, Clone)]
pub struct Sensors {
    /// Pelvis orientation, `(w, x, y, z)`, world frame.
    pub quat: [f64; 4],
    /// Pelvis angular velocity in the pelvis frame (rad/s).
    pub gyro: [f64; 3],
    /// Joint positions and velocities in the bundle's joint order.
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
}

/// Yaw of a quaternion `(w, x, y, z)`: `atan2(R[1][0], R[0][0])`.
pub fn yaw_of(q: [f64; 4]) -> f64 {
    let r = quat_to_mat(q);
    r[3].atan2(r[0])
}

/// The bundle's policy with its history, last action and gait clock.
pub struct Controller {
    pub bundle: Bundle,
    module: CModule,
    history: Vec<f32>,
    last_action: Vec<f32>,
    steps: u64,
    started: bool,
    noise: Option<ChaCha8Rng>,
}

impl Controller {
    /// Load the bundle in `dir`. `noise_seed`: add the training observation noise
    /// (as `eval` and `play` do) from this seed; `None`: clean observations.
    pub fn load(dir: &Path, noise_seed: Option<u64>) -> Result<Controller, DeployError> {
        let bundle = Bundle::read(dir)?;
        let path = bundle.policy_path(dir);
        if !path.is_file() {
            return Err(DeployError::Bundle {
                path,
                message: "missing: the bundle's TorchScript policy".into(),
            });
        }
        let module = CModule::load(&path).map_err(|e| DeployError::Bundle {
            path: path.clone(),
            message: format!("not a TorchScript module: {}", first_line(&e.to_string())),
        })?;
        let (k, d, a) = (
            bundle.policy.history_len,
            bundle.policy.obs_dim,
            bundle.policy.action_dim,
        );
        Ok(Controller {
            module,
            history: vec![0.0; k * d],
            last_action: vec![0.0; a],
            steps: 0,
            started: false,
            noise: noise_seed.map(ChaCha8Rng::seed_from_u64),
            bundle,
        })
    }

    /// Start an episode: the next observation fills the history, the last
    /// action is 0 and the gait clock restarts.
    pub fn reset(&mut self) {
        self.history.iter_mut().for_each(|h| *h = 0.0);
        self.last_action.iter_mut().for_each(|a| *a = 0.0);
        self.steps = 0;
        self.started = false;
    }

    /// The last action after clipping (the observation's `last_action`).
    pub fn last_action(&self) -> &[f32] {
        &self.last_action
    }

    /// Control steps since the reset.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The command `(vx, vy, yaw_rate)` for a heading: the bundle's heading rule
    /// on the measured yaw.
    pub fn heading_command(&self, quat: [f64; 4], vx: f64, vy: f64, heading: f64) -> [f64; 3] {
        let c = &self.bundle.commands;
        let w = c.heading_stiffness * wrap_angle(heading - yaw_of(quat));
        [vx, vy, w.clamp(c.ang_vel_yaw[0], c.ang_vel_yaw[1])]
    }

    /// The observation of this step (the layout of `deploy.yaml`), with noise when
    /// the controller was loaded with a noise seed.
    pub fn observe(&mut self, s: &Sensors, command: [f64; 3]) -> Vec<f32> {
        let b = &self.bundle;
        let mut obs = vec![0.0f32; b.observation.dim];
        let r = quat_to_mat(s.quat);
        // R^T (0, 0, -1)
        let gravity = [-r[6], -r[7], -r[8]];
        let t = self.steps as f64 * b.timing.control_dt;
        let phase = 2.0 * PI * (t / b.commands.gait_period_s).fract();
        let n = b.joints.len();
        let dof_pos: Vec<f64> = (0..n).map(|j| s.q[j] - b.joints[j].default_pos).collect();
        let last: Vec<f64> = self.last_action.iter().map(|&a| a as f64).collect();
        let n_cfg = &b.observation.noise;
        let clip = b.observation.clip;
        for f in &b.observation.fields {
            let (raw, width): (&[f64], f64) = match f.name.as_str() {
                "base_ang_vel" => (&s.gyro, n_cfg.ang_vel),
                "projected_gravity" => (&gravity, n_cfg.gravity),
                "dof_pos" => (&dof_pos, n_cfg.dof_pos),
                "dof_vel" => (&s.qd, n_cfg.dof_vel),
                "command" => (&command, 0.0),
                "last_action" => (&last, 0.0),
                "gait_phase" => (&[phase.sin(), phase.cos()], 0.0),
                _ => (&[], 0.0),
            };
            for i in 0..f.len.min(raw.len()) {
                let sc = scale_of(f, i);
                let mut v = (raw[i] * sc).clamp(-clip, clip);
                if let Some(rng) = self.noise.as_mut() {
                    if width > 0.0 {
                        let e = rng.random_range(-1.0..=1.0) * width * n_cfg.level * sc;
                        v = (v + e).clamp(-clip, clip);
                    }
                }
                obs[f.start + i] = v as f32;
            }
        }
        obs
    }

    /// One control step: observe, run the policy on the observation, the history
    /// and `scan` (the bundle's scandots, already scaled; ignored by a blind
    /// policy), push the observation into the history, and return the joint
    /// position targets (rad) with the observation.
    pub fn act(
        &mut self,
        s: &Sensors,
        command: [f64; 3],
        scan: &[f32],
    ) -> Result<(Vec<f64>, Vec<f32>), DeployError> {
        let obs = self.observe(s, command);
        let p = &self.bundle.policy;
        let (k, d) = (p.history_len, p.obs_dim);
        if !self.started {
            for j in 0..k {
                self.history[j * d..(j + 1) * d].copy_from_slice(&obs);
            }
            self.started = true;
        }
        if scan.len() != p.scan_dim {
            return Err(DeployError::Invalid(format!(
                "scan has {} values, the policy takes {}",
                scan.len(),
                p.scan_dim
            )));
        }
        let o = Tensor::from_slice(&obs).view([1, d as i64]);
        let h = Tensor::from_slice(&self.history).view([1, k as i64, d as i64]);
        let sc = Tensor::from_slice(scan).view([1, p.scan_dim as i64]);
        let out = tch::no_grad(|| self.module.forward_ts(&[o, h, sc]))
            .map_err(|e| DeployError::Invalid(format!("policy: {}", first_line(&e.to_string()))))?;
        let out = out.to_kind(Kind::Float).view([-1]);
        let mut action = vec![0.0f32; p.action_dim];
        out.copy_data(&mut action, p.action_dim);
        let clip = self.bundle.action.clip as f32;
        for a in action.iter_mut() {
            *a = if a.is_finite() {
                a.clamp(-clip, clip)
            } else {
                0.0
            };
        }
        if k > 0 {
            self.history.copy_within(d.., 0);
            self.history[(k - 1) * d..].copy_from_slice(&obs);
        }
        let targets = self
            .bundle
            .joints
            .iter()
            .zip(&action)
            .map(|(j, &a)| j.default_pos + j.action_scale * a as f64)
            .collect();
        self.last_action = action;
        self.steps += 1;
        Ok((targets, obs))
    }
}

fn scale_of(f: &ObsField, i: usize) -> f64 {
    if f.scale.len() == 1 {
        f.scale[0]
    } else {
        f.scale[i]
    }
}

/// The first line of a libtorch error (its C++ backtrace follows).
pub fn first_line(s: &str) -> String {
    s.lines().next().unwrap_or("").trim().to_string()
}
