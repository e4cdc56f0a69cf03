//! Autoregressive rollout: a trained world model generates `H` future states
//! per call from the last `K` states and the terrain under the robot, and chains
//! calls, each call's prediction becoming the next call's history.
//!
//! Everything here is in raw (unnormalized) units, the env's state layout. The
//! terrain comes from a [`TerrainSource`]: fixed scandots ([`FixedTerrain`]), or
//! any closure `FnMut(&Tensor, usize) -> Result<Tensor, WmError>` that is given
//! the current `K` states (`[B, K, S]`, newest last) and the call number and
//! returns the scandots `[B, C]` there, or [`super::map_terrain::MapTerrain`],
//! which reads them from a terrain map along the predicted path (the state is
//! invariant to global position and yaw, so it integrates the pose itself from
//! each prediction, given to [`TerrainSource::advance`]).
use std::path::Path;

use tch::{Device, Tensor};

use super::checkpoint::WmCheckpoint;
use super::denoiser::{Denoiser, Normalizer};
use super::sampler::{sample, Noise};
use super::schedule::NoiseSchedule;
use super::WmError;
use crate::world_model::config::{SamplingConfig, WorldModelConfig};

/// Where the scandots of each call come from.
pub trait TerrainSource {
    /// Scandots `[B, C]` (raw) for the call `call` (from 0) whose history is
    /// `states` (`[B, K, S]`, raw, newest last).
    fn scandots(&mut self, states: &Tensor, call: usize) -> Result<Tensor, WmError>;

    /// Called after each call with its prediction `[B, H, S]` (raw), before the
    /// next call's [`TerrainSource::scandots`]: a source that follows the
    /// predicted path moves along it here. Nothing by default.
    fn advance(&mut self, _predicted: &Tensor) -> Result<(), WmError> {
        Ok(())
    }
}

/// The same scandots at every call (`[B, C]` or `[C]`, broadcast to the batch).
pub struct FixedTerrain(pub Tensor);

impl TerrainSource for FixedTerrain {
    fn scandots(&mut self, states: &Tensor, _call: usize) -> Result<Tensor, WmError> {
        let b = states.size()[0];
        let s = if self.0.dim() == 1 {
            self.0.unsqueeze(0)
        } else {
            self.0.shallow_clone()
        };
        let c = s.size()[1];
        Ok(s.expand([b, c], false))
    }
}

impl<F> TerrainSource for F
where
    F: FnMut(&Tensor, usize) -> Result<Tensor, WmError>,
{
    fn scandots(&mut self, states: &Tensor, call: usize) -> Result<Tensor, WmError> {
        self(states, call)
    }
}

/// A trained world model: the EMA denoiser, its normalization, the schedule
/// and the config it was trained with.
pub struct WorldModel {
    pub net: Denoiser,
    pub norm: Normalizer,
    pub sched: NoiseSchedule,
    pub cfg: WorldModelConfig,
}

impl WorldModel {
    /// Assemble one from its parts.
    pub fn new(net: Denoiser, norm: Normalizer, cfg: &WorldModelConfig) -> WorldModel {
        WorldModel {
            net,
            norm,
            sched: NoiseSchedule::new(&cfg.diffusion),
            cfg: cfg.clone(),
        }
    }

    /// The EMA weights of a world-model checkpoint.
    pub fn load(path: &Path, device: Device) -> Result<WorldModel, WmError> {
        WorldModel::from_checkpoint(&WmCheckpoint::read(path)?, device)
    }

    /// The EMA weights of a checkpoint already read.
    pub fn from_checkpoint(ck: &WmCheckpoint, device: Device) -> Result<WorldModel, WmError> {
        let cfg = ck.config()?;
        let d = ck.meta().dims;
        let net = Denoiser::new(&cfg.model, d.state, d.scan, device);
        ck.load_net("ema", &net)?;
        let norm = ck.normalizer(device)?;
        Ok(WorldModel::new(net, norm, &cfg))
    }

    /// `K`.
    pub fn history(&self) -> usize {
        self.cfg.model.history
    }

    /// `H`.
    pub fn horizon(&self) -> usize {
        self.cfg.model.horizon
    }

    /// One call: `[B, H, S]` raw future states from the raw history `[B, K, S]`
    /// and raw scandots `[B, C]`.
    pub fn predict(
        &self,
        history: &Tensor,
        scan: &Tensor,
        sampling: &SamplingConfig,
        noise: &mut Noise,
    ) -> Result<Tensor, WmError> {
        let (s, c) = self.net.dims();
        let hs = history.size();
        if hs.len() != 3 || hs[1] != self.history() as i64 || hs[2] != s as i64 {
            return Err(WmError::Invalid(format!(
                "history must be [B, {}, {s}], got {hs:?}",
                self.history()
            )));
        }
        let ss = scan.size();
        if ss != [hs[0], c as i64] {
            return Err(WmError::Invalid(format!(
                "scandots must be [{}, {c}], got {ss:?}",
                hs[0]
            )));
        }
        let dev = self.net.device();
        let out = tch::no_grad(|| {
            let hist = self.norm.states(&history.to_device(dev));
            let y = self
                .net
                .terrain_embedding(&self.norm.scans(&scan.to_device(dev)));
            let z = sample(&self.net, &self.sched, sampling, &hist, &y, noise);
            self.norm.unstates(&z)
        });
        Ok(out)
    }

    /// Chain calls from the raw history `[B, K, S]` until `frames` future states
    /// are generated: `[B, frames, S]` (the last call's surplus is dropped).
    /// Seeded: the same `seed` gives the same rollout.
    pub fn rollout(
        &self,
        history: &Tensor,
        terrain: &mut dyn TerrainSource,
        frames: usize,
        sampling: &SamplingConfig,
        seed: u64,
    ) -> Result<Tensor, WmError> {
        if frames == 0 {
            let sz = history.size();
            return Ok(Tensor::zeros(
                [sz[0], 0, sz[2]],
                (tch::Kind::Float, history.device()),
            ));
        }
        let mut noise = Noise::new(seed);
        let (k, h) = (self.history() as i64, self.horizon() as i64);
        let mut hist = history.shallow_clone();
        let mut out: Vec<Tensor> = Vec::new();
        let mut made = 0usize;
        let mut call = 0usize;
        while made < frames {
            let scan = terrain.scandots(&hist, call)?;
            let pred = self.predict(&hist, &scan, sampling, &mut noise)?;
            terrain.advance(&pred)?;
            let all = Tensor::cat(&[&hist.to_device(pred.device()), &pred], 1);
            hist = all.narrow(1, h, k);
            out.push(pred);
            made += h as usize;
            call += 1;
        }
        let all = Tensor::cat(&out, 1);
        Ok(all.narrow(1, 0, frames as i64))
    }
}
