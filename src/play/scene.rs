//! What `play` draws: the G1 as simple primitives, one entity per body in the
//! body's own frame (so that `/tf` moves them), and the ground: the lane's
//! heightfield as a coloured triangle mesh inside a flat border of 1 m checker
//! tiles, or a checker floor on a plane.
use super::foxglove::{
    Color, CubePrimitive, CylinderPrimitive, Pose, Quaternion, SceneEntity, SpherePrimitive, Time,
    TriangleListPrimitive, Vector3,
};
use crate::sim::{Model, ObjType};
use crate::terrain::TerrainMap;

/// The frame every transform is given in.
pub const WORLD: &str = "world";

const SILVER: Color = Color::rgb(0.78, 0.78, 0.8);
const LEFT: Color = Color::rgb(0.35, 0.55, 0.9);
const RIGHT: Color = Color::rgb(0.92, 0.5, 0.3);
const BONE: Color = Color::rgb(0.3, 0.3, 0.32);
const TILE: [Color; 2] = [Color::rgb(0.55, 0.57, 0.6), Color::rgb(0.68, 0.7, 0.72)];
/// Diameter of the links drawn between a body and its children (m).
const BONE_DIAMETER: f64 = 0.025;
/// Diameter of the sphere drawn at every body's origin (its joint) (m).
const JOINT_DIAMETER: f64 = 0.04;
/// Thickness of the checker tiles, whose top is at height 0 (m).
const TILE_THICKNESS: f64 = 0.04;

/// Round to 10 µm: plenty for viewing, and shorter JSON (`-0` becomes `0`).
pub fn round5(x: f64) -> f64 {
    (x * 1e5).round() / 1e5 + 0.0
}

/// Round to 1e-6 (quaternion components).
pub fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6 + 0.0
}

/// The frame name of body `b`: its MuJoCo name (`body<b>` if it has none).
pub fn body_frames(model: &Model) -> Vec<String> {
    (0..model.nbody())
        .map(|b| match model.id2name(ObjType::Body, b) {
            Some(n) if !n.is_empty() && n != WORLD => n.to_string(),
            _ if b == 0 => WORLD.to_string(),
            _ => format!("body{b}"),
        })
        .collect()
}

fn side_color(name: &str) -> Color {
    if name.starts_with("left_") {
        LEFT
    } else if name.starts_with("right_") {
        RIGHT
    } else {
        SILVER
    }
}

fn v3(v: [f64; 3]) -> Vector3 {
    Vector3::new(v.map(round5))
}

fn pose(pos: [f64; 3], quat_wxyz: [f64; 4]) -> Pose {
    let q = Quaternion::from_mujoco(quat_wxyz.map(round6));
    Pose {
        position: v3(pos),
        orientation: q,
    }
}

/// Rotate `v` by the MuJoCo quaternion `q` (`w, x, y, z`).
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [w, x, y, z] = q;
    // t = 2 (q_vec x v); v' = v + w t + q_vec x t
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

/// The MuJoCo quaternion that turns +z onto the unit vector `d`.
fn z_to(d: [f64; 3]) -> [f64; 4] {
    // half-way quaternion between z and d: (1 + d.z, z x d) normalized
    let (w, x, y) = (1.0 + d[2], -d[1], d[0]);
    let n = (w * w + x * x + y * y).sqrt();
    if n < 1e-9 {
        [0.0, 1.0, 0.0, 0.0] // d = -z: half a turn about x
    } else {
        [w / n, x / n, y / n, 0.0]
    }
}

fn cylinder(
    pos: [f64; 3],
    quat: [f64; 4],
    diameter: f64,
    length: f64,
    color: Color,
) -> CylinderPrimitive {
    CylinderPrimitive {
        pose: pose(pos, quat),
        size: v3([diameter, diameter, length]),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color,
    }
}

fn sphere(pos: [f64; 3], size: [f64; 3], color: Color) -> SpherePrimitive {
    SpherePrimitive {
        pose: pose(pos, [1.0, 0.0, 0.0, 0.0]),
        size: v3(size),
        color,
    }
}

/// One entity per robot body (frame = the body's name, frame-locked), drawn
/// from the model: every primitive geom (spheres, capsules as a cylinder with
/// two spheres, cylinders, boxes, ellipsoids; meshes are left out), a sphere
/// at the body's origin, and a thin link from each body to each child's origin.
/// Left-side bodies are blue, right-side orange, the rest silver.
pub fn robot_entities(model: &Model, timestamp: Time) -> Vec<SceneEntity> {
    use mujoco_sys as sys;
    let frames = body_frames(model);
    let mut entities: Vec<SceneEntity> = frames
        .iter()
        .map(|f| SceneEntity::new(timestamp, f, f, true))
        .collect();
    let (types, sizes) = (model.geom_type(), model.geom_size());
    let (gpos, gquat, gbody) = (model.geom_pos(), model.geom_quat(), model.geom_bodyid());
    for g in 0..model.ngeom() {
        let b = gbody[g] as usize;
        if b == 0 {
            continue; // the ground
        }
        let (s, p, q) = (sizes[g], gpos[g], gquat[g]);
        let c = side_color(&frames[b]);
        let e = &mut entities[b];
        match types[g] as u32 {
            t if t == sys::mjGEOM_SPHERE => e.spheres.push(sphere(p, [2.0 * s[0]; 3], c)),
            t if t == sys::mjGEOM_ELLIPSOID => e.spheres.push(sphere(p, s.map(|x| 2.0 * x), c)),
            t if t == sys::mjGEOM_CAPSULE => {
                e.cylinders.push(cylinder(p, q, 2.0 * s[0], 2.0 * s[1], c));
                for sign in [-1.0, 1.0] {
                    let a = rotate(q, [0.0, 0.0, sign * s[1]]);
                    e.spheres.push(sphere(
                        [p[0] + a[0], p[1] + a[1], p[2] + a[2]],
                        [2.0 * s[0]; 3],
                        c,
                    ));
                }
            }
            t if t == sys::mjGEOM_CYLINDER => {
                e.cylinders.push(cylinder(p, q, 2.0 * s[0], 2.0 * s[1], c))
            }
            t if t == sys::mjGEOM_BOX => e.cubes.push(CubePrimitive {
                pose: pose(p, q),
                size: v3(s.map(|x| 2.0 * x)),
                color: c,
            }),
            _ => {} // meshes (the visual geoms), planes, heightfields
        }
    }
    let (parent, body_pos) = (model.body_parentid(), model.body_pos());
    for b in 1..model.nbody() {
        entities[b]
            .spheres
            .push(sphere([0.0; 3], [JOINT_DIAMETER; 3], BONE));
        let p = parent[b] as usize;
        let d = body_pos[b];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if p == 0 || len < 1e-6 {
            continue;
        }
        let mid = d.map(|x| 0.5 * x);
        let q = z_to(d.map(|x| x / len));
        entities[p]
            .cylinders
            .push(cylinder(mid, q, BONE_DIAMETER, len, BONE));
    }
    entities.remove(0); // the world body
    entities
}

/// Colour of a terrain height: low blue-grey through sand to high brown-red.
fn height_color(h: f64, lo: f64, hi: f64) -> Color {
    let t = if hi - lo > 1e-9 {
        ((h - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let r = |x: f64| (x * 1000.0).round() / 1000.0;
    let stops = [
        [0.25, 0.35, 0.55],
        [0.55, 0.7, 0.55],
        [0.85, 0.78, 0.55],
        [0.7, 0.35, 0.25],
    ];
    let f = t * (stops.len() - 1) as f64;
    let k = (f as usize).min(stops.len() - 2);
    let u = f - k as f64;
    let c: [f64; 3] = std::array::from_fn(|i| r(stops[k][i] + u * (stops[k + 1][i] - stops[k][i])));
    Color::rgb(c[0], c[1], c[2])
}

/// Sample index range `[i0, i1]` covering `[x0, x1]` widened to whole metres,
/// inside `0..n` samples of spacing `hs`.
fn metre_span(x0: f64, x1: f64, hs: f64, n: usize) -> (usize, usize) {
    let i0 = ((x0.floor() / hs).round().max(0.0)) as usize;
    let i1 = ((x1.ceil() / hs).round() as usize).min(n - 1);
    (i0.min(i1), i1)
}

/// 1 m checker tiles (top at height 0) over `[x0, x1] x [y0, y1]` (whole
/// metres), leaving out the tiles inside `hole`.
fn checker(x: [f64; 2], y: [f64; 2], hole: Option<([f64; 2], [f64; 2])>) -> Vec<CubePrimitive> {
    let mut cubes = Vec::new();
    let (nx, ny) = ((x[1] - x[0]).round() as i64, (y[1] - y[0]).round() as i64);
    for j in 0..ny {
        for i in 0..nx {
            let (cx, cy) = (x[0] + i as f64 + 0.5, y[0] + j as f64 + 0.5);
            if hole.is_some_and(|(hx, hy)| cx > hx[0] && cx < hx[1] && cy > hy[0] && cy < hy[1]) {
                continue;
            }
            cubes.push(CubePrimitive {
                pose: Pose::at([cx, cy, -0.5 * TILE_THICKNESS]),
                size: Vector3::new([1.0, 1.0, TILE_THICKNESS]),
                color: TILE[((i + j) % 2) as usize],
            });
        }
    }
    cubes
}

/// The ground of a lane: its tile (plus `margin` metres, widened to whole
/// metres) as a triangle mesh of the heightfield at full resolution, coloured
/// by height, and the rest of the map as checker tiles.
pub fn lane_entity(map: &TerrainMap, margin: f64, timestamp: Time) -> SceneEntity {
    let mut e = SceneEntity::new(timestamp, WORLD, "terrain", false);
    let (nx, ny, hs) = (map.nx(), map.ny(), map.horizontal_scale());
    let b = map.tile_bounds(0, 0);
    let (i0, i1) = metre_span(b.x[0] - margin, b.x[1] + margin, hs, nx);
    let (j0, j1) = metre_span(b.y[0] - margin, b.y[1] + margin, hs, ny);
    let [lo, hi] = map.height_range();
    let w = i1 - i0 + 1;
    let mut tri = TriangleListPrimitive {
        pose: Pose::at([0.0; 3]),
        points: Vec::with_capacity(w * (j1 - j0 + 1)),
        color: SILVER,
        colors: Vec::with_capacity(w * (j1 - j0 + 1)),
        indices: Vec::with_capacity(6 * (w - 1) * (j1 - j0)),
    };
    for j in j0..=j1 {
        for i in i0..=i1 {
            let h = map.height_at(i, j);
            tri.points.push(v3([i as f64 * hs, j as f64 * hs, h]));
            tri.colors.push(height_color(h, lo, hi));
        }
    }
    // MuJoCo's split of each cell: along the diagonal (i, j)-(i+1, j+1)
    for j in 0..(j1 - j0) {
        for i in 0..(w - 1) {
            let a = (j * w + i) as u32;
            let (b1, c, d) = (a + 1, a + w as u32, a + w as u32 + 1);
            tri.indices.extend_from_slice(&[a, b1, d, a, d, c]);
        }
    }
    e.triangles.push(tri);
    let [ex, ey] = map.extent();
    let hole = (
        [i0 as f64 * hs, i1 as f64 * hs],
        [j0 as f64 * hs, j1 as f64 * hs],
    );
    e.cubes = checker([0.0, ex.floor()], [0.0, ey.floor()], Some(hole));
    e
}

/// The ground of a plane: checker tiles over `x` (whole metres) and 5 m to
/// either side of the lane's centre line.
pub fn plane_entity(x: [f64; 2], timestamp: Time) -> SceneEntity {
    let mut e = SceneEntity::new(timestamp, WORLD, "terrain", false);
    e.cubes = checker([x[0].floor(), x[1].ceil()], [-5.0, 5.0], None);
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_to_turns_z_onto_the_direction() {
        for d in [
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [0.6, 0.0, -0.8],
        ] {
            let r = rotate(z_to(d), [0.0, 0.0, 1.0]);
            for k in 0..3 {
                assert!((r[k] - d[k]).abs() < 1e-9, "{d:?} -> {r:?}");
            }
        }
    }

    #[test]
    fn checker_leaves_the_hole_out() {
        let all = checker([0.0, 4.0], [0.0, 3.0], None);
        assert_eq!(all.len(), 12);
        let some = checker([0.0, 4.0], [0.0, 3.0], Some(([1.0, 3.0], [1.0, 2.0])));
        assert_eq!(some.len(), 10);
    }
}
