//! Drivers for the AMiRo's sensors and actuators, written from the parts' datasheets.
//!
//! Every driver is generic over an embedded-hal 1.0 bus trait (`I2c` or `SpiDevice`), owns that
//! bus handle, never allocates and never panics on what the bus returns. Errors are one typed enum,
//! [`Error`], with the bus error kept as it came. A board that shares a bus between several drivers
//! passes each one a shared handle (embedded-hal-bus) or, as the board suites in [`suite`] do, a
//! `&mut` borrow of the bus for the length of one call.
//!
//! Device drivers (one module per part): [`l3g4200d`] gyroscope, [`lis331dlh`] accelerometer,
//! [`hmc5883l`] magnetometer, [`bno055`] nine-axis IMU (DiWheelDrive 1-2), [`vcnl4020`] proximity and ambient light, [`pca9544a`] I2C
//! multiplexer, [`bq27500`] fuel gauge, [`tlc5947`] LED driver. Sensor groups as the boards wire
//! them: [`floor`] (DiWheelDrive's four floor sensors), [`ring`] (PowerManagement's eight ring
//! sensors); [`proximity`] turns proximity counts into millimetres; [`suite`] bundles a board's
//! devices behind one `sample(topic)` call that yields amiro-can [`amiro_can::SensorData`].

use core::fmt;

pub mod bno055;
pub mod bq27500;
pub mod floor;
pub mod hmc5883l;
pub mod l3g4200d;
pub mod lis331dlh;
pub mod pca9544a;
pub mod proximity;
pub mod ring;
mod st_spi;
pub mod suite;
pub mod tlc5947;
pub mod vcnl4020;

/// What can go wrong talking to one device.
///
/// `E` is the bus's own error type, kept so the caller can tell a NACK from arbitration loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The bus transfer itself failed.
    Bus(E),
    /// The identity register(s) did not hold the part's identity: wrong part, wrong address, or
    /// a dead bus reading all ones or all zeros. `expected` and `found` are the identity bytes
    /// packed big-endian (e.g. `0x48_3433` for the HMC5883L's "H43").
    WrongIdentity {
        /// Identity the datasheet gives.
        expected: u32,
        /// Identity the device answered with.
        found: u32,
    },
    /// A configuration register read back different from what was written (writable bits only):
    /// the part did not take the setting, so its data would be in the wrong unit.
    ConfigMismatch {
        /// Register address.
        register: u8,
        /// Value written (writable bits).
        expected: u8,
        /// Value read back (same bits).
        found: u8,
    },
    /// The magnetometer reported an axis out of its range (HMC5883L writes -4096): the field is
    /// stronger than the configured gain can measure.
    Overflow {
        /// The axis that overflowed.
        axis: Axis,
    },
    /// A part's own self-test failed (BNO055: ST_RESULT; one bit per sensor and the MCU, set when
    /// it passed).
    SelfTest {
        /// The result bits as read.
        result: u8,
    },
    /// An index argument (LED number, output channel, sensor number) is outside what the part has.
    OutOfRange {
        /// The value that was given.
        value: u16,
        /// The largest value the part accepts.
        max: u16,
    },
}

impl<E> From<E> for Error<E> {
    fn from(bus: E) -> Self {
        Error::Bus(bus)
    }
}

impl<E> Error<E> {
    /// The same error with the bus error mapped, e.g. to the bus's `ErrorKind` so errors from
    /// differently typed buses can share one type.
    pub fn map_bus<F>(self, f: impl FnOnce(E) -> F) -> Error<F> {
        match self {
            Error::Bus(e) => Error::Bus(f(e)),
            Error::WrongIdentity { expected, found } => Error::WrongIdentity { expected, found },
            Error::ConfigMismatch {
                register,
                expected,
                found,
            } => Error::ConfigMismatch {
                register,
                expected,
                found,
            },
            Error::Overflow { axis } => Error::Overflow { axis },
            Error::SelfTest { result } => Error::SelfTest { result },
            Error::OutOfRange { value, max } => Error::OutOfRange { value, max },
        }
    }
}

impl<E: fmt::Debug> fmt::Display for Error<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Bus(e) => write!(f, "bus error: {e:?}"),
            Error::WrongIdentity { expected, found } => {
                write!(
                    f,
                    "wrong device identity: expected {expected:#x}, found {found:#x}"
                )
            }
            Error::ConfigMismatch {
                register,
                expected,
                found,
            } => write!(
                f,
                "register {register:#04x} reads back {found:#04x} after writing {expected:#04x}"
            ),
            Error::Overflow { axis } => write!(f, "{axis:?} axis overflowed its range"),
            Error::SelfTest { result } => write!(f, "self-test failed: result {result:#04x}"),
            Error::OutOfRange { value, max } => write!(f, "index {value} out of range 0..={max}"),
        }
    }
}

/// A sensor axis, in the sensor's own frame (as printed on the part).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// X axis.
    X,
    /// Y axis.
    Y,
    /// Z axis.
    Z,
}

impl Axis {
    /// The three axes in the order every `[_; 3]` reading in this crate uses.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Index into an `[_; 3]` reading.
    pub const fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// Whether bytes a device returned are a dead bus's pattern rather than data: all `0x00` (MISO or
/// SDA held low, a part without power) or all `0xFF` (a floating or pulled-up line nobody drives).
///
/// A living part can return such a reading too (a gyroscope at rest reading exactly zero), so the
/// drivers never reject it on its own: they read the identity register once more and return the
/// data only if the part still answers with its identity ([`Error::WrongIdentity`] otherwise).
pub const fn is_bus_pattern(bytes: &[u8]) -> bool {
    let Some(&first) = bytes.first() else {
        return false;
    };
    if first != 0x00 && first != 0xFF {
        return false;
    }
    let mut i = 1;
    while i < bytes.len() {
        if bytes[i] != first {
            return false;
        }
        i += 1;
    }
    true
}

/// How many samples a board suite group takes between two identity checks of its devices
/// ([`suite`]): a part that reset, lost power or was replaced by a dead line answering plausible
/// bytes is noticed within this many samples even if its data never looks like a bus pattern.
pub const IDENTITY_CHECK_EVERY: u16 = 256;

/// Counts samples towards the next periodic identity check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct IdentitySchedule {
    pub(crate) samples: u16,
}

impl IdentitySchedule {
    /// Counts one sample; true when this sample should check identities first.
    pub(crate) fn due(&mut self) -> bool {
        self.samples = self.samples.wrapping_add(1);
        if self.samples >= IDENTITY_CHECK_EVERY {
            self.samples = 0;
            true
        } else {
            false
        }
    }
}

/// Compares a read-back register with what was written, on the bits the part lets us write.
pub(crate) fn check_register<E>(
    register: u8,
    written: u8,
    read: u8,
    writable: u8,
) -> Result<(), Error<E>> {
    if written & writable == read & writable {
        Ok(())
    } else {
        Err(Error::ConfigMismatch {
            register,
            expected: written & writable,
            found: read & writable,
        })
    }
}

/// `numerator / denominator` rounded to the nearest integer, halves away from zero.
///
/// `denominator` must be positive; every caller passes a datasheet constant.
pub(crate) const fn div_round(numerator: i64, denominator: i64) -> i64 {
    let half = denominator / 2;
    if numerator >= 0 {
        (numerator + half) / denominator
    } else {
        (numerator - half) / denominator
    }
}

/// Saturating conversion to `i16`, for wire units that cannot hold every value a finer unit can.
pub(crate) const fn saturate_i16(value: i64) -> i16 {
    if value > i16::MAX as i64 {
        i16::MAX
    } else if value < i16::MIN as i64 {
        i16::MIN
    } else {
        value as i16
    }
}

/// [`div_round`] in 32 bits: Rust's `/` truncates toward zero as the 64-bit one does, so the
/// result is the same, and the Cortex-M3 divides by a constant without calling the 64-bit division
/// routine (`__aeabi_ldivmod`, about 1 800 cycles bounded). Within `half` of the i32 ends the
/// rounding offset saturates (the callers' public structs can hold any i32), so the quotient is at
/// most one below the 64-bit one in size there: no overflow, and the same side of every i16 end.
pub(crate) const fn div_round_i32(numerator: i32, denominator: i32) -> i32 {
    let half = denominator / 2;
    if numerator >= 0 {
        numerator.saturating_add(half) / denominator
    } else {
        numerator.saturating_sub(half) / denominator
    }
}

// Declared after the shared helpers above, whose line numbers the boards' execution-time bounds
// files key loops by (schedule-analysis/models/*.bounds.json).
pub mod scripted;
