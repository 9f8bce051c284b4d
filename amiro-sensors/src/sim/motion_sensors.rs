//! Simulated L3G4200D gyroscope and LIS331DLH accelerometer, each its own `SpiDevice`.
//!
//! The two ST parts share their register layout (WHO_AM_I, CTRL_REG1..5, STATUS_REG, six output
//! bytes from 0x28), the SPI framing and what a simulator does with them: one [`SimStSensor`]
//! holds that, and a part ([`StPart`]: [`Gyroscope`], [`Accelerometer`]) says only what differs —
//! its identity, which CTRL_REG1 bits power it, its pattern and how a value is encoded at the range
//! CTRL_REG4 selects.

use core::convert::Infallible;
use core::marker::PhantomData;

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use super::{st_spi_transaction, stick_miso, triangle, StRegisters};
use crate::drivers::{l3g4200d, lis331dlh};

// The register map both parts share (checked against both drivers' maps).
const WHO_AM_I: u8 = l3g4200d::reg::WHO_AM_I;
const CTRL_REG1: u8 = l3g4200d::reg::CTRL_REG1;
const CTRL_REG5: u8 = l3g4200d::reg::CTRL_REG5;
const STATUS_REG: u8 = l3g4200d::reg::STATUS_REG;
const OUT_X_L: u8 = l3g4200d::reg::OUT_X_L;
const _: () = assert!(
    WHO_AM_I == lis331dlh::reg::WHO_AM_I
        && CTRL_REG1 == lis331dlh::reg::CTRL_REG1
        && CTRL_REG5 == lis331dlh::reg::CTRL_REG5
        && STATUS_REG == lis331dlh::reg::STATUS_REG
        && OUT_X_L == lis331dlh::reg::OUT_X_L
);

/// What one simulated ST part does differently from the other.
pub trait StPart {
    /// What WHO_AM_I reads.
    const WHO_AM_I: u8;
    /// The CTRL_REG1 bits of which at least one is set while the part is powered.
    const POWER_BITS: u8;
    /// The pattern: the measured value (x, y, z, in the part's unit) at sample `n`.
    fn pattern(n: u32) -> [i32; 3];
    /// The output registers' value of `value` at the range CTRL_REG4 (`ctrl4`) selects.
    fn encode(value: i32, ctrl4: u8) -> i16;
    /// Whether `control` (CTRL_REG1..5) is the AMiRo set-up.
    fn configured_for_amiro(control: &[u8; 5]) -> bool;
    /// A register only this part has (`None`: reads zero).
    fn own_register(register: u8) -> Option<u8> {
        let _ = register;
        None
    }
    /// What a write of `value` to control register `index` (0 = CTRL_REG1) leaves there.
    fn control_written(index: usize, value: u8) -> u8 {
        let _ = index;
        value
    }
}

/// The L3G4200D, in millidegrees per second.
///
/// Pattern (one step per burst read of the outputs): X a ±30 dps triangle over 400 samples, Y
/// 5 dps plus a ±2 dps triangle over 100, Z a ±90 dps triangle over 1000 — a slow yaw. Outputs read
/// zero while the part is powered down or an axis is disabled; the temperature reads 25.
#[derive(Debug, Clone, Copy)]
pub struct Gyroscope;

impl StPart for Gyroscope {
    const WHO_AM_I: u8 = l3g4200d::WHO_AM_I_VALUE;
    const POWER_BITS: u8 = 0x08;

    fn pattern(n: u32) -> [i32; 3] {
        [
            triangle(n, 400, 30_000),
            5_000 + triangle(n, 100, 2_000),
            triangle(n, 1000, 90_000),
        ]
    }

    fn encode(mdps: i32, ctrl4: u8) -> i16 {
        let micro_dps_per_digit = match ctrl4 & 0x30 {
            0x00 => 8_750,
            0x10 => 17_500,
            _ => 70_000,
        };
        crate::drivers::div_round(i64::from(mdps) * 1000, micro_dps_per_digit) as i16
    }

    /// 100 Hz, XYZ, data ready on INT2, ±500 dps.
    fn configured_for_amiro(control: &[u8; 5]) -> bool {
        control[0] == l3g4200d::CTRL_REG1_RUN
            && control[2] == l3g4200d::CTRL_REG3_DRDY_INT2
            && control[3] == l3g4200d::Range::Dps500.ctrl_reg4()
    }

    fn own_register(register: u8) -> Option<u8> {
        (register == l3g4200d::reg::OUT_TEMP).then_some(25)
    }
}

/// The LIS331DLH, in micro-g.
///
/// Pattern (one step per burst read of the outputs): the robot standing level with a little
/// vibration — X a ±50 mg triangle over 200 samples, Y ±30 mg over 300, Z 1 g plus ±20 mg over 50.
/// Encoded as 12 bits left-justified; CTRL_REG2's BOOT bit clears itself.
#[derive(Debug, Clone, Copy)]
pub struct Accelerometer;

impl StPart for Accelerometer {
    const WHO_AM_I: u8 = lis331dlh::WHO_AM_I_VALUE;
    const POWER_BITS: u8 = 0xE0;

    fn pattern(n: u32) -> [i32; 3] {
        [
            triangle(n, 200, 50_000),
            triangle(n, 300, 30_000),
            1_000_000 + triangle(n, 50, 20_000),
        ]
    }

    fn encode(ug: i32, ctrl4: u8) -> i16 {
        let micro_g_per_digit = match ctrl4 & 0x30 {
            0x00 => 1_000,
            0x10 => 2_000,
            _ => 3_900,
        };
        let digits = crate::drivers::div_round(i64::from(ug), micro_g_per_digit).clamp(-2048, 2047);
        (digits as i16) << 4
    }

    /// Normal mode 50 Hz, XYZ, data ready on INT1, ±8 g.
    fn configured_for_amiro(control: &[u8; 5]) -> bool {
        control[0] == lis331dlh::CTRL_REG1_RUN
            && control[2] == lis331dlh::CTRL_REG3_DRDY_INT1
            && control[3] == lis331dlh::Range::G8.ctrl_reg4()
    }

    fn control_written(index: usize, value: u8) -> u8 {
        // CTRL_REG2 BOOT (bit 7) reloads the trimming and clears itself.
        if index == 1 {
            value & 0x7F
        } else {
            value
        }
    }
}

/// A simulated ST SPI part (see the parts for their patterns). Outputs are encoded at the full
/// scale CTRL_REG4 selects; [`SimStSensor::set_measured`] replaces the pattern with a value from
/// outside (a world's robot turning or accelerating).
#[derive(Debug, Clone)]
pub struct SimStSensor<P> {
    control: [u8; 5],
    samples: u32,
    latched: [i16; 3],
    ignored_writes: u8,
    stuck_miso: Option<u8>,
    input: Option<[i32; 3]>,
    part: PhantomData<P>,
}

/// A simulated L3G4200D.
pub type SimGyroscope = SimStSensor<Gyroscope>;
/// A simulated LIS331DLH.
pub type SimAccelerometer = SimStSensor<Accelerometer>;

impl<P: StPart> SimStSensor<P> {
    /// At power-on: control registers at their reset value (powered down).
    pub const fn new() -> Self {
        Self {
            control: [0x07, 0, 0, 0, 0],
            samples: 0,
            latched: [0; 3],
            ignored_writes: 0,
            stuck_miso: None,
            input: None,
            part: PhantomData,
        }
    }

    /// From now on the part measures this (x y z in its unit: millidegrees per second for the
    /// gyroscope, micro-g, gravity included, for the accelerometer), encoded as the pattern would
    /// be; `None` goes back to the pattern.
    pub fn set_measured(&mut self, value: Option<[i32; 3]>) {
        self.input = value;
    }

    /// The pattern's value at sample `n`, in the part's unit.
    pub fn pattern_at(n: u32) -> [i32; 3] {
        P::pattern(n)
    }

    /// CTRL_REG1..5 as the host last wrote them.
    pub const fn control_registers(&self) -> [u8; 5] {
        self.control
    }

    /// Whether the host configured the AMiRo set-up.
    pub fn is_configured_for_amiro(&self) -> bool {
        P::configured_for_amiro(&self.control)
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

    const fn powered(&self) -> bool {
        self.control[0] & P::POWER_BITS != 0
    }

    fn latch(&mut self) {
        let ctrl1 = self.control[0];
        let powered = self.powered();
        let value = self.input.unwrap_or_else(|| P::pattern(self.samples));
        for (axis, (out, v)) in self.latched.iter_mut().zip(value).enumerate() {
            let enabled = ctrl1 & (1 << axis) != 0;
            *out = if powered && enabled {
                P::encode(v, self.control[3])
            } else {
                0
            };
        }
        if powered {
            self.samples = self.samples.wrapping_add(1);
        }
    }
}

impl<P: StPart> Default for SimStSensor<P> {
    fn default() -> Self {
        Self::new()
    }
}

impl<P: StPart> StRegisters for SimStSensor<P> {
    fn read_register(&mut self, register: u8) -> u8 {
        match register {
            WHO_AM_I => P::WHO_AM_I,
            CTRL_REG1..=CTRL_REG5 => self.control[usize::from(register - CTRL_REG1)],
            STATUS_REG if self.powered() => 0x0F,
            OUT_X_L..=0x2D => {
                if register == OUT_X_L {
                    self.latch();
                }
                let i = usize::from(register - OUT_X_L);
                let word = self.latched[i / 2].to_le_bytes();
                word[i % 2]
            }
            _ => P::own_register(register).unwrap_or(0),
        }
    }

    fn write_register(&mut self, register: u8, value: u8) {
        match register {
            CTRL_REG1..=CTRL_REG5 => {
                let index = usize::from(register - CTRL_REG1);
                self.control[index] = P::control_written(index, value);
            }
            _ => self.ignored_writes = self.ignored_writes.saturating_add(1),
        }
    }
}

impl<P> ErrorType for SimStSensor<P> {
    type Error = Infallible;
}

impl<P: StPart> SpiDevice for SimStSensor<P> {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        st_spi_transaction(self, operations)?;
        if let Some(level) = self.stuck_miso {
            stick_miso(level, operations);
        }
        Ok(())
    }
}
