//! Whole frames: the `Message` type, `decode`, `decode_command` and `Message::encode`.

use core::fmt;

use crate::command::Command;
use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::{CanId, Kind, Priority};
use crate::payload::SensorData;
use crate::topic::Topic;

/// Any valid frame of the protocol, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Message {
    /// A command (C/S = 0).
    Command(Command),
    /// Sensor data (C/S = 1).
    Sample {
        /// The frame's priority (the priority of the command that started the publisher).
        priority: Priority,
        /// The values.
        data: SensorData,
    },
}

impl Message {
    /// The frame's priority bits.
    pub const fn priority(&self) -> Priority {
        match self {
            Message::Command(c) => c.priority(),
            Message::Sample { priority, .. } => *priority,
        }
    }

    /// Command or sensor data.
    pub const fn kind(&self) -> Kind {
        match self {
            Message::Command(_) => Kind::Command,
            Message::Sample { .. } => Kind::Sensor,
        }
    }

    /// The topic (an LED command with an LED outside 1..=8 has none: the error says why).
    pub const fn topic(&self) -> Result<Topic, DecodeError> {
        match self {
            Message::Command(c) => c.topic(),
            Message::Sample { data, .. } => Ok(data.topic()),
        }
    }

    /// The frame. Never fails; out-of-range fields give a frame the decoder rejects.
    pub fn encode(&self) -> Frame {
        match self {
            Message::Command(c) => c.encode(),
            Message::Sample { priority, data } => data.encode(*priority),
        }
    }

    /// Checks every field the decoder checks.
    pub const fn validate(&self) -> Result<(), DecodeError> {
        match self {
            Message::Command(c) => c.validate(),
            Message::Sample { data, .. } => data.validate(),
        }
    }

    /// The frame, or the reason a receiver would reject it; `decode` of the frame gives this message back.
    pub fn try_encode(&self) -> Result<Frame, DecodeError> {
        self.validate()?;
        Ok(self.encode())
    }
}

impl From<Command> for Message {
    fn from(command: Command) -> Message {
        Message::Command(command)
    }
}

impl fmt::Display for Message {
    /// `medium command: publish magnetometer-x every 900 µs`, `high gyroscope x=-4 y=30 z=5 dps`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Message::Command(c) => write!(f, "{c}"),
            Message::Sample { priority, data } => write!(f, "{priority} {data}"),
        }
    }
}

/// The identifier and topic of a frame, checked: 11 bits, at most 8 bytes, known topic.
fn split(id: u16, data: &[u8]) -> Result<(CanId, Topic), DecodeError> {
    let id = CanId::try_from(id)?;
    if data.len() > 8 {
        return Err(DecodeError::FrameTooLong { len: data.len() });
    }
    Ok((id, Topic::try_from(id.topic_byte())?))
}

/// Decodes any frame: a command to a sensor topic is a [`crate::SensorCommand`], to the motor or an LED an actuator
/// command; a sensor-data frame is [`Message::Sample`], except on an actuator topic
/// ([`DecodeError::SensorDataOnActuator`]). Never panics, for any `id` and any `data`.
pub fn decode(id: u16, data: &[u8]) -> Result<Message, DecodeError> {
    let (id, topic) = split(id, data)?;
    match id.kind() {
        Kind::Command => Command::decode(topic, id.priority(), data).map(Message::Command),
        Kind::Sensor => SensorData::decode(topic, data).map(|data| Message::Sample {
            priority: id.priority(),
            data,
        }),
    }
}

/// Decodes a frame that must be a command (what a board's command handler accepts); sensor data is
/// [`DecodeError::ExpectedCommand`].
pub fn decode_command(id: u16, data: &[u8]) -> Result<Command, DecodeError> {
    let (id, topic) = split(id, data)?;
    match id.kind() {
        Kind::Command => Command::decode(topic, id.priority(), data),
        Kind::Sensor => Err(DecodeError::ExpectedCommand { topic }),
    }
}
