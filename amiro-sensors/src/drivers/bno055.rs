//! Bosch BNO055 nine-axis sensor on I2C (DiWheelDrive 1-2, I2C1 at 400 kHz, address 0x28).
//!
//! The part is run in its **AMG** operating mode (accelerometer, magnetometer and gyroscope, no
//! fusion; docs/sensors.md argues the choice): the three sensors' samples come out in the
//! datasheet's fixed encodings, whatever range is configured — gyroscope 1/16 °/s, accelerometer
//! 1 mg (UNIT_SEL bit 0 set) and magnetometer 1/16 µT per digit, little-endian, X then Y then Z,
//! in the order accelerometer (0x08), magnetometer (0x0E), gyroscope (0x14), so one 18-byte burst
//! reads all nine axes. The driver converts to the protocol's units (°/s, mg, nT; the same as the
//! 1-1 board's parts).
//!
//! Boot: the board pulses IMU_RESET_N (and keeps IMU_BOOT_LOAD_N high, so the part starts its
//! application, not its bootloader); the part needs about 650 ms from reset to configuration mode
//! and does not answer before ([`Bno055::wait_for_boot`]). [`Bno055::init`] then checks the four
//! identity registers (chip 0xA0, accelerometer 0xFB, magnetometer 0x32, gyroscope 0x0F) and the
//! power-on self-test result (ST_RESULT, every sensor and the MCU passed), enters configuration
//! mode, sets the sensors' ranges on register page 1, selects milli-g, and starts AMG mode, reading
//! every written register back.

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use super::{check_register, div_round, saturate_i16, Error};
use crate::script::Blocking;

/// The part's 7-bit address with COM3 low (the AMiRo's wiring); 0x29 with COM3 high.
pub const ADDRESS: u8 = 0x28;

/// Register addresses (datasheet register map, page 0 unless noted).
pub mod reg {
    /// Chip identity, then accelerometer, magnetometer and gyroscope identities (0x00..=0x03).
    pub const CHIP_ID: u8 = 0x00;
    /// Register page select (0 or 1); present on both pages.
    pub const PAGE_ID: u8 = 0x07;
    /// Accelerometer X LSB: the first of 18 data bytes (accelerometer, magnetometer, gyroscope).
    pub const ACC_DATA_X_LSB: u8 = 0x08;
    /// Magnetometer X LSB.
    pub const MAG_DATA_X_LSB: u8 = 0x0E;
    /// Gyroscope X LSB.
    pub const GYR_DATA_X_LSB: u8 = 0x14;
    /// Power-on self-test result: bit 0 accelerometer, 1 magnetometer, 2 gyroscope, 3 MCU (1 = passed).
    pub const ST_RESULT: u8 = 0x36;
    /// System status (0 idle, 1 error, …, 6 running without fusion).
    pub const SYS_STATUS: u8 = 0x39;
    /// System error code when SYS_STATUS reads 1.
    pub const SYS_ERR: u8 = 0x3A;
    /// Output units: bit 0 accelerometer (1 = mg), bit 1 gyroscope (0 = °/s).
    pub const UNIT_SEL: u8 = 0x3B;
    /// Operating mode (bits 3..0).
    pub const OPR_MODE: u8 = 0x3D;
    /// Power mode (bits 1..0; 0 = normal).
    pub const PWR_MODE: u8 = 0x3E;
    /// System trigger: bit 0 self-test, bit 5 system reset.
    pub const SYS_TRIGGER: u8 = 0x3F;
    /// Page 1: accelerometer range, bandwidth and power mode.
    pub const ACC_CONFIG: u8 = 0x08;
    /// Page 1: magnetometer output rate, operation mode and power mode.
    pub const MAG_CONFIG: u8 = 0x09;
    /// Page 1: gyroscope range and bandwidth.
    pub const GYR_CONFIG_0: u8 = 0x0A;
    /// Page 1: gyroscope power mode.
    pub const GYR_CONFIG_1: u8 = 0x0B;
}

/// The four identity registers: chip, accelerometer, magnetometer, gyroscope.
pub const IDENTITY: [u8; 4] = [0xA0, 0xFB, 0x32, 0x0F];
/// ST_RESULT when the accelerometer, magnetometer, gyroscope and MCU all passed their self-test.
pub const SELF_TEST_PASSED: u8 = 0x0F;

/// Operating modes (OPR_MODE bits 3..0) the driver uses.
pub mod mode {
    /// Configuration mode: the only mode in which page-1 sensor settings may be written.
    pub const CONFIG: u8 = 0x00;
    /// Accelerometer, magnetometer and gyroscope, no fusion.
    pub const AMG: u8 = 0x07;
    /// Fusion of accelerometer and gyroscope (what AMiRo-Apps uses; no magnetometer).
    pub const IMUPLUS: u8 = 0x08;
    /// Nine-axis fusion.
    pub const NDOF: u8 = 0x0C;
}

/// Datasheet switching times (table "operating mode switching time").
pub const CONFIG_TO_OPERATING_MS: u32 = 7;
/// Any operating mode to configuration mode.
pub const OPERATING_TO_CONFIG_MS: u32 = 19;
/// Power-on or reset to configuration mode (typical 650 ms; [`Bno055::wait_for_boot`] waits longer).
pub const BOOT_MS: u32 = 650;

/// ACC_CONFIG: ±8 g (range 10), 62.5 Hz bandwidth (011), normal power (000).
pub const ACC_CONFIG_AMIRO: u8 = 0x0E;
/// MAG_CONFIG: 30 Hz output (111), regular preset (01), normal power (00).
pub const MAG_CONFIG_AMIRO: u8 = 0x0F;
/// GYR_CONFIG_0: ±500 °/s (010), 23 Hz bandwidth (100) — the 1-1 gyroscope's range and about its
/// 25 Hz bandwidth.
pub const GYR_CONFIG_0_AMIRO: u8 = 0x22;
/// GYR_CONFIG_1: normal power mode.
pub const GYR_CONFIG_1_AMIRO: u8 = 0x00;
/// UNIT_SEL: accelerometer in mg, gyroscope in °/s, Windows orientation convention.
pub const UNIT_SEL_AMIRO: u8 = 0x01;

/// Gyroscope digits per °/s (datasheet: 1 °/s = 16 LSB).
pub const GYRO_LSB_PER_DPS: i64 = 16;
/// Magnetometer digits per µT (datasheet: 1 µT = 16 LSB).
pub const MAG_LSB_PER_MICROTESLA: i64 = 16;

/// One reading of all nine axes, raw digits in the sensor's frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RawSample {
    /// Accelerometer X, Y, Z (1 mg per digit in mg units).
    pub accelerometer: [i16; 3],
    /// Magnetometer X, Y, Z (1/16 µT per digit).
    pub magnetometer: [i16; 3],
    /// Gyroscope X, Y, Z (1/16 °/s per digit).
    pub gyroscope: [i16; 3],
}

/// One nine-axis sample in the protocol's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Motion {
    /// Acceleration X, Y, Z in mg.
    pub milli_g: [i16; 3],
    /// Magnetic field X, Y, Z in nanotesla.
    pub nanotesla: [i32; 3],
    /// Angular rate X, Y, Z in °/s.
    pub degrees_per_s: [i16; 3],
}

impl RawSample {
    /// The sample in the protocol's units.
    pub const fn convert(&self) -> Motion {
        Motion {
            milli_g: self.accelerometer,
            nanotesla: nanotesla(self.magnetometer),
            degrees_per_s: degrees_per_s(self.gyroscope),
        }
    }
}

/// Gyroscope digits (1/16 °/s) to whole °/s, rounded to nearest.
pub const fn degrees_per_s(raw: [i16; 3]) -> [i16; 3] {
    [
        saturate_i16(div_round(raw[0] as i64, GYRO_LSB_PER_DPS)),
        saturate_i16(div_round(raw[1] as i64, GYRO_LSB_PER_DPS)),
        saturate_i16(div_round(raw[2] as i64, GYRO_LSB_PER_DPS)),
    ]
}

/// Magnetometer digits (1/16 µT) to nanotesla, rounded to nearest (62.5 nT per digit).
pub const fn nanotesla(raw: [i16; 3]) -> [i32; 3] {
    [
        div_round(raw[0] as i64 * 1000, MAG_LSB_PER_MICROTESLA) as i32,
        div_round(raw[1] as i64 * 1000, MAG_LSB_PER_MICROTESLA) as i32,
        div_round(raw[2] as i64 * 1000, MAG_LSB_PER_MICROTESLA) as i32,
    ]
}

/// One sensor's six data bytes (X, Y, Z, each LSB first) as digits.
pub fn le3(bytes: &[u8]) -> [i16; 3] {
    let word = |i: usize| {
        i16::from_le_bytes([
            bytes.get(i).copied().unwrap_or(0),
            bytes.get(i + 1).copied().unwrap_or(0),
        ])
    };
    [word(0), word(2), word(4)]
}

/// The BNO055 on its I2C bus.
#[derive(Debug, Clone)]
pub struct Bno055<I2C> {
    i2c: I2C,
}

impl<I2C> Bno055<I2C> {
    /// A driver at the AMiRo's address. Does no I/O; call [`init`](Self::init).
    pub const fn new(i2c: I2C) -> Self {
        Self { i2c }
    }
}

impl<I2C: I2c> Bno055<I2C> {
    /// Waits for the part to answer after a reset: reads the chip identity every 10 ms, at most
    /// `timeout_ms` long. The board calls it once after releasing IMU_RESET_N; a part that never
    /// answers returns the last error (and [`init`](Self::init) reports it again later).
    pub fn wait_for_boot(
        &mut self,
        delay: &mut impl DelayNs,
        timeout_ms: u32,
    ) -> Result<(), Error<I2C::Error>> {
        let mut waited = 0;
        loop {
            let mut id = [0u8; 1];
            let result = self.i2c.write_read(ADDRESS, &[reg::CHIP_ID], &mut id);
            let error = match result {
                Ok(()) if id[0] == IDENTITY[0] => return Ok(()),
                Ok(()) => Error::WrongIdentity {
                    expected: u32::from(IDENTITY[0]),
                    found: u32::from(id[0]),
                },
                Err(e) => Error::Bus(e),
            };
            if waited >= timeout_ms {
                return Err(error);
            }
            delay.delay_ms(10);
            waited += 10;
        }
    }

    /// Checks identities and the power-on self-test, configures the sensors and starts AMG mode.
    ///
    /// Busy-waits the datasheet's mode switching times on `delay` (19 ms into configuration mode,
    /// 7 ms out of it): the boot's path. A caller that must not wait (a re-initialisation inside a
    /// bus lock) runs the six steps itself, one a release, and waits between them outside:
    /// [`init_identify`], [`init_self_test_then_config`], then after [`OPERATING_TO_CONFIG_MS`]
    /// [`init_prepare_page_1`], [`init_write_page_1`], [`init_start_amg`], then after
    /// [`CONFIG_TO_OPERATING_MS`] [`init_check_running`]. Each step is two or three short
    /// transfers, no more bus flags than a sample's two register reads ([`read_verified`]), so a
    /// release that takes a step is no longer than one that samples.
    ///
    /// [`init_identify`]: Self::init_identify
    /// [`init_self_test_then_config`]: Self::init_self_test_then_config
    /// [`init_prepare_page_1`]: Self::init_prepare_page_1
    /// [`init_write_page_1`]: Self::init_write_page_1
    /// [`init_start_amg`]: Self::init_start_amg
    /// [`init_check_running`]: Self::init_check_running
    /// [`read_verified`]: Self::read_verified
    pub fn init(&mut self, delay: &mut impl DelayNs) -> Result<(), Error<I2C::Error>> {
        self.init_identify()?;
        self.init_self_test_then_config()?;
        delay.delay_ms(OPERATING_TO_CONFIG_MS);
        self.init_prepare_page_1()?;
        self.init_write_page_1()?;
        self.init_start_amg()?;
        delay.delay_ms(CONFIG_TO_OPERATING_MS);
        self.init_check_running()
    }

    /// Initialisation, step 1: register page 0 (where a set-up that failed on page 1 left the
    /// part), then the four identities checked.
    pub fn init_identify(&mut self) -> Result<(), Error<I2C::Error>> {
        identity(ops::identity_on_page_0(&mut Blocking(&mut self.i2c))?)
    }

    /// Initialisation, step 2: the power-on self-test checked, then configuration mode requested
    /// (the part takes [`OPERATING_TO_CONFIG_MS`] to get there).
    pub fn init_self_test_then_config(&mut self) -> Result<(), Error<I2C::Error>> {
        let bus = &mut Blocking(&mut self.i2c);
        let [result] = ops::self_test_result(bus)?;
        self_test(result)?;
        ops::enter_config(bus)?;
        Ok(())
    }

    /// Initialisation, step 3 (in configuration mode): normal power mode, the units, register
    /// page 1.
    pub fn init_prepare_page_1(&mut self) -> Result<(), Error<I2C::Error>> {
        ops::prepare_page_1(&mut Blocking(&mut self.i2c))?;
        Ok(())
    }

    /// Initialisation, step 4 (on page 1): the four sensor configurations written in one burst
    /// and read back.
    pub fn init_write_page_1(&mut self) -> Result<(), Error<I2C::Error>> {
        check_configuration(ops::write_page_1(&mut Blocking(&mut self.i2c))?)
    }

    /// Initialisation, step 5: page 0, the units read back, AMG mode requested (the part takes
    /// [`CONFIG_TO_OPERATING_MS`] to get there).
    pub fn init_start_amg(&mut self) -> Result<(), Error<I2C::Error>> {
        let bus = &mut Blocking(&mut self.i2c);
        let [units] = ops::page_0_units(bus)?;
        check_units(units)?;
        ops::start_amg(bus)?;
        Ok(())
    }

    /// Initialisation, step 6: the part runs AMG mode.
    pub fn init_check_running(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut opr = [0u8; 1];
        self.i2c.write_read(ADDRESS, &[reg::OPR_MODE], &mut opr)?;
        check_amg_started(opr[0])
    }

    /// Reads the four identity registers in one transfer and compares them with the datasheet's.
    pub fn check_identity(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut id = [0u8; 4];
        self.i2c.write_read(ADDRESS, &[reg::CHIP_ID], &mut id)?;
        identity(id)
    }

    /// Reads the power-on self-test result: every sensor and the MCU must have passed.
    pub fn check_self_test(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut result = [0u8; 1];
        self.i2c
            .write_read(ADDRESS, &[reg::ST_RESULT], &mut result)?;
        self_test(result[0])
    }

    /// Reads six data bytes at `first` (one sensor's X, Y, Z) in one burst.
    fn read_block(&mut self, first: u8) -> Result<[i16; 3], Error<I2C::Error>> {
        let mut out = [0u8; 6];
        self.i2c.write_read(ADDRESS, &[first], &mut out)?;
        if super::is_bus_pattern(&out) {
            self.check_identity()?;
        }
        Ok(le3(&out))
    }

    /// Checks that the part still runs the AMG mode `init` started (OPR_MODE, one byte): a part that
    /// reset (configuration mode, its data reading zero), a dead line (0x00 or 0xFF) or no answer
    /// (a bus error) fails here.
    pub fn check_running(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut opr = [0u8; 1];
        self.i2c.write_read(ADDRESS, &[reg::OPR_MODE], &mut opr)?;
        still_running(opr[0])
    }

    /// One sensor's X, Y, Z digits (one 6-byte burst at `first`), then [`check_running`]: the
    /// board suite's read, the same two transfers on every sample (no periodic identity check, no
    /// second look at a dead-bus pattern), so its time does not vary and a fault is seen at once.
    ///
    /// [`check_running`]: Self::check_running
    pub fn read_verified(&mut self, first: u8) -> Result<[i16; 3], Error<I2C::Error>> {
        let mut out = [0u8; 6];
        self.i2c.write_read(ADDRESS, &[first], &mut out)?;
        self.check_running()?;
        Ok(le3(&out))
    }

    /// Gyroscope X, Y, Z in °/s (one 6-byte burst).
    pub fn read_gyroscope(&mut self) -> Result<[i16; 3], Error<I2C::Error>> {
        Ok(degrees_per_s(self.read_block(reg::GYR_DATA_X_LSB)?))
    }

    /// Accelerometer X, Y, Z in mg (one 6-byte burst).
    pub fn read_accelerometer(&mut self) -> Result<[i16; 3], Error<I2C::Error>> {
        self.read_block(reg::ACC_DATA_X_LSB)
    }

    /// Magnetometer X, Y, Z in nanotesla (one 6-byte burst).
    pub fn read_magnetometer(&mut self) -> Result<[i32; 3], Error<I2C::Error>> {
        Ok(nanotesla(self.read_block(reg::MAG_DATA_X_LSB)?))
    }

    /// All nine axes in one 18-byte burst, raw digits.
    ///
    /// Eighteen bytes of all `0x00` or all `0xFF` are passed on only after the identity registers
    /// still read right ([`Error::WrongIdentity`] otherwise).
    pub fn read_raw(&mut self) -> Result<RawSample, Error<I2C::Error>> {
        let mut out = [0u8; 18];
        self.i2c
            .write_read(ADDRESS, &[reg::ACC_DATA_X_LSB], &mut out)?;
        if super::is_bus_pattern(&out) {
            self.check_identity()?;
        }
        Ok(RawSample {
            accelerometer: le3(&out[0..6]),
            magnetometer: le3(&out[6..12]),
            gyroscope: le3(&out[12..18]),
        })
    }

    /// All nine axes in the protocol's units.
    pub fn read(&mut self) -> Result<Motion, Error<I2C::Error>> {
        Ok(self.read_raw()?.convert())
    }

    /// The bus handle, e.g. for a test to reach a simulator's fault injection.
    pub fn bus_mut(&mut self) -> &mut I2C {
        &mut self.i2c
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }
}

/// The page-1 configuration the set-up writes in one burst from ACC_CONFIG: accelerometer,
/// magnetometer, gyroscope 0 and 1.
pub const CONFIGURATION: [u8; 4] = [
    ACC_CONFIG_AMIRO,
    MAG_CONFIG_AMIRO,
    GYR_CONFIG_0_AMIRO,
    GYR_CONFIG_1_AMIRO,
];

/// The four identity registers: [`IDENTITY`], or [`Error::WrongIdentity`].
pub fn identity<E>(id: [u8; 4]) -> Result<(), Error<E>> {
    if id == IDENTITY {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: u32::from_be_bytes(IDENTITY),
            found: u32::from_be_bytes(id),
        })
    }
}

/// ST_RESULT: every sensor and the MCU passed, or [`Error::SelfTest`].
pub fn self_test<E>(result: u8) -> Result<(), Error<E>> {
    if result & 0x0F == SELF_TEST_PASSED {
        Ok(())
    } else {
        Err(Error::SelfTest {
            result: result & 0x0F,
        })
    }
}

/// The read-back of the page-1 configuration ([`CONFIGURATION`]) on its writable bits.
#[inline(always)]
pub fn check_configuration<E>(readback: [u8; 4]) -> Result<(), Error<E>> {
    // Writable bits: ACC all 8; MAG bits 6..0; GYR_0 bits 5..0; GYR_1 bits 2..0.
    let writable = [0xFF, 0x7F, 0x3F, 0x07];
    for (((register, written), read), mask) in (reg::ACC_CONFIG..)
        .zip(CONFIGURATION)
        .zip(readback)
        .zip(writable)
    {
        check_register(register, written, read, mask)?;
    }
    Ok(())
}

/// UNIT_SEL's read-back on its writable bits.
pub fn check_units<E>(units: u8) -> Result<(), Error<E>> {
    check_register(reg::UNIT_SEL, UNIT_SEL_AMIRO, units, 0x97)
}

/// OPR_MODE after the set-up's switch: AMG in bits 3..0.
pub fn check_amg_started<E>(opr: u8) -> Result<(), Error<E>> {
    check_register(reg::OPR_MODE, mode::AMG, opr, 0x0F)
}

/// OPR_MODE beside a sample: still AMG, the whole byte (a dead line's 0x00 or 0xFF fails).
pub fn still_running<E>(opr: u8) -> Result<(), Error<E>> {
    check_register(reg::OPR_MODE, mode::AMG, opr, 0xFF)
}

/// The part's transactions, written once for the blocking driver and the scripts
/// ([`crate::script::Transfers`]; decoded by the functions above).
pub mod ops {
    use super::{mode, reg, ADDRESS, CONFIGURATION, UNIT_SEL_AMIRO};
    use crate::script::{At, BuildError, Script, Transfers};

    /// Set-up step 1: page 0, then the four identities (write 0x00, read 4,
    /// [`super::identity`]).
    pub fn identity_on_page_0<T: Transfers>(bus: &mut T) -> Result<T::Read<4>, T::Error> {
        bus.send(ADDRESS, &[reg::PAGE_ID, 0])?;
        bus.fetch::<4>(ADDRESS, &[reg::CHIP_ID])
    }

    /// Set-up step 2's read: ST_RESULT (write 0x36, read 1, [`super::self_test`]).
    pub fn self_test_result<T: Transfers>(bus: &mut T) -> Result<T::Read<1>, T::Error> {
        bus.fetch::<1>(ADDRESS, &[reg::ST_RESULT])
    }

    /// Set-up step 2's end once the self-test passed: configuration mode (the part then takes
    /// [`super::OPERATING_TO_CONFIG_MS`]).
    #[inline(always)]
    pub fn enter_config<T: Transfers>(bus: &mut T) -> Result<(), T::Error> {
        bus.send(ADDRESS, &[reg::OPR_MODE, mode::CONFIG])
    }

    /// Set-up step 3: normal power mode, the units, page 1.
    #[inline(always)]
    pub fn prepare_page_1<T: Transfers>(bus: &mut T) -> Result<(), T::Error> {
        bus.send(ADDRESS, &[reg::PWR_MODE, 0x00])?;
        bus.send(ADDRESS, &[reg::UNIT_SEL, UNIT_SEL_AMIRO])?;
        bus.send(ADDRESS, &[reg::PAGE_ID, 1])
    }

    /// Set-up step 4 (on page 1): the four sensor configuration registers in one burst, read
    /// back in one ([`super::check_configuration`]).
    #[inline(always)]
    pub fn write_page_1<T: Transfers>(bus: &mut T) -> Result<T::Read<4>, T::Error> {
        let [a, m, g0, g1] = CONFIGURATION;
        bus.send(ADDRESS, &[reg::ACC_CONFIG, a, m, g0, g1])?;
        bus.fetch::<4>(ADDRESS, &[reg::ACC_CONFIG])
    }

    /// Set-up step 5's first transfers: page 0, UNIT_SEL's read-back ([`super::check_units`]).
    #[inline(always)]
    pub fn page_0_units<T: Transfers>(bus: &mut T) -> Result<T::Read<1>, T::Error> {
        bus.send(ADDRESS, &[reg::PAGE_ID, 0])?;
        bus.fetch::<1>(ADDRESS, &[reg::UNIT_SEL])
    }

    /// Set-up step 5's end once its check passed: AMG mode (the part then takes
    /// [`super::CONFIG_TO_OPERATING_MS`]).
    #[inline(always)]
    pub fn start_amg<T: Transfers>(bus: &mut T) -> Result<(), T::Error> {
        bus.send(ADDRESS, &[reg::OPR_MODE, mode::AMG])
    }

    /// OPR_MODE: write 0x3D, read 1 (set-up step 6, [`super::check_amg_started`]; beside a
    /// sample, [`super::still_running`]).
    pub fn operating_mode(script: &mut Script) -> Result<At<1>, BuildError> {
        script.fetch::<1>(ADDRESS, &[reg::OPR_MODE])
    }

    /// A sample of one sensor ([`super::Bno055::read_verified`]): its six data bytes from
    /// `first` (write it, read 6, [`super::le3`]), then OPR_MODE.
    pub fn verified_block(script: &mut Script, first: u8) -> Result<(At<6>, At<1>), BuildError> {
        let data = script.fetch::<6>(ADDRESS, &[first])?;
        Ok((data, operating_mode(script)?))
    }
}
