//! The unified policy's parts (the paper's stage 3, issue 19), built on the
//! trainer we have:
//! * [`fk`]: heading-frame kinematics of the tracked bodies, from a (predicted)
//!   state or from a simulated robot;
//! * [`track`]: the four body-space tracking terms against the plan's next state;
//! * [`amp`]: the online diffusion-AMP discriminator and its style reward;
//! * [`plan`]: the world model's history buffer and the shifted plan between
//!   re-plans.
pub mod amp;
pub mod fk;
pub mod plan;
pub mod track;
