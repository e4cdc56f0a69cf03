//! One control step of one env ([`Frame`]) and its message bytes.
//!
//! A frame is one MCAP message on the `/frames` channel, fixed size, little-endian,
//! `80 + 4 * (state + action + scandots)` bytes (1336 for the G1's 98 + 29 + 187):
//!
//! | offset | size | type       | field                                                        |
//! |--------|------|------------|--------------------------------------------------------------|
//! | 0      | 8    | u64        | episode id (unique in the dataset, see [`super::episode_id`]) |
//! | 8      | 4    | u32        | env id                                                       |
//! | 12     | 4    | u32        | step index in the episode (0 = first step after a reset)     |
//! | 16     | 4    | u32        | terrain level                                                |
//! | 20     | 1    | u8         | terrain kind: index into the shard metadata's `terrain_kinds` |
//! | 21     | 1    | u8         | flags: bit 0 terminated, bit 1 truncated (other bits 0)      |
//! | 22     | 2    | -          | zero                                                         |
//! | 24     | 24   | 3 x f64    | pelvis position (world, m)                                   |
//! | 48     | 32   | 4 x f64    | pelvis orientation quaternion `[w, x, y, z]` (world)         |
//! | 80     | 4 S  | S x f32    | state `s_t` (the actor observation, `env::obs` layout)       |
//! | +4 S   | 4 A  | A x f32    | action `a_t` taken at `s_t`                                  |
//! | +4 A   | 4 C  | C x f32    | scandots at `s_t` (`env::obs` grid)                          |
//!
//! A frame with a done flag is the last of its episode: the env resets after it.
use crate::env::obs::{OBS_DIM, SCAN_DIM};
use crate::robot::NUM_JOINTS;
use crate::terrain::TerrainKind;

use super::DataError;

/// Bytes before the float blocks.
pub const HEADER_BYTES: usize = 80;
const FLAG_TERMINATED: u8 = 1;
const FLAG_TRUNCATED: u8 = 2;

/// Sizes of a frame's float blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Dims {
    pub state: usize,
    pub action: usize,
    pub scan: usize,
}

impl Dims {
    /// The G1 env's: `OBS_DIM`, `NUM_JOINTS`, `SCAN_DIM`.
    pub const G1: Dims = Dims {
        state: OBS_DIM,
        action: NUM_JOINTS,
        scan: SCAN_DIM,
    };

    /// Bytes of one frame message.
    pub const fn frame_bytes(&self) -> usize {
        HEADER_BYTES + 4 * (self.state + self.action + self.scan)
    }
}

impl Default for Dims {
    fn default() -> Self {
        Dims::G1
    }
}

/// One control step of one env.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub episode: u64,
    pub env: u32,
    /// Step index in the episode.
    pub step: u32,
    pub terrain: TerrainKind,
    pub level: u32,
    /// The episode ended in a fall (or blow-up) at this step.
    pub terminated: bool,
    /// The episode was cut (time-out, map edge) at this step.
    pub truncated: bool,
    /// Pelvis position (world).
    pub pos: [f64; 3],
    /// Pelvis orientation `[w, x, y, z]` (world).
    pub quat: [f64; 4],
    pub state: Vec<f32>,
    pub action: Vec<f32>,
    pub scan: Vec<f32>,
}

impl Frame {
    /// The last frame of its episode.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }

    /// A zero frame of these dims (for tests and benchmarks).
    pub fn zeros(dims: Dims) -> Frame {
        Frame {
            episode: 0,
            env: 0,
            step: 0,
            terrain: TerrainKind::Flat,
            level: 0,
            terminated: false,
            truncated: false,
            pos: [0.0; 3],
            quat: [1.0, 0.0, 0.0, 0.0],
            state: vec![0.0; dims.state],
            action: vec![0.0; dims.action],
            scan: vec![0.0; dims.scan],
        }
    }

    /// Append this frame's message bytes to `out` (the kind byte is [`kind_code`]).
    pub fn encode(&self, dims: Dims, out: &mut Vec<u8>) -> Result<(), DataError> {
        for (what, got, want) in [
            ("state", self.state.len(), dims.state),
            ("action", self.action.len(), dims.action),
            ("scandot", self.scan.len(), dims.scan),
        ] {
            if got != want {
                return Err(DataError::FrameShape { what, got, want });
            }
        }
        out.reserve(dims.frame_bytes());
        out.extend_from_slice(&self.episode.to_le_bytes());
        out.extend_from_slice(&self.env.to_le_bytes());
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&self.level.to_le_bytes());
        out.push(kind_code(self.terrain));
        let flags =
            (self.terminated as u8 * FLAG_TERMINATED) | (self.truncated as u8 * FLAG_TRUNCATED);
        out.push(flags);
        out.extend_from_slice(&[0, 0]);
        for v in self.pos.iter().chain(&self.quat) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in self.state.iter().chain(&self.action).chain(&self.scan) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        Ok(())
    }

    /// Decode one message; `kinds` is the shard's terrain-kind table. The error
    /// string says what is wrong (the caller adds the shard and frame index).
    pub fn decode(bytes: &[u8], dims: Dims, kinds: &[TerrainKind]) -> Result<Frame, String> {
        if bytes.len() != dims.frame_bytes() {
            return Err(format!(
                "{} bytes, a frame of ({dims}) has {}",
                bytes.len(),
                dims.frame_bytes()
            ));
        }
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
        let f64_at = |o: usize| f64::from_le_bytes(bytes[o..o + 8].try_into().expect("8 bytes"));
        let code = bytes[20];
        let terrain = *kinds.get(code as usize).ok_or_else(|| {
            format!(
                "terrain kind code {code} outside the shard's table of {}",
                kinds.len()
            )
        })?;
        let flags = bytes[21];
        if flags & !(FLAG_TERMINATED | FLAG_TRUNCATED) != 0 {
            return Err(format!("unknown flag bits {flags:#04x}"));
        }
        let floats = |start: usize, n: usize| -> Vec<f32> {
            bytes[start..start + 4 * n]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect()
        };
        let s0 = HEADER_BYTES;
        let a0 = s0 + 4 * dims.state;
        let c0 = a0 + 4 * dims.action;
        Ok(Frame {
            episode: u64::from_le_bytes(bytes[0..8].try_into().expect("8 bytes")),
            env: u32_at(8),
            step: u32_at(12),
            level: u32_at(16),
            terrain,
            terminated: flags & FLAG_TERMINATED != 0,
            truncated: flags & FLAG_TRUNCATED != 0,
            pos: [f64_at(24), f64_at(32), f64_at(40)],
            quat: [f64_at(48), f64_at(56), f64_at(64), f64_at(72)],
            state: floats(s0, dims.state),
            action: floats(a0, dims.action),
            scan: floats(c0, dims.scan),
        })
    }
}

/// A terrain kind's code: its index in [`TerrainKind::ALL`] (the table every
/// writer stores in its metadata).
pub fn kind_code(kind: TerrainKind) -> u8 {
    TerrainKind::ALL
        .iter()
        .position(|k| *k == kind)
        .expect("every kind is in ALL") as u8
}
