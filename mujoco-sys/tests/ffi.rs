//! The FFI crate links the library its headers describe, and the raw API works.
use std::ffi::{CStr, CString};

#[test]
fn header_and_library_versions_agree() {
    // SAFETY: mj_version takes no arguments and returns an int.
    let lib = unsafe { mujoco_sys::mj_version() };
    assert_eq!(lib, mujoco_sys::MUJOCO_VERSION_HEADER);
}

#[test]
fn raw_load_step_and_free() {
    let dir = std::env::temp_dir().join(format!("mujoco-sys-ffi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ball.xml");
    std::fs::write(
        &path,
        r#"<mujoco><worldbody><body pos="0 0 1"><freejoint/><geom type="sphere" size="0.1"/></body></worldbody></mujoco>"#,
    )
    .unwrap();
    let cpath = CString::new(path.to_str().unwrap()).unwrap();
    let mut err = [0i8; 500];
    // SAFETY: valid C string, NULL VFS, 500-byte error buffer; pointers checked below.
    unsafe {
        let m =
            mujoco_sys::mj_loadXML(cpath.as_ptr(), std::ptr::null(), err.as_mut_ptr() as _, 500);
        assert!(!m.is_null(), "{:?}", CStr::from_ptr(err.as_ptr() as _));
        assert_eq!((*m).nq, 7);
        let d = mujoco_sys::mj_makeData(m);
        assert!(!d.is_null());
        for _ in 0..100 {
            mujoco_sys::mj_step(m, d);
        }
        // free fall for 100 steps of the default 2 ms: z = 1 - g t^2 / 2 (semi-implicit Euler)
        let z = *(*d).qpos.add(2);
        let t = (*d).time;
        assert!((t - 0.2).abs() < 1e-9);
        assert!((z - (1.0 - 0.5 * 9.81 * t * t)).abs() < 0.01, "z = {z}");
        mujoco_sys::mj_deleteData(d);
        mujoco_sys::mj_deleteModel(m);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
