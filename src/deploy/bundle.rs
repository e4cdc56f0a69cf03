//! The deployment bundle: `policy.pt` (TorchScript, [`crate::rl::export`]) and
//! `deploy.yaml` ([`Bundle`]), everything a controller needs to run the policy
//! without this crate's env: joints in order with their gains, limits and action
//! scales; timing; the observation layout with its scales, noise and history
//! rule; the scandots; the commands and the heading rule; the gait clock; the
//! reset pose; the scene it was validated on; and the checkpoint's eval figures.
//! `deploy.yaml` holds the SHA-256 of `policy.pt` and `policy.npz` and ends in
//! its own seal line; [`Bundle::read`] checks all three.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::DeployError;
use crate::env::config::CollisionMode;
use crate::env::obs::{
    ANG_VEL, COMMAND, DOF_POS, DOF_VEL, GRAVITY, LAST_ACTION, OBS_DIM, PHASE, SCAN_DIM, SCAN_NX,
    SCAN_NY,
};
use crate::env::VecEnv;
use crate::rl::checkpoint::Checkpoint;
use crate::robot::{JOINT_NAMES, NUM_JOINTS};

/// The format tag of `deploy.yaml`.
pub const FORMAT: &str = "dreampolicy-deploy/1";
/// File names inside a bundle directory.
pub const BUNDLE_FILE: &str = "deploy.yaml";
pub const POLICY_FILE: &str = "policy.pt";
pub const NPZ_FILE: &str = "policy.npz";
pub const ONNX_FILE: &str = "policy.onnx";

/// `deploy.yaml`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bundle {
    /// [`FORMAT`].
    pub format: String,
    pub policy: PolicySpec,
    /// The same actor as NumPy arrays (`policy.npz`), for deployers without
    /// libtorch (`scripts/deploy_mujoco.py`).
    pub numpy_policy: crate::rl::export::NpzPolicy,
    /// The same actor as an ONNX graph (`policy.onnx`, `export --format
    /// onnx`), for runtimes without libtorch (onnxruntime, tract).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub onnx_policy: Option<OnnxSpec>,
    /// The checkpoint the bundle was made from.
    pub source: SourceSpec,
    /// The MuJoCo scene the policy was validated on (relative to the repository
    /// root): the G1 with full collisions on a plane.
    pub scene: String,
    pub timing: TimingSpec,
    /// The 29 actuated joints in the order of observations and actions.
    pub joints: Vec<JointSpec>,
    pub action: ActionSpec,
    pub observation: ObservationSpec,
    pub scan: ScanSpec,
    pub commands: CommandSpec,
    pub reset: ResetSpec,
    /// The checkpoint's `eval.json` (the run directory's, beside `checkpoints/`),
    /// when there is one.
    #[serde(default)]
    pub eval: Option<serde_json::Value>,
    /// SHA-256 of the bundle's other files by name (`policy.pt`, `policy.npz`),
    /// checked by [`Bundle::read`]; `deploy.yaml` itself ends in its own seal
    /// line ([`crate::seal::seal_yaml`]).
    #[serde(default)]
    pub files: std::collections::BTreeMap<String, String>,
}

/// The TorchScript file and its signature.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicySpec {
    /// File name inside the bundle.
    pub file: String,
    /// `forward(obs [B, obs_dim], history [B, history_len, obs_dim], scan [B,
    /// scan_dim]) -> action mean [B, action_dim]`, raw (unnormalized) inputs.
    pub signature: String,
    pub obs_dim: usize,
    pub history_len: usize,
    pub scan_dim: usize,
    pub action_dim: usize,
    /// Whether the scan input changes the actions (a blind policy ignores it,
    /// but it is always passed).
    pub uses_scan: bool,
}

/// The ONNX file: the same function as [`PolicySpec`]'s, inputs named
/// `obs`, `history`, `scan`, output `action`, batch dimension `batch`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnnxSpec {
    pub file: String,
    /// Operator set of the default ONNX domain.
    pub opset: i64,
    pub ir_version: i64,
    pub inputs: Vec<String>,
    pub output: String,
    /// Reference inputs and the TorchScript file's actions on them
    /// (`policy_reference.npz`: rows of a rollout and random rows,
    /// [`crate::rl::onnx::write_reference`]): a runtime that runs the ONNX
    /// file should give these actions to ~1e-5.
    pub reference: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    pub checkpoint: String,
    pub iteration: usize,
    pub env_steps: u64,
    pub wall_time_s: f64,
    /// Collision set and solver the policy trained with (`feet_only` or `full`).
    pub training_collision: String,
    pub mujoco_version: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimingSpec {
    /// MuJoCo timestep (s).
    pub physics_dt: f64,
    /// Physics steps per policy step.
    pub decimation: usize,
    /// `physics_dt * decimation` (s): 50 Hz.
    pub control_dt: f64,
}

/// One actuated joint.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// MJCF joint name.
    pub name: String,
    /// MJCF position actuator driving it.
    pub actuator: String,
    /// Default pose (rad): the `stand` keyframe.
    pub default_pos: f64,
    /// PD gains of the position actuator (N m/rad, N m s/rad).
    pub kp: f64,
    pub kd: f64,
    /// Torque limit (N m), the actuator's `forcerange`.
    pub effort_limit: f64,
    /// Radians of target per unit action.
    pub action_scale: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionSpec {
    /// Actions are clipped to `[-clip, clip]` before anything else.
    pub clip: f64,
    /// How a target is made of an action.
    pub rule: String,
    /// Control steps between the policy output and its application in training
    /// (domain randomization's range; evaluation uses 0).
    pub training_latency_steps: [usize; 2],
}

/// One slice of the observation.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObsField {
    pub name: String,
    pub start: usize,
    pub len: usize,
    /// Multiplier of the raw value: one per element, or one for all.
    pub scale: Vec<f64>,
    /// What the raw value is and where a robot gets it.
    pub source: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    pub dim: usize,
    /// Every entry is clipped to `[-clip, clip]` after scaling.
    pub clip: f64,
    pub fields: Vec<ObsField>,
    pub history: HistorySpec,
    pub noise: NoiseSpec,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistorySpec {
    pub length: usize,
    pub rule: String,
}

/// Uniform observation noise `U(-w, w) * level` in raw units (then scaled).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Whether training, `eval` and `play` add it.
    pub on_in_training_and_eval: bool,
    pub level: f64,
    pub ang_vel: f64,
    pub gravity: f64,
    pub dof_pos: f64,
    pub dof_vel: f64,
    pub scan: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanSpec {
    pub dim: usize,
    pub nx: usize,
    pub ny: usize,
    /// Points at `x0 + spacing * ix`, `y0 + spacing * iy` (m) in the yaw-aligned
    /// pelvis frame; index `ix * ny + iy`.
    pub x0: f64,
    pub y0: f64,
    pub spacing: f64,
    /// Ground height minus pelvis height (m), clipped to `[-clip, clip]`, times `scale`.
    pub clip: f64,
    pub scale: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandSpec {
    /// Ranges the policy trained on (m/s, m/s, rad/s).
    pub lin_vel_x: [f64; 2],
    pub lin_vel_y: [f64; 2],
    pub ang_vel_yaw: [f64; 2],
    /// Heading mode: `yaw_rate = clip(heading_stiffness * wrap(heading - yaw),
    /// ang_vel_yaw)` every control step; `eval` and `play` hold heading 0.
    pub heading_command: bool,
    pub heading_stiffness: f64,
    /// The gait clock: `phase = frac(t / gait_period_s)`, `t` = control steps
    /// since reset * control_dt (0 at the reset observation).
    pub gait_period_s: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResetSpec {
    /// The keyframe the robot starts in (joints at `default_pos`).
    pub keyframe: String,
    /// Pelvis height above the ground at reset (m): the keyframe's plus the
    /// config's offset.
    pub pelvis_height: f64,
}

impl Bundle {
    /// Read `dir/deploy.yaml` and check its format and sizes.
    pub fn read(dir: &Path) -> Result<Bundle, DeployError> {
        let path = dir.join(BUNDLE_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| DeployError::Io {
            path: path.clone(),
            source,
        })?;
        let bad = |message: String| {
            Err(DeployError::Bundle {
                path: path.clone(),
                message,
            })
        };
        if let Err(e) = crate::seal::check_yaml(&text) {
            return bad(format!(
                "{e}; or write the bundle again with `dreampolicy export`"
            ));
        }
        let b: Bundle = serde_yaml::from_str(&text).map_err(|e| DeployError::Bundle {
            path: path.clone(),
            message: e.to_string(),
        })?;
        if b.format != FORMAT {
            return bad(format!(
                "format '{}', this build reads '{FORMAT}'",
                b.format
            ));
        }
        if b.joints.len() != b.policy.action_dim {
            return bad(format!(
                "{} joints for {} actions",
                b.joints.len(),
                b.policy.action_dim
            ));
        }
        let end = b.observation.fields.iter().map(|f| f.start + f.len).max();
        if end != Some(b.observation.dim) || b.observation.dim != b.policy.obs_dim {
            return bad(format!(
                "observation fields end at {end:?}, dim {} and the policy's {}",
                b.observation.dim, b.policy.obs_dim
            ));
        }
        for f in &b.observation.fields {
            if f.scale.len() != 1 && f.scale.len() != f.len {
                return bad(format!(
                    "observation field {}: {} scales for {} values",
                    f.name,
                    f.scale.len(),
                    f.len
                ));
            }
        }
        if b.scan.dim != b.policy.scan_dim || b.scan.nx * b.scan.ny != b.scan.dim {
            return bad("scan dims disagree with the policy's".into());
        }
        b.check_files(dir)?;
        Ok(b)
    }

    /// Check the policy files against the digests `deploy.yaml` holds for them.
    fn check_files(&self, dir: &Path) -> Result<(), DeployError> {
        let path = dir.join(BUNDLE_FILE);
        for name in self.file_names() {
            let name = name.as_str();
            let Some(digest) = self.files.get(name) else {
                return Err(DeployError::Bundle {
                    path,
                    message: format!("holds no SHA-256 for {name}"),
                });
            };
            let file = dir.join(name);
            let found = crate::seal::file_sha256(&file).map_err(|source| DeployError::Io {
                path: file.clone(),
                source,
            })?;
            if &found != digest {
                return Err(DeployError::Bundle {
                    path: file,
                    message: format!(
                        "is corrupt: its SHA-256 does not match the one in {BUNDLE_FILE} \
                         (the file changed after `export` wrote it); export the bundle again"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Seal the bundle in `dir` as it is: record the SHA-256 of its policy files
    /// in `deploy.yaml` and seal that (for a bundle written before bundles were
    /// sealed, or edited on purpose; nothing checks the files against anything).
    pub fn seal_dir(dir: &Path) -> Result<(), DeployError> {
        let path = dir.join(BUNDLE_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| DeployError::Io {
            path: path.clone(),
            source,
        })?;
        let mut b: Bundle = serde_yaml::from_str(&text).map_err(|e| DeployError::Bundle {
            path: path.clone(),
            message: e.to_string(),
        })?;
        b.write_sealed(dir)
    }

    /// Fill [`Bundle::files`] from the files in `dir` and write `deploy.yaml`
    /// sealed, atomically.
    fn write_sealed(&mut self, dir: &Path) -> Result<(), DeployError> {
        self.files.clear();
        for name in self.file_names() {
            let file = dir.join(&name);
            let digest = crate::seal::file_sha256(&file)
                .map_err(|source| DeployError::Io { path: file, source })?;
            self.files.insert(name, digest);
        }
        let path = dir.join(BUNDLE_FILE);
        let text = serde_yaml::to_string(self).map_err(|e| DeployError::Bundle {
            path: path.clone(),
            message: e.to_string(),
        })?;
        crate::run::write_atomic(&path, crate::seal::seal_yaml(&text).as_bytes())
            .map_err(|(path, source)| DeployError::Io { path, source })
    }

    /// The bundle's files besides `deploy.yaml`, whose digests it holds.
    fn file_names(&self) -> Vec<String> {
        let mut v = vec![self.policy.file.clone(), NPZ_FILE.to_string()];
        if let Some(o) = &self.onnx_policy {
            v.extend([o.file.clone(), o.reference.clone()]);
        }
        v
    }

    /// The observation field called `name`.
    pub fn field(&self, name: &str) -> Option<&ObsField> {
        self.observation.fields.iter().find(|f| f.name == name)
    }

    /// Path of the TorchScript file of a bundle in `dir`.
    pub fn policy_path(&self, dir: &Path) -> PathBuf {
        dir.join(&self.policy.file)
    }
}

/// What `export` wrote.
#[derive(Debug, Clone, Serialize)]
pub struct BundleInfo {
    pub dir: String,
    pub policy: String,
    /// `policy.onnx`, when written.
    pub onnx: Option<String>,
    pub bundle: String,
    pub history_len: usize,
    pub uses_scan: bool,
    pub eval_included: bool,
}

/// Write a bundle for checkpoint `ck` into `dir` (created); with `onnx`, the
/// actor as `policy.onnx` too.
pub fn write_bundle(ck: &Checkpoint, dir: &Path, onnx: bool) -> Result<BundleInfo, DeployError> {
    std::fs::create_dir_all(dir).map_err(|source| DeployError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let policy_path = dir.join(POLICY_FILE);
    let info = crate::rl::export::export(ck, &policy_path)?;
    let numpy_policy = crate::rl::export::export_npz(ck, &dir.join(NPZ_FILE))?;
    let onnx_policy = if onnx {
        let o = crate::rl::onnx::export_onnx(ck, &dir.join(ONNX_FILE))?;
        let reference = crate::rl::onnx::REFERENCE_FILE;
        crate::rl::onnx::write_reference(ck, &policy_path, &dir.join(reference))?;
        Some(OnnxSpec {
            file: ONNX_FILE.into(),
            opset: o.opset,
            ir_version: o.ir_version,
            inputs: crate::rl::onnx::INPUTS
                .iter()
                .map(|s| s.to_string())
                .collect(),
            output: crate::rl::onnx::OUTPUT.into(),
            reference: reference.into(),
        })
    } else {
        // a bundle written again without ONNX must not keep a stale file
        let _ = std::fs::remove_file(dir.join(ONNX_FILE));
        let _ = std::fs::remove_file(dir.join(crate::rl::onnx::REFERENCE_FILE));
        None
    };
    let cfg = ck.config()?;
    let env = &cfg.env;
    // the G1's facts as the training env resolves them (gains, default pose,
    // per-joint action scale), on the scene the bundle names
    let mut one = env.clone();
    one.n_envs = 1;
    one.threads = 1;
    one.terrain.mode = crate::env::config::TerrainMode::Plane;
    let venv = VecEnv::new(&one).map_err(|e| DeployError::Env(e.to_string()))?;
    let sh = venv.shared();
    let g1 = &sh.scene.g1;
    let model = venv.envs()[0].data().model().clone();
    let joints = (0..NUM_JOINTS)
        .map(|j| JointSpec {
            name: JOINT_NAMES[j].to_string(),
            actuator: model
                .id2name(crate::sim::ObjType::Actuator, g1.actuator[j])
                .unwrap_or_default()
                .to_string(),
            default_pos: g1.default_pos[j],
            kp: g1.kp[j],
            kd: g1.kd[j],
            effort_limit: g1.effort_limit[j],
            action_scale: sh.action_scale[j],
        })
        .collect();
    let o = &env.observation;
    let sc = &o.scales;
    let field = |name: &str, r: std::ops::Range<usize>, scale: Vec<f64>, source: &str| ObsField {
        name: name.into(),
        start: r.start,
        len: r.len(),
        scale,
        source: source.into(),
    };
    let fields = vec![
        field(
            "base_ang_vel",
            ANG_VEL,
            vec![sc.ang_vel],
            "pelvis angular velocity in the pelvis frame (rad/s): the IMU gyro; MuJoCo's free-joint qvel[3..6]",
        ),
        field(
            "projected_gravity",
            GRAVITY,
            vec![1.0],
            "R^T (0, 0, -1), R the pelvis orientation: from the IMU quaternion (w, x, y, z); MuJoCo's free-joint qpos[3..7]",
        ),
        field(
            "dof_pos",
            DOF_POS,
            vec![sc.dof_pos],
            "joint position minus default_pos (rad), joints in the order above: the encoders",
        ),
        field(
            "dof_vel",
            DOF_VEL,
            vec![sc.dof_vel],
            "joint velocity (rad/s): the encoders",
        ),
        field(
            "command",
            COMMAND,
            sc.commands.to_vec(),
            "(vx, vy, yaw_rate) in the heading frame (m/s, m/s, rad/s); in heading mode the yaw rate comes from the heading rule",
        ),
        field(
            "last_action",
            LAST_ACTION,
            vec![1.0],
            "the previous policy output after clipping, before action_scale; 0 at reset",
        ),
        field(
            "gait_phase",
            PHASE,
            vec![1.0],
            "(sin 2 pi phase, cos 2 pi phase), phase = frac(t / gait_period_s), t = control steps since reset * control_dt",
        ),
    ];
    let n = &o.noise;
    let k = info.history_len;
    let eval = ck
        .path
        .parent()
        .and_then(|p| p.parent())
        .map(|run| run.join("eval.json"))
        .and_then(|p| std::fs::read_to_string(p).ok())
        .and_then(|t| serde_json::from_str(&t).ok());
    let mut bundle = Bundle {
        format: FORMAT.into(),
        policy: PolicySpec {
            file: POLICY_FILE.into(),
            signature: "forward(obs [B, obs_dim], history [B, history_len, obs_dim], scan [B, scan_dim]) -> action mean [B, action_dim]; raw inputs, the normalization is inside".into(),
            obs_dim: info.obs_dim,
            history_len: k,
            scan_dim: info.scan_dim,
            action_dim: info.action_dim,
            uses_scan: info.uses_scan,
        },
        numpy_policy,
        onnx_policy,
        source: SourceSpec {
            checkpoint: ck.path.display().to_string(),
            iteration: ck.meta.iteration,
            env_steps: ck.meta.env_steps,
            wall_time_s: ck.meta.wall_time_s,
            training_collision: match env.sim.collision {
                CollisionMode::Full => "full",
                CollisionMode::FeetOnly => "feet_only",
            }
            .into(),
            mujoco_version: crate::sim::mujoco_version(),
        },
        scene: "models/g1/scene_flat.xml".into(),
        timing: TimingSpec {
            physics_dt: env.sim.timestep,
            decimation: env.sim.decimation,
            control_dt: env.sim.control_dt(),
        },
        joints,
        action: ActionSpec {
            clip: env.control.clip_actions,
            rule: "target_j = default_pos_j + action_scale_j * clip(a_j, -clip, clip), sent as the position actuator's ctrl for the next decimation physics steps".into(),
            training_latency_steps: env.domain_rand.action_latency,
        },
        observation: ObservationSpec {
            dim: OBS_DIM,
            clip: o.clip,
            fields,
            history: HistorySpec {
                length: k,
                rule: format!(
                    "history holds the {k} observations before the current one, oldest first; \
                     at reset all {k} are the first observation; the current observation goes \
                     in obs only"
                ),
            },
            noise: NoiseSpec {
                on_in_training_and_eval: o.add_noise,
                level: o.noise_level,
                ang_vel: n.ang_vel,
                gravity: n.gravity,
                dof_pos: n.dof_pos,
                dof_vel: n.dof_vel,
                scan: n.scan,
            },
        },
        scan: ScanSpec {
            dim: SCAN_DIM,
            nx: SCAN_NX,
            ny: SCAN_NY,
            x0: o.scan_grid.x0,
            y0: o.scan_grid.y0,
            spacing: o.scan_grid.spacing,
            clip: o.scan_clip,
            scale: sc.scan,
        },
        commands: CommandSpec {
            lin_vel_x: env.commands.lin_vel_x,
            lin_vel_y: env.commands.lin_vel_y,
            ang_vel_yaw: env.commands.ang_vel_yaw,
            heading_command: env.commands.heading_command,
            heading_stiffness: env.commands.heading_stiffness,
            gait_period_s: o.gait_period_s,
        },
        reset: ResetSpec {
            keyframe: crate::robot::STAND_KEY.into(),
            pelvis_height: g1.stand_height + env.init.height_offset,
        },
        eval,
        files: Default::default(),
    };
    let path = dir.join(BUNDLE_FILE);
    bundle.write_sealed(dir)?;
    Ok(BundleInfo {
        dir: dir.display().to_string(),
        policy: policy_path.display().to_string(),
        onnx: bundle
            .onnx_policy
            .as_ref()
            .map(|o| dir.join(&o.file).display().to_string()),
        bundle: path.display().to_string(),
        history_len: k,
        uses_scan: info.uses_scan,
        eval_included: bundle.eval.is_some(),
    })
}
