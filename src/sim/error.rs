//! Typed errors of the simulation layer.
use std::fmt;
use std::path::PathBuf;

/// Everything the safe MuJoCo layer can fail with.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The model file does not exist (checked before MuJoCo sees it).
    #[error("MuJoCo model file {0} does not exist")]
    NotFound(PathBuf),
    /// MuJoCo rejected the model; `message` is MuJoCo's own error text.
    #[error("MuJoCo could not load {path}: {message}")]
    Load { path: PathBuf, message: String },
    /// Writing or reading a file around a load failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `mj_makeData` returned NULL.
    #[error("mj_makeData failed for model {0}")]
    MakeData(String),
    /// A name lookup failed.
    #[error("model {model} has no {kind} named '{name}'")]
    UnknownName {
        kind: &'static str,
        name: String,
        model: String,
    },
    /// An index is out of range (keyframe, heightfield, ...).
    #[error("{kind} index {index} out of range: the model has {count}")]
    BadIndex {
        kind: &'static str,
        index: usize,
        count: usize,
    },
    /// A buffer handed to the layer has the wrong length.
    #[error("{what}: expected {expected} values, got {got}")]
    Size {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// A heightfield value or geometry that MuJoCo cannot represent.
    #[error("heightfield: {0}")]
    Hfield(String),
    /// Offscreen rendering is unavailable or failed (`sim::render`).
    #[error("rendering: {0}")]
    Render(String),
    /// A G1 joint's armature in the compiled model is not its motor's (robot::check_armature).
    #[error(
        "model {model}: joint {joint} has armature {found}, the motor table says {expected}; \
         run scripts/setup.sh to regenerate models/unitree_g1/g1_armature.xml"
    )]
    Armature {
        model: String,
        joint: String,
        found: f64,
        expected: f64,
    },
    /// The simulation blew up; the env layer resets and counts it.
    #[error("simulation unstable at t = {time:.3} s: {reason}")]
    Unstable { time: f64, reason: Instability },
}

/// Why a state was judged unstable.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Instability {
    /// MuJoCo raised mjWARN_BADQACC (NaN/Inf/huge acceleration) and reset the data.
    BadQacc { dof: i32 },
    /// MuJoCo raised mjWARN_BADQPOS.
    BadQpos { dof: i32 },
    /// MuJoCo raised mjWARN_BADQVEL.
    BadQvel { dof: i32 },
    /// A NaN or Inf in `qpos` or `qvel`.
    NonFinite { field: &'static str, index: usize },
    /// A generalized velocity beyond the configured bound.
    Velocity { dof: usize, value: f64, limit: f64 },
}

impl fmt::Display for Instability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Instability::BadQacc { dof } => write!(f, "MuJoCo reported a bad qacc at dof {dof}"),
            Instability::BadQpos { dof } => write!(f, "MuJoCo reported a bad qpos at dof {dof}"),
            Instability::BadQvel { dof } => write!(f, "MuJoCo reported a bad qvel at dof {dof}"),
            Instability::NonFinite { field, index } => {
                write!(f, "non-finite {field}[{index}]")
            }
            Instability::Velocity { dof, value, limit } => {
                write!(f, "|qvel[{dof}]| = {value:.1} exceeds the bound {limit}")
            }
        }
    }
}
