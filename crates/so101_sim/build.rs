//! Generates Rust bindings for Debian's MuJoCo 2.2.2 C API (libmujoco-dev) at build time, so no
//! third-party header text is committed and the bindings always match the installed library.

use std::{env, path::PathBuf};

const HEADER: &str = "/usr/include/mujoco/mujoco.h";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={HEADER}");
    println!("cargo:rustc-link-lib=dylib=mujoco");
    if !std::path::Path::new(HEADER).exists() {
        panic!("{HEADER} not found: install Debian's libmujoco-dev (scripts/setup.sh does this)");
    }
    let bindings = bindgen::Builder::default()
        .header(HEADER)
        .allowlist_function("mj.*")
        .allowlist_type("mj.*")
        .allowlist_var("mj.*")
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false)
        .generate()
        .expect("bindgen could not read the MuJoCo headers");
    let out =
        PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("mujoco_bindings.rs");
    bindings
        .write_to_file(out)
        .expect("cannot write the MuJoCo bindings");
}
