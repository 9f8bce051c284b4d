//! Sensor data (C/S = 1): the payload of every sensor topic in its wire units, with encoders and decoders.
//!
//! Units are chosen so one integer on the wire is one value with a plain unit (see `docs/protocol.md` for why each
//! differs from the thesis where it does).

use core::fmt;

use crate::diagnostics::DiagnosticsPage;
use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::{CanId, Kind, Priority};
use crate::topic::{led_topics, Board, Topic};
use crate::wire;

/// A magnetometer axis; each has its own topic because one i32 per axis fills half a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Topic `magnetometer-x` (0x05).
    X,
    /// Topic `magnetometer-y` (0x06).
    Y,
    /// Topic `magnetometer-z` (0x07).
    Z,
}

impl Axis {
    /// All axes.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// The axis's magnetometer topic.
    pub const fn magnetometer_topic(self) -> Topic {
        match self {
            Axis::X => Topic::MagnetometerX,
            Axis::Y => Topic::MagnetometerY,
            Axis::Z => Topic::MagnetometerZ,
        }
    }

    /// `x`, `y` or `z`.
    pub const fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }
}

/// 2π × 10¹² picoradians: one turn, exact enough that µrad conversions round correctly over a whole turn.
const TURN_PICORAD: i128 = 6_283_185_307_180;
/// Heading counts per turn.
const TURN_COUNTS: i128 = 65_536;

/// Dead-reckoning pose in wire units: x and y as signed 24-bit counts of 100 µm (±838.8 m), heading as an
/// unsigned 16-bit fraction of a turn (65536 = 360°, counter-clockwise from the x axis).
///
/// The fields are private so an `Odometry` always fits its frame; build one with [`Odometry::new`] or
/// [`Odometry::from_micrometres`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Odometry {
    x_100um: i32,
    y_100um: i32,
    heading: u16,
}

impl Odometry {
    /// Smallest x or y in 100 µm units (−2²³).
    pub const MIN_100UM: i32 = -(1 << 23);
    /// Largest x or y in 100 µm units (2²³ − 1).
    pub const MAX_100UM: i32 = (1 << 23) - 1;
    /// Heading counts per full turn.
    pub const HEADING_PER_TURN: u32 = 65_536;

    /// From wire units; `None` when x or y does not fit 24 bits.
    pub const fn new(x_100um: i32, y_100um: i32, heading: u16) -> Option<Odometry> {
        if Self::fits(x_100um) && Self::fits(y_100um) {
            Some(Odometry {
                x_100um,
                y_100um,
                heading,
            })
        } else {
            None
        }
    }

    const fn fits(v: i32) -> bool {
        v >= Self::MIN_100UM && v <= Self::MAX_100UM
    }

    /// From µm and µrad: position rounded to the nearest 100 µm, heading to the nearest 1/65536 turn and wrapped
    /// into one turn (any angle is accepted). `None` when x or y is beyond ±838.8 m.
    ///
    /// No 64-bit division (the STM32F103 has none: each is a call of the runtime's loop): x and y
    /// through the 32-bit divide (a value that does not fit 32 bits is beyond the wire's range), the
    /// heading through multiplications by reciprocals (`heading_counts`). The results are the
    /// exact formula's (`tests/odometry_exact.rs` compares them).
    pub fn from_micrometres(x_um: i64, y_um: i64, heading_urad: i64) -> Option<Odometry> {
        Odometry::new(
            hundred_micrometres(x_um)?,
            hundred_micrometres(y_um)?,
            heading_counts(heading_urad),
        )
    }

    /// x in 100 µm units.
    pub const fn x_100um(&self) -> i32 {
        self.x_100um
    }

    /// y in 100 µm units.
    pub const fn y_100um(&self) -> i32 {
        self.y_100um
    }

    /// Heading in 1/65536 turn.
    pub const fn heading(&self) -> u16 {
        self.heading
    }

    /// x in µm (exact: ±838 860 800 fits an i32).
    pub const fn x_um(&self) -> i32 {
        self.x_100um * 100
    }

    /// y in µm.
    pub const fn y_um(&self) -> i32 {
        self.y_100um * 100
    }

    /// Heading in µrad, 0..6 283 185, rounded to the nearest µrad.
    pub fn heading_urad(&self) -> u32 {
        // At most 6 283 185, so the cast is exact.
        round_div(
            i128::from(self.heading) * TURN_PICORAD,
            TURN_COUNTS * 1_000_000,
        ) as u32
    }

    /// Heading in hundredths of a degree, 0..36000, rounded.
    pub fn heading_centidegrees(&self) -> u32 {
        // At most 36 000, so the cast is exact.
        round_div(i128::from(self.heading) * 36_000, TURN_COUNTS) as u32
    }

    fn to_bytes(self) -> [u8; 8] {
        let [x0, x1, x2, _] = self.x_100um.to_le_bytes();
        let [y0, y1, y2, _] = self.y_100um.to_le_bytes();
        let [h0, h1] = self.heading.to_le_bytes();
        [x0, x1, x2, y0, y1, y2, h0, h1]
    }

    fn from_bytes(bytes: [u8; 8]) -> Odometry {
        let [x0, x1, x2, y0, y1, y2, h0, h1] = bytes;
        // Put the 24 bits at the top and shift back arithmetically to sign-extend.
        let x_100um = i32::from_le_bytes([0, x0, x1, x2]) >> 8;
        let y_100um = i32::from_le_bytes([0, y0, y1, y2]) >> 8;
        Odometry {
            x_100um,
            y_100um,
            heading: u16::from_le_bytes([h0, h1]),
        }
    }
}

/// `value_um / 100` rounded half away from zero, `None` where it does not fit an `i32` or the
/// wire's 24 bits anyway. A magnitude of 2³² or more is more than 42 949 672 hundreds, beyond the
/// wire's ±2²³ (and the exact quotient's `Odometry::new` refuses it): below that, one 32-bit divide.
fn hundred_micrometres(value_um: i64) -> Option<i32> {
    // |i64::MIN| + 50 fits a u64.
    let magnitude = u32::try_from(value_um.unsigned_abs() + 50).ok()? / 100;
    // At most 42 949 672: fits an i32 either way.
    let magnitude = magnitude as i32;
    Some(if value_um < 0 { -magnitude } else { magnitude })
}

/// An exact quotient and remainder by a constant `d` (2 ≤ d < 2⁶⁴) without a 64-bit division: one
/// multiply-high by the reciprocal `⌊2⁶⁴ / d⌋` (taken at compile time) and one correction. With
/// `R = ⌊2⁶⁴ / d⌋ > 2⁶⁴ / d − 1`, `q = ⌊n·R / 2⁶⁴⌋` is at most `n / d` and more than
/// `n / d − n / 2⁶⁴ > n / d − 1`: the quotient or one below it, so one step finishes it.
#[derive(Clone, Copy)]
struct ConstDivisor {
    d: u64,
    reciprocal: u64,
}

impl ConstDivisor {
    const fn new(d: u64) -> Self {
        assert!(d >= 2);
        ConstDivisor {
            d,
            reciprocal: ((1u128 << 64) / d as u128) as u64,
        }
    }

    /// `(n / d, n % d)`.
    #[inline(always)]
    fn div_rem(self, n: u64) -> (u64, u64) {
        let mut q = mul_high(n, self.reciprocal);
        // q ≤ n / d: no underflow.
        let mut r = n - q * self.d;
        if r >= self.d {
            q += 1;
            r -= self.d;
        }
        (q, r)
    }
}

/// The high 64 bits of `a × b`, from four 32 × 32 → 64-bit products (`UMULL`), not a 128-bit
/// multiply's runtime call.
#[inline(always)]
const fn mul_high(a: u64, b: u64) -> u64 {
    let (a0, a1) = (a & 0xFFFF_FFFF, a >> 32);
    let (b0, b1) = (b & 0xFFFF_FFFF, b >> 32);
    let low = a0 * b0;
    let cross_a = a1 * b0;
    let cross_b = a0 * b1;
    // At most 3 × (2³² − 1): no overflow.
    let middle = (low >> 32) + (cross_a & 0xFFFF_FFFF) + (cross_b & 0xFFFF_FFFF);
    a1 * b1 + (cross_a >> 32) + (cross_b >> 32) + (middle >> 32)
}

/// `M = TURN_PICORAD / 20` µrad: exactly 50 000 turns of 65536 counts.
const HEADING_M: u64 = (TURN_PICORAD / 20) as u64;
/// Division by `M`.
const BY_M: ConstDivisor = ConstDivisor::new(HEADING_M);
/// Division by `2M`.
const BY_2M: ConstDivisor = ConstDivisor::new(2 * HEADING_M);

/// `heading_urad × 65536 × 10⁶ / TURN_PICORAD`, rounded to the nearest count and wrapped into one turn,
/// without a 64-bit division: each of the three quotients is an exact [`ConstDivisor`] by a
/// constant (a 128-bit division is a loop of up to 128 passes the compiler writes inline, a
/// 64-bit one a call of the runtime's shift-and-subtract loop, 1 781 cycles at its worst).
///
/// `M` µrad are exactly 50 000 turns of 65536 counts, so the heading is reduced modulo `M` first
/// (`r`, of the magnitude, then mirrored for a negative heading: Euclid's remainder), then the
/// whole turns of `r × 50 000 / M` dropped (`u = r × 50 000 mod M`): what is left is
/// `65536 × u / M` counts, below 65536. No exact half occurs (`M` is odd and `u < M`), so rounding
/// to the nearest is the exact formula's rounding of halves away from zero.
fn heading_counts(heading_urad: i64) -> u16 {
    let (_, magnitude) = BY_M.div_rem(heading_urad.unsigned_abs());
    let r = if heading_urad < 0 && magnitude != 0 {
        HEADING_M - magnitude
    } else {
        magnitude
    };
    // r < M ≈ 3.1 × 10¹¹, r × 50 000 < 1.6 × 10¹⁶ and u × 131 072 + M < 4.2 × 10¹⁶: all within u64.
    let (_, u) = BY_M.div_rem(r * 50_000);
    let (counts, _) = BY_2M.div_rem(u * 2 * TURN_COUNTS as u64 + HEADING_M);
    // At most 65536 (one turn), which the cast wraps to 0 as the exact formula's rem_euclid does.
    counts as u16
}

/// Integer division rounding half away from zero; `d` is positive.
fn round_div(n: i128, d: i128) -> i128 {
    if n >= 0 {
        (n + d / 2) / d
    } else {
        (n - d / 2) / d
    }
}

/// Writes `value / 10^decimals` with exactly `decimals` digits after the point and the sign kept for −0.x.
fn fixed_point(f: &mut fmt::Formatter<'_>, value: i64, decimals: u32) -> fmt::Result {
    // `max(1)` lets the compiler see the divisor is never zero, so no panic path is generated.
    let scale = 10u64.pow(decimals).max(1);
    let magnitude = value.unsigned_abs();
    let sign = if value < 0 { "-" } else { "" };
    let width = decimals as usize;
    write!(
        f,
        "{sign}{}.{:0width$}",
        magnitude / scale,
        magnitude % scale
    )
}

impl fmt::Display for Odometry {
    /// `x=1234.5 mm y=-0.3 mm heading=90.00°`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("x=")?;
        fixed_point(f, i64::from(self.x_100um), 1)?;
        f.write_str(" mm y=")?;
        fixed_point(f, i64::from(self.y_100um), 1)?;
        f.write_str(" mm heading=")?;
        fixed_point(f, i64::from(self.heading_centidegrees()), 2)?;
        f.write_str("°")
    }
}

/// Measured velocity of the robot (topic `velocity`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Velocity {
    /// Forward velocity in µm/s (positive = forward).
    pub velocity_um_s: i32,
    /// Angular velocity about the vertical axis in µrad/s (positive = counter-clockwise seen from above).
    pub angular_urad_s: i32,
}

/// Battery state (topic `power-status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct PowerStatus {
    /// The charger is connected and charging.
    pub charging: bool,
    /// State of charge in percent, 0..=100.
    pub state_of_charge: u8,
    /// Minutes until full when charging, until empty otherwise.
    pub minutes: u16,
    /// Power drawn by the robot in mW.
    pub power_mw: u16,
}

impl PowerStatus {
    /// Which way the charge goes and where `minutes` ends: `("charging", "full")` or
    /// `("discharging", "empty")`, the words every display of this status uses.
    pub const fn direction(&self) -> (&'static str, &'static str) {
        if self.charging {
            ("charging", "full")
        } else {
            ("discharging", "empty")
        }
    }
}

impl fmt::Display for PowerStatus {
    /// `discharging, 62 %, 32806 min to empty, 31860 mW`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (state, until) = self.direction();
        write!(
            f,
            "{state}, {} %, {} min to {until}, {} mW",
            self.state_of_charge, self.minutes, self.power_mw
        )
    }
}

/// One sensor-data frame, decoded into wire units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SensorData {
    /// x, y, z angular rate in degrees per second.
    Gyroscope([i16; 3]),
    /// x, y, z acceleration in milli-g (1000 = 9.81 m/s²).
    Accelerometer([i16; 3]),
    /// One magnetometer axis in nanotesla.
    Magnetometer {
        /// Which axis (and so which topic).
        axis: Axis,
        /// Field strength in nT (1 gauss = 100 000 nT).
        nanotesla: i32,
    },
    /// The four floor sensors' raw VCNL4020 proximity counts (higher = more reflected light).
    FloorProximity([u16; 4]),
    /// Position and heading.
    Odometry(Odometry),
    /// Measured velocity.
    Velocity(Velocity),
    /// Battery state.
    PowerStatus(PowerStatus),
    /// One proximity-ring sensor's distance; a full ring sample is eight of these frames.
    ProximityRing {
        /// Sensor index 0..=7.
        sensor: u8,
        /// Distance in mm.
        mm: u16,
    },
    /// One page of a board's diagnostics topic: a part of a health sample, or half of an admission verdict.
    Diagnostics {
        /// The board (its diagnostics topic carries the frame).
        board: Board,
        /// The page.
        page: DiagnosticsPage,
    },
}

impl SensorData {
    /// The topic this data is published on.
    pub const fn topic(&self) -> Topic {
        match self {
            SensorData::Gyroscope(_) => Topic::Gyroscope,
            SensorData::Accelerometer(_) => Topic::Accelerometer,
            SensorData::Magnetometer { axis, .. } => axis.magnetometer_topic(),
            SensorData::FloorProximity(_) => Topic::FloorProximity,
            SensorData::Odometry(_) => Topic::Odometry,
            SensorData::Velocity(_) => Topic::Velocity,
            SensorData::PowerStatus(_) => Topic::PowerStatus,
            SensorData::ProximityRing { .. } => Topic::ProximityRing,
            SensorData::Diagnostics { board, .. } => board.diagnostics_topic(),
        }
    }

    /// The data frame (C/S = 1) with this priority. Never fails; a field out of range (ring sensor ≥ 8, state of
    /// charge > 100) gives a frame the decoder rejects; [`SensorData::validate`] checks first.
    pub fn encode(&self, priority: Priority) -> Frame {
        let topic = self.topic();
        let id = CanId::new(Kind::Sensor, priority, topic as u8);
        let data = match *self {
            SensorData::Gyroscope(v) | SensorData::Accelerometer(v) => three_i16(v),
            SensorData::Magnetometer { nanotesla, .. } => {
                let [a, b, c, d] = nanotesla.to_le_bytes();
                [a, b, c, d, 0, 0, 0, 0]
            }
            SensorData::FloorProximity([s1, s2, s3, s4]) => {
                let [a0, a1] = s1.to_le_bytes();
                let [b0, b1] = s2.to_le_bytes();
                let [c0, c1] = s3.to_le_bytes();
                let [d0, d1] = s4.to_le_bytes();
                [a0, a1, b0, b1, c0, c1, d0, d1]
            }
            SensorData::Odometry(o) => o.to_bytes(),
            SensorData::Velocity(v) => wire::two_i32(v.velocity_um_s, v.angular_urad_s),
            SensorData::PowerStatus(p) => {
                let [m0, m1] = p.minutes.to_le_bytes();
                let [p0, p1] = p.power_mw.to_le_bytes();
                [
                    u8::from(p.charging),
                    p.state_of_charge,
                    m0,
                    m1,
                    p0,
                    p1,
                    0,
                    0,
                ]
            }
            SensorData::ProximityRing { sensor, mm } => {
                let [d0, d1] = mm.to_le_bytes();
                [sensor, d0, d1, 0, 0, 0, 0, 0]
            }
            SensorData::Diagnostics { page, .. } => page.to_bytes(),
        };
        wire::frame(id, topic.dlc(), data)
    }

    /// Checks the fields the decoder checks.
    pub const fn validate(&self) -> Result<(), DecodeError> {
        match *self {
            SensorData::ProximityRing { sensor, .. } if sensor > 7 => {
                Err(DecodeError::SensorIndexOutOfRange { index: sensor })
            }
            SensorData::PowerStatus(PowerStatus {
                state_of_charge, ..
            }) if state_of_charge > 100 => Err(DecodeError::StateOfChargeOutOfRange {
                percent: state_of_charge,
            }),
            SensorData::Diagnostics { page, .. } => page.validate(),
            _ => Ok(()),
        }
    }

    /// Decodes the data of a sensor-data frame on `topic`. An actuator topic is
    /// [`DecodeError::SensorDataOnActuator`].
    pub fn decode(topic: Topic, data: &[u8]) -> Result<SensorData, DecodeError> {
        let k = Kind::Sensor;
        Ok(match topic {
            Topic::Gyroscope => {
                SensorData::Gyroscope(split_three_i16(wire::exact(topic, k, data)?))
            }
            Topic::Accelerometer => {
                SensorData::Accelerometer(split_three_i16(wire::exact(topic, k, data)?))
            }
            Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
                let axis = match topic {
                    Topic::MagnetometerX => Axis::X,
                    Topic::MagnetometerY => Axis::Y,
                    _ => Axis::Z,
                };
                SensorData::Magnetometer {
                    axis,
                    nanotesla: i32::from_le_bytes(wire::exact(topic, k, data)?),
                }
            }
            Topic::FloorProximity => {
                let [a0, a1, b0, b1, c0, c1, d0, d1] = wire::exact(topic, k, data)?;
                SensorData::FloorProximity([
                    u16::from_le_bytes([a0, a1]),
                    u16::from_le_bytes([b0, b1]),
                    u16::from_le_bytes([c0, c1]),
                    u16::from_le_bytes([d0, d1]),
                ])
            }
            Topic::Odometry => {
                SensorData::Odometry(Odometry::from_bytes(wire::exact(topic, k, data)?))
            }
            Topic::Velocity => {
                let (velocity_um_s, angular_urad_s) =
                    wire::split_two_i32(wire::exact(topic, k, data)?);
                SensorData::Velocity(Velocity {
                    velocity_um_s,
                    angular_urad_s,
                })
            }
            Topic::PowerStatus => {
                let [flag, state_of_charge, m0, m1, p0, p1] = wire::exact(topic, k, data)?;
                let charging = match flag {
                    0 => false,
                    1 => true,
                    value => return Err(DecodeError::BadChargingFlag { value }),
                };
                if state_of_charge > 100 {
                    return Err(DecodeError::StateOfChargeOutOfRange {
                        percent: state_of_charge,
                    });
                }
                SensorData::PowerStatus(PowerStatus {
                    charging,
                    state_of_charge,
                    minutes: u16::from_le_bytes([m0, m1]),
                    power_mw: u16::from_le_bytes([p0, p1]),
                })
            }
            Topic::ProximityRing => {
                let [sensor, d0, d1] = wire::exact(topic, k, data)?;
                if sensor > 7 {
                    return Err(DecodeError::SensorIndexOutOfRange { index: sensor });
                }
                SensorData::ProximityRing {
                    sensor,
                    mm: u16::from_le_bytes([d0, d1]),
                }
            }
            Topic::DiWheelDriveDiagnostics
            | Topic::PowerManagementDiagnostics
            | Topic::LightRingDiagnostics => {
                let board = topic.board();
                SensorData::Diagnostics {
                    board,
                    page: DiagnosticsPage::from_bytes(topic, wire::exact(topic, k, data)?)?,
                }
            }
            Topic::MotorCommand | Topic::Shutdown | led_topics!() => {
                return Err(DecodeError::SensorDataOnActuator { topic })
            }
        })
    }
}

fn three_i16([x, y, z]: [i16; 3]) -> [u8; 8] {
    let [x0, x1] = x.to_le_bytes();
    let [y0, y1] = y.to_le_bytes();
    let [z0, z1] = z.to_le_bytes();
    [x0, x1, y0, y1, z0, z1, 0, 0]
}

fn split_three_i16([x0, x1, y0, y1, z0, z1]: [u8; 6]) -> [i16; 3] {
    [
        i16::from_le_bytes([x0, x1]),
        i16::from_le_bytes([y0, y1]),
        i16::from_le_bytes([z0, z1]),
    ]
}

impl fmt::Display for SensorData {
    /// `gyroscope x=-4 y=30 z=5 dps`, `magnetometer-x 21000 nT`, `floor-proximity 310 295 12 980 counts`,
    /// `proximity-ring sensor 3: 120 mm`, ...
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let topic = self.topic();
        match self {
            SensorData::Gyroscope([x, y, z]) => write!(f, "{topic} x={x} y={y} z={z} dps"),
            SensorData::Accelerometer([x, y, z]) => write!(f, "{topic} x={x} y={y} z={z} milli-g"),
            SensorData::Magnetometer { nanotesla, .. } => write!(f, "{topic} {nanotesla} nT"),
            SensorData::FloorProximity([a, b, c, d]) => {
                write!(f, "{topic} {a} {b} {c} {d} counts")
            }
            SensorData::Odometry(o) => write!(f, "{topic} {o}"),
            SensorData::Velocity(v) => {
                write!(
                    f,
                    "{topic} {} µm/s, {} µrad/s",
                    v.velocity_um_s, v.angular_urad_s
                )
            }
            SensorData::PowerStatus(p) => write!(f, "{topic} {p}"),
            SensorData::ProximityRing { sensor, mm } => {
                write!(f, "{topic} sensor {sensor}: {mm} mm")
            }
            SensorData::Diagnostics { page, .. } => write!(f, "{topic} {page}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;

    /// The heading conversion in 64-bit arithmetic is the exact 128-bit formula: at the ends of the
    /// range, around every multiple of the reduction's 50 000 turns and of a turn, and across the range.
    #[test]
    fn heading_counts_match_the_exact_division() {
        let exact = |h: i64| {
            round_div(i128::from(h) * TURN_COUNTS * 1_000_000, TURN_PICORAD).rem_euclid(TURN_COUNTS)
                as u16
        };
        let m = (TURN_PICORAD / 20) as i64;
        let turn = 6_283_185i64;
        let mut cases = std::vec![i64::MIN, i64::MIN + 1, i64::MAX, i64::MAX - 1, 0, 1, -1];
        for k in [-3i64, -2, -1, 1, 2, 3, 1000, -1000] {
            for d in -3..=3 {
                cases.push(k * m + d);
                cases.push(k * turn + d);
                cases.push(k * (turn + 1) + d);
            }
        }
        // A deterministic spread over the whole range (a 64-bit LCG), and every µrad of one turn.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..200_000 {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            cases.push(x as i64);
            cases.push((x as i64) >> 20);
        }
        cases.extend(-turn..=2 * turn);
        for h in cases {
            assert_eq!(heading_counts(h), exact(h), "heading {h} µrad");
        }
    }

    #[test]
    fn odometry_i24_sign_extension() {
        let o = Odometry::new(-1, Odometry::MIN_100UM, 0xFFFF).unwrap();
        let bytes = o.to_bytes();
        assert_eq!(bytes, [0xFF, 0xFF, 0xFF, 0x00, 0x00, 0x80, 0xFF, 0xFF]);
        assert_eq!(Odometry::from_bytes(bytes), o);
        assert_eq!(Odometry::new(Odometry::MAX_100UM + 1, 0, 0), None);
        assert_eq!(Odometry::new(0, Odometry::MIN_100UM - 1, 0), None);
        let max = Odometry::new(Odometry::MAX_100UM, Odometry::MAX_100UM, 0).unwrap();
        assert_eq!(Odometry::from_bytes(max.to_bytes()), max);
    }

    #[test]
    fn odometry_unit_conversions() {
        let o = Odometry::from_micrometres(1_234_549, -50, 1_570_796).unwrap();
        assert_eq!(o.x_100um(), 12_345);
        assert_eq!(o.y_100um(), -1); // −50 µm rounds away from zero
        assert_eq!(o.heading(), 16_384); // π/2
        assert_eq!(o.heading_urad(), 1_570_796);
        assert_eq!(o.heading_centidegrees(), 9_000);
        assert_eq!(o.x_um(), 1_234_500);
        // Angles wrap into one turn in both directions.
        assert_eq!(
            Odometry::from_micrometres(0, 0, -1_570_796)
                .unwrap()
                .heading(),
            49_152
        );
        assert_eq!(
            Odometry::from_micrometres(0, 0, 6_283_185 + 1_570_796)
                .unwrap()
                .heading(),
            16_384
        );
        assert_eq!(
            Odometry::from_micrometres(0, 0, 6_283_185)
                .unwrap()
                .heading(),
            0
        );
        assert_eq!(Odometry::from_micrometres(838_860_800, 0, 0), None);
        assert_eq!(Odometry::from_micrometres(i64::MIN, 0, 0), None);
        assert!(Odometry::from_micrometres(0, 0, i64::MAX).is_some());
        // Every heading survives µrad and back.
        for h in 0..=u16::MAX {
            let o = Odometry::new(0, 0, h).unwrap();
            assert_eq!(
                Odometry::from_micrometres(0, 0, i64::from(o.heading_urad()))
                    .unwrap()
                    .heading(),
                h
            );
        }
    }

    #[test]
    fn display_has_units_and_signs() {
        assert_eq!(
            format!("{}", SensorData::Gyroscope([-4, 30, 5])),
            "gyroscope x=-4 y=30 z=5 dps"
        );
        assert_eq!(
            format!("{}", SensorData::Accelerometer([26, -2, 1038])),
            "accelerometer x=26 y=-2 z=1038 milli-g"
        );
        assert_eq!(
            format!(
                "{}",
                SensorData::Magnetometer {
                    axis: Axis::Y,
                    nanotesla: -21_000
                }
            ),
            "magnetometer-y -21000 nT"
        );
        let o = Odometry::new(12_345, -3, 16_384).unwrap();
        assert_eq!(
            format!("{}", SensorData::Odometry(o)),
            "odometry x=1234.5 mm y=-0.3 mm heading=90.00°"
        );
        let p = PowerStatus {
            charging: false,
            state_of_charge: 62,
            minutes: 327,
            power_mw: 3186,
        };
        assert_eq!(
            format!("{}", SensorData::PowerStatus(p)),
            "power-status discharging, 62 %, 327 min to empty, 3186 mW"
        );
        assert_eq!(
            format!("{}", SensorData::ProximityRing { sensor: 3, mm: 120 }),
            "proximity-ring sensor 3: 120 mm"
        );
        assert_eq!(
            format!("{}", SensorData::FloorProximity([1, 2, 3, 65535])),
            "floor-proximity 1 2 3 65535 counts"
        );
        assert_eq!(
            format!(
                "{}",
                SensorData::Velocity(Velocity {
                    velocity_um_s: -5,
                    angular_urad_s: 7
                })
            ),
            "velocity -5 µm/s, 7 µrad/s"
        );
    }
}
