//! Register-level simulators of the AMiRo's devices, and a simulated wheel plant: what the real
//! drivers talk to on the host and in the firmware's QEMU build, where there is no hardware.
//!
//! Each simulator implements the bus trait its part sits on (`SpiDevice` for the SPI parts, `I2c`
//! through [`SimBus`] for the I2C parts; a register-addressed part implements [`RegisterDevice`],
//! which brings the register pointer), answers the identity registers, stores configuration
//! writes with the part's writable-bit rules (so the drivers' read-back checks mean something), and
//! produces a slow, deterministic pattern computed from a per-device sample counter — no clock, no
//! randomness, the same bytes on every run. Values are generated in physical units and encoded
//! with whatever range the driver configured, so a driver that set the wrong range reads the
//! wrong number. All state is a few bytes per device; nothing allocates.
//!
//! **Fed from outside.** Each measuring simulator also takes its physical input from outside
//! instead of its pattern — `SimGyroscope::set_measured` (mdps), `SimAccelerometer::set_measured` (µg),
//! `SimHmc5883l::set_field`, `SimBno055::set_motion`, `SimVcnl4020::set_proximity` (and
//! `SimMuxedProximity::set_proximity` by channel, `feed_ring` and `feed_floor` by protocol index) — encoded exactly as the pattern would be. This
//! is how a world (amiro-world, docs/world.md) reaches the real drivers: the robot host sends
//! the readings over the robot link and the board's QEMU build hands them to these setters.
//!
//! | simulator | part | bus |
//! |---|---|---|
//! | [`SimGyroscope`] | L3G4200D | `SpiDevice` |
//! | [`SimAccelerometer`] | LIS331DLH | `SpiDevice` |
//! | [`SimCompassBus`] | HMC5883L at 0x1E | `I2c` |
//! | [`SimImuBus`] | BNO055 at 0x28 (DiWheelDrive 1-2) | `I2c` |
//! | [`SimFloorBus`] | PCA9544A at 0x77 + 4 × VCNL4020 | `I2c` |
//! | [`SimPowerBus`] | PCA9544A + 4 × VCNL4020 + bq27500 at 0x55 | `I2c` |
//! | [`SimLedDriver`], [`SimLedChain`] | TLC5947, or a chain of them (LightRing 1-2: three) | `SpiDevice` |
//! | [`WheelPlant`] | motors, gears, encoders | [`crate::motion::MotorPwm`], counts |

use core::convert::Infallible;

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{self, ErrorType, I2c, Operation};

mod bno055;
mod compass;
mod feed;
mod fuel_gauge;
mod leds;
mod motion_sensors;
mod plant;
mod proximity;
mod scripts;

pub use bno055::{
    Bno055Fault, Bno055Motion, SimBno055, SimImuBus, FIELD_DOWN_NT, FIELD_HORIZONTAL_NT,
    FIELD_TOTAL_NT, GRAVITY_MG, GYRO_OFFSET_DIGITS,
};
pub use compass::SimHmc5883l;
pub use feed::{feed_floor, feed_ring};
pub use fuel_gauge::SimBq27500;
pub use leds::{SimLedChain, SimLedDriver};
pub use motion_sensors::{
    Accelerometer, Gyroscope, SimAccelerometer, SimGyroscope, SimStSensor, StPart,
};
pub use plant::{MotorModel, SimWheel, WheelPlant};
pub use proximity::{SimMuxedProximity, SimVcnl4020};
pub use scripts::{Answer, SCL_HZ};

/// The DiWheelDrive's I2C1 with its HMC5883L.
pub type SimCompassBus = SimBus<SimHmc5883l>;
/// The DiWheelDrive's I2C2: the mux and the four floor sensors.
pub type SimFloorBus = SimBus<SimMuxedProximity>;
/// One of the PowerManagement's buses: a mux with four ring sensors, and a fuel gauge.
pub type SimPowerBus = SimBus<(SimMuxedProximity, SimBq27500)>;

/// A simulated I2C device (or several, see the tuple implementation): byte-level callbacks in
/// the order the bus delivers them.
pub trait I2cTarget {
    /// Whether something answers `address` right now (a device behind a disabled mux channel
    /// does not).
    fn acknowledges(&self, address: u8) -> bool;
    /// A START or repeated START for `address`, writing (`read == false`) or reading.
    fn start(&mut self, address: u8, read: bool);
    /// A byte written by the host.
    fn write_byte(&mut self, address: u8, byte: u8);
    /// A byte read by the host.
    fn read_byte(&mut self, address: u8) -> u8;
}

/// Two targets on one bus: `A` is asked first.
impl<A: I2cTarget, B: I2cTarget> I2cTarget for (A, B) {
    fn acknowledges(&self, address: u8) -> bool {
        self.0.acknowledges(address) || self.1.acknowledges(address)
    }

    fn start(&mut self, address: u8, read: bool) {
        if self.0.acknowledges(address) {
            self.0.start(address, read);
        } else {
            self.1.start(address, read);
        }
    }

    fn write_byte(&mut self, address: u8, byte: u8) {
        if self.0.acknowledges(address) {
            self.0.write_byte(address, byte);
        } else {
            self.1.write_byte(address, byte);
        }
    }

    fn read_byte(&mut self, address: u8) -> u8 {
        if self.0.acknowledges(address) {
            self.0.read_byte(address)
        } else {
            self.1.read_byte(address)
        }
    }
}

/// The register pointer of a [`RegisterDevice`]: where the next byte goes to or comes from, and
/// whether the next written byte sets it instead (the first byte of a write transfer).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RegisterPointer {
    at: u8,
    expect_pointer: bool,
}

impl RegisterPointer {
    /// At register 0, as the parts come out of reset.
    pub const fn new() -> Self {
        Self {
            at: 0,
            expect_pointer: false,
        }
    }

    /// The register the next byte goes to or comes from.
    pub const fn at(&self) -> u8 {
        self.at
    }
}

/// A register-addressed I2C part: a write transfer's first byte selects a register, every byte
/// after it (written or read) is the next register's. Its simulator supplies the registers; the
/// pointer handling and the byte-level [`I2cTarget`] callbacks are the same for every such part
/// and live here.
pub trait RegisterDevice {
    /// The part's 7-bit address.
    const ADDRESS: u8;
    /// The register pointer.
    fn pointer(&mut self) -> &mut RegisterPointer;
    /// The host writes `byte` to `register`.
    fn write_register(&mut self, register: u8, byte: u8);
    /// The host reads `register`.
    fn read_register(&mut self, register: u8) -> u8;
    /// The register the pointer moves to after `register`: the next one, unless the part wraps.
    fn next_register(&self, register: u8) -> u8 {
        register.wrapping_add(1)
    }
    /// A read transfer starts at `register` (a part that measures on a read hooks in here).
    fn read_started(&mut self, register: u8) {
        let _ = register;
    }
}

impl<D: RegisterDevice> I2cTarget for D {
    fn acknowledges(&self, address: u8) -> bool {
        address == D::ADDRESS
    }

    fn start(&mut self, _address: u8, read: bool) {
        let pointer = self.pointer();
        pointer.expect_pointer = !read;
        let at = pointer.at;
        if read {
            self.read_started(at);
        }
    }

    fn write_byte(&mut self, _address: u8, byte: u8) {
        let pointer = self.pointer();
        if pointer.expect_pointer {
            pointer.at = byte;
            pointer.expect_pointer = false;
            return;
        }
        let register = pointer.at;
        self.write_register(register, byte);
        self.pointer().at = self.next_register(register);
    }

    fn read_byte(&mut self, _address: u8) -> u8 {
        let register = self.pointer().at;
        let value = self.read_register(register);
        self.pointer().at = self.next_register(register);
        value
    }
}

/// The only thing that goes wrong on a simulated bus: nobody acknowledged the address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoAcknowledge {
    /// The address nobody answered.
    pub address: u8,
}

impl i2c::Error for NoAcknowledge {
    fn kind(&self) -> i2c::ErrorKind {
        i2c::ErrorKind::NoAcknowledge(i2c::NoAcknowledgeSource::Address)
    }
}

/// An I2C bus with simulated devices on it.
#[derive(Debug, Clone, Default)]
pub struct SimBus<T> {
    /// The device(s) on the bus, for inspection.
    pub target: T,
    nack: bool,
}

impl<T> SimBus<T> {
    /// A bus with `target` on it.
    pub const fn with(target: T) -> Self {
        Self {
            target,
            nack: false,
        }
    }

    /// Fault injection: from now on nobody acknowledges any address (a part that lost power, a
    /// cut line), until called again with `false`.
    pub fn set_nack(&mut self, nack: bool) {
        self.nack = nack;
    }
}

impl SimCompassBus {
    /// The DiWheelDrive's I2C1: an HMC5883L at power-on.
    pub const fn new() -> Self {
        Self::with(SimHmc5883l::new())
    }
}

impl SimFloorBus {
    /// The DiWheelDrive's I2C2: the mux and four floor sensors (indices 0..=3) at power-on.
    pub const fn new() -> Self {
        Self::with(SimMuxedProximity::new(0))
    }
}

impl SimPowerBus {
    /// One PowerManagement bus: ring sensors numbered `first_sensor..first_sensor + 4` (so the two
    /// buses give different patterns) and a gauge that is charging or not.
    pub const fn new(first_sensor: u8, charging: bool) -> Self {
        Self::with((
            SimMuxedProximity::new(first_sensor),
            SimBq27500::new(charging),
        ))
    }
}

impl<T: I2cTarget> ErrorType for SimBus<T> {
    type Error = NoAcknowledge;
}

impl<T: I2cTarget> I2c for SimBus<T> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        if self.nack || !self.target.acknowledges(address) {
            return Err(NoAcknowledge { address });
        }
        // Adjacent operations of the same direction are one transfer; a change of direction is a
        // repeated START (embedded-hal's transaction contract).
        let mut direction = None;
        for operation in operations {
            let read = matches!(operation, Operation::Read(_));
            if direction != Some(read) {
                self.target.start(address, read);
                direction = Some(read);
            }
            match operation {
                Operation::Read(buffer) => {
                    for byte in buffer.iter_mut() {
                        *byte = self.target.read_byte(address);
                    }
                }
                Operation::Write(bytes) => {
                    for &byte in bytes.iter() {
                        self.target.write_byte(address, byte);
                    }
                }
            }
        }
        Ok(())
    }
}

/// A delay that returns at once: the simulated devices need no time between transfers.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDelay;

impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// The SPI protocol of ST's motion sensors, for the simulators: a command byte (read bit,
/// auto-increment bit, 6-bit address) then data, per chip-select assertion.
pub(crate) trait StRegisters {
    /// The host reads `register`.
    fn read_register(&mut self, register: u8) -> u8;
    /// The host writes `value` to `register`.
    fn write_register(&mut self, register: u8, value: u8);
}

/// Where an ST SPI transaction is: before the command byte, or reading/writing at an address.
#[derive(Clone, Copy)]
struct StSpiState {
    command: Option<(bool, bool, u8)>,
}

impl StSpiState {
    fn exchange<R: StRegisters>(&mut self, device: &mut R, mosi: u8) -> u8 {
        match self.command {
            None => {
                self.command = Some((mosi & 0x80 != 0, mosi & 0x40 != 0, mosi & 0x3F));
                0xFF
            }
            Some((read, increment, address)) => {
                let miso = if read {
                    device.read_register(address)
                } else {
                    device.write_register(address, mosi);
                    0xFF
                };
                if increment {
                    self.command = Some((read, increment, (address + 1) & 0x3F));
                }
                miso
            }
        }
    }
}

/// Runs one `SpiDevice` transaction against ST-style registers.
pub(crate) fn st_spi_transaction<R: StRegisters>(
    device: &mut R,
    operations: &mut [embedded_hal::spi::Operation<'_, u8>],
) -> Result<(), Infallible> {
    use embedded_hal::spi::Operation as Op;
    let mut state = StSpiState { command: None };
    for operation in operations {
        match operation {
            Op::Read(buffer) => {
                for byte in buffer.iter_mut() {
                    *byte = state.exchange(device, 0x00);
                }
            }
            Op::Write(bytes) => {
                for &byte in bytes.iter() {
                    state.exchange(device, byte);
                }
            }
            Op::Transfer(read, write) => {
                for i in 0..read.len().max(write.len()) {
                    let miso = state.exchange(device, write.get(i).copied().unwrap_or(0x00));
                    if let Some(slot) = read.get_mut(i) {
                        *slot = miso;
                    }
                }
            }
            Op::TransferInPlace(buffer) => {
                for byte in buffer.iter_mut() {
                    *byte = state.exchange(device, *byte);
                }
            }
            Op::DelayNs(_) => {}
        }
    }
    Ok(())
}

/// Fault injection for the SPI simulators: every byte the host reads is `level` (a MISO line stuck
/// low or high), whatever the part would have sent. Writes still reach the part.
pub(crate) fn stick_miso(level: u8, operations: &mut [embedded_hal::spi::Operation<'_, u8>]) {
    use embedded_hal::spi::Operation as Op;
    for operation in operations {
        match operation {
            Op::Read(buffer) | Op::TransferInPlace(buffer) | Op::Transfer(buffer, _) => {
                buffer.fill(level)
            }
            Op::Write(_) | Op::DelayNs(_) => {}
        }
    }
}

/// A triangle wave through 0 → +amplitude → 0 → −amplitude → 0 over `period` samples.
pub(crate) const fn triangle(sample: u32, period: u32, amplitude: i32) -> i32 {
    if period == 0 {
        return 0;
    }
    let p = (sample % period) as i64 * 4;
    let period = period as i64;
    let a = amplitude as i64;
    let value = if p < period {
        a * p / period
    } else if p < 3 * period {
        a * (2 * period - p) / period
    } else {
        a * (p - 4 * period) / period
    };
    value as i32
}
