//! A simulated AMiRo in its AMiRo-BLT bootloaders, for testing a flashing host without a robot.
//!
//! Written from the bootloader's public sources (`xcp.c`, `can.c`, `flash.c`, `Boot/main.c`) and
//! the facts in `docs/flashing.md`, never from the `amiro-blt` host code, so the two can disagree
//! and a test catch it. [`Robot`] is the whole robot in virtual time (nanoseconds): the main
//! board's UART receiver and gateway, the CAN link with its stop-and-wait acknowledgements, the
//! modules behind it and each board's [`flash::Flash`]. [`pty`] serves a robot on a
//! pseudo-terminal in real time, so a real serial-port client can flash it.
#![deny(missing_docs)]

pub mod flash;
pub mod pty;
pub mod robot;

pub use flash::{Flash, IdInCode, SimChip};
pub use robot::{BoardSpec, Faults, Mode, Nak, Robot, Timing};
