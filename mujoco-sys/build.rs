//! Finds a MuJoCo build, runs bindgen over its headers and links it.
//!
//! * `MUJOCO_DIR=<dir>`: `<dir>/include/mujoco/mujoco.h` and
//!   `<dir>/lib/libmujoco.so[.X.Y.Z]`. A library that only exists under its
//!   versioned name (the PyPI wheel ships `libmujoco.so.3.3.7`) is linked with
//!   a verbatim name. The workspace's `.cargo/config.toml` sets it to the
//!   MuJoCo 3.3.7 that `scripts/setup.sh` unpacks: that is the default build.
//! * `MUJOCO_DIR=system` (or unset): Debian 12's `libmujoco-dev` (MuJoCo 2.2.2):
//!   headers in `/usr/include/mujoco`, library in the multiarch lib dir.
//!
//! Emits `cfg(mujoco_v3)` for 3.x headers and, through `links = "mujoco"`,
//! `DEP_MUJOCO_LIB_DIR` / `DEP_MUJOCO_VERSION` for dependents' build scripts
//! (which put the lib dir into their rpath).
use std::path::{Path, PathBuf};

fn main() {
    println!("cargo:rerun-if-env-changed=MUJOCO_DIR");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-check-cfg=cfg(mujoco_v3)");

    let (include_dir, lib_dir) = match std::env::var_os("MUJOCO_DIR").filter(|d| d != "system") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            (dir.join("include"), dir.join("lib"))
        }
        None => (
            PathBuf::from("/usr/include"),
            debian_lib_dir().unwrap_or_else(|| {
                panic!(
                    "libmujoco not found: install Debian's libmujoco-dev (scripts/setup.sh) \
                     or set MUJOCO_DIR=<dir with include/ and lib/>"
                )
            }),
        ),
    };
    let header = include_dir.join("mujoco").join("mujoco.h");
    if !header.exists() {
        panic!(
            "{} not found: run scripts/setup.sh (it unpacks MuJoCo 3.3.7 into third_party/), \
             set MUJOCO_DIR=system for Debian's libmujoco-dev, or point MUJOCO_DIR at a MuJoCo build",
            header.display()
        );
    }
    println!("cargo:rerun-if-changed={}", header.display());
    let version = read_version(&header);

    // Link: plain libmujoco.so if present, else the versioned file, verbatim.
    let lib_name = find_library(&lib_dir).unwrap_or_else(|| {
        panic!("no libmujoco.so* in {}", lib_dir.display());
    });
    println!("cargo:rustc-link-search=native={}", lib_dir.display());
    if lib_name == "libmujoco.so" {
        println!("cargo:rustc-link-lib=dylib=mujoco");
    } else {
        println!("cargo:rustc-link-lib=dylib:+verbatim={lib_name}");
    }
    // rpath for this crate's own tests; dependents add theirs from DEP_MUJOCO_LIB_DIR.
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
    println!("cargo:lib_dir={}", lib_dir.display());
    println!("cargo:version={version}");
    println!("cargo:rustc-env=MUJOCO_SYS_LIB_DIR={}", lib_dir.display());
    if version >= 300 {
        println!("cargo:rustc-cfg=mujoco_v3");
    }

    let bindings = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .clang_arg(format!("-I{}", include_dir.display()))
        .allowlist_function("mj_.*")
        .allowlist_function("mju_.*")
        .allowlist_type("mj.*")
        .allowlist_var("mjVERSION_HEADER")
        .allowlist_var("mju_user_.*")
        // the pairwise collision table (dreampolicy::sim::hfield_contact replaces two entries)
        .allowlist_var("mjCOLLISIONFUNC")
        .allowlist_var(
            "mjNEQDATA|mjNDYN|mjNGAIN|mjNBIAS|mjNREF|mjNIMP|mjNSOLVER|mjMINVAL|mjMAXCONPAIR",
        )
        // The offscreen renderer's calls (dreampolicy::sim::render); the rest of
        // the UI and render API, and MJAPI's variadic printing helpers, are not needed.
        .allowlist_function(
            "mjv_defaultCamera|mjv_defaultOption|mjv_defaultScene|mjv_makeScene|mjv_freeScene\
             |mjv_updateScene|mjr_defaultContext|mjr_makeContext|mjr_freeContext|mjr_setBuffer\
             |mjr_render|mjr_readPixels",
        )
        .blocklist_function("mjui_.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false)
        .generate_comments(false)
        .parse_callbacks(Box::new(bindgen::CargoCallbacks::new()))
        .generate()
        .expect("bindgen failed over the MuJoCo headers");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap()).join("bindings.rs");
    bindings.write_to_file(&out).expect("write bindings.rs");
}

fn debian_lib_dir() -> Option<PathBuf> {
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let candidates = [
        format!("/usr/lib/{arch}-linux-gnu"),
        "/usr/lib".to_string(),
        "/usr/local/lib".to_string(),
    ];
    candidates
        .into_iter()
        .map(PathBuf::from)
        .find(|d| find_library(d).is_some())
}

fn find_library(dir: &Path) -> Option<String> {
    if dir.join("libmujoco.so").exists() {
        return Some("libmujoco.so".into());
    }
    let mut versioned: Vec<String> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("libmujoco.so."))
        .collect();
    versioned.sort();
    versioned.pop()
}

fn read_version(header: &Path) -> u32 {
    let text = std::fs::read_to_string(header).expect("read mujoco.h");
    text.lines()
        .find_map(|l| {
            let rest = l.trim().strip_prefix("#define mjVERSION_HEADER")?;
            rest.trim().parse().ok()
        })
        .unwrap_or_else(|| panic!("no mjVERSION_HEADER in {}", header.display()))
}
