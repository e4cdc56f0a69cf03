//! The terrain module, checked by measuring the generated height arrays: step
//! heights and treads, gap and bridge widths, slope angles, arch profiles,
//! curriculum directions, roughness, determinism, the MuJoCo export, bad
//! configs and the PNG renderer.
mod common;

use std::sync::{Arc, OnceLock};

use common::Scratch;
use dreampolicy::sim::{Data, HeightField, Model, ObjType};
use dreampolicy::terrain::render::{lane_png_size, png_size, render_kind, render_lane, render_map};
use dreampolicy::terrain::{
    tile_rng, Curriculum, LevelSampling, TerrainConfig, TerrainError, TerrainKind, TerrainMap,
    TileParams, UnevenParams, WaveParams, COMBINED_PAIRS,
};

const SEEDS: [u64; 3] = [1, 2, 3];

/// Every kind, two columns each, all ten levels.
fn all_kinds_config() -> TerrainConfig {
    TerrainConfig {
        num_cols: 2 * TerrainKind::ALL.len(),
        kinds: TerrainKind::ALL.into_iter().map(|k| (k, 1.0)).collect(),
        border: 1.0,
        ..TerrainConfig::default()
    }
}

/// The all-kinds map for each of [`SEEDS`], generated once.
fn maps() -> &'static [(TerrainConfig, TerrainMap)] {
    static MAPS: OnceLock<Vec<(TerrainConfig, TerrainMap)>> = OnceLock::new();
    MAPS.get_or_init(|| {
        let cfg = all_kinds_config();
        SEEDS
            .iter()
            .map(|&s| (cfg.clone(), TerrainMap::generate(&cfg, s).unwrap()))
            .collect()
    })
}

/// One tile's samples as a local view.
struct Tile<'a> {
    map: &'a TerrainMap,
    i0: usize,
    j0: usize,
    nx: usize,
    ny: usize,
    hs: f64,
}

impl Tile<'_> {
    fn of(map: &TerrainMap, level: usize, col: usize) -> Tile<'_> {
        let b = map.tile_bounds(level, col);
        let hs = map.horizontal_scale();
        let [nx, ny] = map.tile_samples();
        Tile {
            map,
            i0: (b.x[0] / hs).round() as usize,
            j0: (b.y[0] / hs).round() as usize,
            nx,
            ny,
            hs,
        }
    }
    fn h(&self, i: usize, j: usize) -> f64 {
        self.map.height_at(self.i0 + i, self.j0 + j)
    }
    /// Sample index of tile-local x (m).
    fn ix(&self, x: f64) -> usize {
        (x / self.hs).round() as usize
    }
    /// Median height across y at every x: robust to the roughness.
    fn profile(&self) -> Vec<f64> {
        (0..self.nx)
            .map(|i| median((0..self.ny).map(|j| self.h(i, j)).collect()))
            .collect()
    }
    /// Samples across y at column `i` that are above half the pit depth.
    fn solid_across(&self, i: usize, pit: f64) -> usize {
        (0..self.ny).filter(|&j| self.h(i, j) > -pit / 2.0).count()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One tile of the shared maps under test.
struct Case {
    cfg: &'static TerrainConfig,
    level: usize,
    /// Difficulty `level / max_level`.
    d: f64,
    t: Tile<'static>,
    params: &'static TileParams,
}

impl Case {
    /// Roughness bound at this difficulty plus one height quantum.
    fn tol(&self) -> f64 {
        tol(self.cfg, self.d)
    }
    /// `v` is a value the curriculum `c` can give at this level, up to `slack`
    /// (half a sample or half a height quantum of rounding).
    fn drawn(&self, what: &str, v: f64, c: &Curriculum, slack: f64) {
        let (a, b) = (c.0[0], c.bound(self.d));
        assert!(
            v >= a.min(b) - slack && v <= a.max(b) + slack,
            "{what} = {v} outside [{a}, {b}] at level {}",
            self.level
        );
    }
    fn solid_across(&self, i: usize) -> usize {
        self.t.solid_across(i, self.cfg.pit_depth)
    }
}

/// Bound on roughness at difficulty `d` plus one height quantum.
fn tol(cfg: &TerrainConfig, d: f64) -> f64 {
    cfg.base_roughness * d + cfg.min_roughness + cfg.vertical_scale
}

/// Every tile of `kind` in every shared map.
fn cases(kind: TerrainKind) -> Vec<Case> {
    let mut out = Vec::new();
    for (cfg, map) in maps() {
        for col in (0..map.num_cols()).filter(|&c| map.tile_kind(c) == kind) {
            out.extend((0..map.num_levels()).map(|level| Case {
                cfg,
                level,
                d: level as f64 / cfg.max_level() as f64,
                t: Tile::of(map, level, col),
                params: map.tile_params(level, col),
            }));
        }
    }
    assert!(!out.is_empty(), "no {kind} tile");
    out
}

/// Runs of consecutive indices where `pred` holds: (start, length).
fn runs<T: Copy>(v: &[T], pred: impl Fn(T) -> bool) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for (i, &x) in v.iter().enumerate() {
        if pred(x) {
            match out.last_mut() {
                Some((s, n)) if *s + *n == i => *n += 1,
                _ => out.push((i, 1)),
            }
        }
    }
    out
}

#[test]
fn stairs_have_the_drawn_risers_and_treads() {
    for c in cases(TerrainKind::Stair) {
        let &TileParams::Stair {
            x0,
            steps,
            height,
            tread,
            top_length,
        } = c.params
        else {
            panic!("{:?}", c.params);
        };
        let (hs, vs) = (c.cfg.horizontal_scale, c.cfg.vertical_scale);
        c.drawn("riser", height, &c.cfg.stair.height, vs / 2.0);
        c.drawn("tread", tread, &c.cfg.stair.tread, hs / 2.0);
        assert!((1..=10).contains(&steps));
        let (t, p) = (&c.t, c.t.profile());
        let risers: Vec<(usize, f64)> = (1..p.len())
            .map(|i| (i, p[i] - p[i - 1]))
            .filter(|(_, dh)| dh.abs() > height / 2.0)
            .collect();
        let up: Vec<_> = risers.iter().filter(|r| r.1 > 0.0).collect();
        let down: Vec<_> = risers.iter().filter(|r| r.1 < 0.0).collect();
        assert_eq!(
            (up.len(), down.len()),
            (steps, steps),
            "level {}: {risers:?}",
            c.level
        );
        for (_, dh) in &risers {
            assert!(
                (dh.abs() - height).abs() <= c.tol(),
                "riser {dh} vs {height}"
            );
        }
        assert_eq!(up[0].0, t.ix(x0));
        for w in up.windows(2).chain(down.windows(2)) {
            assert_eq!(w[1].0 - w[0].0, t.ix(tread), "tread at level {}", c.level);
        }
        assert_eq!(down[0].0 - up[steps - 1].0, t.ix(top_length));
        let top = p[up[steps - 1].0 + 1];
        assert!((top - steps as f64 * height).abs() <= c.tol());
    }
}

/// `count` gaps of `gap` from `x0`, `platform` apart, pit deep, across the tile.
fn check_gaps(c: &Case, x0: f64, count: usize, gap: f64, platform: f64) {
    let t = &c.t;
    assert!((0.2 - 1e-9..=0.3 + 1e-9).contains(&gap), "gap width {gap}");
    c.drawn("gap", gap, &c.cfg.gap.gap, c.cfg.horizontal_scale / 2.0);
    c.drawn(
        "platform",
        platform,
        &c.cfg.gap.platform,
        c.cfg.horizontal_scale / 2.0,
    );
    // a gap is a column with no solid sample across the tile
    let solid: Vec<usize> = (0..t.nx).map(|i| c.solid_across(i)).collect();
    let gaps = runs(&solid, |n| n == 0);
    assert_eq!(gaps.len(), count, "{gaps:?}");
    assert_eq!(gaps[0].0, t.ix(x0));
    for g in &gaps {
        assert_eq!(g.1, t.ix(gap));
        for i in g.0..g.0 + g.1 {
            let depth = median((0..t.ny).map(|j| t.h(i, j)).collect());
            assert!((depth + c.cfg.pit_depth).abs() <= c.tol(), "pit at {depth}");
        }
    }
    for w in gaps.windows(2) {
        assert_eq!(
            w[1].0 - (w[0].0 + w[0].1),
            t.ix(platform),
            "platform length"
        );
    }
}

#[test]
fn gaps_have_the_drawn_widths_depth_and_platforms() {
    for c in cases(TerrainKind::Gap) {
        let &TileParams::Gap {
            x0,
            count,
            gap,
            platform,
        } = c.params
        else {
            panic!("{:?}", c.params);
        };
        assert!((1..=10).contains(&count));
        check_gaps(&c, x0, count, gap, platform);
        // platforms are solid across the whole width
        if count > 1 {
            assert_eq!(c.solid_across(c.t.ix(x0 + gap + platform / 2.0)), c.t.ny);
        }
    }
}

/// `gap.depth` (a training curriculum): each gap draws its own depth, shallow
/// at level 0 and up to the range's far end at the top; the paper's table
/// (unset) keeps every gap a pit, as above.
#[test]
fn gap_depth_follows_its_curriculum_when_set() {
    let mut cfg = TerrainConfig {
        num_cols: 2,
        kinds: [(TerrainKind::Gap, 1.0)].into(),
        border: 1.0,
        base_roughness: 0.0,
        min_roughness: 0.0,
        ..TerrainConfig::default()
    };
    cfg.gap.gap = Curriculum([0.05, 0.30]);
    cfg.gap.depth = Some(Curriculum([0.05, 1.0]));
    let map = TerrainMap::generate(&cfg, 9).unwrap();
    let mut deepest = vec![0.0f64; map.num_levels()];
    for level in 0..map.num_levels() {
        let d = level as f64 / cfg.max_level() as f64;
        for col in 0..map.num_cols() {
            let t = Tile::of(&map, level, col);
            let &TileParams::Gap {
                x0,
                count,
                gap,
                platform,
            } = map.tile_params(level, col)
            else {
                panic!("{:?}", map.tile_params(level, col));
            };
            for k in 0..count {
                let i = t.ix(x0 + k as f64 * (gap + platform));
                let depth = -median((0..t.ny).map(|j| t.h(i, j)).collect());
                let bound = cfg.gap.depth.unwrap().bound(d);
                assert!(
                    depth >= 0.05 - 1e-3 && depth <= bound + cfg.vertical_scale,
                    "level {level}: gap {k} {depth} m deep, outside [0.05, {bound}]"
                );
                deepest[level] = deepest[level].max(depth);
            }
        }
    }
    assert!(deepest[0] <= 0.05 + cfg.vertical_scale, "{deepest:?}");
    assert!(deepest[9] > 0.5, "{deepest:?}");
    // a depth below zero is a config error naming the key
    cfg.gap.depth = Some(Curriculum([-0.1, 1.0]));
    let e = TerrainMap::generate(&cfg, 9).err().unwrap().to_string();
    assert!(e.contains("gap.depth"), "{e}");
}

#[test]
fn bridges_are_as_wide_as_drawn() {
    for c in cases(TerrainKind::Bridge) {
        let &TileParams::Bridge { x0, x1, width } = c.params else {
            panic!("{:?}", c.params);
        };
        c.drawn(
            "bridge width",
            width,
            &c.cfg.bridge.width,
            c.cfg.horizontal_scale / 2.0,
        );
        let t = &c.t;
        for i in t.ix(x0)..t.ix(x1) {
            assert_eq!(c.solid_across(i), t.ix(width), "level {} x {i}", c.level);
            let centre = t.h(i, t.ny / 2);
            assert!(centre.abs() <= c.tol(), "bridge at ground level: {centre}");
        }
        assert_eq!(c.solid_across(t.ix(x0) - 1), t.ny, "solid start area");
        assert_eq!(c.solid_across(t.ix(x1)), t.ny, "solid end area");
    }
}

#[test]
fn balancing_beams_have_gap_layout_and_bridge_width() {
    for c in cases(TerrainKind::BalancingBeam) {
        let &TileParams::BalancingBeam {
            x0,
            count,
            gap,
            platform,
            width,
        } = c.params
        else {
            panic!("{:?}", c.params);
        };
        c.drawn(
            "beam width",
            width,
            &c.cfg.bridge.width,
            c.cfg.horizontal_scale / 2.0,
        );
        check_gaps(&c, x0, count, gap, platform);
        let t = &c.t;
        for k in 1..count {
            let start = t.ix(x0) + k * t.ix(gap) + (k - 1) * t.ix(platform);
            for i in start..start + t.ix(platform) {
                assert_eq!(c.solid_across(i), t.ix(width), "beam {k}");
            }
        }
    }
}

/// Least-squares slope of `p[a..b]` per sample.
fn fit_slope(p: &[f64], a: usize, b: usize) -> f64 {
    let n = (b - a) as f64;
    let mx = (a..b).map(|i| i as f64).sum::<f64>() / n;
    let my = p[a..b].iter().sum::<f64>() / n;
    let sxy: f64 = (a..b).map(|i| (i as f64 - mx) * (p[i] - my)).sum();
    let sxx: f64 = (a..b).map(|i| (i as f64 - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn slopes_are_thirty_degrees() {
    for c in cases(TerrainKind::Slope) {
        let &TileParams::Slope {
            x0,
            angle_deg,
            ramp_length,
            top_length,
        } = c.params
        else {
            panic!("{:?}", c.params);
        };
        assert_eq!(angle_deg, 30.0);
        let t = &c.t;
        let mean: Vec<f64> = (0..t.nx)
            .map(|i| (0..t.ny).map(|j| t.h(i, j)).sum::<f64>() / t.ny as f64)
            .collect();
        let (a, r, top) = (t.ix(x0), t.ix(ramp_length), t.ix(top_length));
        let up = fit_slope(&mean, a, a + r + 1) / t.hs;
        let down = fit_slope(&mean, a + r + top, a + 2 * r + top + 1) / t.hs;
        for s in [up, -down] {
            let deg = s.atan().to_degrees();
            assert!((deg - 30.0).abs() <= 1.0, "level {}: {deg} deg", c.level);
        }
        let rise = ramp_length * 30f64.to_radians().tan();
        assert!((mean[a + r + top / 2] - rise).abs() <= c.tol());
    }
}

#[test]
fn slope_bridge_lanes_are_half_sine_arches() {
    let cfg = TerrainConfig::default();
    let kind = TerrainKind::SlopeBridge;
    for level in [0, cfg.max_level()] {
        let d = level as f64 / cfg.max_level() as f64;
        for seed in SEEDS {
            let lane =
                TerrainMap::lane(&cfg, kind, level, kind.default_lane_length(), 4.0, seed).unwrap();
            let TileParams::SlopeBridge {
                x0,
                arch_length,
                amplitude,
                width,
            } = lane.segments()[0].params
            else {
                panic!("slope bridge params");
            };
            assert_eq!(
                arch_length, 18.0,
                "the paper's full arch fits the default lane"
            );
            let top = cfg.slope_bridge.amplitude.bound(d);
            assert!(
                amplitude >= 1.5 && amplitude <= top + 0.003,
                "amplitude {amplitude}"
            );
            let t = Tile::of(lane.map(), 0, 0);
            let (jc, a, n) = (t.ny / 2, t.ix(x0), t.ix(arch_length));
            let peak = (a..=a + n).map(|i| t.h(i, jc)).fold(f64::MIN, f64::max);
            let tol = tol(&cfg, d);
            assert!(peak >= 1.5 - tol && peak <= 2.5 + tol, "peak {peak}");
            for i in a..=a + n {
                let s = (i - a) as f64 / n as f64;
                let want = amplitude * (std::f64::consts::PI * s).sin();
                assert!((t.h(i, jc) - want).abs() <= tol, "s = {s}");
                if i > a && i < a + n {
                    let solid = t.solid_across(i, cfg.pit_depth);
                    assert_eq!(solid, t.ix(width), "pit on both sides");
                }
            }
        }
    }
}

#[test]
fn waves_stay_within_their_amplitudes_and_start_flat() {
    for c in cases(TerrainKind::Wave) {
        let TileParams::Wave {
            x0,
            x1,
            fade,
            ref waves,
        } = *c.params
        else {
            panic!("{:?}", c.params);
        };
        assert!((5..=10).contains(&waves.len()));
        for w in waves {
            c.drawn("amplitude", w.amplitude, &c.cfg.wave.amplitude, 1e-12);
            assert!((4.0..=12.0).contains(&w.wavelength));
        }
        let total: f64 = waves.iter().map(|w| w.amplitude).sum();
        let t = &c.t;
        for j in 0..t.ny {
            for i in 0..t.nx {
                let (x, y, h) = (i as f64 * t.hs, j as f64 * t.hs, t.h(i, j));
                assert!(h.abs() <= total + c.tol());
                if x <= x0 {
                    assert!(h.abs() <= c.tol(), "flat run-up");
                } else if x >= x0 + fade && x < x1 - fade {
                    // recomputed from the documented formula
                    let want: f64 = waves
                        .iter()
                        .map(|w| {
                            let phase = 2.0 * std::f64::consts::PI / w.wavelength
                                * (x * w.direction.cos() + y * w.direction.sin());
                            w.amplitude * (phase + w.phase).sin()
                        })
                        .sum();
                    assert!((h - want).abs() <= c.tol(), "sum of sines at ({x}, {y})");
                }
            }
        }
    }
}

#[test]
fn uneven_blocks_have_heights_in_the_range() {
    for c in cases(TerrainKind::Uneven) {
        let &TileParams::Uneven {
            x0,
            x1,
            blocks,
            max_height,
            ..
        } = c.params
        else {
            panic!("{:?}", c.params);
        };
        let area = (x1 - x0) * c.cfg.tile_width;
        let expected = [150.0, 200.0].map(|n: f64| (n * area / 64.0).round() as usize);
        assert!(
            (expected[0]..=expected[1]).contains(&blocks),
            "{blocks} blocks"
        );
        let t = &c.t;
        let (mut raised, mut total) = (0, 0);
        for j in 0..t.ny {
            for i in t.ix(x0)..t.ix(x1) {
                let h = t.h(i, j).abs();
                // `heights: isaac` (the default): h or h / 2, h >= 0.10
                let block = h >= 0.05 - c.tol() && h <= max_height + c.tol();
                assert!(
                    h <= c.tol() || block,
                    "level {}: |h| = {h} is neither ground nor a block",
                    c.level
                );
                raised += usize::from(h > 0.025);
                total += 1;
            }
        }
        assert!(
            raised * 5 > total,
            "blocks cover {raised} of {total} samples"
        );
    }
}

/// A two-level map of `cols` uneven columns with `uneven`'s blocks and no
/// roughness, drawn with `seed`.
fn uneven_map(cols: usize, uneven: UnevenParams, seed: u64) -> TerrainMap {
    let cfg = TerrainConfig {
        num_levels: 2,
        num_cols: cols,
        kinds: [(TerrainKind::Uneven, 1.0)].into(),
        base_roughness: 0.0,
        min_roughness: 0.0,
        uneven,
        ..TerrainConfig::default()
    };
    TerrainMap::generate(&cfg, seed).unwrap()
}

/// `uneven.width` as wide as the tile lays strips: every block spans the tile
/// across y, so the height changes only along x (edges that cross the walk),
/// and the heights are still the paper's blocks.
#[test]
fn uneven_width_lays_strips_across_the_walk() {
    let map = uneven_map(
        2,
        UnevenParams {
            width: Some(Curriculum([4.0, 4.0])),
            ..UnevenParams::default()
        },
        3,
    );
    for (level, col) in [(0, 0), (1, 1)] {
        let t = Tile::of(&map, level, col);
        let mut steps = 0;
        for i in 0..t.nx {
            let h0 = t.h(i, 0);
            for j in 0..t.ny {
                assert!(
                    (t.h(i, j) - h0).abs() < 1e-9,
                    "level {level}: ({i}, {j}) differs across y"
                );
            }
            steps += usize::from(i > 0 && (h0 - t.h(i - 1, 0)).abs() > 0.05);
        }
        assert!(steps >= 4, "level {level}: {steps} edges along x");
    }
}

/// The paper's level 0 (`h` = 0.10 m): `heights: isaac` lays blocks of +-10
/// and +-5 cm, Isaac Gym's `discrete_obstacles_terrain` choice, each of the
/// four common; `full` lays +-10 cm blocks only.
#[test]
fn uneven_heights_are_isaac_gyms_choice_or_the_full_height() {
    use dreampolicy::terrain::UnevenHeights;
    for (heights, want) in [
        (UnevenHeights::Isaac, vec![-100, -50, 50, 100]),
        (UnevenHeights::Full, vec![-100, 100]),
    ] {
        let map = uneven_map(
            1,
            UnevenParams {
                heights,
                ..UnevenParams::default()
            },
            7,
        );
        let t = Tile::of(&map, 0, 0);
        let mut seen = std::collections::BTreeMap::<i64, usize>::new();
        for i in 0..t.nx {
            for j in 0..t.ny {
                let mm = (t.h(i, j) * 1000.0).round() as i64;
                if mm != 0 {
                    *seen.entry(mm).or_default() += 1;
                }
            }
        }
        let got: Vec<i64> = seen.keys().copied().collect();
        assert_eq!(got, want, "{heights:?}: block heights (mm) {seen:?}");
        let total: usize = seen.values().sum();
        for (mm, n) in &seen {
            assert!(
                n * 4 * want.len() > total,
                "{heights:?}: {mm} mm on {n} of {total} block samples"
            );
        }
    }
}

/// `uneven.raised_fraction` 1 raises every block and 0 lowers every one (the
/// probes that compare step-ups with step-downs).
#[test]
fn uneven_raised_fraction_picks_the_blocks_sign() {
    for (fraction, sign) in [(1.0, 1.0), (0.0, -1.0)] {
        let map = uneven_map(
            1,
            UnevenParams {
                raised_fraction: fraction,
                ..UnevenParams::default()
            },
            5,
        );
        let t = Tile::of(&map, 1, 0);
        let (mut blocks, mut wrong) = (0, 0);
        for i in 0..t.nx {
            for j in 0..t.ny {
                let h = t.h(i, j) * sign;
                blocks += usize::from(h > 0.05);
                wrong += usize::from(h < -1e-9);
            }
        }
        assert!(
            blocks > t.nx * t.ny / 5,
            "raised_fraction {fraction}: {blocks} block samples"
        );
        assert_eq!(
            wrong, 0,
            "raised_fraction {fraction}: blocks of the other sign"
        );
    }
}

/// `(values at level 0, mean value at the top level)` of `f` over the tiles of
/// `kind` in a two-level map with many columns per kind, for three seeds.
fn ends(kind: TerrainKind, f: impl Fn(&TileParams) -> f64) -> (Vec<f64>, f64) {
    let cfg = TerrainConfig {
        num_levels: 2,
        num_cols: 16,
        kinds: [(kind, 1.0)].into(),
        tile_width: 1.0,
        border: 0.0,
        ..TerrainConfig::default()
    };
    let (mut first, mut last) = (Vec::new(), Vec::new());
    for seed in SEEDS {
        let map = TerrainMap::generate(&cfg, seed).unwrap();
        for col in 0..cfg.num_cols {
            first.push(f(map.tile_params(0, col)));
            last.push(f(map.tile_params(1, col)));
        }
    }
    (first, last.iter().sum::<f64>() / last.len() as f64)
}

#[test]
fn curriculum_makes_every_parameter_harder_with_the_level() {
    type Field = fn(&TileParams) -> f64;
    let cases: [(TerrainKind, &str, Field, [f64; 2]); 7] = [
        (
            TerrainKind::Stair,
            "stair height",
            |p| match p {
                TileParams::Stair { height, .. } => *height,
                _ => f64::NAN,
            },
            [0.15, 0.30],
        ),
        (
            TerrainKind::Stair,
            "stair tread",
            |p| match p {
                TileParams::Stair { tread, .. } => *tread,
                _ => f64::NAN,
            },
            [0.40, 0.25],
        ),
        (
            TerrainKind::Gap,
            "gap width",
            |p| match p {
                TileParams::Gap { gap, .. } => *gap,
                _ => f64::NAN,
            },
            [0.20, 0.30],
        ),
        (
            TerrainKind::Gap,
            "gap platform",
            |p| match p {
                TileParams::Gap { platform, .. } => *platform,
                _ => f64::NAN,
            },
            [0.60, 0.40],
        ),
        (
            TerrainKind::Bridge,
            "bridge width",
            |p| match p {
                TileParams::Bridge { width, .. } => *width,
                _ => f64::NAN,
            },
            [0.40, 0.20],
        ),
        (
            TerrainKind::Uneven,
            "uneven max height",
            |p| match p {
                TileParams::Uneven { max_height, .. } => *max_height,
                _ => f64::NAN,
            },
            [0.10, 0.20],
        ),
        (
            TerrainKind::Wave,
            "wave amplitude",
            |p| match p {
                TileParams::Wave { waves, .. } => {
                    waves.iter().map(|w| w.amplitude).sum::<f64>() / waves.len() as f64
                }
                _ => f64::NAN,
            },
            [0.2, 0.5],
        ),
    ];
    for (kind, what, f, [p0, p1]) in cases {
        let (first, top_mean) = ends(kind, f);
        for v in first {
            assert!((v - p0).abs() < 1e-9, "{what} at level 0 is {v}, not {p0}");
        }
        // the top level draws uniformly over [p0, p1]: its mean moves towards p1
        let moved = (top_mean - p0) / (p1 - p0);
        assert!(
            moved > 0.2 && moved <= 1.0,
            "{what}: top-level mean {top_mean}"
        );
    }
    let (first, top) = ends(TerrainKind::Stair, |p| match p {
        TileParams::Stair { steps, .. } => *steps as f64,
        _ => f64::NAN,
    });
    assert!(
        first.iter().all(|&s| s == 5.0) && top > 5.5,
        "steps {first:?} -> {top}"
    );
}

#[test]
fn no_tile_has_an_exactly_flat_square_metre() {
    // the always-on roughness puts +-min_roughness on every 0.2 m control point:
    // every aligned 1 m x 1 m window of every tile (and of the border) varies
    for (_, map) in maps() {
        let w = (1.0 / map.horizontal_scale()).round() as usize;
        for wj in 0..map.ny() / w {
            for wi in 0..map.nx() / w {
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for j in wj * w..(wj + 1) * w {
                    for i in wi * w..(wi + 1) * w {
                        lo = lo.min(map.height_at(i, j));
                        hi = hi.max(map.height_at(i, j));
                    }
                }
                assert!(hi > lo, "flat window at ({wi}, {wj}) m");
            }
        }
    }
    // and heights are multiples of the vertical scale
    let (cfg, map) = &maps()[0];
    for h in map.heights() {
        let q = h / cfg.vertical_scale;
        assert!((q - q.round()).abs() < 1e-6, "{h}");
    }
}

#[test]
fn generation_is_deterministic_and_tiles_are_independent() {
    let cfg = TerrainConfig {
        num_levels: 4,
        num_cols: 2,
        kinds: [(TerrainKind::Stair, 1.0), (TerrainKind::Gap, 1.0)].into(),
        ..TerrainConfig::default()
    };
    let a = TerrainMap::generate(&cfg, 7).unwrap();
    let b = TerrainMap::generate(&cfg, 7).unwrap();
    let bits = |m: &TerrainMap| m.heights().iter().map(|h| h.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    assert_ne!(bits(&a), bits(&TerrainMap::generate(&cfg, 8).unwrap()));
    // more columns, another border, other gap parameters: the stair tiles of
    // column 0 are the same samples
    let mut other = cfg.clone();
    other.num_cols = 4;
    other.border = 2.0;
    other.gap.platform.0 = [0.5, 0.3];
    let c = TerrainMap::generate(&other, 7).unwrap();
    assert_eq!(
        (c.tile_kind(0), c.tile_kind(1), c.tile_kind(2)),
        (TerrainKind::Stair, TerrainKind::Stair, TerrainKind::Gap)
    );
    for level in 0..cfg.num_levels {
        let (ta, tc) = (Tile::of(&a, level, 0), Tile::of(&c, level, 0));
        for j in 0..ta.ny {
            for i in 0..ta.nx {
                assert_eq!(
                    ta.h(i, j).to_bits(),
                    tc.h(i, j).to_bits(),
                    "level {level} ({i}, {j})"
                );
            }
        }
        assert_eq!(a.tile_params(level, 0), c.tile_params(level, 0));
        // and a tile drawn on its own with that tile's RNG is the same tile
        let one = TerrainKind::Stair
            .tile(&cfg, level, &mut tile_rng(7, level, 0))
            .unwrap();
        assert_eq!((one.nx, one.ny), (ta.nx, ta.ny));
        assert_eq!(&one.params, a.tile_params(level, 0));
        for (k, h) in one.heights.iter().enumerate() {
            assert_eq!(h.to_bits(), ta.h(k % one.nx, k / one.nx).to_bits());
        }
        assert_ne!(
            a.tile_params(level, 1),
            c.tile_params(level, 2),
            "gap params changed"
        );
    }
}

#[test]
fn map_layout_spawns_and_edges() {
    let cfg = TerrainConfig::default();
    let map = TerrainMap::generate(&cfg, 0).unwrap();
    assert_eq!((map.num_levels(), map.num_cols()), (10, 10));
    assert_eq!((map.nx(), map.ny()), (1801, 1001));
    let kinds: Vec<_> = (0..10).map(|c| map.tile_kind(c)).collect();
    let expect: Vec<_> = TerrainKind::TRAINING
        .iter()
        .flat_map(|k| [*k, *k])
        .collect();
    assert_eq!(
        kinds, expect,
        "legged_gym proportions: two columns per kind"
    );
    let b = map.tile_bounds(3, 4);
    let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
    assert!(close(b.x, [5.0 + 3.0 * 8.0, 5.0 + 4.0 * 8.0]), "{b:?}");
    assert!(close(b.y, [5.0 + 4.0 * 4.0, 5.0 + 5.0 * 4.0]), "{b:?}");
    let [x, y, z] = map.spawn(3, 4);
    assert!(close([x, y], [b.x[0] + 1.0, 5.0 + 18.0]));
    assert!(z.abs() <= tol(&cfg, 1.0), "spawn on the run-up: {z}");
    // edges: at stair risers, not on treads, nowhere on a flat tile
    let TileParams::Stair { x0, tread, .. } = *map.tile_params(9, 4) else {
        panic!()
    };
    let s = map.tile_bounds(9, 4);
    let yc = 0.5 * (s.y[0] + s.y[1]);
    assert!(map.is_edge(s.x[0] + x0, yc) && map.is_edge(s.x[0] + x0 - 0.05, yc));
    assert!(!map.is_edge(s.x[0] + x0 + tread / 2.0, yc));
    assert!(!map.is_edge(-1.0, 3.0), "off the map");
    let f = Tile::of(&map, 9, 0);
    assert_eq!(map.tile_kind(0), TerrainKind::Flat);
    for j in 1..f.ny - 1 {
        for i in 1..f.nx - 1 {
            assert!(!map.edge_mask()[(f.j0 + j) * map.nx() + f.i0 + i]);
        }
    }
    // weights are proportions by name
    let cfg = TerrainConfig::from_yaml_str("num_cols: 8\nkinds: {stair: 3, gap: 1}\n").unwrap();
    let cols = cfg.column_kinds();
    assert_eq!(cols.iter().filter(|k| **k == TerrainKind::Stair).count(), 6);
    assert_eq!(cols[7], TerrainKind::Gap);
}

#[test]
fn lanes_and_combined_lanes() {
    let cfg = TerrainConfig::default();
    let lane = TerrainMap::lane(&cfg, TerrainKind::Stair, 5, 10.0, 4.0, 3).unwrap();
    let [sx, _, _] = lane.spawn();
    assert!((lane.goal_x() - sx - 10.0).abs() < 1e-9);
    assert_eq!(sx, cfg.border + 1.0);
    assert!((lane.map().extent()[0] - (2.0 * cfg.border + 12.0)).abs() < 1e-9);
    for (first, second) in COMBINED_PAIRS {
        let lane = TerrainMap::combined_lane(&cfg, first, second, 9, 10.0, 4.0, 11).unwrap();
        let segs = lane.segments();
        assert_eq!((segs[0].kind, segs[1].kind), (first, second));
        assert!((segs[0].x[1] - (sx + 5.0)).abs() < 1e-9 && segs[1].x[1] == lane.goal_x());
        // each half's obstacles lie inside its half (local x: lane tile from `border`)
        for s in segs {
            let (a, b) = extent(&s.params);
            assert!(
                a + cfg.border >= s.x[0] && b + cfg.border <= s.x[1] + 1e-9,
                "{s:?}"
            );
        }
        // and each half shows its own kind: risers, pits or blocks
        let t = Tile::of(lane.map(), 0, 0);
        let p = t.profile();
        for s in segs {
            let span = t.ix(s.x[0] - cfg.border)..t.ix(s.x[1] - cfg.border);
            let pit = span.clone().any(|i| p[i] < -cfg.pit_depth / 2.0);
            let rise = span.clone().any(|i| p[i] > 0.1);
            let rough = span
                .clone()
                .filter(|&i| (0..t.ny).any(|j| t.h(i, j).abs() > 0.05))
                .count();
            match s.kind {
                TerrainKind::Stair => assert!(rise && !pit, "{first}&{second}"),
                TerrainKind::Gap | TerrainKind::Bridge => assert!(pit, "{first}&{second}"),
                TerrainKind::Uneven => assert!(!pit && rough * 2 > span.len(), "{first}&{second}"),
                _ => unreachable!(),
            }
        }
    }
    let err = TerrainMap::lane(&cfg, TerrainKind::Gap, 10, 10.0, 4.0, 0).unwrap_err();
    assert!(
        matches!(
            err,
            TerrainError::Level {
                level: 10,
                max_level: 9
            }
        ),
        "{err}"
    );
    let err = TerrainKind::Gap
        .tile(&cfg, 10, &mut tile_rng(0, 0, 0))
        .unwrap_err();
    assert!(matches!(err, TerrainError::Level { .. }), "{err}");
    let err = TerrainMap::lane(&cfg, TerrainKind::Gap, 1, -3.0, 4.0, 0).unwrap_err();
    assert!(err.to_string().contains("lane length"), "{err}");
}

/// Local x extent of a segment's obstacles.
fn extent(p: &TileParams) -> (f64, f64) {
    match *p {
        TileParams::Stair {
            x0,
            steps,
            tread,
            top_length,
            ..
        } => (x0, x0 + 2.0 * (steps - 1) as f64 * tread + top_length),
        TileParams::Gap {
            x0,
            count,
            gap,
            platform,
        }
        | TileParams::BalancingBeam {
            x0,
            count,
            gap,
            platform,
            ..
        } => (x0, x0 + count as f64 * gap + (count - 1) as f64 * platform),
        TileParams::Bridge { x0, x1, .. }
        | TileParams::Uneven { x0, x1, .. }
        | TileParams::Wave { x0, x1, .. } => (x0, x1),
        TileParams::Slope {
            x0,
            ramp_length,
            top_length,
            ..
        } => (x0, x0 + 2.0 * ramp_length + top_length),
        TileParams::SlopeBridge {
            x0, arch_length, ..
        } => (x0, x0 + arch_length),
        TileParams::Flat => (f64::INFINITY, f64::NEG_INFINITY),
    }
}

#[test]
fn hfield_export_agrees_with_the_heights() {
    let (_, map) = &maps()[0];
    let data = map.hfield_data();
    assert_eq!(data.len(), map.nx() * map.ny());
    assert!(data.iter().all(|v| (0.0..=1.0).contains(v)));
    assert!(data.contains(&0.0) && data.contains(&1.0));
    let [lo, hi] = map.height_range();
    let size = map.hfield_size();
    let pos = map.hfield_pos();
    assert_eq!(size[2], hi - lo);
    assert_eq!(pos[2], lo);
    assert_eq!(
        [pos[0] - size[0], pos[1] - size[1]],
        [0.0, 0.0],
        "corner at the origin"
    );
    let hf = map.height_field();
    assert_eq!((hf.nrow(), hf.ncol()), map.hfield_shape());
    let hs = map.horizontal_scale();
    for j in (0..map.ny()).step_by(7) {
        for i in (0..map.nx()).step_by(5) {
            let (x, y) = (i as f64 * hs, j as f64 * hs);
            assert!(
                (hf.height(x, y) - map.height_at(i, j)).abs() < 1e-5,
                "({i}, {j})"
            );
            let (xm, ym) = (x + 0.37 * hs, y + 0.61 * hs);
            assert!((hf.height(xm, ym) - map.height(xm, ym)).abs() < 1e-5);
        }
    }
}

#[test]
fn hfield_uploads_into_mujoco_where_the_heights_say() {
    let cfg = TerrainConfig {
        border: 1.0,
        ..TerrainConfig::default()
    };
    let lane = TerrainMap::lane(&cfg, TerrainKind::Stair, 9, 4.0, 2.0, 5).unwrap();
    let map = lane.map();
    let (asset, geom) = map.hfield_mjcf("terrain");
    let xml = format!("<mujoco><asset>{asset}</asset><worldbody>{geom}</worldbody></mujoco>");
    let dir = Scratch::new("terrain-mj");
    let mut model = Model::from_xml_str(&xml, &dir.0, "terrain").unwrap();
    model.set_hfield_data(0, &map.hfield_data()).unwrap();
    let g = model.id(ObjType::Geom, "terrain").unwrap();
    let from_model = HeightField::from_model(&model, g).unwrap();
    let mut d = Data::new(Arc::new(model)).unwrap();
    d.forward();
    let [ex, ey] = map.extent();
    for k in 0..400 {
        let (x, y) = (
            0.1 + (ex - 0.2) * (k as f64 * 0.618).fract(),
            0.1 + (ey - 0.2) * (k as f64 * 0.377).fract(),
        );
        let (dist, _) = d
            .ray([x, y, 5.0], [0.0, 0.0, -1.0], None, true, None)
            .expect("ray hits");
        assert!((5.0 - dist - map.height(x, y)).abs() < 1e-3, "({x}, {y})");
        assert!((from_model.height(x, y) - map.height(x, y)).abs() < 1e-5);
    }
}

#[test]
fn bad_configs_are_clear_errors() {
    let msg = TerrainKind::from_name("stairs").unwrap_err().to_string();
    for k in TerrainKind::ALL {
        assert!(msg.contains(k.name()), "{msg}");
    }
    assert!(msg.contains("'stairs'"), "{msg}");
    for k in TerrainKind::ALL {
        assert_eq!(TerrainKind::from_name(k.name()).unwrap(), k);
    }
    let yaml_err = |y: &str| TerrainConfig::from_yaml_str(y).unwrap_err().to_string();
    let msg = yaml_err("kinds: {stairs: 1}");
    assert!(
        msg.contains("stairs") && msg.contains("balancing_beam"),
        "{msg}"
    );
    let msg = yaml_err("num_levels: 0");
    assert!(
        msg.contains("num_levels") && msg.contains("at least 1"),
        "{msg}"
    );
    let msg = yaml_err("tile_length: -8.0");
    assert!(msg.contains("tile_length") && msg.contains("-8"), "{msg}");
    let msg = yaml_err("tile_lenght: 8.0");
    assert!(
        msg.contains("unknown field") && msg.contains("tile_lenght"),
        "{msg}"
    );
    let msg = yaml_err("stair: {hieght: [0.1, 0.2]}");
    assert!(msg.contains("hieght"), "{msg}");
    let msg = yaml_err("kinds: {stair: 0, gap: 0}");
    assert!(msg.contains("all weights are zero"), "{msg}");
    let msg = yaml_err("kinds: {}");
    assert!(msg.contains("kinds") && msg.contains("empty"), "{msg}");
    let msg = yaml_err("kinds: {stair: -1}");
    assert!(msg.contains("kinds.stair"), "{msg}");
    let msg = yaml_err("tile_width: 4.03");
    assert!(msg.contains("multiple of horizontal_scale"), "{msg}");
    let msg = yaml_err("num_cols: 2");
    assert!(msg.contains("no column"), "{msg}");
    let msg = yaml_err("horizontal_scale: .nan");
    assert!(msg.contains("horizontal_scale"), "{msg}");
    let msg = yaml_err("stair: {tread: [0.4, 0.0]}");
    assert!(msg.contains("stair.tread[1]"), "{msg}");
    // a bound that must be positive says so, not f64::MIN_POSITIVE's 300 digits
    let msg = yaml_err("gap: {gap: [0.0, 0.3]}");
    assert!(
        msg.contains("gap.gap[0]") && msg.contains("> 0") && msg.len() < 200,
        "{msg}"
    );
    // the resolved config round-trips through YAML
    let cfg = all_kinds_config();
    let text = serde_yaml::to_string(&cfg).unwrap();
    assert!(text.contains("balancing_beam: 1.0"), "{text}");
    assert_eq!(TerrainConfig::from_yaml_str(&text).unwrap(), cfg);
    let err = TerrainConfig::from_yaml_file("/no/such/terrain.yaml").unwrap_err();
    assert!(err.to_string().contains("/no/such/terrain.yaml"));
}

#[test]
fn odd_but_valid_configs_generate_without_panicking() {
    let base = TerrainConfig {
        kinds: TerrainKind::ALL.into_iter().map(|k| (k, 1.0)).collect(),
        num_cols: 9,
        ..TerrainConfig::default()
    };
    let configs = [
        TerrainConfig {
            horizontal_scale: 0.5,
            roughness_cell: 0.5,
            tile_length: 2.5,
            tile_width: 0.5,
            border: 0.0,
            ..base.clone()
        },
        TerrainConfig {
            horizontal_scale: 0.1,
            num_levels: 1,
            roughness_cell: 0.1,
            ..base.clone()
        },
        TerrainConfig {
            base_roughness: 0.0,
            min_roughness: 0.0,
            num_levels: 2,
            ..base.clone()
        },
        TerrainConfig {
            wave: WaveParams {
                count: Curriculum([0.0, 0.0]),
                ..WaveParams::default()
            },
            tile_width: 0.5,
            arch_length: 0.1,
            ..base.clone()
        },
    ];
    for cfg in &configs {
        let map = TerrainMap::generate(cfg, 5).unwrap();
        assert!(map.heights().iter().all(|h| h.is_finite()));
        let data = map.hfield_data();
        assert!(data.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(map.hfield_size()[2] >= 1e-3);
        let _ = map.height_field();
        for kind in TerrainKind::ALL {
            let lane = TerrainMap::lane(cfg, kind, cfg.max_level(), 1.0, 0.5, 1).unwrap();
            assert!(lane.map().heights().iter().all(|h| h.is_finite()), "{kind}");
        }
        for (a, b) in COMBINED_PAIRS {
            TerrainMap::combined_lane(cfg, a, b, 0, 2.0, 0.5, 1).unwrap();
        }
    }
}

fn png_dims(path: &std::path::Path) -> (u32, u32) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let reader = png::Decoder::new(file).read_info().unwrap();
    let info = reader.info();
    (info.width, info.height)
}

#[test]
fn render_writes_png_of_the_expected_size() {
    let dir = Scratch::new("terrain-png");
    // DREAMPOLICY_TERRAIN_PNG=/some/dir keeps the images for a look
    let out = std::env::var_os("DREAMPOLICY_TERRAIN_PNG").map_or(dir.0.clone(), Into::into);
    let (_, map) = &maps()[0];
    let path = out.join("map.png");
    render_map(map, &path).unwrap();
    let (w, h) = png_size(map);
    assert_eq!(png_dims(&path), (w as u32, h as u32));
    assert!(w >= map.nx() && h >= map.ny());
    let cfg = TerrainConfig::default();
    for kind in TerrainKind::ALL {
        let path = out.join(format!("{kind}.png"));
        let lane = render_kind(&cfg, kind, 9, 1, &path).unwrap();
        let (w, h) = lane_png_size(&lane);
        assert!(w >= 400, "at least 400 px wide");
        assert_eq!(png_dims(&path), (w as u32, h as u32));
    }
    let lane =
        TerrainMap::combined_lane(&cfg, TerrainKind::Stair, TerrainKind::Gap, 9, 10.0, 4.0, 1)
            .unwrap();
    render_lane(&lane, out.join("stair_gap.png")).unwrap();
    let err = render_map(map, "/proc/no/such/dir/x.png").unwrap_err();
    assert!(matches!(err, TerrainError::Io { .. }), "{err}");
}

/// `level_sampling: bound` (legged_gym's): every tile of a level holds exactly
/// the level's bound, where the paper's sampling draws between the easy end and
/// the bound; both draw the same random numbers, so the other draws agree.
#[test]
fn bound_level_sampling_draws_each_levels_bound() {
    let mut cfg = TerrainConfig::default();
    cfg.bridge.width = Curriculum([1.0, 0.2]);
    cfg.stair.height = Curriculum([0.0, 0.2]);
    let widths = |cfg: &TerrainConfig, level: usize| -> Vec<f64> {
        (0..8u64)
            .map(|seed| {
                let lane =
                    TerrainMap::lane(cfg, TerrainKind::Bridge, level, 10.0, 4.0, seed).unwrap();
                match lane.segments()[0].params {
                    TileParams::Bridge { width, .. } => width,
                    ref p => panic!("{p:?}"),
                }
            })
            .collect()
    };
    let paper = widths(&cfg, 7);
    let bound = 1.0 - 0.8 * 7.0 / 9.0;
    // the paper's draws spread between 1.0 and the bound
    assert!(
        paper.iter().all(|w| *w >= bound - 0.05 && *w <= 1.0),
        "{paper:?}"
    );
    assert!(paper.iter().any(|w| *w > bound + 0.1), "{paper:?}");
    cfg.level_sampling = LevelSampling::Bound;
    for level in [0, 4, 7, 9] {
        let want = 1.0 - 0.8 * level as f64 / 9.0;
        for w in widths(&cfg, level) {
            assert!(
                (w - want).abs() <= cfg.horizontal_scale,
                "level {level}: {w} for {want}"
            );
        }
    }
    for level in [2, 8] {
        let want = 0.2 * level as f64 / 9.0;
        for seed in 0..4u64 {
            let lane = TerrainMap::lane(&cfg, TerrainKind::Stair, level, 10.0, 4.0, seed).unwrap();
            let TileParams::Stair { height, .. } = lane.segments()[0].params else {
                panic!();
            };
            assert!(
                (height - want).abs() <= cfg.vertical_scale,
                "level {level}: {height} for {want}"
            );
        }
    }
    // YAML spells it as the enum's name
    let c = TerrainConfig::from_yaml_str("level_sampling: bound").unwrap();
    assert_eq!(c.level_sampling, LevelSampling::Bound);
    assert!(TerrainConfig::from_yaml_str("level_sampling: hardest").is_err());
}
