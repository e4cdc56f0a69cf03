//! Sphere and capsule contacts against a heightfield's surface.
//!
//! MuJoCo collides a geom with a heightfield prism by prism: every triangle of
//! the grid is extruded down to the base into a convex prism, and each prism the
//! geom overlaps gives one contact, at the minimum-penetration direction of that
//! prism. The prisms' side faces lie inside the terrain (neighbouring prisms
//! share them), yet they take part: where a resting foot capsule, sunk a few
//! millimetres into the surface by the soft contact, reaches less than that
//! depth across a cell boundary, the cheapest way out of the neighbouring prism
//! is sideways, and the contact comes back with a horizontal normal (MuJoCo then
//! re-aims capsule normals from the capsule's axis through the contact point,
//! which keeps them tilted). On a perfectly flat heightfield a standing G1 gets
//! ~95 contacts, some tilted by 30-90 degrees, a net sideways ground force of
//! 10-60 N, a foot that tips onto an edge and sinks (1 cm), and it falls
//! where it stands on a plane.
//!
//! [`install`] replaces MuJoCo's heightfield-sphere and heightfield-capsule
//! functions (`mjCOLLISIONFUNC`) with [`collide`], which sees only the surface:
//! the capsule's axis is cut where its ground projection crosses the grid's
//! cells and diagonals; each piece lies over one triangle; consecutive pieces
//! over coplanar triangles are merged; and each merged run gives a contact at
//! both of its ends against its triangle's plane (normal = the triangle's
//! normal, depth = the capsule's clearance to that plane), as MuJoCo's
//! plane-capsule test gives one at each end of the capsule. A capsule on a flat
//! heightfield thus gets the two contacts it gets on a plane. A sphere is a
//! capsule of zero length (one contact, under its centre).
//!
//! Where the surface bends, a contact against a triangle's plane is only right
//! if the capsule is over that triangle. At a convex edge (a block's or a
//! platform's rim, whose vertical face the grid turns into a one-cell ramp) a
//! capsule lying on the top face at the rim is, by the ramp's plane extended
//! back under it, 0.55 of its radius deep (a 10 cm step over a 5 cm cell, a
//! 63-degree ramp): the first version of this module (kept as
//! [`SURFACE_PLANES`]) gave that contact, deeper than the top face's own, along
//! the ramp's normal, which shoves a foot resting on a rim off it, sideways and
//! down (on a gap's 1 m pit, almost horizontally). [`SURFACE_CONTACTS`] takes
//! at each run end the closest point of the surface itself (every triangle
//! around the point): on a face it is the plane contact, at a rim it is the
//! rim, along the direction from the rim to the capsule, and where two runs
//! meet they give one contact, not two.
//!
//! The replacement is process-wide (MuJoCo has one table), so it applies to
//! a heightfield geom only when the geom says so: its first `user` value is
//! [`SURFACE_CONTACTS`] or [`SURFACE_PLANES`] (the scene writes it on the
//! terrain geom). Any other heightfield is handed to MuJoCo's own function.
use std::sync::OnceLock;

use mujoco_sys as sys;

/// `geom_user[0]` of a heightfield geom that asks for surface contacts: the
/// closest point of the surface at each run end (the default).
pub const SURFACE_CONTACTS: f64 = 1.0;
/// `geom_user[0]` of a heightfield geom that asks for the first version's
/// contacts: each run end against its own triangle's plane, extended (before
/// 2026-12-04; see the module doc).
pub const SURFACE_PLANES: f64 = 2.0;

/// Most break points along one axis (ends, grid lines, diagonals). A longer
/// capsule (over ~40 cells) goes to MuJoCo's function.
const MAX_BREAKS: usize = 128;

/// MuJoCo's own heightfield-sphere and heightfield-capsule functions.
static ORIGINAL: OnceLock<[sys::mjfCollision; 2]> = OnceLock::new();

/// Put [`collide`] into MuJoCo's collision table for heightfield-sphere and
/// heightfield-capsule pairs, keeping MuJoCo's functions for the others.
/// Called once, from [`super::handlers::install`], before any model exists.
pub(super) fn install() {
    let (h, s, c) = (
        sys::mjGEOM_HFIELD as usize,
        sys::mjGEOM_SPHERE as usize,
        sys::mjGEOM_CAPSULE as usize,
    );
    // SAFETY: mjCOLLISIONFUNC is MuJoCo's exported table of function pointers;
    // this runs once per process (handlers' Once), before any model or data
    // exists, so no collision can read the table while it is written.
    unsafe {
        let table = &mut *std::ptr::addr_of_mut!(sys::mjCOLLISIONFUNC);
        ORIGINAL.get_or_init(|| [table[h][s], table[h][c]]);
        table[h][s] = Some(collide);
        table[h][c] = Some(collide);
    }
}

/// Which surface contacts heightfield geom `g` of `m` asks for: Some(true) the
/// surface's closest points, Some(false) the triangles' planes, None MuJoCo's.
fn wants_surface(m: &sys::mjModel, g: usize) -> Option<bool> {
    let n = m.nuser_geom;
    if n <= 0 {
        return None;
    }
    // SAFETY: geom_user holds ngeom * nuser_geom values.
    let u = unsafe { *m.geom_user.add(g * n as usize) };
    if u == SURFACE_CONTACTS {
        Some(true)
    } else if u == SURFACE_PLANES {
        Some(false)
    } else {
        None
    }
}

/// MuJoCo's collision-function signature: heightfield `g1`, sphere or capsule
/// `g2`; writes at most `mjMAXCONPAIR` contacts into `con`, returns their count.
///
/// # Safety
/// Called by MuJoCo's collision driver with a valid model, data, a contact
/// buffer of `mjMAXCONPAIR` entries, and geoms of the registered types.
unsafe extern "C" fn collide(
    m: *const sys::mjModel,
    d: *const sys::mjData,
    con: *mut sys::mjContact,
    g1: i32,
    g2: i32,
    margin: f64,
) -> i32 {
    // SAFETY: MuJoCo passes valid pointers for the duration of the call.
    let (mr, dr) = unsafe { (&*m, &*d) };
    let capsule = unsafe { *mr.geom_type.add(g2 as usize) } == sys::mjGEOM_CAPSULE as i32;
    if let Some(closest) = wants_surface(mr, g1 as usize) {
        // SAFETY: as above; con has room for mjMAXCONPAIR contacts.
        let out = unsafe { std::slice::from_raw_parts_mut(con, sys::mjMAXCONPAIR as usize) };
        if let Some(n) = surface_contacts(mr, dr, out, g1 as usize, g2 as usize, margin, closest) {
            return n as i32;
        }
    }
    match ORIGINAL.get().and_then(|o| o[capsule as usize]) {
        // SAFETY: MuJoCo's own function, called with MuJoCo's own arguments.
        Some(f) => unsafe { f(m, d, con, g1, g2, margin) },
        None => 0,
    }
}

/// The heightfield of a geom, in its own frame: vertex `(c, r)` sits at
/// `(c * dx - sx, r * dy - sy, data[r * ncol + c] * sz)`.
struct Grid<'a> {
    data: &'a [f32],
    nrow: usize,
    ncol: usize,
    size: [f64; 4],
    dx: f64,
    dy: f64,
}

impl Grid<'_> {
    fn z(&self, c: usize, r: usize) -> f64 {
        self.data[r * self.ncol + c] as f64 * self.size[2]
    }

    /// The triangle under grid point `(gx, gy)` (grid units): its corner `(c, r)`
    /// and its plane `z = z0 + sx * (x - x0) + sy * (y - y0)` as
    /// `(x0, y0, z0, sx, sy)`. Cells are split along `(c, r)`-`(c+1, r+1)`, as
    /// MuJoCo triangulates them. None off the grid.
    fn plane(&self, gx: f64, gy: f64) -> Option<[f64; 5]> {
        if !(gx >= 0.0 && gy >= 0.0) {
            return None;
        }
        let (c, r) = (gx.floor() as usize, gy.floor() as usize);
        if c + 1 >= self.ncol || r + 1 >= self.nrow {
            return None;
        }
        let (u, v) = (gx - c as f64, gy - r as f64);
        let [x0, y0, h00] = self.vertex(c, r);
        let h11 = self.z(c + 1, r + 1);
        let (sx, sy) = if u >= v {
            let h10 = self.z(c + 1, r);
            ((h10 - h00) / self.dx, (h11 - h10) / self.dy)
        } else {
            let h01 = self.z(c, r + 1);
            ((h11 - h01) / self.dx, (h01 - h00) / self.dy)
        };
        Some([x0, y0, h00, sx, sy])
    }

    /// Point `(x, y)` of the heightfield's frame in grid units.
    fn to_grid(&self, x: f64, y: f64) -> [f64; 2] {
        [(x + self.size[0]) / self.dx, (y + self.size[1]) / self.dy]
    }

    /// Vertex `(c, r)` in the heightfield's frame.
    fn vertex(&self, c: usize, r: usize) -> [f64; 3] {
        [
            c as f64 * self.dx - self.size[0],
            r as f64 * self.dy - self.size[1],
            self.z(c, r),
        ]
    }

    /// The closest point to `q` (heightfield frame) of the triangles of the
    /// cells within `reach` cells of `q`'s cell, or None if there are none.
    fn closest_point(&self, q: [f64; 3], reach: usize) -> Option<[f64; 3]> {
        let [gx, gy] = self.to_grid(q[0], q[1]);
        if !(gx >= 0.0 && gy >= 0.0) {
            return None;
        }
        let (c, r) = (gx.floor() as usize, gy.floor() as usize);
        let mut best: Option<([f64; 3], f64)> = None;
        for rr in r.saturating_sub(reach)..=(r + reach).min(self.nrow.saturating_sub(2)) {
            for cc in c.saturating_sub(reach)..=(c + reach).min(self.ncol.saturating_sub(2)) {
                let (v00, v11) = (self.vertex(cc, rr), self.vertex(cc + 1, rr + 1));
                for tri in [
                    [v00, self.vertex(cc + 1, rr), v11],
                    [v00, v11, self.vertex(cc, rr + 1)],
                ] {
                    let p = closest_on_triangle(q, &tri);
                    let d = sub(q, p);
                    let d2 = dot(d, d);
                    if best.is_none_or(|(_, b)| d2 < b) {
                        best = Some((p, d2));
                    }
                }
            }
        }
        best.map(|(p, _)| p)
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn along(a: [f64; 3], d: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] + s * d[0], a[1] + s * d[1], a[2] + s * d[2]]
}

/// The point of triangle `t` closest to `p` (Ericson, Real-Time Collision
/// Detection, 5.1.5: the Voronoi regions of the vertices, edges and face).
fn closest_on_triangle(p: [f64; 3], t: &[[f64; 3]; 3]) -> [f64; 3] {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return along(a, ab, d1 / (d1 - d3));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return along(a, ac, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    along(along(a, ab, vb * denom), ac, vc * denom)
}

fn mat_t_vec(mat: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        mat[0] * v[0] + mat[3] * v[1] + mat[6] * v[2],
        mat[1] * v[0] + mat[4] * v[1] + mat[7] * v[2],
        mat[2] * v[0] + mat[5] * v[1] + mat[8] * v[2],
    ]
}

fn mat_vec(mat: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        mat[0] * v[0] + mat[1] * v[1] + mat[2] * v[2],
        mat[3] * v[0] + mat[4] * v[1] + mat[5] * v[2],
        mat[6] * v[0] + mat[7] * v[1] + mat[8] * v[2],
    ]
}

/// Surface contacts of sphere/capsule `g2` with heightfield `g1` (module doc).
/// None when the capsule crosses too many cells: MuJoCo's function takes it.
fn surface_contacts(
    m: &sys::mjModel,
    d: &sys::mjData,
    con: &mut [sys::mjContact],
    g1: usize,
    g2: usize,
    margin: f64,
    closest: bool,
) -> Option<usize> {
    // SAFETY: every read below is inside MuJoCo's arrays for valid ids g1, g2
    // (geom_* have ngeom entries, hfield_* nhfield, hfield_data nhfielddata).
    let (grid, p1, mat1, p2, mat2, gsize) = unsafe {
        let hid = *m.geom_dataid.add(g1) as usize;
        let nrow = *m.hfield_nrow.add(hid) as usize;
        let ncol = *m.hfield_ncol.add(hid) as usize;
        let size = *(m.hfield_size.add(4 * hid) as *const [f64; 4]);
        let data = std::slice::from_raw_parts(
            m.hfield_data.add(*m.hfield_adr.add(hid) as usize),
            nrow * ncol,
        );
        let grid = Grid {
            data,
            nrow,
            ncol,
            size,
            dx: 2.0 * size[0] / (ncol - 1) as f64,
            dy: 2.0 * size[1] / (nrow - 1) as f64,
        };
        (
            grid,
            *(d.geom_xpos.add(3 * g1) as *const [f64; 3]),
            &*(d.geom_xmat.add(9 * g1) as *const [f64; 9]),
            *(d.geom_xpos.add(3 * g2) as *const [f64; 3]),
            &*(d.geom_xmat.add(9 * g2) as *const [f64; 9]),
            *(m.geom_size.add(3 * g2) as *const [f64; 3]),
        )
    };
    let capsule = unsafe { *m.geom_type.add(g2) } == sys::mjGEOM_CAPSULE as i32;
    let (radius, half) = (gsize[0], if capsule { gsize[1] } else { 0.0 });

    // the axis in the heightfield's frame
    let centre = mat_t_vec(mat1, [p2[0] - p1[0], p2[1] - p1[1], p2[2] - p1[2]]);
    let axis = mat_t_vec(mat1, [mat2[2], mat2[5], mat2[8]]);
    let a = [
        centre[0] - half * axis[0],
        centre[1] - half * axis[1],
        centre[2] - half * axis[2],
    ];
    let ab = [
        2.0 * half * axis[0],
        2.0 * half * axis[1],
        2.0 * half * axis[2],
    ];
    // above the highest possible surface: nothing
    if a[2].min(a[2] + ab[2]) - radius > grid.size[2] + margin {
        return Some(0);
    }

    // grid coordinates along the axis: g(t) = ga + t * gd, t in [0, 1]
    let ga = grid.to_grid(a[0], a[1]);
    let gd = [ab[0] / grid.dx, ab[1] / grid.dy];

    // break points: the ends, and where the projection crosses x or y grid
    // lines or the cells' diagonals (x - y = integer in grid units)
    let mut breaks = [0.0f64; MAX_BREAKS];
    breaks[1] = 1.0;
    let mut nb = 2;
    for (start, delta) in [
        (ga[0], gd[0]),
        (ga[1], gd[1]),
        (ga[0] - ga[1], gd[0] - gd[1]),
    ] {
        if delta.abs() < 1e-12 {
            continue;
        }
        let (lo, hi) = (start.min(start + delta), start.max(start + delta));
        let mut k = lo.floor() + 1.0;
        while k < hi {
            if nb == MAX_BREAKS {
                return None;
            }
            breaks[nb] = (k - start) / delta;
            nb += 1;
            k += 1.0;
        }
    }
    let breaks = &mut breaks[..nb];
    breaks.sort_unstable_by(f64::total_cmp);

    // clearance of the capsule at axis parameter t to plane p
    let point = |t: f64| [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
    let plane_contact = |t: f64, p: &[f64; 5]| {
        let [x0, y0, z0, sx, sy] = *p;
        let inv = 1.0 / (1.0 + sx * sx + sy * sy).sqrt();
        let n = [-sx * inv, -sy * inv, inv];
        let q = point(t);
        let dist = n[0] * (q[0] - x0) + n[1] * (q[1] - y0) + n[2] * (q[2] - z0) - radius;
        (q, n, dist)
    };
    // cells around a point that can hold a surface point within the contact
    // distance (radius + margin): no farther one can give a contact
    let reach = ((radius + margin.max(0.0)) / grid.dx.min(grid.dy)).ceil() as usize;
    let reach = reach.clamp(1, 4);
    let mut count = 0;
    let mut emit = |t: f64, p: &[f64; 5], con: &mut [sys::mjContact]| {
        let (q, mut n, mut dist) = plane_contact(t, p);
        if dist >= margin || count >= con.len() {
            return;
        }
        // the surface's own closest point, unless the axis is under the plane
        // (deeper than the radius: the plane's direction is the way out)
        if closest && dist + radius > 0.0 {
            if let Some(c) = grid.closest_point(q, reach) {
                let d = sub(q, c);
                let len = dot(d, d).sqrt();
                if len > 1e-12 {
                    n = [d[0] / len, d[1] / len, d[2] / len];
                    dist = len - radius;
                    if dist >= margin {
                        return;
                    }
                }
            }
        }
        // midway between the capsule's lowest point and the surface
        let s = radius + 0.5 * dist;
        let pos = mat_vec(mat1, [q[0] - s * n[0], q[1] - s * n[1], q[2] - s * n[2]]);
        let c = &mut con[count];
        c.dist = dist;
        c.pos = [pos[0] + p1[0], pos[1] + p1[1], pos[2] + p1[2]];
        let nw = mat_vec(mat1, n);
        c.frame = [nw[0], nw[1], nw[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        count += 1;
    };

    // a sphere, or a capsule standing on end: one point
    if gd[0].abs() + gd[1].abs() < 1e-9 {
        if let Some(p) = grid.plane(ga[0], ga[1]) {
            let t = if ab[2] < 0.0 { 1.0 } else { 0.0 };
            emit(t, &p, con);
        }
        return Some(count);
    }

    // runs of pieces over coplanar triangles; a contact at each end of a run
    // (with closest points, one where two runs meet: the same point of the
    // surface, taken with the deeper of the two planes)
    let mut ends = [(0.0f64, [0.0f64; 5]); 2 * MAX_BREAKS];
    let mut ne = 0;
    let mut push = |t: f64, p: [f64; 5]| {
        if closest && ne > 0 && ends[ne - 1].0 == t {
            if plane_contact(t, &p).2 < plane_contact(t, &ends[ne - 1].1).2 {
                ends[ne - 1].1 = p;
            }
        } else {
            ends[ne] = (t, p);
            ne += 1;
        }
    };
    let mut run: Option<(f64, f64, [f64; 5])> = None;
    for w in breaks.windows(2) {
        let (t0, t1) = (w[0], w[1]);
        if t1 - t0 < 1e-12 {
            continue;
        }
        let tm = 0.5 * (t0 + t1);
        let here = grid.plane(ga[0] + tm * gd[0], ga[1] + tm * gd[1]);
        match (&mut run, here) {
            (Some((_, end, p)), Some(h))
                if (p[3] - h[3]).abs() < 1e-9 && (p[4] - h[4]).abs() < 1e-9 =>
            {
                *end = t1;
            }
            _ => {
                if let Some((s, e, p)) = run.take() {
                    push(s, p);
                    push(e, p);
                }
                run = here.map(|h| (t0, t1, h));
            }
        }
    }
    if let Some((s, e, p)) = run {
        push(s, p);
        push(e, p);
    }
    for (t, p) in &ends[..ne] {
        emit(*t, p, con);
    }
    Some(count)
}
