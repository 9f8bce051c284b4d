//! A sensor sample's bus work as one *script*: a bounded list of I2C operations that an
//! interrupt-driven engine runs from start to end with no other client's operation in between
//! (docs/i2c.md). The bytes to write travel inside the script and the bytes read come back inside
//! its [`Readings`], both by value, so a client that gives up on a script leaves no pointer behind.
//!
//! Each operation is one transaction on the bus (it ends with a STOP): a write, a read, or a write
//! then a read after a repeated START (a register read). Operations end with a STOP rather than
//! run into the next one with a repeated START because the PCA9544A connects a selected channel
//! only at a STOP (its datasheet, "Control register"): a mux select and the read behind it must be
//! two transactions.
//!
//! The capacities are the AMiRo devices' largest scripts (`drivers/`):
//!
//! | Device and read | Operations | Written | Read |
//! |---|---|---|---|
//! | HMC5883L sample (`read_raw`) | 1: write 1, read 6 | 1 | 6 |
//! | VCNL4020 floor round, proximity only (`Floor::read_proximity`) | 8: 4 × (mux select; write 1, read 2) | 8 | 8 |
//! | VCNL4020 floor or ring round (`Floor::read`, one bus of `Ring::read`) | 12: 4 × (select; proximity; ambient) | 12 | 16 |
//! | bq27500 standard command (`read_u16`) | 1: write 1, read 2 | 1 | 2 |
//! | BNO055 nine axes (`read_raw`) | 1: write 1, read 18 | 1 | 18 |
//! | BNO055 one sensor then OPR_MODE (`read_verified`) | 2 | 2 | 7 |
//! | BNO055 configuration write (`ACC_CONFIG`) | 1: write 5 | 5 | 0 |
//!
//! The bq27500 wants 66 µs of bus-free time between packets (`bq27500::BUS_FREE_NS`), which no
//! script holds: each of its commands is a script of its own, the pause the client's between them.
use core::fmt;

/// Operations a script holds: a floor (or one bus of the ring) round of four VCNL4020s, each a mux
/// select and two two-byte result reads.
pub const MAX_OPERATIONS: usize = 12;
/// Bytes a script writes, all operations together: the floor round's twelve register and control
/// bytes, with room for a BNO055 configuration write.
pub const MAX_WRITE_BYTES: usize = 16;
/// Bytes a script reads, all operations together: the BNO055's 18-byte nine-axis burst with a
/// check read beside it, or a floor round's sixteen.
pub const MAX_READ_BYTES: usize = 24;

/// One transaction of a script: `write` bytes (taken from the script's written bytes in order),
/// then, after a repeated START if both are non-zero, `read` bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Operation {
    /// The device's 7-bit address.
    pub address: u8,
    /// Bytes written (0 for a plain read).
    pub write: u8,
    /// Bytes read (0 for a plain write).
    pub read: u8,
}

/// Why a script could not be built (the shapes are constants of the drivers: a failure here is a
/// programming error that a host test of the driver finds).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuildError {
    /// The script already holds [`MAX_OPERATIONS`].
    TooManyOperations,
    /// The bytes to write would pass [`MAX_WRITE_BYTES`].
    TooManyWrittenBytes,
    /// The bytes to read would pass [`MAX_READ_BYTES`].
    TooManyReadBytes,
    /// An operation that neither writes nor reads (an address probe: not supported).
    EmptyOperation,
    /// Not a 7-bit address.
    Address(u8),
}

/// A bounded list of I2C operations, with the bytes they write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Script {
    operations: [Operation; MAX_OPERATIONS],
    count: u8,
    written: [u8; MAX_WRITE_BYTES],
    written_len: u8,
    read_len: u8,
}

impl Default for Script {
    fn default() -> Self {
        Self::new()
    }
}

impl Script {
    /// An empty script.
    pub const fn new() -> Self {
        Self {
            operations: [Operation {
                address: 0,
                write: 0,
                read: 0,
            }; MAX_OPERATIONS],
            count: 0,
            written: [0; MAX_WRITE_BYTES],
            written_len: 0,
            read_len: 0,
        }
    }

    /// Appends a write of `bytes` to `address`.
    pub fn write(&mut self, address: u8, bytes: &[u8]) -> Result<&mut Self, BuildError> {
        self.push(address, bytes, 0)
    }

    /// Appends a read of `count` bytes from `address`.
    pub fn read(&mut self, address: u8, count: usize) -> Result<&mut Self, BuildError> {
        self.push(address, &[], count)
    }

    /// Appends a write of `bytes` then, after a repeated START, a read of `count` bytes: a
    /// register read.
    pub fn write_read(
        &mut self,
        address: u8,
        bytes: &[u8],
        count: usize,
    ) -> Result<&mut Self, BuildError> {
        self.push(address, bytes, count)
    }

    fn push(&mut self, address: u8, bytes: &[u8], count: usize) -> Result<&mut Self, BuildError> {
        if address > 0x7F {
            return Err(BuildError::Address(address));
        }
        if bytes.is_empty() && count == 0 {
            return Err(BuildError::EmptyOperation);
        }
        let index = usize::from(self.count);
        if index >= MAX_OPERATIONS {
            return Err(BuildError::TooManyOperations);
        }
        let start = usize::from(self.written_len);
        let end = start + bytes.len();
        let target = self
            .written
            .get_mut(start..end)
            .ok_or(BuildError::TooManyWrittenBytes)?;
        let read_end = usize::from(self.read_len) + count;
        if read_end > MAX_READ_BYTES {
            return Err(BuildError::TooManyReadBytes);
        }
        target.copy_from_slice(bytes);
        // Each of the three is below its capacity (at most 24), so the narrowing is exact.
        self.operations[index] = Operation {
            address,
            write: bytes.len() as u8,
            read: count as u8,
        };
        self.count += 1;
        self.written_len = end as u8;
        self.read_len = read_end as u8;
        Ok(self)
    }

    /// The operations, in order.
    pub fn operations(&self) -> &[Operation] {
        &self.operations[..usize::from(self.count)]
    }

    /// Every byte the script writes, in order (the operations' `write` counts split it).
    pub fn written(&self) -> &[u8] {
        &self.written[..usize::from(self.written_len)]
    }

    /// How many bytes the script reads, all operations together.
    pub fn read_len(&self) -> usize {
        usize::from(self.read_len)
    }

    /// The script's traffic on the wire, in order: what the bus carries and so what its time is
    /// charged from.
    pub fn wire(&self) -> Wire<'_> {
        Wire {
            script: self,
            operation: 0,
            step: Step::Start,
            written: 0,
        }
    }

    /// SCL periods the script occupies the bus for: nine per byte (eight bits and the
    /// acknowledge), one per START, repeated START and STOP (each is at most one period at
    /// 400 kHz: a START's hold and set-up times are 0.6 µs each, a STOP's set-up time and the
    /// bus-free time after it 0.6 µs and 1.3 µs, of a 2.5 µs period; I2C-bus specification
    /// UM10204, table 10). A device's clock stretching is not in it: the analysis adds the
    /// devices' stated stretches.
    ///
    /// Counted per operation, not by walking [`Self::wire`] symbol by symbol (a script's time is
    /// worked out at each submission, in the client's job: 12 passes at most where the walk
    /// takes up to 100): its START and STOP; where it writes, its address and written bytes;
    /// where it writes and reads, the repeated START; where it reads, its address and read bytes
    /// — the wire's symbols exactly (`the_periods_counted_per_operation_are_the_wires`).
    pub fn scl_periods(&self) -> u32 {
        let mut periods = 0u32;
        for op in self.operations() {
            let (write, read) = (u32::from(op.write), u32::from(op.read));
            periods += 2;
            if write > 0 {
                periods += 9 * (1 + write);
            }
            if write > 0 && read > 0 {
                periods += 1;
            }
            if read > 0 {
                periods += 9 * (1 + read);
            }
        }
        periods
    }

    /// The script's time on the bus in nanoseconds at `scl_hz` (rounded up): [`Self::scl_periods`]
    /// SCL periods.
    pub fn bus_time_ns(&self, scl_hz: u32) -> u64 {
        periods_ns(self.scl_periods(), scl_hz)
    }
}

/// `periods` SCL periods in nanoseconds at `scl_hz` (rounded up).
pub fn periods_ns(periods: u32, scl_hz: u32) -> u64 {
    (u64::from(periods) * 1_000_000_000).div_ceil(u64::from(scl_hz.max(1)))
}

/// One symbol on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Symbol {
    /// A START condition.
    Start,
    /// A repeated START (between an operation's write and its read).
    RepeatedStart,
    /// The address byte: 7-bit address and the direction bit.
    Address {
        /// The 7-bit address.
        address: u8,
        /// The direction bit (a read).
        read: bool,
    },
    /// A byte the master writes.
    Written(u8),
    /// A byte the device sends; `last` is not acknowledged by the master.
    Read {
        /// The operation's last byte (the master answers NACK).
        last: bool,
    },
    /// A STOP condition.
    Stop,
}

impl Symbol {
    /// SCL periods the symbol holds the bus for: nine for a byte and its acknowledge, one for a
    /// START, repeated START or STOP ([`Script::scl_periods`]).
    pub const fn scl_periods(self) -> u32 {
        match self {
            Symbol::Address { .. } | Symbol::Written(_) | Symbol::Read { .. } => 9,
            Symbol::Start | Symbol::RepeatedStart | Symbol::Stop => 1,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Start,
    WriteAddress,
    Write(u8),
    RepeatedStart,
    ReadAddress,
    Read(u8),
    Stop,
}

/// The iterator of [`Script::wire`].
#[derive(Debug, Clone)]
pub struct Wire<'a> {
    script: &'a Script,
    operation: usize,
    step: Step,
    written: usize,
}

impl Iterator for Wire<'_> {
    type Item = Symbol;

    fn next(&mut self) -> Option<Symbol> {
        let op = *self.script.operations().get(self.operation)?;
        let (symbol, next) = match self.step {
            Step::Start if op.write > 0 => (Symbol::Start, Step::WriteAddress),
            Step::Start => (Symbol::Start, Step::ReadAddress),
            Step::WriteAddress => (
                Symbol::Address {
                    address: op.address,
                    read: false,
                },
                Step::Write(0),
            ),
            Step::Write(n) => {
                let byte = self.script.written().get(self.written).copied()?;
                self.written += 1;
                let next = if n + 1 < op.write {
                    Step::Write(n + 1)
                } else if op.read > 0 {
                    Step::RepeatedStart
                } else {
                    Step::Stop
                };
                (Symbol::Written(byte), next)
            }
            Step::RepeatedStart => (Symbol::RepeatedStart, Step::ReadAddress),
            Step::ReadAddress => (
                Symbol::Address {
                    address: op.address,
                    read: true,
                },
                Step::Read(0),
            ),
            Step::Read(n) => {
                let last = n + 1 == op.read;
                let next = if last { Step::Stop } else { Step::Read(n + 1) };
                (Symbol::Read { last }, next)
            }
            Step::Stop => {
                self.operation += 1;
                (Symbol::Stop, Step::Start)
            }
        };
        self.step = next;
        Some(symbol)
    }
}

/// The bytes a script read, by value, split by operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Readings {
    bytes: [u8; MAX_READ_BYTES],
    /// Each operation's read count, as in its script.
    reads: [u8; MAX_OPERATIONS],
    stored: u8,
}

impl Readings {
    /// No readings (a slot's before its first script).
    pub const fn empty() -> Self {
        Self {
            bytes: [0; MAX_READ_BYTES],
            reads: [0; MAX_OPERATIONS],
            stored: 0,
        }
    }

    /// Empty readings laid out for `script`'s operations.
    pub fn for_script(script: &Script) -> Self {
        let mut reads = [0; MAX_OPERATIONS];
        for (read, op) in reads.iter_mut().zip(script.operations()) {
            *read = op.read;
        }
        Self {
            bytes: [0; MAX_READ_BYTES],
            reads,
            stored: 0,
        }
    }

    /// Stores the next byte read (the engine calls it in wire order); a byte past the capacity is
    /// dropped (the engine reads no more than the script asks for).
    pub fn push(&mut self, byte: u8) {
        let stored = self.stored;
        if let Some(slot) = self.bytes.get_mut(usize::from(stored)) {
            *slot = byte;
            self.stored = stored + 1;
        }
    }

    /// The bytes operation `index` read (empty for a write or an index past the script).
    pub fn of(&self, index: usize) -> &[u8] {
        let start: usize = self.reads.iter().take(index).map(|&r| usize::from(r)).sum();
        let len = self.reads.get(index).map_or(0, |&r| usize::from(r));
        self.bytes.get(start..start + len).unwrap_or(&[])
    }

    /// Every byte read so far, in order.
    pub fn all(&self) -> &[u8] {
        &self.bytes[..usize::from(self.stored)]
    }
}

/// What ended a script early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Nobody acknowledged the address (device absent, or busy and refusing).
    NackAddress,
    /// The device did not acknowledge a written byte.
    NackData,
    /// A misplaced START or STOP on the bus (BERR).
    Bus,
    /// Another master won the bus (ARLO).
    ArbitrationLoss,
    /// The data register was overrun (OVR; in master mode only with a fault of the block).
    Overrun,
    /// The block raised an event the sequence does not allow at this step (the block is reset).
    UnexpectedEvent,
    /// The client already has a script on the bus (one slot per client).
    Busy,
    /// The script was still on the bus at its deadline (its wire time and a stated allowance per
    /// flag: a device stretched SCL longer, or held it); the bus ended it, cleared the lines and
    /// reset the block (`amiro_firmware::i2c_bus`).
    Stretched,
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Failure::NackAddress => "address not acknowledged",
            Failure::NackData => "data byte not acknowledged",
            Failure::Bus => "bus error",
            Failure::ArbitrationLoss => "arbitration lost",
            Failure::Overrun => "overrun",
            Failure::UnexpectedEvent => "unexpected event",
            Failure::Busy => "client busy",
            Failure::Stretched => "past its deadline (clock stretched)",
        })
    }
}

/// A script's failure and the operation it happened in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScriptError {
    /// The failing operation's index in its script.
    pub operation: u8,
    /// What happened.
    pub failure: Failure,
}

impl fmt::Display for ScriptError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "operation {}: {}", self.operation, self.failure)
    }
}

/// Where a part's transactions go, so that each sequence is written once (the drivers' `ops`
/// modules) and both paths run it: a script being built ([`Script`]; a read answers with where its
/// bytes will land, [`At`]) or a blocking bus that runs each transaction at once ([`Blocking`]; a
/// read answers with its bytes). The methods are named apart from [`Script`]'s own builders.
pub trait Transfers {
    /// What a transaction that cannot be made reports.
    type Error;
    /// What a read of `N` bytes answers with.
    type Read<const N: usize>;
    /// A write of `bytes` to `address`.
    fn send(&mut self, address: u8, bytes: &[u8]) -> Result<(), Self::Error>;
    /// A register read: `bytes` written to `address`, then `N` bytes read after a repeated START.
    fn fetch<const N: usize>(
        &mut self,
        address: u8,
        bytes: &[u8],
    ) -> Result<Self::Read<N>, Self::Error>;
}

/// Where an `N`-byte read of a script lands in its [`Readings`]: its operation's index, as the
/// sequence that built the script answered it (no caller restates a script's layout).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct At<const N: usize>(u8);

impl<const N: usize> At<N> {
    /// The read's operation index.
    pub const fn operation(self) -> usize {
        self.0 as usize
    }

    /// The bytes the read gave, or `None` if `readings` hold another count there (a script
    /// that came back short).
    pub fn of(self, readings: &Readings) -> Option<[u8; N]> {
        readings.of(self.operation()).try_into().ok()
    }
}

impl Transfers for Script {
    type Error = BuildError;
    type Read<const N: usize> = At<N>;

    fn send(&mut self, address: u8, bytes: &[u8]) -> Result<(), BuildError> {
        self.write(address, bytes).map(|_| ())
    }

    fn fetch<const N: usize>(&mut self, address: u8, bytes: &[u8]) -> Result<At<N>, BuildError> {
        let at = At(self.count);
        self.write_read(address, bytes, N)?;
        Ok(at)
    }
}

/// A blocking embedded-hal bus seen as [`Transfers`]: each transaction runs at once (the blocking
/// drivers' side of their `ops`).
#[derive(Debug)]
pub struct Blocking<'a, I>(pub &'a mut I);

impl<I: embedded_hal::i2c::I2c> Transfers for Blocking<'_, I> {
    type Error = I::Error;
    type Read<const N: usize> = [u8; N];

    #[inline(always)]
    fn send(&mut self, address: u8, bytes: &[u8]) -> Result<(), I::Error> {
        self.0.write(address, bytes)
    }

    #[inline(always)]
    fn fetch<const N: usize>(&mut self, address: u8, bytes: &[u8]) -> Result<[u8; N], I::Error> {
        let mut read = [0u8; N];
        self.0.write_read(address, bytes, &mut read)?;
        Ok(read)
    }
}

/// The sensor buses' SCL rate: 400 kHz (fast mode) on I2C1 and I2C2 of every board
/// (amiro-boards.md); the one figure the engine's timeouts and the simulated buses' times use.
pub const SCL_HZ: u32 = 400_000;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::{bno055, bq27500, hmc5883l, pca9544a, vcnl4020};

    /// The floor round of `Floor::read`: per sensor a mux select, the proximity and the ambient
    /// result (each a one-byte register write and a two-byte read).
    fn floor_round() -> Script {
        let mut script = Script::new();
        for channel in [4u8, 5, 6, 7] {
            script.write(pca9544a::AMIRO_ADDRESS, &[channel]).unwrap();
            script
                .write_read(vcnl4020::ADDRESS, &[vcnl4020::reg::PROXIMITY_RESULT], 2)
                .unwrap();
            script
                .write_read(vcnl4020::ADDRESS, &[vcnl4020::reg::AMBIENT_RESULT], 2)
                .unwrap();
        }
        script
    }

    #[test]
    fn the_devices_largest_scripts_fit() {
        let floor = floor_round();
        assert_eq!(floor.operations().len(), MAX_OPERATIONS);
        assert_eq!(floor.read_len(), 16);
        let mut bno = Script::new();
        bno.write_read(bno055::ADDRESS, &[0x08], 18).unwrap();
        bno.write_read(bno055::ADDRESS, &[0x3D], 1).unwrap();
        assert_eq!(bno.read_len(), 19);
        let mut config = Script::new();
        config.write(bno055::ADDRESS, &[0x08, 1, 2, 3, 4]).unwrap();
        let mut gauge = Script::new();
        gauge.write_read(bq27500::ADDRESS, &[0x06], 2).unwrap();
        let mut hmc = Script::new();
        hmc.write_read(hmc5883l::ADDRESS, &[hmc5883l::reg::DATA_X_MSB], 6)
            .unwrap();
        assert_eq!(
            hmc.operations()[0],
            Operation {
                address: 0x1E,
                write: 1,
                read: 6
            }
        );
    }

    #[test]
    fn a_full_script_refuses_with_the_capacity_it_hit() {
        let mut floor = floor_round();
        assert_eq!(
            floor.write(0x10, &[1]).unwrap_err(),
            BuildError::TooManyOperations
        );
        let mut script = Script::new();
        assert_eq!(
            script.read(0x10, MAX_READ_BYTES + 1).unwrap_err(),
            BuildError::TooManyReadBytes
        );
        assert_eq!(
            script.write(0x10, &[0; MAX_WRITE_BYTES + 1]).unwrap_err(),
            BuildError::TooManyWrittenBytes
        );
        assert_eq!(
            script.write(0x80, &[1]).unwrap_err(),
            BuildError::Address(0x80)
        );
        assert_eq!(
            script.read(0x10, 0).unwrap_err(),
            BuildError::EmptyOperation
        );
        // A refused operation changes nothing.
        assert!(script.operations().is_empty() && script.written().is_empty());
        assert_eq!(script.read_len(), 0);
    }

    #[test]
    fn the_wire_of_a_register_read_has_its_repeated_start() {
        let mut script = Script::new();
        script.write_read(0x1E, &[0x03], 3).unwrap();
        let wire: Vec<Symbol> = script.wire().collect();
        assert_eq!(
            wire,
            [
                Symbol::Start,
                Symbol::Address {
                    address: 0x1E,
                    read: false
                },
                Symbol::Written(0x03),
                Symbol::RepeatedStart,
                Symbol::Address {
                    address: 0x1E,
                    read: true
                },
                Symbol::Read { last: false },
                Symbol::Read { last: false },
                Symbol::Read { last: true },
                Symbol::Stop,
            ]
        );
        // Six bytes (two addresses, the register, three read) of nine periods, START, repeated
        // START and STOP.
        assert_eq!(script.scl_periods(), 57);
        assert_eq!(script.bus_time_ns(400_000), 142_500);
    }

    #[test]
    fn the_floor_round_is_twelve_transactions_on_the_wire() {
        let floor = floor_round();
        let wire: Vec<Symbol> = floor.wire().collect();
        assert_eq!(wire.iter().filter(|s| **s == Symbol::Start).count(), 12);
        assert_eq!(wire.iter().filter(|s| **s == Symbol::Stop).count(), 12);
        assert_eq!(
            wire.iter().filter(|s| **s == Symbol::RepeatedStart).count(),
            8
        );
        // Select: S, addr, byte, P; each result read: S, addr, reg, Sr, addr, 2 bytes, P.
        assert_eq!(
            &wire[..4],
            [
                Symbol::Start,
                Symbol::Address {
                    address: 0x77,
                    read: false
                },
                Symbol::Written(4),
                Symbol::Stop
            ]
        );
        // Bytes: 4 × (2 + 2 × 5) = 48 → 432 periods, plus 12 + 12 + 8 conditions.
        assert_eq!(floor.scl_periods(), 464);
    }

    #[test]
    fn the_periods_counted_per_operation_are_the_wires() {
        let walk = |s: &Script| s.wire().map(Symbol::scl_periods).sum::<u32>();
        let floor = floor_round();
        assert_eq!(floor.scl_periods(), walk(&floor));
        let mut shapes = Script::new();
        shapes
            .write(0x10, &[1])
            .unwrap()
            .read(0x11, 1)
            .unwrap()
            .write_read(0x12, &[2, 3], 4)
            .unwrap()
            .write(0x13, &[4, 5, 6])
            .unwrap()
            .read(0x14, 24 - 1 - 4)
            .unwrap();
        assert_eq!(shapes.scl_periods(), walk(&shapes));
        assert_eq!(Script::new().scl_periods(), 0);
    }

    #[test]
    fn readings_split_by_operation() {
        let mut script = Script::new();
        script
            .write(0x77, &[4])
            .unwrap()
            .write_read(0x13, &[0x87], 2)
            .unwrap()
            .read(0x13, 3)
            .unwrap();
        let mut readings = Readings::for_script(&script);
        for byte in 1..=5 {
            readings.push(byte);
        }
        assert_eq!(readings.of(0), &[] as &[u8]);
        assert_eq!(readings.of(1), [1, 2]);
        assert_eq!(readings.of(2), [3, 4, 5]);
        assert_eq!(readings.of(3), &[] as &[u8]);
        assert_eq!(readings.all(), [1, 2, 3, 4, 5]);
    }
}
