//! The sensor groups' bus work as [`Script`]s, decoded by the same driver code that the blocking
//! path runs (docs/i2c.md, "The sensor groups' scripts").
//!
//! A publisher that samples through the interrupt-driven bus engine cannot call a driver that
//! polls the bus; but the drivers hold everything a sample is made of — the register maps, the
//! byte layouts, the identity and read-back checks, the groups' fault policy ([`Supervised`]) —
//! and a second copy of each for the split path would drift from the first. So the split path
//! runs the *same* code on a [`ReplayBus`]: an embedded-hal `I2c` that records the transfers the
//! code makes into a script instead of making them, and, once the script has run, serves the
//! code the readings. [`step`] does a round, for a job whose log ([`Job`]) the caller keeps
//! ([`begin_sample`] / [`finish_sample`] for a publisher's sample; [`Replayed`] for the host):
//!
//! 1. **Record.** The work (a group's `sample`, a set-up step, a gauge transfer) runs on a copy
//!    of the state. Transfers the log does not hold yet are appended to the script and answered
//!    with a stand-in: the datasheet's identity or the mode the part is put in
//!    ([`Expected`]), or the value the work wrote to that register earlier in the log (a
//!    read-back), or `0x5A` bytes (not a dead bus's pattern). The copy and its result are
//!    dropped: [`Next::Run`] hands the script to the bus.
//! 2. **Replay.** With the script's result in the log ([`Job::complete`]) the work runs
//!    again on a fresh copy, and the bus answers every logged transfer with what the devices
//!    answered (or with the bus error of the transfer that failed). If the work needs nothing
//!    more, the copy becomes the state and the work's result is the sample: [`Next::Done`].
//!    If it needs more (a dead-bus pattern that calls for an identity check, a check that
//!    passed and lets a set-up go on, a transfer after a failed one), those are recorded in
//!    the next script.
//!
//! Rules that keep the replay equal to the blocking path:
//! - A recording ends before a write that changes a device (not a mux select) once it holds a
//!   read: a write goes to the bus only when every check before it ran on the devices' real
//!   answers (an identity that does not match stops a set-up before it writes, as blocking).
//!   Reads and mux selects may be recorded on a stand-in's guess; a guess that was wrong costs
//!   the reads made after it and a further round, never a write the blocking path would not
//!   make.
//! - A script that goes on behind a PCA9544A starts with the channel select the work made last
//!   (sent again, not served to the work), and never ends with a select: a select and the reads
//!   behind it are in one script, with no other client's operation between.
//! - A script that fails returns no readings (the engine's `Result<Readings, ScriptError>`):
//!   the operations before the failed one are replayed with their stand-ins, the failed one with
//!   its error (mapped to embedded-hal's [`ErrorKind`], as a blocking bus reports it), and the
//!   ones after it were never made.
//!
//! - A part that needs time after a transfer (the BNO055's mode switch, the bq27500's bus-free
//!   time) ends its script there, and the job asks for the wait before its next script
//!   ([`Job::settle_us`]).
//!
//! A job's rounds are bounded: every round but the last adds at least one transfer, made on the
//! bus, to the log's confirmed part, so a work of `n` transfers ends within `n + 1` rounds
//! ([`MAX_ROUNDS`]) — when no other job on the same group ends in between (one that does can
//! send the work another way; a job out of rounds ends [`Unfinished`]). A work must change
//! nothing but its state (no log line, no report): a round may run it more than once.

use amiro_can::Topic;
use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{self, ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};

use super::bno055::{self, Bno055};
use super::bq27500;
use super::floor::FloorSensors;
use super::hmc5883l::{self, Hmc5883l};
use super::pca9544a::{self, Pca9544a};
use super::suite::{Compass, ImuSensors, Samples, SensorGroup, Supervised};
use super::vcnl4020;
use crate::script::{
    Failure, Readings, Script, ScriptError, MAX_OPERATIONS, MAX_READ_BYTES, MAX_WRITE_BYTES,
};

/// What a script came back with.
pub type ScriptResult = Result<Readings, ScriptError>;

/// A bus that runs a script to its end at once: the simulated buses
/// ([`crate::sim::SimBus::answer`]), or a client that awaits the engine.
pub trait ScriptBus {
    /// Runs `script`: its readings, or the failed operation's error.
    fn run(&mut self, script: &Script) -> ScriptResult;
}

/// A script run operation by operation on a blocking embedded-hal bus (the polled master at
/// boot, before the engine takes the block): each operation one `write`, `read` or `write_read`,
/// the first that fails ending the script with its failure ([`kind_failure`]).
#[derive(Debug)]
pub struct OnI2c<I>(pub I);

impl<I: I2c> ScriptBus for OnI2c<I> {
    fn run(&mut self, script: &Script) -> ScriptResult {
        let mut readings = Readings::for_script(script);
        let mut written = script.written();
        for (index, op) in script.operations().iter().enumerate() {
            let (bytes, rest) = written.split_at(usize::from(op.write).min(written.len()));
            written = rest;
            let mut read = [0u8; MAX_READ_BYTES];
            let read = read.get_mut(..usize::from(op.read)).unwrap_or(&mut []);
            let result = match (bytes.is_empty(), read.is_empty()) {
                (false, true) => self.0.write(op.address, bytes),
                (true, false) => self.0.read(op.address, read),
                _ => self.0.write_read(op.address, bytes, read),
            };
            if let Err(error) = result {
                return Err(ScriptError {
                    operation: index as u8,
                    failure: kind_failure(i2c::Error::kind(&error)),
                });
            }
            for &byte in read.iter() {
                readings.push(byte);
            }
        }
        Ok(readings)
    }
}

/// The engine failure a blocking bus's error kind stands for ([`failure_kind`]'s inverse; a kind
/// the engine has no failure for, a polled master's timeout among them, is
/// [`Failure::UnexpectedEvent`]).
pub const fn kind_failure(kind: ErrorKind) -> Failure {
    match kind {
        ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data) => Failure::NackData,
        ErrorKind::NoAcknowledge(_) => Failure::NackAddress,
        ErrorKind::Bus => Failure::Bus,
        ErrorKind::ArbitrationLoss => Failure::ArbitrationLoss,
        ErrorKind::Overrun => Failure::Overrun,
        _ => Failure::UnexpectedEvent,
    }
}

/// Most bytes one transfer of an AMiRo driver writes: the BNO055's configuration burst (the
/// register and four values).
pub const MAX_TRANSFER_WRITE: usize = 5;
/// Transfers a job's log holds: the floor group's boot set-up, four VCNL4020s each with its
/// select and PRODUCT_ID, then five registers written and read back behind a select sent again
/// (4 × 17 = 68).
pub const MAX_LOGGED: usize = 72;
/// Bytes the logged transfers read.
pub const MAX_LOGGED_READ: usize = 48;
/// Rounds of one job at most ([`Replayed::run`]): every round but the last confirms a transfer.
pub const MAX_ROUNDS: usize = MAX_LOGGED + 1;
/// The stand-in byte for a read nothing predicts: neither `0x00` nor `0xFF`, so a stand-in never
/// looks like a dead bus's pattern and calls for no identity check of its own.
pub const STAND_IN: u8 = 0x5A;

/// What a register read is expected to return, the stand-in while its script has not run: an
/// identity register, or a mode the driver put the part in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expected {
    /// The device's address.
    pub address: u8,
    /// The register the read starts at (the transfer's one written byte).
    pub register: u8,
    /// The bytes from there on.
    pub bytes: &'static [u8],
}

/// A write after which the part needs time before the next transfer (the BNO055's operating
/// mode switch): the recording ends with it, and the next script waits `us` first
/// ([`Job::settle_us`]). A paced device's transfer (the bq27500) asks for its bus-free time the
/// same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settle {
    /// The device's address.
    pub address: u8,
    /// The register written.
    pub register: u8,
    /// The value written.
    pub value: u8,
    /// The wait before the part takes the next transfer, µs.
    pub us: u32,
}

/// Why a replayed transfer did not complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayError {
    /// The transfer ran on the bus and failed.
    Bus(Failure),
    /// The transfer is recorded for the next script; the work's result is not used.
    Deferred,
    /// A transfer no script can carry (a write then a write after a read, more than
    /// [`MAX_TRANSFER_WRITE`] bytes, or nothing at all), or a job larger than the log: a
    /// driver's shape that a host test of it finds.
    Unsupported,
}

impl i2c::Error for ReplayError {
    fn kind(&self) -> ErrorKind {
        match self {
            ReplayError::Bus(failure) => failure_kind(*failure),
            ReplayError::Deferred | ReplayError::Unsupported => ErrorKind::Other,
        }
    }
}

/// The embedded-hal error kind of an engine failure, as a blocking bus reports the same event.
pub const fn failure_kind(failure: Failure) -> ErrorKind {
    match failure {
        Failure::NackAddress => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
        Failure::NackData => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data),
        Failure::Bus => ErrorKind::Bus,
        Failure::ArbitrationLoss => ErrorKind::ArbitrationLoss,
        Failure::Overrun => ErrorKind::Overrun,
        Failure::UnexpectedEvent | Failure::Busy => ErrorKind::Other,
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    /// In the script handed to the bus, not back yet.
    Pending,
    /// Back with its readings.
    Read,
    /// Made on the bus before a failed operation of its script: its readings are lost, the
    /// replay serves its stand-in.
    Unknown,
    /// The failed operation.
    Failed(Failure),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Entry {
    address: u8,
    written: [u8; MAX_TRANSFER_WRITE],
    write: u8,
    read: u8,
    /// Where its readings are in the log's bytes.
    read_at: u8,
    outcome: Outcome,
    /// A mux select sent again at a script's start: on the bus, not one of the work's transfers.
    inserted: bool,
}

impl Entry {
    fn written(&self) -> &[u8] {
        self.written.get(..usize::from(self.write)).unwrap_or(&[])
    }

    fn is_select(&self, mux: Option<u8>) -> bool {
        Some(self.address) == mux && self.write == 1 && self.read == 0
    }
}

const EMPTY_ENTRY: Entry = Entry {
    address: 0,
    written: [0; MAX_TRANSFER_WRITE],
    write: 0,
    read: 0,
    read_at: 0,
    outcome: Outcome::Pending,
    inserted: false,
};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Recording {
    /// Every transfer so far was in the log.
    Off,
    /// Recording from the entry at `start`; `has_read` once a recorded transfer reads.
    On { start: u8, has_read: bool },
    /// The script is full (or a device-changing write waits for real data): every further
    /// transfer of this round is deferred.
    Closed { start: u8 },
}

/// The log of one job (a sample, a set-up step, a gauge transfer) while its scripts run: the
/// transfers recorded so far and what the bus answered. It belongs to the job, not to the
/// group, so two publishers whose jobs on one group overlap each keep their own; the group's
/// state changes only when a job ends ([`step`]).
#[derive(Debug, Clone)]
pub struct Job {
    entries: [Entry; MAX_LOGGED],
    len: u8,
    bytes: [u8; MAX_LOGGED_READ],
    bytes_len: u8,
    /// The settling time of the last script recorded ([`Settle`]).
    recorded_settle_us: u32,
    /// The wait the last completed script asks for before the next.
    settle_us: u32,
}

impl Default for Job {
    fn default() -> Self {
        Self::new()
    }
}

impl Job {
    /// A job not begun.
    pub const fn new() -> Self {
        Self {
            entries: [EMPTY_ENTRY; MAX_LOGGED],
            len: 0,
            bytes: [0; MAX_LOGGED_READ],
            bytes_len: 0,
            recorded_settle_us: 0,
            settle_us: 0,
        }
    }

    /// Transfers in the log.
    pub const fn logged(&self) -> usize {
        self.len as usize
    }

    /// How long to wait before the script [`step`] asked for: a part's settling time after the
    /// previous script's last write ([`Settle`]), 0 mostly.
    pub const fn settle_us(&self) -> u32 {
        self.settle_us
    }

    fn entries(&self) -> &[Entry] {
        self.entries.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Stores the result of the script [`step`] asked for in its entries (the pending ones).
    pub fn complete(&mut self, result: &ScriptResult) {
        let first = self
            .entries()
            .iter()
            .position(|e| e.outcome == Outcome::Pending)
            .unwrap_or(usize::from(self.len));
        let mut keep = usize::from(self.len);
        self.settle_us = if result.is_ok() {
            self.recorded_settle_us
        } else {
            0
        };
        self.recorded_settle_us = 0;
        for (k, entry) in self.entries.iter_mut().enumerate().take(keep).skip(first) {
            let op = k - first;
            match result {
                Ok(readings) => {
                    let start = usize::from(entry.read_at);
                    let end = start + usize::from(entry.read);
                    if let Some(slot) = self.bytes.get_mut(start..end) {
                        let got = readings.of(op);
                        if got.len() == slot.len() {
                            slot.copy_from_slice(got);
                        }
                    }
                    entry.outcome = Outcome::Read;
                }
                Err(error) if op < usize::from(error.operation) => entry.outcome = Outcome::Unknown,
                Err(error) if op == usize::from(error.operation) => {
                    entry.outcome = Outcome::Failed(error.failure)
                }
                Err(_) => {
                    keep = keep.min(k);
                }
            }
        }
        self.truncate(keep);
    }

    /// The script [`step`] asked for did not end within its client's timeout (the block was
    /// reset): its first operation fails, with the kind a polled master's timeout has
    /// ([`ErrorKind::Other`]).
    pub fn timed_out(&mut self) {
        self.complete(&Err(ScriptError {
            operation: 0,
            failure: Failure::UnexpectedEvent,
        }));
    }

    fn truncate(&mut self, len: usize) {
        if len < usize::from(self.len) {
            if let Some(entry) = self.entries.get(len) {
                self.bytes_len = entry.read_at;
            }
            self.len = len as u8;
        }
    }
}

/// An embedded-hal `I2c` whose transfers are recorded into scripts and served from their
/// results ([`Replayed`]). One per bus; it carries the log of the job under way.
#[derive(Debug, Clone)]
pub struct ReplayBus {
    /// The PCA9544A on this bus, if there is one (its selects are sent again at a script's
    /// start).
    mux: Option<u8>,
    /// A device beside the mux that needs bus-free time between packets (the bq27500): each of
    /// its transfers is a script of its own.
    paced: Option<u8>,
    expected: &'static [Expected],
    settles: &'static [Settle],
    /// The job's log while a round runs (empty between rounds).
    log: Job,
    // The round under way.
    cursor: u8,
    recording: Recording,
    /// The control byte of the work's last mux select in this round.
    selected: Option<u8>,
    unsupported: bool,
}

impl ReplayBus {
    /// A bus with `mux` (a PCA9544A's address) or none, and the reads whose answers the
    /// datasheets fix.
    pub const fn new(mux: Option<u8>, expected: &'static [Expected]) -> Self {
        Self {
            mux,
            paced: None,
            expected,
            settles: &[],
            log: Job::new(),
            cursor: 0,
            recording: Recording::Off,
            selected: None,
            unsupported: false,
        }
    }

    /// DiWheelDrive 1-1's I2C1: the HMC5883L.
    pub const fn compass() -> Self {
        Self::new(None, &COMPASS_EXPECTED)
    }

    /// DiWheelDrive 1-2's I2C1: the BNO055.
    pub const fn imu() -> Self {
        let mut bus = Self::new(None, &IMU_EXPECTED);
        bus.settles = &IMU_SETTLES;
        bus
    }

    /// A bus of VCNL4020s behind a PCA9544A at 0x77 (DiWheelDrive's floor on I2C2, either of
    /// PowerManagement's buses), with PowerManagement's bq27500 beside them.
    pub const fn muxed() -> Self {
        let mut bus = Self::new(Some(pca9544a::AMIRO_ADDRESS), &MUXED_EXPECTED);
        bus.paced = Some(bq27500::ADDRESS);
        bus
    }

    fn begin_round(&mut self) {
        self.cursor = 0;
        self.recording = Recording::Off;
        self.selected = None;
        self.unsupported = false;
    }

    /// The script this round recorded, if it recorded one.
    fn recorded(&self) -> Option<Script> {
        let start = match self.recording {
            Recording::Off => return None,
            Recording::On { start, .. } | Recording::Closed { start } => usize::from(start),
        };
        let entries = self.log.entries().get(start..)?;
        if entries.is_empty() {
            return None;
        }
        let mut script = Script::new();
        for entry in entries {
            // The recording kept within the script's capacities, so every push succeeds.
            let _ = match (entry.write, entry.read) {
                (0, n) => script.read(entry.address, usize::from(n)),
                (_, 0) => script.write(entry.address, entry.written()),
                (_, n) => script.write_read(entry.address, entry.written(), usize::from(n)),
            };
        }
        Some(script)
    }

    /// The stand-in for a read of `read.len()` bytes after writing `write` to `address`.
    fn stand_in(&self, upto: usize, address: u8, write: &[u8], read: &mut [u8]) {
        read.fill(STAND_IN);
        let [register] = write else {
            return;
        };
        if let Some(expected) = self
            .expected
            .iter()
            .find(|e| e.address == address && e.register == *register)
        {
            for (out, &byte) in read.iter_mut().zip(expected.bytes) {
                *out = byte;
            }
            return;
        }
        // A read-back: the last value the work wrote to each register of the read.
        let earlier = self.log.entries().get(..upto).unwrap_or(&[]);
        for (offset, out) in read.iter_mut().enumerate() {
            let wanted = register.wrapping_add(offset as u8);
            let last = earlier.iter().rev().find_map(|e| {
                let [first, values @ ..] = e.written() else {
                    return None;
                };
                if e.address != address || e.read != 0 || e.inserted {
                    return None;
                }
                let at = wanted.wrapping_sub(*first);
                values.get(usize::from(at)).copied()
            });
            if let Some(value) = last {
                *out = value;
            }
        }
    }

    /// One transfer of the work: served from the log, or recorded.
    fn transfer(&mut self, address: u8, write: &[u8], read: &mut [u8]) -> Result<(), ReplayError> {
        if let Recording::Closed { .. } = self.recording {
            return Err(ReplayError::Deferred);
        }
        let select = Some(address) == self.mux && write.len() == 1 && read.is_empty();
        if self.recording == Recording::Off {
            // Skip the selects sent again at a script's start: the work did not make them. One that
            // failed failed the script there (the engine ran nothing after it): that failure is the
            // work's next transfer's, so the group counts it as the blocking path would.
            while let Some(entry) = self
                .log
                .entries()
                .get(usize::from(self.cursor))
                .filter(|e| e.inserted)
            {
                let outcome = entry.outcome;
                self.cursor += 1;
                if let Outcome::Failed(failure) = outcome {
                    return Err(ReplayError::Bus(failure));
                }
            }
            let at = usize::from(self.cursor);
            if let Some(&entry) = self.log.entries().get(at) {
                if entry.address == address
                    && entry.written() == write
                    && usize::from(entry.read) == read.len()
                {
                    self.cursor += 1;
                    if select {
                        self.selected = write.first().copied();
                    }
                    return match entry.outcome {
                        Outcome::Read => {
                            let start = usize::from(entry.read_at);
                            match self.log.bytes.get(start..start + read.len()) {
                                Some(bytes) => read.copy_from_slice(bytes),
                                None => read.fill(STAND_IN),
                            }
                            Ok(())
                        }
                        Outcome::Failed(failure) => Err(ReplayError::Bus(failure)),
                        // Pending: not reached, `step` refuses a job with a script out.
                        Outcome::Unknown | Outcome::Pending => {
                            self.stand_in(at, address, write, read);
                            Ok(())
                        }
                    };
                }
                // The work went another way than the stand-ins guessed: the rest of the log
                // was made on a guess (reads and selects only) and is dropped.
                self.log.truncate(at);
            }
            self.recording = Recording::On {
                start: self.log.len,
                has_read: false,
            };
            if !select && Some(address) != self.paced {
                if let Some(control) = self.selected {
                    self.push_inserted_select(control)?;
                }
            }
        }
        let Recording::On { start, has_read } = self.recording else {
            return Err(ReplayError::Deferred);
        };
        if read.is_empty() && !select && has_read {
            return self.close(start);
        }
        if write.is_empty() && read.is_empty() {
            return Err(self.unsupported());
        }
        let paced = Some(address) == self.paced;
        let recorded = usize::from(self.log.len) - usize::from(start);
        if !self.fits(start, write.len(), read.len()) || (paced && recorded > 0) {
            return self.close(start);
        }
        let at = usize::from(self.log.len);
        self.push(address, write, read.len(), false);
        self.stand_in(at, address, write, read);
        if select {
            self.selected = write.first().copied();
        }
        let settle = self
            .settles
            .iter()
            .find(|s| s.address == address && write == [s.register, s.value]);
        if let Some(settle) = settle {
            self.log.recorded_settle_us = settle.us;
        } else if paced {
            self.log.recorded_settle_us = bq27500::BUS_FREE_NS.div_ceil(1_000);
        }
        self.recording = if paced || settle.is_some() {
            Recording::Closed { start }
        } else {
            Recording::On {
                start,
                has_read: has_read || !read.is_empty(),
            }
        };
        Ok(())
    }

    /// Ends the recording: a select at its end goes to the next script, with its reads.
    fn close(&mut self, start: u8) -> Result<(), ReplayError> {
        let len = usize::from(self.log.len);
        if len > usize::from(start) + 1 {
            if let Some(last) = self.log.entries().get(len - 1) {
                if last.is_select(self.mux) && !last.inserted {
                    self.log.truncate(len - 1);
                }
            }
        }
        let recorded = self.log.entries().get(usize::from(start)..).unwrap_or(&[]);
        if recorded.iter().all(|e| e.inserted) {
            // Nothing fits: a transfer larger than a script, or a job larger than the log.
            self.unsupported = true;
            return Err(ReplayError::Unsupported);
        }
        self.recording = Recording::Closed { start };
        Err(ReplayError::Deferred)
    }

    /// A transfer this bus cannot log (larger than a script or the log): the job ends `Unfinished`
    /// (`step` reads the mark), never a bus fault of the group's.
    fn unsupported(&mut self) -> ReplayError {
        self.unsupported = true;
        ReplayError::Unsupported
    }

    fn push_inserted_select(&mut self, control: u8) -> Result<(), ReplayError> {
        let Some(mux) = self.mux else {
            return Ok(());
        };
        if usize::from(self.log.len) >= MAX_LOGGED {
            self.unsupported = true;
            return Err(ReplayError::Unsupported);
        }
        self.push(mux, &[control], 0, true);
        Ok(())
    }

    /// Whether one more transfer fits the script recorded from `start` and the log.
    fn fits(&self, start: u8, write: usize, read: usize) -> bool {
        let recorded = self.log.entries().get(usize::from(start)..).unwrap_or(&[]);
        let written: usize = recorded.iter().map(|e| usize::from(e.write)).sum();
        let reads: usize = recorded.iter().map(|e| usize::from(e.read)).sum();
        recorded.len() < MAX_OPERATIONS
            && written + write <= MAX_WRITE_BYTES
            && reads + read <= MAX_READ_BYTES
            && usize::from(self.log.len) < MAX_LOGGED
            && usize::from(self.log.bytes_len) + read <= MAX_LOGGED_READ
    }

    fn push(&mut self, address: u8, write: &[u8], read: usize, inserted: bool) {
        let mut written = [0; MAX_TRANSFER_WRITE];
        for (slot, &byte) in written.iter_mut().zip(write) {
            *slot = byte;
        }
        if let Some(entry) = self.log.entries.get_mut(usize::from(self.log.len)) {
            // Both within their capacities (checked by `fits`), so the narrowing is exact.
            *entry = Entry {
                address,
                written,
                write: write.len() as u8,
                read: read as u8,
                read_at: self.log.bytes_len,
                outcome: Outcome::Pending,
                inserted,
            };
            self.log.len += 1;
            self.log.bytes_len += read as u8;
        }
    }
}

impl ErrorType for ReplayBus {
    type Error = ReplayError;
}

impl I2c for ReplayBus {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        // A transaction is a script's operation: writes, then reads after a repeated START.
        let mut write = [0u8; MAX_TRANSFER_WRITE];
        let mut write_len = 0;
        let mut read = [0u8; MAX_READ_BYTES];
        let mut read_len = 0;
        for operation in operations.iter() {
            match operation {
                Operation::Write(bytes) if read_len == 0 => {
                    let slot = write
                        .get_mut(write_len..write_len + bytes.len())
                        .ok_or_else(|| self.unsupported())?;
                    slot.copy_from_slice(bytes);
                    write_len += bytes.len();
                }
                Operation::Write(_) => return Err(self.unsupported()),
                Operation::Read(buffer) => {
                    read_len += buffer.len();
                    if read_len > MAX_READ_BYTES {
                        return Err(self.unsupported());
                    }
                }
            }
        }
        let (Some(write), Some(read)) = (write.get(..write_len), read.get_mut(..read_len)) else {
            return Err(self.unsupported());
        };
        self.transfer(address, write, read)?;
        let mut from = 0;
        for operation in operations.iter_mut() {
            if let Operation::Read(buffer) = operation {
                let end = from + buffer.len();
                if let Some(bytes) = read.get(from..end) {
                    buffer.copy_from_slice(bytes);
                }
                from = end;
            }
        }
        Ok(())
    }
}

/// What a group's replay needs: its bus.
pub trait Replaying {
    /// The group's [`ReplayBus`].
    fn replay_bus(&mut self) -> &mut ReplayBus;
}

impl Replaying for ReplayBus {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self
    }
}

impl Replaying for Hmc5883l<ReplayBus> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.bus_mut()
    }
}

impl Replaying for Compass<ReplayBus> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.magnetometer.bus_mut()
    }
}

impl<D> Replaying for ImuSensors<ReplayBus, D> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.imu.bus_mut()
    }
}

impl Replaying for Bno055<ReplayBus> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.bus_mut()
    }
}

impl Replaying for Pca9544a<ReplayBus> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.bus_mut()
    }
}

impl Replaying for FloorSensors<ReplayBus> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.mux_mut().bus_mut()
    }
}

impl<G: Replaying + SensorGroup> Replaying for Supervised<G> {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.group_mut().replay_bus()
    }
}

/// What a round of [`Replayed::step`] asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next<T> {
    /// Run this script on the bus and hand its result to [`Replayed::complete`].
    Run(Script),
    /// The work ended on the devices' answers: its result.
    Done(T),
}

/// A job's rounds did not end within [`MAX_ROUNDS`], or a transfer could not be carried by a
/// script: a driver's shape that a host test finds (the state is left as before the job).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unfinished;

/// One round of `work` on `state` for `job` ([module documentation](self)): the script the work
/// needs next, or its result. The work runs on a copy of `state`; only a round that needs no
/// further script (the work's result is the devices' answers) puts its copy in `state`, and
/// `job` begins again empty. `state`'s bus log is empty between rounds. A step while the last
/// script's result is not in `job` ([`Job::complete`]) is refused, the job dropped: its work
/// would otherwise end on stand-ins.
pub fn step<S: Clone + Replaying, T>(
    state: &mut S,
    job: &mut Job,
    work: impl FnOnce(&mut S) -> T,
) -> Result<Next<T>, Unfinished> {
    if job.entries().iter().any(|e| e.outcome == Outcome::Pending) {
        *job = Job::new();
        return Err(Unfinished);
    }
    let mut round = state.clone();
    let bus = round.replay_bus();
    bus.log = job.clone();
    bus.begin_round();
    let value = work(&mut round);
    let bus = round.replay_bus();
    if bus.unsupported {
        *job = Job::new();
        return Err(Unfinished);
    }
    if let Some(script) = bus.recorded() {
        *job = bus.log.clone();
        return Ok(Next::Run(script));
    }
    bus.log = Job::new();
    bus.begin_round();
    *state = round;
    *job = Job::new();
    Ok(Next::Done(value))
}

/// A publisher's sample of `topic` taken at `now_us` on a supervised group, begun: the first
/// script it needs, or its frames at once (a reading reused, a group in its back-off). The
/// caller keeps `job` until the sample is done.
pub fn begin_sample<G: SensorGroup + Clone + Replaying>(
    group: &mut Supervised<G>,
    job: &mut Job,
    topic: Topic,
    now_us: u64,
) -> Next<Samples> {
    *job = Job::new();
    resume(group, job, topic, now_us)
}

/// The same sample, its last script's `result` in: the next script, or the frames. A sample
/// whose rounds run out ([`Unfinished`]) has no frames.
pub fn finish_sample<G: SensorGroup + Clone + Replaying>(
    group: &mut Supervised<G>,
    job: &mut Job,
    topic: Topic,
    now_us: u64,
    result: &ScriptResult,
) -> Next<Samples> {
    job.complete(result);
    resume(group, job, topic, now_us)
}

fn resume<G: SensorGroup + Clone + Replaying>(
    group: &mut Supervised<G>,
    job: &mut Job,
    topic: Topic,
    now_us: u64,
) -> Next<Samples> {
    step(group, job, |g| g.sample(topic, now_us)).unwrap_or(Next::Done(Samples::new()))
}

/// A state (a supervised group, a bus with a gauge's read) and one job on it at a time: the
/// simulators' and the host tests' way to run [`step`].
#[derive(Debug, Clone)]
pub struct Replayed<S> {
    state: S,
    job: Job,
}

impl<S: Clone + Replaying> Replayed<S> {
    /// The state, its bus's log emptied. Its constructor must have made no transfer (a
    /// [`Supervised`] group's boot set-up is a job: [`Replayed::boot`]).
    pub fn new(mut state: S) -> Self {
        let bus = state.replay_bus();
        bus.log = Job::new();
        bus.begin_round();
        Self {
            state,
            job: Job::new(),
        }
    }

    /// The state between jobs.
    pub fn state(&self) -> &S {
        &self.state
    }

    /// The state between jobs, e.g. to feed a sensor's calibration.
    pub fn state_mut(&mut self) -> &mut S {
        &mut self.state
    }

    /// One round of `work` ([`step`]).
    pub fn step<T>(&mut self, work: impl FnOnce(&mut S) -> T) -> Result<Next<T>, Unfinished> {
        step(&mut self.state, &mut self.job, work)
    }

    /// How long to wait before running the script the last [`step`](Self::step) asked for
    /// ([`Job::settle_us`]). The simulators need no wait ([`Replayed::run`] makes none).
    pub fn settle_us(&self) -> u32 {
        self.job.settle_us()
    }

    /// The result of the script the last [`step`](Self::step) asked for.
    pub fn complete(&mut self, result: &ScriptResult) {
        self.job.complete(result);
    }

    /// A whole job on a bus that runs scripts at once (the simulators, the host tests):
    /// rounds until the work is done.
    pub fn run<T>(
        &mut self,
        bus: &mut impl ScriptBus,
        work: impl FnMut(&mut S) -> T,
    ) -> Result<T, Unfinished> {
        self.run_paced(bus, &mut crate::sim::NoDelay, work)
    }

    /// [`run`](Self::run) on real devices: waits each script's [`settle_us`](Self::settle_us)
    /// on `delay` before it (the boot on the polled master, [`OnI2c`]).
    pub fn run_paced<T>(
        &mut self,
        bus: &mut impl ScriptBus,
        delay: &mut impl DelayNs,
        mut work: impl FnMut(&mut S) -> T,
    ) -> Result<T, Unfinished> {
        for _ in 0..MAX_ROUNDS {
            match self.step(&mut work)? {
                Next::Run(script) => {
                    delay.delay_us(self.settle_us());
                    let result = bus.run(&script);
                    self.complete(&result);
                }
                Next::Done(value) => return Ok(value),
            }
        }
        self.job = Job::new();
        Err(Unfinished)
    }
}

impl<G: Clone + Replaying + SensorGroup> Replayed<Supervised<G>> {
    /// A supervised group whose boot set-up ([`Supervised::new`]) ran as scripts on `bus`, with no
    /// waits between them (the simulators).
    pub fn boot(group: G, bus: &mut impl ScriptBus) -> Result<Self, Unfinished> {
        Self::boot_paced(group, bus, &mut crate::sim::NoDelay)
    }

    /// [`boot`](Self::boot) on real devices, each script's settling time waited on `delay`.
    pub fn boot_paced(
        group: G,
        bus: &mut impl ScriptBus,
        delay: &mut impl DelayNs,
    ) -> Result<Self, Unfinished> {
        let mut boot = Replayed::new(group);
        let supervised = boot.run_paced(bus, delay, |group| {
            // The set-up's transfers are made on the new value's bus: the round's bus takes
            // them over, so the round sees what was recorded.
            let mut supervised = Supervised::new(group.clone());
            *group.replay_bus() = supervised.replay_bus().clone();
            supervised
        })?;
        Ok(Replayed::new(supervised))
    }
}

/// The BNO055's operating mode switches (datasheet table "operating mode switching time").
static IMU_SETTLES: [Settle; 2] = [
    Settle {
        address: bno055::ADDRESS,
        register: bno055::reg::OPR_MODE,
        value: bno055::mode::CONFIG,
        us: bno055::OPERATING_TO_CONFIG_MS * 1_000,
    },
    Settle {
        address: bno055::ADDRESS,
        register: bno055::reg::OPR_MODE,
        value: bno055::mode::AMG,
        us: bno055::CONFIG_TO_OPERATING_MS * 1_000,
    },
];

/// The HMC5883L's identification registers.
static COMPASS_EXPECTED: [Expected; 1] = [Expected {
    address: hmc5883l::ADDRESS,
    register: hmc5883l::reg::IDENTIFICATION_A,
    bytes: &hmc5883l::IDENTITY,
}];

/// The BNO055's identities, its self-test passed, and the AMG mode the driver runs it in.
static IMU_EXPECTED: [Expected; 3] = [
    Expected {
        address: bno055::ADDRESS,
        register: bno055::reg::CHIP_ID,
        bytes: &bno055::IDENTITY,
    },
    Expected {
        address: bno055::ADDRESS,
        register: bno055::reg::ST_RESULT,
        bytes: &[bno055::SELF_TEST_PASSED],
    },
    Expected {
        address: bno055::ADDRESS,
        register: bno055::reg::OPR_MODE,
        bytes: &[bno055::mode::AMG],
    },
];

/// The VCNL4020's product ID and the bq27500's answer to Control(DEVICE_TYPE).
static MUXED_EXPECTED: [Expected; 2] = [
    Expected {
        address: vcnl4020::ADDRESS,
        register: vcnl4020::reg::PRODUCT_ID,
        bytes: &[vcnl4020::PRODUCT_ID_VALUE],
    },
    Expected {
        address: bq27500::ADDRESS,
        register: bq27500::cmd::CONTROL,
        bytes: &DEVICE_TYPE_LE,
    },
];

const DEVICE_TYPE_LE: [u8; 2] = bq27500::DEVICE_TYPE_VALUE.to_le_bytes();
