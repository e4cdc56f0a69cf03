//! Height lookups over a MuJoCo heightfield, in Rust, without ray casting.
//!
//! MuJoCo's heightfield surface is piecewise planar: every grid cell is split
//! along the diagonal from `(r, c)` to `(r+1, c+1)` into two triangles (see
//! `mj_rayHfield` and the hfield collider). [`HeightField::height`] evaluates
//! exactly that surface, so it agrees with `mj_ray` to floating-point precision;
//! [`HeightField::height_bilinear`] is the smooth bilinear interpolant, equal to
//! the triangles wherever a cell is planar.
use super::{Model, SimError};

/// A heightfield placed in the world by an axis-aligned geom.
#[derive(Debug, Clone)]
pub struct HeightField {
    nrow: usize,
    ncol: usize,
    /// MuJoCo's `(radius_x, radius_y, elevation_z, base_z)`.
    size: [f64; 4],
    /// World position of the geom frame (the hfield's centre, at elevation 0).
    origin: [f64; 3],
    /// Normalized elevations, row-major; row index = y, column index = x.
    data: Vec<f32>,
    dx: f64,
    dy: f64,
}

impl HeightField {
    /// Build from explicit parts (`data.len() == nrow * ncol`, values in [0, 1]).
    pub fn new(
        nrow: usize,
        ncol: usize,
        size: [f64; 4],
        origin: [f64; 3],
        data: Vec<f32>,
    ) -> Result<HeightField, SimError> {
        if nrow < 2 || ncol < 2 {
            return Err(SimError::Hfield(format!(
                "needs at least 2x2 samples, got {nrow}x{ncol}"
            )));
        }
        if data.len() != nrow * ncol {
            return Err(SimError::Size {
                what: "heightfield data (nrow * ncol)",
                expected: nrow * ncol,
                got: data.len(),
            });
        }
        Ok(HeightField {
            nrow,
            ncol,
            size,
            origin,
            data,
            dx: 2.0 * size[0] / (ncol - 1) as f64,
            dy: 2.0 * size[1] / (nrow - 1) as f64,
        })
    }

    /// Copy heightfield geom `geom` (type hfield, attached to the world body with
    /// identity orientation) out of a compiled model.
    pub fn from_model(model: &Model, geom: usize) -> Result<HeightField, SimError> {
        if geom >= model.ngeom() {
            return Err(SimError::BadIndex {
                kind: "geom",
                index: geom,
                count: model.ngeom(),
            });
        }
        if model.geom_type()[geom] != mujoco_sys::mjGEOM_HFIELD as i32 {
            return Err(SimError::Hfield(format!(
                "geom {geom} is not a heightfield"
            )));
        }
        let q = model.geom_quat()[geom];
        if (q[0] - 1.0).abs() > 1e-9 || model.geom_bodyid()[geom] != 0 {
            return Err(SimError::Hfield(
                "only world-attached, axis-aligned heightfield geoms are supported".into(),
            ));
        }
        let id = model.geom_dataid()[geom] as usize;
        let info = model.hfield(id)?;
        HeightField::new(
            info.nrow,
            info.ncol,
            info.size,
            model.geom_pos()[geom],
            model.hfield_data(id)?.to_vec(),
        )
    }

    pub fn nrow(&self) -> usize {
        self.nrow
    }
    pub fn ncol(&self) -> usize {
        self.ncol
    }
    pub fn size(&self) -> [f64; 4] {
        self.size
    }
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }
    /// Sample spacing along x (m).
    pub fn dx(&self) -> f64 {
        self.dx
    }

    /// Cell coordinates of a world point, clamped to the field: `(r, c, u, v)`
    /// with `u` along x (columns) and `v` along y (rows), both in [0, 1].
    #[inline]
    fn locate(&self, x: f64, y: f64) -> (usize, usize, f64, f64) {
        let fx = ((x - self.origin[0] + self.size[0]) / self.dx).clamp(0.0, (self.ncol - 1) as f64);
        let fy = ((y - self.origin[1] + self.size[1]) / self.dy).clamp(0.0, (self.nrow - 1) as f64);
        let c = (fx as usize).min(self.ncol - 2);
        let r = (fy as usize).min(self.nrow - 2);
        (r, c, fx - c as f64, fy - r as f64)
    }

    #[inline]
    fn corners(&self, r: usize, c: usize) -> (f64, f64, f64, f64) {
        let i = r * self.ncol + c;
        let d = &self.data;
        (
            d[i] as f64,
            d[i + 1] as f64,
            d[i + self.ncol] as f64,
            d[i + self.ncol + 1] as f64,
        )
    }

    #[inline]
    fn to_world(&self, normalized: f64) -> f64 {
        self.origin[2] + normalized * self.size[2]
    }

    /// World height of MuJoCo's surface at `(x, y)` (clamped to the field's edge).
    #[inline]
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let (r, c, u, v) = self.locate(x, y);
        let (h00, h10, h01, h11) = self.corners(r, c);
        // h10 = (r, c+1), h01 = (r+1, c). Diagonal from (0,0) to (1,1).
        let h = if u >= v {
            h00 + u * (h10 - h00) + v * (h11 - h10)
        } else {
            h00 + v * (h01 - h00) + u * (h11 - h01)
        };
        self.to_world(h)
    }

    /// The surface a foot steps over: the field's morphological closing (a
    /// max filter, then a min filter, over a square of `2 radius + 1` samples).
    /// Pits narrower than the square (a gap between platforms, a sliver
    /// between two blocks) are filled to the lower of their rims; monotone
    /// edges (a riser, a block's side wider than the square) and anything
    /// higher than its surroundings are left where they are. `radius == 0` is
    /// the field itself.
    pub fn closed(&self, radius: usize) -> HeightField {
        let mut data = self.data.clone();
        if radius > 0 {
            let (nr, nc) = (self.nrow, self.ncol);
            let max = |a: f32, b: f32| a.max(b);
            let min = |a: f32, b: f32| a.min(b);
            running(&mut data, nr, nc, radius, max);
            running(&mut data, nr, nc, radius, min);
        }
        HeightField {
            data,
            ..self.clone()
        }
    }

    /// World height by bilinear interpolation of the four cell corners.
    #[inline]
    pub fn height_bilinear(&self, x: f64, y: f64) -> f64 {
        let (r, c, u, v) = self.locate(x, y);
        let (h00, h10, h01, h11) = self.corners(r, c);
        let h = (1.0 - v) * ((1.0 - u) * h00 + u * h10) + v * ((1.0 - u) * h01 + u * h11);
        self.to_world(h)
    }
}

/// Replace every sample of a row-major `nr x nc` grid by `op` over the square of
/// `2 radius + 1` samples around it (clipped at the edges): along rows, then
/// along columns (separable for max and min).
fn running(data: &mut [f32], nr: usize, nc: usize, radius: usize, op: impl Fn(f32, f32) -> f32) {
    let mut line = Vec::new();
    // (lines, samples a line, stride between lines, stride along a line)
    let (rows, cols) = ((nr, nc, nc, 1), (nc, nr, 1, nc));
    for (lines, n, between, along) in [rows, cols] {
        for l in 0..lines {
            let at = |k: usize| l * between + k * along;
            line.clear();
            line.extend((0..n).map(|k| data[at(k)]));
            for k in 0..n {
                let (lo, hi) = (k.saturating_sub(radius), (k + radius).min(n - 1));
                data[at(k)] = line[lo..=hi].iter().copied().reduce(&op).unwrap_or(line[k]);
            }
        }
    }
}
