//! `dreampolicy deploy-sim`: a bundle driven in a MuJoCo scene through
//! [`Controller`] alone: the scene loaded as stock MuJoCo loads it, joints and
//! actuators found by the bundle's names, sensors read as a robot reads them
//! (pelvis quaternion and gyro, joint encoders), scandots cast with `mj_ray`.
//! Nothing of the training env is used.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use super::controller::{quat_to_mat, yaw_of, Controller, Sensors};
use super::DeployError;
use crate::sim::{Data, Model, ObjType};

/// Pelvis height above the ground (m) and tilt (deg) past which the deployer
/// counts a fall: the training env's termination.
pub const FALL_HEIGHT: f64 = 0.45;
pub const FALL_TILT_DEG: f64 = 50.0;

/// What to run.
#[derive(Debug, Clone)]
pub struct DeploySimOptions {
    /// Scene file; default: the bundle's `scene`, relative to the repository root.
    pub scene: Option<PathBuf>,
    pub seconds: f64,
    /// Forward speed command (m/s); heading held at 0 (the `eval` and `play` rule).
    pub speed: f64,
    /// Add the training observation noise from this seed.
    pub noise_seed: Option<u64>,
}

/// How the run went.
#[derive(Debug, Clone, Serialize)]
pub struct DeploySummary {
    pub scene: String,
    pub mujoco_version: String,
    pub steps: u64,
    pub seconds: f64,
    /// Pelvis displacement along the commanded heading (world x) (m).
    pub distance_m: f64,
    pub mean_forward_speed: f64,
    pub commanded_speed: f64,
    /// Mean over control steps of |v_xy - command_xy| (m/s).
    pub vel_tracking_error: f64,
    /// Yaw at the end (deg; the command holds 0).
    pub final_yaw_deg: f64,
    pub fell: bool,
    pub fell_at_s: Option<f64>,
    pub observation_noise: bool,
}

/// The robot's handles in a scene.
struct Handles {
    free_qpos: usize,
    free_dof: usize,
    qpos: Vec<usize>,
    dof: Vec<usize>,
    actuator: Vec<usize>,
}

fn resolve(model: &Model, c: &Controller, scene: &Path) -> Result<Handles, DeployError> {
    let missing = |what: &str, name: &str| {
        DeployError::Invalid(format!(
            "{}: no {what} named '{name}' (the bundle's joint list does not match the scene)",
            scene.display()
        ))
    };
    let free = (0..model.njnt())
        .find(|&j| model.jnt_type()[j] == mujoco_sys::mjJNT_FREE as i32)
        .ok_or_else(|| {
            DeployError::Invalid(format!(
                "{}: no free joint (a floating base)",
                scene.display()
            ))
        })?;
    let mut h = Handles {
        free_qpos: model.jnt_qposadr()[free] as usize,
        free_dof: model.jnt_dofadr()[free] as usize,
        qpos: vec![],
        dof: vec![],
        actuator: vec![],
    };
    for j in &c.bundle.joints {
        let id = model
            .name2id(ObjType::Joint, &j.name)
            .ok_or_else(|| missing("joint", &j.name))?;
        h.qpos.push(model.jnt_qposadr()[id] as usize);
        h.dof.push(model.jnt_dofadr()[id] as usize);
        let a = model
            .name2id(ObjType::Actuator, &j.actuator)
            .ok_or_else(|| missing("actuator", &j.actuator))?;
        h.actuator.push(a);
    }
    Ok(h)
}

/// Pelvis position and orientation `(w, x, y, z)`: the free joint's qpos.
fn pelvis(d: &Data, h: &Handles) -> ([f64; 3], [f64; 4]) {
    let q = &d.qpos()[h.free_qpos..h.free_qpos + 7];
    ([q[0], q[1], q[2]], [q[3], q[4], q[5], q[6]])
}

fn sensors(d: &Data, h: &Handles) -> Sensors {
    let (qpos, qvel) = (d.qpos(), d.qvel());
    Sensors {
        quat: pelvis(d, h).1,
        // MuJoCo's free-joint angular velocity is in the body frame, as a gyro's
        gyro: [
            qvel[h.free_dof + 3],
            qvel[h.free_dof + 4],
            qvel[h.free_dof + 5],
        ],
        q: h.qpos.iter().map(|&a| qpos[a]).collect(),
        qd: h.dof.iter().map(|&a| qvel[a]).collect(),
    }
}

/// Ground height under world `(x, y)`: a ray down from `top` that skips the
/// robot's own geoms (bodies other than the world).
pub fn ground_height(d: &Data, x: f64, y: f64, top: f64) -> f64 {
    let body = d.model().geom_bodyid();
    let mut z = top;
    for _ in 0..8 {
        match d.ray([x, y, z], [0.0, 0.0, -1.0], None, true, None) {
            Some((dist, g)) if body[g] == 0 => return z - dist,
            Some((dist, _)) => z -= dist + 1e-4,
            None => break,
        }
    }
    top - 10.0
}

/// Resolve the bundle's scene path against the repository root.
fn scene_path(c: &Controller, o: &DeploySimOptions) -> PathBuf {
    o.scene.clone().unwrap_or_else(|| {
        crate::robot::models_dir()
            .parent()
            .map(|root| root.join(&c.bundle.scene))
            .unwrap_or_else(|| PathBuf::from(&c.bundle.scene))
    })
}

/// Run the bundle in `dir` for `o.seconds`, or until it falls.
pub fn deploy_sim(dir: &Path, o: &DeploySimOptions) -> Result<DeploySummary, DeployError> {
    if !(o.seconds.is_finite() && o.seconds > 0.0 && o.speed.is_finite()) {
        return Err(DeployError::Invalid(format!(
            "--seconds must be positive and --speed finite, got {} and {}",
            o.seconds, o.speed
        )));
    }
    let mut c = Controller::load(dir, o.noise_seed)?;
    let scene = scene_path(&c, o);
    let mut model =
        Model::from_xml_path(&scene).map_err(|e| DeployError::Invalid(e.to_string()))?;
    let t = c.bundle.timing.clone();
    model.set_timestep(t.physics_dt);
    let model = Arc::new(model);
    let h = resolve(&model, &c, &scene)?;
    let mut d = Data::new(model.clone()).map_err(|e| DeployError::Invalid(e.to_string()))?;
    if let Some(key) = model.name2id(ObjType::Key, &c.bundle.reset.keyframe) {
        d.reset_keyframe(key)
            .map_err(|e| DeployError::Invalid(e.to_string()))?;
    }
    for (j, spec) in c.bundle.joints.iter().enumerate() {
        d.qpos_mut()[h.qpos[j]] = spec.default_pos;
        d.ctrl_mut()[h.actuator[j]] = spec.default_pos;
    }
    d.qpos_mut()[h.free_qpos + 2] = c.bundle.reset.pelvis_height;
    d.forward();
    c.reset();
    let scan_spec = c.bundle.scan.clone();
    let steps = (o.seconds / t.control_dt).round().max(1.0) as u64;
    let x0 = pelvis(&d, &h).0[0];
    let mut err_sum = 0.0;
    let mut fell_at = None;
    let mut done = 0;
    let mut scan = vec![0.0f32; scan_spec.dim];
    for step in 0..steps {
        let s = sensors(&d, &h);
        let cmd = c.heading_command(s.quat, o.speed, 0.0, 0.0);
        let base = pelvis(&d, &h).0;
        if c.bundle.policy.uses_scan {
            let (sy, cy) = yaw_of(s.quat).sin_cos();
            for (k, v) in scan.iter_mut().enumerate() {
                let (ix, iy) = (k / scan_spec.ny, k % scan_spec.ny);
                let px = scan_spec.x0 + scan_spec.spacing * ix as f64;
                let py = scan_spec.y0 + scan_spec.spacing * iy as f64;
                let (x, y) = (base[0] + cy * px - sy * py, base[1] + sy * px + cy * py);
                let g = ground_height(&d, x, y, base[2] + 2.0);
                *v =
                    ((g - base[2]).clamp(-scan_spec.clip, scan_spec.clip) * scan_spec.scale) as f32;
            }
        }
        let (targets, _) = c.act(&s, cmd, &scan)?;
        for (j, &a) in h.actuator.iter().enumerate() {
            d.ctrl_mut()[a] = targets[j];
        }
        for _ in 0..t.decimation {
            d.step().map_err(|e| {
                DeployError::Invalid(format!(
                    "physics at {:.2} s: {e}",
                    step as f64 * t.control_dt
                ))
            })?;
        }
        done = step + 1;
        let v = d.qvel();
        err_sum += (v[h.free_dof] - cmd[0]).hypot(v[h.free_dof + 1] - cmd[1]);
        let ([bx, by, bz], quat) = pelvis(&d, &h);
        let height = bz - ground_height(&d, bx, by, bz + 2.0);
        let tilted = quat_to_mat(quat)[8] < FALL_TILT_DEG.to_radians().cos();
        if height < FALL_HEIGHT || tilted {
            fell_at = Some(done as f64 * t.control_dt);
            break;
        }
    }
    let seconds = done as f64 * t.control_dt;
    let (end, quat) = pelvis(&d, &h);
    let distance = end[0] - x0;
    Ok(DeploySummary {
        scene: scene.display().to_string(),
        mujoco_version: crate::sim::mujoco_version(),
        steps: done,
        seconds,
        distance_m: distance,
        mean_forward_speed: distance / seconds,
        commanded_speed: o.speed,
        vel_tracking_error: err_sum / done.max(1) as f64,
        final_yaw_deg: yaw_of(quat).to_degrees(),
        fell: fell_at.is_some(),
        fell_at_s: fell_at,
        observation_noise: o.noise_seed.is_some(),
    })
}
