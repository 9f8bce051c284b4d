//! Worst-case response-time analysis of the AMiRo board tasks and the CAN bus, end to end.
//!
//! One analysis, two layers around it:
//!
//! * the **core** — [`time`], [`busy_window`], [`board`], [`can`], [`board_analysis`], [`bus_analysis`],
//!   [`suspension_analysis`] (the sensor buses' rounds) and [`admission`] — is `no_std` and allocation-free (build with `--no-default-features`).
//!   [`board_analysis::analyse`] analyses one board and [`bus_analysis::analyse`] the bus, for the report and for
//!   the chip alike; [`admission`] is the check a board runs with them before it starts a publisher, on a table
//!   [`admission_host`] lowers from the same apps and timing files;
//! * the **host layer** (feature `std`, on by default) reads models ([`model`]), the generated bounds files
//!   ([`bounds`]), RTIC apps ([`rtic_source`]), timing files and scenarios ([`scenario`]), runs the whole system ([`analysis`]: names, ceilings and overheads
//!   around the core's board and bus analyses, then the end-to-end paths; [`sensor_bus`]: jobs that suspend on a
//!   sensor bus; [`sensitivity`]) and renders the report
//!   ([`report`]); [`rng`] is the deterministic generator of its randomised experiments (benchmark sets,
//!   `cargo xtask campaign`, the admission-cost search). `cargo xtask analyze` is a thin front end over it.
//!
//! docs/analysis.md documents the model format, the equations and how to read the report.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod admission;
pub mod board;
pub mod board_analysis;
pub mod bus_analysis;
pub mod busy_window;
pub mod can;
pub mod suspension_analysis;
pub mod time;

#[cfg(feature = "std")]
#[cfg(feature = "std")]
pub mod admission_host;
#[cfg(feature = "std")]
pub mod analysis;
#[cfg(feature = "std")]
pub mod bounds;
#[cfg(feature = "std")]
pub mod model;
#[cfg(feature = "std")]
pub mod report;
#[cfg(feature = "std")]
pub mod rng;
#[cfg(feature = "std")]
pub mod rtic_source;
#[cfg(feature = "std")]
pub mod scenario;
#[cfg(feature = "std")]
pub mod sensitivity;
#[cfg(feature = "std")]
pub mod sensor_bus;

pub use busy_window::{AnalysisError, Limits, Response};
pub use time::Time;
