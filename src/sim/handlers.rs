//! MuJoCo's process-wide error and warning callbacks.
//!
//! MuJoCo's default error handler prints and calls `exit()`, and its warnings go
//! to stdout and a file. We install, once per process:
//! * an error handler that prints MuJoCo's message with context and aborts: MuJoCo
//!   cannot continue after `mju_error` (its callers assume it never returns), and
//!   unwinding a Rust panic through C frames is undefined behaviour. Load errors do
//!   not come through here: `mj_loadXML` reports them in its error buffer, and
//!   [`super::Model`] turns those into `SimError::Load`.
//! * a warning handler that counts every warning and keeps the last message.
//!   Per-`Data` warnings (bad qacc, contact overflow, ...) are also counted by
//!   [`super::Data`] from `mjData.warning`.
//!
//! The same `Once` installs the heightfield surface contacts
//! ([`super::hfield_contact`]) into MuJoCo's collision table.
use std::ffi::{c_char, CStr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, Once};

static INSTALL: Once = Once::new();
static WARNINGS: AtomicU64 = AtomicU64::new(0);
/// The last warning's text, truncated to a fixed buffer: the handler runs inside
/// `mj_step` and must not allocate.
static LAST_WARNING: Mutex<([u8; 256], usize)> = Mutex::new(([0; 256], 0));

fn message(msg: *const c_char) -> String {
    if msg.is_null() {
        return String::from("(no message)");
    }
    // SAFETY: MuJoCo passes a NUL-terminated string that lives for the call.
    unsafe { CStr::from_ptr(msg) }
        .to_string_lossy()
        .into_owned()
}

extern "C" fn on_error(msg: *const c_char) {
    eprintln!(
        "dreampolicy: MuJoCo fatal error: {}\n\
         dreampolicy: MuJoCo cannot continue after an error; aborting the process.",
        message(msg)
    );
    std::process::abort();
}

extern "C" fn on_warning(msg: *const c_char) {
    WARNINGS.fetch_add(1, Ordering::Relaxed);
    if msg.is_null() {
        return;
    }
    // SAFETY: MuJoCo passes a NUL-terminated string that lives for the call.
    let bytes = unsafe { CStr::from_ptr(msg) }.to_bytes();
    if let Ok(mut last) = LAST_WARNING.lock() {
        let n = bytes.len().min(last.0.len());
        last.0[..n].copy_from_slice(&bytes[..n]);
        last.1 = n;
    }
}

/// Install the handlers (idempotent; every `Model` constructor calls it).
pub fn install() {
    INSTALL.call_once(|| {
        // SAFETY: plain writes of two function pointers that MuJoCo reads when it
        // reports; done once, before any model exists in this process.
        unsafe {
            mujoco_sys::mju_user_error = Some(on_error);
            mujoco_sys::mju_user_warning = Some(on_warning);
        }
        super::hfield_contact::install();
    });
}

/// Number of MuJoCo warnings reported through `mju_warning` in this process.
pub fn warning_count() -> u64 {
    WARNINGS.load(Ordering::Relaxed)
}

/// The text of the most recent MuJoCo warning (at most 256 bytes), if any.
pub fn last_warning() -> Option<String> {
    let last = LAST_WARNING.lock().ok()?;
    (last.1 > 0).then(|| String::from_utf8_lossy(&last.0[..last.1]).into_owned())
}
