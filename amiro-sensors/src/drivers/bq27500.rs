//! Texas Instruments bq27500 fuel gauge on I2C (address 0x55; PowerManagement has two, one per
//! battery: the front gauge on I2C2, the rear gauge on I2C1).
//!
//! The gauge speaks "standard commands": one command byte selects a 16-bit little-endian value.
//! The map used here (bq27500 datasheet, standard data commands):
//!
//! | cmd | name | unit |
//! |---|---|---|
//! | 0x00 | Control() | subcommand in, result out |
//! | 0x06 | Temperature() | 0.1 K |
//! | 0x08 | Voltage() | mV |
//! | 0x0A | Flags() | bits, see [`Flags`] |
//! | 0x10 | RemainingCapacity() | mAh |
//! | 0x12 | FullChargeCapacity() | mAh |
//! | 0x14 | AverageCurrent() | mA, signed, positive = charging |
//! | 0x16 | TimeToEmpty() | min, 65535 = not discharging |
//! | 0x18 | TimeToFull() | min, 65535 = not charging |
//! | 0x24 | AveragePower() | mW, signed, positive = charging |
//! | 0x2C | StateOfCharge() | % |
//!
//! Control(): the subcommand is written to 0x00/0x01, then the result read from 0x00;
//! DEVICE_TYPE (0x0001) answers 0x0500. The datasheet asks for at least 66 µs of bus-free time
//! between packets to the gauge and, above 100 kHz, for single-byte writes; this driver writes the
//! subcommand as two one-byte writes and waits [`BUS_FREE_NS`] after every transfer (the AMiRo
//! 2.x runs the buses at 400 kHz).

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use super::Error;

/// The gauge's fixed 7-bit address.
pub const ADDRESS: u8 = 0x55;
/// Bus-free time the gauge needs between packets.
pub const BUS_FREE_NS: u32 = 66_000;
/// What Control(DEVICE_TYPE) returns on a bq27500.
pub const DEVICE_TYPE_VALUE: u16 = 0x0500;
/// The 0.1 K value of 0 °C.
const ZERO_CELSIUS_DECIKELVIN: i32 = 2731;

/// Standard command codes.
pub mod cmd {
    /// Control(): subcommand register.
    pub const CONTROL: u8 = 0x00;
    /// Temperature() in 0.1 K.
    pub const TEMPERATURE: u8 = 0x06;
    /// Voltage() in mV.
    pub const VOLTAGE: u8 = 0x08;
    /// Flags().
    pub const FLAGS: u8 = 0x0A;
    /// RemainingCapacity() in mAh.
    pub const REMAINING_CAPACITY: u8 = 0x10;
    /// FullChargeCapacity() in mAh.
    pub const FULL_CHARGE_CAPACITY: u8 = 0x12;
    /// AverageCurrent() in mA.
    pub const AVERAGE_CURRENT: u8 = 0x14;
    /// TimeToEmpty() in minutes.
    pub const TIME_TO_EMPTY: u8 = 0x16;
    /// TimeToFull() in minutes.
    pub const TIME_TO_FULL: u8 = 0x18;
    /// AveragePower() in mW.
    pub const AVERAGE_POWER: u8 = 0x24;
    /// StateOfCharge() in %.
    pub const STATE_OF_CHARGE: u8 = 0x2C;
}

/// Control() subcommands.
pub mod subcommand {
    /// CONTROL_STATUS.
    pub const CONTROL_STATUS: u16 = 0x0000;
    /// DEVICE_TYPE, answers [`super::DEVICE_TYPE_VALUE`].
    pub const DEVICE_TYPE: u16 = 0x0001;
    /// FW_VERSION.
    pub const FW_VERSION: u16 = 0x0002;
}

/// The time registers' "not applicable" value.
pub const TIME_NOT_APPLICABLE: u16 = 0xFFFF;

/// Flags() bits this crate interprets (bq27500 datasheet Flags table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Flags(pub u16);

impl Flags {
    /// Bit 15 OTC: over-temperature while charging.
    pub const OVER_TEMPERATURE_CHARGE: u16 = 1 << 15;
    /// Bit 14 OTD: over-temperature while discharging.
    pub const OVER_TEMPERATURE_DISCHARGE: u16 = 1 << 14;
    /// Bit 9 FC: full charge detected.
    pub const FULL_CHARGE: u16 = 1 << 9;
    /// Bit 8 CHG: (fast) charging allowed.
    pub const CHARGE_ALLOWED: u16 = 1 << 8;
    /// Bit 2 SOC1: state of charge below the first threshold.
    pub const SOC_LOW: u16 = 1 << 2;
    /// Bit 1 SOCF: state of charge below the final threshold.
    pub const SOC_FINAL: u16 = 1 << 1;
    /// Bit 0 DSG: discharging detected.
    pub const DISCHARGING: u16 = 1 << 0;

    /// Whether `bit` (one of the constants above) is set.
    pub const fn contains(self, bit: u16) -> bool {
        self.0 & bit != 0
    }
}

/// One battery's state as the gauge reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BatteryStatus {
    /// Cell temperature in 0.1 °C.
    pub temperature_decicelsius: i16,
    /// Battery voltage in mV.
    pub voltage_mv: u16,
    /// Flags().
    pub flags: Flags,
    /// Remaining capacity in mAh.
    pub remaining_capacity_mah: u16,
    /// Full-charge capacity in mAh.
    pub full_charge_capacity_mah: u16,
    /// Average current in mA, positive while charging.
    pub average_current_ma: i16,
    /// Minutes to empty, `None` while not discharging.
    pub time_to_empty_min: Option<u16>,
    /// Minutes to full, `None` while not charging.
    pub time_to_full_min: Option<u16>,
    /// Average power in mW, positive while charging.
    pub average_power_mw: i16,
    /// State of charge in % (0..=100).
    pub state_of_charge: u8,
}

impl BatteryStatus {
    /// Charging: current flows in and the gauge has not flagged discharge.
    pub const fn charging(&self) -> bool {
        self.average_current_ma > 0 && !self.flags.contains(Flags::DISCHARGING)
    }

    /// Minutes to full while charging, to empty otherwise; 65535 when the gauge has no estimate.
    pub fn minutes(&self) -> u16 {
        let estimate = if self.charging() {
            self.time_to_full_min
        } else {
            self.time_to_empty_min
        };
        estimate.unwrap_or(TIME_NOT_APPLICABLE)
    }

    /// Magnitude of the average power in mW.
    pub const fn power_mw(&self) -> u16 {
        self.average_power_mw.unsigned_abs()
    }
}

/// The robot's power state from both batteries: what the protocol's power-status frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PowerSummary {
    /// At least one battery is charging.
    pub charging: bool,
    /// Capacity-weighted state of charge of both batteries, %.
    pub state_of_charge: u8,
    /// Minutes until both are full (charging) or until both are empty (discharging); 65535 unknown.
    pub minutes: u16,
    /// Total power into or out of both batteries, mW (saturating).
    pub power_mw: u16,
}

impl PowerSummary {
    /// The summary of one battery.
    pub fn of(battery: &BatteryStatus) -> Self {
        Self {
            charging: battery.charging(),
            state_of_charge: battery.state_of_charge,
            minutes: battery.minutes(),
            power_mw: battery.power_mw(),
        }
    }

    /// The summary of the two batteries.
    ///
    /// Decisions (documented in docs/sensors.md): the state of charge is remaining over full
    /// capacity of both packs (the mean of the two percentages when a gauge reports no capacity);
    /// the robot runs on until the last pack is empty and is done charging when the last one is
    /// full, so the minutes are the larger of the two estimates that apply (an unknown estimate is
    /// ignored unless both are unknown); power is the sum.
    pub fn of_pair(a: &BatteryStatus, b: &BatteryStatus) -> Self {
        let charging = a.charging() || b.charging();
        let full = u32::from(a.full_charge_capacity_mah) + u32::from(b.full_charge_capacity_mah);
        let remaining = u32::from(a.remaining_capacity_mah) + u32::from(b.remaining_capacity_mah);
        let state_of_charge = match (remaining.min(full) * 100).checked_div(full) {
            Some(percent) => percent as u8,
            None => ((u32::from(a.state_of_charge) + u32::from(b.state_of_charge)) / 2) as u8,
        };
        let pick = |s: &BatteryStatus| {
            if charging {
                s.time_to_full_min
            } else {
                s.time_to_empty_min
            }
        };
        let minutes = match (pick(a), pick(b)) {
            (Some(x), Some(y)) => x.max(y),
            (Some(x), None) | (None, Some(x)) => x,
            (None, None) => TIME_NOT_APPLICABLE,
        };
        Self {
            charging,
            state_of_charge,
            minutes,
            power_mw: a.power_mw().saturating_add(b.power_mw()),
        }
    }
}

/// A bq27500 on an I2C bus, with a delay for the gauge's bus-free time.
#[derive(Debug)]
pub struct Bq27500<I2C, D> {
    i2c: I2C,
    delay: D,
}

impl<I2C: I2c, D: DelayNs> Bq27500<I2C, D> {
    /// A driver for the gauge at [`ADDRESS`]. Does no I/O.
    pub const fn new(i2c: I2C, delay: D) -> Self {
        Self { i2c, delay }
    }

    /// Checks that the gauge is a bq27500 (Control(DEVICE_TYPE) = 0x0500). The gauge needs no
    /// configuration.
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        device_type(self.control(subcommand::DEVICE_TYPE)?)
    }

    /// Sends a Control() subcommand and reads its result.
    pub fn control(&mut self, subcommand: u16) -> Result<u16, Error<I2C::Error>> {
        let [low, high, answer] = control_transfers(subcommand);
        self.transfer(low)?;
        self.transfer(high)?;
        self.transfer(answer)
    }

    /// Makes one transfer, then the bus-free time: a read's word, 0 for a write.
    pub fn transfer(&mut self, transfer: Transfer) -> Result<u16, Error<I2C::Error>> {
        match transfer {
            Transfer::Write { command, value } => self.write_paced(&[command, value]).map(|()| 0),
            Transfer::Read(command) => self.read_u16(command),
        }
    }

    /// Reads one standard command's 16-bit value.
    pub fn read_u16(&mut self, command: u8) -> Result<u16, Error<I2C::Error>> {
        let mut value = [0u8; 2];
        let result = self.i2c.write_read(ADDRESS, &[command], &mut value);
        self.delay.delay_ns(BUS_FREE_NS);
        result?;
        Ok(word(value))
    }

    /// Reads everything [`BatteryStatus`] holds (ten transfers, in command order): a
    /// [`StatusRead`] stepped to its end.
    ///
    /// Temperature and voltage both all `0x00` or all `0xFF` (0 K at 0 V, or 6553.5 K at
    /// 65.5 V: no gauge measures that) are a dead line's pattern; the status is returned only if
    /// the gauge then still answers DEVICE_TYPE ([`Error::WrongIdentity`] otherwise).
    pub fn read_status(&mut self) -> Result<BatteryStatus, Error<I2C::Error>> {
        let mut read = StatusRead::new();
        loop {
            if let Some(done) = read.step(self) {
                return done;
            }
        }
    }

    /// Gives the bus and the delay back.
    pub fn release(self) -> (I2C, D) {
        (self.i2c, self.delay)
    }

    fn write_paced(&mut self, bytes: &[u8]) -> Result<(), Error<I2C::Error>> {
        let result = self.i2c.write(ADDRESS, bytes);
        self.delay.delay_ns(BUS_FREE_NS);
        result?;
        Ok(())
    }
}

/// The status commands in the order a read makes them (temperature and voltage first: their
/// pattern decides whether the identity is checked before the rest).
const STATUS_COMMANDS: [u8; 10] = [
    cmd::TEMPERATURE,
    cmd::VOLTAGE,
    cmd::FLAGS,
    cmd::REMAINING_CAPACITY,
    cmd::FULL_CHARGE_CAPACITY,
    cmd::AVERAGE_CURRENT,
    cmd::TIME_TO_EMPTY,
    cmd::TIME_TO_FULL,
    cmd::AVERAGE_POWER,
    cmd::STATE_OF_CHARGE,
];

/// A status read ([`Bq27500::read_status`]) one transfer at a time, so that a caller sharing the
/// bus can give it back between transfers: a task waiting for the bus then waits for one
/// transfer to the gauge, not for a whole status read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatusRead {
    /// The words read so far, in [`STATUS_COMMANDS`] order.
    words: [u16; STATUS_COMMANDS.len()],
    /// How many of them are read.
    read: u8,
    /// The identity check's transfers made (0 to 3: the subcommand's two bytes, the answer; 3
    /// when it passed); [`IDENTITY_UNCHECKED`] while temperature and voltage show no dead
    /// line's pattern.
    identity: u8,
}

impl Default for StatusRead {
    fn default() -> Self {
        Self::new()
    }
}

/// [`StatusRead::identity`] while no identity check is needed.
const IDENTITY_UNCHECKED: u8 = u8::MAX;

impl StatusRead {
    /// The most transfers a read makes: ten reads and the three of the identity check.
    pub const MAX_TRANSFERS: usize = STATUS_COMMANDS.len() + 3;

    /// A read not begun.
    pub const fn new() -> Self {
        Self {
            words: [0; STATUS_COMMANDS.len()],
            read: 0,
            identity: IDENTITY_UNCHECKED,
        }
    }

    /// Begins the read again (the words already read are overwritten before they are used).
    pub fn restart(&mut self) {
        self.read = 0;
        self.identity = IDENTITY_UNCHECKED;
    }

    /// Makes the read's next transfer on `gauge`: `None` while transfers remain, then the status,
    /// or the error of the transfer that failed (the read ends there). At most
    /// [`StatusRead::MAX_TRANSFERS`] calls return `None` in a row.
    pub fn step<I2C: I2c, D: DelayNs>(
        &mut self,
        gauge: &mut Bq27500<I2C, D>,
    ) -> Option<Result<BatteryStatus, Error<I2C::Error>>> {
        let Some(transfer) = self.next_transfer() else {
            return Some(Ok(self.status()));
        };
        let outcome = gauge.transfer(transfer);
        self.complete(outcome)
    }

    /// The read's next transfer: the identity check's three when a dead line's pattern called
    /// for it, else the next status word's read; `None` once the ten words are read.
    pub fn next_transfer(&self) -> Option<Transfer> {
        match control_transfers(subcommand::DEVICE_TYPE).get(usize::from(self.identity)) {
            Some(&transfer) => Some(transfer),
            None => STATUS_COMMANDS
                .get(usize::from(self.read))
                .map(|&command| Transfer::Read(command)),
        }
    }

    /// The outcome of the transfer [`next_transfer`](Self::next_transfer) named (a read's word,
    /// anything for a write): `None` while transfers remain, then the status, or the error of
    /// the transfer that failed (the read ends there).
    pub fn complete<E>(
        &mut self,
        outcome: Result<u16, Error<E>>,
    ) -> Option<Result<BatteryStatus, Error<E>>> {
        let checking = self.identity < 3;
        let k = usize::from(self.read);
        let step = match (self.identity, outcome) {
            (_, Err(e)) => Err(e),
            (2, Ok(found)) => device_type(found),
            (0 | 1, Ok(_)) => Ok(()),
            (_, Ok(value)) => match self.words.get_mut(k) {
                Some(word) => {
                    *word = value;
                    Ok(())
                }
                None => return Some(Ok(self.status())),
            },
        };
        if let Err(e) = step {
            return Some(Err(e));
        }
        if checking {
            self.identity += 1;
        } else {
            self.read += 1;
            if self.read == 2 {
                let [t, v, ..] = self.words;
                let [t0, t1] = t.to_le_bytes();
                let [v0, v1] = v.to_le_bytes();
                if super::is_bus_pattern(&[t0, t1, v0, v1]) {
                    self.identity = 0;
                }
            }
        }
        (usize::from(self.read) == STATUS_COMMANDS.len()).then(|| Ok(self.status()))
    }

    /// The status from the ten words.
    fn status(&self) -> BatteryStatus {
        let [temperature, voltage_mv, flags, remaining, full, current, tte, ttf, power, soc] =
            self.words;
        let celsius = i32::from(temperature) - ZERO_CELSIUS_DECIKELVIN;
        BatteryStatus {
            temperature_decicelsius: celsius.clamp(i16::MIN.into(), i16::MAX.into()) as i16,
            voltage_mv,
            flags: Flags(flags),
            remaining_capacity_mah: remaining,
            full_charge_capacity_mah: full,
            average_current_ma: current as i16,
            time_to_empty_min: (tte != TIME_NOT_APPLICABLE).then_some(tte),
            time_to_full_min: (ttf != TIME_NOT_APPLICABLE).then_some(ttf),
            average_power_mw: power as i16,
            state_of_charge: soc.min(100) as u8,
        }
    }
}

/// One packet to the gauge: each a transfer of its own, with [`BUS_FREE_NS`] of bus-free time
/// after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transfer {
    /// A one-byte write to a command register (a Control() subcommand byte).
    Write {
        /// The command register.
        command: u8,
        /// The byte.
        value: u8,
    },
    /// A standard command's 16-bit little-endian read ([`word`]).
    Read(u8),
}

/// A Control() subcommand's transfers: its low byte to 0x00, its high byte to 0x01 (one-byte
/// writes, as the datasheet asks above 100 kHz), the answer read from 0x00.
pub const fn control_transfers(subcommand: u16) -> [Transfer; 3] {
    let [low, high] = subcommand.to_le_bytes();
    [
        Transfer::Write {
            command: cmd::CONTROL,
            value: low,
        },
        Transfer::Write {
            command: cmd::CONTROL + 1,
            value: high,
        },
        Transfer::Read(cmd::CONTROL),
    ]
}

/// Control(DEVICE_TYPE)'s answer: a bq27500's [`DEVICE_TYPE_VALUE`], or
/// [`Error::WrongIdentity`].
pub fn device_type<E>(found: u16) -> Result<(), Error<E>> {
    if found == DEVICE_TYPE_VALUE {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: DEVICE_TYPE_VALUE.into(),
            found: found.into(),
        })
    }
}

/// A standard command's two bytes (little-endian) as its word.
pub const fn word(bytes: [u8; 2]) -> u16 {
    u16::from_le_bytes(bytes)
}

/// A transfer as a script operation (decoded by [`word`]); the script holds nothing else, for
/// the gauge's bus-free time between packets.
pub fn transfer_op(
    script: &mut crate::script::Script,
    transfer: Transfer,
) -> Result<(), crate::script::BuildError> {
    match transfer {
        Transfer::Write { command, value } => script.write(ADDRESS, &[command, value])?,
        Transfer::Read(command) => script.write_read(ADDRESS, &[command], 2)?,
    };
    Ok(())
}
