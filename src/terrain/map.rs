//! [`TerrainMap`]: legged_gym's grid of tiles (rows = difficulty levels along x,
//! columns = kinds along y) inside a flat border, with spawn points, tile
//! bounds, the edge mask, height lookups and the MuJoCo heightfield export.
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::canvas::{quantize, samples, Canvas};
use super::shapes::{add_roughness, TileParams};
use super::{TerrainConfig, TerrainError, TerrainKind, SPAWN_OFFSET};
use crate::sim::HeightField;

/// MuJoCo's heightfield base depth (`size[3]`), the box under the lowest point (m).
pub const HFIELD_BASE: f64 = 1.0;
/// The smallest elevation range given to MuJoCo (`size[2]`), for a flat map (m).
pub const MIN_ELEVATION_RANGE: f64 = 1e-3;
/// The RNG stream of the border's roughness.
pub(crate) const BORDER_STREAM: u64 = u64::MAX;

/// The RNG of tile `(row, col)`: ChaCha8 keyed by the seed, one stream per tile,
/// so a tile does not depend on any other tile or on the map's size.
pub fn tile_rng(seed: u64, row: usize, col: usize) -> ChaCha8Rng {
    stream_rng(seed, ((row as u64) << 32) | col as u64)
}

pub(crate) fn stream_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// World-space bounds of one tile (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileBounds {
    pub x: [f64; 2],
    pub y: [f64; 2],
}

/// Kind, level and drawn parameters of one tile.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TileInfo {
    pub kind: TerrainKind,
    pub level: usize,
    pub params: TileParams,
}

/// Sizes in samples of a map under construction.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout {
    pub rows: usize,
    pub cols: usize,
    /// Samples per tile along x and y.
    pub tile: [usize; 2],
    pub border: usize,
}

/// A generated terrain: heights in metres on an `nx x ny` grid, y-major
/// (`heights()[j * nx + i]` is at world `(i * hs, j * hs)`, the map's corner
/// at the origin, border included).
#[derive(Debug, Clone)]
pub struct TerrainMap {
    nx: usize,
    ny: usize,
    hs: f64,
    vs: f64,
    heights: Vec<f64>,
    edges: Vec<bool>,
    layout: Layout,
    tiles: Vec<TileInfo>,
}

impl TerrainMap {
    /// legged_gym's curriculum map: row `l` holds level `l` of every column's
    /// kind. Deterministic: the same config and seed give bit-identical heights.
    pub fn generate(cfg: &TerrainConfig, seed: u64) -> Result<TerrainMap, TerrainError> {
        cfg.validate()?;
        let hs = cfg.horizontal_scale;
        let layout = Layout {
            rows: cfg.num_levels,
            cols: cfg.num_cols,
            tile: [
                samples(cfg.tile_length, hs, 1),
                samples(cfg.tile_width, hs, 1),
            ],
            border: samples(cfg.border, hs, 0),
        };
        let kinds = cfg.column_kinds();
        let mut map = TerrainMap::blank(cfg, seed, layout);
        for row in 0..layout.rows {
            for (col, &kind) in kinds.iter().enumerate() {
                let tile = kind.tile_unchecked(cfg, row, &mut tile_rng(seed, row, col));
                map.blit(row, col, tile.nx, &tile.heights);
                map.tiles.push(TileInfo {
                    kind,
                    level: row,
                    params: tile.params,
                });
            }
        }
        map.finish(cfg);
        Ok(map)
    }

    /// A map of `layout` whose every sample is border: flat with the minimum
    /// roughness; tiles are blitted over it, then [`TerrainMap::finish`].
    pub(crate) fn blank(cfg: &TerrainConfig, seed: u64, layout: Layout) -> TerrainMap {
        let nx = 2 * layout.border + layout.rows * layout.tile[0] + 1;
        let ny = 2 * layout.border + layout.cols * layout.tile[1] + 1;
        let mut c = Canvas::new(nx, ny, cfg.horizontal_scale);
        add_roughness(&mut c, cfg, 0.0, &mut stream_rng(seed, BORDER_STREAM));
        TerrainMap {
            nx,
            ny,
            hs: cfg.horizontal_scale,
            vs: cfg.vertical_scale,
            heights: c.h,
            edges: Vec::new(),
            layout,
            tiles: Vec::with_capacity(layout.rows * layout.cols),
        }
    }

    /// Copy a tile's y-major heights (`nx` samples a row) into place.
    pub(crate) fn blit(&mut self, row: usize, col: usize, nx: usize, heights: &[f64]) {
        let i0 = self.layout.border + row * self.layout.tile[0];
        let j0 = self.layout.border + col * self.layout.tile[1];
        for (j, src) in heights.chunks_exact(nx).enumerate() {
            let dst = (j0 + j) * self.nx + i0;
            self.heights[dst..dst + nx].copy_from_slice(src);
        }
    }

    pub(crate) fn push_tile(&mut self, info: TileInfo) {
        self.tiles.push(info);
    }

    /// Quantize to the vertical scale and compute the edge mask.
    pub(crate) fn finish(&mut self, cfg: &TerrainConfig) {
        for h in &mut self.heights {
            *h = quantize(*h, self.vs);
        }
        let (nx, ny, h) = (self.nx, self.ny, &self.heights);
        let thr = cfg.edge_threshold;
        self.edges = (0..nx * ny)
            .map(|k| {
                let (i, j) = (k % nx, k / nx);
                let d = |o: usize| (h[k] - h[o]).abs() > thr;
                (i > 0 && d(k - 1))
                    || (i + 1 < nx && d(k + 1))
                    || (j > 0 && d(k - nx))
                    || (j + 1 < ny && d(k + nx))
            })
            .collect();
    }

    /// Samples along x.
    pub fn nx(&self) -> usize {
        self.nx
    }
    /// Samples along y.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Grid spacing (m).
    pub fn horizontal_scale(&self) -> f64 {
        self.hs
    }
    /// Height quantum (m).
    pub fn vertical_scale(&self) -> f64 {
        self.vs
    }
    /// Heights (m), y-major: `heights()[j * nx() + i]`.
    pub fn heights(&self) -> &[f64] {
        &self.heights
    }
    /// Height (m) of sample `(i, j)`.
    pub fn height_at(&self, i: usize, j: usize) -> f64 {
        self.heights[j * self.nx + i]
    }
    /// World extent `[x, y]` of the grid (m): samples span `[0, extent]`.
    pub fn extent(&self) -> [f64; 2] {
        [
            (self.nx - 1) as f64 * self.hs,
            (self.ny - 1) as f64 * self.hs,
        ]
    }
    /// Rows of tiles (difficulty levels; 1 for a lane).
    pub fn num_levels(&self) -> usize {
        self.layout.rows
    }
    /// Columns of tiles.
    pub fn num_cols(&self) -> usize {
        self.layout.cols
    }
    /// Samples per tile `[along x, along y]`.
    pub fn tile_samples(&self) -> [usize; 2] {
        self.layout.tile
    }
    /// Border width in samples.
    pub fn border_samples(&self) -> usize {
        self.layout.border
    }

    fn tile(&self, level: usize, col: usize) -> &TileInfo {
        assert!(
            level < self.layout.rows && col < self.layout.cols,
            "tile ({level}, {col}) outside the {} x {} map",
            self.layout.rows,
            self.layout.cols
        );
        &self.tiles[level * self.layout.cols + col]
    }

    /// The kind of column `col`. Panics if `col >= num_cols()`.
    pub fn tile_kind(&self, col: usize) -> TerrainKind {
        self.tile(0, col).kind
    }

    /// What was drawn in tile `(level, col)` (positions relative to the tile's
    /// start). Panics outside the map.
    pub fn tile_params(&self, level: usize, col: usize) -> &TileParams {
        &self.tile(level, col).params
    }

    /// The curriculum level of row `row` (the row itself in a generated map).
    pub fn tile_level(&self, row: usize) -> usize {
        self.tile(row, 0).level
    }

    /// World bounds of tile `(level, col)`. Panics outside the map.
    pub fn tile_bounds(&self, level: usize, col: usize) -> TileBounds {
        let _ = self.tile(level, col);
        let [tx, ty] = self.layout.tile;
        let b = self.layout.border;
        let hs = self.hs;
        TileBounds {
            x: [
                (b + level * tx) as f64 * hs,
                (b + (level + 1) * tx) as f64 * hs,
            ],
            y: [(b + col * ty) as f64 * hs, (b + (col + 1) * ty) as f64 * hs],
        }
    }

    /// The tile `(level, col)` that world `(x, y)` lies in; `None` on the
    /// border or off the map.
    pub fn tile_at(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let [tx, ty] = self.layout.tile;
        let b = self.layout.border as f64 * self.hs;
        let fx = (x - b) / (tx as f64 * self.hs);
        let fy = (y - b) / (ty as f64 * self.hs);
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (row, col) = (fx as usize, fy as usize);
        (row < self.layout.rows && col < self.layout.cols).then_some((row, col))
    }

    /// Spawn point of tile `(level, col)`: 1 m into the tile, on its centre line,
    /// at ground height. Panics outside the map.
    pub fn spawn(&self, level: usize, col: usize) -> [f64; 3] {
        let b = self.tile_bounds(level, col);
        let (x, y) = (b.x[0] + SPAWN_OFFSET, 0.5 * (b.y[0] + b.y[1]));
        [x, y, self.height(x, y)]
    }

    /// Height of MuJoCo's surface at world `(x, y)`, clamped to the grid: each
    /// cell split along the diagonal `(i, j)`-`(i+1, j+1)` into two planar
    /// triangles, as MuJoCo collides with it and [`HeightField::height`] reads it.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let cell = |p: f64, n: usize| {
            let f = (p / self.hs).clamp(0.0, (n - 1) as f64);
            let k = (f as usize).min(n - 2);
            (k, f - k as f64)
        };
        let ((i, u), (j, v)) = (cell(x, self.nx), cell(y, self.ny));
        let at = |di: usize, dj: usize| self.height_at(i + di, j + dj);
        let (a, b, c, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
        if u >= v {
            a + u * (b - a) + v * (d - b)
        } else {
            a + v * (c - a) + u * (d - c)
        }
    }

    /// Per-sample edge flags, y-major like [`TerrainMap::heights`]: true where a
    /// 4-neighbour differs by more than `edge_threshold` (both sides of a step).
    pub fn edge_mask(&self) -> &[bool] {
        &self.edges
    }

    /// The edge flag of the sample nearest to world `(x, y)`; false off the grid.
    pub fn is_edge(&self, x: f64, y: f64) -> bool {
        let (fi, fj) = ((x / self.hs).round(), (y / self.hs).round());
        if !(fi >= 0.0 && fj >= 0.0 && fi < self.nx as f64 && fj < self.ny as f64) {
            return false;
        }
        self.edges[fj as usize * self.nx + fi as usize]
    }

    /// Lowest and highest height (m).
    pub fn height_range(&self) -> [f64; 2] {
        self.heights
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], &h| {
                [lo.min(h), hi.max(h)]
            })
    }

    /// MuJoCo's `(nrow, ncol)` = `(ny, nx)`.
    pub fn hfield_shape(&self) -> (usize, usize) {
        (self.ny, self.nx)
    }

    /// Elevations normalized to `[0, 1]` in MuJoCo's layout (row-major, rows
    /// along y): world height = `hfield_pos()[2] + data * hfield_size()[2]`.
    pub fn hfield_data(&self) -> Vec<f32> {
        let [lo, _] = self.height_range();
        let range = self.hfield_size()[2];
        self.heights
            .iter()
            .map(|h| (((h - lo) / range) as f32).clamp(0.0, 1.0))
            .collect()
    }

    /// MuJoCo's hfield `size`: half extents in x and y, the elevation range
    /// (at least [`MIN_ELEVATION_RANGE`]) and the base depth [`HFIELD_BASE`].
    /// MuJoCo fixes `size` and the geom's `pos` when it compiles the model, so
    /// another map uploaded into the same model at run time must share them
    /// (same layout and height range); otherwise compile a new model.
    pub fn hfield_size(&self) -> [f64; 4] {
        let [ex, ey] = self.extent();
        let [lo, hi] = self.height_range();
        [
            ex / 2.0,
            ey / 2.0,
            (hi - lo).max(MIN_ELEVATION_RANGE),
            HFIELD_BASE,
        ]
    }

    /// Position of the hfield geom: the map's centre, at the lowest height.
    pub fn hfield_pos(&self) -> [f64; 3] {
        let [ex, ey] = self.extent();
        [ex / 2.0, ey / 2.0, self.height_range()[0]]
    }

    /// MJCF for this map: an `<hfield>` asset and its world `<geom>`, both named
    /// `name`; upload [`TerrainMap::hfield_data`] after compiling.
    pub fn hfield_mjcf(&self, name: &str) -> (String, String) {
        let (nrow, ncol) = self.hfield_shape();
        let [a, b, c, d] = self.hfield_size();
        let [x, y, z] = self.hfield_pos();
        (
            format!(
                r#"<hfield name="{name}" nrow="{nrow}" ncol="{ncol}" size="{a} {b} {c} {d}"/>"#
            ),
            format!(r#"<geom name="{name}" type="hfield" hfield="{name}" pos="{x} {y} {z}"/>"#),
        )
    }

    /// The [`HeightField`] MuJoCo sees once [`TerrainMap::hfield_data`] is
    /// uploaded with [`TerrainMap::hfield_size`] and [`TerrainMap::hfield_pos`].
    pub fn height_field(&self) -> HeightField {
        let (nrow, ncol) = self.hfield_shape();
        HeightField::new(
            nrow,
            ncol,
            self.hfield_size(),
            self.hfield_pos(),
            self.hfield_data(),
        )
        .expect("a terrain map has at least 2 x 2 samples and nrow * ncol values")
    }
}
