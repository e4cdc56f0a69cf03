//! dreampolicy: the DreamPolicy pipeline (terrain specialists, diffusion world
//! model, unified goal-conditioned policy) for the Unitree G1 on MuJoCo.
//!
//! Module map (kept in sync with the README):
//! * [`sim`] safe MuJoCo layer over our `mujoco-sys` FFI crate
//! * [`robot`] G1 facts: joint order, motors, body sets, scene files
//! * [`terrain`] procedural heightfields: terrain kinds, curriculum map, lanes, PNGs
//! * [`env`] the locomotion env and the batched `VecEnv`
//! * [`eval`] lane evaluation: success and completion rates, tracking error
//! * [`play`] one rollout of a checkpoint written as an MCAP file for Foxglove, or rendered as a video
//! * [`rl`] PPO on libtorch: actor-critic, storage, normalizers, checkpoints, runner
//! * [`config`] serde structs of the YAML experiment files
//! * [`world_model`] the terrain-aware autoregressive diffusion world model: DiT denoiser, DDPM/DDIM, CFG, scheduled-sampling trainer, rollout
//! * [`unified`] the unified policy's parts: body-space kinematics and tracking terms, the diffusion-AMP discriminator, the world model's history and plan buffers
//! * [`data`] the expert dataset: MCAP shards of frames, windows, split, shuffle, stats
//! * [`checkpoint`] checkpoint files shared by the trainers: named tensors + a JSON record, written atomically
//! * [`seal`] SHA-256 seals inside the YAML and JSON files a later run trusts (config.yaml, deploy.yaml, stats.json)
//! * [`run`] run directories (config.yaml, metrics.csv and its TensorBoard event file, log.txt) and progress bars
//! * [`plot`] PNG training curves (a grid of line-chart panels) from a metrics CSV
//! * [`collect`] the expert dataset's collection: specialists rolled out into MCAP shards
//! * [`bench`] the `dreampolicy bench ...` measurements
//! * [`sweep`] config-driven sweeps: sweep files, their runs, the task body, Slurm arrays, collection
//! * [`baselines`] the paper's comparison methods as trainer modes: DAgger distillation, without GCRL, without diffusion
//! * [`benchmark`] the paper's comparison: methods x single, unseen and combined lanes, Wilson intervals, the report
pub mod baselines;
pub mod bench;
pub mod benchmark;
pub mod checkpoint;
pub mod collect;
pub mod config;
pub mod data;
pub mod deploy;
pub mod env;
pub mod eval;
pub mod play;
pub mod plot;
pub mod rl;
pub mod robot;
pub mod run;
pub mod seal;
pub mod sim;
pub mod sweep;
pub mod terrain;
pub mod unified;
pub mod world_model;
