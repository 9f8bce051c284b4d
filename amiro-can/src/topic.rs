//! The topics of the robot and the one table that describes them (owner, payload, DLC, default period).
//!
//! `docs/protocol.md` shows the same table; `tests/protocol_doc.rs` fails when the two disagree.

use core::fmt;

use crate::error::DecodeError;

/// The pattern of the eight LED topics, for the `match`es that treat them alike (one list, kept
/// exhaustive by the compiler wherever it is used).
macro_rules! led_topics {
    () => {
        $crate::topic::Topic::Led1
            | $crate::topic::Topic::Led2
            | $crate::topic::Topic::Led3
            | $crate::topic::Topic::Led4
            | $crate::topic::Topic::Led5
            | $crate::topic::Topic::Led6
            | $crate::topic::Topic::Led7
            | $crate::topic::Topic::Led8
    };
}
pub(crate) use led_topics;

/// The board that owns a topic: it publishes the sensor, or it drives the actuator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Board {
    /// The bottom board: motors, encoders, gyroscope, accelerometer, magnetometer, floor sensors (STM32F103).
    DiWheelDrive,
    /// The middle board: batteries, fuel gauge and the proximity ring (STM32F405).
    PowerManagement,
    /// The top board: eight RGB LEDs (STM32F103).
    LightRing,
}

impl Board {
    /// All boards, bottom to top.
    pub const ALL: [Board; 3] = [
        Board::DiWheelDrive,
        Board::PowerManagement,
        Board::LightRing,
    ];

    /// The board's diagnostics topic (`0x1A` DiWheelDrive, `0x1B` PowerManagement, `0x1C` LightRing): its health
    /// counters as a sensor topic, and the admission verdicts and admission-policy command.
    pub const fn diagnostics_topic(self) -> Topic {
        match self {
            Board::DiWheelDrive => Topic::DiWheelDriveDiagnostics,
            Board::PowerManagement => Topic::PowerManagementDiagnostics,
            Board::LightRing => Topic::LightRingDiagnostics,
        }
    }

    /// The board's name as the AMiRo project spells it (`DiWheelDrive`, `PowerManagement`, `LightRing`).
    pub const fn name(self) -> &'static str {
        match self {
            Board::DiWheelDrive => "DiWheelDrive",
            Board::PowerManagement => "PowerManagement",
            Board::LightRing => "LightRing",
        }
    }
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A known topic: the low byte of the identifier. Only values in this enum pass the decoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Topic {
    /// Dead-reckoning position and heading (DiWheelDrive).
    Odometry = 0x01,
    /// Measured forward and angular velocity (DiWheelDrive).
    Velocity = 0x02,
    /// The four floor-facing VCNL4020 sensors (DiWheelDrive). ID fixed by the thesis.
    FloorProximity = 0x04,
    /// Magnetometer x axis (DiWheelDrive). ID fixed by the thesis.
    MagnetometerX = 0x05,
    /// Magnetometer y axis (DiWheelDrive). ID fixed by the thesis.
    MagnetometerY = 0x06,
    /// Magnetometer z axis (DiWheelDrive). ID fixed by the thesis.
    MagnetometerZ = 0x07,
    /// Three-axis gyroscope (DiWheelDrive). ID fixed by the thesis.
    Gyroscope = 0x08,
    /// Three-axis accelerometer (DiWheelDrive).
    Accelerometer = 0x09,
    /// Target velocity for the differential drive (DiWheelDrive, actuator).
    MotorCommand = 0x10,
    /// LED 1 of the light ring (actuator).
    Led1 = 0x11,
    /// LED 2 of the light ring (actuator).
    Led2 = 0x12,
    /// LED 3 of the light ring (actuator).
    Led3 = 0x13,
    /// LED 4 of the light ring (actuator).
    Led4 = 0x14,
    /// LED 5 of the light ring (actuator).
    Led5 = 0x15,
    /// LED 6 of the light ring (actuator).
    Led6 = 0x16,
    /// LED 7 of the light ring (actuator).
    Led7 = 0x17,
    /// LED 8 of the light ring (actuator).
    Led8 = 0x18,
    /// DiWheelDrive's health: command, receive, transmit and deadline counters, faults, uptime (six pages).
    DiWheelDriveDiagnostics = 0x1A,
    /// PowerManagement's health (the same six pages as every diagnostics topic).
    PowerManagementDiagnostics = 0x1B,
    /// LightRing's health (the same six pages as every diagnostics topic).
    LightRingDiagnostics = 0x1C,
    /// Shut the robot down (PowerManagement, actuator): hibernate, deep sleep, transportation or restart.
    Shutdown = 0x1D,
    /// Charging flag, state of charge, time left, power (PowerManagement). ID fixed by the thesis.
    PowerStatus = 0x1E,
    /// The eight proximity-ring sensors, one frame each (PowerManagement). ID fixed by the thesis.
    ProximityRing = 0x1F,
}

/// Number of known topics.
pub const TOPIC_COUNT: usize = 23;

impl Topic {
    /// Every topic in identifier order (the order of [`TOPICS`]).
    pub const ALL: [Topic; TOPIC_COUNT] = [
        Topic::Odometry,
        Topic::Velocity,
        Topic::FloorProximity,
        Topic::MagnetometerX,
        Topic::MagnetometerY,
        Topic::MagnetometerZ,
        Topic::Gyroscope,
        Topic::Accelerometer,
        Topic::MotorCommand,
        Topic::Led1,
        Topic::Led2,
        Topic::Led3,
        Topic::Led4,
        Topic::Led5,
        Topic::Led6,
        Topic::Led7,
        Topic::Led8,
        Topic::DiWheelDriveDiagnostics,
        Topic::PowerManagementDiagnostics,
        Topic::LightRingDiagnostics,
        Topic::Shutdown,
        Topic::PowerStatus,
        Topic::ProximityRing,
    ];

    /// The topic byte (identifier bits 7–0).
    pub const fn byte(self) -> u8 {
        self as u8
    }

    /// Position of this topic in [`Topic::ALL`] and [`TOPICS`]; a dense index for per-topic arrays.
    pub const fn index(self) -> usize {
        match self {
            Topic::Odometry => 0,
            Topic::Velocity => 1,
            Topic::FloorProximity => 2,
            Topic::MagnetometerX => 3,
            Topic::MagnetometerY => 4,
            Topic::MagnetometerZ => 5,
            Topic::Gyroscope => 6,
            Topic::Accelerometer => 7,
            Topic::MotorCommand => 8,
            Topic::Led1 => 9,
            Topic::Led2 => 10,
            Topic::Led3 => 11,
            Topic::Led4 => 12,
            Topic::Led5 => 13,
            Topic::Led6 => 14,
            Topic::Led7 => 15,
            Topic::Led8 => 16,
            Topic::DiWheelDriveDiagnostics => 17,
            Topic::PowerManagementDiagnostics => 18,
            Topic::LightRingDiagnostics => 19,
            Topic::Shutdown => 20,
            Topic::PowerStatus => 21,
            Topic::ProximityRing => 22,
        }
    }

    /// The topic with this byte, if it is a known one.
    pub const fn from_byte(byte: u8) -> Option<Topic> {
        Some(match byte {
            0x01 => Topic::Odometry,
            0x02 => Topic::Velocity,
            0x04 => Topic::FloorProximity,
            0x05 => Topic::MagnetometerX,
            0x06 => Topic::MagnetometerY,
            0x07 => Topic::MagnetometerZ,
            0x08 => Topic::Gyroscope,
            0x09 => Topic::Accelerometer,
            0x10 => Topic::MotorCommand,
            0x11 => Topic::Led1,
            0x12 => Topic::Led2,
            0x13 => Topic::Led3,
            0x14 => Topic::Led4,
            0x15 => Topic::Led5,
            0x16 => Topic::Led6,
            0x17 => Topic::Led7,
            0x18 => Topic::Led8,
            0x1A => Topic::DiWheelDriveDiagnostics,
            0x1B => Topic::PowerManagementDiagnostics,
            0x1C => Topic::LightRingDiagnostics,
            0x1D => Topic::Shutdown,
            0x1E => Topic::PowerStatus,
            0x1F => Topic::ProximityRing,
            _ => return None,
        })
    }

    /// This topic's row of [`TOPICS`].
    pub const fn info(self) -> &'static TopicInfo {
        // `index()` is below TOPIC_COUNT for every variant, and the const check below proves the table order.
        &TOPIC_TABLE[self.index()]
    }

    /// The topic's command-line name (`magnetometer-x`, `led-3`, ...).
    pub const fn name(self) -> &'static str {
        self.info().name
    }

    /// The topic with this name, as printed by [`Topic::name`] (case-insensitive).
    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(name))
    }

    /// The owning board.
    pub const fn board(self) -> Board {
        WIRE[self.index()].board
    }

    /// True for topics a board publishes, false for actuators (motor, LEDs).
    pub const fn is_sensor(self) -> bool {
        WIRE[self.index()].is_sensor
    }

    /// The exact DLC of a data frame (sensors) or of a command frame (actuators): `info().dlc`, without
    /// linking the topic table's strings into a firmware image.
    pub const fn dlc(self) -> u8 {
        WIRE[self.index()].dlc
    }

    /// Frames per sample: `info().frames_per_sample`, without the table's strings.
    pub const fn frames_per_sample(self) -> u8 {
        WIRE[self.index()].frames_per_sample
    }

    /// The default period in µs (0 for actuators): `info().default_period_us`, without the table's strings.
    pub const fn default_period_us(self) -> u32 {
        WIRE[self.index()].default_period_us
    }

    /// The identifier of a command to this topic at `priority` (C/S = 0).
    pub const fn command_id(self, priority: crate::Priority) -> crate::CanId {
        crate::CanId::new(crate::Kind::Command, priority, self as u8)
    }

    /// The identifier of this topic's data at `priority` (C/S = 1).
    pub const fn data_id(self, priority: crate::Priority) -> crate::CanId {
        crate::CanId::new(crate::Kind::Sensor, priority, self as u8)
    }

    /// The LED number 1..=8 for an LED topic.
    pub const fn led_number(self) -> Option<u8> {
        match self {
            led_topics!() => Some(self as u8 - Topic::Led1 as u8 + 1),
            _ => None,
        }
    }

    /// The board whose diagnostics topic this is, or `None` for any other topic.
    pub const fn diagnostics_of(self) -> Option<Board> {
        match self {
            Topic::DiWheelDriveDiagnostics => Some(Board::DiWheelDrive),
            Topic::PowerManagementDiagnostics => Some(Board::PowerManagement),
            Topic::LightRingDiagnostics => Some(Board::LightRing),
            _ => None,
        }
    }

    /// The topic of LED `led` (1..=8).
    pub const fn led(led: u8) -> Option<Topic> {
        if led >= 1 && led <= 8 {
            Topic::from_byte(Topic::Led1 as u8 + led - 1)
        } else {
            None
        }
    }
}

impl TryFrom<u8> for Topic {
    type Error = DecodeError;

    fn try_from(byte: u8) -> Result<Self, Self::Error> {
        Topic::from_byte(byte).ok_or(DecodeError::UnknownTopic { topic: byte })
    }
}

impl From<Topic> for u8 {
    fn from(topic: Topic) -> u8 {
        topic as u8
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One row of the topic table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicInfo {
    /// The topic.
    pub topic: Topic,
    /// Command-line name, lower case with dashes.
    pub name: &'static str,
    /// The board that publishes (sensor) or acts on (actuator) this topic.
    pub board: Board,
    /// Sensor (published with C/S = 1 after a sensor command) or actuator (only ever commanded).
    pub is_sensor: bool,
    /// The payload layout in words: field, wire type, unit. For actuators, the command payload.
    pub layout: &'static str,
    /// Frames that make up one sample (8 for the proximity ring, 1 otherwise; 1 command frame for actuators).
    pub frames_per_sample: u8,
    /// The exact DLC of a data frame (sensors) or of a command frame (actuators).
    pub dlc: u8,
    /// The period the board's sensor naturally runs at, in µs, as a suggestion for operators and the default
    /// schedule scenario; 0 for actuators. A mode-1 command without a sample time still means
    /// [`crate::SampleTime::DEFAULT`] (50 ms) for every topic, as the thesis fixes.
    pub default_period_us: u32,
}

impl TopicInfo {
    /// The default period as a sample time, `None` for actuators.
    pub fn default_sample_time(&self) -> Option<crate::SampleTime> {
        crate::SampleTime::from_micros(u64::from(self.default_period_us)).ok()
    }
}

const fn sensor(
    topic: Topic,
    name: &'static str,
    board: Board,
    layout: &'static str,
    frames_per_sample: u8,
    dlc: u8,
    default_period_us: u32,
) -> TopicInfo {
    TopicInfo {
        topic,
        name,
        board,
        is_sensor: true,
        layout,
        frames_per_sample,
        dlc,
        default_period_us,
    }
}

const fn actuator(
    topic: Topic,
    name: &'static str,
    board: Board,
    layout: &'static str,
    dlc: u8,
) -> TopicInfo {
    TopicInfo {
        topic,
        name,
        board,
        is_sensor: false,
        layout,
        frames_per_sample: 1,
        dlc,
        default_period_us: 0,
    }
}

const LED_LAYOUT: &str = "r u8, g u8, b u8";
const DIAGNOSTICS_LAYOUT: &str =
    "page u8 (0..5 health, 0x80/0x81 admission verdict), 7 bytes by page (see Diagnostics)";
/// Diagnostics are a health signal, not a control input: once a second is plenty.
const DIAGNOSTICS_PERIOD_US: u32 = 1_000_000;

const TOPIC_ROWS: [TopicInfo; TOPIC_COUNT] = [
    sensor(
        Topic::Odometry,
        "odometry",
        Board::DiWheelDrive,
        "x i24 (100 µm), y i24 (100 µm), heading u16 (1/65536 turn)",
        1,
        8,
        50_000,
    ),
    sensor(
        Topic::Velocity,
        "velocity",
        Board::DiWheelDrive,
        "forward i32 (µm/s), angular i32 (µrad/s)",
        1,
        8,
        10_000,
    ),
    sensor(
        Topic::FloorProximity,
        "floor-proximity",
        Board::DiWheelDrive,
        "sensor 1..4 u16 (raw proximity counts)",
        1,
        8,
        62_500,
    ),
    sensor(
        Topic::MagnetometerX,
        "magnetometer-x",
        Board::DiWheelDrive,
        "x i32 (nT)",
        1,
        4,
        62_500,
    ),
    sensor(
        Topic::MagnetometerY,
        "magnetometer-y",
        Board::DiWheelDrive,
        "y i32 (nT)",
        1,
        4,
        62_500,
    ),
    sensor(
        Topic::MagnetometerZ,
        "magnetometer-z",
        Board::DiWheelDrive,
        "z i32 (nT)",
        1,
        4,
        62_500,
    ),
    sensor(
        Topic::Gyroscope,
        "gyroscope",
        Board::DiWheelDrive,
        "x i16, y i16, z i16 (dps)",
        1,
        6,
        10_000,
    ),
    sensor(
        Topic::Accelerometer,
        "accelerometer",
        Board::DiWheelDrive,
        "x i16, y i16, z i16 (milli-g)",
        1,
        6,
        62_500,
    ),
    actuator(
        Topic::MotorCommand,
        "motor",
        Board::DiWheelDrive,
        "forward i32 (µm/s), angular i32 (µrad/s)",
        8,
    ),
    actuator(Topic::Led1, "led-1", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led2, "led-2", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led3, "led-3", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led4, "led-4", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led5, "led-5", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led6, "led-6", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led7, "led-7", Board::LightRing, LED_LAYOUT, 3),
    actuator(Topic::Led8, "led-8", Board::LightRing, LED_LAYOUT, 3),
    sensor(
        Topic::DiWheelDriveDiagnostics,
        "diwheeldrive-diagnostics",
        Board::DiWheelDrive,
        DIAGNOSTICS_LAYOUT,
        crate::diagnostics::PAGES_PER_SAMPLE,
        8,
        DIAGNOSTICS_PERIOD_US,
    ),
    sensor(
        Topic::PowerManagementDiagnostics,
        "powermanagement-diagnostics",
        Board::PowerManagement,
        DIAGNOSTICS_LAYOUT,
        crate::diagnostics::PAGES_PER_SAMPLE,
        8,
        DIAGNOSTICS_PERIOD_US,
    ),
    sensor(
        Topic::LightRingDiagnostics,
        "lightring-diagnostics",
        Board::LightRing,
        DIAGNOSTICS_LAYOUT,
        crate::diagnostics::PAGES_PER_SAMPLE,
        8,
        DIAGNOSTICS_PERIOD_US,
    ),
    actuator(
        Topic::Shutdown,
        "shutdown",
        Board::PowerManagement,
        "mode u8 (1 hibernate, 2 deep sleep, 3 transportation, 4 restart), key u16 (0xAA55)",
        3,
    ),
    sensor(
        Topic::PowerStatus,
        "power-status",
        Board::PowerManagement,
        "charging u8 (0/1), state of charge u8 (%), time left u16 (min), power u16 (mW)",
        1,
        6,
        1_000_000,
    ),
    sensor(
        Topic::ProximityRing,
        "proximity-ring",
        Board::PowerManagement,
        "sensor index u8 (0..7), distance u16 (mm)",
        8,
        3,
        62_500,
    ),
];

/// The one topic table, in identifier order. Everything else (DLC checks, names, the docs) derives from it.
pub static TOPICS: &[TopicInfo] = &TOPIC_TABLE;

static TOPIC_TABLE: [TopicInfo; TOPIC_COUNT] = TOPIC_ROWS;

/// What a board needs of a topic on the wire, without the names and layouts (the operator's): the firmware
/// reads only this table, so its images do not carry the strings of [`TOPICS`].
#[derive(Clone, Copy)]
struct Wire {
    board: Board,
    is_sensor: bool,
    frames_per_sample: u8,
    dlc: u8,
    default_period_us: u32,
}

static WIRE: [Wire; TOPIC_COUNT] = {
    let mut wire = [Wire {
        board: Board::DiWheelDrive,
        is_sensor: false,
        frames_per_sample: 0,
        dlc: 0,
        default_period_us: 0,
    }; TOPIC_COUNT];
    let mut i = 0;
    while i < TOPIC_COUNT {
        let row = &TOPIC_ROWS[i];
        wire[i] = Wire {
            board: row.board,
            is_sensor: row.is_sensor,
            frames_per_sample: row.frames_per_sample,
            dlc: row.dlc,
            default_period_us: row.default_period_us,
        };
        i += 1;
    }
    wire
};

// The table must list the topics in the order of `Topic::ALL`/`Topic::index`, or `Topic::info` would return the
// wrong row; checked when the crate compiles.
const _: () = {
    let mut i = 0;
    while i < TOPIC_COUNT {
        assert!(TOPIC_TABLE[i].topic as u8 == Topic::ALL[i] as u8);
        assert!(Topic::ALL[i].index() == i);
        assert!(TOPIC_TABLE[i].dlc <= 8);
        // A diagnostics topic belongs to the board it describes.
        if let Some(board) = Topic::ALL[i].diagnostics_of() {
            assert!(TOPIC_TABLE[i].board as u8 == board as u8);
            assert!(board.diagnostics_topic() as u8 == Topic::ALL[i] as u8);
        }
        i += 1;
    }
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_names_and_indices_agree() {
        for (i, topic) in Topic::ALL.into_iter().enumerate() {
            assert_eq!(topic.index(), i);
            assert_eq!(Topic::try_from(topic.byte()), Ok(topic));
            assert_eq!(Topic::from_name(topic.name()), Some(topic));
            assert_eq!(topic.info().topic, topic);
            assert_eq!(TOPICS[i].topic, topic);
        }
        let unknown = (0..=255u8)
            .filter(|b| Topic::from_byte(*b).is_none())
            .count();
        assert_eq!(unknown, 256 - TOPIC_COUNT);
        assert_eq!(
            Topic::try_from(0x03),
            Err(DecodeError::UnknownTopic { topic: 0x03 })
        );
    }

    #[test]
    fn ids_fixed_by_the_thesis() {
        assert_eq!(Topic::FloorProximity.byte(), 0x04);
        assert_eq!(Topic::MagnetometerX.byte(), 0x05);
        assert_eq!(Topic::MagnetometerY.byte(), 0x06);
        assert_eq!(Topic::MagnetometerZ.byte(), 0x07);
        assert_eq!(Topic::Gyroscope.byte(), 0x08);
        assert_eq!(Topic::PowerStatus.byte(), 0x1E);
        assert_eq!(Topic::ProximityRing.byte(), 0x1F);
    }

    #[test]
    fn leds_are_numbered_one_to_eight() {
        for led in 1..=8u8 {
            let topic = Topic::led(led).unwrap();
            assert_eq!(topic.led_number(), Some(led));
            assert_eq!(topic.byte(), 0x10 + led);
            assert_eq!(topic.board(), Board::LightRing);
        }
        assert_eq!(Topic::led(0), None);
        assert_eq!(Topic::led(9), None);
        assert_eq!(Topic::Gyroscope.led_number(), None);
        assert_eq!(
            Topic::MagnetometerX
                .command_id(crate::Priority::Medium)
                .raw(),
            0x205
        );
        assert_eq!(
            Topic::MagnetometerX.data_id(crate::Priority::Medium).raw(),
            0x605
        );
    }

    #[test]
    fn actuators_have_no_period_and_sensors_have_one() {
        for info in TOPICS {
            assert_eq!(info.is_sensor, info.default_period_us > 0, "{}", info.name);
            assert_eq!(
                info.is_sensor,
                info.default_sample_time().is_some(),
                "{}",
                info.name
            );
        }
    }
}
