//! Simulated L3G4200D gyroscope and LIS331DLH accelerometer, each its own `SpiDevice`.

use core::convert::Infallible;

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use super::{st_spi_transaction, stick_miso, triangle, StRegisters};
use crate::drivers::{l3g4200d, lis331dlh};

/// A simulated L3G4200D.
///
/// Pattern (millidegrees per second, one step per burst read of the outputs): X a ±30 dps
/// triangle over 400 samples, Y 5 dps plus a ±2 dps triangle over 100, Z a ±90 dps triangle over
/// 1000 — a slow yaw. Outputs read zero while the part is powered down or an axis is disabled, and
/// are encoded at the full scale CTRL_REG4 selects. [`SimGyroscope::set_rate`] replaces the pattern
/// with a rate from outside (a world's robot turning).
#[derive(Debug, Clone)]
pub struct SimGyroscope {
    control: [u8; 5],
    samples: u32,
    latched: [i16; 3],
    ignored_writes: u8,
    stuck_miso: Option<u8>,
    input_mdps: Option<[i32; 3]>,
}

impl SimGyroscope {
    /// At power-on: control registers at their reset value (powered down).
    pub const fn new() -> Self {
        Self {
            control: [0x07, 0, 0, 0, 0],
            samples: 0,
            latched: [0; 3],
            ignored_writes: 0,
            stuck_miso: None,
            input_mdps: None,
        }
    }

    /// From now on the part measures this angular rate (millidegrees per second, x y z), encoded
    /// as the pattern would be; `None` goes back to the pattern.
    pub fn set_rate(&mut self, mdps: Option<[i32; 3]>) {
        self.input_mdps = mdps;
    }

    /// CTRL_REG1..5 as the host last wrote them.
    pub const fn control_registers(&self) -> [u8; 5] {
        self.control
    }

    /// Whether the host configured the AMiRo set-up (100 Hz, XYZ, DRDY on INT2, ±500 dps).
    pub const fn is_configured_for_amiro(&self) -> bool {
        self.control[0] == l3g4200d::CTRL_REG1_RUN
            && self.control[2] == l3g4200d::CTRL_REG3_DRDY_INT2
            && self.control[3] == l3g4200d::Range::Dps500.ctrl_reg4()
    }

    /// Fault injection: `Some(level)` makes every byte the host reads `level` (MISO stuck low
    /// with 0x00, high with 0xFF) from now on; `None` repairs the line.
    pub fn set_stuck_miso(&mut self, level: Option<u8>) {
        self.stuck_miso = level;
    }

    /// Burst reads of the outputs so far.
    pub const fn samples(&self) -> u32 {
        self.samples
    }

    /// Writes to read-only or reserved registers (the real part ignores them too).
    pub const fn ignored_writes(&self) -> u8 {
        self.ignored_writes
    }

    /// The simulated angular rate at sample `n` in millidegrees per second.
    pub const fn rate_at(n: u32) -> [i32; 3] {
        [
            triangle(n, 400, 30_000),
            5_000 + triangle(n, 100, 2_000),
            triangle(n, 1000, 90_000),
        ]
    }

    fn micro_dps_per_digit(&self) -> i64 {
        match self.control[3] & 0x30 {
            0x00 => 8_750,
            0x10 => 17_500,
            _ => 70_000,
        }
    }

    fn latch(&mut self) {
        let ctrl1 = self.control[0];
        let powered = ctrl1 & 0x08 != 0;
        let rate = match self.input_mdps {
            Some(rate) => rate,
            None => Self::rate_at(self.samples),
        };
        let s = self.micro_dps_per_digit();
        for (axis, (out, mdps)) in self.latched.iter_mut().zip(rate).enumerate() {
            let enabled = ctrl1 & (1 << axis) != 0;
            *out = if powered && enabled {
                crate::drivers::div_round(i64::from(mdps) * 1000, s) as i16
            } else {
                0
            };
        }
        if powered {
            self.samples = self.samples.wrapping_add(1);
        }
    }
}

impl Default for SimGyroscope {
    fn default() -> Self {
        Self::new()
    }
}

impl StRegisters for SimGyroscope {
    fn read_register(&mut self, register: u8) -> u8 {
        match register {
            l3g4200d::reg::WHO_AM_I => l3g4200d::WHO_AM_I_VALUE,
            0x20..=0x24 => self.control[usize::from(register - 0x20)],
            l3g4200d::reg::OUT_TEMP => 25,
            l3g4200d::reg::STATUS_REG if self.control[0] & 0x08 != 0 => 0x0F,
            0x28..=0x2D => {
                if register == l3g4200d::reg::OUT_X_L {
                    self.latch();
                }
                let i = usize::from(register - 0x28);
                let word = self.latched[i / 2].to_le_bytes();
                word[i % 2]
            }
            _ => 0,
        }
    }

    fn write_register(&mut self, register: u8, value: u8) {
        match register {
            0x20..=0x24 => self.control[usize::from(register - 0x20)] = value,
            _ => self.ignored_writes = self.ignored_writes.saturating_add(1),
        }
    }
}

impl ErrorType for SimGyroscope {
    type Error = Infallible;
}

impl SpiDevice for SimGyroscope {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        st_spi_transaction(self, operations)?;
        if let Some(level) = self.stuck_miso {
            stick_miso(level, operations);
        }
        Ok(())
    }
}

/// A simulated LIS331DLH.
///
/// Pattern (micro-g, one step per burst read of the outputs): the robot standing level with a
/// little vibration — X a ±50 mg triangle over 200 samples, Y ±30 mg over 300, Z 1 g plus ±20 mg
/// over 50. Encoded as 12 bits left-justified at the full scale CTRL_REG4 selects; outputs read
/// zero while powered down. [`SimAccelerometer::set_acceleration`] replaces the pattern with an
/// acceleration from outside.
#[derive(Debug, Clone)]
pub struct SimAccelerometer {
    control: [u8; 5],
    samples: u32,
    latched: [i16; 3],
    ignored_writes: u8,
    stuck_miso: Option<u8>,
    input_ug: Option<[i32; 3]>,
}

impl SimAccelerometer {
    /// At power-on: control registers at their reset value (powered down).
    pub const fn new() -> Self {
        Self {
            control: [0x07, 0, 0, 0, 0],
            samples: 0,
            latched: [0; 3],
            ignored_writes: 0,
            stuck_miso: None,
            input_ug: None,
        }
    }

    /// From now on the part measures this acceleration (micro-g, x y z, gravity included);
    /// `None` goes back to the pattern.
    pub fn set_acceleration(&mut self, ug: Option<[i32; 3]>) {
        self.input_ug = ug;
    }

    /// CTRL_REG1..5 as the host last wrote them.
    pub const fn control_registers(&self) -> [u8; 5] {
        self.control
    }

    /// Whether the host configured the AMiRo set-up (normal mode 50 Hz, XYZ, ±8 g).
    pub const fn is_configured_for_amiro(&self) -> bool {
        self.control[0] == lis331dlh::CTRL_REG1_RUN
            && self.control[2] == lis331dlh::CTRL_REG3_DRDY_INT1
            && self.control[3] == lis331dlh::Range::G8.ctrl_reg4()
    }

    /// Fault injection: `Some(level)` makes every byte the host reads `level` (MISO stuck low
    /// with 0x00, high with 0xFF) from now on; `None` repairs the line.
    pub fn set_stuck_miso(&mut self, level: Option<u8>) {
        self.stuck_miso = level;
    }

    /// Burst reads of the outputs so far.
    pub const fn samples(&self) -> u32 {
        self.samples
    }

    /// Writes to read-only or reserved registers.
    pub const fn ignored_writes(&self) -> u8 {
        self.ignored_writes
    }

    /// The simulated acceleration at sample `n` in micro-g.
    pub const fn acceleration_at(n: u32) -> [i32; 3] {
        [
            triangle(n, 200, 50_000),
            triangle(n, 300, 30_000),
            1_000_000 + triangle(n, 50, 20_000),
        ]
    }

    fn micro_g_per_digit(&self) -> i64 {
        match self.control[3] & 0x30 {
            0x00 => 1_000,
            0x10 => 2_000,
            _ => 3_900,
        }
    }

    fn latch(&mut self) {
        let ctrl1 = self.control[0];
        let powered = ctrl1 & 0xE0 != 0;
        let accel = match self.input_ug {
            Some(accel) => accel,
            None => Self::acceleration_at(self.samples),
        };
        let s = self.micro_g_per_digit();
        for (axis, (out, ug)) in self.latched.iter_mut().zip(accel).enumerate() {
            let enabled = ctrl1 & (1 << axis) != 0;
            let digits = crate::drivers::div_round(i64::from(ug), s).clamp(-2048, 2047);
            *out = if powered && enabled {
                (digits as i16) << 4
            } else {
                0
            };
        }
        if powered {
            self.samples = self.samples.wrapping_add(1);
        }
    }
}

impl Default for SimAccelerometer {
    fn default() -> Self {
        Self::new()
    }
}

impl StRegisters for SimAccelerometer {
    fn read_register(&mut self, register: u8) -> u8 {
        match register {
            lis331dlh::reg::WHO_AM_I => lis331dlh::WHO_AM_I_VALUE,
            0x20..=0x24 => self.control[usize::from(register - 0x20)],
            lis331dlh::reg::STATUS_REG if self.control[0] & 0xE0 != 0 => 0x0F,
            0x28..=0x2D => {
                if register == lis331dlh::reg::OUT_X_L {
                    self.latch();
                }
                let i = usize::from(register - 0x28);
                let word = self.latched[i / 2].to_le_bytes();
                word[i % 2]
            }
            _ => 0,
        }
    }

    fn write_register(&mut self, register: u8, value: u8) {
        match register {
            // CTRL_REG2 BOOT (bit 7) reloads the trimming and clears itself.
            lis331dlh::reg::CTRL_REG2 => self.control[1] = value & 0x7F,
            0x20..=0x24 => self.control[usize::from(register - 0x20)] = value,
            _ => self.ignored_writes = self.ignored_writes.saturating_add(1),
        }
    }
}

impl ErrorType for SimAccelerometer {
    type Error = Infallible;
}

impl SpiDevice for SimAccelerometer {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        st_spi_transaction(self, operations)?;
        if let Some(level) = self.stuck_miso {
            stick_miso(level, operations);
        }
        Ok(())
    }
}
