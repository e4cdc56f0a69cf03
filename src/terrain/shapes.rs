//! The generator of every [`TerrainKind`]: a function of the difficulty, the
//! config's parameters and an RNG that draws obstacles into a [`Region`] of a
//! [`Canvas`] and returns what it drew as [`TileParams`]; and
//! [`TerrainKind::tile`], one whole map tile as a [`TileGrid`].
//!
//! Lengths are rounded to whole samples and heights to the vertical scale
//! before drawing, and [`TileParams`] reports those realized values, so that a
//! test (or a reader of an eval report) can measure exactly what it states.
//! Where the curriculum asks for more steps or gaps than the region holds,
//! the count is capped to fit and the cap is what [`TileParams`] reports.
use std::f64::consts::PI;

use rand::Rng;
use serde::Serialize;

use super::canvas::{quantize, samples, Canvas, Region};
use super::config::{difficulty, UnevenHeights};
use super::{
    TerrainConfig, TerrainError, TerrainKind, END_CLEARANCE, SPAWN_CLEARANCE, SPAWN_OFFSET,
};

/// One sine of a wave tile: `amplitude * sin(2 pi / wavelength * (x cos(direction)
/// + y sin(direction)) + phase)` in tile-local metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Wave {
    pub amplitude: f64,
    pub wavelength: f64,
    pub direction: f64,
    pub phase: f64,
}

/// The truth parameters of one drawn tile or lane segment. `x0` is where the
/// obstacles start, in metres from the start of the tile (or lane).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TileParams {
    Flat,
    /// `blocks` blocks; each height in `[height[0], max_height]`, each side in
    /// `[size[0], max_size]` (the curriculum's bounds at this level).
    Uneven {
        x0: f64,
        x1: f64,
        blocks: usize,
        max_height: f64,
        max_size: f64,
    },
    /// `steps` risers of `height` up (the first at `x0`), treads of `tread`, a top
    /// platform of `top_length`, `steps` risers down.
    Stair {
        x0: f64,
        steps: usize,
        height: f64,
        tread: f64,
        top_length: f64,
    },
    /// `count` pits of width `gap`, the first at `x0`, separated by `platform`.
    Gap {
        x0: f64,
        count: usize,
        gap: f64,
        platform: f64,
    },
    /// A bridge of `width` from `x0` to `x1` over a pit.
    Bridge {
        x0: f64,
        x1: f64,
        width: f64,
    },
    /// A sum of sines, faded in over `fade` metres after `x0`.
    Wave {
        x0: f64,
        x1: f64,
        fade: f64,
        waves: Vec<Wave>,
    },
    /// Ramps of `ramp_length` at `angle_deg` around a top platform of `top_length`.
    Slope {
        x0: f64,
        angle_deg: f64,
        ramp_length: f64,
        top_length: f64,
    },
    /// Gap's layout whose platforms are `width` wide.
    BalancingBeam {
        x0: f64,
        count: usize,
        gap: f64,
        platform: f64,
        width: f64,
    },
    /// A bridge of `width` at height `amplitude * sin(pi * s / arch_length)`.
    SlopeBridge {
        x0: f64,
        arch_length: f64,
        amplitude: f64,
        width: f64,
    },
}

/// One tile drawn on its own: what [`TerrainKind::tile`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct TileGrid {
    /// Samples along x (`tile_length / horizontal_scale`).
    pub nx: usize,
    /// Samples along y (`tile_width / horizontal_scale`).
    pub ny: usize,
    /// Heights (m), y-major, quantized, roughness included; sample `(i, j)` at
    /// tile-local `(i * hs, j * hs)`.
    pub heights: Vec<f64>,
    pub params: TileParams,
}

impl TerrainKind {
    /// Draw one map tile of this kind at curriculum `level`: the kind's
    /// obstacles between 1.5 m (0.5 m past the spawn point) and 0.5 m before
    /// the tile's end, the base roughness, heights quantized. This is exactly
    /// what [`super::TerrainMap::generate`] puts at `(level, col)` when `rng`
    /// is that tile's generator.
    pub fn tile<R: Rng + ?Sized>(
        self,
        cfg: &TerrainConfig,
        level: usize,
        rng: &mut R,
    ) -> Result<TileGrid, TerrainError> {
        cfg.validate()?;
        if level > cfg.max_level() {
            return Err(TerrainError::Level {
                level,
                max_level: cfg.max_level(),
            });
        }
        Ok(self.tile_unchecked(cfg, level, rng))
    }

    /// [`TerrainKind::tile`] for a validated config and level.
    pub(crate) fn tile_unchecked<R: Rng + ?Sized>(
        self,
        cfg: &TerrainConfig,
        level: usize,
        rng: &mut R,
    ) -> TileGrid {
        let hs = cfg.horizontal_scale;
        let mut c = Canvas::new(
            samples(cfg.tile_length, hs, 1),
            samples(cfg.tile_width, hs, 1),
            hs,
        );
        let i0 = samples(SPAWN_OFFSET + SPAWN_CLEARANCE, hs, 1).min(c.nx);
        let region = Region {
            i0,
            i1: c.nx.saturating_sub(samples(END_CLEARANCE, hs, 0)).max(i0),
        };
        let ctx = Ctx {
            cfg,
            d: difficulty(level, cfg.max_level()),
        };
        let params = draw(self, &mut c, region, &ctx, rng);
        add_roughness(&mut c, cfg, ctx.d, rng);
        for h in &mut c.h {
            *h = quantize(*h, cfg.vertical_scale);
        }
        TileGrid {
            nx: c.nx,
            ny: c.ny,
            heights: c.h,
            params,
        }
    }
}

/// What a generator reads: the config and the difficulty in `[0, 1]`.
pub(crate) struct Ctx<'a> {
    pub cfg: &'a TerrainConfig,
    pub d: f64,
}

impl Ctx<'_> {
    /// A parameter's value for this tile (its level's difficulty, the config's
    /// `level_sampling`).
    fn draw<R: Rng + ?Sized>(&self, c: &super::config::Curriculum, rng: &mut R) -> f64 {
        c.draw(self.d, self.cfg.level_sampling, rng)
    }

    fn draw_count<R: Rng + ?Sized>(&self, c: &super::config::Curriculum, rng: &mut R) -> usize {
        c.draw_count(self.d, self.cfg.level_sampling, rng)
    }
}

/// Draw `kind` into `region` of `c`; the rest of `c` is left alone.
pub(crate) fn draw<R: Rng + ?Sized>(
    kind: TerrainKind,
    c: &mut Canvas,
    region: Region,
    ctx: &Ctx,
    rng: &mut R,
) -> TileParams {
    match kind {
        TerrainKind::Flat => TileParams::Flat,
        TerrainKind::Uneven => uneven(c, region, ctx, rng),
        TerrainKind::Stair => stair(c, region, ctx, rng),
        TerrainKind::Gap => gaps(c, region, ctx, None, rng),
        TerrainKind::Bridge => bridge(c, region, ctx, rng),
        TerrainKind::Wave => wave(c, region, ctx, rng),
        TerrainKind::Slope => slope(c, region, ctx),
        TerrainKind::BalancingBeam => {
            let width = c.cells(ctx.draw(&ctx.cfg.bridge.width, rng), 1);
            gaps(c, region, ctx, Some(width), rng)
        }
        TerrainKind::SlopeBridge => slope_bridge(c, region, ctx, rng),
    }
}

fn uneven<R: Rng + ?Sized>(c: &mut Canvas, r: Region, ctx: &Ctx, rng: &mut R) -> TileParams {
    let (p, d, vs) = (&ctx.cfg.uneven, ctx.d, ctx.cfg.vertical_scale);
    let area = r.len() as f64 * c.hs * c.ny as f64 * c.hs;
    let blocks = (ctx.draw(&p.count, rng) * area / p.reference_area).round() as usize;
    for _ in 0..blocks {
        let sx = c.cells(ctx.draw(&p.size, rng), 1).min(r.len());
        let sy = c
            .cells(ctx.draw(p.width.as_ref().unwrap_or(&p.size), rng), 1)
            .min(c.ny);
        let i = rng.random_range(r.i0..=r.i1 - sx);
        let j = rng.random_range(0..=c.ny - sy);
        // an even chance draws a bool, as before the parameter existed, so that
        // with `heights: full` the paper's lanes stay the ones every eval
        // before 2026-12-04 scored
        let raised = if p.raised_fraction == 0.5 {
            rng.random::<bool>()
        } else {
            rng.random::<f64>() < p.raised_fraction
        };
        let sign = if raised { 1.0 } else { -1.0 };
        let mut h = ctx.draw(&p.height, rng);
        // Isaac Gym's choice: h or h / 2 (`full` draws nothing more)
        if p.heights == UnevenHeights::Isaac && rng.random::<bool>() {
            h /= 2.0;
        }
        let h = sign * quantize(h, vs);
        c.fill(i..i + sx, j..j + sy, h);
    }
    TileParams::Uneven {
        x0: c.x(r.i0),
        x1: c.x(r.i1),
        blocks,
        max_height: p.height.bound(d),
        max_size: p.size.bound(d),
    }
}

fn stair<R: Rng + ?Sized>(c: &mut Canvas, r: Region, ctx: &Ctx, rng: &mut R) -> TileParams {
    let p = &ctx.cfg.stair;
    let height = quantize(ctx.draw(&p.height, rng), ctx.cfg.vertical_scale);
    let tread = c.cells(ctx.draw(&p.tread, rng), 1);
    let wanted = ctx.draw_count(&p.steps, rng).max(1);
    // n risers up and n down around the top tread: 2 (n - 1) treads + the top
    let top = c.cells(p.top_length, 1).min(r.len());
    let fit = 1 + (r.len() - top) / (2 * tread);
    let steps = wanted.min(fit);
    let mut i = r.i0;
    for k in 1..steps {
        c.columns(i..i + tread, |_| k as f64 * height);
        i += tread;
    }
    c.columns(i..i + top, |_| steps as f64 * height);
    i += top;
    for k in (1..steps).rev() {
        c.columns(i..i + tread, |_| k as f64 * height);
        i += tread;
    }
    TileParams::Stair {
        x0: c.x(r.i0),
        steps,
        height,
        tread: c.x(tread),
        top_length: c.x(top),
    }
}

/// Gaps across the region; with `beam = Some(width)`, the platforms between
/// them are only `width` samples wide (balancing beam) and pit surrounds them.
fn gaps<R: Rng + ?Sized>(
    c: &mut Canvas,
    r: Region,
    ctx: &Ctx,
    beam: Option<usize>,
    rng: &mut R,
) -> TileParams {
    let (p, pit) = (
        &ctx.cfg.gap,
        -quantize(ctx.cfg.pit_depth, ctx.cfg.vertical_scale),
    );
    let platform = c.cells(ctx.draw(&p.platform, rng), 1);
    let gap = c.cells(ctx.draw(&p.gap, rng), 1).min(r.len());
    let wanted = ctx.draw_count(&p.count, rng).max(1);
    // n gaps and the n - 1 platforms between them
    let count = wanted.min((r.len() + platform) / (gap + platform)).max(1);
    let end = r.i0 + count * gap + (count - 1) * platform;
    match beam {
        None => {
            for k in 0..count {
                let i = r.i0 + k * (gap + platform);
                let depth = match p.depth {
                    Some(depth) => -quantize(ctx.draw(&depth, rng), ctx.cfg.vertical_scale),
                    None => pit,
                };
                c.columns(i..i + gap, |_| depth);
            }
        }
        Some(width) => {
            c.columns(r.i0..end, |_| pit);
            let strip = c.centre_strip(width);
            for k in 1..count {
                let i = r.i0 + k * (gap + platform) - platform;
                c.fill(i..i + platform, strip.clone(), 0.0);
            }
        }
    }
    let (x0, gap, platform) = (c.x(r.i0), c.x(gap), c.x(platform));
    match beam {
        None => TileParams::Gap {
            x0,
            count,
            gap,
            platform,
        },
        Some(width) => TileParams::BalancingBeam {
            x0,
            count,
            gap,
            platform,
            width: c.x(width.min(c.ny)),
        },
    }
}

fn bridge<R: Rng + ?Sized>(c: &mut Canvas, r: Region, ctx: &Ctx, rng: &mut R) -> TileParams {
    let width = c.cells(ctx.draw(&ctx.cfg.bridge.width, rng), 1).min(c.ny);
    let pit = -quantize(ctx.cfg.pit_depth, ctx.cfg.vertical_scale);
    c.columns(r.i0..r.i1, |_| pit);
    c.fill(r.i0..r.i1, c.centre_strip(width), 0.0);
    TileParams::Bridge {
        x0: c.x(r.i0),
        x1: c.x(r.i1),
        width: c.x(width),
    }
}

fn wave<R: Rng + ?Sized>(c: &mut Canvas, r: Region, ctx: &Ctx, rng: &mut R) -> TileParams {
    let p = &ctx.cfg.wave;
    let n = ctx.draw_count(&p.count, rng);
    let waves: Vec<Wave> = (0..n)
        .map(|_| Wave {
            amplitude: ctx.draw(&p.amplitude, rng),
            wavelength: rng.random_range(p.wavelength[0]..=p.wavelength[1]),
            direction: rng.random_range(0.0..2.0 * PI),
            phase: rng.random_range(0.0..2.0 * PI),
        })
        .collect();
    let (x0, x1) = (c.x(r.i0), c.x(r.i1));
    let fade = p.fade.min((x1 - x0) / 2.0);
    let smooth = |t: f64| {
        let t = t.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    for j in 0..c.ny {
        let y = c.x(j);
        for i in r.i0..r.i1 {
            let x = c.x(i);
            let w = smooth((x - x0) / fade).min(smooth((x1 - x) / fade));
            let s: f64 = waves
                .iter()
                .map(|v| {
                    let k = 2.0 * PI / v.wavelength;
                    v.amplitude
                        * (k * (x * v.direction.cos() + y * v.direction.sin()) + v.phase).sin()
                })
                .sum();
            c.h[j * c.nx + i] = w * s;
        }
    }
    TileParams::Wave {
        x0,
        x1,
        fade,
        waves,
    }
}

fn slope(c: &mut Canvas, r: Region, ctx: &Ctx) -> TileParams {
    let p = &ctx.cfg.slope;
    let top = c.cells(p.top_length, 0).min(r.len());
    let ramp = c.cells(p.ramp_length, 1).min((r.len() - top) / 2);
    let grade = p.angle_deg.to_radians().tan() * c.hs;
    let (a, b) = (r.i0 + ramp, r.i0 + ramp + top);
    c.columns(r.i0..b + ramp + 1, |i| {
        let k = if i <= a {
            i - r.i0
        } else if i < b {
            ramp
        } else {
            b + ramp - i
        };
        k as f64 * grade
    });
    TileParams::Slope {
        x0: c.x(r.i0),
        angle_deg: p.angle_deg,
        ramp_length: c.x(ramp),
        top_length: c.x(top),
    }
}

fn slope_bridge<R: Rng + ?Sized>(c: &mut Canvas, r: Region, ctx: &Ctx, rng: &mut R) -> TileParams {
    let cfg = ctx.cfg;
    let width = c.cells(ctx.draw(&cfg.bridge.width, rng), 1).min(c.ny);
    let mut amplitude = ctx.draw(&cfg.slope_bridge.amplitude, rng);
    let arch = c.cells(cfg.arch_length, 2).min(r.len()).max(2);
    // a region shorter than the arch gets a scaled-down arch: same steepness
    amplitude *= (c.x(arch) / cfg.arch_length).min(1.0);
    let amplitude = quantize(amplitude, cfg.vertical_scale);
    let pit = -quantize(cfg.pit_depth, cfg.vertical_scale);
    // the arch meets the ground at both ends; the pit lies between them
    c.columns(r.i0 + 1..r.i0 + arch, |_| pit);
    let strip = c.centre_strip(width);
    for i in r.i0..=r.i0 + arch {
        let s = (i - r.i0) as f64 / arch as f64;
        c.fill(i..i + 1, strip.clone(), amplitude * (PI * s).sin());
    }
    TileParams::SlopeBridge {
        x0: c.x(r.i0),
        arch_length: c.x(arch),
        amplitude,
        width: c.x(width),
    }
}

/// The paper's base roughness `random(-a, a) * difficulty` plus the
/// always-on floor, on the config's coarse grid.
pub(crate) fn add_roughness<R: rand::Rng + ?Sized>(
    c: &mut Canvas,
    cfg: &TerrainConfig,
    d: f64,
    rng: &mut R,
) {
    let cell = c.cells(cfg.roughness_cell, 1);
    c.add_roughness(cfg.base_roughness * d, cfg.min_roughness, cell, rng);
}
