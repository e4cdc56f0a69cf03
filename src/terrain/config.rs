//! [`TerrainConfig`]: map layout, grid resolution, the paper's curriculum ranges
//! per kind, read from YAML with unknown keys refused and every value validated.
use std::collections::BTreeMap;
use std::path::Path;

use rand::Rng;
use serde::{Deserialize, Serialize};

use super::{TerrainError, TerrainKind};

/// A curriculum range `[p0, p1]` (the paper's appendix): at level `l` of
/// `0..=max_level` the value is `p0 + random((p1 - p0) / max_level * l)` with
/// `random(a)` uniform in `[0, a]`. Level 0 always gives `p0`; `p1 < p0` means a
/// larger value is easier (stair treads 0.40 -> 0.25).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Curriculum(pub [f64; 2]);

/// Which offsets an uneven block takes from its drawn height `h`
/// ([`UnevenParams::heights`]); the sign is `raised_fraction`'s either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UnevenHeights {
    /// `h` or `h / 2` with an even chance: Isaac Gym's
    /// `discrete_obstacles_terrain` (`[-h, -h/2, h/2, h]`), the generator whose
    /// parameters (max height, min and max size, rectangle count) the paper's
    /// table gives. The paper's level 0 (`h` = 0.10 m) has 5 and 10 cm blocks.
    #[default]
    Isaac,
    /// Every block `h` (this project's reading of the table before; the
    /// paper's level 0 then has only 10 cm blocks and 20 cm steps between a
    /// raised and a lowered one).
    Full,
}

/// How tile parameters follow the difficulty ([`TerrainConfig::level_sampling`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LevelSampling {
    /// `p0 + u (p1 - p0) d`, `u` uniform in [0, 1] (the paper's appendix).
    #[default]
    Paper,
    /// `p0 + (p1 - p0) d` (legged_gym's).
    Bound,
}

impl Curriculum {
    /// The value at difficulty `d` under `mode`: [`Curriculum::sample`] or
    /// [`Curriculum::bound`] (which still draws, so that the tile's other
    /// draws are the same in both modes).
    pub fn draw<R: Rng + ?Sized>(&self, d: f64, mode: LevelSampling, rng: &mut R) -> f64 {
        let v = self.sample(d, rng);
        match mode {
            LevelSampling::Paper => v,
            LevelSampling::Bound => self.bound(d),
        }
    }

    /// [`Curriculum::draw`] rounded to the nearest integer (counts).
    pub fn draw_count<R: Rng + ?Sized>(&self, d: f64, mode: LevelSampling, rng: &mut R) -> usize {
        self.draw(d, mode, rng).round().max(0.0) as usize
    }

    /// Draw the value for difficulty `d = level / max_level` in `[0, 1]`.
    pub fn sample<R: Rng + ?Sized>(&self, d: f64, rng: &mut R) -> f64 {
        let [p0, p1] = self.0;
        p0 + rng.random::<f64>() * (p1 - p0) * d
    }

    /// The far end of the values possible at difficulty `d`: `p0 + (p1 - p0) * d`.
    pub fn bound(&self, d: f64) -> f64 {
        let [p0, p1] = self.0;
        p0 + (p1 - p0) * d
    }

    fn check(&self, field: &str, min: f64) -> Result<(), TerrainError> {
        for (i, v) in self.0.iter().enumerate() {
            if !v.is_finite() || *v < min {
                let bound = if min == f64::MIN_POSITIVE {
                    "> 0".to_string()
                } else {
                    format!(">= {min}")
                };
                return Err(TerrainError::config(
                    format!("{field}[{i}]"),
                    format!("{v} must be a finite number {bound}"),
                ));
            }
        }
        Ok(())
    }
}

/// Difficulty in `[0, 1]` of `level` out of `0..=max_level` (0 when there is one level).
pub fn difficulty(level: usize, max_level: usize) -> f64 {
    if max_level == 0 {
        0.0
    } else {
        level as f64 / max_level as f64
    }
}

macro_rules! params {
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $field:ident : $ty:ty = $default:expr),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct $name { $($(#[$fm])* pub $field: $ty),* }
        impl Default for $name {
            fn default() -> $name { $name { $($field: $default),* } }
        }
    };
}

params!(
    /// Uneven ground (paper table): random rectangular blocks, each raised or
    /// lowered (random sign); each block draws its height `h` and both sides
    /// from the curriculum, and `heights` says which offsets `h` gives.
    UnevenParams {
        /// Block height `h` (m): the largest offset of a block.
        height: Curriculum = Curriculum([0.10, 0.20]),
        /// The offsets a block takes from its `h`: `isaac` (Isaac Gym's
        /// `discrete_obstacles_terrain`, which the paper's table parametrizes:
        /// `h` or `h / 2`, an even chance) or `full` (every block `h`).
        heights: UnevenHeights = UnevenHeights::Isaac,
        /// Block side (m), drawn separately along x and y.
        size: Curriculum = Curriculum([0.40, 0.70]),
        /// Block side across the walking direction (along y, m), a training
        /// curriculum beside the paper's table: unset (the paper's table), `size`.
        /// Wide blocks at the low levels are strips whose edges all cross the
        /// walking direction, as a stair's do; narrowing them brings the
        /// sideways edges in one level at a time.
        width: Option<Curriculum> = None,
        /// Chance that a block is raised rather than lowered (the paper: even).
        raised_fraction: f64 = 0.5,
        /// Block count per `reference_area`.
        count: Curriculum = Curriculum([150.0, 200.0]),
        /// The area the paper's counts refer to: its 8 m x 8 m tiles (m^2). The
        /// count is scaled by (area the blocks are laid in) / this, so a 8 m x 4 m
        /// tile keeps the paper's coverage instead of being tiled solid.
        reference_area: f64 = 64.0,
    }
);

params!(
    /// Stairs along x (paper table).
    StairParams {
        /// Riser height (m).
        height: Curriculum = Curriculum([0.15, 0.30]),
        /// Tread length (m); shorter is harder.
        tread: Curriculum = Curriculum([0.40, 0.25]),
        /// Steps up (and as many down); capped so the stairs fit the tile.
        steps: Curriculum = Curriculum([5.0, 10.0]),
        /// Length of the top platform (m).
        top_length: f64 = 1.0,
    }
);

params!(
    /// Gaps across the tile (paper table and text).
    GapParams {
        /// Platform between two gaps (m); shorter is harder.
        platform: Curriculum = Curriculum([0.60, 0.40]),
        /// Gap width (m): the paper's [0.2, 0.3], wider at higher levels.
        gap: Curriculum = Curriculum([0.20, 0.30]),
        /// Number of gaps; capped so they fit the tile.
        count: Curriculum = Curriculum([5.0, 10.0]),
        /// Depth of each gap (m), a training curriculum below the paper's
        /// table: unset (the paper's table), every gap is a pit `pit_depth`
        /// deep. One heightfield sample wide and a metre deep, a 5 cm gap is a
        /// V-shaped slot 10 cm wide that traps the G1's foot capsules; shallow
        /// gaps at the low levels let a foundation learn to step over them.
        depth: Option<Curriculum> = None,
    }
);

params!(
    /// A bridge over a pit (paper table); also the width of balancing-beam
    /// platforms and of the slope bridge.
    BridgeParams {
        /// Bridge width (m); narrower is harder.
        width: Curriculum = Curriculum([0.40, 0.20]),
    }
);

params!(
    /// A sum of sines (paper text): count and amplitudes from the curriculum.
    WaveParams {
        /// Number of sines.
        count: Curriculum = Curriculum([5.0, 10.0]),
        /// Amplitude of each sine (m).
        amplitude: Curriculum = Curriculum([0.2, 0.5]),
        /// Wavelength range (m), uniform and level-independent: 4 m and more
        /// keeps a single 0.5 m sine under 38 degrees of slope.
        wavelength: [f64; 2] = [4.0, 12.0],
        /// Length (m) over which the waves fade in after the flat run-up (and
        /// out before the end of the obstacle region).
        fade: f64 = 2.0,
    }
);

params!(
    /// A ramp up, a platform, a ramp down (paper: a fixed 30 degrees).
    SlopeParams {
        /// Ramp inclination (degrees).
        angle_deg: f64 = 30.0,
        /// Horizontal length of each ramp (m); shortened if the tile is short.
        ramp_length: f64 = 2.0,
        /// Length of the top platform (m).
        top_length: f64 = 1.0,
    }
);

params!(
    /// The arched bridge (paper text): width from [`BridgeParams`].
    SlopeBridgeParams {
        /// Arch height (m).
        amplitude: Curriculum = Curriculum([1.5, 2.5]),
    }
);

fn default_kinds() -> BTreeMap<TerrainKind, f64> {
    TerrainKind::TRAINING
        .into_iter()
        .map(|k| (k, 1.0))
        .collect()
}

params!(
    /// The terrain map and everything its tiles are drawn from.
    TerrainConfig {
        /// Tile length along x, the walking direction (m).
        tile_length: f64 = 8.0,
        /// Tile width along y (m).
        tile_width: f64 = 4.0,
        /// Rows of the map = difficulty levels `0..num_levels`.
        num_levels: usize = 10,
        /// Columns of the map, shared among `kinds` in proportion to the weights.
        num_cols: usize = 10,
        /// Kind -> weight (legged_gym's proportions, by name).
        kinds: BTreeMap<TerrainKind, f64> = default_kinds(),
        /// Flat border around the map (m).
        border: f64 = 5.0,
        /// Grid spacing (m). 0.05 m, not 0.1 m: a 0.25 m tread or a 0.2 m gap then
        /// spans 4-5 samples, where 0.1 m would alias them to 2-3 and let their
        /// widths jump by 50 % with the sampling phase; and MuJoCo triangulates
        /// each cell, so every vertical edge becomes a one-cell slope, which must
        /// stay short next to a 0.2 m foot.
        horizontal_scale: f64 = 0.05,
        /// Heights are multiples of this (m), as legged_gym's int16 raw heights.
        vertical_scale: f64 = 0.005,
        /// Depth of gaps and of the pit under bridges (m below ground).
        pit_depth: f64 = 1.0,
        /// Spacing of the roughness control grid, bilinearly upsampled (m).
        roughness_cell: f64 = 0.2,
        /// The paper's base roughness: heights `random(-a, a) * difficulty` (m).
        base_roughness: f64 = 0.02,
        /// Always-on roughness (m), `+-min_roughness` at every control point, so
        /// that no tile is exactly flat.
        min_roughness: f64 = 0.005,
        /// Length of the slope bridge's arch (m), the paper's 18 m.
        arch_length: f64 = 18.0,
        /// How a tile's parameters follow its level: `paper` (the paper's
        /// formula, uniform between the easy end and the level's bound, so that
        /// a level holds every easier lane too) or `bound` (exactly the level's
        /// bound, legged_gym's: a curriculum level then says the hardest lane
        /// it holds, and every env trains at its frontier).
        level_sampling: LevelSampling = LevelSampling::Paper,
        /// A cell is an edge where a 4-neighbour differs by more than this (m).
        edge_threshold: f64 = 0.05,
        uneven: UnevenParams = UnevenParams::default(),
        stair: StairParams = StairParams::default(),
        gap: GapParams = GapParams::default(),
        bridge: BridgeParams = BridgeParams::default(),
        wave: WaveParams = WaveParams::default(),
        slope: SlopeParams = SlopeParams::default(),
        slope_bridge: SlopeBridgeParams = SlopeBridgeParams::default(),
    }
);

/// Refuse maps beyond this many samples (a typo such as `horizontal_scale: 0.0005`).
const MAX_SAMPLES: f64 = 1.0e8;

fn check(ok: bool, field: &str, value: f64, what: &str) -> Result<(), TerrainError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(TerrainError::config(field, format!("{value} {what}")))
    }
}

impl TerrainConfig {
    /// Parse and validate a YAML document.
    pub fn from_yaml_str(text: &str) -> Result<TerrainConfig, TerrainError> {
        let cfg: TerrainConfig = serde_yaml::from_str(text)?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Read, parse and validate a YAML file.
    pub fn from_yaml_file(path: impl AsRef<Path>) -> Result<TerrainConfig, TerrainError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| TerrainError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        TerrainConfig::from_yaml_str(&text)
    }

    /// The highest level, `num_levels - 1`.
    pub fn max_level(&self) -> usize {
        self.num_levels.saturating_sub(1)
    }

    /// Check every value; the error names the offending field.
    pub fn validate(&self) -> Result<(), TerrainError> {
        if self.num_levels == 0 {
            return Err(TerrainError::config("num_levels", "must be at least 1"));
        }
        if self.num_cols == 0 {
            return Err(TerrainError::config("num_cols", "must be at least 1"));
        }
        let hs = self.horizontal_scale;
        check(
            hs > 0.0 && hs <= 0.5,
            "horizontal_scale",
            hs,
            "must be in (0, 0.5] m",
        )?;
        let vs = self.vertical_scale;
        check(
            vs > 0.0 && vs <= 0.1,
            "vertical_scale",
            vs,
            "must be in (0, 0.1] m",
        )?;
        for (field, v, min) in [
            ("tile_length", self.tile_length, 2.5),
            ("tile_width", self.tile_width, 0.5),
            ("border", self.border, 0.0),
        ] {
            check(v >= min, field, v, &format!("must be at least {min} m"))?;
            let cells = v / hs;
            check(
                (cells - cells.round()).abs() < 1e-6,
                field,
                v,
                &format!("must be a multiple of horizontal_scale ({hs} m)"),
            )?;
        }
        let samples = (self.num_levels as f64 * self.tile_length + 2.0 * self.border)
            * (self.num_cols as f64 * self.tile_width + 2.0 * self.border)
            / (hs * hs);
        check(
            samples <= MAX_SAMPLES,
            "horizontal_scale",
            hs,
            &format!("gives {samples:.3e} samples, more than the {MAX_SAMPLES:.0e} allowed"),
        )?;
        for (field, v) in [
            ("pit_depth", self.pit_depth),
            ("arch_length", self.arch_length),
            ("edge_threshold", self.edge_threshold),
            ("uneven.reference_area", self.uneven.reference_area),
            ("wave.fade", self.wave.fade),
            ("slope.ramp_length", self.slope.ramp_length),
        ] {
            check(v > 0.0, field, v, "must be positive")?;
        }
        let rf = self.uneven.raised_fraction;
        check(
            (0.0..=1.0).contains(&rf),
            "uneven.raised_fraction",
            rf,
            "must be in [0, 1]",
        )?;
        for (field, v) in [
            ("base_roughness", self.base_roughness),
            ("min_roughness", self.min_roughness),
            ("stair.top_length", self.stair.top_length),
            ("slope.top_length", self.slope.top_length),
        ] {
            check(v >= 0.0, field, v, "must not be negative")?;
        }
        let rc = self.roughness_cell;
        check(
            rc >= hs,
            "roughness_cell",
            rc,
            "must be at least horizontal_scale",
        )?;
        let a = self.slope.angle_deg;
        check(
            a > 0.0 && a < 80.0,
            "slope.angle_deg",
            a,
            "must be in (0, 80) degrees",
        )?;
        let [w0, w1] = self.wave.wavelength;
        check(
            w0 > 0.0 && w1 >= w0,
            "wave.wavelength",
            w0,
            "must be positive and <= the upper end",
        )?;
        let positive = f64::MIN_POSITIVE;
        for (field, c, min) in [
            ("uneven.height", self.uneven.height, 0.0),
            ("uneven.size", self.uneven.size, positive),
            (
                "uneven.width",
                self.uneven.width.unwrap_or(Curriculum([1.0, 1.0])),
                positive,
            ),
            ("uneven.count", self.uneven.count, 0.0),
            ("stair.height", self.stair.height, 0.0),
            ("stair.tread", self.stair.tread, positive),
            ("stair.steps", self.stair.steps, 1.0),
            ("gap.platform", self.gap.platform, positive),
            ("gap.gap", self.gap.gap, positive),
            ("gap.count", self.gap.count, 1.0),
            (
                "gap.depth",
                self.gap.depth.unwrap_or(Curriculum([1.0, 1.0])),
                positive,
            ),
            ("bridge.width", self.bridge.width, positive),
            ("wave.count", self.wave.count, 0.0),
            ("wave.amplitude", self.wave.amplitude, 0.0),
            ("slope_bridge.amplitude", self.slope_bridge.amplitude, 0.0),
        ] {
            c.check(field, min)?;
        }
        self.check_kinds()
    }

    fn check_kinds(&self) -> Result<(), TerrainError> {
        if self.kinds.is_empty() {
            return Err(TerrainError::config(
                "kinds",
                format!(
                    "is empty: give at least one of {}",
                    TerrainKind::valid_names()
                ),
            ));
        }
        for (kind, w) in &self.kinds {
            check(
                *w >= 0.0,
                &format!("kinds.{kind}"),
                *w,
                "must be a weight >= 0",
            )?;
        }
        if self.kinds.values().all(|w| *w == 0.0) {
            return Err(TerrainError::config("kinds", "all weights are zero"));
        }
        let cols = self.column_kinds();
        let missing: Vec<&str> = self
            .kinds
            .iter()
            .filter(|(k, w)| **w > 0.0 && !cols.contains(k))
            .map(|(k, _)| k.name())
            .collect();
        if !missing.is_empty() {
            return Err(TerrainError::config(
                "num_cols",
                format!(
                    "{} columns leave no column to {}: raise num_cols or the weights",
                    self.num_cols,
                    missing.join(", ")
                ),
            ));
        }
        Ok(())
    }

    /// The kind of every column, as legged_gym assigns them: column `j` takes the
    /// first kind whose cumulative weight share exceeds `j / num_cols + 0.001`
    /// (kinds in [`TerrainKind::ALL`] order, zero weights skipped).
    pub fn column_kinds(&self) -> Vec<TerrainKind> {
        let active: Vec<(TerrainKind, f64)> = self
            .kinds
            .iter()
            .filter(|(_, w)| **w > 0.0)
            .map(|(k, w)| (*k, *w))
            .collect();
        let total: f64 = active.iter().map(|(_, w)| w).sum();
        (0..self.num_cols)
            .map(|j| {
                let choice = j as f64 / self.num_cols as f64 + 0.001;
                let mut cum = 0.0;
                for (k, w) in &active {
                    cum += w / total;
                    if choice < cum {
                        return *k;
                    }
                }
                active.last().map_or(TerrainKind::Flat, |(k, _)| *k)
            })
            .collect()
    }
}
