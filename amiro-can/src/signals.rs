//! Every payload as bit fields ("signals"): where each value sits in a frame, its width, sign, scale and unit —
//! the form CAN tools (DBC files, cantools, SavvyCAN) describe a protocol in.
//!
//! All signals are little-endian (Intel byte order); `start_bit` is the position of the least significant bit,
//! counted from bit 0 of data byte 0. A multi-frame topic's page or index byte is its [`Mux::Multiplexer`]; the
//! fields of one page are [`Mux::Page`]. Names are the field names `amiro decode --json` prints, so a tool's
//! decoding and `amiro`'s can be compared field by field (the interop check in `tools/interop/` does).

use crate::topic::{led_topics, Topic};

/// Where a signal is present in a multiplexed message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mux {
    /// In every frame of the message.
    Always,
    /// The selector: its value names the page (or sensor) of the frame.
    Multiplexer,
    /// Only in frames whose multiplexer has this value.
    Page(u8),
}

/// One value in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Signal {
    /// Field name, as `amiro decode --json` prints it.
    pub name: &'static str,
    /// Bit position of the least significant bit (little-endian).
    pub start_bit: u8,
    /// Width in bits.
    pub bits: u8,
    /// Two's complement.
    pub signed: bool,
    /// Physical value = raw × factor (a decimal, exact as written).
    pub factor: &'static str,
    /// Unit of the physical value (ASCII, as DBC files want).
    pub unit: &'static str,
    /// Presence.
    pub mux: Mux,
    /// Names of raw values (enumerations), empty for plain numbers.
    pub choices: &'static [(u32, &'static str)],
}

const fn sig(
    name: &'static str,
    start_bit: u8,
    bits: u8,
    signed: bool,
    unit: &'static str,
) -> Signal {
    Signal {
        name,
        start_bit,
        bits,
        signed,
        factor: "1",
        unit,
        mux: Mux::Always,
        choices: &[],
    }
}

const fn page(mut signal: Signal, page: u8) -> Signal {
    signal.mux = Mux::Page(page);
    signal
}

const fn scaled(mut signal: Signal, factor: &'static str) -> Signal {
    signal.factor = factor;
    signal
}

const fn named(mut signal: Signal, choices: &'static [(u32, &'static str)]) -> Signal {
    signal.choices = choices;
    signal
}

const fn selector(mut signal: Signal) -> Signal {
    signal.mux = Mux::Multiplexer;
    signal
}

const UNITS: &[(u32, &str)] = &[(0, "ms"), (1, "s"), (2, "us")];
/// A verdict's requested unit: 3 marks a one-shot request (its value: the interval in ms it was analysed at).
const REQUESTED_UNITS: &[(u32, &str)] = &[(0, "ms"), (1, "s"), (2, "us"), (3, "one-shot-ms")];
const PRIORITIES: &[(u32, &str)] = &[(0, "urgent"), (1, "high"), (2, "medium"), (3, "low")];
const PRIORITY_NEEDED: &[(u32, &str)] = &[
    (0, "none"),
    (1, "urgent"),
    (2, "high"),
    (3, "medium"),
    (4, "low"),
];
const VERDICTS: &[(u32, &str)] = &[(0, "refused"), (1, "accepted-with-warning")];
const VIOLATIONS: &[(u32, &str)] = &[(0, "unknown"), (1, "task"), (2, "message")];
const PAGES: &[(u32, &str)] = &[
    (0, "status"),
    (1, "commands"),
    (2, "rejections"),
    (3, "admission-and-receive"),
    (4, "transmit"),
    (5, "deadlines"),
    (0x80, "verdict"),
    (0x81, "verdict-bound"),
];
const MODES: &[(u32, &str)] = &[
    (0, "stop"),
    (1, "publish"),
    (2, "once"),
    (3, "admission-policy"),
];
const SENSOR_MODES: &[(u32, &str)] = &[(0, "stop"), (1, "publish"), (2, "once")];
const POLICIES: &[(u32, &str)] = &[(0, "refuse"), (1, "accept-and-warn")];
const SHUTDOWN_MODES: &[(u32, &str)] = &[
    (1, "hibernate"),
    (2, "deep-sleep"),
    (3, "transportation"),
    (4, "restart"),
];
const TOPIC_NAMES: &[(u32, &str)] = &[
    (0x01, "odometry"),
    (0x02, "velocity"),
    (0x04, "floor-proximity"),
    (0x05, "magnetometer-x"),
    (0x06, "magnetometer-y"),
    (0x07, "magnetometer-z"),
    (0x08, "gyroscope"),
    (0x09, "accelerometer"),
    (0x1A, "diwheeldrive-diagnostics"),
    (0x1B, "powermanagement-diagnostics"),
    (0x1C, "lightring-diagnostics"),
    (0x1E, "power-status"),
    (0x1F, "proximity-ring"),
];

const ODOMETRY: &[Signal] = &[
    scaled(sig("x_um", 0, 24, true, "um"), "100"),
    scaled(sig("y_um", 24, 24, true, "um"), "100"),
    sig("heading_counts", 48, 16, false, "1/65536 turn"),
];
const VELOCITY: &[Signal] = &[
    sig("velocity_um_s", 0, 32, true, "um/s"),
    sig("angular_urad_s", 32, 32, true, "urad/s"),
];
const FLOOR: &[Signal] = &[
    sig("counts_1", 0, 16, false, "counts"),
    sig("counts_2", 16, 16, false, "counts"),
    sig("counts_3", 32, 16, false, "counts"),
    sig("counts_4", 48, 16, false, "counts"),
];
const MAGNETOMETER: &[Signal] = &[sig("nanotesla", 0, 32, true, "nT")];
const GYROSCOPE: &[Signal] = &[
    sig("x_dps", 0, 16, true, "deg/s"),
    sig("y_dps", 16, 16, true, "deg/s"),
    sig("z_dps", 32, 16, true, "deg/s"),
];
const ACCELEROMETER: &[Signal] = &[
    sig("x_milli_g", 0, 16, true, "milli-g"),
    sig("y_milli_g", 16, 16, true, "milli-g"),
    sig("z_milli_g", 32, 16, true, "milli-g"),
];
const MOTOR: &[Signal] = &[
    sig("velocity_um_s", 0, 32, true, "um/s"),
    sig("angular_urad_s", 32, 32, true, "urad/s"),
];
const LED: &[Signal] = &[
    sig("r", 0, 8, false, ""),
    sig("g", 8, 8, false, ""),
    sig("b", 16, 8, false, ""),
];
const POWER_STATUS: &[Signal] = &[
    sig("charging", 0, 8, false, ""),
    sig("state_of_charge_percent", 8, 8, false, "%"),
    sig("minutes", 16, 16, false, "min"),
    sig("power_mw", 32, 16, false, "mW"),
];
const PROXIMITY_RING: &[Signal] = &[
    selector(sig("sensor", 0, 8, false, "")),
    sig("mm", 8, 16, false, "mm"),
];
const SHUTDOWN: &[Signal] = &[
    named(sig("mode", 0, 8, false, ""), SHUTDOWN_MODES),
    sig("key", 8, 16, false, ""),
];
const DIAGNOSTICS: &[Signal] = &[
    named(selector(sig("page", 0, 8, false, "")), PAGES),
    page(sig("uptime_s", 8, 32, false, "s"), 0),
    page(sig("reset_cause", 40, 8, false, ""), 0),
    page(sig("flags", 48, 8, false, ""), 0),
    page(sig("sensor_faults", 56, 8, false, ""), 0),
    page(sig("accepted", 8, 24, false, ""), 1),
    page(sig("rejected", 32, 24, false, ""), 1),
    page(sig("reasons", 56, 8, false, ""), 1),
    page(sig("first", 8, 8, false, ""), 2),
    page(sig("counts_1", 16, 16, false, ""), 2),
    page(sig("counts_2", 32, 16, false, ""), 2),
    page(sig("counts_3", 48, 16, false, ""), 2),
    page(sig("admission_refused", 8, 16, false, ""), 3),
    page(sig("admission_warned", 24, 16, false, ""), 3),
    page(sig("rx_dropped_at_least", 40, 16, false, ""), 3),
    page(sig("rx_overruns", 56, 8, false, ""), 3),
    page(sig("tx_dropped", 8, 24, false, ""), 4),
    page(sig("tx_displaced", 32, 16, false, ""), 4),
    page(sig("error_passive", 48, 8, false, ""), 4),
    page(sig("bus_off", 56, 8, false, ""), 4),
    page(sig("deadline_misses_urgent", 8, 14, false, ""), 5),
    page(sig("deadline_misses_high", 22, 14, false, ""), 5),
    page(sig("deadline_misses_medium", 36, 14, false, ""), 5),
    page(sig("deadline_misses_low", 50, 14, false, ""), 5),
    page(named(sig("topic", 8, 8, false, ""), TOPIC_NAMES), 0x80),
    page(sig("requested_value", 16, 16, false, ""), 0x80),
    page(
        named(sig("requested_unit", 32, 2, false, ""), REQUESTED_UNITS),
        0x80,
    ),
    page(named(sig("priority", 34, 2, false, ""), PRIORITIES), 0x80),
    page(named(sig("verdict", 36, 1, false, ""), VERDICTS), 0x80),
    page(
        named(sig("priority_needed", 37, 3, false, ""), PRIORITY_NEEDED),
        0x80,
    ),
    page(sig("shortest_period_value", 40, 16, false, ""), 0x80),
    page(
        named(sig("shortest_period_unit", 56, 2, false, ""), UNITS),
        0x80,
    ),
    page(named(sig("violation", 58, 2, false, ""), VIOLATIONS), 0x80),
    page(
        named(sig("violated_priority", 60, 2, false, ""), PRIORITIES),
        0x80,
    ),
    page(sig("has_shortest_period", 62, 1, false, ""), 0x80),
    page(sig("not_searched", 63, 1, false, ""), 0x80),
    page(sig("violated", 8, 8, false, ""), 0x81),
    page(sig("wcrt_us", 16, 24, false, "us"), 0x81),
    page(sig("deadline_us", 40, 24, false, "us"), 0x81),
];

/// A command to a sensor topic (DLC 1 for stop and once, 4 for publish).
const SENSOR_COMMAND: &[Signal] = &[
    named(selector(sig("mode", 0, 8, false, "")), SENSOR_MODES),
    page(sig("sample_time_value", 8, 16, false, ""), 1),
    page(named(sig("sample_time_unit", 24, 8, false, ""), UNITS), 1),
];
/// A command to a diagnostics topic: the sensor commands plus the admission policy (mode 3, DLC 2).
const DIAGNOSTICS_COMMAND: &[Signal] = &[
    named(selector(sig("mode", 0, 8, false, "")), MODES),
    page(sig("sample_time_value", 8, 16, false, ""), 1),
    page(named(sig("sample_time_unit", 24, 8, false, ""), UNITS), 1),
    page(named(sig("policy", 8, 8, false, ""), POLICIES), 3),
];

impl Topic {
    /// The signals of the frames a board sends on this topic (sensors), or of the command frame (actuators).
    pub const fn data_signals(self) -> &'static [Signal] {
        match self {
            Topic::Odometry => ODOMETRY,
            Topic::Velocity => VELOCITY,
            Topic::FloorProximity => FLOOR,
            Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => MAGNETOMETER,
            Topic::Gyroscope => GYROSCOPE,
            Topic::Accelerometer => ACCELEROMETER,
            Topic::MotorCommand => MOTOR,
            led_topics!() => LED,
            Topic::DiWheelDriveDiagnostics
            | Topic::PowerManagementDiagnostics
            | Topic::LightRingDiagnostics => DIAGNOSTICS,
            Topic::Shutdown => SHUTDOWN,
            Topic::PowerStatus => POWER_STATUS,
            Topic::ProximityRing => PROXIMITY_RING,
        }
    }

    /// The signals of a command frame to this topic: the sensor commands (stop / publish / once, and the
    /// admission policy on a diagnostics topic), or the actuator's payload.
    pub const fn command_signals(self) -> &'static [Signal] {
        if self.diagnostics_of().is_some() {
            DIAGNOSTICS_COMMAND
        } else if self.is_sensor() {
            SENSOR_COMMAND
        } else {
            self.data_signals()
        }
    }

    /// The length of the longest command frame to this topic (4 for a publish command; the actuator's DLC).
    pub const fn command_dlc(self) -> u8 {
        if self.is_sensor() {
            4
        } else {
            self.info().dlc
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signals of one frame never overlap and stay inside the frame.
    fn check(topic: Topic, signals: &[Signal], dlc: u8) {
        let pages: std::vec::Vec<Option<u8>> = signals
            .iter()
            .map(|s| match s.mux {
                Mux::Page(p) => Some(p),
                _ => None,
            })
            .collect();
        for page in pages.iter().copied().chain([None]) {
            let mut used = 0u64;
            for s in signals {
                let present = match s.mux {
                    Mux::Always | Mux::Multiplexer => true,
                    Mux::Page(p) => Some(p) == page,
                };
                if !present {
                    continue;
                }
                assert!(
                    s.bits > 0 && u32::from(s.start_bit) + u32::from(s.bits) <= u32::from(dlc) * 8,
                    "{topic} {}",
                    s.name
                );
                let mask = (u64::MAX >> (64 - u32::from(s.bits))) << s.start_bit;
                assert_eq!(used & mask, 0, "{topic}: {} overlaps", s.name);
                used |= mask;
            }
        }
        for (i, a) in signals.iter().enumerate() {
            for b in &signals[i + 1..] {
                assert_ne!(a.name, b.name, "{topic}: signal names must be unique");
            }
        }
    }

    #[test]
    fn signals_fit_their_frames() {
        for topic in Topic::ALL {
            check(topic, topic.data_signals(), topic.info().dlc);
            check(topic, topic.command_signals(), topic.command_dlc());
        }
    }
}
