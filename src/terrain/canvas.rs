//! One tile's (or lane's) height grid while it is drawn: metre heights, y-major,
//! sample `(i, j)` at local `(i * hs, j * hs)`; rectangle fills in whole samples,
//! the base roughness; and the rounding helpers.
use std::ops::Range;

use rand::Rng;

/// A height grid under construction.
#[derive(Debug, Clone)]
pub(crate) struct Canvas {
    pub nx: usize,
    pub ny: usize,
    pub hs: f64,
    pub h: Vec<f64>,
}

/// The samples `i0..i1` along x where a generator may put obstacles; outside it
/// the ground stays at 0 (spawn area before, end area after).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Region {
    pub i0: usize,
    pub i1: usize,
}

impl Region {
    pub fn len(&self) -> usize {
        self.i1 - self.i0
    }
}

impl Canvas {
    pub fn new(nx: usize, ny: usize, hs: f64) -> Canvas {
        Canvas {
            nx,
            ny,
            hs,
            h: vec![0.0; nx * ny],
        }
    }

    /// Whole samples in `len` metres (at least `min`).
    pub fn cells(&self, len: f64, min: usize) -> usize {
        samples(len, self.hs, min)
    }

    /// Local x (m) of sample column `i`.
    pub fn x(&self, i: usize) -> f64 {
        i as f64 * self.hs
    }

    /// Set the rectangle `xs x ys` (sample ranges, clipped) to `value`.
    pub fn fill(&mut self, xs: Range<usize>, ys: Range<usize>, value: f64) {
        let (x1, y1) = (xs.end.min(self.nx), ys.end.min(self.ny));
        for j in ys.start..y1 {
            let row = &mut self.h[j * self.nx..(j + 1) * self.nx];
            for v in &mut row[xs.start.min(x1)..x1] {
                *v = value;
            }
        }
    }

    /// Set whole columns `xs` to `f(i)`.
    pub fn columns(&mut self, xs: Range<usize>, f: impl Fn(usize) -> f64) {
        let x1 = xs.end.min(self.nx);
        for i in xs.start..x1 {
            let v = f(i);
            for j in 0..self.ny {
                self.h[j * self.nx + i] = v;
            }
        }
    }

    /// The `width` samples centred across y (the bridge strip).
    pub fn centre_strip(&self, width: usize) -> Range<usize> {
        let w = width.min(self.ny);
        let j0 = (self.ny - w) / 2;
        j0..j0 + w
    }

    /// Add roughness: control points every `cell` samples carry
    /// `uniform(-amp, amp) + sign * floor` (random sign), bilinearly
    /// interpolated in between, like legged_gym's `random_uniform_terrain`
    /// (plus the always-on `floor`, which keeps a tile from being exactly flat).
    pub fn add_roughness<R: Rng + ?Sized>(
        &mut self,
        amp: f64,
        floor: f64,
        cell: usize,
        rng: &mut R,
    ) {
        let cell = cell.max(1);
        let (cx, cy) = ((self.nx - 1) / cell + 2, (self.ny - 1) / cell + 2);
        let nodes: Vec<f64> = (0..cx * cy)
            .map(|_| {
                let u = if amp > 0.0 {
                    rng.random_range(-amp..=amp)
                } else {
                    0.0
                };
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                u + sign * floor
            })
            .collect();
        let inv = 1.0 / cell as f64;
        for j in 0..self.ny {
            let (b, v) = (j / cell, (j % cell) as f64 * inv);
            for i in 0..self.nx {
                let (a, u) = (i / cell, (i % cell) as f64 * inv);
                let n = |p: usize, q: usize| nodes[q * cx + p];
                let r = (1.0 - v) * ((1.0 - u) * n(a, b) + u * n(a + 1, b))
                    + v * ((1.0 - u) * n(a, b + 1) + u * n(a + 1, b + 1));
                self.h[j * self.nx + i] += r;
            }
        }
    }
}

/// Whole samples of spacing `hs` in `len` metres (at least `min`).
pub(crate) fn samples(len: f64, hs: f64, min: usize) -> usize {
    ((len / hs).round() as usize).max(min)
}

/// `v` rounded to a multiple of `vs`.
pub(crate) fn quantize(v: f64, vs: f64) -> f64 {
    (v / vs).round() * vs
}
