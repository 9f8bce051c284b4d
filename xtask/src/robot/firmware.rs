//! The robot's boards as `cargo xtask robot`, its benchmark and its scenarios run them: each
//! board's QEMU build of the robot's revision.
use std::path::Path;

use amiro_robot::{stimulus, Firmware};
use anyhow::{Context, Result};

/// The robot revision `cargo xtask robot` emulates.
pub const ROBOT_REVISION: &str = "1-1";

/// Builds the boards' QEMU builds (one cargo invocation each) in node order.
pub fn firmware(root: &Path) -> Result<[Firmware; 3]> {
    firmware_with(root, &[])
}

/// [`firmware`] with trial features the shipped images do not enable: a `board/feature` (e.g.
/// `powermgmt/scripted-i2c`) for that board alone, a plain `feature` for each board whose manifest
/// declares it.
pub fn firmware_with(root: &Path, extra: &[&str]) -> Result<[Firmware; 3]> {
    let mut out = Vec::new();
    for name in stimulus::BOARDS {
        let board = crate::boards::by_name(name).with_context(|| format!("no board {name}"))?;
        // The robot runs revision 1-1 (DiWheelDrive 1-1 with its L3G4200D, LIS331DLH and HMC5883L; the
        // robot scenarios' thesis demo is not schedulable on DiWheelDrive 1-2's BNO055, docs/analysis.md).
        let build =
            crate::revision::plan(&[board], &crate::revision::Choice::Robot(ROBOT_REVISION))?
                .into_iter()
                .next()
                .with_context(|| format!("no revision-{ROBOT_REVISION} image of {name}"))?;
        let manifest = std::fs::read_to_string(root.join(name).join("Cargo.toml"))
            .with_context(|| format!("reading {name}'s Cargo.toml"))?;
        let declared: Vec<&str> = extra
            .iter()
            .filter_map(|f| match f.split_once('/') {
                Some((board, feature)) => (board == name).then_some(feature),
                None => manifest
                    .lines()
                    .any(|l| l.starts_with(&format!("{f} =")))
                    .then_some(*f),
            })
            .collect();
        out.push(Firmware {
            elf: crate::workspace::build_qemu_with(root, &build, &declared)?,
            machine: board.qemu_machine,
        });
    }
    out.try_into()
        .map_err(|_| anyhow::anyhow!("three boards expected"))
}
