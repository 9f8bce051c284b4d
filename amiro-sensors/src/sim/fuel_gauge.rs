//! Simulated bq27500 fuel gauge (I2C 0x55).

use super::{RegisterDevice, RegisterPointer, SimBus};
use crate::drivers::bq27500::{self, cmd, subcommand, Flags};

/// Full-charge capacity of the simulated cell, mAh.
const FULL_MAH: u32 = 2_000;
/// Charging current, mA.
const CHARGE_MA: i32 = 800;
/// Discharging current, mA (negative: out of the cell).
const DISCHARGE_MA: i32 = -450;

/// A simulated bq27500.
///
/// Pattern (one step per read of StateOfCharge(), the last value a status read asks for): a
/// 2000 mAh cell discharging at 450 mA from 90 % down to 11 % and starting over, or charging at
/// 800 mA from 10 % up to 99 %, one percent every eight samples; voltage, power, remaining
/// capacity, time to empty/full and the flags follow from that, the time estimates 65535 where the
/// gauge has none. Control(): subcommands DEVICE_TYPE (0x0500), FW_VERSION (0x0109) and
/// CONTROL_STATUS (0) are answered.
#[derive(Debug, Clone)]
pub struct SimBq27500 {
    charging: bool,
    pointer: RegisterPointer,
    subcommand: u16,
    samples: u16,
}

impl SimBq27500 {
    /// A gauge on a cell that is charging (`true`) or discharging.
    pub const fn new(charging: bool) -> Self {
        Self {
            charging,
            pointer: RegisterPointer::new(),
            subcommand: 0,
            samples: 0,
        }
    }

    /// Switches between charging and discharging.
    pub fn set_charging(&mut self, charging: bool) {
        self.charging = charging;
    }

    /// StateOfCharge() reads so far.
    pub const fn samples(&self) -> u16 {
        self.samples
    }

    /// The last Control() subcommand written.
    pub const fn last_subcommand(&self) -> u16 {
        self.subcommand
    }

    /// State of charge in % at sample `n`.
    pub const fn state_of_charge_at(charging: bool, n: u16) -> u16 {
        let step = (n / 8) % 80;
        if charging {
            10 + step
        } else {
            90 - step
        }
    }

    /// The 16-bit value of standard command `command` now.
    pub fn value(&self, command: u8) -> u16 {
        let soc = Self::state_of_charge_at(self.charging, self.samples);
        let remaining = FULL_MAH * u32::from(soc) / 100;
        let current = if self.charging {
            CHARGE_MA
        } else {
            DISCHARGE_MA
        };
        let voltage = 3_500 + 7 * u32::from(soc);
        match command {
            cmd::CONTROL => match self.subcommand {
                subcommand::DEVICE_TYPE => bq27500::DEVICE_TYPE_VALUE,
                subcommand::FW_VERSION => 0x0109,
                _ => 0,
            },
            cmd::TEMPERATURE => 2_981 + self.samples % 20,
            cmd::VOLTAGE => voltage as u16,
            cmd::FLAGS => {
                if self.charging {
                    Flags::CHARGE_ALLOWED
                } else {
                    Flags::DISCHARGING
                }
            }
            cmd::REMAINING_CAPACITY => remaining as u16,
            cmd::FULL_CHARGE_CAPACITY => FULL_MAH as u16,
            cmd::AVERAGE_CURRENT => current as i16 as u16,
            cmd::TIME_TO_EMPTY if !self.charging => {
                (remaining * 60 / DISCHARGE_MA.unsigned_abs()) as u16
            }
            cmd::TIME_TO_FULL if self.charging => {
                ((FULL_MAH - remaining) * 60 / CHARGE_MA.unsigned_abs()) as u16
            }
            cmd::TIME_TO_EMPTY | cmd::TIME_TO_FULL => bq27500::TIME_NOT_APPLICABLE,
            cmd::AVERAGE_POWER => (current * voltage as i32 / 1000) as i16 as u16,
            cmd::STATE_OF_CHARGE => soc,
            _ => 0,
        }
    }
}

impl RegisterDevice for SimBq27500 {
    const ADDRESS: u8 = bq27500::ADDRESS;

    fn pointer(&mut self) -> &mut RegisterPointer {
        &mut self.pointer
    }

    fn write_register(&mut self, register: u8, byte: u8) {
        // Only Control() is writable among the standard commands.
        let [low, high] = self.subcommand.to_le_bytes();
        match register {
            0x00 => self.subcommand = u16::from_le_bytes([byte, high]),
            0x01 => self.subcommand = u16::from_le_bytes([low, byte]),
            _ => {}
        }
    }

    fn read_register(&mut self, register: u8) -> u8 {
        let command = register & !1;
        let [low, high] = self.value(command).to_le_bytes();
        if register == cmd::STATE_OF_CHARGE + 1 {
            self.samples = self.samples.wrapping_add(1);
        }
        if register & 1 == 0 {
            low
        } else {
            high
        }
    }
}

impl SimBus<(super::SimMuxedProximity, SimBq27500)> {
    /// The simulated fuel gauge.
    pub const fn fuel_gauge(&self) -> &SimBq27500 {
        &self.target.1
    }

    /// The simulated fuel gauge, to change its state.
    pub fn fuel_gauge_mut(&mut self) -> &mut SimBq27500 {
        &mut self.target.1
    }

    /// The simulated mux and ring sensors.
    pub const fn proximity(&self) -> &super::SimMuxedProximity {
        &self.target.0
    }
}
