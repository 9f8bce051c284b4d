//! Picks the linker memory map: behind AMiRo-BLT by default (`memory.x`), the whole chip with feature `bare-chip`,
//! the QEMU machine's map with feature `qemu`.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let layout = if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        "memory-qemu.x"
    } else if env::var_os("CARGO_FEATURE_BARE_CHIP").is_some() {
        "memory-bare.x"
    } else {
        "memory.x"
    };
    fs::copy(layout, out.join("memory.x")).expect("copy memory map");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={layout}");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
