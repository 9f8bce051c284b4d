//! Every way a frame (or a message about to be encoded) can be wrong, as one `Copy` enum.
//!
//! Firmware keeps one counter per reason: `counters[error.kind_index()] += 1`, with
//! `[u32; DecodeError::KINDS.len()]` as the array and `DecodeError::KINDS[i]` as the counter's name.

use core::fmt;

use crate::id::Kind;
use crate::topic::Topic;

/// Why a frame could not be decoded (or why a message cannot be encoded into a frame that decodes back to it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DecodeError {
    /// The identifier does not fit in 11 bits.
    IdOutOfRange {
        /// The raw identifier received.
        id: u16,
    },
    /// A 29-bit extended identifier: the AMiRo protocol uses standard identifiers only.
    ExtendedId {
        /// The raw extended identifier.
        id: u32,
    },
    /// A remote (RTR) frame: the protocol never requests data that way.
    RemoteFrame,
    /// More than 8 data bytes: not a classic CAN frame.
    FrameTooLong {
        /// Number of bytes given.
        len: usize,
    },
    /// A two-bit priority value above 3 (only from [`crate::Priority::try_from`]).
    BadPriority {
        /// The value given.
        value: u8,
    },
    /// The topic byte names no topic in [`crate::TOPICS`].
    UnknownTopic {
        /// The topic byte (identifier bits 7–0).
        topic: u8,
    },
    /// A sensor-data frame (C/S = 1) on an actuator topic: motors and LEDs never publish.
    SensorDataOnActuator {
        /// The actuator topic.
        topic: Topic,
    },
    /// A sensor-data frame where only commands are accepted ([`crate::decode_command`]).
    ExpectedCommand {
        /// The topic of the data frame.
        topic: Topic,
    },
    /// A sensor command (stop / publish / once) addressed to an actuator topic; only from encoding, the decoder
    /// reads a command frame to an actuator as an actuator command.
    NotASensor {
        /// The actuator topic.
        topic: Topic,
    },
    /// Fewer data bytes than the topic (or the command mode) needs.
    DlcTooShort {
        /// The topic.
        topic: Topic,
        /// Command or sensor-data frame.
        frame: Kind,
        /// The DLC received.
        dlc: u8,
        /// The DLC that would have been right.
        expected: u8,
    },
    /// More data bytes than the topic (or the command mode) allows.
    DlcTooLong {
        /// The topic.
        topic: Topic,
        /// Command or sensor-data frame.
        frame: Kind,
        /// The DLC received.
        dlc: u8,
        /// The DLC that would have been right.
        expected: u8,
    },
    /// Sensor command mode other than 0 (stop), 1 (publish), 2 (once).
    BadMode {
        /// The mode byte (data\[0\]).
        mode: u8,
    },
    /// Sample-time unit other than 0 (ms), 1 (s), 2 (µs).
    BadUnit {
        /// The unit byte (data\[3\]).
        unit: u8,
    },
    /// A publish command with a sample time of zero.
    ZeroSampleTime,
    /// A publish period longer than [`crate::MAX_PERIOD_US`], which the firmware monotonic cannot schedule.
    PeriodTooLong {
        /// The requested period in µs.
        micros: u64,
    },
    /// A period below the limit that no unit (µs, ms, s) carries exactly in 16 bits, such as 65 536 001 µs
    /// (only from [`crate::SampleTime::from_micros`]).
    PeriodNotEncodable {
        /// The requested period in µs.
        micros: u64,
    },
    /// An LED number outside 1..=8.
    LedOutOfRange {
        /// The LED number.
        led: u8,
    },
    /// A proximity-ring sensor index outside 0..=7.
    SensorIndexOutOfRange {
        /// The index byte.
        index: u8,
    },
    /// A power-status charging flag other than 0 or 1.
    BadChargingFlag {
        /// The flag byte.
        value: u8,
    },
    /// A state of charge above 100 %.
    StateOfChargeOutOfRange {
        /// The percentage byte.
        percent: u8,
    },
    /// A page byte (data\[0\]) that names no page of a multi-page topic (diagnostics).
    UnknownPage {
        /// The topic.
        topic: Topic,
        /// The page byte.
        page: u8,
    },
    /// Bits the protocol reserves (must be 0) are set, or a field holds a code it reserves.
    ReservedBits {
        /// The topic.
        topic: Topic,
        /// The data byte that holds them.
        byte: u8,
    },
    /// An admission-policy command with a policy other than 0 (refuse) or 1 (accept and warn).
    BadPolicy {
        /// The policy byte (data\[1\]).
        value: u8,
    },
    /// A shutdown command whose bytes 1–2 are not [`crate::SHUTDOWN_KEY`].
    BadShutdownKey {
        /// The key received.
        key: u16,
    },
    /// A shutdown command with a mode other than 1 (hibernate), 2 (deep sleep), 3 (transportation), 4 (restart).
    BadShutdownMode {
        /// The mode byte (data\[0\]).
        value: u8,
    },
}

/// The reasons' short names and their counter order, from one list: `KINDS` and `kind_index` are
/// generated together, so a name cannot drift from its index.
macro_rules! decode_error_kinds {
    ($($variant:ident => $name:literal,)*) => {
        impl DecodeError {
            /// One short, stable name per variant, in [`DecodeError::kind_index`] order: counter and
            /// log names.
            pub const KINDS: [&'static str; [$($name),*].len()] = [$($name),*];

            /// The index of this error's reason in [`DecodeError::KINDS`] (always below
            /// `KINDS.len()`).
            pub const fn kind_index(&self) -> usize {
                // The variants in list order: their discriminants are the indices.
                enum Index {
                    $($variant),*
                }
                match self {
                    $(DecodeError::$variant { .. } => Index::$variant as usize,)*
                }
            }
        }
    };
}

decode_error_kinds! {
    IdOutOfRange => "id-out-of-range",
    ExtendedId => "extended-id",
    RemoteFrame => "remote-frame",
    FrameTooLong => "frame-too-long",
    BadPriority => "bad-priority",
    UnknownTopic => "unknown-topic",
    SensorDataOnActuator => "sensor-data-on-actuator",
    ExpectedCommand => "expected-command",
    NotASensor => "not-a-sensor",
    DlcTooShort => "dlc-too-short",
    DlcTooLong => "dlc-too-long",
    BadMode => "bad-mode",
    BadUnit => "bad-unit",
    ZeroSampleTime => "zero-sample-time",
    PeriodTooLong => "period-too-long",
    PeriodNotEncodable => "period-not-encodable",
    LedOutOfRange => "led-out-of-range",
    SensorIndexOutOfRange => "sensor-index-out-of-range",
    BadChargingFlag => "bad-charging-flag",
    StateOfChargeOutOfRange => "state-of-charge-out-of-range",
    UnknownPage => "unknown-page",
    ReservedBits => "reserved-bits",
    BadPolicy => "bad-policy",
    BadShutdownMode => "bad-shutdown-mode",
    BadShutdownKey => "bad-shutdown-key",
}

impl DecodeError {
    /// The short name of this error's reason (`KINDS[kind_index()]`).
    pub const fn kind_name(&self) -> &'static str {
        Self::KINDS[self.kind_index()]
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecodeError::IdOutOfRange { id } => {
                write!(f, "identifier 0x{id:X} does not fit in 11 bits")
            }
            DecodeError::ExtendedId { id } => write!(
                f,
                "extended identifier 0x{id:08X}: only standard ids are used"
            ),
            DecodeError::RemoteFrame => {
                f.write_str("remote frame: the protocol uses data frames only")
            }
            DecodeError::FrameTooLong { len } => {
                write!(f, "{len} data bytes: a CAN frame carries at most 8")
            }
            DecodeError::BadPriority { value } => write!(f, "priority {value} is not 0..3"),
            DecodeError::UnknownTopic { topic } => write!(f, "unknown topic 0x{topic:02X}"),
            DecodeError::SensorDataOnActuator { topic } => {
                write!(
                    f,
                    "sensor data on actuator topic {topic}: actuators never publish"
                )
            }
            DecodeError::ExpectedCommand { topic } => {
                write!(f, "{topic} sensor data where a command was expected")
            }
            DecodeError::NotASensor { topic } => {
                write!(f, "{topic} is an actuator: it takes no stop/publish/once")
            }
            DecodeError::DlcTooShort {
                topic,
                frame,
                dlc,
                expected,
            }
            | DecodeError::DlcTooLong {
                topic,
                frame,
                dlc,
                expected,
            } => {
                let how = if matches!(self, DecodeError::DlcTooShort { .. }) {
                    "short"
                } else {
                    "long"
                };
                write!(
                    f,
                    "DLC {dlc} too {how} for {topic} {frame} frame (needs {expected})"
                )
            }
            DecodeError::BadMode { mode } => write!(
                f,
                "bad sensor command mode {mode} (0 stop, 1 publish, 2 once)"
            ),
            DecodeError::BadUnit { unit } => {
                write!(f, "bad sample time unit {unit} (0 ms, 1 s, 2 µs)")
            }
            DecodeError::ZeroSampleTime => f.write_str("sample time of zero"),
            DecodeError::PeriodTooLong { micros } => {
                write!(
                    f,
                    "period of {micros} µs is longer than the {} µs the firmware can schedule",
                    crate::MAX_PERIOD_US
                )
            }
            DecodeError::PeriodNotEncodable { micros } => {
                write!(
                    f,
                    "period of {micros} µs cannot be sent exactly as 16-bit µs, ms or s"
                )
            }
            DecodeError::LedOutOfRange { led } => write!(f, "LED {led} does not exist (1..8)"),
            DecodeError::SensorIndexOutOfRange { index } => {
                write!(f, "proximity-ring sensor {index} does not exist (0..7)")
            }
            DecodeError::BadChargingFlag { value } => {
                write!(f, "charging flag {value} is neither 0 nor 1")
            }
            DecodeError::StateOfChargeOutOfRange { percent } => {
                write!(f, "state of charge {percent} % is above 100 %")
            }
            DecodeError::UnknownPage { topic, page } => {
                write!(f, "{topic} has no page 0x{page:02X}")
            }
            DecodeError::ReservedBits { topic, byte } => {
                write!(f, "reserved bits or codes set in byte {byte} of {topic}")
            }
            DecodeError::BadPolicy { value } => write!(
                f,
                "bad admission policy {value} (0 refuse, 1 accept and warn)"
            ),
            DecodeError::BadShutdownKey { key } => write!(
                f,
                "shutdown key 0x{key:04X} is not 0x{:04X}",
                crate::SHUTDOWN_KEY
            ),
            DecodeError::BadShutdownMode { value } => write!(
                f,
                "bad shutdown mode {value} (1 hibernate, 2 deep sleep, 3 transportation, 4 restart)"
            ),
        }
    }
}

/// Lets hosts use `?` into `anyhow` / `Box<dyn Error>`; `core::error::Error` needs no std.
impl core::error::Error for DecodeError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kind_names_are_unique() {
        for (i, a) in DecodeError::KINDS.iter().enumerate() {
            for b in &DecodeError::KINDS[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }
}
