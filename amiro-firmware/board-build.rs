//! The one build script of every board crate (`build = "../amiro-firmware/board-build.rs"`):
//! writes the linker memory map for the board's chip family (from the target triple) and link
//! (behind AMiRo-BLT by default, feature `bare-chip` or `qemu` otherwise), from
//! `amiro_firmware::layout`; and the board's admission table (`admission_table.rs`, included with
//! `amiro_firmware::admission_table!()`) from the same app sources and timing files
//! `cargo xtask analyze` reads — the build fails when they disagree; and the trace numbers of the
//! board's tasks (`trace_tasks.rs`, included with `amiro_firmware::trace_tasks!()`).
use std::{env, fs, path::PathBuf};

use amiro_firmware::layout::{Family, Link, MemoryMap};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let target = env::var("TARGET").expect("cargo sets TARGET");
    let family = Family::of_target(&target)
        .unwrap_or_else(|| panic!("{target} is not an AMiRo chip target (thumbv7m / thumbv7em)"));
    let link = if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        Link::Qemu
    } else if env::var_os("CARGO_FEATURE_BARE_CHIP").is_some() {
        Link::BareChip
    } else {
        Link::Bootloader
    };
    let mut memory_x = String::new();
    MemoryMap::new(family, link)
        .write_memory_x(&mut memory_x)
        .expect("formatting into a String");
    fs::write(out.join("memory.x"), memory_x).expect("write memory.x");
    let root =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"))
            .join("..");
    // The robot's board revision (the board's `rev-*` feature) selects its timing files
    // (`schedule_analysis::scenario::REVISION_ENV`) for the admission table below. A board revision
    // names its robot's, but LightRing 1-0, which sits on 1-1 robots (docs/boards.md, "Revisions").
    let revision = env::vars().find_map(|(k, _)| {
        k.strip_prefix("CARGO_FEATURE_REV_").map(|r| match r {
            "1_0" => "1-1".to_string(),
            r => r.replace('_', "-"),
        })
    });
    if let Some(revision) = revision {
        env::set_var("AMIRO_REVISION", revision);
    }
    println!("cargo:rerun-if-env-changed=AMIRO_REVISION");
    // A board without `scripted-i2c` links no sensor-bus rounds (`amiro-firmware/sensor-buses`), so its
    // table may state no sensor bus and no script.
    let sensor_buses = env::var_os("CARGO_FEATURE_SCRIPTED_I2C").is_some();
    let table = amiro_firmware::admission::table_source(&root, sensor_buses).unwrap_or_else(|e| {
        panic!("admission table: the apps and the timing files disagree (as `cargo xtask analyze` would say): {e}")
    });
    fs::write(out.join("admission_table.rs"), table).expect("write admission_table.rs");
    let board = env::var("CARGO_PKG_NAME").expect("cargo sets CARGO_PKG_NAME");
    let tasks = amiro_firmware::trace_ids::board_names(&root, &board)
        .unwrap_or_else(|e| panic!("trace task numbers of {board}: {e}"));
    fs::write(
        out.join("trace_tasks.rs"),
        amiro_firmware::trace_ids::rust_source(&tasks),
    )
    .expect("write trace_tasks.rs");
    println!("cargo:rerun-if-changed=../schedule-analysis/models");
    for board in ["diwheeldrive", "powermgmt", "lightring"] {
        println!("cargo:rerun-if-changed=../{board}/src/main.rs");
    }
    println!("cargo:rustc-link-search={}", out.display());
    // The script itself (it lives here, not in the board crate: a `build.rs` there does not exist,
    // and a path that does not exist makes cargo rebuild the board at every invocation).
    println!("cargo:rerun-if-changed=../amiro-firmware/board-build.rs");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    // Identical code folding: functions (and read-only sections) that compile to the same bytes —
    // generic monomorphisations, mostly — are linked once (−0.5 KB on PowerManagement). No firmware
    // code compares function addresses (`--icf=safe` folds nothing here: the fat-LTO object carries
    // no address-significance table).
    println!("cargo:rustc-link-arg-bins=--icf=all");
}
