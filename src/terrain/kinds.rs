//! The terrain kinds of the paper, their snake_case names (the only spelling a
//! config or the CLI accepts), and the paper's training, unseen and combined sets.
use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::TerrainError;

/// One terrain kind. Training kinds come first, then the unseen ones; the order
/// is the order of [`TerrainKind::ALL`] and of a map's columns for equal weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum TerrainKind {
    /// Nothing but the base roughness.
    Flat,
    /// Random raised and lowered rectangular blocks.
    Uneven,
    /// A run-up, steps up, a top platform, steps down.
    Stair,
    /// Pits across the whole tile width between short platforms.
    Gap,
    /// A narrow bridge at ground level over a pit.
    Bridge,
    /// A sum of long sines (unseen).
    Wave,
    /// A 30 degree ramp up, a platform, a ramp down (unseen).
    Slope,
    /// Gap's layout with platforms only as wide as the bridge (unseen).
    BalancingBeam,
    /// A bridge arched as the first half of a sine (unseen).
    SlopeBridge,
}

/// The paper's five combined-terrain lanes: first half, second half.
pub const COMBINED_PAIRS: [(TerrainKind, TerrainKind); 5] = [
    (TerrainKind::Stair, TerrainKind::Uneven),
    (TerrainKind::Bridge, TerrainKind::Uneven),
    (TerrainKind::Stair, TerrainKind::Gap),
    (TerrainKind::Stair, TerrainKind::Bridge),
    (TerrainKind::Bridge, TerrainKind::Gap),
];

impl TerrainKind {
    /// Every kind, training kinds first.
    pub const ALL: [TerrainKind; 9] = [
        TerrainKind::Flat,
        TerrainKind::Uneven,
        TerrainKind::Stair,
        TerrainKind::Gap,
        TerrainKind::Bridge,
        TerrainKind::Wave,
        TerrainKind::Slope,
        TerrainKind::BalancingBeam,
        TerrainKind::SlopeBridge,
    ];
    /// The kinds the specialists and the unified policy train on.
    pub const TRAINING: [TerrainKind; 5] = [
        TerrainKind::Flat,
        TerrainKind::Uneven,
        TerrainKind::Stair,
        TerrainKind::Gap,
        TerrainKind::Bridge,
    ];
    /// The kinds held out for evaluation.
    pub const UNSEEN: [TerrainKind; 4] = [
        TerrainKind::Wave,
        TerrainKind::Slope,
        TerrainKind::BalancingBeam,
        TerrainKind::SlopeBridge,
    ];

    /// The snake_case name used in configs, file names and the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            TerrainKind::Flat => "flat",
            TerrainKind::Uneven => "uneven",
            TerrainKind::Stair => "stair",
            TerrainKind::Gap => "gap",
            TerrainKind::Bridge => "bridge",
            TerrainKind::Wave => "wave",
            TerrainKind::Slope => "slope",
            TerrainKind::BalancingBeam => "balancing_beam",
            TerrainKind::SlopeBridge => "slope_bridge",
        }
    }

    /// Parse a snake_case name; an unknown one is an error that lists every name.
    pub fn from_name(name: &str) -> Result<TerrainKind, TerrainError> {
        TerrainKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| TerrainError::UnknownKind {
                name: name.to_string(),
                valid: TerrainKind::valid_names(),
            })
    }

    /// `"flat, uneven, ..."`: every valid name, for messages.
    pub fn valid_names() -> String {
        TerrainKind::ALL.map(TerrainKind::name).join(", ")
    }

    /// True for the kinds of [`TerrainKind::TRAINING`].
    pub fn is_training(self) -> bool {
        TerrainKind::TRAINING.contains(&self)
    }

    /// The walking length of an evaluation lane of this kind: the paper's 10 m,
    /// except the slope bridge, whose arch the paper fixes at 18 m; its lane is
    /// 18.5 m so that the default 18 m arch fits after the 0.5 m between the
    /// spawn point and the first obstacle.
    pub fn default_lane_length(self) -> f64 {
        match self {
            TerrainKind::SlopeBridge => 18.5,
            _ => 10.0,
        }
    }
}

impl fmt::Display for TerrainKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for TerrainKind {
    type Err = TerrainError;
    fn from_str(s: &str) -> Result<TerrainKind, TerrainError> {
        TerrainKind::from_name(s)
    }
}

impl Serialize for TerrainKind {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for TerrainKind {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<TerrainKind, D::Error> {
        let name = String::deserialize(d)?;
        TerrainKind::from_name(&name).map_err(serde::de::Error::custom)
    }
}
