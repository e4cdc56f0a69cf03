//! The compiled scene an env batch shares: the G1 on a plane or on the terrain
//! map's heightfield, the model buckets of domain randomization, and the body
//! classes used to read contacts.
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::EnvError;
use crate::config::{EnvConfig, TerrainMode};
use crate::robot::{self, G1};
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

/// A Flat tile served by a box geom (plane-speed contacts) instead of the
/// heightfield; the heightfield under it is lowered by [`FLAT_BOX_CLEARANCE`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlatBox {
    pub x: [f64; 2],
    pub y: [f64; 2],
    /// Height of the walking surface (the map's ground level).
    pub top: f64,
}

/// How far the heightfield is lowered under a flat box (m): enough for MuJoCo's
/// prism height test to skip every prism under a foot standing on the box.
pub const FLAT_BOX_CLEARANCE: f64 = 0.01;

/// The scene shared by all envs of a batch.
pub struct Scene {
    /// One compiled model per domain-randomization bucket (index = bucket).
    pub models: Vec<Arc<Model>>,
    pub buckets: Vec<BucketParams>,
    pub g1: G1,
    pub terrain: Option<Arc<TerrainMap>>,
    /// Rust-side height lookup of the uploaded heightfield (None on a plane).
    pub heights: Option<Arc<HeightField>>,
    pub body_class: Vec<BodyClass>,
    /// Robot weight (N) of the nominal model, for normalizing forces.
    pub robot_weight: f64,
    /// Flat tiles served by boxes (empty on a plane or with `flat_boxes: false`).
    pub flat_boxes: Vec<FlatBox>,
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
        let flat_boxes = match (&terrain, cfg.terrain.flat_boxes) {
            (Some(map), true) => flat_tiles(map),
            _ => Vec::new(),
        };
        let xml = scene_xml(cfg, terrain.as_deref(), &flat_boxes);
        let dir = robot::models_dir().join("g1");
        let mut model = Model::from_xml_str(&xml, &dir, "generated G1 scene")?;
        robot::apply_armature(&mut model)?;
        let g1 = G1::resolve(&model)?;
        let terrain_geom = model.id(ObjType::Geom, "terrain")?;
        let heights = match &terrain {
            Some(map) => {
                let hid = model.geom_dataid()[terrain_geom] as usize;
                model.set_hfield_data(hid, &lowered_under_boxes(map, &flat_boxes))?;
                Some(Arc::new(HeightField::from_model(&model, terrain_geom)?))
            }
            None => None,
        };
        configure_collisions(&mut model, &g1, cfg.sim.self_collisions);
        let body_class = classify_bodies(&model, &g1, &cfg.termination.contact_bodies)?;
        let robot_weight = model.body_subtreemass()[g1.pelvis] * 9.81;

        let dr = &cfg.domain_rand;
        let n_buckets = if dr.enabled { dr.model_buckets } else { 1 };
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x00B0_C4E7);
        let mut models = Vec::with_capacity(n_buckets);
        let mut buckets = Vec::with_capacity(n_buckets);
        let mut nominal = Some(model);
        for b in 0..n_buckets {
            let params = if dr.enabled {
                BucketParams {
                    friction: rng.random_range(dr.friction[0]..=dr.friction[1]),
                    added_mass: rng.random_range(dr.added_mass[0]..=dr.added_mass[1]),
                    motor_strength: rng.random_range(dr.motor_strength[0]..=dr.motor_strength[1]),
                }
            } else {
                BucketParams::default()
            };
            // the last bucket takes the nominal model itself, the others copies
            let mut m = match (b + 1 == n_buckets, nominal.as_ref()) {
                (false, Some(nom)) => nom.clone(),
                _ => nominal
                    .take()
                    .expect("nominal model taken once, by the last bucket"),
            };
            apply_bucket(&mut m, &g1, &params)?;
            models.push(Arc::new(m));
            buckets.push(params);
        }
        Ok(Scene {
            models,
            buckets,
            g1,
            terrain,
            heights,
            body_class,
            robot_weight,
            flat_boxes,
        })
    }

    /// Terrain height at a world point (0 on a plane).
    #[inline]
    pub fn ground(&self, x: f64, y: f64) -> f64 {
        let h = self.heights.as_ref().map_or(0.0, |h| h.height(x, y));
        for b in &self.flat_boxes {
            if x >= b.x[0] && x <= b.x[1] && y >= b.y[0] && y <= b.y[1] {
                return h.max(b.top);
            }
        }
        h
    }
}

/// The scene's MJCF: our G1 (`g1_actuators.xml`, included relative to
/// `models/g1/`, where the generated file is written) on a plane or a heightfield.
pub fn scene_xml(cfg: &EnvConfig, terrain: Option<&TerrainMap>, boxes: &[FlatBox]) -> String {
    let (asset, ground) = match terrain {
        None => (
            String::new(),
            r#"<geom name="terrain" type="plane" size="0 0 1" contype="1" conaffinity="1" condim="3"/>"#
                .to_string(),
        ),
        Some(map) => {
            let (size, pos) = (map.hfield_size(), map.hfield_pos());
            let (nrow, ncol) = map.hfield_shape();
            let mut geoms = format!(
                r#"<geom name="terrain" type="hfield" hfield="terrain" pos="{} {} {}" contype="1" conaffinity="1" condim="3"/>"#,
                pos[0], pos[1], pos[2]
            );
            for (k, b) in boxes.iter().enumerate() {
                geoms.push_str(&format!(
                    "\n    <geom name=\"flat_box_{k}\" type=\"box\" pos=\"{} {} {}\" size=\"{} {} 0.5\" contype=\"1\" conaffinity=\"1\" condim=\"3\" rgba=\"0.35 0.45 0.55 1\"/>",
                    0.5 * (b.x[0] + b.x[1]),
                    0.5 * (b.y[0] + b.y[1]),
                    b.top - 0.5,
                    0.5 * (b.x[1] - b.x[0]),
                    0.5 * (b.y[1] - b.y[0]),
                ));
            }
            (
                format!(
                    r#"<asset><hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{} {} {} {}"/></asset>"#,
                    size[0], size[1], size[2], size[3]
                ),
                geoms,
            )
        }
    };
    format!(
        r#"<mujoco model="g1_dreampolicy">
  <include file="g1_actuators.xml"/>
  <option timestep="{dt}" integrator="{integrator}"/>
  {asset}
  <worldbody>
    {ground}
  </worldbody>
</mujoco>
"#,
        dt = cfg.sim.timestep,
        integrator = cfg.sim.integrator.mjcf()
    )
}

/// The Flat tiles of a map, as box tops at the map's ground level (0).
fn flat_tiles(map: &TerrainMap) -> Vec<FlatBox> {
    let mut boxes = Vec::new();
    for col in 0..map.num_cols() {
        if map.tile_kind(col) != TerrainKind::Flat {
            continue;
        }
        for level in 0..map.num_levels() {
            let b = map.tile_bounds(level, col);
            boxes.push(FlatBox {
                x: b.x,
                y: b.y,
                top: 0.0,
            });
        }
    }
    boxes
}

/// The map's normalized heightfield data, lowered to `top - FLAT_BOX_CLEARANCE`
/// wherever a flat box covers it (box edges included).
fn lowered_under_boxes(map: &TerrainMap, boxes: &[FlatBox]) -> Vec<f32> {
    let mut data = map.hfield_data();
    if boxes.is_empty() {
        return data;
    }
    let (nrow, ncol) = map.hfield_shape();
    let (size, pos) = (map.hfield_size(), map.hfield_pos());
    let hs = map.horizontal_scale();
    for b in boxes {
        let limit = (((b.top - FLAT_BOX_CLEARANCE - pos[2]) / size[2]).clamp(0.0, 1.0)) as f32;
        let i0 = (b.x[0] / hs).floor().max(0.0) as usize;
        let i1 = ((b.x[1] / hs).ceil() as usize).min(ncol - 1);
        let j0 = (b.y[0] / hs).floor().max(0.0) as usize;
        let j1 = ((b.y[1] / hs).ceil() as usize).min(nrow - 1);
        for j in j0..=j1 {
            for v in &mut data[j * ncol + i0..=j * ncol + i1] {
                *v = v.min(limit);
            }
        }
    }
    data
}

/// Robot geoms: only the feet keep condim 3 (others frictionless, condim 1, as in
/// mjlab's G1 setup), and without self-collisions the robot's contype is cleared
/// so that robot geoms collide with the ground only.
fn configure_collisions(model: &mut Model, g1: &G1, self_collisions: bool) {
    let bodies = model.geom_bodyid().to_vec();
    let contype = model.geom_contype().to_vec();
    let raw = model.raw_mut();
    for (g, &b) in bodies.iter().enumerate() {
        if b == 0 || contype[g] == 0 && raw_conaffinity(raw, g) == 0 {
            continue; // world geoms and visual-only geoms
        }
        let foot = g1.feet.contains(&(b as usize));
        // SAFETY: g < ngeom; the arrays have ngeom entries.
        unsafe {
            if !foot {
                *raw.geom_condim.add(g) = 1;
            }
            if !self_collisions {
                *raw.geom_contype.add(g) = 0;
            }
        }
    }
}

fn raw_conaffinity(raw: &mujoco_sys::mjModel, g: usize) -> i32 {
    // SAFETY: g < ngeom.
    unsafe { *raw.geom_conaffinity.add(g) }
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
