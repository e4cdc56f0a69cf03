//! The `env` section of an experiment file: the locomotion environment, its
//! batch, physics, observations, commands, termination, terrain and domain
//! randomization, with the validation serde cannot do. The reward table is
//! [`crate::env::rewards::RewardConfig`], owned by the rewards module.
use serde::{Deserialize, Serialize};

use super::rewards::RewardConfig;
use crate::config::ConfigError;
use crate::terrain::TerrainConfig;

/// The locomotion environment and its batch.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvConfig {
    /// Number of parallel environments (> 0).
    pub n_envs: i64,
    /// Worker threads stepping them (> 0).
    #[serde(default = "one_i64")]
    pub threads: i64,
    #[serde(default)]
    pub seed: u64,
    /// Episode time limit; reaching it truncates (bootstrapped), it does not terminate.
    #[serde(default = "d_episode")]
    pub episode_length_s: f64,
    #[serde(default)]
    pub sim: SimConfig,
    #[serde(default)]
    pub init: InitConfig,
    #[serde(default)]
    pub control: ControlConfig,
    #[serde(default)]
    pub observation: ObservationConfig,
    #[serde(default)]
    pub commands: CommandConfig,
    #[serde(default)]
    pub rewards: RewardConfig,
    #[serde(default)]
    pub termination: TerminationConfig,
    #[serde(default)]
    pub terrain: TerrainSetting,
    #[serde(default)]
    pub domain_rand: DomainRandConfig,
}

fn one_i64() -> i64 {
    1
}
fn d_episode() -> f64 {
    20.0
}

/// Physics settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// MuJoCo timestep (s).
    pub timestep: f64,
    /// Physics steps per control step (50 Hz control = 0.005 s x 4).
    pub decimation: usize,
    /// |qvel| past this counts as a blow-up.
    pub max_qvel: f64,
    /// Robot self-collisions (off by default: mjlab's FULL_COLLISION_WITHOUT_SELF, faster).
    pub self_collisions: bool,
    /// MuJoCo integrator; `implicitfast` exists only in MuJoCo 3.x.
    pub integrator: Integrator,
    /// Contact buffer size (`<size nconmax>`). MuJoCo 2.2.2's default of 100 overflows
    /// when a G1 lies on a heightfield (every foot capsule meets several prisms);
    /// an overflow drops contacts and is counted as a warning.
    pub nconmax: usize,
    /// Constraint rows (`<size njmax>`); 2.2.2 allocates njmax^2 doubles per env.
    pub njmax: usize,
    /// Which robot geoms touch the ground: `full` (every collision geom) or
    /// `feet_only` (Playground's training scene; falls are then detected from
    /// height and tilt only).
    pub collision: CollisionMode,
    /// Solver iterations (`<option iterations>`; MuJoCo's default 100).
    pub iterations: usize,
    /// Line-search iterations (`<option ls_iterations>`; MuJoCo's default 50).
    pub ls_iterations: usize,
    /// How robot spheres and capsules touch a heightfield terrain: `surface`
    /// (the terrain's top surface only, each contact at the surface's closest
    /// point: `sim::hfield_contact`), `surface_planes` (its first version,
    /// before 2026-12-04: contacts against the triangles' planes, extended,
    /// which push a foot resting on a block's rim off it) or `prisms` (MuJoCo's
    /// own prism-by-prism test, whose internal side faces tilt contact normals:
    /// a G1 standing still on a flat heightfield slides and falls).
    pub hfield_contacts: HfieldContacts,
}

/// Heightfield collision model of the terrain geom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HfieldContacts {
    Surface,
    SurfacePlanes,
    Prisms,
}

/// Robot-ground collision set of the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CollisionMode {
    Full,
    FeetOnly,
}

/// MuJoCo's integrators, by their MJCF names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    Euler,
    Rk4,
    Implicit,
    Implicitfast,
}

impl Integrator {
    /// The MJCF attribute value.
    pub fn mjcf(self) -> &'static str {
        match self {
            Integrator::Euler => "Euler",
            Integrator::Rk4 => "RK4",
            Integrator::Implicit => "implicit",
            Integrator::Implicitfast => "implicitfast",
        }
    }
}

impl SimConfig {
    /// The control period (s): `timestep x decimation`.
    pub fn control_dt(&self) -> f64 {
        self.timestep * self.decimation as f64
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            timestep: 0.005,
            decimation: 4,
            max_qvel: 100.0,
            self_collisions: false,
            integrator: Integrator::Implicit,
            nconmax: 300,
            njmax: 1200,
            collision: CollisionMode::Full,
            iterations: 100,
            ls_iterations: 50,
            hfield_contacts: HfieldContacts::Surface,
        }
    }
}

/// Initial state at each reset.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitConfig {
    /// Initial yaw drawn from `[lo, hi]` (rad); lanes run along +x, so 0 by default.
    pub yaw: [f64; 2],
    /// Added to the keyframe's pelvis height above the ground at the spawn point (m).
    pub height_offset: f64,
    /// Uniform noise added to the default joint pose (rad).
    pub joint_pos_noise: f64,
}

impl Default for InitConfig {
    fn default() -> Self {
        InitConfig {
            yaw: [0.0, 0.0],
            height_offset: 0.02,
            joint_pos_noise: 0.05,
        }
    }
}

/// Action interface: `q_target = q_default + action_scale * clip(a)`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControlConfig {
    pub action_scale: f64,
    pub clip_actions: f64,
    /// Per-joint scale `action_scale * effort_limit / kp` (mjlab's G1): an action
    /// of 1 asks for `action_scale` of the joint's torque limit, whatever its
    /// stiffness. Off: `action_scale` radians for every joint.
    pub scale_by_effort: bool,
}

impl Default for ControlConfig {
    fn default() -> Self {
        ControlConfig {
            action_scale: 0.25,
            clip_actions: 10.0,
            scale_by_effort: false,
        }
    }
}

/// Where the 187 scandots lie in the yaw-aligned pelvis frame: a 17 x 11 grid
/// from `(x0, y0)` (its back right corner), `spacing` apart on both axes
/// (`env.observation.scan_grid`; `obs::ScanGrid::point` gives point `k`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanGrid {
    pub x0: f64,
    pub y0: f64,
    pub spacing: f64,
}

impl Default for ScanGrid {
    /// 1.6 m x 1.0 m at 0.1 m: 0.6 m behind to 1.0 m ahead of the pelvis, 0.5 m
    /// to either side (the paper's crop, and the grid every checkpoint before
    /// 2026-12-06 saw).
    fn default() -> Self {
        ScanGrid {
            x0: -0.6,
            y0: -0.5,
            spacing: 0.1,
        }
    }
}

/// Observation scales and noise (legged_gym's defaults).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObservationConfig {
    pub scales: ObsScales,
    /// Uniform noise half-widths, multiplied by `noise_level`; `add_noise: false` turns it off.
    pub noise: ObsNoise,
    pub add_noise: bool,
    pub noise_level: f64,
    /// Observations are clipped to +-clip after scaling.
    pub clip: f64,
    /// Gait phase period (s) for the `[sin, cos]` clock.
    pub gait_period_s: f64,
    /// Scandots are clipped to +-scan_clip metres.
    pub scan_clip: f64,
    /// Where the 187 scandots lie (origin and spacing of the 17 x 11 grid).
    pub scan_grid: ScanGrid,
}

impl Default for ObservationConfig {
    fn default() -> Self {
        ObservationConfig {
            scales: ObsScales::default(),
            noise: ObsNoise::default(),
            add_noise: true,
            noise_level: 1.0,
            clip: 100.0,
            gait_period_s: 0.8,
            scan_clip: 1.0,
            scan_grid: ScanGrid::default(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObsScales {
    pub lin_vel: f64,
    pub ang_vel: f64,
    pub dof_pos: f64,
    pub dof_vel: f64,
    /// Scales of the command `[vx, vy, yaw_rate]` in the observation.
    pub commands: [f64; 3],
    pub scan: f64,
}

impl Default for ObsScales {
    fn default() -> Self {
        ObsScales {
            lin_vel: 2.0,
            ang_vel: 0.25,
            dof_pos: 1.0,
            dof_vel: 0.05,
            commands: [2.0, 2.0, 0.25],
            scan: 1.0,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObsNoise {
    pub ang_vel: f64,
    pub gravity: f64,
    pub dof_pos: f64,
    pub dof_vel: f64,
    pub scan: f64,
}

impl Default for ObsNoise {
    fn default() -> Self {
        ObsNoise {
            ang_vel: 0.2,
            gravity: 0.05,
            dof_pos: 0.01,
            dof_vel: 1.5,
            scan: 0.02,
        }
    }
}

/// Velocity commands `[vx, vy, yaw_rate]`, resampled on a timer.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CommandConfig {
    pub resample_time_s: f64,
    /// Heading mode: sample a heading and steer the yaw rate towards it.
    pub heading_command: bool,
    pub heading_stiffness: f64,
    pub lin_vel_x: [f64; 2],
    pub lin_vel_y: [f64; 2],
    pub ang_vel_yaw: [f64; 2],
    pub heading: [f64; 2],
    /// Planar commands below this norm are zeroed (standing is a command too).
    pub min_norm: f64,
    /// Heading mode, lane keeping (pure pursuit): the heading target points at
    /// the lane's centre line this far ahead (m), the lane being the line
    /// through the spawn point along the drawn heading:
    /// `target = heading + atan2(-lateral_offset, lane_lookahead)`. Unset: the
    /// drawn heading alone, and a sideways drift is never steered back.
    pub lane_lookahead: Option<f64>,
}

impl CommandConfig {
    /// Each command range is `[lo, hi]` with `lo <= hi` (no NaN); the error
    /// names the range as `{prefix}.{key}`.
    pub fn check_ranges(&self, prefix: &str) -> Result<(), String> {
        for (what, r) in [
            ("lin_vel_x", self.lin_vel_x),
            ("lin_vel_y", self.lin_vel_y),
            ("ang_vel_yaw", self.ang_vel_yaw),
            ("heading", self.heading),
        ] {
            if r[0].is_nan() || r[1].is_nan() || r[0] > r[1] {
                return Err(format!(
                    "{prefix}.{what} must be [lo, hi] with lo <= hi, got {r:?}"
                ));
            }
        }
        Ok(())
    }
}

impl Default for CommandConfig {
    fn default() -> Self {
        CommandConfig {
            resample_time_s: 10.0,
            heading_command: true,
            heading_stiffness: 0.5,
            lin_vel_x: [-1.0, 1.0],
            lin_vel_y: [-0.5, 0.5],
            ang_vel_yaw: [-1.0, 1.0],
            heading: [-std::f64::consts::PI, std::f64::consts::PI],
            min_norm: 0.2,
            lane_lookahead: None,
        }
    }
}

/// When an episode ends.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerminationConfig {
    /// Pelvis height above the terrain below which the robot has fallen (m).
    pub min_base_height: f64,
    /// Tilt of the pelvis from upright past which it has fallen (deg).
    pub max_tilt_deg: f64,
    /// Bodies whose contact with the ground ends the episode.
    pub contact_bodies: Vec<String>,
    /// Contact force (N) that counts for `contact_bodies`.
    pub contact_force: f64,
    /// Distance to the map's edge (m) that truncates the episode.
    pub map_margin: f64,
}

impl Default for TerminationConfig {
    fn default() -> Self {
        TerminationConfig {
            min_base_height: 0.3,
            max_tilt_deg: 60.0,
            contact_bodies: vec!["pelvis".into(), "torso_link".into()],
            contact_force: 1.0,
            map_margin: 1.0,
        }
    }
}

/// Ground: a plane, or a procedural heightfield map with a curriculum.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainSetting {
    /// `plane` or `map`.
    pub mode: TerrainMode,
    pub map: TerrainConfig,
    /// Move envs up/down levels by distance walked (legged_gym).
    pub curriculum: bool,
    /// Envs start at levels in `[0, init_max_level]`.
    pub init_max_level: usize,
    /// Seed of the terrain map (kept apart from the env seed so that runs with
    /// different env seeds can share a map).
    pub seed: u64,
    /// Envs bound to a Flat column run on a plane instead of the heightfield:
    /// MuJoCo collides feet with a heightfield prism by prism, about 2x slower
    /// than with a plane even when flat (README, "Benchmarks"). Their flat tiles
    /// then have no base roughness.
    pub flat_on_plane: bool,
    /// Pits narrower than about twice this (m) are filled in the surface that
    /// the pelvis and feet heights of the state are measured from (the swing
    /// and base-height rewards, the fall check): over a 0.2 m gap the swing
    /// target is the platforms' level, not the pit's floor a metre down. 0:
    /// the raw heightfield (the runs before 2026-12-03 trained so). Scandots
    /// and collisions always see the raw terrain.
    pub support_radius: f64,
}

impl Default for TerrainSetting {
    fn default() -> Self {
        TerrainSetting {
            mode: TerrainMode::Plane,
            map: TerrainConfig::default(),
            curriculum: true,
            init_max_level: 2,
            seed: 0,
            flat_on_plane: true,
            support_radius: 0.2,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerrainMode {
    Plane,
    Map,
}

/// Domain randomization. Model parameters (friction, added mass, motor strength)
/// are drawn per model bucket (legged_gym's friction buckets): `model_buckets`
/// copies of the compiled model, each env bound to one at construction.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DomainRandConfig {
    pub enabled: bool,
    pub model_buckets: usize,
    pub friction: [f64; 2],
    /// Mass added to the pelvis (kg).
    pub added_mass: [f64; 2],
    /// Multiplier of every actuator's gains.
    pub motor_strength: [f64; 2],
    /// Seconds between pushes (0 = no pushes).
    pub push_interval_s: f64,
    /// Largest planar velocity (m/s) a push adds to the pelvis.
    pub max_push_vel: f64,
    /// Action latency in control steps, drawn per episode from `[lo, hi]`.
    pub action_latency: [usize; 2],
}

impl Default for DomainRandConfig {
    fn default() -> Self {
        DomainRandConfig {
            enabled: true,
            model_buckets: 8,
            friction: [0.5, 1.25],
            added_mass: [-1.0, 3.0],
            motor_strength: [0.9, 1.1],
            push_interval_s: 8.0,
            max_push_vel: 0.5,
            action_latency: [0, 1],
        }
    }
}

impl EnvConfig {
    /// Number of envs and threads as validated counts.
    pub fn counts(&self) -> (usize, usize) {
        (self.n_envs as usize, self.threads as usize)
    }

    /// Check values serde cannot: positive counts, known reward terms, ranges.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        if self.n_envs <= 0 {
            return bad(format!("env.n_envs must be positive, got {}", self.n_envs));
        }
        if self.threads <= 0 {
            return bad(format!(
                "env.threads must be positive, got {}",
                self.threads
            ));
        }
        if self.sim.timestep.is_nan() || self.sim.timestep <= 0.0 || self.sim.decimation == 0 {
            return bad("env.sim.timestep must be > 0 and env.sim.decimation >= 1".into());
        }
        if self.sim.iterations == 0 || self.sim.ls_iterations == 0 {
            return bad("env.sim.iterations and env.sim.ls_iterations must be >= 1".into());
        }
        if self.sim.integrator == Integrator::Implicitfast
            && mujoco_sys::MUJOCO_VERSION_HEADER < 300
        {
            return bad(format!(
                "env.sim.integrator: implicitfast needs MuJoCo 3.x; this build links MuJoCo {} \
                 (rebuild with MUJOCO_DIR, see the README) or use implicit",
                crate::sim::mujoco_version()
            ));
        }
        if self.episode_length_s.is_nan() || self.episode_length_s <= 0.0 {
            return bad(format!(
                "env.episode_length_s must be positive, got {}",
                self.episode_length_s
            ));
        }
        if let Some(l) = self.commands.lane_lookahead {
            if l.is_nan() || l <= 0.0 {
                return bad(format!(
                    "env.commands.lane_lookahead must be positive (m) or left out, got {l}"
                ));
            }
        }
        let g = &self.observation.scan_grid;
        if !(g.spacing > 0.0 && g.spacing <= 0.5 && g.x0.is_finite() && g.y0.is_finite()) {
            return bad(format!(
                "env.observation.scan_grid needs finite x0, y0 and 0 < spacing <= 0.5 m, got {g:?}"
            ));
        }
        self.rewards.validate()?;
        self.commands
            .check_ranges("env.commands")
            .map_err(ConfigError::Invalid)?;
        for (what, r) in [
            ("init.yaw", self.init.yaw),
            ("domain_rand.friction", self.domain_rand.friction),
            ("domain_rand.added_mass", self.domain_rand.added_mass),
            (
                "domain_rand.motor_strength",
                self.domain_rand.motor_strength,
            ),
        ] {
            if r[0].is_nan() || r[1].is_nan() || r[0] > r[1] {
                return bad(format!(
                    "env.{what} must be [lo, hi] with lo <= hi, got {r:?}"
                ));
            }
        }
        if self.domain_rand.action_latency[0] > self.domain_rand.action_latency[1] {
            return bad("env.domain_rand.action_latency must be [lo, hi] with lo <= hi".into());
        }
        if self.domain_rand.friction[0] < 0.0 {
            return bad("env.domain_rand.friction must be non-negative".into());
        }
        if self.domain_rand.model_buckets == 0 {
            return bad("env.domain_rand.model_buckets must be >= 1".into());
        }
        let r = self.terrain.support_radius;
        if !(r.is_finite() && (0.0..=2.0).contains(&r)) {
            return bad(format!(
                "env.terrain.support_radius must be in [0, 2] m, got {r}"
            ));
        }
        if self.terrain.mode == TerrainMode::Map {
            self.terrain
                .map
                .validate()
                .map_err(|e| ConfigError::Invalid(format!("env.terrain.map: {e}")))?;
        }
        Ok(())
    }
}
