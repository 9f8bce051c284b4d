//! Commands (C/S = 0): sensor commands (stop / publish / once), the admission-policy command on a diagnostics
//! topic, and the actuator commands (motor, LEDs, shutdown).

use core::fmt;

use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::{CanId, Kind, Priority};
use crate::topic::{Board, Topic};
use crate::wire;

/// The mode byte (data\[0\]) of an admission-policy command on a diagnostics topic; modes 0–2 are the sensor
/// command modes every sensor topic takes.
pub const POLICY_MODE: u8 = 3;

/// How a board answers a publish or re-prioritisation request its admission check says would break a bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum AdmissionPolicy {
    /// 0: refuse it, change nothing, and send an admission verdict (the default after reset).
    #[default]
    Refuse = 0,
    /// 1: start it anyway and send an admission verdict that says it was accepted with a warning.
    AcceptAndWarn = 1,
}

impl AdmissionPolicy {
    /// The name used by `amiro` (`refuse`, `accept-and-warn`).
    pub const fn name(self) -> &'static str {
        match self {
            AdmissionPolicy::Refuse => "refuse",
            AdmissionPolicy::AcceptAndWarn => "accept-and-warn",
        }
    }
}

impl TryFrom<u8> for AdmissionPolicy {
    type Error = DecodeError;

    fn try_from(value: u8) -> Result<Self, Self::Error> {
        match value {
            0 => Ok(AdmissionPolicy::Refuse),
            1 => Ok(AdmissionPolicy::AcceptAndWarn),
            _ => Err(DecodeError::BadPolicy { value }),
        }
    }
}

impl fmt::Display for AdmissionPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Bytes 1–2 of a shutdown command (u16 little-endian): the payload of the AMiRo 1.x firmware's shutdown
/// broadcast, kept as a key so that no stray or truncated frame powers the robot off.
pub const SHUTDOWN_KEY: u16 = 0xAA55;

/// What a shutdown command asks of the robot. The codes are AMiRo-BLT's shutdown reasons, the value
/// PowerManagement writes to byte 0 of `RTC_BKP0R` before it hands over to the bootloader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ShutdownMode {
    /// 1: hibernate — everything off except what wakes the robot on the charger or a button.
    Hibernate = 1,
    /// 2: deep sleep — everything off; a wake-up source restarts the robot.
    DeepSleep = 2,
    /// 3: transportation — everything off with the fewest wake-up sources (for shipping).
    Transportation = 3,
    /// 4: restart — power-cycle the system and boot again.
    Restart = 4,
}

impl ShutdownMode {
    /// Every mode, in code order.
    pub const ALL: [ShutdownMode; 4] = [
        ShutdownMode::Hibernate,
        ShutdownMode::DeepSleep,
        ShutdownMode::Transportation,
        ShutdownMode::Restart,
    ];

    /// The AMiRo-BLT shutdown reason: byte 0 of `RTC_BKP0R` (the same number as the wire code).
    pub const fn blt_reason(self) -> u8 {
        self as u8
    }

    /// The name used by `amiro` (`hibernate`, `deep-sleep`, `transportation`, `restart`).
    pub const fn name(self) -> &'static str {
        match self {
            ShutdownMode::Hibernate => "hibernate",
            ShutdownMode::DeepSleep => "deep-sleep",
            ShutdownMode::Transportation => "transportation",
            ShutdownMode::Restart => "restart",
        }
    }
}

impl TryFrom<u8> for ShutdownMode {
    type Error = DecodeError;

    fn try_from(value: u8) -> Result<Self, Self::Error> {
        match value {
            1 => Ok(ShutdownMode::Hibernate),
            2 => Ok(ShutdownMode::DeepSleep),
            3 => Ok(ShutdownMode::Transportation),
            4 => Ok(ShutdownMode::Restart),
            _ => Err(DecodeError::BadShutdownMode { value }),
        }
    }
}

impl fmt::Display for ShutdownMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The longest publish period the firmware monotonic accepts, in µs (a 32-bit microsecond timer span, ≈ 71.6 min).
pub const MAX_PERIOD_US: u64 = u32::MAX as u64;

/// How often a board takes a one-shot (`once`) request at most, in ms: its admission task takes one command per
/// this interval. So a one-shot is decided — by the boards' admission check, by `amiro` and by the report's
/// `one_shots` — as a sample of its topic at its priority every this many ms, in place of the topic's publisher
/// (a one-shot stops it). docs/analysis.md, "The admission task".
pub const ONE_SHOT_INTERVAL_MS: u16 = 40;

/// The unit byte of a publish command (data\[3\]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum TimeUnit {
    /// 0: milliseconds (the thesis's default unit).
    Millis = 0,
    /// 1: seconds.
    Seconds = 1,
    /// 2: microseconds.
    Micros = 2,
}

impl TimeUnit {
    /// Microseconds in one of this unit.
    pub const fn micros(self) -> u64 {
        match self {
            TimeUnit::Millis => 1_000,
            TimeUnit::Seconds => 1_000_000,
            TimeUnit::Micros => 1,
        }
    }

    /// The SI symbol (`ms`, `s`, `µs`).
    pub const fn symbol(self) -> &'static str {
        match self {
            TimeUnit::Millis => "ms",
            TimeUnit::Seconds => "s",
            TimeUnit::Micros => "µs",
        }
    }
}

impl fmt::Display for TimeUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

impl TryFrom<u8> for TimeUnit {
    type Error = DecodeError;

    fn try_from(unit: u8) -> Result<Self, Self::Error> {
        match unit {
            0 => Ok(TimeUnit::Millis),
            1 => Ok(TimeUnit::Seconds),
            2 => Ok(TimeUnit::Micros),
            _ => Err(DecodeError::BadUnit { unit }),
        }
    }
}

/// A publish period as it travels on the bus: a u16 count of a unit.
///
/// The fields are public so a firmware can match on them; a value built by hand is checked by
/// [`SampleTime::validate`] (the decoder and [`crate::Message::try_encode`] do it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SampleTime {
    /// Number of units.
    pub value: u16,
    /// The unit.
    pub unit: TimeUnit,
}

impl SampleTime {
    /// 50 ms: what a publish command without a sample time (DLC 1) means.
    pub const DEFAULT: SampleTime = SampleTime {
        value: 50,
        unit: TimeUnit::Millis,
    };

    /// A checked sample time: not zero and not above [`MAX_PERIOD_US`].
    pub const fn new(value: u16, unit: TimeUnit) -> Result<SampleTime, DecodeError> {
        let time = SampleTime { value, unit };
        match time.validate() {
            Ok(()) => Ok(time),
            Err(e) => Err(e),
        }
    }

    /// Rejects a zero period and one the firmware monotonic cannot schedule.
    pub const fn validate(&self) -> Result<(), DecodeError> {
        let micros = self.as_micros();
        if micros == 0 {
            Err(DecodeError::ZeroSampleTime)
        } else if micros > MAX_PERIOD_US {
            Err(DecodeError::PeriodTooLong { micros })
        } else {
            Ok(())
        }
    }

    /// The period in microseconds (cannot overflow: at most 65535 s).
    pub const fn as_micros(&self) -> u64 {
        self.value as u64 * self.unit.micros()
    }

    /// The coarsest exact encoding of a period: 50 000 µs becomes 50 ms, 2 000 000 µs becomes 2 s, 900 µs stays.
    ///
    /// Zero, a period above [`MAX_PERIOD_US`], and a period no unit can carry exactly in 16 bits (such as
    /// 65 536 001 µs) are errors; the last is reported as [`DecodeError::PeriodTooLong`] only when it is too long,
    /// otherwise as [`DecodeError::PeriodNotEncodable`].
    pub const fn from_micros(micros: u64) -> Result<SampleTime, DecodeError> {
        if micros == 0 {
            return Err(DecodeError::ZeroSampleTime);
        }
        if micros > MAX_PERIOD_US {
            return Err(DecodeError::PeriodTooLong { micros });
        }
        let units = [TimeUnit::Seconds, TimeUnit::Millis, TimeUnit::Micros];
        let mut i = 0;
        while i < units.len() {
            let unit = units[i];
            let per = unit.micros();
            if micros.is_multiple_of(per) && micros / per <= u16::MAX as u64 {
                return Ok(SampleTime {
                    value: (micros / per) as u16,
                    unit,
                });
            }
            i += 1;
        }
        Err(DecodeError::PeriodNotEncodable { micros })
    }
}

impl Default for SampleTime {
    fn default() -> Self {
        SampleTime::DEFAULT
    }
}

impl fmt::Display for SampleTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.value, self.unit.symbol())
    }
}

/// What a sensor command asks of a topic's publisher (data\[0\]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SensorMode {
    /// Mode 0: stop the publisher.
    Stop,
    /// Mode 1: start the publisher, or change its period and priority if it runs.
    Publish(SampleTime),
    /// Mode 2: send one sample now, and stop a running publisher of the topic (as the thesis specifies).
    Once,
}

impl SensorMode {
    /// The mode byte.
    pub const fn byte(&self) -> u8 {
        match self {
            SensorMode::Stop => 0,
            SensorMode::Publish(_) => 1,
            SensorMode::Once => 2,
        }
    }
}

/// A command to a sensor topic. Its priority becomes the priority of the frames the publisher sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SensorCommand {
    /// The sensor topic.
    pub topic: Topic,
    /// The command's priority, and the priority of the answering frames.
    pub priority: Priority,
    /// Stop, publish or once.
    pub mode: SensorMode,
}

impl SensorCommand {
    /// The identifier of this command (C/S = 0).
    pub const fn id(&self) -> CanId {
        CanId::new(Kind::Command, self.priority, self.topic as u8)
    }

    /// The identifier the board answers with (C/S = 1, same priority and topic): `0x205` → `0x605`.
    pub const fn reply_id(&self) -> CanId {
        CanId::new(Kind::Sensor, self.priority, self.topic as u8)
    }

    /// The frame. A publish command always carries its sample time (DLC 4), so the receiver never has to know
    /// the default; stop and once are DLC 1.
    pub fn encode(&self) -> Frame {
        let mut data = [0u8; 8];
        data[0] = self.mode.byte();
        let len = match self.mode {
            SensorMode::Publish(time) => {
                let [lo, hi] = time.value.to_le_bytes();
                data[1] = lo;
                data[2] = hi;
                data[3] = time.unit as u8;
                4
            }
            SensorMode::Stop | SensorMode::Once => 1,
        };
        wire::frame(self.id(), len, data)
    }

    /// Decodes the data of a command frame to a sensor topic.
    pub fn decode(
        topic: Topic,
        priority: Priority,
        data: &[u8],
    ) -> Result<SensorCommand, DecodeError> {
        let too_short = |expected| DecodeError::DlcTooShort {
            topic,
            frame: Kind::Command,
            dlc: wire::dlc(data),
            expected,
        };
        let too_long = |expected| DecodeError::DlcTooLong {
            topic,
            frame: Kind::Command,
            dlc: wire::dlc(data),
            expected,
        };
        let (&mode, rest) = data.split_first().ok_or(too_short(1))?;
        let mode = match mode {
            0 | 2 if !rest.is_empty() => return Err(too_long(1)),
            0 => SensorMode::Stop,
            2 => SensorMode::Once,
            1 => match *rest {
                [] => SensorMode::Publish(SampleTime::DEFAULT),
                [lo, hi, unit] => {
                    let unit = TimeUnit::try_from(unit)?;
                    SensorMode::Publish(SampleTime::new(u16::from_le_bytes([lo, hi]), unit)?)
                }
                [_] | [_, _] => return Err(too_short(4)),
                _ => return Err(too_long(4)),
            },
            mode => return Err(DecodeError::BadMode { mode }),
        };
        Ok(SensorCommand {
            topic,
            priority,
            mode,
        })
    }

    /// Checks what the decoder would check: a sensor topic and a valid sample time.
    pub const fn validate(&self) -> Result<(), DecodeError> {
        if !self.topic.is_sensor() {
            return Err(DecodeError::NotASensor { topic: self.topic });
        }
        match self.mode {
            SensorMode::Publish(time) => time.validate(),
            SensorMode::Stop | SensorMode::Once => Ok(()),
        }
    }
}

impl fmt::Display for SensorCommand {
    /// `publish magnetometer-x every 900 µs`, `stop gyroscope`, `once floor-proximity`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.mode {
            SensorMode::Stop => write!(f, "stop {}", self.topic),
            SensorMode::Publish(time) => write!(f, "publish {} every {time}", self.topic),
            SensorMode::Once => write!(f, "once {}", self.topic),
        }
    }
}

/// Target velocity of the differential drive (topic `motor`, DLC 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct MotorCommand {
    /// Forward velocity in µm/s (positive = forward).
    pub velocity_um_s: i32,
    /// Angular velocity about the vertical axis in µrad/s (positive = counter-clockwise seen from above).
    pub angular_urad_s: i32,
}

impl MotorCommand {
    /// Standing still.
    pub const STOP: MotorCommand = MotorCommand {
        velocity_um_s: 0,
        angular_urad_s: 0,
    };

    pub(crate) fn to_bytes(self) -> [u8; 8] {
        wire::two_i32(self.velocity_um_s, self.angular_urad_s)
    }

    pub(crate) fn from_bytes(bytes: [u8; 8]) -> MotorCommand {
        let (velocity_um_s, angular_urad_s) = wire::split_two_i32(bytes);
        MotorCommand {
            velocity_um_s,
            angular_urad_s,
        }
    }
}

impl fmt::Display for MotorCommand {
    /// `motor 100000 µm/s, -50000 µrad/s`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "motor {} µm/s, {} µrad/s",
            self.velocity_um_s, self.angular_urad_s
        )
    }
}

/// An RGB colour, one byte per channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Rgb {
    /// Red 0..=255.
    pub r: u8,
    /// Green 0..=255.
    pub g: u8,
    /// Blue 0..=255.
    pub b: u8,
}

impl Rgb {
    /// LED off.
    pub const OFF: Rgb = Rgb { r: 0, g: 0, b: 0 };
}

impl fmt::Display for Rgb {
    /// `rgb(10,50,120)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "rgb({},{},{})", self.r, self.g, self.b)
    }
}

/// Set one LED of the light ring (topics `led-1` .. `led-8`, DLC 3: R, G, B).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LedCommand {
    /// The LED, 1..=8 (the topic byte is 0x10 + led).
    pub led: u8,
    /// The colour.
    pub rgb: Rgb,
}

impl LedCommand {
    /// A checked LED command (`led` in 1..=8).
    pub const fn new(led: u8, rgb: Rgb) -> Result<LedCommand, DecodeError> {
        match Topic::led(led) {
            Some(_) => Ok(LedCommand { led, rgb }),
            None => Err(DecodeError::LedOutOfRange { led }),
        }
    }

    /// The LED's topic, or the error if `led` is not 1..=8.
    pub const fn topic(&self) -> Result<Topic, DecodeError> {
        match Topic::led(self.led) {
            Some(topic) => Ok(topic),
            None => Err(DecodeError::LedOutOfRange { led: self.led }),
        }
    }
}

impl fmt::Display for LedCommand {
    /// `led 3 rgb(10,50,120)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "led {} {}", self.led, self.rgb)
    }
}

/// Any command frame (C/S = 0), decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// Stop / publish / once to a sensor topic.
    Sensor(SensorCommand),
    /// Target velocity for the motors.
    Motor {
        /// Frame priority.
        priority: Priority,
        /// The velocities.
        command: MotorCommand,
    },
    /// Colour of one LED.
    Led {
        /// Frame priority.
        priority: Priority,
        /// LED and colour.
        command: LedCommand,
    },
    /// The admission policy of one board: mode 3 on that board's diagnostics topic, DLC 2.
    Policy {
        /// Frame priority.
        priority: Priority,
        /// The board the policy is for (the diagnostics topic's owner).
        board: Board,
        /// Refuse or accept-and-warn.
        policy: AdmissionPolicy,
    },
    /// Shut the robot down (topic `shutdown`, PowerManagement, DLC 3: mode, then [`SHUTDOWN_KEY`]).
    Shutdown {
        /// Frame priority.
        priority: Priority,
        /// Hibernate, deep sleep, transportation or restart.
        mode: ShutdownMode,
    },
}

impl Command {
    /// The priority bits of the command frame.
    pub const fn priority(&self) -> Priority {
        match self {
            Command::Sensor(c) => c.priority,
            Command::Motor { priority, .. }
            | Command::Led { priority, .. }
            | Command::Policy { priority, .. }
            | Command::Shutdown { priority, .. } => *priority,
        }
    }

    /// The addressed topic; for an LED command with an LED outside 1..=8 the error.
    pub const fn topic(&self) -> Result<Topic, DecodeError> {
        match self {
            Command::Sensor(c) => Ok(c.topic),
            Command::Motor { .. } => Ok(Topic::MotorCommand),
            Command::Led { command, .. } => command.topic(),
            Command::Policy { board, .. } => Ok(board.diagnostics_topic()),
            Command::Shutdown { .. } => Ok(Topic::Shutdown),
        }
    }

    /// The frame. Never fails; a command with an out-of-range field gives a frame the decoder rejects (an LED
    /// outside 1..=8 is sent to an unused topic byte). Use [`Command::try_encode`] to refuse such a command.
    pub fn encode(&self) -> Frame {
        match self {
            Command::Sensor(c) => c.encode(),
            Command::Motor { priority, command } => wire::frame(
                CanId::new(Kind::Command, *priority, Topic::MotorCommand as u8),
                8,
                command.to_bytes(),
            ),
            Command::Led { priority, command } => {
                // 0x10 + led, so LED 0 or 9.. never lands on an LED topic; wrapping keeps this panic-free.
                let topic_byte = (Topic::MotorCommand as u8).wrapping_add(command.led);
                let Rgb { r, g, b } = command.rgb;
                wire::frame(
                    CanId::new(Kind::Command, *priority, topic_byte),
                    3,
                    [r, g, b, 0, 0, 0, 0, 0],
                )
            }
            Command::Policy {
                priority,
                board,
                policy,
            } => wire::frame(
                board.diagnostics_topic().command_id(*priority),
                2,
                [POLICY_MODE, *policy as u8, 0, 0, 0, 0, 0, 0],
            ),
            Command::Shutdown { priority, mode } => {
                let [k0, k1] = SHUTDOWN_KEY.to_le_bytes();
                wire::frame(
                    Topic::Shutdown.command_id(*priority),
                    3,
                    [*mode as u8, k0, k1, 0, 0, 0, 0, 0],
                )
            }
        }
    }

    /// Checks every field the decoder would check.
    pub const fn validate(&self) -> Result<(), DecodeError> {
        match self {
            Command::Sensor(c) => c.validate(),
            Command::Motor { .. } | Command::Policy { .. } | Command::Shutdown { .. } => Ok(()),
            Command::Led { command, .. } => match command.topic() {
                Ok(_) => Ok(()),
                Err(e) => Err(e),
            },
        }
    }

    /// The frame, or the reason a receiver would reject it.
    pub fn try_encode(&self) -> Result<Frame, DecodeError> {
        self.validate()?;
        Ok(self.encode())
    }

    /// Decodes the data of a command frame to `topic` (sensor command or actuator command by the topic's role).
    pub fn decode(topic: Topic, priority: Priority, data: &[u8]) -> Result<Command, DecodeError> {
        if let (Some(board), Some(&POLICY_MODE)) = (topic.diagnostics_of(), data.first()) {
            let [_, policy] = wire::exact::<2>(topic, Kind::Command, data)?;
            return Ok(Command::Policy {
                priority,
                board,
                policy: AdmissionPolicy::try_from(policy)?,
            });
        }
        if topic.is_sensor() {
            return SensorCommand::decode(topic, priority, data).map(Command::Sensor);
        }
        if topic == Topic::Shutdown {
            let [mode, k0, k1] = wire::exact::<3>(topic, Kind::Command, data)?;
            let key = u16::from_le_bytes([k0, k1]);
            if key != SHUTDOWN_KEY {
                return Err(DecodeError::BadShutdownKey { key });
            }
            return Ok(Command::Shutdown {
                priority,
                mode: ShutdownMode::try_from(mode)?,
            });
        }
        match topic.led_number() {
            Some(led) => {
                let [r, g, b] = wire::exact::<3>(topic, Kind::Command, data)?;
                Ok(Command::Led {
                    priority,
                    command: LedCommand {
                        led,
                        rgb: Rgb { r, g, b },
                    },
                })
            }
            None => {
                let bytes = wire::exact::<8>(topic, Kind::Command, data)?;
                Ok(Command::Motor {
                    priority,
                    command: MotorCommand::from_bytes(bytes),
                })
            }
        }
    }
}

impl fmt::Display for Command {
    /// `medium command: publish magnetometer-x every 900 µs`, `high command: motor 100000 µm/s, 0 µrad/s`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} command: ", self.priority())?;
        match self {
            Command::Sensor(c) => write!(f, "{c}"),
            Command::Motor { command, .. } => write!(f, "{command}"),
            Command::Led { command, .. } => write!(f, "{command}"),
            Command::Policy { board, policy, .. } => {
                write!(f, "admission policy of {board}: {policy}")
            }
            Command::Shutdown { mode, .. } => write!(f, "shut the robot down ({mode})"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mag_x(data: &[u8]) -> Result<SensorCommand, DecodeError> {
        SensorCommand::decode(Topic::MagnetometerX, Priority::Medium, data)
    }

    #[test]
    fn thesis_example_payload() {
        let c = mag_x(&[0x01, 0x84, 0x03, 0x02]).unwrap();
        assert_eq!(
            c.mode,
            SensorMode::Publish(SampleTime {
                value: 900,
                unit: TimeUnit::Micros
            })
        );
        assert_eq!(c.id().raw(), 0x205);
        assert_eq!(c.reply_id().raw(), 0x605);
        assert_eq!(c.encode().data(), &[0x01, 0x84, 0x03, 0x02]);
    }

    #[test]
    fn mode_lengths() {
        let short = |dlc, expected| DecodeError::DlcTooShort {
            topic: Topic::MagnetometerX,
            frame: Kind::Command,
            dlc,
            expected,
        };
        let long = |dlc, expected| DecodeError::DlcTooLong {
            topic: Topic::MagnetometerX,
            frame: Kind::Command,
            dlc,
            expected,
        };
        assert_eq!(mag_x(&[]), Err(short(0, 1)));
        assert_eq!(mag_x(&[0]).unwrap().mode, SensorMode::Stop);
        assert_eq!(mag_x(&[2]).unwrap().mode, SensorMode::Once);
        assert_eq!(mag_x(&[0, 0]), Err(long(2, 1)));
        assert_eq!(mag_x(&[2, 1, 2, 3]), Err(long(4, 1)));
        assert_eq!(
            mag_x(&[1]).unwrap().mode,
            SensorMode::Publish(SampleTime::DEFAULT)
        );
        assert_eq!(mag_x(&[1, 5]), Err(short(2, 4)));
        assert_eq!(mag_x(&[1, 5, 0]), Err(short(3, 4)));
        assert_eq!(mag_x(&[1, 5, 0, 0, 0]), Err(long(5, 4)));
        assert_eq!(mag_x(&[1, 5, 0, 0, 0, 0, 0, 0]), Err(long(8, 4)));
        assert_eq!(mag_x(&[3]), Err(DecodeError::BadMode { mode: 3 }));
        assert_eq!(
            mag_x(&[0xFF, 1, 2]),
            Err(DecodeError::BadMode { mode: 0xFF })
        );
    }

    #[test]
    fn sample_time_rules() {
        assert_eq!(mag_x(&[1, 0, 0, 0]), Err(DecodeError::ZeroSampleTime));
        assert_eq!(mag_x(&[1, 5, 0, 3]), Err(DecodeError::BadUnit { unit: 3 }));
        // 4295 s is just above u32::MAX µs; 4294 s is just below.
        assert_eq!(
            mag_x(&[1, 0xC7, 0x10, 1]),
            Err(DecodeError::PeriodTooLong {
                micros: 4_295_000_000
            })
        );
        assert!(mag_x(&[1, 0xC6, 0x10, 1]).is_ok());
        assert_eq!(
            SampleTime {
                value: 65535,
                unit: TimeUnit::Millis
            }
            .as_micros(),
            65_535_000
        );
        assert_eq!(SampleTime::DEFAULT.as_micros(), 50_000);
    }

    #[test]
    fn from_micros_picks_the_coarsest_exact_unit() {
        assert_eq!(
            SampleTime::from_micros(900),
            Ok(SampleTime {
                value: 900,
                unit: TimeUnit::Micros
            })
        );
        assert_eq!(SampleTime::from_micros(50_000), Ok(SampleTime::DEFAULT));
        assert_eq!(
            SampleTime::from_micros(2_000_000),
            Ok(SampleTime {
                value: 2,
                unit: TimeUnit::Seconds
            })
        );
        assert_eq!(
            SampleTime::from_micros(62_500),
            Ok(SampleTime {
                value: 62_500,
                unit: TimeUnit::Micros
            })
        );
        assert_eq!(
            SampleTime::from_micros(65_536_001),
            Err(DecodeError::PeriodNotEncodable { micros: 65_536_001 })
        );
        assert_eq!(
            SampleTime::from_micros(65_536),
            Err(DecodeError::PeriodNotEncodable { micros: 65_536 })
        );
        assert_eq!(SampleTime::from_micros(0), Err(DecodeError::ZeroSampleTime));
        assert_eq!(
            SampleTime::from_micros(MAX_PERIOD_US + 1),
            Err(DecodeError::PeriodTooLong {
                micros: MAX_PERIOD_US + 1
            })
        );
        for micros in [
            1u64,
            999,
            1000,
            1001,
            65_535,
            66_000,
            1_000_000,
            65_535_000,
            65_000_000,
            4_294_000_000,
        ] {
            assert_eq!(SampleTime::from_micros(micros).unwrap().as_micros(), micros);
        }
    }

    #[test]
    fn actuator_commands() {
        let led = Command::decode(Topic::Led3, Priority::High, &[10, 50, 120]).unwrap();
        assert_eq!(
            led,
            Command::Led {
                priority: Priority::High,
                command: LedCommand {
                    led: 3,
                    rgb: Rgb {
                        r: 10,
                        g: 50,
                        b: 120
                    }
                }
            }
        );
        assert_eq!(led.encode().id().raw(), 0x113);
        assert_eq!(
            Command::decode(Topic::Led1, Priority::High, &[1, 2]),
            Err(DecodeError::DlcTooShort {
                topic: Topic::Led1,
                frame: Kind::Command,
                dlc: 2,
                expected: 3
            })
        );
        let motor = Command::decode(
            Topic::MotorCommand,
            Priority::Urgent,
            &[0xA0, 0x86, 1, 0, 0xFF, 0xFF, 0xFF, 0xFF],
        )
        .unwrap();
        assert_eq!(
            motor,
            Command::Motor {
                priority: Priority::Urgent,
                command: MotorCommand {
                    velocity_um_s: 100_000,
                    angular_urad_s: -1
                }
            }
        );
        assert_eq!(
            Command::decode(Topic::MotorCommand, Priority::Urgent, &[0; 9]),
            Err(DecodeError::DlcTooLong {
                topic: Topic::MotorCommand,
                frame: Kind::Command,
                dlc: 9,
                expected: 8
            })
        );
    }

    #[test]
    fn try_encode_refuses_what_the_decoder_would() {
        let bad_led = Command::Led {
            priority: Priority::Low,
            command: LedCommand {
                led: 9,
                rgb: Rgb::OFF,
            },
        };
        assert_eq!(
            bad_led.try_encode(),
            Err(DecodeError::LedOutOfRange { led: 9 })
        );
        assert_eq!(
            LedCommand::new(0, Rgb::OFF),
            Err(DecodeError::LedOutOfRange { led: 0 })
        );
        let to_actuator = Command::Sensor(SensorCommand {
            topic: Topic::MotorCommand,
            priority: Priority::Low,
            mode: SensorMode::Stop,
        });
        assert_eq!(
            to_actuator.try_encode(),
            Err(DecodeError::NotASensor {
                topic: Topic::MotorCommand
            })
        );
        let zero = Command::Sensor(SensorCommand {
            topic: Topic::Gyroscope,
            priority: Priority::Low,
            mode: SensorMode::Publish(SampleTime {
                value: 0,
                unit: TimeUnit::Seconds,
            }),
        });
        assert_eq!(zero.try_encode(), Err(DecodeError::ZeroSampleTime));
    }

    #[test]
    fn display() {
        let c = Command::Sensor(mag_x(&[0x01, 0x84, 0x03, 0x02]).unwrap());
        assert_eq!(
            std::format!("{c}"),
            "medium command: publish magnetometer-x every 900 µs"
        );
        let m = Command::Motor {
            priority: Priority::High,
            command: MotorCommand {
                velocity_um_s: 100_000,
                angular_urad_s: -50_000,
            },
        };
        assert_eq!(
            std::format!("{m}"),
            "high command: motor 100000 µm/s, -50000 µrad/s"
        );
        let l = Command::Led {
            priority: Priority::Low,
            command: LedCommand {
                led: 3,
                rgb: Rgb {
                    r: 10,
                    g: 50,
                    b: 120,
                },
            },
        };
        assert_eq!(std::format!("{l}"), "low command: led 3 rgb(10,50,120)");
    }
}
