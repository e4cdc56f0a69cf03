//! The unified policy's parts (the paper's stage 3, issue 19), built on the
//! trainer we have:
//! * [`fk`]: heading-frame kinematics of the tracked bodies, from a (predicted)
//!   state or from a simulated robot;
//! * [`track`]: the four body-space tracking terms against the plan's next state;
//! * [`amp`]: the online diffusion-AMP discriminator and its style reward;
//! * [`plan`]: the world model's history buffer and the shifted plan between
//!   re-plans;
//! * [`config`]: the `unified:` section of a `task: unified` config;
//! * [`task`]: [`task::UnifiedTask`], the env with the world model in the loop
//!   as a `VecTask`, and [`train`], `train unified`.
pub mod amp;
pub mod config;
pub mod export;
pub mod fk;
pub mod plan;
pub mod task;
pub mod track;

use std::path::Path;

use crate::rl::config::ExperimentConfig;
use crate::rl::runner::{train_task, TrainSummary};
use crate::rl::RlError;

/// Train the unified policy of `cfg` (`task: unified`) in `run_dir`, fresh or
/// resumed: the same run directory, metrics, checkpoints and resume as
/// `train specialist`, the discriminator saved in the checkpoint.
pub fn train(
    cfg: &ExperimentConfig,
    run_dir: &Path,
    resume: bool,
    quiet: bool,
) -> Result<TrainSummary, RlError> {
    // the task plans with the world model as it starts: on the run's thread
    // count already, or its first plans differ from a resumed run's
    tch::set_num_threads(cfg.train.torch_threads as i32);
    let mut task = task::UnifiedTask::new(cfg)?;
    if task.cfg.plan != config::PlanSource::WorldModel {
        return Err(RlError::Invalid(
            "unified.plan=hold is an inference ablation for eval and play; \
             training plans with the world model (remove the key)"
                .into(),
        ));
    }
    train_task(cfg, &mut task, run_dir, resume, quiet)
}
