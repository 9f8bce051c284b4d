//! Everything that can go wrong while flashing, each with what the user can do about it.
use std::io;
use std::time::Duration;

use crate::xcp::ErrorCode;

/// A flashing failure.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The main board never answered CONNECT.
    #[error(
        "no answer from the main board's bootloader in {waited:?}: it listens only for 500 ms \
         after a reset. Check the cable is on DiWheelDrive's programming port, then press the \
         robot's reset button (or wire RTS to reset and pass --reset-line) and run again"
    )]
    NoAnswer {
        /// How long the host kept asking.
        waited: Duration,
    },
    /// A board selected through the gateway never answered.
    #[error(
        "{board} (device id {id:#010x}) does not answer: is it in the robot, and is it of the \
         revision its main board's bootloader (or --ids) names? The main board now waits for it \
         forever: reset the robot (it stays in its bootloaders) and run again"
    )]
    NoAnswerFromBoard {
        /// Board name.
        board: String,
        /// The id the CONNECT carried.
        id: u32,
    },
    /// The board that answered cannot be the one the image is for.
    #[error(
        "wrong board answering for {board} (device id {id:#010x}): {found}. Nothing was erased; \
         check which board carries which id (--ids) and that the cable is on the right port"
    )]
    WrongBoard {
        /// Board name.
        board: String,
        /// The id the CONNECT carried.
        id: u32,
        /// What the answering board showed.
        found: String,
    },
    /// The image does not start at the application origin (a bare-chip build).
    #[error(
        "{board}: the image starts at {start:#010x}, not at the application origin {origin:#010x} \
         behind AMiRo-BLT (a --bare-chip build?). Nothing was erased; rebuild without bare-chip"
    )]
    NotLinkedForBootloader {
        /// Board name.
        board: String,
        /// The image's lowest address.
        start: u32,
        /// Where the bootloader starts applications.
        origin: u32,
    },
    /// The image does not fit between the application origin and the end of flash.
    #[error("{board}: the image spans {size} bytes but the application region holds {available}; nothing was erased")]
    ImageTooLarge {
        /// Board name.
        board: String,
        /// Bytes from the origin to the image's end.
        size: u64,
        /// Bytes from the origin to the end of flash.
        available: u64,
    },
    /// The image itself is malformed.
    #[error("unusable image: {0}")]
    BadImage(String),
    /// The bootloader refused a command.
    #[error("{board}: the bootloader answered {command} with {code}: {}", code.advice())]
    Xcp {
        /// Board name.
        board: String,
        /// The refused command.
        command: &'static str,
        /// Its error code.
        code: ErrorCode,
    },
    /// The link went quiet or garbled in the middle of an image and retries did not help.
    #[error(
        "lost the connection to {board} after {written} of {total} bytes ({reason}). The board \
         stays in its bootloader with no valid application; reset the robot and run again to \
         finish it"
    )]
    LostConnection {
        /// Board name.
        board: String,
        /// Bytes programmed before the loss.
        written: usize,
        /// Bytes in the image.
        total: usize,
        /// What the last attempt saw.
        reason: String,
    },
    /// The read-back differed from the image.
    #[error(
        "{board}: verification found {found:#04x} at {address:#010x} where the image has \
         {expected:#04x}; the application was invalidated, so the board stays in its \
         bootloader: run again"
    )]
    VerifyFailed {
        /// Board name.
        board: String,
        /// First differing address.
        address: u32,
        /// The image's byte.
        expected: u8,
        /// The flash's byte.
        found: u8,
    },
    /// The serial port failed.
    #[error("serial port: {0}")]
    Io(#[from] io::Error),
}
