//! The robot's boards as `cargo xtask robot`, its benchmark and its scenarios run them: each
//! board's QEMU build of the robot's revision.
use std::path::Path;

use amiro_robot::{stimulus, Firmware};
use anyhow::{Context, Result};

/// The robot revision `cargo xtask robot` emulates.
pub const ROBOT_REVISION: &str = "1-1";

/// Builds the boards' QEMU builds (one cargo invocation each) in node order.
pub fn firmware(root: &Path) -> Result<[Firmware; 3]> {
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
        out.push(Firmware {
            elf: crate::workspace::build_qemu(root, &build)?,
            machine: board.qemu_machine,
        });
    }
    out.try_into()
        .map_err(|_| anyhow::anyhow!("three boards expected"))
}
