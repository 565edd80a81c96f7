//! Linker set-up for the firmware binaries, only when building for a bare-metal target.
//!
//! On the host (`cargo build --workspace`, `cargo test --workspace`) this script does
//! nothing, so host builds never see `link.x` or `defmt.x`. For `thumbv7em-none-eabihf`
//! it puts the selected board's memory layout into `OUT_DIR` (the budget of the real
//! part: the link fails if the firmware outgrows it) and passes the cortex-m-rt and defmt
//! linker scripts to the binaries only. The layouts:
//!
//! * `mps2-an386`: the workspace's `memory.x` (1 MiB flash at 0, 128 KiB RAM), included
//!   by cortex-m-rt's `link.x`;
//! * `f405`: `boards/f405/memory-f405.x` (the STM32F405RG: 1 MiB flash at 0x0800_0000,
//!   128 KiB SRAM at 0x2000_0000; not QEMU's 192 KiB, and no CCM), included by
//!   `boards/f405/link-f405.x`, cortex-m-rt's `link.x` with that one name changed: the
//!   linker runs in the workspace root and finds an INCLUDEd `memory.x` there first, so
//!   a board's layout cannot be another file of that name (see the script's header).

use std::{env, fs, path::PathBuf};

fn main() {
    // Note(unwrap): cargo always sets CARGO_MANIFEST_DIR for a build script.
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let f405 = manifest_dir.join("boards").join("f405");
    // The scripts copied into OUT_DIR, and the top-level one passed with -T.
    let (scripts, link_x) = if env::var_os("CARGO_FEATURE_F405").is_some() {
        let memory = f405.join("memory-f405.x");
        (vec![memory, f405.join("link-f405.x")], "link-f405.x")
    } else {
        (vec![manifest_dir.join("..").join("memory.x")], "link.x")
    };
    for script in &scripts {
        println!("cargo:rerun-if-changed={}", script.display());
    }
    println!("cargo:rerun-if-changed=build.rs");

    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }

    // Note(unwrap): cargo always sets OUT_DIR for a build script.
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("set by cargo"));
    for script in &scripts {
        // Note(unwrap): a missing or unwritable script must fail the build, with the path.
        let contents =
            fs::read(script).unwrap_or_else(|e| panic!("cannot read {}: {e}", script.display()));
        let name = script.file_name().expect("a file");
        fs::write(out.join(name), contents).expect("write the linker script into OUT_DIR");
    }
    println!("cargo:rustc-link-search={}", out.display());

    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-T{link_x}");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
