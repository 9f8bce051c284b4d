//! Simulated BNO055 (I2C 0x28): a DiWheelDrive 1-2 standing still on a level floor in Bielefeld.

use super::{I2cTarget, SimBus};
use crate::drivers::bno055::{self, mode, reg};

/// The geomagnetic field in Bielefeld (about 52.0° N, 8.5° E): total intensity about 49 µT,
/// inclination about 67° (the field points 67° below the horizontal, to magnetic north).
pub const FIELD_TOTAL_NT: i32 = 49_000;
/// Horizontal component, 49 µT × cos 67°.
pub const FIELD_HORIZONTAL_NT: i32 = 19_146;
/// Vertical component (downwards), 49 µT × sin 67°.
pub const FIELD_DOWN_NT: i32 = 45_105;
/// Gravity as the accelerometer of a part lying flat, face up, reads it: +1 g on Z.
pub const GRAVITY_MG: i32 = 1_000;
/// The gyroscope's zero-rate offsets in 1/16 °/s digits: a part at rest does not read exactly
/// zero (datasheet: offset within ±1 °/s).
pub const GYRO_OFFSET_DIGITS: [i16; 3] = [-3, 2, 1];

/// How the simulated part fails (fault injection).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Bno055Fault {
    /// A working part.
    #[default]
    None,
    /// Nothing answers at 0x28 (not fitted, no power, held in reset).
    Absent,
    /// SDA held low: every address is acknowledged and every byte reads 0x00.
    StuckLow,
    /// The part answers but its power-on self-test failed (gyroscope bit clear in ST_RESULT).
    SelfTestFailed,
}

/// What the BNO055 measures when it is fed from outside ([`SimBno055::set_motion`]), in the units
/// of [`SimBno055::physical_at`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Bno055Motion {
    /// Acceleration including gravity, mg, x y z.
    pub accel_mg: [i32; 3],
    /// Magnetic field, nT, x y z.
    pub field_nt: [i32; 3],
    /// Angular rate, 1/16 °/s digits, x y z.
    pub rate_digits: [i32; 3],
}

/// A simulated BNO055.
///
/// The robot stands still, level, facing magnetic north, the part flat and face up (its Z axis
/// up, X forward): the accelerometer reads (0, 0, +1000) mg, the magnetometer
/// (19.1, 0, −45.1) µT (the Bielefeld field, see [`FIELD_TOTAL_NT`]) and the gyroscope its small
/// zero-rate offset; each axis carries a deterministic ±1-digit dither that steps with every data
/// burst. Encodings are the datasheet's: accelerometer 1 mg per digit with UNIT_SEL bit 0 set (else
/// 0.01 m/s²), gyroscope 1/16 °/s (or 1/900 rad/s with UNIT_SEL bit 1), magnetometer 1/16 µT;
/// all little-endian from 0x08 in the order accelerometer, magnetometer, gyroscope.
///
/// Register behaviour: two pages (PAGE_ID at 0x07 on both); the pointer auto-increments; the
/// page-1 sensor configuration and UNIT_SEL take writes only in configuration mode (as on the
/// part), so a driver that skips configuration mode reads back the defaults; data registers read
/// zero in configuration mode; the identities, ST_RESULT and SYS_STATUS answer as the datasheet
/// says. A burst that starts in the data registers latches a new sample. [`SimBno055::set_motion`]
/// replaces the robot at rest with a motion from outside (a world's robot driving).
#[derive(Debug, Clone)]
pub struct SimBno055 {
    page: u8,
    opr_mode: u8,
    pwr_mode: u8,
    unit_sel: u8,
    /// Page 1 ACC_CONFIG, MAG_CONFIG, GYR_CONFIG_0, GYR_CONFIG_1.
    sensor_config: [u8; 4],
    pointer: u8,
    expect_pointer: bool,
    samples: u32,
    latched: [u8; 18],
    fault: Bno055Fault,
    mode_switches: u32,
    input: Option<Bno055Motion>,
}

impl SimBno055 {
    /// At power-on: configuration mode, datasheet register defaults.
    pub const fn new() -> Self {
        Self {
            page: 0,
            opr_mode: mode::CONFIG,
            pwr_mode: 0,
            unit_sel: 0x80,
            sensor_config: [0x0D, 0x6D, 0x38, 0x00],
            pointer: 0,
            expect_pointer: false,
            samples: 0,
            latched: [0; 18],
            fault: Bno055Fault::None,
            mode_switches: 0,
            input: None,
        }
    }

    /// From now on the part measures `motion` (each burst encodes it as the pattern would be);
    /// `None` goes back to the robot at rest.
    pub fn set_motion(&mut self, motion: Option<Bno055Motion>) {
        self.input = motion;
    }

    /// Fault injection from now on.
    pub fn set_fault(&mut self, fault: Bno055Fault) {
        self.fault = fault;
    }

    /// The injected fault.
    pub const fn fault(&self) -> Bno055Fault {
        self.fault
    }

    /// The operating mode the host set.
    pub const fn operating_mode(&self) -> u8 {
        self.opr_mode
    }

    /// Page-1 sensor configuration (ACC, MAG, GYR_0, GYR_1) as it holds now.
    pub const fn sensor_config(&self) -> [u8; 4] {
        self.sensor_config
    }

    /// Whether the host configured the AMiRo set-up (AMG mode, mg, the ranges of the driver).
    pub const fn is_configured_for_amiro(&self) -> bool {
        self.opr_mode == mode::AMG
            && self.unit_sel & 0x03 == bno055::UNIT_SEL_AMIRO
            && self.sensor_config[0] == bno055::ACC_CONFIG_AMIRO
            && self.sensor_config[1] == bno055::MAG_CONFIG_AMIRO
            && self.sensor_config[2] == bno055::GYR_CONFIG_0_AMIRO
    }

    /// Data bursts latched so far.
    pub const fn samples(&self) -> u32 {
        self.samples
    }

    /// How often the host changed the operating mode.
    pub const fn mode_switches(&self) -> u32 {
        self.mode_switches
    }

    /// The simulated physical sample `n`: acceleration in mg, field in nT, rate in 1/16 °/s
    /// digits (X, Y, Z each), before encoding.
    pub const fn physical_at(n: u32) -> ([i32; 3], [i32; 3], [i32; 3]) {
        // ±1 digit in a four-sample cycle, shifted per axis.
        const fn dither(n: u32, axis: u32) -> i32 {
            match (n + axis) % 4 {
                1 => 1,
                3 => -1,
                _ => 0,
            }
        }
        (
            [dither(n, 0), dither(n, 1), GRAVITY_MG + dither(n, 2)],
            [
                FIELD_HORIZONTAL_NT + 62 * dither(n, 1),
                62 * dither(n, 2),
                -FIELD_DOWN_NT + 62 * dither(n, 3),
            ],
            [
                GYRO_OFFSET_DIGITS[0] as i32 + dither(n, 3),
                GYRO_OFFSET_DIGITS[1] as i32 + dither(n, 0),
                GYRO_OFFSET_DIGITS[2] as i32 + dither(n, 1),
            ],
        )
    }

    fn measuring(&self) -> bool {
        self.opr_mode != mode::CONFIG
    }

    fn latch(&mut self) {
        if !self.measuring() {
            self.latched = [0; 18];
            return;
        }
        let (accel, field, rate) = match self.input {
            Some(m) => (m.accel_mg, m.field_nt, m.rate_digits),
            None => Self::physical_at(self.samples),
        };
        let clamp = |v: i64| v.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16;
        let mut words = [0i16; 9];
        for axis in 0..3 {
            let mg = i64::from(accel[axis]);
            // 1 mg per digit, or 0.01 m/s² (1 g = 9.80665 m/s² = 980.665 digits).
            words[axis] = if self.unit_sel & 0x01 != 0 {
                clamp(mg)
            } else {
                clamp(crate::drivers::div_round(mg * 980_665, 1_000_000))
            };
            words[3 + axis] = clamp(crate::drivers::div_round(
                i64::from(field[axis]) * bno055::MAG_LSB_PER_MICROTESLA,
                1000,
            ));
            // 16 digits per °/s, or 900 per rad/s (1 °/s = π/180 rad/s).
            let digits = i64::from(rate[axis]);
            words[6 + axis] = if self.unit_sel & 0x02 != 0 {
                clamp(crate::drivers::div_round(
                    digits * 900 * 314_159,
                    16 * 180 * 100_000,
                ))
            } else {
                clamp(digits)
            };
        }
        for (slot, word) in self.latched.chunks_exact_mut(2).zip(words) {
            slot.copy_from_slice(&word.to_le_bytes());
        }
        self.samples = self.samples.wrapping_add(1);
    }

    fn read_register(&self, register: u8) -> u8 {
        if register == reg::PAGE_ID {
            return self.page;
        }
        if self.page == 1 {
            return match register {
                0x08..=0x0B => self.sensor_config[usize::from(register - 0x08)],
                _ => 0,
            };
        }
        match register {
            0x00..=0x03 => bno055::IDENTITY[usize::from(register)],
            0x04 => 0x11, // software revision 0x0311
            0x05 => 0x03,
            0x06 => 0x15, // bootloader revision
            0x08..=0x19 => self.latched[usize::from(register - 0x08)],
            reg::ST_RESULT => {
                if self.fault == Bno055Fault::SelfTestFailed {
                    bno055::SELF_TEST_PASSED & !0x04
                } else {
                    bno055::SELF_TEST_PASSED
                }
            }
            reg::SYS_STATUS => match self.opr_mode {
                mode::CONFIG => 0,
                m if m >= mode::IMUPLUS => 5,
                _ => 6,
            },
            reg::UNIT_SEL => self.unit_sel,
            reg::OPR_MODE => self.opr_mode,
            reg::PWR_MODE => self.pwr_mode,
            0x41 => 0x24, // AXIS_MAP_CONFIG default
            _ => 0,
        }
    }

    fn write_register(&mut self, register: u8, value: u8) {
        if register == reg::PAGE_ID {
            self.page = value & 0x01;
            return;
        }
        let config = !self.measuring();
        if self.page == 1 {
            if config && (0x08..=0x0B).contains(&register) {
                let masks = [0xFF, 0x7F, 0x3F, 0x07];
                let i = usize::from(register - 0x08);
                self.sensor_config[i] = value & masks[i];
            }
            return;
        }
        match register {
            reg::OPR_MODE => {
                let next = value & 0x0F;
                if next != self.opr_mode {
                    self.mode_switches = self.mode_switches.wrapping_add(1);
                }
                self.opr_mode = next;
                if !self.measuring() {
                    self.latched = [0; 18];
                }
            }
            reg::PWR_MODE if config => self.pwr_mode = value & 0x03,
            reg::UNIT_SEL if config => self.unit_sel = value & 0x97,
            reg::SYS_TRIGGER if value & 0x20 != 0 => {
                // System reset: back to the power-on state (faults stay injected).
                let fault = self.fault;
                let switches = self.mode_switches;
                let input = self.input;
                *self = Self::new();
                self.fault = fault;
                self.mode_switches = switches;
                // The world outside does not reset with the part.
                self.input = input;
            }
            _ => {}
        }
    }
}

impl Default for SimBno055 {
    fn default() -> Self {
        Self::new()
    }
}

impl I2cTarget for SimBno055 {
    fn acknowledges(&self, address: u8) -> bool {
        match self.fault {
            Bno055Fault::Absent => false,
            // A stuck SDA line "acknowledges" whatever address is sent.
            Bno055Fault::StuckLow => true,
            _ => address == bno055::ADDRESS,
        }
    }

    fn start(&mut self, _address: u8, read: bool) {
        self.expect_pointer = !read;
        if read
            && self.page == 0
            && (reg::ACC_DATA_X_LSB..=0x19).contains(&self.pointer)
            && self.fault != Bno055Fault::StuckLow
        {
            self.latch();
        }
    }

    fn write_byte(&mut self, _address: u8, byte: u8) {
        if self.fault == Bno055Fault::StuckLow {
            return;
        }
        if self.expect_pointer {
            self.pointer = byte;
            self.expect_pointer = false;
            return;
        }
        self.write_register(self.pointer, byte);
        self.pointer = self.pointer.wrapping_add(1) & 0x7F;
    }

    fn read_byte(&mut self, _address: u8) -> u8 {
        if self.fault == Bno055Fault::StuckLow {
            return 0x00;
        }
        let value = self.read_register(self.pointer);
        self.pointer = self.pointer.wrapping_add(1) & 0x7F;
        value
    }
}

/// DiWheelDrive 1-2's I2C1 with its BNO055.
pub type SimImuBus = SimBus<SimBno055>;

impl SimBus<SimBno055> {
    /// DiWheelDrive 1-2's I2C1: a BNO055 just out of reset.
    pub const fn new() -> Self {
        Self::with(SimBno055::new())
    }

    /// The simulated part.
    pub const fn imu(&self) -> &SimBno055 {
        &self.target
    }

    /// The simulated part, e.g. to inject a fault.
    pub fn imu_mut(&mut self) -> &mut SimBno055 {
        &mut self.target
    }
}
