//! Host side of the AMiRo-BLT bootloader: flash every board of an assembled AMiRo through the one
//! serial port that is reachable (DiWheelDrive's), as the C tool SerialBoot does.
//!
//! The crate has no I/O of its own. [`frame`] is SerialBoot's framing, [`xcp`] the XCP commands and
//! replies as AMiRo-BLT defines them, [`gateway`] the CAN forwarding a main board does for the
//! modules behind it, [`identify`] how the robot's revision is learnt from the main board's own
//! bootloader, [`image`] the image a board receives, [`target`] the boards and their
//! flash layouts, and [`session`] the state machine that drives all of it over a [`Transport`]
//! (read with a timeout, write, optional reset line). A serial port, a pty or a simulated robot in
//! virtual time are thin adapters around that trait. The protocol facts and every decision taken
//! where the bootloader is silent are in `docs/flashing.md`.
#![deny(missing_docs)]

pub mod error;
pub mod frame;
pub mod gateway;
pub mod identify;
pub mod image;
pub mod session;
pub mod target;
pub mod transport;
pub mod xcp;

pub use error::Error;
pub use identify::{Identification, MainBoardId};
pub use image::{Image, Segment};
pub use session::{Event, Flasher, Observer, Options, Phase, RestartOutcome};
pub use target::{Chip, IdSet, Target};
pub use transport::Transport;
