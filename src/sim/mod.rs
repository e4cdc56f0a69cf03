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
pub mod render;

pub use data::{contact_geoms, Contact, Data, DEFAULT_MAX_QVEL, NUM_WARNINGS};
pub use error::{Instability, SimError};
pub use hfield::HeightField;
pub use model::{HfieldInfo, Model, ObjType};

/// Rotation matrix (row-major, as MuJoCo's `xmat`) of a unit quaternion
/// `(w, x, y, z)`, as MuJoCo's `mju_quat2Mat`.
pub fn quat_to_mat(q: [f64; 4]) -> [f64; 9] {
    let [w, x, y, z] = q;
    [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    ]
}

/// Wrap an angle to [-pi, pi).
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut x = (a + std::f64::consts::PI) % two_pi;
    if x < 0.0 {
        x += two_pi;
    }
    x - std::f64::consts::PI
}

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
