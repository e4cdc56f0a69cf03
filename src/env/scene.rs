//! The compiled scene an env batch shares: the G1 on a plane or on the terrain
//! map's heightfield, the model buckets of domain randomization, and the body
//! classes used to read contacts.
//!
//! Flat tiles on a plane: MuJoCo collides a foot with a heightfield prism by
//! prism, so even a flat heightfield steps about 2x slower than a plane (README,
//! "Benchmarks"). Envs bound to a Flat column of the map therefore run on a
//! second set of bucket models, compiled from the same scene with a plane at
//! ground level in place of the heightfield: they step at plane speed, and their
//! ground lookups, scandots and edges read that plane too. (Flat tiles lose their
//! base roughness for those envs; `terrain.flat_on_plane: false` keeps it.)
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::EnvError;
use crate::env::config::{EnvConfig, HfieldContacts, TerrainMode};
use crate::robot::{self, G1};
use crate::sim::hfield_contact::{SURFACE_CONTACTS, SURFACE_PLANES};
use crate::sim::{HeightField, Model, ObjType};
use crate::terrain::{TerrainKind, TerrainMap};

/// What a body is, for contact bookkeeping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BodyClass {
    World,
    /// Left (0) or right (1) foot.
    Foot(usize),
    /// A robot body whose ground contact ends the episode.
    Fatal,
    /// Any other robot body (counts as a collision).
    Robot,
}

/// Model parameters drawn for one bucket.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BucketParams {
    pub friction: f64,
    pub added_mass: f64,
    pub motor_strength: f64,
}

impl Default for BucketParams {
    fn default() -> Self {
        BucketParams {
            friction: 1.0,
            added_mass: 0.0,
            motor_strength: 1.0,
        }
    }
}

/// The scene shared by all envs of a batch.
pub struct Scene {
    /// One compiled model per domain-randomization bucket (index = bucket).
    pub models: Vec<Arc<Model>>,
    pub buckets: Vec<BucketParams>,
    pub g1: G1,
    pub terrain: Option<Arc<TerrainMap>>,
    /// Rust-side height lookup of the uploaded heightfield (None on a plane).
    pub heights: Option<Arc<HeightField>>,
    /// The surface the feet step over: `heights` with pits narrower than
    /// `terrain.support_radius` filled ([`HeightField::closed`]). Heights above
    /// the ground in the state (pelvis, feet) are measured from it, so that a
    /// swing over a gap is not asked to reach into the pit.
    pub support: Option<Arc<HeightField>>,
    pub body_class: Vec<BodyClass>,
    /// Robot weight (N) of the nominal model, for normalizing forces.
    pub robot_weight: f64,
    /// Bucket models for envs that live on Flat columns: heightfield off, plane on
    /// (empty unless `terrain.flat_on_plane` and the map has a Flat column).
    pub plane_models: Vec<Arc<Model>>,
}

impl Scene {
    /// Build the scene of `cfg`: generate the terrain (map mode), compile the
    /// model, upload the heightfield, then copy it into the buckets.
    pub fn build(cfg: &EnvConfig) -> Result<Scene, EnvError> {
        robot::check_vendor_files()?;
        let terrain = match cfg.terrain.mode {
            TerrainMode::Plane => None,
            TerrainMode::Map => Some(Arc::new(TerrainMap::generate(
                &cfg.terrain.map,
                cfg.terrain.seed,
            )?)),
        };
        Scene::with_terrain(cfg, terrain)
    }

    /// Build on a given terrain (a map, a lane, or None for a plane).
    pub fn with_terrain(
        cfg: &EnvConfig,
        terrain: Option<Arc<TerrainMap>>,
    ) -> Result<Scene, EnvError> {
        let (model, g1) = compile(cfg, terrain.as_deref())?;
        let heights = match &terrain {
            Some(_) => {
                let geom = model.id(ObjType::Geom, "terrain")?;
                Some(Arc::new(HeightField::from_model(&model, geom)?))
            }
            None => None,
        };
        let support = heights.as_ref().map(|h| {
            let cells = (cfg.terrain.support_radius / h.dx() - 1e-9).ceil().max(0.0) as usize;
            Arc::new(h.closed(cells))
        });
        let body_class = classify_bodies(&model, &g1, &cfg.termination.contact_bodies)?;
        let robot_weight = model.body_subtreemass()[g1.pelvis] * 9.81;
        // envs on Flat columns step on a scene compiled with a plane instead
        let plane = match &terrain {
            Some(m)
                if cfg.terrain.flat_on_plane
                    && (0..m.num_cols()).any(|c| m.tile_kind(c) == TerrainKind::Flat) =>
            {
                Some(compile(cfg, None)?.0)
            }
            _ => None,
        };

        let dr = &cfg.domain_rand;
        let n_buckets = if dr.enabled { dr.model_buckets } else { 1 };
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x00B0_C4E7);
        let buckets: Vec<BucketParams> = (0..n_buckets)
            .map(|_| {
                if dr.enabled {
                    BucketParams {
                        friction: rng.random_range(dr.friction[0]..=dr.friction[1]),
                        added_mass: rng.random_range(dr.added_mass[0]..=dr.added_mass[1]),
                        motor_strength: rng
                            .random_range(dr.motor_strength[0]..=dr.motor_strength[1]),
                    }
                } else {
                    BucketParams::default()
                }
            })
            .collect();
        let models = bucket_models(model, &g1, &buckets)?;
        let plane_models = match plane {
            Some(p) => bucket_models(p, &g1, &buckets)?,
            None => Vec::new(),
        };
        Ok(Scene {
            models,
            buckets,
            g1,
            terrain,
            heights,
            support,
            body_class,
            robot_weight,
            plane_models,
        })
    }

    /// Terrain height at a world point (0 on a plane).
    #[inline]
    pub fn ground(&self, x: f64, y: f64) -> f64 {
        self.heights.as_ref().map_or(0.0, |h| h.height(x, y))
    }

    /// Height of the surface the feet step over at a world point (0 on a plane).
    #[inline]
    pub fn support(&self, x: f64, y: f64) -> f64 {
        self.support.as_ref().map_or(0.0, |h| h.height(x, y))
    }

    /// Whether the env bound to map column `col` runs on the plane models.
    pub fn column_on_plane(&self, col: usize) -> bool {
        !self.plane_models.is_empty()
            && self
                .terrain
                .as_ref()
                .is_some_and(|m| m.tile_kind(col) == TerrainKind::Flat)
    }
}

/// The scene's MJCF: our G1 (`g1_actuators.xml`, included relative to
/// `models/g1/`, where the generated file is written) on a plane or a heightfield.
pub fn scene_xml(cfg: &EnvConfig, terrain: Option<&TerrainMap>) -> String {
    let (asset, ground) = match terrain {
        None => (
            String::new(),
            r#"<geom name="terrain" type="plane" size="0 0 1" material="ground" contype="1" conaffinity="1" condim="3"/>"#
                .to_string(),
        ),
        Some(map) => {
            let (size, pos) = (map.hfield_size(), map.hfield_pos());
            // `user` = SURFACE_CONTACTS: our surface contacts (sim::hfield_contact)
            let user = match cfg.sim.hfield_contacts {
                HfieldContacts::Surface => format!(r#" user="{}""#, SURFACE_CONTACTS),
                HfieldContacts::SurfacePlanes => format!(r#" user="{}""#, SURFACE_PLANES),
                HfieldContacts::Prisms => String::new(),
            };
            let (nrow, ncol) = map.hfield_shape();
            (
                format!(
                    r#"<hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{} {} {} {}"/>"#,
                    size[0], size[1], size[2], size[3]
                ),
                format!(
                    r#"<geom name="terrain" type="hfield" hfield="terrain" material="ground" pos="{} {} {}" contype="1" conaffinity="1" condim="3"{user}/>"#,
                    pos[0], pos[1], pos[2]
                ),
            )
        }
    };
    // The sky, the ground's 1 m checker and the light only matter to
    // `render` (sim::render): no physics reads them.
    format!(
        r#"<mujoco model="g1_dreampolicy">
  <include file="g1_actuators.xml"/>
  <option timestep="{dt}" integrator="{integrator}" iterations="{iterations}"{ls_iterations}/>
  <size nconmax="{nconmax}" njmax="{njmax}"/>
  <visual>
    <headlight diffuse=".5 .5 .5" ambient=".35 .35 .35" specular="0 0 0"/>
    <quality shadowsize="2048"/>
  </visual>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1=".45 .6 .75" rgb2=".05 .07 .1" width="64" height="384"/>
    <texture name="ground" type="2d" builtin="checker" mark="edge" rgb1=".32 .36 .4" rgb2=".24 .27 .3" markrgb=".55 .6 .65" width="256" height="256"/>
    <material name="ground" texture="ground" texrepeat="1 1" texuniform="true"/>
    {asset}
  </asset>
  <worldbody>
    <light name="sun" pos="0 0 10" dir="0.3 0.2 -1" directional="true" diffuse=".6 .6 .6" castshadow="true"/>
    {ground}
  </worldbody>
</mujoco>
"#,
        dt = cfg.sim.timestep,
        integrator = cfg.sim.integrator.mjcf(),
        iterations = cfg.sim.iterations,
        // MuJoCo 2.2.2 has no ls_iterations (its line search is not capped separately)
        ls_iterations = if cfg!(mujoco_v3) {
            format!(r#" ls_iterations="{}""#, cfg.sim.ls_iterations)
        } else {
            String::new()
        },
        nconmax = cfg.sim.nconmax,
        njmax = cfg.sim.njmax,
    )
}

/// Compile the scene of `cfg` on `terrain` (armature checked, heightfield data
/// uploaded, collision settings applied): the nominal model of the buckets.
fn compile(cfg: &EnvConfig, terrain: Option<&TerrainMap>) -> Result<(Model, G1), EnvError> {
    let xml = scene_xml(cfg, terrain);
    let dir = robot::models_dir().join("g1");
    let mut model = Model::from_xml_str(&xml, &dir, "generated G1 scene")?;
    robot::check_armature(&model)?;
    let g1 = G1::resolve(&model)?;
    if let Some(map) = terrain {
        let geom = model.id(ObjType::Geom, "terrain")?;
        let hid = model.geom_dataid()[geom] as usize;
        model.set_hfield_data(hid, &map.hfield_data())?;
    }
    configure_collisions(&mut model, &g1, &cfg.sim);
    Ok((model, g1))
}

/// One model per bucket: copies of `nominal` (the last bucket takes it) with the
/// bucket's parameters written in.
fn bucket_models(
    nominal: Model,
    g1: &G1,
    buckets: &[BucketParams],
) -> Result<Vec<Arc<Model>>, EnvError> {
    let mut nominal = Some(nominal);
    let mut models = Vec::with_capacity(buckets.len());
    for (b, params) in buckets.iter().enumerate() {
        let mut m = match (b + 1 == buckets.len(), nominal.as_ref()) {
            (false, Some(nom)) => nom.clone(),
            _ => nominal
                .take()
                .expect("nominal model taken once, by the last bucket"),
        };
        apply_bucket(&mut m, g1, params)?;
        models.push(Arc::new(m));
    }
    Ok(models)
}

/// Robot geoms: only the feet keep condim 3 (others frictionless, condim 1, as in
/// mjlab's G1 setup), and without self-collisions the robot's contype is cleared
/// so that robot geoms collide with the ground only. `feet_only` also clears the
/// conaffinity of every non-foot robot geom: they touch nothing (Playground's
/// G1 training scene).
fn configure_collisions(model: &mut Model, g1: &G1, sim: &crate::env::config::SimConfig) {
    let self_collisions = sim.self_collisions;
    let bodies = model.geom_bodyid().to_vec();
    // world geoms and visual-only geoms (contype = conaffinity = 0) stay as they are
    let robot: Vec<bool> = bodies
        .iter()
        .zip(model.geom_contype().iter().zip(model.geom_conaffinity()))
        .map(|(&b, (&ct, &ca))| b != 0 && (ct != 0 || ca != 0))
        .collect();
    for (g, &b) in bodies.iter().enumerate() {
        if robot[g] && !g1.feet.contains(&(b as usize)) {
            model.geom_condim_mut()[g] = 1;
        }
    }
    if !self_collisions {
        for (g, ct) in model.geom_contype_mut().iter_mut().enumerate() {
            if robot[g] {
                *ct = 0;
            }
        }
    }
    if sim.collision == crate::env::config::CollisionMode::FeetOnly {
        for (g, &b) in bodies.iter().enumerate() {
            if robot[g] && !g1.feet.contains(&(b as usize)) {
                model.geom_contype_mut()[g] = 0;
                model.geom_conaffinity_mut()[g] = 0;
            }
        }
    }
}

fn classify_bodies(model: &Model, g1: &G1, fatal: &[String]) -> Result<Vec<BodyClass>, EnvError> {
    let mut class = vec![BodyClass::Robot; model.nbody()];
    class[0] = BodyClass::World;
    class[g1.feet[0]] = BodyClass::Foot(0);
    class[g1.feet[1]] = BodyClass::Foot(1);
    for name in fatal {
        let b = model.id(ObjType::Body, name)?;
        class[b] = BodyClass::Fatal;
    }
    Ok(class)
}

/// Write a bucket's friction, pelvis mass and motor strength into a model copy.
fn apply_bucket(model: &mut Model, g1: &G1, p: &BucketParams) -> Result<(), EnvError> {
    for f in model.geom_friction_mut() {
        f[0] = p.friction;
    }
    model.body_mass_mut()[g1.pelvis] += p.added_mass;
    let (ng, nb) = (mujoco_sys::mjNGAIN as usize, mujoco_sys::mjNBIAS as usize);
    for &a in &g1.actuator {
        model.actuator_gainprm_mut()[a * ng] *= p.motor_strength;
        model.actuator_biasprm_mut()[a * nb + 1] *= p.motor_strength;
        model.actuator_biasprm_mut()[a * nb + 2] *= p.motor_strength;
    }
    model.set_const()?;
    Ok(())
}
