//! One G1 locomotion environment.
//!
//! The order of one control step ([`LocoEnv::step`]), in one place:
//! 1. clip the action, push it into the latency buffer, take the delayed one;
//! 2. `ctrl = q_default + action_scale[j] * a_delayed` (MuJoCo's PD actuators, torques
//!    clipped to the effort limits by `forcerange`);
//! 3. `decimation` physics steps, each checked for a blow-up;
//! 4. derive the state (`EnvState`): pelvis, joints, torques, feet contacts and air
//!    time, collisions, terrain under the robot;
//! 5. steer the yaw-rate command toward the heading (heading mode);
//! 6. terminations (fall: height, tilt, fatal body contact) and truncations
//!    (time-out, edge of the map);
//! 7. reward terms (`weight * term * dt`), added to the episode sums;
//! 8. timers: command resampling, pushes;
//! 9. if the episode ended: keep the final observation, update the curriculum,
//!    reset;
//! 10. observations (actor with noise, critic, scandots).
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::obs;
use super::scene::BodyClass;
use super::state::{rotate_inv, rpy, wrap_angle, EnvState};
use super::{EnvShared, Outcome};
use crate::env::config::TerrainMode;
use crate::robot::NUM_JOINTS;
use crate::sim::{contact_geoms, Data, SimError};

/// Spacing (m) of the support samples ahead of a foot (`swing_lookahead`).
const LOOKAHEAD_STEP: f64 = 0.05;

/// Longest supported action latency (control steps).
pub const MAX_LATENCY: usize = 8;

/// One environment: its MuJoCo state, its RNG and its episode bookkeeping.
pub struct LocoEnv {
    data: Data,
    pub(crate) bucket: usize,
    rng: ChaCha8Rng,
    pub(crate) state: EnvState,
    step_in_episode: u64,
    actions: [[f64; NUM_JOINTS]; MAX_LATENCY + 1],
    latency: usize,
    pub(crate) spawn: [f64; 3],
    /// The drawn heading (heading mode); the yaw target adds lane keeping.
    heading: Option<f64>,
    pub(crate) level: usize,
    pub(crate) col: usize,
    pub(crate) episode_sums: Vec<f64>,
    last_sums: Vec<f64>,
    goal_x: f64,
    past_goal: bool,
    fatal_contact: bool,
    /// Bound to a Flat column and stepping on the plane models (scene doc).
    on_plane: bool,
    /// Pelvis position, spawn point and command when the last episode ended.
    last_end: EpisodeEnd,
}

/// Where the last finished episode ended (evaluation reads it after the reset).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpisodeEnd {
    pub base_pos: [f64; 3],
    pub spawn: [f64; 3],
    pub command: [f64; 3],
    /// What ended it when it was a fall (None: a time-out, the map's edge, a
    /// blow-up or a reset from outside).
    pub fall: Option<FallCause>,
}

/// The termination condition that ended an episode as a fall, the first that
/// holds in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FallCause {
    /// A `termination.contact_bodies` body touched the ground.
    Contact,
    /// The pelvis tilted past `termination.max_tilt_deg`.
    Tilt,
    /// The pelvis sank below `termination.min_base_height` above the terrain.
    BaseHeight,
}

/// Where one env writes its outputs (its rows of the batch buffers).
pub struct EnvOut<'a> {
    pub obs: &'a mut [f32],
    pub critic: &'a mut [f32],
    pub scan: &'a mut [f32],
    pub final_obs: &'a mut [f32],
    pub final_critic: &'a mut [f32],
    pub final_scan: &'a mut [f32],
}

impl LocoEnv {
    /// A new env bound to `bucket`, seeded by `seed`, placed and reset.
    pub fn new(sh: &EnvShared, index: usize, seed: u64) -> Result<LocoEnv, SimError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let bucket = rng.random_range(0..sh.scene.models.len());
        let (level, col) = match &sh.scene.terrain {
            Some(map) => (
                rng.random_range(0..=sh.cfg.terrain.init_max_level.min(map.num_levels() - 1)),
                index % map.num_cols(),
            ),
            None => (0, 0),
        };
        let on_plane = sh.scene.column_on_plane(col);
        let model = if on_plane {
            &sh.scene.plane_models[bucket]
        } else {
            &sh.scene.models[bucket]
        };
        let mut data = Data::new(model.clone())?;
        data.set_max_qvel(sh.cfg.sim.max_qvel);
        let g1 = &sh.scene.g1;
        let mut env = LocoEnv {
            data,
            bucket,
            rng,
            state: EnvState {
                qd_limit: g1.velocity_limit,
                tau_limit: g1.effort_limit,
                ..EnvState::new(sh.dt, g1.default_pos, g1.joint_range)
            },
            step_in_episode: 0,
            actions: [[0.0; NUM_JOINTS]; MAX_LATENCY + 1],
            latency: 0,
            spawn: [0.0; 3],
            heading: None,
            level,
            col,
            episode_sums: vec![0.0; sh.rewards.len()],
            last_sums: vec![0.0; sh.rewards.len()],
            goal_x: f64::INFINITY,
            past_goal: false,
            fatal_contact: false,
            on_plane,
            last_end: EpisodeEnd::default(),
        };
        env.reset(sh);
        Ok(env)
    }

    pub fn data(&self) -> &Data {
        &self.data
    }

    pub(crate) fn data_mut(&mut self) -> &mut Data {
        &mut self.data
    }

    /// Raw MuJoCo pointers of this env (benchmark baselines only).
    pub fn raw_ptrs(&mut self) -> (*const mujoco_sys::mjModel, *mut mujoco_sys::mjData) {
        self.data.as_raw_ptrs()
    }

    pub fn state(&self) -> &EnvState {
        &self.state
    }

    pub fn terrain_level(&self) -> usize {
        self.level
    }

    /// The map column (terrain kind) the env is bound to (0 on a plane scene).
    pub fn column(&self) -> usize {
        self.col
    }

    /// Domain-randomization bucket (index into `Scene::buckets`).
    pub fn bucket(&self) -> usize {
        self.bucket
    }

    /// Action latency of the current episode (control steps).
    pub fn latency(&self) -> usize {
        self.latency
    }

    /// Where the last finished episode ended.
    pub fn last_episode_end(&self) -> EpisodeEnd {
        self.last_end
    }

    /// Where the current episode started.
    pub fn spawn(&self) -> [f64; 3] {
        self.spawn
    }

    /// Per-term reward sums of the last finished episode (order of `RewardSet::names`).
    pub fn last_episode_sums(&self) -> &[f64] {
        &self.last_sums
    }

    /// RNG state and level (see `env::task::EnvSnapshot`).
    pub fn snapshot(&self) -> super::task::EnvSnapshot {
        super::task::EnvSnapshot::new(&self.rng, self.level)
    }

    /// Restore a snapshot's RNG and level.
    pub fn restore(&mut self, sh: &EnvShared, s: &super::task::EnvSnapshot) -> Result<(), String> {
        let levels = sh.scene.terrain.as_ref().map_or(1, |m| m.num_levels());
        if s.level >= levels {
            return Err(format!("level {} of a map with {levels} levels", s.level));
        }
        self.rng = s.rng();
        self.level = s.level;
        Ok(())
    }

    /// Reset and write the first observations.
    pub fn reset_and_observe(
        &mut self,
        sh: &EnvShared,
        obs: &mut [f32],
        critic: &mut [f32],
        scan: &mut [f32],
    ) {
        self.reset(sh);
        self.write_obs(sh, obs, critic, scan);
    }

    /// Put the robot at its tile's spawn point in the default pose and start an episode.
    pub fn reset(&mut self, sh: &EnvShared) {
        let g1 = &sh.scene.g1;
        self.spawn = match &sh.scene.terrain {
            Some(map) => {
                let [x, y, _] = map.spawn(self.level, self.col);
                [x, y, self.ground(sh, x, y)]
            }
            None => [0.0, 0.0, 0.0],
        };
        self.goal_x = match &sh.scene.terrain {
            Some(map) => map.tile_bounds(self.level, self.col).x[1],
            None => f64::INFINITY,
        };
        let init = &sh.cfg.init;
        let yaw = self.rng.random_range(init.yaw[0]..=init.yaw[1]);
        self.data
            .reset_keyframe(g1.stand_key)
            .expect("stand keyframe resolved at build");
        {
            let qpos = self.data.qpos_mut();
            qpos[0] = self.spawn[0];
            qpos[1] = self.spawn[1];
            qpos[2] = self.spawn[2] + g1.stand_height + init.height_offset;
            let (s, c) = (0.5 * yaw).sin_cos();
            qpos[3..7].copy_from_slice(&[c, 0.0, 0.0, s]);
        }
        for i in 0..NUM_JOINTS {
            let noise = self.rng.random_range(-1.0..=1.0) * init.joint_pos_noise;
            let [lo, hi] = g1.joint_range[i];
            self.data.qpos_mut()[g1.qpos_adr[i]] = (g1.default_pos[i] + noise).clamp(lo, hi);
            self.data.ctrl_mut()[g1.actuator[i]] = g1.default_pos[i];
        }
        self.data.forward();
        self.actions = [[0.0; NUM_JOINTS]; MAX_LATENCY + 1];
        let lat = sh.cfg.domain_rand.action_latency;
        self.latency = if sh.cfg.domain_rand.enabled {
            self.rng.random_range(lat[0]..=lat[1]).min(MAX_LATENCY)
        } else {
            0
        };
        self.step_in_episode = 0;
        self.past_goal = false;
        self.episode_sums.iter_mut().for_each(|s| *s = 0.0);
        self.state.action = [0.0; NUM_JOINTS];
        self.state.last_action = [0.0; NUM_JOINTS];
        self.state.last_last_action = [0.0; NUM_JOINTS];
        self.state.feet_air_time = [0.0; 2];
        self.state.feet_contact_time = [0.0; 2];
        self.state.terrain_level = self.level;
        self.resample_command(sh);
        self.derive_state(sh);
        // in heading mode the yaw rate follows the heading rule from the first
        // observation on (not the draw above), on this episode's yaw
        self.steer_heading(sh);
        self.state.feet_vel = [[0.0; 3]; 2];
        self.state.gait_phase = 0.0;
        self.state.last_qd = self.state.qd;
        self.state.last_torque = self.state.torque;
    }

    fn resample_command(&mut self, sh: &EnvShared) {
        let c = &sh.cfg.commands;
        let mut u = |r: [f64; 2]| self.rng.random_range(r[0]..=r[1]);
        let (vx, vy, wz) = (u(c.lin_vel_x), u(c.lin_vel_y), u(c.ang_vel_yaw));
        let heading = c.heading_command.then(|| u(c.heading));
        let planar = if vx.hypot(vy) < c.min_norm {
            (0.0, 0.0)
        } else {
            (vx, vy)
        };
        self.state.command = [planar.0, planar.1, wz];
        // the yaw target follows from it in `steer_heading`, which runs next
        self.heading = heading;
    }

    /// One control step (see the module doc for the order). Returns this step's
    /// reward and how the episode stands; writes observations into `out`.
    pub fn step(&mut self, sh: &EnvShared, action: &[f32], out: EnvOut<'_>) -> Outcome {
        let clip = sh.cfg.control.clip_actions;
        let s = &mut self.state;
        s.last_last_action = s.last_action;
        s.last_action = s.action;
        for i in 0..NUM_JOINTS {
            let a = action[i] as f64;
            s.action[i] = if a.is_finite() {
                a.clamp(-clip, clip)
            } else {
                0.0
            };
        }
        self.actions.rotate_right(1);
        self.actions[0] = s.action;
        let applied = self.actions[self.latency];
        let g1 = &sh.scene.g1;
        {
            let ctrl = self.data.ctrl_mut();
            for i in 0..NUM_JOINTS {
                ctrl[g1.actuator[i]] = g1.default_pos[i] + sh.action_scale[i] * applied[i];
            }
        }
        let mut blowup = false;
        for _ in 0..sh.cfg.sim.decimation {
            if self.data.step().is_err() {
                blowup = true;
                break;
            }
        }
        self.step_in_episode += 1;
        if blowup {
            // MuJoCo may already have reset the state: report the last good
            // observation as final, count it, start over.
            out.final_obs.copy_from_slice(out.obs);
            out.final_critic.copy_from_slice(out.critic);
            out.final_scan.copy_from_slice(out.scan);
            self.last_sums.copy_from_slice(&self.episode_sums);
            self.remember_end();
            self.reset(sh);
            self.write_obs(sh, out.obs, out.critic, out.scan);
            return Outcome {
                reward: 0.0,
                terminated: true,
                truncated: false,
                blowup: true,
                episode_done: true,
            };
        }
        self.state.last_qd = self.state.qd;
        self.state.last_torque = self.state.torque;
        self.derive_state(sh);
        self.state.gait_phase =
            (self.step_in_episode as f64 * sh.dt / sh.cfg.observation.gait_period_s).fract();
        self.steer_heading(sh);

        // terminations and truncations
        let t = &sh.cfg.termination;
        let s = &mut self.state;
        let cause = if self.fatal_contact {
            Some(FallCause::Contact)
        } else if -s.gravity[2] < sh.cos_max_tilt {
            Some(FallCause::Tilt)
        } else if s.base_height < t.min_base_height {
            Some(FallCause::BaseHeight)
        } else {
            None
        };
        let fell = cause.is_some();
        s.terminated = fell;
        let timeout = self.step_in_episode >= sh.max_episode_steps;
        let off_map = sh.scene.terrain.as_ref().is_some_and(|m| {
            let [lx, ly] = m.extent();
            let (x, y, e) = (s.base_pos[0], s.base_pos[1], t.map_margin);
            x < e || y < e || x > lx - e || y > ly - e
        });
        let beyond = s.base_pos[0] >= self.goal_x;
        s.reached_goal = beyond && !self.past_goal;
        self.past_goal |= beyond;
        let reward = sh.rewards.compute(&self.state, &mut self.episode_sums);

        // timers
        let k = self.step_in_episode;
        if k.is_multiple_of(sh.resample_steps) {
            self.resample_command(sh);
            self.steer_heading(sh);
        }
        if sh.push_steps > 0 && k.is_multiple_of(sh.push_steps) {
            let v = sh.cfg.domain_rand.max_push_vel;
            let (dx, dy) = (self.rng.random_range(-v..=v), self.rng.random_range(-v..=v));
            let qvel = self.data.qvel_mut();
            qvel[0] += dx;
            qvel[1] += dy;
        }

        let truncated = !fell && (timeout || off_map);
        let done = fell || truncated;
        if done {
            self.write_obs(sh, out.final_obs, out.final_critic, out.final_scan);
            self.update_curriculum(sh);
            self.last_sums.copy_from_slice(&self.episode_sums);
            self.remember_end();
            self.last_end.fall = cause;
            self.reset(sh);
        }
        self.write_obs(sh, out.obs, out.critic, out.scan);
        Outcome {
            reward: reward as f32,
            terminated: fell,
            truncated,
            blowup: false,
            episode_done: done,
        }
    }
}

impl LocoEnv {
    fn remember_end(&mut self) {
        self.last_end = EpisodeEnd {
            base_pos: self.state.base_pos,
            spawn: self.spawn,
            command: self.state.command,
            fall: None,
        };
    }

    /// Height of the ground this env's physics sees.
    #[inline]
    pub fn ground(&self, sh: &EnvShared, x: f64, y: f64) -> f64 {
        height_on(self.on_plane, sh.scene.heights.as_deref(), x, y)
    }

    /// Whether this env runs on a plane in place of its Flat tiles (scene doc).
    pub fn on_plane(&self) -> bool {
        self.on_plane
    }

    /// Read the MuJoCo state into `self.state` (step 4 of the step order).
    fn derive_state(&mut self, sh: &EnvShared) {
        let scene = &sh.scene;
        let on_plane = self.on_plane;
        // heights above the ground are measured from the surface a foot steps
        // over, not from a pit's floor
        let support = scene.support.as_deref();
        let ground = |x: f64, y: f64| height_on(on_plane, support, x, y);
        let g1 = &scene.g1;
        let d = &self.data;
        let s = &mut self.state;
        let qpos = d.qpos();
        let qvel = d.qvel();
        s.base_pos = [qpos[0], qpos[1], qpos[2]];
        // the orientation after the last physics step, as the IMU reads it (xmat
        // is the kinematics computed at the start of that step, 5 ms older)
        s.base_rot = crate::sim::quat_to_mat([qpos[3], qpos[4], qpos[5], qpos[6]]);
        s.base_lin_vel_world = [qvel[0], qvel[1], qvel[2]];
        s.base_lin_vel = rotate_inv(&s.base_rot, s.base_lin_vel_world);
        s.base_ang_vel = [qvel[3], qvel[4], qvel[5]];
        s.gravity = rotate_inv(&s.base_rot, [0.0, 0.0, -1.0]);
        s.yaw = s.base_rot[3].atan2(s.base_rot[0]);
        s.base_height = s.base_pos[2] - ground(s.base_pos[0], s.base_pos[1]);
        let force = d.actuator_force();
        for i in 0..NUM_JOINTS {
            s.q[i] = qpos[g1.qpos_adr[i]];
            s.qd[i] = qvel[g1.dof_adr[i]];
            s.torque[i] = force[g1.actuator[i]];
        }
        let xpos = d.xpos();
        let xmat = d.xmat();
        let params = &sh.rewards.params;
        let raw = scene.heights.as_deref();
        // support samples ahead of each foot for the swing terms, along the heading
        let ahead = (params.swing_lookahead / LOOKAHEAD_STEP).round() as usize;
        let (cy, sy) = (s.yaw.cos(), s.yaw.sin());
        for f in 0..2 {
            let p = xpos[g1.feet[f]];
            for a in 0..3 {
                s.feet_vel[f][a] = (p[a] - s.feet_pos[f][a]) / s.dt;
            }
            s.feet_pos[f] = p;
            s.feet_rpy[f] = rpy(&xmat[g1.feet[f]]);
            s.feet_ground[f] = ground(s.feet_pos[f][0], s.feet_pos[f][1]);
            s.feet_swing_ground[f] = (1..=ahead)
                .map(|k| {
                    let d = k as f64 * LOOKAHEAD_STEP;
                    ground(s.feet_pos[f][0] + d * cy, s.feet_pos[f][1] + d * sy)
                })
                .fold(s.feet_ground[f], f64::max);
            s.feet_on_edge[f] = !on_plane
                && scene
                    .terrain
                    .as_ref()
                    .is_some_and(|m| m.is_edge(s.feet_pos[f][0], s.feet_pos[f][1]));
            s.feet_over_pit[f] =
                !on_plane && over_pit(raw, support, p, &xmat[g1.feet[f]], params.feet_gap_depth);
            s.feet_straddle[f] =
                !on_plane && straddles(raw, p, &xmat[g1.feet[f]], params.straddle_height);
            s.knees_pos[f] = xpos[g1.knees[f]];
        }

        // contacts with the ground: feet forces, collisions, fatal contacts
        let model = d.model();
        let geom_body = model.geom_bodyid();
        s.feet_force = [[0.0; 3]; 2];
        s.collisions = 0;
        let mut collided = [false; 64];
        self.fatal_contact = false;
        for (i, c) in d.contacts().iter().enumerate() {
            let (g1c, g2c) = contact_geoms(c);
            let (b1, b2) = (
                geom_body[g1c as usize] as usize,
                geom_body[g2c as usize] as usize,
            );
            let (body, robot_is_second) = match (scene.body_class[b1], scene.body_class[b2]) {
                (BodyClass::World, _) => (b2, true),
                (_, BodyClass::World) => (b1, false),
                _ => continue, // self-collision
            };
            let Some(f) = d.contact_force(i) else {
                continue;
            };
            match scene.body_class[body] {
                BodyClass::Foot(k) => {
                    // contact frame rows: normal, tangent1, tangent2 (world); the force
                    // acts on geom2 along +normal, so flip it when the foot is geom1
                    let sign = if robot_is_second { 1.0 } else { -1.0 };
                    let fr = &c.frame;
                    for a in 0..3 {
                        s.feet_force[k][a] +=
                            sign * (f[0] * fr[a] + f[1] * fr[3 + a] + f[2] * fr[6 + a]);
                    }
                }
                class => {
                    let magnitude = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
                    if magnitude > params.collision_force
                        && body < collided.len()
                        && !collided[body]
                    {
                        collided[body] = true;
                        s.collisions += 1;
                    }
                    if class == BodyClass::Fatal && magnitude > sh.cfg.termination.contact_force {
                        self.fatal_contact = true;
                    }
                }
            }
        }
        // feet air time (legged_gym): contact = vertical force above 1 N
        for k in 0..2 {
            let contact = s.feet_force[k][2] > 1.0;
            s.feet_first_contact[k] = contact && s.feet_air_time[k] > 0.0;
            s.feet_touchdown_air_time[k] = if s.feet_first_contact[k] {
                s.feet_air_time[k] + s.dt
            } else {
                0.0
            };
            s.feet_air_time[k] = if contact {
                0.0
            } else {
                s.feet_air_time[k] + s.dt
            };
            s.feet_contact_time[k] = if contact {
                s.feet_contact_time[k] + s.dt
            } else {
                0.0
            };
            s.feet_contact[k] = contact;
        }
        s.terrain_level = self.level;
    }

    /// Heading mode: yaw-rate command = clip(k * wrap(target - yaw)), the
    /// target being the drawn heading, turned towards the lane's centre line
    /// when `commands.lane_lookahead` is set.
    fn steer_heading(&mut self, sh: &EnvShared) {
        let c = &sh.cfg.commands;
        self.state.heading_target = self.heading.map(|h| match c.lane_lookahead {
            Some(l) => {
                let (dx, dy) = (
                    self.state.base_pos[0] - self.spawn[0],
                    self.state.base_pos[1] - self.spawn[1],
                );
                h + lane_correction(-dx * h.sin() + dy * h.cos(), l)
            }
            None => h,
        });
        if let Some(h) = self.state.heading_target {
            let w = c.heading_stiffness * wrap_angle(h - self.state.yaw);
            self.state.command[2] = w.clamp(c.ang_vel_yaw[0], c.ang_vel_yaw[1]);
        }
    }

    /// legged_gym's terrain curriculum, at the end of an episode: walked more than
    /// half a tile => one level up (past the top: a random level); walked less than
    /// half of what the command asked for => one level down.
    fn update_curriculum(&mut self, sh: &EnvShared) {
        let Some(map) = &sh.scene.terrain else { return };
        if !sh.cfg.terrain.curriculum || sh.cfg.terrain.mode != TerrainMode::Map {
            return;
        }
        let s = &self.state;
        let walked = (s.base_pos[0] - self.spawn[0]).hypot(s.base_pos[1] - self.spawn[1]);
        let asked = s.command[0].hypot(s.command[1]) * sh.cfg.episode_length_s * 0.5;
        let b = map.tile_bounds(self.level, self.col);
        let up = walked > (b.x[1] - b.x[0]) / 2.0;
        let down = !up && walked < asked;
        self.level = next_level(self.level, up, down, map.num_levels(), &mut self.rng);
    }

    /// Observations of the current state (step 10), written by [`obs::write`].
    fn write_obs(&mut self, sh: &EnvShared, obs: &mut [f32], critic: &mut [f32], scan: &mut [f32]) {
        let (on_plane, scene) = (self.on_plane, &sh.scene);
        let ctx = obs::ObsContext {
            state: &self.state,
            cfg: &sh.cfg.observation,
            time: self.step_in_episode as f64 * self.state.dt,
            robot_weight: scene.robot_weight,
            bucket: scene.buckets[self.bucket],
            latency: self.latency,
            ground: &|x, y| height_on(on_plane, scene.heights.as_deref(), x, y),
        };
        obs::write(&ctx, &mut self.rng, obs, critic, scan);
    }
}

/// Height of `field` (the scene's terrain, `Scene::heights`, or the surface
/// the feet step over, `Scene::support`) for an env: 0 when the env steps on
/// its plane or the scene has no heightfield.
#[inline]
fn height_on(on_plane: bool, field: Option<&crate::sim::HeightField>, x: f64, y: f64) -> f64 {
    match field {
        Some(h) if !on_plane => h.height(x, y),
        _ => 0.0,
    }
}

/// World `(x, y)` of the point `(x, y, 0)` of a foot's ankle-roll link frame
/// (origin `pos`, rotation `mat`, row-major).
fn sole_point(pos: [f64; 3], mat: &[f64; 9], x: f64, y: f64) -> (f64, f64) {
    (
        pos[0] + mat[0] * x + mat[1] * y,
        pos[1] + mat[3] * x + mat[4] * y,
    )
}

/// Whether the heel or the toe of a foot (ankle-roll link at `pos`, rotation
/// `mat`, row-major) is over a pit: `support` more than `depth` above `raw`
/// there. False without a heightfield.
fn over_pit(
    raw: Option<&crate::sim::HeightField>,
    support: Option<&crate::sim::HeightField>,
    pos: [f64; 3],
    mat: &[f64; 9],
    depth: f64,
) -> bool {
    let (Some(raw), Some(support)) = (raw, support) else {
        return false;
    };
    crate::robot::SOLE_HEEL_TOE_X.iter().any(|&x| {
        let (px, py) = sole_point(pos, mat, x, 0.0);
        support.height(px, py) - raw.height(px, py) > depth
    })
}

/// Whether the terrain `raw` under the four corners of a foot's sole (ankle-roll
/// link at `pos`, rotation `mat`) spans more than `step`. False without a
/// heightfield.
fn straddles(
    raw: Option<&crate::sim::HeightField>,
    pos: [f64; 3],
    mat: &[f64; 9],
    step: f64,
) -> bool {
    let Some(raw) = raw else { return false };
    let w = crate::robot::SOLE_HALF_WIDTH;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in crate::robot::SOLE_HEEL_TOE_X {
        for y in [-w, w] {
            let (px, py) = sole_point(pos, mat, x, y);
            let h = raw.height(px, py);
            (lo, hi) = (lo.min(h), hi.max(h));
        }
    }
    hi - lo > step
}

/// One curriculum move. Past the top level an env goes to a random level
/// (legged_gym), so that solved terrains keep being visited.
pub fn next_level(level: usize, up: bool, down: bool, levels: usize, rng: &mut impl Rng) -> usize {
    if up {
        if level + 1 >= levels {
            rng.random_range(0..levels)
        } else {
            level + 1
        }
    } else if down {
        level.saturating_sub(1)
    } else {
        level
    }
}

/// Pure pursuit of a straight lane: the heading offset (rad) that points at the
/// centre line `lookahead` metres ahead, from `lateral` metres left of it.
pub fn lane_correction(lateral: f64, lookahead: f64) -> f64 {
    (-lateral).atan2(lookahead.max(1e-6))
}
