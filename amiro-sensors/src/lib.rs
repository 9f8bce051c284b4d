//! AMiRo sensor and actuator drivers, and the board-independent sensor-data handler.
//!
//! Everything here is hardware-free: drivers are generic over embedded-hal 1.0 traits, the handler
//! runs under any [`clock::Clock`]. The board apps only wire these to the chip.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod clock;
pub mod drivers;
pub mod handler;
pub mod motion;
pub mod script;
pub mod sim;
pub mod trace;
pub mod tx_queue;
