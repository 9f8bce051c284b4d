//! The simulated buses answer a whole [`Script`]: its operations run against the simulated
//! devices' registers, byte by byte as the wire carries them, and the answer holds the readings
//! (or the typed error of the operation that failed) and the script's time on the bus, so the
//! QEMU build can complete the script after that time on its monotonic, as the engine's
//! interrupt would.

use super::{I2cTarget, SimBus};
use crate::drivers::scripted::{OnI2c, ScriptBus};
use crate::script::{Readings, Script, ScriptError, Symbol};

/// The AMiRo's I2C clock, [`crate::script::SCL_HZ`].
pub use crate::script::SCL_HZ;

/// What a simulated bus answers to a script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Answer {
    /// The readings, or the failing operation's error.
    pub result: Result<Readings, ScriptError>,
    /// SCL periods the script held the bus for: the whole script's
    /// ([`Script::scl_periods`]), or up to the STOP after the address nobody acknowledged.
    pub scl_periods: u32,
}

impl Answer {
    /// The bus time in nanoseconds at [`SCL_HZ`] (rounded up).
    pub fn bus_time_ns(&self) -> u64 {
        crate::script::periods_ns(self.scl_periods, SCL_HZ)
    }
}

/// SCL periods of `script` up to and including operation `failed`'s address byte and the STOP
/// the master sends after the missing acknowledge.
fn periods_until_nack(script: &Script, failed: usize) -> u32 {
    let mut periods = 0;
    let mut stops = 0;
    let mut addressed = false;
    for symbol in script.wire() {
        periods += symbol.scl_periods();
        match symbol {
            Symbol::Stop => stops += 1,
            Symbol::Address { .. } if stops == failed => {
                addressed = true;
                break;
            }
            _ => {}
        }
    }
    if addressed {
        periods + 1
    } else {
        periods
    }
}

impl<T: I2cTarget> SimBus<T> {
    /// Runs `script` on the simulated devices: each operation is a transfer (the write, then the
    /// read after a repeated START), the first one whose address nobody acknowledges ends the
    /// script with [`Failure::NackAddress`](crate::script::Failure::NackAddress) (a device that is absent, behind a channel the mux has
    /// not connected, or every device while [`SimBus::set_nack`] holds).
    pub fn answer(&mut self, script: &Script) -> Answer {
        // The operations as the blocking path makes them (one embedded-hal transfer each, on
        // this bus's own `I2c`), so the simulators answer a script as they answer the drivers.
        let result = OnI2c(&mut *self).run(script);
        let scl_periods = match result {
            Err(ScriptError { operation, .. }) => {
                periods_until_nack(script, usize::from(operation))
            }
            Ok(_) => script.scl_periods(),
        };
        Answer {
            result,
            scl_periods,
        }
    }
}

impl<T: I2cTarget> ScriptBus for SimBus<T> {
    fn run(&mut self, script: &Script) -> Result<Readings, ScriptError> {
        self.answer(script).result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::hmc5883l;
    use crate::script::Failure;
    use crate::sim::{SimCompassBus, SimFloorBus};

    #[test]
    fn a_register_read_answers_the_registers_and_its_wire_time() {
        let mut bus = SimCompassBus::new();
        let mut script = Script::new();
        script
            .write_read(hmc5883l::ADDRESS, &[hmc5883l::reg::IDENTIFICATION_A], 3)
            .unwrap();
        let answer = bus.answer(&script);
        assert_eq!(answer.result.unwrap().of(0), b"H43");
        // S, address, register, Sr, address, three bytes, P: 6 × 9 + 3 periods.
        assert_eq!(answer.scl_periods, 57);
        assert_eq!(answer.bus_time_ns(), 142_500);
    }

    #[test]
    fn a_missing_device_fails_its_operation_and_the_time_ends_at_its_stop() {
        let mut bus = SimFloorBus::new();
        let mut script = Script::new();
        // The mux answers; the VCNL4020 behind it does not until a channel is connected.
        script.write(0x77, &[0x00]).unwrap();
        script.write_read(0x13, &[0x81], 1).unwrap();
        let answer = bus.answer(&script);
        assert_eq!(
            answer.result,
            Err(ScriptError {
                operation: 1,
                failure: Failure::NackAddress
            })
        );
        // The select (S, 2 bytes, P = 20) and S, address, P of the refused operation (11).
        assert_eq!(answer.scl_periods, 31);
        bus.set_nack(true);
        let answer = bus.answer(&script);
        assert_eq!(answer.result.unwrap_err().operation, 0);
        assert_eq!(answer.scl_periods, 11);
    }
}
