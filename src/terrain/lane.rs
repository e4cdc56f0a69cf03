//! Evaluation lanes: one tile long enough for the paper's 10 m walk (a 1 m
//! run-up, the walking length, a 1 m tail past the goal line) inside the
//! config's border, holding one kind or, for the combined benchmark, one kind
//! in the first half of the walk and another in the second.
use super::canvas::{samples, Canvas, Region};
use super::config::difficulty;
use super::map::{stream_rng, Layout, TileInfo};
use super::shapes::add_roughness;
use super::shapes::{draw, Ctx, TileParams};
use super::{TerrainConfig, TerrainError, TerrainKind, TerrainMap, SPAWN_CLEARANCE, SPAWN_OFFSET};

/// Plain ground kept past a lane's goal line (m).
pub const LANE_TAIL: f64 = 1.0;
/// The shortest walking length a lane segment may have (m).
pub const MIN_SEGMENT_LENGTH: f64 = 1.0;
/// The RNG stream of a lane's roughness (segment `k` uses stream `k`).
const ROUGHNESS_STREAM: u64 = u64::MAX - 1;

/// One kind's part of a lane.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    pub kind: TerrainKind,
    /// World x span of the segment's walk (m): from the spawn point (or the
    /// previous segment's end) to its end; obstacles start 0.5 m in.
    pub x: [f64; 2],
    /// What was drawn; its positions are relative to the lane tile's start.
    pub params: TileParams,
}

/// A single evaluation lane: walk from [`Lane::spawn`] along +x to [`Lane::goal_x`].
#[derive(Debug, Clone)]
pub struct Lane {
    map: TerrainMap,
    level: usize,
    segments: Vec<Segment>,
    goal_x: f64,
}

impl Lane {
    /// The lane's heightfield: a one-tile map (use it for MuJoCo and rendering);
    /// its tile reports the first segment, [`Lane::segments`] all of them.
    pub fn map(&self) -> &TerrainMap {
        &self.map
    }
    /// The curriculum level its obstacles were drawn at.
    pub fn level(&self) -> usize {
        self.level
    }
    /// The segments in walking order (one, or two for a combined lane).
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }
    /// Start point: 1 m into the lane tile, on its centre line, at ground height.
    pub fn spawn(&self) -> [f64; 3] {
        self.map.spawn(0, 0)
    }
    /// World x of the goal line: spawn x + the walking length.
    pub fn goal_x(&self) -> f64 {
        self.goal_x
    }
    /// Walking length from spawn to goal line (m).
    pub fn length(&self) -> f64 {
        self.goal_x - self.spawn()[0]
    }
}

impl TerrainMap {
    /// An evaluation lane of one `kind` at curriculum `level` (of the config's
    /// `0..num_levels`): `length` metres of walk (the paper's 10 m; see
    /// [`TerrainKind::default_lane_length`]), `width` metres wide.
    pub fn lane(
        cfg: &TerrainConfig,
        kind: TerrainKind,
        level: usize,
        length: f64,
        width: f64,
        seed: u64,
    ) -> Result<Lane, TerrainError> {
        build(cfg, &[kind], level, length, width, seed)
    }

    /// A combined lane: `first` in the first half of the walk, `second` in the
    /// second half (the paper's pairs are [`super::COMBINED_PAIRS`]).
    pub fn combined_lane(
        cfg: &TerrainConfig,
        first: TerrainKind,
        second: TerrainKind,
        level: usize,
        length: f64,
        width: f64,
        seed: u64,
    ) -> Result<Lane, TerrainError> {
        build(cfg, &[first, second], level, length, width, seed)
    }
}

fn build(
    cfg: &TerrainConfig,
    kinds: &[TerrainKind],
    level: usize,
    length: f64,
    width: f64,
    seed: u64,
) -> Result<Lane, TerrainError> {
    cfg.validate()?;
    if level > cfg.max_level() {
        return Err(TerrainError::Level {
            level,
            max_level: cfg.max_level(),
        });
    }
    let min_length = MIN_SEGMENT_LENGTH * kinds.len() as f64;
    if !(length.is_finite() && length >= min_length && length <= 1000.0) {
        return Err(TerrainError::config(
            "lane length",
            format!("{length} must be in [{min_length}, 1000] m"),
        ));
    }
    if !(width.is_finite() && (0.5..=100.0).contains(&width)) {
        return Err(TerrainError::config(
            "lane width",
            format!("{width} must be in [0.5, 100] m"),
        ));
    }
    let hs = cfg.horizontal_scale;
    let (spawn, walk) = (samples(SPAWN_OFFSET, hs, 1), samples(length, hs, 1));
    let layout = Layout {
        rows: 1,
        cols: 1,
        tile: [
            spawn + walk + samples(LANE_TAIL, hs, 1),
            samples(width, hs, 1),
        ],
        border: samples(cfg.border, hs, 0),
    };
    let mut map = TerrainMap::blank(cfg, seed, layout);
    let mut c = Canvas::new(layout.tile[0], layout.tile[1], hs);
    let ctx = Ctx {
        cfg,
        d: difficulty(level, cfg.max_level()),
    };
    let origin = layout.border as f64 * hs;
    let n = kinds.len();
    let mut segments = Vec::with_capacity(n);
    for (k, &kind) in kinds.iter().enumerate() {
        let (start, end) = (spawn + k * walk / n, spawn + (k + 1) * walk / n);
        let region = Region {
            i0: start + samples(SPAWN_CLEARANCE, hs, 1),
            i1: end,
        };
        let params = draw(kind, &mut c, region, &ctx, &mut stream_rng(seed, k as u64));
        segments.push(Segment {
            kind,
            x: [origin + c.x(start), origin + c.x(end)],
            params,
        });
    }
    add_roughness(&mut c, cfg, ctx.d, &mut stream_rng(seed, ROUGHNESS_STREAM));
    map.blit(0, 0, c.nx, &c.h);
    map.push_tile(TileInfo {
        kind: kinds[0],
        level,
        params: segments[0].params.clone(),
    });
    map.finish(cfg);
    Ok(Lane {
        map,
        level,
        goal_x: origin + c.x(spawn + walk),
        segments,
    })
}
