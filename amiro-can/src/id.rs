//! The 11-bit standard identifier: command/sensor bit, priority and topic byte.
//!
//! Layout (bit 10 is the most significant bit of the identifier):
//!
//! ```text
//!  10 | 9 8      | 7 ... 0
//! C/S | priority | topic byte
//! ```
//!
//! A lower identifier wins CAN arbitration, so commands (C/S = 0) beat sensor data and urgent (0) beats low (3).

use core::fmt;

use crate::error::DecodeError;

/// Whether a frame is a command to a topic or data published by a topic (identifier bit 10).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Kind {
    /// C/S = 0: a command from the operator to a sensor or actuator; wins arbitration over sensor data.
    Command = 0,
    /// C/S = 1: sensor (status) data published by a board.
    Sensor = 1,
}

impl Kind {
    /// The lower-case English name (`command`, `sensor`).
    pub const fn name(self) -> &'static str {
        match self {
            Kind::Command => "command",
            Kind::Sensor => "sensor",
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The two priority bits of an identifier (bits 9–8). Lower is more urgent.
///
/// A sensor command's priority becomes the priority of the frames its publisher sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Priority {
    /// 0: wins arbitration against everything else of the same kind.
    Urgent = 0,
    /// 1.
    High = 1,
    /// 2 ("normal" in the thesis's worked example).
    Medium = 2,
    /// 3: loses arbitration against everything else of the same kind.
    Low = 3,
}

impl Priority {
    /// All priorities, most urgent first.
    pub const ALL: [Priority; 4] = [
        Priority::Urgent,
        Priority::High,
        Priority::Medium,
        Priority::Low,
    ];

    /// The two-bit wire value.
    pub const fn bits(self) -> u8 {
        self as u8
    }

    /// The priority from its two low bits; higher bits are ignored (this is how the identifier is split).
    pub const fn from_bits_truncate(bits: u8) -> Priority {
        match bits & 0b11 {
            0 => Priority::Urgent,
            1 => Priority::High,
            2 => Priority::Medium,
            _ => Priority::Low,
        }
    }

    /// The lower-case English name (`urgent`, `high`, `medium`, `low`).
    pub const fn name(self) -> &'static str {
        match self {
            Priority::Urgent => "urgent",
            Priority::High => "high",
            Priority::Medium => "medium",
            Priority::Low => "low",
        }
    }

    /// The priority with this name (as printed by [`Priority::name`]), case-insensitive. `normal` is accepted for
    /// medium, as the thesis calls it.
    pub fn from_name(name: &str) -> Option<Priority> {
        let is = |s: &str| name.eq_ignore_ascii_case(s);
        if is("urgent") {
            Some(Priority::Urgent)
        } else if is("high") {
            Some(Priority::High)
        } else if is("medium") || is("normal") {
            Some(Priority::Medium)
        } else if is("low") {
            Some(Priority::Low)
        } else {
            None
        }
    }
}

impl TryFrom<u8> for Priority {
    type Error = DecodeError;

    fn try_from(value: u8) -> Result<Self, Self::Error> {
        if value <= 3 {
            Ok(Priority::from_bits_truncate(value))
        } else {
            Err(DecodeError::BadPriority { value })
        }
    }
}

impl fmt::Display for Priority {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A validated 11-bit standard CAN identifier in the AMiRo layout.
///
/// Every 11-bit value is a legal `CanId`; whether its topic byte names a known [`crate::Topic`] is checked by the
/// decoder, so an identifier of a topic this crate does not know can still be carried and printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CanId(u16);

impl CanId {
    /// The largest standard identifier (11 bits).
    pub const MAX_RAW: u16 = 0x7FF;

    /// Builds the identifier from its three fields; cannot fail, every combination fits in 11 bits.
    pub const fn new(kind: Kind, priority: Priority, topic_byte: u8) -> CanId {
        CanId(((kind as u16) << 10) | ((priority as u16) << 8) | topic_byte as u16)
    }

    /// The raw 11-bit identifier.
    pub const fn raw(self) -> u16 {
        self.0
    }

    /// Command or sensor data (bit 10).
    pub const fn kind(self) -> Kind {
        if self.0 & 0x400 == 0 {
            Kind::Command
        } else {
            Kind::Sensor
        }
    }

    /// The priority bits (9–8).
    pub const fn priority(self) -> Priority {
        Priority::from_bits_truncate((self.0 >> 8) as u8)
    }

    /// The topic byte (bits 7–0), which may or may not name a known topic.
    pub const fn topic_byte(self) -> u8 {
        (self.0 & 0xFF) as u8
    }

    /// The same topic and priority with the other kind: a publisher answers a command `0x205` with `0x605`.
    pub const fn with_kind(self, kind: Kind) -> CanId {
        CanId::new(kind, self.priority(), self.topic_byte())
    }
}

impl TryFrom<u16> for CanId {
    type Error = DecodeError;

    fn try_from(raw: u16) -> Result<Self, Self::Error> {
        if raw <= Self::MAX_RAW {
            Ok(CanId(raw))
        } else {
            Err(DecodeError::IdOutOfRange { id: raw })
        }
    }
}

impl From<CanId> for u16 {
    fn from(id: CanId) -> u16 {
        id.raw()
    }
}

impl fmt::Display for CanId {
    /// Three hex digits, as can-utils print a standard identifier (`205`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:03X}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_identifier_fields() {
        let id = CanId::try_from(0x205).unwrap();
        assert_eq!(id.kind(), Kind::Command);
        assert_eq!(id.priority(), Priority::Medium);
        assert_eq!(id.topic_byte(), 0x05);
        assert_eq!(id.with_kind(Kind::Sensor).raw(), 0x605);
        assert_eq!(CanId::new(Kind::Command, Priority::Medium, 0x05), id);
    }

    #[test]
    fn every_raw_identifier_round_trips() {
        for raw in 0..=0x7FFu16 {
            let id = CanId::try_from(raw).unwrap();
            assert_eq!(
                CanId::new(id.kind(), id.priority(), id.topic_byte()).raw(),
                raw
            );
        }
        assert_eq!(
            CanId::try_from(0x800),
            Err(DecodeError::IdOutOfRange { id: 0x800 })
        );
        assert_eq!(
            CanId::try_from(u16::MAX),
            Err(DecodeError::IdOutOfRange { id: u16::MAX })
        );
    }

    #[test]
    fn lower_identifier_wins_so_commands_and_urgent_come_first() {
        let urgent_cmd = CanId::new(Kind::Command, Priority::Urgent, 0xFF);
        let low_cmd = CanId::new(Kind::Command, Priority::Low, 0x00);
        let urgent_data = CanId::new(Kind::Sensor, Priority::Urgent, 0x00);
        assert!(urgent_cmd.raw() < low_cmd.raw());
        assert!(low_cmd.raw() < urgent_data.raw());
    }

    #[test]
    fn priority_conversions() {
        for p in Priority::ALL {
            assert_eq!(Priority::try_from(p.bits()), Ok(p));
            assert_eq!(Priority::from_name(p.name()), Some(p));
        }
        assert_eq!(
            Priority::try_from(4),
            Err(DecodeError::BadPriority { value: 4 })
        );
        assert_eq!(Priority::from_name("NORMAL"), Some(Priority::Medium));
        assert_eq!(Priority::from_name("fast"), None);
    }
}
