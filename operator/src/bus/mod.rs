//! Where frames go to and come from: a bus URL (`socketcan:can0`, `slcan:/dev/ttyUSB0`, `file:run.log`) and the
//! one small trait every transport implements, so `send` and `monitor` never know which one they talk to.

pub mod logfile;
pub mod relay;
pub mod slcan;
#[cfg(feature = "socketcan")]
pub mod socketcan;

use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{bail, Context, Result};

use crate::frame::{LoggedFrame, RawFrame};

/// What waiting for a frame produced.
#[derive(Debug)]
pub enum Reception {
    /// A frame arrived.
    Frame(LoggedFrame),
    /// The wait ran out with nothing received.
    TimedOut,
    /// The source has no more frames (end of a log file).
    Ended,
    /// The user pressed Ctrl-C.
    Interrupted,
}

/// A CAN bus seen from the operator's computer.
pub trait Bus {
    /// Puts one frame on the bus (or in the log).
    fn send(&mut self, frame: &RawFrame) -> Result<()>;

    /// Waits for the next frame, at most `timeout` (`None`: as long as it takes).
    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception>;

    /// Leaves the bus cleanly (an SLCAN adapter's channel is closed). Called once, at the end.
    fn close(&mut self) -> Result<()> {
        Ok(())
    }
}

/// A parsed `--bus` value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BusUrl {
    /// Linux SocketCAN interface, e.g. `socketcan:can0`.
    SocketCan {
        /// Interface name.
        interface: String,
    },
    /// A serial-line CAN adapter speaking SLCAN (Lawicel), e.g. `slcan:/dev/ttyUSB0@115200`.
    Slcan {
        /// The serial device.
        path: PathBuf,
        /// Serial baud rate; `None` leaves the port's setting alone (USB CDC adapters ignore it).
        baud: Option<u32>,
    },
    /// A candump `-l` log file, e.g. `file:run.log`.
    File {
        /// The log file.
        path: PathBuf,
    },
}

impl BusUrl {
    /// Parses `socketcan:IFACE`, `slcan:PATH[@BAUD]` or `file:PATH`.
    pub fn parse(text: &str) -> Result<Self> {
        let Some((scheme, rest)) = text.split_once(':') else {
            bail!("bus {text:?} has no type: write socketcan:can0, slcan:/dev/ttyUSB0 or file:run.log");
        };
        if rest.is_empty() {
            bail!("bus {text:?} names no {scheme} device");
        }
        match scheme {
            "socketcan" => Ok(Self::SocketCan {
                interface: rest.to_string(),
            }),
            "slcan" => {
                let (path, baud) = match rest.rsplit_once('@') {
                    Some((path, baud_text)) => {
                        let baud = baud_text
                            .parse::<u32>()
                            .ok()
                            .filter(|baud| *baud > 0)
                            .with_context(|| {
                                format!("baud rate {baud_text:?} in {text:?} is not a number")
                            })?;
                        (path, Some(baud))
                    }
                    None => (rest, None),
                };
                Ok(Self::Slcan {
                    path: PathBuf::from(path),
                    baud,
                })
            }
            "file" => Ok(Self::File {
                path: PathBuf::from(rest),
            }),
            other => {
                bail!("unknown bus type {other:?} in {text:?}: use socketcan:, slcan: or file:")
            }
        }
    }
}

impl fmt::Display for BusUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SocketCan { interface } => write!(f, "socketcan:{interface}"),
            Self::Slcan {
                path,
                baud: Some(baud),
            } => write!(f, "slcan:{}@{baud}", path.display()),
            Self::Slcan { path, baud: None } => write!(f, "slcan:{}", path.display()),
            Self::File { path } => write!(f, "file:{}", path.display()),
        }
    }
}

/// How a bus is opened: a log file is read (monitor) or appended to (send).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Frames will be sent.
    Send,
    /// Frames will be received; `realtime` replays a log at the pace it was recorded.
    Receive {
        /// Pace a log file by its timestamps.
        realtime: bool,
    },
}

/// Opens the bus a URL names.
pub fn open(url: &BusUrl, direction: Direction) -> Result<Box<dyn Bus>> {
    let bus: Box<dyn Bus> = match url {
        BusUrl::SocketCan { interface } => open_socketcan(interface)?,
        // Shared: a second `amiro` on the same adapter goes through the first instead of closing its channel.
        BusUrl::Slcan { path, baud } => relay::open_shared(path, *baud)
            .with_context(|| format!("cannot open the SLCAN adapter {url}"))?,
        BusUrl::File { path } => match direction {
            Direction::Send => Box::new(logfile::LogWriter::open(path)?),
            Direction::Receive { realtime } => Box::new(logfile::LogReader::open(path, realtime)?),
        },
    };
    Ok(bus)
}

#[cfg(feature = "socketcan")]
fn open_socketcan(interface: &str) -> Result<Box<dyn Bus>> {
    Ok(Box::new(socketcan::SocketCanBus::open(interface)?))
}

#[cfg(not(feature = "socketcan"))]
fn open_socketcan(interface: &str) -> Result<Box<dyn Bus>> {
    bail!("socketcan:{interface}: this amiro was built without the `socketcan` feature")
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn note_interrupt(_signal: nix::libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Makes Ctrl-C (and SIGTERM) end a wait instead of killing the process, so an SLCAN channel is closed before
/// exit. Without `SA_RESTART`, a blocked `poll` returns `EINTR` and the transports report `Interrupted`.
pub fn catch_interrupts() -> Result<()> {
    use nix::sys::signal::{sigaction, SaFlags, SigAction, SigHandler, SigSet, Signal};
    let action = SigAction::new(
        SigHandler::Handler(note_interrupt),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for signal in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(signal, &action) }.context("cannot install the Ctrl-C handler")?;
    }
    Ok(())
}

/// Whether Ctrl-C has been pressed since `catch_interrupts`.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_urls_parse() {
        assert_eq!(
            BusUrl::parse("socketcan:can0").unwrap(),
            BusUrl::SocketCan {
                interface: "can0".into()
            }
        );
        assert_eq!(
            BusUrl::parse("slcan:/dev/ttyUSB0@115200").unwrap(),
            BusUrl::Slcan {
                path: "/dev/ttyUSB0".into(),
                baud: Some(115_200)
            }
        );
        assert_eq!(
            BusUrl::parse("slcan:/dev/ttyACM0").unwrap(),
            BusUrl::Slcan {
                path: "/dev/ttyACM0".into(),
                baud: None
            }
        );
        assert_eq!(
            BusUrl::parse("file:run.log").unwrap(),
            BusUrl::File {
                path: "run.log".into()
            }
        );
        assert_eq!(
            BusUrl::parse("slcan:/dev/ttyUSB0@115200")
                .unwrap()
                .to_string(),
            "slcan:/dev/ttyUSB0@115200"
        );
    }

    #[test]
    fn bad_bus_urls_are_explained() {
        for bad in [
            "can0",
            "socketcan:",
            "usb:/dev/x",
            "slcan:/dev/ttyUSB0@fast",
            "slcan:/dev/ttyUSB0@0",
        ] {
            assert!(BusUrl::parse(bad).is_err(), "{bad}");
        }
    }
}
