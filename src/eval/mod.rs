//! Evaluation on the paper's 10 m lanes: success rate (reaching the end line
//! without a fall, within the time limit), completion rate (distance walked
//! before a fall or the time limit / lane length), velocity-tracking error and
//! falls, for a checkpoint's deterministic policy.
//!
//! The evaluation scene is the project's default physics (full collisions,
//! MuJoCo's default solver, no domain randomization, no pushes) unless the
//! training scene is asked for: a walker trained on the feet-only scene must
//! pass on the full one (sim-to-sim). Commands: forward speed drawn per episode
//! from `eval.lin_vel_x`, no sideways speed, heading held along the lane.
use serde::Serialize;

pub mod sim2sim;

use crate::env::config::{CollisionMode, EnvConfig, Integrator, TerrainMode};
use crate::rl::config::{EvalConfig, ExperimentConfig};
use std::sync::Arc;

use crate::env::{Scene, VecEnv};
use crate::rl::checkpoint::Checkpoint;
use crate::rl::{Agent, RlError, VecTask};
use crate::terrain::{Lane, TerrainKind, TerrainMap};

/// What an evaluation measured.
#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    pub terrain: String,
    pub episodes: usize,
    pub success_rate: f64,
    pub completion_rate: f64,
    /// Mean |v_cmd - v| of the planar base velocity over every control step (m/s).
    pub vel_tracking_error: f64,
    pub falls: usize,
    pub timeouts: usize,
    /// The falls by the termination condition that ended them.
    pub fall_causes: FallCauses,
    /// Mean commanded speed (m/s) and mean distance along the lane (m) of the
    /// walks that fell (NaN without a fall): whether the falls come with the
    /// fast commands, and where on the lane.
    pub falls_mean_commanded_speed: f64,
    pub falls_mean_distance: f64,
    /// Mean |lateral offset| of the pelvis from its spawn point (the lane's
    /// centre line) when a walk fell (m; NaN without a fall): a fall off a
    /// bridge's side or a drift off the lane shows here, a fall in place does not.
    pub falls_mean_abs_lateral_offset: f64,
    /// What the feet did in the second before each fall, beside how often the
    /// same happens in any second of the counted walks.
    pub fall_precursors: FallPrecursors,
    /// Mean |yaw-rate command - pelvis yaw rate| over every control step
    /// (rad/s): how closely the heading controller's (or a cell's fixed)
    /// yaw-rate command is followed.
    pub yaw_rate_tracking_error: f64,
    /// Mean commanded and actual pelvis yaw rate over every control step
    /// (rad/s; positive turns left).
    pub mean_commanded_yaw_rate: f64,
    pub mean_yaw_rate: f64,
    /// Mean forward speed along the lane over all episodes (m/s).
    pub mean_forward_speed: f64,
    pub mean_commanded_speed: f64,
    /// The gait's foot clearance: ankle height at the top of each swing (a
    /// foot's highest point between lift-off and touchdown, over swings of at
    /// least [`MIN_SWING_STEPS`] control steps) above the ground it stepped
    /// over, the higher of the ground at lift-off and at touchdown (a step up
    /// is measured against the upper tread), averaged over the swings of both
    /// feet (m; NaN without one). A swing whose lift-off or touchdown has the
    /// ankle more than [`OVER_GROUND`] above the ground under it (the ankle
    /// hangs over a pit or an edge, so the ground under it is not what the
    /// foot stands on) is left out.
    pub swing_peak_height: f64,
    /// Mean ankle height above the ground while a foot is in contact (m): the
    /// sole's offset, so that `swing_peak_height - stance_foot_height` is the
    /// clearance of the sole (contacts with the ankle over a pit left out).
    pub stance_foot_height: f64,
    /// The sole's rise at the top of each swing above where it took off and
    /// landed: ankle z at the top - the higher of the ankle's lowest z in the
    /// stance before (flat foot) and its z at touchdown (m, over the same swings; no ground lookup, so it means the
    /// same on every terrain; on a plane about `swing_peak_height -
    /// stance_foot_height`).
    pub swing_rise: f64,
    pub lane_length: f64,
    /// Curriculum level of the lanes (None for flat lanes, which are the plane).
    pub level: Option<usize>,
    /// The table the lanes were drawn from (None for flat lanes).
    pub table: Option<EvalTable>,
    /// The steering's lane-keeping lookahead (m); None: heading held along
    /// the lane.
    pub lane_lookahead: Option<f64>,
    pub full_collision: bool,
    pub checkpoint: String,
    pub checkpoint_iteration: usize,
    pub checkpoint_env_steps: u64,
    /// The checkpoints whose mean the evaluated one holds (`dreampolicy
    /// checkpoint average`); empty (and left out) for a checkpoint a run saved.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub checkpoint_averaged_from: Vec<String>,
    pub mujoco_version: String,
    pub seed: u64,
    /// The uneven blocks' heights (`terrain.uneven.heights` of the lanes'
    /// table) when the lanes hold uneven ground; None otherwise.
    pub uneven_heights: Option<crate::terrain::UnevenHeights>,
    /// How the robot touched the lanes' heightfield (`env.sim.hfield_contacts`
    /// of the eval scene) on non-flat lanes; None on the plane.
    pub hfield_contacts: Option<crate::env::config::HfieldContacts>,
    /// `eval.*` overrides of the checkpoint's stored config (`eval --set`),
    /// and a unified policy's inference keys (its world model and sampler).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub eval_sets: Vec<String>,
    /// Distinct lanes (terrain seeds) the episodes were shared over
    /// (`eval.lanes`, at most `episodes`); None on the plane. Episodes on one
    /// lane walk the same ground, so the rates' spread between evaluations
    /// follows the number of lanes more than the number of episodes.
    pub lanes: Option<usize>,
    /// Each lane's seed, episodes, successes and mean completion, in order
    /// (empty and left out on the plane).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub per_lane: Vec<LaneResult>,
}

/// Falls counted by [`FallCause`] (`contact`: a `termination.contact_bodies`
/// body on the ground; `tilt`: the pelvis past `termination.max_tilt_deg`;
/// `base_height`: the pelvis below `termination.min_base_height`), and
/// `blowup`: the physics went unstable (the env ends the episode as a
/// termination without a condition).
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct FallCauses {
    pub contact: usize,
    pub tilt: usize,
    pub base_height: usize,
    pub blowup: usize,
}

/// Foot events before the falls: for each, the fraction of falls with one in
/// the [`PRECURSOR_STEPS`] control steps before the fall (`before_fall`; a
/// fall's own stumbles and hops are in it), the fraction with one in the
/// window before that (`second_before_fall`, from `2 window_s` to `window_s`
/// before the fall: what happened before balance was lost), and the fraction
/// of all consecutive windows of as many counted steps that hold one
/// (`any_window`, the base rate to read both against; NaN without a fall or a
/// full window).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct FallPrecursors {
    pub window_s: f64,
    /// A foot in contact across a step's edge (the `feet_straddle` reward's
    /// condition: the terrain under the sole's corners spans more than
    /// `straddle_height`).
    pub straddle: Precursor,
    /// A foot's horizontal contact force above 4 times its vertical one
    /// (`feet_stumble`'s condition: a toe against a riser or a block's side).
    pub stumble: Precursor,
    /// Neither foot on the ground (a hop).
    pub flight: Precursor,
}

/// One row of [`FallPrecursors`].
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Precursor {
    pub before_fall: f64,
    pub second_before_fall: f64,
    pub any_window: f64,
}

/// Control steps of a [`FallPrecursors`] window (1 s at 50 Hz; two fit the
/// 128-bit history kept per walk).
pub const PRECURSOR_STEPS: u32 = 50;

/// One lane of an evaluation.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LaneResult {
    pub seed: u64,
    pub episodes: usize,
    pub successes: usize,
    pub completion: f64,
}

/// Shorter flights of a foot (a contact lost for a step or two while it
/// slides or bounces) are not swings for `swing_peak_height`.
pub const MIN_SWING_STEPS: u32 = 5;

/// An ankle this far above the ground under it in contact is over a pit or an
/// edge (in stance it sits ~0.04 m above the sole): `swing_peak_height` and
/// `stance_foot_height` leave such contacts out.
pub const OVER_GROUND: f64 = 0.2;

/// How to evaluate.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    pub terrain: TerrainKind,
    /// A combined lane: `terrain` in the first half of the walk, this kind in
    /// the second (the paper's pairs: [`crate::terrain::COMBINED_PAIRS`]).
    pub then: Option<TerrainKind>,
    pub episodes: usize,
    /// The project's default scene (full collisions, default solver) instead of
    /// the checkpoint's training scene.
    pub full_collision: bool,
    pub seed: u64,
    pub threads: usize,
    /// Lane difficulty level; `None` takes the config's `eval.level`.
    pub level: Option<usize>,
    /// The table the lanes are drawn from.
    pub table: EvalTable,
    /// Lane keeping: the heading command points at the lane's centre line this
    /// far ahead (m, `env.commands.lane_lookahead`); `None` holds the heading
    /// along the lane, and a sideways drift is not steered back.
    pub lane_lookahead: Option<f64>,
}

/// Which terrain table an evaluation's lanes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EvalTable {
    /// The config's `eval.terrain` (the paper's table unless it says
    /// otherwise): every policy measured on the same lanes.
    #[default]
    Eval,
    /// The checkpoint's own training curriculum (`env.terrain.map`): where its
    /// curriculum level means what the lane's level means.
    Training,
}

/// The env config of an evaluation, derived from the training config.
pub fn eval_env_config(cfg: &ExperimentConfig, o: &EvalOptions) -> EnvConfig {
    let e = &cfg.eval;
    let mut env = cfg.env.clone();
    env.n_envs = e.n_envs.min(o.episodes.max(1) as i64);
    env.threads = o.threads as i64;
    env.seed = o.seed;
    env.episode_length_s = e.time_limit_s;
    env.domain_rand.enabled = false;
    env.init.yaw = [0.0, 0.0];
    let c = &mut env.commands;
    c.lin_vel_x = e.lin_vel_x;
    c.lin_vel_y = [0.0, 0.0];
    c.heading_command = true;
    c.heading = [0.0, 0.0];
    c.resample_time_s = e.time_limit_s * 2.0;
    c.min_norm = 0.0;
    c.lane_lookahead = o.lane_lookahead;
    scene_protocol(&mut env, o.full_collision, e);
    env.terrain.mode = if o.terrain == TerrainKind::Flat {
        TerrainMode::Plane
    } else {
        TerrainMode::Map
    };
    env.terrain.curriculum = false;
    env.terrain.flat_on_plane = false;
    env
}

/// The scene `eval` and `play` walk a lane in: with `full_collision` the
/// project's default scene (every collision geom, MuJoCo's default solver, the
/// implicit integrator, default terminations and heightfield contacts), then
/// `eval.hfield_contacts` when the config names one.
pub fn scene_protocol(env: &mut EnvConfig, full_collision: bool, e: &EvalConfig) {
    if full_collision {
        let d = crate::env::config::SimConfig::default();
        env.sim.collision = CollisionMode::Full;
        env.sim.iterations = d.iterations;
        env.sim.ls_iterations = d.ls_iterations;
        env.sim.integrator = Integrator::Implicit;
        env.sim.hfield_contacts = d.hfield_contacts;
        env.termination = Default::default();
    }
    if let Some(h) = e.hfield_contacts {
        env.sim.hfield_contacts = h;
    }
}

/// Evaluate the checkpoint's policy on `o.episodes` lanes: flat lanes are the
/// plane; any other kind is walked on [`crate::terrain::TerrainMap::lane`]s of
/// `eval.terrain` (the paper's table unless the config says otherwise) at `eval.level`, `eval.lanes` different lanes
/// (seeds `o.seed`, `o.seed + 1`, ...) sharing the episodes evenly.
pub fn evaluate(ck: &Checkpoint, o: &EvalOptions) -> Result<EvalReport, RlError> {
    let mut cfg = ck.config()?;
    if o.table == EvalTable::Training {
        cfg.eval.terrain = cfg.env.terrain.map.clone();
    }
    let env_cfg = eval_env_config(&cfg, o);
    evaluate_in(ck, &cfg, &env_cfg, o)
}

/// [`evaluate`] in a given env (the checkpoint's `cfg` turned into an eval env
/// by [`eval_env_config`], then changed: the sim-to-sim matrix's cells).
pub fn evaluate_in(
    ck: &Checkpoint,
    cfg: &ExperimentConfig,
    env_cfg: &EnvConfig,
    o: &EvalOptions,
) -> Result<EvalReport, RlError> {
    if o.episodes == 0 {
        return Err(RlError::Invalid("--episodes must be at least 1".into()));
    }
    env_cfg.validate()?;
    let length = cfg.eval.lane_length;
    let level = o.level.unwrap_or(cfg.eval.level);
    let mut t = Tally::default();
    let mut per_lane = Vec::new();
    if o.terrain == TerrainKind::Flat {
        let env = VecEnv::new(env_cfg)?;
        run_in(ck, cfg, env, o.episodes, length, &mut t)?;
    } else {
        let lanes = cfg.eval.lanes.clamp(1, o.episodes);
        for k in 0..lanes {
            let count = o.episodes / lanes + usize::from(k < o.episodes % lanes);
            let seed = o.seed.wrapping_add(k as u64);
            let lane = eval_lane_then(cfg, o.terrain, o.then, level, seed)?;
            let mut lane_cfg = env_cfg.clone();
            lane_cfg.n_envs = env_cfg.n_envs.min(count as i64);
            lane_cfg.seed = o.seed.wrapping_add(1000 * k as u64);
            let scene = Scene::with_terrain(&lane_cfg, Some(Arc::new(lane.map().clone())))?;
            let env = VecEnv::with_scene(&lane_cfg, scene)?;
            let (done, successes, completion) = (t.done, t.successes, t.completion);
            run_in(ck, cfg, env, count, length, &mut t)?;
            per_lane.push(LaneResult {
                seed,
                episodes: t.done - done,
                successes: t.successes - successes,
                completion: (t.completion - completion) / (t.done - done).max(1) as f64,
            });
        }
    }
    let d = t.done as f64;
    Ok(EvalReport {
        terrain: lane_name(o.terrain, o.then),
        episodes: t.done,
        success_rate: t.successes as f64 / d,
        completion_rate: t.completion / d,
        vel_tracking_error: t.per_step(t.err_sum),
        yaw_rate_tracking_error: t.per_step(t.yaw_err_sum),
        mean_commanded_yaw_rate: t.per_step(t.yaw_cmd_sum),
        mean_yaw_rate: t.per_step(t.yaw_rate_sum),
        falls: t.falls,
        timeouts: t.timeouts,
        fall_causes: t.causes,
        falls_mean_commanded_speed: t.fall_cmd_sum / t.falls as f64,
        falls_mean_distance: t.fall_dist_sum / t.falls as f64,
        falls_mean_abs_lateral_offset: t.fall_lat_sum / t.falls as f64,
        fall_precursors: t.precursors(env_cfg.sim.control_dt()),
        mean_forward_speed: t.fwd_sum / d,
        mean_commanded_speed: t.cmd_sum / d,
        swing_peak_height: t.swing_sum / t.swings as f64,
        stance_foot_height: t.stance_sum / t.stance_n as f64,
        swing_rise: t.rise_sum / t.rises as f64,
        lane_length: length,
        level: (o.terrain != TerrainKind::Flat).then_some(level),
        table: (o.terrain != TerrainKind::Flat).then_some(o.table),
        lane_lookahead: o.lane_lookahead,
        full_collision: o.full_collision,
        checkpoint: ck.path.display().to_string(),
        checkpoint_iteration: ck.meta.iteration,
        checkpoint_env_steps: ck.meta.env_steps,
        checkpoint_averaged_from: ck.meta.averaged_from.clone(),
        mujoco_version: crate::sim::mujoco_version(),
        seed: o.seed,
        uneven_heights: [Some(o.terrain), o.then]
            .contains(&Some(TerrainKind::Uneven))
            .then_some(cfg.eval.terrain.uneven.heights),
        hfield_contacts: (o.terrain != TerrainKind::Flat).then_some(env_cfg.sim.hfield_contacts),
        eval_sets: ck.eval_sets().to_vec(),
        lanes: (o.terrain != TerrainKind::Flat).then_some(per_lane.len()),
        per_lane,
    })
}

/// The lane `evaluate` walks for lane seed `seed` at `level` of the config's
/// `eval.terrain` (lane `k` of an evaluation has seed `o.seed + k`): `play`
/// draws the same lanes, so that the rollout a person watches is a scored one.
/// The terrain is drawn over at least 1 m; success is measured at
/// `eval.lane_length`.
pub fn eval_lane(
    cfg: &ExperimentConfig,
    kind: TerrainKind,
    level: usize,
    seed: u64,
) -> Result<Lane, RlError> {
    eval_lane_then(cfg, kind, None, level, seed)
}

/// [`eval_lane`], or with `then` the combined lane: `first` in the first half
/// of the walk, `then` in the second (each segment at least 1 m).
pub fn eval_lane_then(
    cfg: &ExperimentConfig,
    first: TerrainKind,
    then: Option<TerrainKind>,
    level: usize,
    seed: u64,
) -> Result<Lane, RlError> {
    let map_cfg = &cfg.eval.terrain;
    if level > map_cfg.max_level() {
        return Err(RlError::Invalid(format!(
            "level {level} is above {}'s top level {}",
            eval_table_name(cfg),
            map_cfg.max_level()
        )));
    }
    let segments = if then.is_some() { 2.0 } else { 1.0 };
    let length = cfg
        .eval
        .lane_length
        .max(segments * crate::terrain::lane::MIN_SEGMENT_LENGTH);
    let width = map_cfg.tile_width;
    match then {
        None => TerrainMap::lane(map_cfg, first, level, length, width, seed),
        Some(second) => {
            TerrainMap::combined_lane(map_cfg, first, second, level, length, width, seed)
        }
    }
    .map_err(|e| RlError::Invalid(format!("building the {} lane: {e}", lane_name(first, then))))
}

/// A lane's name: its kind, or `first&second` for a combined lane.
pub fn lane_name(first: TerrainKind, then: Option<TerrainKind>) -> String {
    match then {
        None => first.name().to_string(),
        Some(t) => format!("{}&{}", first.name(), t.name()),
    }
}

/// What `eval.terrain` is, in words: "the paper's table" when the config keeps
/// the default, "the training curriculum's table" when it is the config's own
/// `env.terrain.map` (`eval --table training`), else "the config's eval.terrain".
pub fn eval_table_name(cfg: &ExperimentConfig) -> &'static str {
    if cfg.eval.terrain == crate::terrain::TerrainConfig::default() {
        "the paper's table"
    } else if cfg.eval.terrain == cfg.env.terrain.map {
        "the training curriculum's table"
    } else {
        "the config's eval.terrain"
    }
}

/// Run `episodes` counted episodes of the checkpoint's deterministic policy on
/// `env`, adding them to `t`. An episode succeeds when the base is `length`
/// metres past its spawn point along x.
fn run_episodes<T: EvalTask>(
    ck: &Checkpoint,
    cfg: &ExperimentConfig,
    task: &mut T,
    episodes: usize,
    length: f64,
    t: &mut Tally,
) -> Result<(), RlError> {
    let n = task.n_envs();
    // the env's seed (the evaluation's, per lane) seeds sampled actions too
    let seed = task.loco().shared().cfg.seed;
    let mut actor = Actor::of(ck, cfg, &*task, seed)?;
    let target = t.done + episodes;

    // env i runs a counted episode while counted[i]; new episodes are counted
    // until `episodes` have started
    let mut started = n.min(episodes);
    let mut counted: Vec<bool> = (0..n).map(|i| i < started).collect();
    let (mut steps, mut speed) = (vec![0u64; n], vec![0.0f64; n]);
    let mut peak = vec![[Swing::default(); 2]; n];
    let mut watch = vec![Watch::default(); n];
    while t.done < target {
        actor.step(task);
        for i in 0..n {
            let out = task.outcomes()[i];
            let e = &task.loco().envs()[i];
            let end = if out.episode_done {
                // the env has reset: the episode's end is what it remembered
                let last = e.last_episode_end();
                let dist = last.base_pos[0] - last.spawn[0];
                if counted[i] && out.terminated {
                    let lateral = (last.base_pos[1] - last.spawn[1]).abs();
                    t.fell(last.fall, [dist, lateral], last.command[0], &watch[i]);
                }
                Some((
                    if out.terminated {
                        Ending::Fall
                    } else {
                        Ending::Timeout
                    },
                    dist,
                    last.command[0],
                ))
            } else {
                let s = e.state();
                if counted[i] {
                    steps[i] += 1;
                    t.err_sum +=
                        (s.command[0] - s.base_lin_vel[0]).hypot(s.command[1] - s.base_lin_vel[1]);
                    t.err_n += 1;
                    t.yaw_err_sum += (s.command[2] - s.base_ang_vel[2]).abs();
                    t.yaw_cmd_sum += s.command[2];
                    t.yaw_rate_sum += s.base_ang_vel[2];
                    speed[i] += s.base_lin_vel_world[0];
                    t.feet(s, &mut peak[i]);
                    t.watch(s, &mut watch[i]);
                }
                let dist = s.base_pos[0] - e.spawn()[0];
                (dist >= length).then_some((Ending::Success, length, s.command[0]))
            };
            let Some((end, dist, cmd)) = end else {
                continue;
            };
            if counted[i] {
                t.add(
                    end,
                    (dist / length).clamp(0.0, 1.0),
                    speed[i] / steps[i].max(1) as f64,
                    cmd,
                );
            }
            counted[i] = started < episodes;
            started += counted[i] as usize;
            steps[i] = 0;
            speed[i] = 0.0;
            peak[i] = [Swing::default(); 2];
            watch[i] = Watch::default();
            if end == Ending::Success {
                task.restart(i);
                actor.restarted(i, task.obs());
            }
        }
    }
    Ok(())
}

/// What acts in an evaluation: a checkpoint's policy (its deterministic mean,
/// through its normalizers and history), or the world model of a controller
/// checkpoint (the w/o-GCRL baseline, `task: no_gcrl`).
enum Actor {
    /// The agent, and its Gaussian's sampler when it acts on samples
    /// (`eval.sample_actions`).
    Policy(Box<Agent>, Option<Box<Sampler>>),
    WorldModel(Box<crate::baselines::no_gcrl::WmController>),
}

/// Gaussian action samples for `eval.sample_actions`: a generator of its own
/// (parallel evaluations in one process do not share torch's global one) and
/// the frozen policy's std.
struct Sampler {
    rng: rand_chacha::ChaCha8Rng,
    std: Vec<f32>,
}

impl Actor {
    /// The actor of `ck` for `task`'s envs, started on their current states.
    fn of(
        ck: &Checkpoint,
        cfg: &ExperimentConfig,
        task: &dyn VecTask,
        seed: u64,
    ) -> Result<Actor, RlError> {
        if cfg.task == crate::rl::config::TaskKind::NoGcrl {
            let mut c = crate::baselines::no_gcrl::WmController::new(cfg, task.n_envs())?;
            c.reset_all(task);
            return Ok(Actor::WorldModel(Box::new(c)));
        }
        let mut agent = Agent::new(
            &cfg.policy,
            task.dims(),
            task.n_envs(),
            cfg.ppo.normalize_obs,
        );
        ck.load_agent(&mut agent)?;
        agent.set_frozen(true);
        agent.reset_history(task);
        let sampler = if cfg.eval.sample_actions {
            use rand::SeedableRng;
            // the frozen policy's std, read once
            let std = Vec::<f32>::try_from(&agent.policy.std().to_kind(tch::Kind::Float))
                .map_err(|e| RlError::Invalid(format!("the policy's action std: {e}")))?;
            Some(Box::new(Sampler {
                rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed),
                std,
            }))
        } else {
            None
        };
        Ok(Actor::Policy(Box::new(agent), sampler))
    }

    /// One control step of `task`.
    fn step(&mut self, task: &mut dyn VecTask) {
        match self {
            Actor::Policy(a, None) => {
                a.step_mean(task);
            }
            Actor::Policy(a, Some(smp)) => {
                use rand_distr::{Distribution, StandardNormal};
                a.prepare(&*task);
                let mut actions = a.act_mean();
                // one std per action dimension, the same for every env
                for (x, sd) in actions.iter_mut().zip(smp.std.iter().cycle()) {
                    let z: f32 = StandardNormal.sample(&mut smp.rng);
                    *x += sd * z;
                }
                task.step(&actions);
                a.after_step(&*task);
            }
            Actor::WorldModel(c) => {
                c.step(task);
            }
        }
    }

    /// Env `i` was restarted by the evaluation (it reached the end line).
    fn restarted(&mut self, i: usize, obs: &[f32]) {
        match self {
            Actor::Policy(a, _) => a.reset_history_env(i, obs),
            Actor::WorldModel(c) => c.reset_env(i, obs),
        }
    }
}

/// What an evaluation steps: the G1 env, or a unified policy's task around it
/// (the paper's inference loop: the world model plans from the robot's history
/// and the lane's scandots, the policy tracks the plan).
pub trait EvalTask: VecTask {
    /// The G1 env underneath (robot states, spawn points, episode ends).
    fn loco(&self) -> &VecEnv;
    /// Start env `i` on a new episode now.
    fn restart(&mut self, i: usize);
}

impl EvalTask for VecEnv {
    fn loco(&self) -> &VecEnv {
        self
    }
    fn restart(&mut self, i: usize) {
        self.reset_env(i);
    }
}

impl EvalTask for crate::unified::task::UnifiedTask {
    fn loco(&self) -> &VecEnv {
        self.env()
    }
    fn restart(&mut self, i: usize) {
        self.reset_env(i);
    }
}

/// Run `episodes` on `env`, through the unified task when the checkpoint is a
/// unified policy's.
fn run_in(
    ck: &Checkpoint,
    cfg: &ExperimentConfig,
    env: VecEnv,
    episodes: usize,
    length: f64,
    t: &mut Tally,
) -> Result<(), RlError> {
    if cfg.task == crate::rl::config::TaskKind::Unified {
        let mut task = crate::unified::task::UnifiedTask::with_env(cfg, env)?;
        run_episodes(ck, cfg, &mut task, episodes, length, t)
    } else {
        let mut env = env;
        run_episodes(ck, cfg, &mut env, episodes, length, t)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ending {
    Success,
    Fall,
    Timeout,
}

/// One foot's current swing in an evaluation.
#[derive(Debug, Clone, Copy, Default)]
struct Swing {
    /// Highest ankle z (world) and steps of the swing in progress (None in contact).
    peak: Option<(f64, u32)>,
    /// The foot's last stance: its lowest ankle z (the flat foot, before the
    /// heel lifts) and the ground under the foot at lift-off (None before the
    /// first: a swing the episode starts in is not counted).
    lift: Option<(f64, f64)>,
}

/// Running sums of an evaluation.
#[derive(Default)]
struct Tally {
    done: usize,
    successes: usize,
    falls: usize,
    timeouts: usize,
    completion: f64,
    err_sum: f64,
    err_n: u64,
    yaw_err_sum: f64,
    yaw_cmd_sum: f64,
    yaw_rate_sum: f64,
    fwd_sum: f64,
    cmd_sum: f64,
    swing_sum: f64,
    swings: u64,
    stance_sum: f64,
    stance_n: u64,
    rise_sum: f64,
    rises: u64,
    causes: FallCauses,
    fall_cmd_sum: f64,
    fall_dist_sum: f64,
    fall_lat_sum: f64,
    /// Full windows of [`PRECURSOR_STEPS`] counted steps, and those holding
    /// each foot event (straddle, stumble, flight).
    windows: u64,
    window_hits: [u64; 3],
    /// Falls with each foot event in the window before them, and in the
    /// window before that.
    fall_hits: [u64; 3],
    fall_hits_earlier: [u64; 3],
}

/// The foot events of one env's walk in progress: for each event, a bit per
/// counted step, the newest lowest (the last 2 [`PRECURSOR_STEPS`]), and the
/// events of the current window.
#[derive(Debug, Clone, Copy, Default)]
struct Watch {
    recent: [u128; 3],
    window: [bool; 3],
    window_steps: u64,
}

/// This step's foot events: a straddling foothold, a stumble, a flight (the
/// conditions of the rewards of the same names).
fn foot_events(s: &crate::env::state::EnvState) -> [bool; 3] {
    use crate::env::rewards::{feet_straddling, in_flight, stumbling};
    [feet_straddling(s) > 0, stumbling(s), in_flight(s)]
}

impl Tally {
    /// One counted step of an env's walk: its foot events.
    fn watch(&mut self, s: &crate::env::state::EnvState, w: &mut Watch) {
        let ev = foot_events(s);
        for j in 0..3 {
            w.recent[j] = (w.recent[j] << 1) | ev[j] as u128;
            w.window[j] |= ev[j];
        }
        w.window_steps += 1;
        if w.window_steps == PRECURSOR_STEPS as u64 {
            self.windows += 1;
            for j in 0..3 {
                self.window_hits[j] += w.window[j] as u64;
            }
            w.window = [false; 3];
            w.window_steps = 0;
        }
    }

    /// A counted walk fell.
    /// `at`: the distance along the lane and the |lateral offset| where it fell.
    fn fell(&mut self, cause: Option<crate::env::FallCause>, at: [f64; 2], cmd: f64, w: &Watch) {
        use crate::env::FallCause;
        match cause {
            Some(FallCause::Contact) => self.causes.contact += 1,
            Some(FallCause::Tilt) => self.causes.tilt += 1,
            Some(FallCause::BaseHeight) => self.causes.base_height += 1,
            None => self.causes.blowup += 1,
        }
        self.fall_cmd_sum += cmd;
        self.fall_dist_sum += at[0];
        self.fall_lat_sum += at[1];
        let window = (1u128 << PRECURSOR_STEPS) - 1;
        for j in 0..3 {
            self.fall_hits[j] += (w.recent[j] & window != 0) as u64;
            self.fall_hits_earlier[j] += ((w.recent[j] >> PRECURSOR_STEPS) & window != 0) as u64;
        }
    }

    /// The precursor table of the falls so far.
    fn precursors(&self, control_dt: f64) -> FallPrecursors {
        let row = |j: usize| Precursor {
            before_fall: self.fall_hits[j] as f64 / self.falls as f64,
            second_before_fall: self.fall_hits_earlier[j] as f64 / self.falls as f64,
            any_window: self.window_hits[j] as f64 / self.windows as f64,
        };
        FallPrecursors {
            window_s: PRECURSOR_STEPS as f64 * control_dt,
            straddle: row(0),
            stumble: row(1),
            flight: row(2),
        }
    }

    /// A sum over the counted control steps as a mean per step (NaN without one).
    fn per_step(&self, sum: f64) -> f64 {
        if self.err_n > 0 {
            sum / self.err_n as f64
        } else {
            f64::NAN
        }
    }

    /// One step of the feet: a swing's peak is counted at its touchdown.
    fn feet(&mut self, s: &crate::env::state::EnvState, swing: &mut [Swing; 2]) {
        for (k, w) in swing.iter_mut().enumerate() {
            let (z, ground) = (s.feet_pos[k][2], s.feet_ground[k]);
            if !s.feet_contact[k] {
                w.peak = Some(w.peak.map_or((z, 1), |(top, n)| (top.max(z), n + 1)));
                continue;
            }
            let grounded = z - ground <= OVER_GROUND;
            if grounded {
                self.stance_sum += z - ground;
                self.stance_n += 1;
            }
            let landed = w.peak.take();
            if let (Some((top, steps)), Some((lift_z, lift_ground))) = (landed, w.lift) {
                if steps >= MIN_SWING_STEPS {
                    self.rise_sum += top - lift_z.max(z);
                    self.rises += 1;
                    if grounded && lift_z - lift_ground <= OVER_GROUND {
                        self.swing_sum += top - lift_ground.max(ground);
                        self.swings += 1;
                    }
                }
            }
            // a new stance starts at touchdown; the lowest ankle z of a stance
            w.lift = Some(match (landed, w.lift) {
                (None, Some((low, _))) => (low.min(z), ground),
                _ => (z, ground),
            });
        }
    }

    fn add(&mut self, end: Ending, completion: f64, speed: f64, cmd: f64) {
        self.done += 1;
        match end {
            Ending::Success => self.successes += 1,
            Ending::Fall => self.falls += 1,
            Ending::Timeout => self.timeouts += 1,
        }
        self.completion += completion;
        self.fwd_sum += speed;
        self.cmd_sum += cmd;
    }
}

/// Parse a level list: `0-9` (inclusive range), `0,2,5`, or a mix (`0-3,7`).
pub fn parse_levels(text: &str) -> Result<Vec<usize>, String> {
    let num = |s: &str| {
        s.trim()
            .parse::<usize>()
            .map_err(|_| format!("'{}' in --levels is not a level (0, 1, ...)", s.trim()))
    };
    let mut levels = Vec::new();
    for part in text.split(',').filter(|p| !p.trim().is_empty()) {
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (num(a)?, num(b)?);
                if a > b {
                    return Err(format!("--levels range {a}-{b} runs backwards"));
                }
                levels.extend(a..=b);
            }
            None => levels.push(num(part)?),
        }
    }
    if levels.is_empty() {
        return Err("--levels is empty; give e.g. 0-9 or 0,3,5".into());
    }
    levels.sort_unstable();
    levels.dedup();
    Ok(levels)
}

/// One checkpoint's evaluation at each of `levels` on its terrain (`o.level`
/// is replaced by each level in turn): the level sweep of a specialist.
pub fn level_sweep(
    ck: &Checkpoint,
    o: &EvalOptions,
    levels: &[usize],
) -> Result<Vec<EvalReport>, RlError> {
    if o.terrain == TerrainKind::Flat {
        return Err(RlError::Invalid(
            "a level sweep needs a terrain with levels; flat lanes are the plane".into(),
        ));
    }
    levels
        .iter()
        .map(|&level| {
            evaluate(
                ck,
                &EvalOptions {
                    level: Some(level),
                    ..o.clone()
                },
            )
        })
        .collect()
}
