//! Bakes the library directories of libmujoco (from mujoco-sys) and libtorch
//! (from torch-sys) into the rpath of every binary and test of this package, so
//! nothing needs LD_LIBRARY_PATH. Re-exports mujoco-sys' `cfg(mujoco_v3)`.
fn main() {
    println!("cargo:rustc-check-cfg=cfg(mujoco_v3)");
    for key in ["DEP_MUJOCO_LIB_DIR", "DEP_TCH_LIBTORCH_LIB"] {
        if let Ok(dir) = std::env::var(key) {
            println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
        }
    }
    // libtorch version for `dreampolicy info`, from the version.py beside its lib/.
    let torch_version = std::env::var("DEP_TCH_LIBTORCH_LIB")
        .ok()
        .and_then(|lib| {
            std::fs::read_to_string(std::path::Path::new(&lib).join("../version.py")).ok()
        })
        .and_then(|text| {
            text.lines().find_map(|l| {
                l.strip_prefix("__version__ = ")
                    .map(|v| v.trim_matches(['\'', '"']).to_string())
            })
        })
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=DREAMPOLICY_LIBTORCH_VERSION={torch_version}");
    let version: u32 = std::env::var("DEP_MUJOCO_VERSION")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    if version >= 300 {
        println!("cargo:rustc-cfg=mujoco_v3");
    }
}
