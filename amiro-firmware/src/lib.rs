//! The firmware runtime every AMiRo board app is built on.
//!
//! Everything a board does the same way lives here once: the CAN path (one register-level bxCAN
//! driver for the F103 and the F405), the monotonic glue, telemetry (RTT on the robot, semihosting in
//! QEMU), the fault policy hook, the system signals and the AMiRo-BLT hand-over, the generic
//! publisher loop, the independent watchdog, the clock-tree reset, and the QEMU platform. A board
//! crate keeps only its `board.rs` (pins and devices), its sampling and its RTIC app (wiring).
//!
//! The portable core ([`can`], [`bxcan`], [`clock_tree`], [`command_job`], [`i2c_bus`], [`i2c_clear`], [`i2c_engine`], [`i2c_fault`], [`i2c_sim`],
//! [`layout`], [`scripted`], [`spi`], [`timer_monotonic`], [`trace_ring`]) builds and is tested on
//! the host; `admission_search` exists only on the host; the rest only on the chips (`target_os = "none"`). Exactly one chip family feature (`f1`, `f4`)
//! is enabled on a chip build; `qemu` selects the QEMU platform.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod admission;
// The host's search for the admission check's costliest step needs `std` (its sequences, its log's text).
#[cfg(all(not(target_os = "none"), not(test)))]
extern crate std;
#[cfg(not(target_os = "none"))]
pub mod admission_search;
pub mod bxcan;
pub mod can;
pub mod clock_tree;
pub mod command_job;
pub mod digits;
pub mod i2c_bus;
pub mod i2c_clear;
pub mod i2c_engine;
pub mod i2c_fault;
#[cfg(test)]
mod i2c_model;
pub mod i2c_sim;
#[cfg(test)]
mod i2c_tests;
pub mod layout;
pub mod rx_queue;
pub mod scripted;
#[cfg(test)]
mod scripted_tests;
pub mod spi;
#[cfg(test)]
mod test_waker;
pub mod timer_monotonic;
pub mod timer_queue;
pub mod trace_ring;

#[cfg(target_os = "none")]
pub mod bootloader;
#[cfg(target_os = "none")]
pub mod channels;
#[cfg(target_os = "none")]
pub mod chip;
#[cfg(target_os = "none")]
pub mod fault;
#[cfg(target_os = "none")]
pub mod health;
#[cfg(target_os = "none")]
pub mod i2c;
#[cfg(target_os = "none")]
pub mod i2c_block;
#[cfg(target_os = "none")]
pub mod liveness;
#[cfg(target_os = "none")]
pub mod mono;
#[cfg(target_os = "none")]
pub mod publisher;
pub mod publisher_walk;
#[cfg(all(target_os = "none", feature = "qemu"))]
pub mod qemu;
#[cfg(target_os = "none")]
pub mod signals;

#[cfg(target_os = "none")]
pub mod tasks;
#[cfg(target_os = "none")]
pub mod telemetry;
#[cfg(not(target_os = "none"))]
pub mod trace_ids;
#[cfg(target_os = "none")]
pub mod tracing;
#[cfg(target_os = "none")]
pub mod watchdog;

/// The trace numbers of the board's tasks (`pub mod trace_task { pub const CAN_RX: u8 = 0; … }`),
/// written by `board-build.rs` from the app's source into the board crate's `OUT_DIR`
/// (see `trace_ids` on the host, and `tracing` on the chip).
#[macro_export]
macro_rules! trace_tasks {
    () => {
        include!(concat!(env!("OUT_DIR"), "/trace_tasks.rs"));
    };
}

// For `timer_monotonic!` in the board crates.
#[cfg(target_os = "none")]
#[doc(hidden)]
pub use cortex_m as __cortex_m;
#[cfg(target_os = "none")]
#[doc(hidden)]
pub use rtic_time as __rtic_time;

#[cfg(all(target_os = "none", not(any(feature = "f1", feature = "f4"))))]
compile_error!("amiro-firmware: enable the chip family feature `f1` or `f4`");
#[cfg(all(feature = "f1", feature = "f4"))]
compile_error!(
    "amiro-firmware: `f1` and `f4` are exclusive (build one firmware per cargo invocation)"
);
