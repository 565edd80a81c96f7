//! Linker set-up for the firmware binary, only when building for a bare-metal target.
//!
//! On the host (`cargo build --workspace`, `cargo test --workspace`) this script does
//! nothing, so host builds never see `link.x` or `defmt.x`. For `thumbv7em-none-eabihf`
//! it copies the workspace's `memory.x` (the budget of the real part: the link fails if
//! the firmware outgrows it) into `OUT_DIR` and passes the cortex-m-rt and defmt linker
//! scripts to the binary only.

use std::{env, fs, path::PathBuf};

fn main() {
    // Note(unwrap): cargo always sets CARGO_MANIFEST_DIR for a build script.
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let memory_x = manifest_dir.join("..").join("memory.x");
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");

    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }

    // Note(unwrap): cargo always sets OUT_DIR for a build script.
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("set by cargo"));
    // Note(unwrap): a missing or unwritable memory.x must fail the build, with the path.
    let contents =
        fs::read(&memory_x).unwrap_or_else(|e| panic!("cannot read {}: {e}", memory_x.display()));
    fs::write(out.join("memory.x"), contents).expect("write memory.x into OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());

    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
