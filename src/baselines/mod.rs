//! The paper's comparison methods that are not DreamPolicy itself (appendix,
//! "Detailed Implementation of Baselines"), each a trainer mode over the code
//! the main pipeline already has:
//! * [`dagger`]: the distillation baseline: one student with the specialists'
//!   observation interface trained online on the mixed terrain map by
//!   supervision from the specialist of the terrain each env stands on
//!   (`train dagger`);
//! * [`no_gcrl`]: the ablation without goal-conditioned RL: the world model's
//!   predicted next state holds the action executed (`train no-gcrl` writes
//!   the controller, `eval` runs it);
//! * [`no_diffusion`]: the ablation without the diffusion world model: PPO
//!   with a standard AMP discriminator on the expert dataset's transitions
//!   (`train no-diffusion`).
pub mod dagger;
pub mod no_diffusion;
pub mod no_gcrl;
