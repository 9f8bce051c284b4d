//! `cargo xtask robot`: the whole robot in emulation. The host side (board processes, the exchange,
//! the bus report, the SLCAN port) is the `amiro-robot` library; here are the command
//! ([`cli`]: builds the boards' QEMU builds, runs, prints), its benchmark (`bench`) and the
//! robot's CI scenarios ([`scenarios`]).
pub mod bench;
pub mod cli;
pub mod firmware;
pub mod scenarios;
pub mod world_scenario;
