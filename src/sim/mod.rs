//! Safe MuJoCo: [`Model`] and [`Data`] own their pointers, load errors carry
//! MuJoCo's text, unstable states become [`SimError::Unstable`], heightfields can
//! be written at run time and sampled in Rust ([`HeightField`]).
//!
//! `unsafe` lives here and in `mujoco-sys` only; every block says why it is sound.
mod data;
mod error;
pub mod handlers;
mod hfield;
pub mod hfield_contact;
mod model;

pub use data::{contact_geoms, Contact, Data, DEFAULT_MAX_QVEL, NUM_WARNINGS};
pub use error::{Instability, SimError};
pub use hfield::HeightField;
pub use model::{HfieldInfo, Model, ObjType};

/// Version of the linked libmujoco, e.g. "2.2.2".
pub fn mujoco_version() -> String {
    // SAFETY: mj_versionString returns a static NUL-terminated string.
    let p = unsafe { mujoco_sys::mj_versionString() };
    if p.is_null() {
        return format!("{}", mujoco_sys::MUJOCO_VERSION_HEADER);
    }
    // SAFETY: non-null static C string.
    unsafe { std::ffi::CStr::from_ptr(p) }
        .to_string_lossy()
        .into_owned()
}
