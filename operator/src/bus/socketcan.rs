//! The `socketcan:` bus: a Linux SocketCAN interface (`can0` on the robot's operator board, `vcan0` for tests).
//!
//! The interface must already be up at the right bitrate (`ip link set can0 up type can bitrate 1000000`);
//! configuring it needs root, and the operator tool should not.

use std::io::ErrorKind;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, ExtendedId, Id, Socket, StandardId};

use super::{interrupted, Bus, Reception};
use crate::frame::{FrameId, LoggedFrame, RawFrame, Timestamp};

/// A raw CAN socket bound to one interface.
pub struct SocketCanBus {
    interface: String,
    socket: CanSocket,
}

impl SocketCanBus {
    /// Opens a raw socket on `interface`.
    pub fn open(interface: &str) -> Result<Self> {
        let socket = CanSocket::open(interface).with_context(|| {
            format!("cannot open SocketCAN interface {interface} (does it exist and is it up? see `ip link`)")
        })?;
        Ok(Self {
            interface: interface.to_string(),
            socket,
        })
    }
}

fn to_socketcan(frame: &RawFrame) -> Option<CanFrame> {
    let id: Id = match frame.id() {
        FrameId::Standard(id) => StandardId::new(id)?.into(),
        FrameId::Extended(id) => ExtendedId::new(id)?.into(),
    };
    if frame.is_remote() {
        CanFrame::new_remote(id, usize::from(frame.len()))
    } else {
        CanFrame::new(id, frame.data())
    }
}

fn from_socketcan(frame: &CanFrame) -> Option<RawFrame> {
    let id = match frame.id() {
        Id::Standard(id) => FrameId::Standard(id.as_raw()),
        Id::Extended(id) => FrameId::Extended(id.as_raw()),
    };
    match frame {
        CanFrame::Data(_) => RawFrame::data_frame(id, frame.data()),
        CanFrame::Remote(_) => RawFrame::remote_frame(id, u8::try_from(frame.dlc()).ok()?),
        CanFrame::Error(_) => None,
    }
}

impl Bus for SocketCanBus {
    fn send(&mut self, frame: &RawFrame) -> Result<()> {
        let can_frame =
            to_socketcan(frame).with_context(|| format!("{frame} cannot be sent on SocketCAN"))?;
        self.socket
            .write_frame_insist(&can_frame)
            .with_context(|| format!("cannot send {frame} on {}", self.interface))
    }

    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
        let deadline = timeout.map(|timeout| Instant::now() + timeout);
        loop {
            if interrupted() {
                return Ok(Reception::Interrupted);
            }
            let result = match deadline {
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(Reception::TimedOut);
                    }
                    self.socket.read_frame_timeout(left)
                }
                None => self.socket.read_frame(),
            };
            let can_frame = match result {
                Ok(can_frame) => can_frame,
                Err(error)
                    if matches!(error.kind(), ErrorKind::Interrupted | ErrorKind::TimedOut) =>
                {
                    continue
                }
                Err(error) => {
                    return Err(error)
                        .with_context(|| format!("cannot read from {}", self.interface))
                }
            };
            match from_socketcan(&can_frame) {
                Some(frame) => {
                    let logged = LoggedFrame {
                        timestamp: Some(Timestamp::now()),
                        interface: Some(self.interface.clone()),
                        frame,
                    };
                    return Ok(Reception::Frame(logged));
                }
                None => eprintln!("warning: {}: error frame {can_frame:?}", self.interface),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_compact;

    #[test]
    fn frames_convert_both_ways() {
        for text in ["205#01840302", "605#", "1234ABCD#FF", "205#R4"] {
            let frame = parse_compact(text).unwrap();
            let can_frame = to_socketcan(&frame).unwrap();
            assert_eq!(from_socketcan(&can_frame), Some(frame), "{text}");
        }
    }
}
