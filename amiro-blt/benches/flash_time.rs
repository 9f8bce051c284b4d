//! Time to flash each board through the simulated robot at 115200 baud, in virtual time, against
//! the serial line's limit (11 520 bytes/s of payload at 8N1). Prints figures; asserts nothing.
//!
//! Uses the release ELFs when `cargo xtask build` has left them in the target directory, and
//! firmware-sized synthetic images otherwise.
#[path = "../tests/common/mod.rs"]
mod common;

use amiro_blt::{Flasher, Image, Options, Transport};
use amiro_blt_sim::Faults;
use common::{firmware, sim_robot, targets, SimLink};
use std::path::PathBuf;

const BAUD: u32 = 115_200;

fn release_elf(name: &str, triple: &str) -> Option<Image> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"));
    let bytes = std::fs::read(dir.join(triple).join("release").join(name)).ok()?;
    Image::from_elf(&bytes).ok()
}

fn main() {
    let line_limit = f64::from(BAUD) / 10.0;
    println!(
        "flashing through the simulated robot at {BAUD} baud (line limit {line_limit:.0} bytes/s)"
    );
    println!(
        "{:<14} {:<9} {:>8} {:>10} {:>10} {:>8}",
        "board", "image", "bytes", "time", "bytes/s", "of line"
    );
    let triples = [
        "thumbv7m-none-eabi",
        "thumbv7em-none-eabihf",
        "thumbv7m-none-eabi",
    ];
    for (i, target) in targets().iter().enumerate() {
        let (image, source) = match release_elf(&target.name, triples[i]) {
            Some(img) => (img, "release"),
            None => (firmware(target, 30_000, i as u32 + 1), "synthetic"),
        };
        let mut flasher = Flasher::new(
            SimLink::new(sim_robot(Faults::default()), BAUD),
            Options::default(),
        );
        flasher.enter_flash_mode(&mut ()).expect("flash mode");
        let start = flasher.link().clock();
        flasher.flash(target, &image, &mut ()).expect("flash");
        let took = flasher.link().clock() - start;
        let rate = image.len() as f64 / took.as_secs_f64();
        println!(
            "{:<14} {:<9} {:>8} {:>9.2}s {:>10.0} {:>7.0}%",
            target.name,
            source,
            image.len(),
            took.as_secs_f64(),
            rate,
            100.0 * rate / line_limit
        );
    }
    println!(
        "(each figure includes erase, programming, the checksum write and the full read-back)"
    );
}
