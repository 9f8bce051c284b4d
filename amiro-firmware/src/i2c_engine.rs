//! The interrupt-driven I2C master: a hardware-free state machine that runs one [`Script`] on
//! the STM32 I2C v1 block (the F103's, RM0008 §26; the F405's is the same IP, RM0090 §27), one
//! interrupt at a time (docs/i2c.md).
//!
//! At each event interrupt (I2Cx_EV) the caller reads SR1 and hands it to [`Engine::on_event`];
//! at each error interrupt (I2Cx_ER) to [`Engine::on_error`]. The engine answers with register
//! actions on a [`Block`] (SR2 read, DR read and write, CR1's START, STOP, ACK and POS, CR2's
//! interrupt enables, an error flag cleared, the block reset), in the order the reference manual
//! gives them. The chip's [`Block`] is a thin adapter of volatile accesses (`i2c_block`); the host
//! tests' is a register-level model of the block and the devices on its bus.
//!
//! Sources (the step each action follows is named beside it in the code):
//! - RM0008 rev 21, §26.3.3 "I2C master mode": the start condition and EV5, the slave address
//!   and EV6, the master transmitter (EV8_1, EV8, EV8_2) and the master receiver (EV7, EV7_1);
//!   "Closing the communication" and its method 2 (for interrupts that are not the highest
//!   priority in the application): the endings for N = 1, N = 2 (POS) and N > 2 bytes ("When 3
//!   bytes remain to be read").
//! - RM0008 §26.3.4 "Error conditions" (BERR, ARLO, AF, OVR) and §26.6.1, the note to CR1's
//!   START and STOP bits: no write to CR1 while a STOP (or START) the software set is pending.
//! - ST AN2824, "STM32F10xxx I2C optimized examples", the interrupt-driven master receiver: the
//!   one-byte and N > 2 endings run with interrupts masked; and the STM32F10x errata sheets'
//!   I2C entry "Some software events must be managed before the current byte is being
//!   transferred", which is why.
//!
//! **What must not be interrupted, and how it is not.** Two sequences race the bus: the one-byte
//! read's "clear ADDR, then program STOP" (the byte is on the wire from the moment ADDR is
//! cleared, so a STOP set after its acknowledge bit comes too late and the block clocks another
//! byte), and the N > 2 read's "read DataN-2, program STOP, read DataN-1" (reading DataN-2 starts
//! DataN's reception, whose end the STOP must precede). The events before them stretch SCL (EV6
//! and BTF hold the clock low until software answers), so their start may be late; their middle
//! may not. The bus (`i2c_bus`) runs every call into the engine inside its critical section
//! (interrupts masked on the single-core chip), so no interrupt of any priority and no client
//! comes between two actions of one event. The section's length is an event's actions (at most
//! five; nine register accesses with the SR1 read) and the bus's one walk of its slots.
//!
//! Each operation is a transaction of its own (it ends with a STOP; a write then a read has a
//! repeated START between them). A START is set only once the previous STOP has cleared (the
//! CR1 note), and a repeated START, set at BTF, leaves BTF raising the event interrupt until it
//! is on the bus. Either condition takes at most one SCL period once SCL is free (2.5 µs at
//! 400 kHz) and raises no interrupt of its own, so the engine says it waits for it
//! ([`Engine::awaiting`]) and the caller polls it outside the critical section, for at most
//! [`CONDITION_WAIT_NS`] (two SCL periods) on the cycle counter and at most [`CONDITION_POLLS`]
//! times, each poll a section of its own, then calls [`Engine::resume`].
//!
//! **A repeated START a device delays past that wait** (it stretches SCL after its acknowledge)
//! would leave BTF raising the event interrupt until the START is out: a handler re-entered at
//! the engine's priority for as long as the device holds SCL (for ever, if it never lets go).
//! Instead the engine *stalls*: it masks the event interrupt (ITEVTEN off, ITERREN kept;
//! [`Engine::stalled`]) and the bus's watch (`I2cBus::serve_watch`, a task on the monotonic)
//! looks again every [`STRETCH_REARM_US`]: one poll of CR1.START, and the event interrupt back on
//! once the START is out (SB then raises it), else the stall goes on. After [`MAX_REARMS`] looks
//! the engine stops looking; the script's deadline ([`deadline_us`]) ends it
//! ([`Engine::expire`], [`Failure::Stretched`]), or its client's timeout, which aborts it (the
//! block reset). So a script costs at most its own events and [`MAX_REARMS`] re-arms of one poll
//! each, whatever a device does with SCL, and holds its bus at most until its deadline.
use amiro_sensors::script::{Failure, Operation, Readings, Script, ScriptError};

/// CR1: peripheral enable.
pub const CR1_PE: u16 = 1 << 0;
/// CR1: START generation.
pub const CR1_START: u16 = 1 << 8;
/// CR1: STOP generation.
pub const CR1_STOP: u16 = 1 << 9;
/// CR1: acknowledge enable.
pub const CR1_ACK: u16 = 1 << 10;
/// CR1: acknowledge / PEC position (the two-byte reception).
pub const CR1_POS: u16 = 1 << 11;
/// CR1: software reset.
pub const CR1_SWRST: u16 = 1 << 15;
/// CR2: error interrupt enable.
pub const CR2_ITERREN: u16 = 1 << 8;
/// CR2: event interrupt enable.
pub const CR2_ITEVTEN: u16 = 1 << 9;
/// CR2: buffer interrupt enable (TXE and RXNE raise the event interrupt).
pub const CR2_ITBUFEN: u16 = 1 << 10;
/// SR1: start bit (master mode): EV5.
pub const SR1_SB: u16 = 1 << 0;
/// SR1: address sent (master mode): EV6.
pub const SR1_ADDR: u16 = 1 << 1;
/// SR1: byte transfer finished.
pub const SR1_BTF: u16 = 1 << 2;
/// SR1: data register not empty (receiver).
pub const SR1_RXNE: u16 = 1 << 6;
/// SR1: data register empty (transmitter).
pub const SR1_TXE: u16 = 1 << 7;
/// SR1: bus error.
pub const SR1_BERR: u16 = 1 << 8;
/// SR1: arbitration lost.
pub const SR1_ARLO: u16 = 1 << 9;
/// SR1: acknowledge failure.
pub const SR1_AF: u16 = 1 << 10;
/// SR1: overrun / underrun.
pub const SR1_OVR: u16 = 1 << 11;
/// The error flags the engine serves (I2Cx_ER).
pub const SR1_ERRORS: u16 = SR1_BERR | SR1_ARLO | SR1_AF | SR1_OVR;

/// The condition wait's time bound: two SCL periods of the bus's 400 kHz, each 2.5 µs plus the
/// SCL rise time (at most 300 ns in Fast-mode, UM10204 Table 10). A STOP programmed at BTF goes
/// out within one SCL period of SCL's release, one programmed before a read's last byte within
/// the NACK bit's period and the STOP's set-up after the byte's RXNE (UM10204 §3.1.4, Table 10:
/// tSU;STO ≥ 0.6 µs); a repeated START set at BTF within one period (RM0008 §26.6.1, CR1's
/// START: a repeated start in master mode; BTF holds SCL low, and the START goes out once the
/// block releases it). Longer is a device holding SCL: the fault path
/// ([`Engine::resume`] with `cleared` false). Counted on the core's cycle counter
/// ([`Block::cycles`]); the stated peripheral wait of tools/engine-bound's bounds files.
pub const CONDITION_WAIT_NS: u32 = 5_600;

/// Polls of CR1.STOP (before a START) or CR1.START (after a repeated START is set) at most, as well
/// as [`CONDITION_WAIT_NS`]: where the cycle counter runs (the chips) the time ends the wait first
/// (a poll is a critical section, a volatile read on APB1 and the counter's read, more than eight
/// cycles, so 128 polls outlast the 941 cycles 5.6 µs are at 168 MHz); where it does not (QEMU has
/// no DWT, the host model's default) the count ends it, as in the polled master (`i2c::Master`).
pub const CONDITION_POLLS: u32 = 128;

/// The interval between two looks at a stalled repeated START (µs): a hundred SCL periods at
/// 400 kHz, so a stretch costs one re-arm's poll per 250 µs of it instead of the handler's
/// continuous re-entry.
pub const STRETCH_REARM_US: u32 = 250;

/// Looks at a stalled repeated START per script at most; after them the engine leaves the event
/// interrupt masked and the script to its client's timeout. 20 × [`STRETCH_REARM_US`] = 5 ms, more
/// than the longest stretch an AMiRo device states within a packet (the bq27500's 4 ms; the
/// HMC5883L, the VCNL4020, the PCA9544A and the BNO055 state none longer).
pub const MAX_REARMS: u8 = 20;

/// A script's allowance per flag the engine awaits (an event: SB, ADDR, TXE, BTF, RXNE): the polled
/// master's flag timeout (`i2c::FLAG_TIMEOUT_US`, 200 µs against one byte's 22.5 µs at 400 kHz),
/// kept so that a script ends where the polled path's transfer of the same bytes would have given up
/// at the latest. A device that stretches SCL longer than its script's flags allow in all
/// (the bq27xxx family's 4 ms within a packet addressed to it, its 5 ms as it wakes) ends the script
/// with [`Failure::Stretched`] ([`deadline_us`]).
pub const FLAG_ALLOWANCE_US: u32 = 200;

/// The events the engine serves for `script` on a bus where every byte is acknowledged (its
/// interrupts, each a flag the block raises): per operation its first START's SB and ADDR, a TXE per
/// written byte and BTF; a read (after the repeated START's SB and ADDR, or alone) one RXNE for one
/// byte, BTF for two, BTF and RXNE for three, and for N > 3 an RXNE per byte but the last three, BTF
/// and RXNE. The host tests count them on the register model (`i2c_tests`).
pub fn events(script: &Script) -> u32 {
    script
        .operations()
        .iter()
        .map(|op| {
            let write = if op.write > 0 || op.read == 0 {
                3 + u32::from(op.write)
            } else {
                0
            };
            let read = match op.read {
                0 => 0,
                1 | 2 => 3,
                3 => 4,
                n => 1 + u32::from(n),
            };
            write + read
        })
        .sum()
}

/// A script's deadline on the bus (µs from its start): its wire time at
/// [`SCL_HZ`](amiro_sensors::script::SCL_HZ), rounded up, plus [`FLAG_ALLOWANCE_US`] per event
/// ([`events`]). The bus's watch (`I2cBus::serve_watch`) ends a script still running then with
/// [`Failure::Stretched`]; the analysis charges a script's bus time at most this (docs/i2c.md, "A
/// script's deadline").
pub fn deadline_us(script: &Script) -> u32 {
    deadline_after(script, wire_us(script))
}

/// [`deadline_us`] of `script` whose wire time ([`wire_us`]) is `wire_us`.
pub fn deadline_after(script: &Script, wire_us: u32) -> u32 {
    wire_us.saturating_add(events(script).saturating_mul(FLAG_ALLOWANCE_US))
}

/// A script's time on the wire at [`SCL_HZ`](amiro_sensors::script::SCL_HZ), µs rounded up.
pub fn wire_us(script: &Script) -> u32 {
    let wire = script
        .bus_time_ns(amiro_sensors::script::SCL_HZ)
        .div_ceil(1000);
    u32::try_from(wire).unwrap_or(u32::MAX)
}

/// Which of the block's interrupts are on (CR2's three enables).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interrupts {
    /// None: the block is idle.
    Off,
    /// ITERREN alone: a stalled repeated START (BTF would raise the event interrupt until the
    /// START is out; the errors still end the script).
    Errors,
    /// ITEVTEN and ITERREN: SB, ADDR, BTF and the errors (a step that waits for BTF).
    Events,
    /// ITEVTEN, ITBUFEN and ITERREN: TXE and RXNE as well (a step that moves one byte).
    Buffer,
}

impl Interrupts {
    /// CR2's enable bits.
    pub const fn bits(self) -> u16 {
        match self {
            Interrupts::Off => 0,
            Interrupts::Errors => CR2_ITERREN,
            Interrupts::Events => CR2_ITEVTEN | CR2_ITERREN,
            Interrupts::Buffer => CR2_ITEVTEN | CR2_ITERREN | CR2_ITBUFEN,
        }
    }
}

/// The register actions of one I2C block: what the engine does, in the order it does it.
pub trait Block {
    /// Reads SR1 (the caller's, at each interrupt: the engine is given its value).
    fn read_sr1(&mut self) -> u16;
    /// Reads SR2 (after an SR1 read with ADDR set, this clears ADDR: EV6).
    fn read_sr2(&mut self) -> u16;
    /// Reads DR (a received byte; clears RXNE, and BTF with it).
    fn read_dr(&mut self) -> u8;
    /// Writes DR (an address byte or a data byte).
    fn write_dr(&mut self, byte: u8);
    /// Sets the bits `set` and clears the bits `clear` of CR1 (a read-modify-write).
    fn modify_cr1(&mut self, set: u16, clear: u16);
    /// Whether CR1.STOP is still set (a STOP not yet on the bus).
    fn stop_pending(&mut self) -> bool;
    /// Whether CR1.START is still set (a START not yet on the bus).
    fn start_pending(&mut self) -> bool;
    /// Sets CR2's interrupt enables (the FREQ field kept).
    fn set_interrupts(&mut self, interrupts: Interrupts);
    /// Clears the rc_w0 flags `flags` of SR1 (writes 0 to them, 1 to the others).
    fn clear_sr1(&mut self, flags: u16);
    /// Resets the block (SWRST) and sets it up again for 400 kHz, interrupts off.
    fn reset(&mut self);
    /// The core's cycle counter (DWT CYCCNT on the chip): the condition wait's clock. A block
    /// with no counter keeps this default, 0, and the wait ends at [`CONDITION_POLLS`].
    fn cycles(&mut self) -> u32 {
        0
    }
    /// [`CONDITION_WAIT_NS`] in cycles of the counter [`Block::cycles`] reads.
    fn condition_cycles(&self) -> u32 {
        u32::MAX
    }
}

/// A condition the engine waits to see on the bus before it goes on: the caller polls it
/// ([`Engine::condition_pending`]) outside its critical section, at most [`CONDITION_POLLS`]
/// times, then calls [`Engine::resume`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Condition {
    /// The STOP before an operation's START has to clear (RM0008 §26.6.1, the CR1 note).
    Stop,
    /// A repeated START set at BTF has to go out (BTF, and with it the event interrupt, stays set
    /// until it has).
    Start,
}

/// What an event did to the script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// The script goes on (or the engine is idle and the event was stray).
    Running,
    /// The script ended: every operation done, or the first failure.
    Finished(Result<(), ScriptError>),
}

/// Where the engine is in the current operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// No script.
    Idle,
    /// START set; waiting for SB (EV5), then the address byte: an operation's first START
    /// (`repeated` false: its direction is the operation's), or the repeated START of a write
    /// then a read (the read's).
    Start { repeated: bool },
    /// Address byte written; waiting for ADDR (EV6).
    Address { read: bool },
    /// Writing: the script's bytes before [`Engine::cursor`] are in DR or gone; waiting for TXE
    /// (EV8_1, EV8).
    Transmit,
    /// Every byte written; waiting for BTF (EV8_2).
    TransmitEnd,
    /// Reading N > 3 bytes, `left` of them still to come (> 3); RXNE each (EV7).
    Receive { left: u8 },
    /// Reading N > 2 bytes, three left: waiting for BTF (DataN-2 in DR, DataN-1 in the shift
    /// register: method 2).
    ReceiveThreeLeft,
    /// Reading two bytes with POS: waiting for BTF (both received).
    ReceiveTwo,
    /// The last byte (its NACK and the STOP already programmed): waiting for RXNE.
    ReceiveLast,
}

/// The state machine of one I2C block's master: which operation of the running script, and
/// which step of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Engine {
    phase: Phase,
    /// The condition awaited, and which wait it is (a client's abort and a new script between
    /// the polls make the old wait's resume a no-op).
    awaiting: Option<(Condition, u32)>,
    waits: u32,
    /// A repeated START that did not go out within the condition wait: the wait's number, while
    /// the event interrupt is masked for it.
    stalled: Option<u32>,
    /// The running script's re-arms so far ([`MAX_REARMS`] at most).
    rearms: u8,
    /// The running operation's index (the low byte) and the running script's operation count,
    /// taken once at its start (the high byte): one load at an operation's end tells whether the
    /// script has another.
    operations: u16,
    /// The next byte to write: its index in the script's written bytes (the bytes of the
    /// operations before are all sent, or the script failed).
    cursor: u8,
    /// The running operation's address byte with its direction bit clear, the end of its
    /// written bytes (an index like `cursor`) and its bytes to read: taken from the script once,
    /// at the operation's SB, so that its other events read them from the engine instead of
    /// looking the operation up again.
    address: u8,
    write_end: u8,
    read: u8,
}

impl Default for Engine {
    fn default() -> Self {
        Self::new()
    }
}

impl Engine {
    /// An idle engine.
    pub const fn new() -> Self {
        Self {
            phase: Phase::Idle,
            awaiting: None,
            waits: 0,
            stalled: None,
            rearms: 0,
            operations: 0,
            cursor: 0,
            address: 0,
            write_end: 0,
            read: 0,
        }
    }

    /// Whether no script runs.
    pub fn is_idle(&self) -> bool {
        self.phase == Phase::Idle
    }

    /// Starts `script` (its first operation's START). An empty script finishes at once.
    pub fn start(&mut self, script: &Script, block: &mut impl Block) -> Progress {
        self.cursor = 0;
        self.rearms = 0;
        // At most `MAX_OPERATIONS` (12); the running one 0.
        self.operations =
            u16::from(u8::try_from(script.operations().len()).unwrap_or(u8::MAX)) << 8;
        self.begin(block)
    }

    /// Stops the running script where it is (the client's timeout, or a dropped client) and
    /// leaves the block reset and set up again.
    pub fn abort(&mut self, block: &mut impl Block) {
        self.phase = Phase::Idle;
        self.awaiting = None;
        self.stalled = None;
        block.reset();
    }

    /// Ends the running script at its deadline (the bus's watch): the block reset (its
    /// interrupts off), the failure [`Failure::Stretched`] in the operation it had reached.
    pub fn expire(&mut self, block: &mut impl Block) -> ScriptError {
        block.reset();
        let error = ScriptError {
            operation: self.operation(),
            failure: Failure::Stretched,
        };
        self.phase = Phase::Idle;
        self.awaiting = None;
        self.stalled = None;
        error
    }

    /// The running operation's index.
    #[inline(always)]
    fn operation(&self) -> u8 {
        self.operations as u8
    }

    #[inline(always)]
    fn current(&self, script: &Script) -> Option<Operation> {
        script
            .operations()
            .get(usize::from(self.operation()))
            .copied()
    }

    /// The running operation's START, or the script's end. The operation itself is looked up at
    /// its SB (EV5), the one event every operation has: the event that ended the operation before
    /// it then does no look-up.
    #[inline(always)]
    fn begin(&mut self, block: &mut impl Block) -> Progress {
        if self.operations & 0xff >= self.operations >> 8 {
            // Nothing is awaited or stalled here: an event comes only after the wait before it
            // was resumed and with no stall (a stall masks the event interrupt until it ends).
            self.phase = Phase::Idle;
            block.set_interrupts(Interrupts::Off);
            return Progress::Finished(Ok(()));
        }
        // RM0008 §26.6.1, CR1 note: no write to CR1 until the STOP set before has cleared; the
        // START is set in `resume`.
        self.phase = Phase::Start { repeated: false };
        self.wait_for(Condition::Stop);
        Progress::Running
    }

    fn wait_for(&mut self, condition: Condition) {
        self.waits = self.waits.wrapping_add(1);
        self.awaiting = Some((condition, self.waits));
    }

    /// The condition to poll before the script goes on, and which wait it is.
    pub fn awaiting(&self) -> Option<(Condition, u32)> {
        self.awaiting
    }

    /// One poll of the awaited condition: `true` while it is still pending.
    pub fn condition_pending(&self, block: &mut impl Block) -> bool {
        match self.awaiting {
            Some((Condition::Stop, _)) => block.stop_pending(),
            Some((Condition::Start, _)) => block.start_pending(),
            None => false,
        }
    }

    /// After the polls of the awaited condition (`cleared`: it went out within them). A STOP
    /// that did not clear is a device holding SCL: the block is reset (which drops the STOP) and
    /// the START set anyway; it waits for a free bus, which a stuck bus never gives, and the
    /// client's timeout ends the script. A repeated START that did not go out within the polls
    /// (a device stretching SCL after its acknowledge) stalls the script: the event interrupt
    /// masked (BTF would raise it until the START is out), to be re-armed by
    /// [`Engine::rearm`] ([`Engine::stalled`] says so).
    pub fn resume(&mut self, cleared: bool, block: &mut impl Block) {
        match self.awaiting.take() {
            Some((Condition::Start, wait)) if !cleared => {
                block.set_interrupts(Interrupts::Errors);
                self.stalled = Some(wait);
            }
            Some((Condition::Stop, _)) => {
                if !cleared {
                    block.reset();
                }
                block.set_interrupts(Interrupts::Events);
                // §26.3.3 "Start condition": setting START makes the block a master (once the
                // bus is free); SB follows.
                block.modify_cr1(CR1_START, 0);
            }
            Some((Condition::Start, _)) | None => {}
        }
    }

    /// The stalled repeated START's wait number, while the event interrupt is masked for it and
    /// the re-arms are not spent.
    pub fn stalled(&self) -> Option<u32> {
        self.stalled
    }

    /// One look at the stalled repeated START, [`STRETCH_REARM_US`] after the last (`pending`:
    /// CR1.START still set, the caller's one poll). Out: the event interrupt on again (SB raises
    /// it at once). Still pending: the stall goes on, for [`MAX_REARMS`] looks a script; after the
    /// last the event interrupt stays masked and [`Engine::stalled`] is `None`: the client's
    /// timeout ends the script (its abort resets the block).
    pub fn rearm(&mut self, pending: bool, block: &mut impl Block) {
        if self.stalled.is_none() {
            return;
        }
        if !pending {
            self.stalled = None;
            block.set_interrupts(Interrupts::Events);
            return;
        }
        self.rearms = self.rearms.saturating_add(1);
        if self.rearms >= MAX_REARMS {
            self.stalled = None;
        }
    }

    /// The next operation, or the script's end.
    #[inline(always)]
    fn next_operation(&mut self, block: &mut impl Block) -> Progress {
        self.operations += 1;
        self.begin(block)
    }

    fn fail(&mut self, failure: Failure) -> Progress {
        self.phase = Phase::Idle;
        self.awaiting = None;
        self.stalled = None;
        Progress::Finished(Err(ScriptError {
            operation: self.operation(),
            failure,
        }))
    }

    /// An event interrupt (I2Cx_EV) with SR1 read as `sr1`; bytes read go to `readings`.
    /// Inlined into its caller (the bus's handler), so that an event pays no second call and
    /// prologue.
    #[inline(always)]
    pub fn on_event(
        &mut self,
        sr1: u16,
        script: &Script,
        readings: &mut Readings,
        block: &mut impl Block,
    ) -> Progress {
        match self.phase {
            Phase::Idle => {
                self.on_stray_event(block);
                Progress::Running
            }
            Phase::Start { repeated } if sr1 & SR1_SB != 0 => {
                let read = if repeated {
                    true
                } else {
                    // The operation's address and byte counts, kept for its other events.
                    let Some(op) = self.current(script) else {
                        // Not the script `start` was given (the bus never does this): nothing to
                        // address; the interrupts off, the client's timeout aborts the script.
                        self.on_stray_event(block);
                        return Progress::Running;
                    };
                    self.address = op.address << 1;
                    self.write_end = self.cursor.wrapping_add(op.write);
                    self.read = op.read;
                    op.write == 0
                };
                // EV5: SB is cleared by the SR1 read (the caller's) followed by the DR write of
                // the address byte.
                block.write_dr(self.address | u8::from(read));
                self.phase = Phase::Address { read };
                Progress::Running
            }
            Phase::Address { read: false } if sr1 & SR1_ADDR != 0 => {
                // EV6: ADDR is cleared by the SR1 read followed by the SR2 read; the transmitter
                // then has TXE (EV8_1), served with the buffer interrupt.
                block.read_sr2();
                block.set_interrupts(Interrupts::Buffer);
                self.phase = Phase::Transmit;
                Progress::Running
            }
            Phase::Address { read: true } if sr1 & SR1_ADDR != 0 => {
                self.addressed_for_read(self.read, block);
                Progress::Running
            }
            Phase::Transmit if sr1 & SR1_TXE != 0 => {
                // EV8_1 (first byte), EV8 (the others): TXE is cleared by writing DR.
                let index = self.cursor;
                let byte = script.written().get(usize::from(index)).copied();
                block.write_dr(byte.unwrap_or(0));
                self.cursor = index.wrapping_add(1);
                if self.cursor == self.write_end {
                    // The last byte is in DR: TXE off, wait for BTF (EV8_2).
                    block.set_interrupts(Interrupts::Events);
                    self.phase = Phase::TransmitEnd;
                }
                Progress::Running
            }
            Phase::TransmitEnd if sr1 & SR1_BTF != 0 => {
                if self.read > 0 {
                    // §26.3.3 "Closing the communication" / a write then a read: a repeated
                    // START instead of the STOP, set while BTF holds SCL low. BTF stays set
                    // (and would raise this interrupt again) until the START is on the bus: the
                    // caller waits for it (`Condition::Start`); SB's own interrupt follows.
                    block.modify_cr1(CR1_START, 0);
                    self.phase = Phase::Start { repeated: true };
                    self.wait_for(Condition::Start);
                    Progress::Running
                } else {
                    // EV8_2: TXE = BTF = 1, program STOP (it clears both).
                    block.modify_cr1(CR1_STOP, 0);
                    self.next_operation(block)
                }
            }
            Phase::Receive { left } if sr1 & SR1_RXNE != 0 => {
                // EV7: RXNE is cleared by reading DR.
                readings.push(block.read_dr());
                let left = left - 1;
                if left <= 3 {
                    // Method 2: with three left, wait for BTF instead of RXNE.
                    block.set_interrupts(Interrupts::Events);
                    self.phase = Phase::ReceiveThreeLeft;
                } else {
                    self.phase = Phase::Receive { left };
                }
                Progress::Running
            }
            Phase::ReceiveThreeLeft if sr1 & SR1_BTF != 0 => {
                // Method 2, "When 3 bytes remain to be read": BTF = 1 (DataN-2 in DR, DataN-1 in
                // the shift register, SCL held low). Clear ACK; read DataN-2 (DataN's reception
                // starts, to be NACKed); program STOP; read DataN-1. The last three must not be
                // interrupted (AN2824; the critical section, above).
                block.modify_cr1(0, CR1_ACK);
                let n_2 = block.read_dr();
                block.modify_cr1(CR1_STOP, 0);
                let n_1 = block.read_dr();
                readings.push(n_2);
                readings.push(n_1);
                // Then RXNE for DataN (EV7).
                block.set_interrupts(Interrupts::Buffer);
                self.phase = Phase::ReceiveLast;
                Progress::Running
            }
            Phase::ReceiveTwo if sr1 & SR1_BTF != 0 => {
                // Method 2, N = 2: BTF = 1 (data 1 in DR, data 2 in the shift register); program
                // STOP, read data 1 and data 2.
                block.modify_cr1(CR1_STOP, 0);
                let first = block.read_dr();
                let second = block.read_dr();
                readings.push(first);
                readings.push(second);
                self.next_operation(block)
            }
            Phase::ReceiveLast if sr1 & SR1_RXNE != 0 => {
                // EV7 of the last byte (its NACK and the STOP programmed before it came).
                readings.push(block.read_dr());
                self.next_operation(block)
            }
            _ if sr1 & (SR1_SB | SR1_ADDR) != 0 => {
                // SB or ADDR where the sequence has none: they hold SCL and raise the event
                // interrupt until served, and no step serves them here.
                block.reset();
                self.fail(Failure::UnexpectedEvent)
            }
            // Anything else is an interrupt whose flag has gone (a TXE or RXNE pended just before
            // its enable was turned off, a BTF beside a byte already served): nothing to do.
            _ => Progress::Running,
        }
    }

    /// An event interrupt with no script running (one pended as the last ended, or a fault of
    /// the block): its enables off, so that it does not come back.
    pub fn on_stray_event(&mut self, block: &mut impl Block) {
        self.phase = Phase::Idle;
        self.awaiting = None;
        self.stalled = None;
        block.set_interrupts(Interrupts::Off);
    }

    /// EV6 of a read of `count` bytes: the acknowledge set up for its ending before ADDR is
    /// cleared (the first byte's reception starts when it is).
    fn addressed_for_read(&mut self, count: u8, block: &mut impl Block) {
        match count {
            1 => {
                // Method 2, N = 1: ACK = 0 in the ADDR event, before ADDR is cleared; STOP
                // programmed just after (no interrupt between the two: AN2824,
                // the errata's "must be managed before the current byte is being transferred").
                block.modify_cr1(0, CR1_ACK | CR1_POS);
                block.read_sr2();
                block.modify_cr1(CR1_STOP, 0);
                // EV7: the byte's read when RXNE comes.
                block.set_interrupts(Interrupts::Buffer);
                self.phase = Phase::ReceiveLast;
            }
            2 => {
                // Method 2, N = 2: ACK low and POS high, then clear ADDR; wait for BTF (the
                // buffer interrupt off).
                block.modify_cr1(CR1_POS, CR1_ACK);
                block.read_sr2();
                block.set_interrupts(Interrupts::Events);
                self.phase = Phase::ReceiveTwo;
            }
            _ => {
                // N > 2: every byte but the last two acknowledged as it comes (ACK = 1, POS = 0
                // before the first byte's reception), method 2's ending at three left.
                block.modify_cr1(CR1_ACK, CR1_POS);
                block.read_sr2();
                if count > 3 {
                    block.set_interrupts(Interrupts::Buffer);
                    self.phase = Phase::Receive { left: count };
                } else {
                    block.set_interrupts(Interrupts::Events);
                    self.phase = Phase::ReceiveThreeLeft;
                }
            }
        }
    }

    /// An error interrupt (I2Cx_ER) with SR1 read as `sr1` (RM0008 §26.3.4). An arbitration loss,
    /// a bus error or an overrun resets the block (the polled master's rule); a missing
    /// acknowledge programs the STOP the reference manual asks the master for and leaves the
    /// block as it is. Arbitration loss is served first (the block is no longer a master), then
    /// a bus error, an overrun, and a missing acknowledge.
    #[inline(always)]
    pub fn on_error(&mut self, sr1: u16, block: &mut impl Block) -> Progress {
        let flags = sr1 & SR1_ERRORS;
        if flags == 0 {
            return Progress::Running;
        }
        block.clear_sr1(flags);
        if self.phase == Phase::Idle {
            block.set_interrupts(Interrupts::Off);
            return Progress::Running;
        }
        let failure = if flags & SR1_ARLO != 0 {
            // ARLO: the block went back to slave mode and released the lines.
            Failure::ArbitrationLoss
        } else if flags & SR1_BERR != 0 {
            Failure::Bus
        } else if flags & SR1_OVR != 0 {
            Failure::Overrun
        } else {
            match self.phase {
                Phase::Address { .. } => Failure::NackAddress,
                Phase::Transmit | Phase::TransmitEnd => Failure::NackData,
                // A missing acknowledge while the block receives or starts is not a step of
                // the sequence.
                _ => Failure::UnexpectedEvent,
            }
        };
        match failure {
            Failure::NackAddress | Failure::NackData => {
                // AF: "a Stop or repeated Start condition must be generated by software".
                block.modify_cr1(CR1_STOP, 0);
                block.set_interrupts(Interrupts::Off);
            }
            _ => block.reset(),
        }
        self.fail(failure)
    }
}
