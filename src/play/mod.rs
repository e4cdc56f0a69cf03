//! `dreampolicy play`: one robot driven by a checkpoint's deterministic policy
//! (mean actions) on an evaluation lane, written as an MCAP file that Foxglove
//! opens as it is (README, "Watching a rollout").
//!
//! The env is the evaluation's (no domain randomization or pushes, heading held
//! along the lane, the checkpoint's training scene or with `full_collision` the
//! project's default one), with one env, a fixed commanded forward speed and
//! no time-out inside the rollout. A flat lane is a plane; any other kind is
//! `eval`'s lane (`eval::eval_lane`: the config's `eval.terrain`, the paper's table
//! by default, at `eval.level` or `--level`), compiled into the scene.
//! The rollout stops after `seconds`, at a fall (or a physics blow-up), or when
//! the robot walks off the lane's map.
//!
//! Topics, all JSON with a JSON Schema ([`file::Topic`]): `/tf`
//! (`foxglove.FrameTransforms`, every body in `world` at every frame), `/robot`
//! and `/terrain` (`foxglove.SceneUpdate`, once, at the first frame), `/command`,
//! `/state` (every frame) and `/reward` (every control step, with its terms);
//! a unified policy's file adds `/plan` (`foxglove.SceneUpdate`, every frame:
//! the world model's plan, a sphere for the pelvis and each foot of every
//! predicted state, placed as [`crate::unified::task::UnifiedTask::plan_in_world`] says).
//! Frame `k` is the state after `k` control steps (frame 0: the reset state),
//! stamped [`START_NS`] + `k` x the control period. A step that ends the
//! episode writes no frame: the env has already reset its robot.
pub mod file;
pub mod foxglove;
pub mod scene;
pub mod video;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use crate::env::config::{EnvConfig, TerrainMode};
use crate::env::{EnvError, Scene, VecEnv};
use crate::rl::checkpoint::Checkpoint;
use crate::rl::config::ExperimentConfig;
use crate::rl::{Agent, RlError};
use crate::terrain::{TerrainError, TerrainKind};
use file::{PlayFile, Topic};
use foxglove::{FrameTransform, FrameTransforms, Quaternion, SceneUpdate, Time, Vector3};
use scene::{round5, round6, WORLD};

/// Timestamp of frame 0 (ns): simulated time starts at 1 s, so that no message
/// is stamped 0.
pub const START_NS: u64 = 1_000_000_000;
/// Default rollout length (s).
pub const DEFAULT_SECONDS: f64 = 20.0;
/// Longest rollout accepted (s): an hour of frames.
pub const MAX_SECONDS: f64 = 3600.0;

/// Errors of a play rollout.
#[derive(Debug, thiserror::Error)]
pub enum PlayError {
    #[error(transparent)]
    Rl(#[from] RlError),
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Terrain(#[from] TerrainError),
    #[error("{path}: {source}", path = .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: MCAP error: {source}", path = .path.display())]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("encoding a {topic} message: {why}")]
    Json { topic: &'static str, why: String },
    #[error(transparent)]
    Sim(#[from] crate::sim::SimError),
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    #[error("{0}")]
    Invalid(String),
}

impl PlayError {
    fn io(path: &Path, source: std::io::Error) -> PlayError {
        PlayError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// What to play.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    pub terrain: TerrainKind,
    /// Curriculum level of the lane (default: the config's `eval.level`).
    pub level: Option<usize>,
    /// Simulated seconds (stops earlier at a fall).
    pub seconds: f64,
    /// Commanded forward speed (m/s; default: the middle of `eval.lin_vel_x`).
    pub speed: Option<f64>,
    /// Seed of the env (reset noise, observation noise) and of the lane.
    pub seed: u64,
    /// The project's default scene (full collisions, default solver) instead of
    /// the checkpoint's training scene.
    pub full_collision: bool,
    /// Lane keeping, as `eval --lane-lookahead` (m; None: heading held).
    pub lane_lookahead: Option<f64>,
    /// The MCAP file to write.
    pub out: PathBuf,
}

impl PlayOptions {
    /// Defaults: 20 s, the config's level and speed, seed 0, training scene.
    pub fn new(terrain: TerrainKind, out: impl Into<PathBuf>) -> PlayOptions {
        PlayOptions {
            terrain,
            level: None,
            seconds: DEFAULT_SECONDS,
            speed: None,
            seed: 0,
            full_collision: false,
            lane_lookahead: None,
            out: out.into(),
        }
    }
}

/// How a rollout ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    /// It ran the requested time.
    TimeUp,
    /// It fell (height, tilt or a fatal contact: the config's terminations).
    Fell,
    /// The physics blew up.
    BlowUp,
    /// It walked off the lane's map.
    LeftMap,
}

/// What a rollout did and wrote.
#[derive(Debug, Clone, Serialize)]
pub struct PlaySummary {
    pub out: String,
    pub terrain: String,
    /// Lane level (None on a plane).
    pub level: Option<usize>,
    /// The table the lane was drawn from: "the paper's table" (`eval.terrain`'s
    /// default) or "the config's eval.terrain"; None on a plane.
    pub table: Option<String>,
    /// Spawn to goal line of the lane (m; None on a plane).
    pub lane_length: Option<f64>,
    pub commanded_speed: f64,
    /// Control steps simulated (including a last one that ended the episode).
    pub steps: u64,
    /// Frames written (`/tf`, `/state`, `/command` messages): the reset state
    /// plus every step that did not end the episode.
    pub frames: u64,
    pub seconds: f64,
    /// Pelvis x at the end - spawn x (m).
    pub distance: f64,
    pub mean_forward_speed: f64,
    pub fell: bool,
    pub ending: Ending,
    /// Crossed the lane's goal line (None on a plane).
    pub reached_goal: Option<bool>,
    /// Sum of the per-step rewards.
    pub total_reward: f64,
    pub bodies: usize,
    pub file_bytes: u64,
    pub full_collision: bool,
    pub seed: u64,
    pub checkpoint: String,
}

/// The env config of a rollout, derived from the training config like an
/// evaluation's (`eval::eval_env_config`): one env, the given speed, no
/// time-out within `seconds`, and a map for a lane of `terrain`.
pub fn play_env_config(cfg: &ExperimentConfig, o: &PlayOptions, speed: f64) -> EnvConfig {
    let mut env = cfg.env.clone();
    env.n_envs = 1;
    env.threads = 1;
    env.seed = o.seed;
    env.episode_length_s = o.seconds + 1.0;
    env.domain_rand.enabled = false;
    env.init.yaw = [0.0, 0.0];
    let c = &mut env.commands;
    c.lin_vel_x = [speed, speed];
    c.lin_vel_y = [0.0, 0.0];
    c.heading_command = true;
    c.heading = [0.0, 0.0];
    c.resample_time_s = 2.0 * env.episode_length_s;
    c.min_norm = 0.0;
    c.lane_lookahead = o.lane_lookahead;
    crate::eval::scene_protocol(&mut env, o.full_collision, &cfg.eval);
    env.terrain.mode = match o.terrain {
        TerrainKind::Flat => TerrainMode::Plane,
        _ => TerrainMode::Map,
    };
    env.terrain.curriculum = false;
    env
}

fn check(o: &PlayOptions) -> Result<(), PlayError> {
    if !(o.seconds.is_finite() && o.seconds > 0.0 && o.seconds <= MAX_SECONDS) {
        return Err(PlayError::Invalid(format!(
            "--seconds must be in (0, {MAX_SECONDS}], got {}",
            o.seconds
        )));
    }
    if let Some(v) = o.speed {
        if !(v.is_finite() && v.abs() <= 5.0) {
            return Err(PlayError::Invalid(format!(
                "--speed must be a speed in [-5, 5] m/s, got {v}"
            )));
        }
    }
    Ok(())
}

/// What `play` steps: the G1 env, or a unified policy's task around it, whose
/// plan is drawn on `/plan`.
trait PlayTask: crate::eval::EvalTask {
    /// The world model that plans (a unified policy's), if any: its file has
    /// `/plan`.
    fn world_model(&self) -> Option<&str> {
        None
    }
    /// Env 0's plan in the world (a unified policy's), if it has one now.
    fn plan_poses(&mut self) -> Option<Vec<crate::unified::task::PlannedPose>> {
        None
    }
}

impl PlayTask for VecEnv {}

impl PlayTask for crate::unified::task::UnifiedTask {
    fn world_model(&self) -> Option<&str> {
        Some(&self.cfg.world_model)
    }
    fn plan_poses(&mut self) -> Option<Vec<crate::unified::task::PlannedPose>> {
        self.plan_in_world(0)
    }
}

/// What else watches a rollout, frame by frame: `render`'s video encoder.
pub trait FrameSink {
    /// Frame `k` of the rollout: env 0 of `env` holds the state after `k`
    /// control steps (frame 0: the reset state). Called for every frame the
    /// MCAP file gets, in order.
    fn frame(&mut self, env: &VecEnv, k: u64) -> Result<(), PlayError>;
}

/// No sink: `play` alone.
impl FrameSink for () {
    fn frame(&mut self, _: &VecEnv, _: u64) -> Result<(), PlayError> {
        Ok(())
    }
}

/// Roll the checkpoint's policy out on one lane and write `o.out`. A unified
/// policy runs the paper's inference loop (the world model named in its
/// config plans from the robot's history and the lane's scandots) and its
/// plan goes to `/plan`.
pub fn play(ck: &Checkpoint, o: &PlayOptions) -> Result<PlaySummary, PlayError> {
    play_into(ck, o, Some(&o.out), &mut ())
}

/// [`play`], writing the MCAP file to `mcap` (None: no file) and handing every
/// frame to `sink`. The summary's `out` is `o.out` either way.
pub fn play_into(
    ck: &Checkpoint,
    o: &PlayOptions,
    mcap: Option<&Path>,
    sink: &mut dyn FrameSink,
) -> Result<PlaySummary, PlayError> {
    check(o)?;
    let cfg = ck.config()?;
    let [lo, hi] = cfg.eval.lin_vel_x;
    let speed = o.speed.unwrap_or(0.5 * (lo + hi));
    let env_cfg = play_env_config(&cfg, o, speed);
    let level = o.level.unwrap_or(cfg.eval.level);
    let lane = match o.terrain {
        TerrainKind::Flat => None,
        kind => Some(crate::eval::eval_lane(&cfg, kind, level, o.seed)?),
    };
    let scene = Scene::with_terrain(&env_cfg, lane.as_ref().map(|l| Arc::new(l.map().clone())))?;
    let mut env = VecEnv::with_scene(&env_cfg, scene)?;
    env.set_penalty_scale(ck.meta.penalty_scale);
    let run = Rollout {
        ck,
        cfg: &cfg,
        o,
        lane: lane.as_ref(),
        level,
        speed,
    };
    if cfg.task == crate::rl::config::TaskKind::Unified {
        let mut task = crate::unified::task::UnifiedTask::with_env(&cfg, env)?;
        run.go(&mut task, mcap, sink)
    } else {
        run.go(&mut env, mcap, sink)
    }
}

/// One `play` rollout's fixed inputs.
struct Rollout<'a> {
    ck: &'a Checkpoint,
    cfg: &'a ExperimentConfig,
    o: &'a PlayOptions,
    lane: Option<&'a crate::terrain::Lane>,
    level: usize,
    speed: f64,
}

impl Rollout<'_> {
    fn go<T: PlayTask>(
        &self,
        task: &mut T,
        mcap: Option<&Path>,
        sink: &mut dyn FrameSink,
    ) -> Result<PlaySummary, PlayError> {
        let Rollout {
            ck,
            cfg,
            o,
            lane,
            level,
            speed,
        } = *self;
        let mut agent = Agent::new(&cfg.policy, task.dims(), 1, cfg.ppo.normalize_obs);
        ck.load_agent(&mut agent)?;
        agent.set_frozen(true);
        agent.reset_history(&*task);

        let model = task.loco().envs()[0].data().model().clone();
        let frames = scene::body_frames(&model);
        let term_names = task.loco().shared().rewards.names();
        let dt = task.loco().shared().dt;
        let mut metadata = BTreeMap::from([
            ("checkpoint".into(), ck.path.display().to_string()),
            ("checkpoint_iteration".into(), ck.meta.iteration.to_string()),
            ("terrain".into(), o.terrain.name().to_string()),
            (
                "level".into(),
                lane.map_or("plane".into(), |_| level.to_string()),
            ),
            ("commanded_speed".into(), speed.to_string()),
            ("seconds".into(), o.seconds.to_string()),
            ("seed".into(), o.seed.to_string()),
            ("full_collision".into(), o.full_collision.to_string()),
            (
                "lane_lookahead".into(),
                o.lane_lookahead.map_or("none".into(), |l| l.to_string()),
            ),
            ("start_ns".into(), START_NS.to_string()),
            ("control_dt".into(), dt.to_string()),
            ("mujoco_version".into(), crate::sim::mujoco_version()),
            (
                "writer".into(),
                format!("dreampolicy {}", env!("CARGO_PKG_VERSION")),
            ),
        ]);
        let world_model = task.world_model().map(String::from);
        let plans = world_model.is_some();
        if let Some(wm) = world_model {
            metadata.insert("world_model".into(), wm);
        }
        let mut file = match mcap {
            Some(path) => PlayFile::create(path, metadata, &term_names, plans)?,
            None => PlayFile::discard(),
        };

        // the scene, once, at frame 0
        let t0 = Time::from_nanos(START_NS);
        let robot = SceneUpdate {
            deletions: Vec::new(),
            entities: scene::robot_entities(&model, t0),
        };
        file.write(Topic::Robot, START_NS, &robot)?;
        let spawn = task.loco().envs()[0].spawn();
        let ground = match lane {
            Some(l) => scene::lane_entity(l.map(), 1.0, t0),
            None => {
                let reach = speed * o.seconds;
                scene::plane_entity([reach.min(0.0) - 5.0, reach.max(0.0) + 5.0], t0)
            }
        };
        file.write(
            Topic::Terrain,
            START_NS,
            &SceneUpdate {
                deletions: Vec::new(),
                entities: vec![ground],
            },
        )?;

        let dt_ns = (dt * 1e9).round() as u64;
        let max_steps = ((o.seconds / dt).round() as u64).max(1);
        let mut prev_sums = task.loco().envs()[0].episode_sums.clone();
        let mut terms = BTreeMap::new();
        let (mut ret, mut speed_sum, mut ending, mut steps) = (0.0, 0.0, Ending::TimeUp, 0);
        let weight = task.loco().shared().scene.robot_weight;
        let mut distance = write_frame(&mut file, task.loco(), &frames, 0, dt, weight, spawn)?;
        write_plan(&mut file, task, START_NS)?;
        sink.frame(task.loco(), 0)?;
        for k in 1..=max_steps {
            agent.step_mean(task);
            steps = k;
            let out = task.outcomes()[0];
            let e = &task.loco().envs()[0];
            if out.episode_done {
                ending = if out.blowup {
                    Ending::BlowUp
                } else if out.terminated {
                    Ending::Fell
                } else {
                    Ending::LeftMap
                };
                let end = e.last_episode_end();
                distance = end.base_pos[0] - end.spawn[0];
                ret += out.reward as f64;
                break;
            }
            ret += out.reward as f64;
            speed_sum += e.state().base_lin_vel_world[0];
            for ((name, now), before) in term_names.iter().zip(&e.episode_sums).zip(&prev_sums) {
                terms.insert(*name, round6(now - before));
            }
            prev_sums.copy_from_slice(&e.episode_sums);
            let t = START_NS + k * dt_ns;
            file.write(
                Topic::Reward,
                t,
                &RewardMsg {
                    step: k,
                    total: round6(out.reward as f64),
                    r#return: round6(ret),
                    terms: &terms,
                },
            )?;
            distance = write_frame(&mut file, task.loco(), &frames, k, dt, weight, spawn)?;
            write_plan(&mut file, task, t)?;
            sink.frame(task.loco(), k)?;
        }
        let written = file.count(Topic::State);
        let file_bytes = file.finish()?;
        let lane_length = lane.map(|l| l.length());
        Ok(PlaySummary {
            out: o.out.display().to_string(),
            terrain: o.terrain.name().to_string(),
            level: lane.map(|_| level),
            table: lane.map(|_| crate::eval::eval_table_name(cfg).to_string()),
            lane_length,
            commanded_speed: speed,
            steps,
            frames: written,
            seconds: steps as f64 * dt,
            distance,
            mean_forward_speed: speed_sum / (written.max(2) - 1) as f64,
            fell: matches!(ending, Ending::Fell | Ending::BlowUp),
            ending,
            reached_goal: lane_length.map(|l| distance >= l),
            total_reward: ret,
            bodies: frames.len() - 1,
            file_bytes,
            full_collision: o.full_collision,
            seed: o.seed,
            checkpoint: ck.path.display().to_string(),
        })
    }
}

/// Colors of the plan's spheres: pelvis, left foot, right foot.
const PLAN_COLORS: [foxglove::Color; 3] = [
    foxglove::Color::rgb(0.2, 0.4, 1.0),
    foxglove::Color::rgb(1.0, 0.3, 0.2),
    foxglove::Color::rgb(0.2, 0.8, 0.3),
];

/// `/plan` at `t_ns`: one entity `plan` (replacing the last one) with a sphere
/// for the pelvis and each foot of every predicted state, fading along the
/// horizon (nothing when the task has no plan).
fn write_plan<T: PlayTask>(file: &mut PlayFile, task: &mut T, t_ns: u64) -> Result<(), PlayError> {
    let Some(poses) = task.plan_poses() else {
        return Ok(());
    };
    let stamp = Time::from_nanos(t_ns);
    let mut entity = foxglove::SceneEntity::new(stamp, WORLD, "plan", false);
    let h = poses.len().max(1) as f64;
    for (k, p) in poses.iter().enumerate() {
        let fade = 1.0 - 0.7 * k as f64 / h;
        for (at, (color, d)) in [p.pelvis, p.left_foot, p.right_foot]
            .into_iter()
            .zip(PLAN_COLORS.into_iter().zip([0.08, 0.05, 0.05]))
        {
            entity.spheres.push(foxglove::SpherePrimitive {
                pose: foxglove::Pose::at(at.map(round5)),
                size: Vector3::new([d; 3]),
                color: foxglove::Color { a: fade, ..color },
            });
        }
    }
    file.write(
        Topic::Plan,
        t_ns,
        &SceneUpdate {
            deletions: Vec::new(),
            entities: vec![entity],
        },
    )
}

/// `/command` message.
#[derive(Serialize)]
struct CommandMsg {
    vx: f64,
    vy: f64,
    yaw_rate: f64,
}

/// `/state` message (fields: [`file::STATE_FIELDS`]).
#[derive(Serialize)]
struct StateMsg {
    step: u64,
    time: f64,
    x: f64,
    y: f64,
    z: f64,
    distance: f64,
    base_height: f64,
    vx: f64,
    vy: f64,
    vz: f64,
    vx_world: f64,
    yaw_rate: f64,
    roll: f64,
    pitch: f64,
    yaw: f64,
    left_contact: u8,
    right_contact: u8,
    feet_force: f64,
}

/// `/reward` message (fields: [`file::REWARD_FIELDS`] and `terms`).
#[derive(Serialize)]
struct RewardMsg<'a> {
    step: u64,
    total: f64,
    r#return: f64,
    terms: &'a BTreeMap<&'static str, f64>,
}

/// Write frame `k` (`/tf`, `/state`, `/command`) of env 0; the distance walked.
fn write_frame(
    file: &mut PlayFile,
    env: &VecEnv,
    frames: &[String],
    k: u64,
    dt: f64,
    weight: f64,
    spawn: [f64; 3],
) -> Result<f64, PlayError> {
    let t = START_NS + k * (dt * 1e9).round() as u64;
    let stamp = Time::from_nanos(t);
    let e = &env.envs()[0];
    let d = e.data();
    let (xpos, xquat) = (d.xpos(), d.xquat());
    let tf = FrameTransforms {
        transforms: (1..frames.len())
            .map(|b| FrameTransform {
                timestamp: stamp,
                parent_frame_id: WORLD,
                child_frame_id: &frames[b],
                translation: Vector3::new(xpos[b].map(round5)),
                rotation: Quaternion::from_mujoco(xquat[b].map(round6)),
            })
            .collect(),
    };
    file.write(Topic::Tf, t, &tf)?;
    let s = e.state();
    let [roll, pitch, yaw] = crate::env::state::rpy(&s.base_rot);
    let distance = s.base_pos[0] - spawn[0];
    let state = StateMsg {
        step: k,
        time: round6(k as f64 * dt),
        x: round5(s.base_pos[0]),
        y: round5(s.base_pos[1]),
        z: round5(s.base_pos[2]),
        distance: round5(distance),
        base_height: round5(s.base_height),
        vx: round5(s.base_lin_vel[0]),
        vy: round5(s.base_lin_vel[1]),
        vz: round5(s.base_lin_vel[2]),
        vx_world: round5(s.base_lin_vel_world[0]),
        yaw_rate: round5(s.base_ang_vel[2]),
        roll: round6(roll),
        pitch: round6(pitch),
        yaw: round6(yaw),
        left_contact: s.feet_contact[0] as u8,
        right_contact: s.feet_contact[1] as u8,
        feet_force: round5((s.feet_force[0][2] + s.feet_force[1][2]) / weight),
    };
    file.write(Topic::State, t, &state)?;
    let c = s.command;
    file.write(
        Topic::Command,
        t,
        &CommandMsg {
            vx: round5(c[0]),
            vy: round5(c[1]),
            yaw_rate: round5(c[2]),
        },
    )?;
    Ok(distance)
}
