//! A register-level model of one bxCAN block: what the controller does with what the driver writes,
//! and what the bus does to it. The driver's tests run [`super::Mailboxes`], [`super::Fifo0`],
//! [`super::ErrorMonitor`] and [`super::configure`] over it (`tests/bxcan.rs`), and the QEMU build
//! runs the boards' CAN path over it (`qemu::can`), with the robot's bus on the other side: one
//! model, so the emulation runs the driver the robot runs.
//!
//! Modelled as RM0008 §24 and RM0090 §32 describe the block:
//! - MCR/MSR: the initialisation and sleep handshake (INRQ/INAK, SLEEP/SLAK, RESET), TXFP, NART, RFLM;
//!   BTR is writable only in initialisation mode; ERRI and its acknowledgement.
//! - The three transmit mailboxes (TIxR, TDTxR, TDLxR, TDHxR, write-protected while pending) and
//!   TSR: RQCP, TXOK, ALST, TERR and ABRQ per mailbox, CODE, TME and LOW. The controller offers the
//!   pending mailbox of the lowest identifier, ties to the lower mailbox number (TXFP clear), or in
//!   request order (TXFP set). An abort request ends a mailbox that is not on the bus; one on the bus
//!   ends as its transmission does (sent, or aborted instead of retried).
//! - Receive FIFO 0: three mailboxes (RIxR, RDTxR, RDLxR, RDHxR of the oldest), FMP, FULL, FOVR and
//!   RFOM; on an overrun the newest frame is overwritten (RFLM clear) or the incoming one is
//!   discarded (RFLM set). Filter bank 0 (the one the driver uses) in 32-bit mask or list mode, its
//!   FIFO assignment and activation, FINIT.
//! - IER and the lines of the transmit, FIFO 0 and status-change interrupts.
//! - ESR: the error counters and the warning, passive and bus-off flags they imply.
//!
//! Not modelled: FIFO 1, filter banks 1–27 and the 16-bit filter scale (they match nothing),
//! time-triggered mode, the last-error code, the wake-up and sleep interrupts, loop-back and silent
//! modes. Nothing here allocates or panics: an access the hardware ignores (a write to a pending
//! mailbox, a register the model does not hold) is ignored and counted ([`Model::ignored_writes`]).

use super::{bit, reg};

mod bus;
pub use bus::{Failure, Reception, RxRequest, TxRequest};

/// MCR bits the model adds to the driver's.
const MCR_RFLM: u32 = 1 << 3;
/// MSR: sleep acknowledge.
const MSR_SLAK: u32 = 1 << 1;
/// TSR: arbitration lost, transmission error (per mailbox, shifted by 8 × mailbox).
const TSR_ALST: u32 = 1 << 2;
const TSR_TERR: u32 = 1 << 3;
/// RF0R: FIFO full.
const RF_FULL: u32 = 1 << 3;
/// IER: FIFO 0 full interrupt enable.
const IER_FFIE0: u32 = 1 << 2;
/// The reset values of MCR and MSR (RM0008 §24.9.2): sleep mode requested and acknowledged.
const MCR_RESET_VALUE: u32 = 0x0001_0002;

/// One transmit mailbox's registers and status.
#[derive(Debug, Clone, Copy, Default)]
struct TxMailbox {
    /// TIxR (identifier, IDE, RTR, TXRQ: TXRQ set means pending).
    tir: u32,
    tdtr: u32,
    tdlr: u32,
    tdhr: u32,
    /// This mailbox's TSR byte (RQCP, TXOK, ALST, TERR, ABRQ).
    status: u32,
    /// When its request was made, in requests counted (the order TXFP sends in).
    requested: u32,
}

impl TxMailbox {
    fn pending(&self) -> bool {
        self.tir & bit::TIR_TXRQ != 0
    }
}

/// A register write's effect the bus side must act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Written {
    /// The mailboxes whose transmission this write requested (TXRQ), one bit each.
    pub requested: u8,
    /// The mailboxes for which this write asked for an abort (ABRQ on a pending one), one bit each.
    pub abort_requested: u8,
}

/// One bxCAN block (see the module's notes for what is modelled).
#[derive(Debug, Clone)]
pub struct Model {
    mcr: u32,
    msr: u32,
    btr: u32,
    ier: u32,
    tec: u8,
    rec: u8,
    bus_off: bool,
    tx: [TxMailbox; 3],
    requests: u32,
    fifo: [[u32; 4]; 3],
    fifo_len: u8,
    fifo_full: bool,
    fifo_overrun: bool,
    fmr: u32,
    fm1r: u32,
    fs1r: u32,
    ffa1r: u32,
    fa1r: u32,
    bank0: [u32; 2],
    ignored_writes: u32,
    /// The block gets no clock: it never acknowledges a mode request.
    pub unclocked: bool,
    /// The bus is held dominant (or CAN_RX is open): the controller never sees the 11 recessive
    /// bits it needs to leave initialisation mode.
    pub bus_held_dominant: bool,
}

impl Default for Model {
    fn default() -> Self {
        Self::new()
    }
}

impl Model {
    /// A block at reset (sleep mode, every register at its reset value).
    pub const fn new() -> Self {
        Self {
            mcr: MCR_RESET_VALUE,
            msr: MSR_SLAK,
            btr: 0x0123_0000,
            ier: 0,
            tec: 0,
            rec: 0,
            bus_off: false,
            tx: [TxMailbox {
                tir: 0,
                tdtr: 0,
                tdlr: 0,
                tdhr: 0,
                status: 0,
                requested: 0,
            }; 3],
            requests: 0,
            fifo: [[0; 4]; 3],
            fifo_len: 0,
            fifo_full: false,
            fifo_overrun: false,
            fmr: 0x2A1C_0E01,
            fm1r: 0,
            fs1r: 0,
            ffa1r: 0,
            fa1r: 0,
            bank0: [0; 2],
            ignored_writes: 0,
            unclocked: false,
            bus_held_dominant: false,
        }
    }

    /// Reads the register at `offset` (0 for one the model does not hold). Inlined: the driver
    /// names its registers by constant offsets, so each access folds to its own arm (in the QEMU
    /// build a register access should cost little more than the chip's load).
    #[inline(always)]
    pub fn read(&self, offset: usize) -> u32 {
        match offset {
            reg::MCR => self.mcr,
            reg::MSR => self.msr,
            reg::TSR => self.tsr(),
            reg::RF0R => self.rf0r(),
            reg::IER => self.ier,
            reg::ESR => self.esr(),
            reg::BTR => self.btr,
            0x180..=0x1AC => {
                self.tx
                    .get((offset - 0x180) / 0x10)
                    .map_or(0, |m| match (offset - 0x180) % 0x10 {
                        0x0 => m.tir,
                        0x4 => m.tdtr,
                        0x8 => m.tdlr,
                        _ => m.tdhr,
                    })
            }
            reg::RI0R..=reg::RDH0R if self.fifo_len > 0 => self.fifo[0]
                .get((offset - reg::RI0R) / 4)
                .copied()
                .unwrap_or(0),
            reg::FMR => self.fmr,
            reg::FM1R => self.fm1r,
            reg::FS1R => self.fs1r,
            reg::FFA1R => self.ffa1r,
            reg::FA1R => self.fa1r,
            reg::F0R1 => self.bank0[0],
            reg::F0R2 => self.bank0[1],
            _ => 0,
        }
    }

    /// Writes the register at `offset` as the block would take it; says what the bus side must act
    /// on. Inlined, as [`Model::read`].
    #[inline(always)]
    pub fn write(&mut self, offset: usize, value: u32) -> Written {
        let mut written = Written::default();
        match offset {
            reg::MCR => self.write_mcr(value),
            // ERRI is write-1-to-clear; the wake-up and sleep flags are not modelled.
            reg::MSR if value & bit::MSR_ERRI != 0 => self.msr &= !bit::MSR_ERRI,
            reg::MSR => {}
            reg::TSR => written.abort_requested = self.write_tsr(value),
            reg::RF0R => self.write_rf0r(value),
            reg::IER => self.ier = value,
            // The last-error code is the one writable field: not modelled.
            reg::ESR => {}
            reg::BTR if self.in_init() => self.btr = value,
            0x180..=0x1AC => {
                let (i, r) = ((offset - 0x180) / 0x10, (offset - 0x180) % 0x10);
                if self.write_mailbox(i, r, value) {
                    written.requested = 1 << i;
                }
            }
            reg::FMR => self.fmr = value,
            reg::FA1R => self.fa1r = value & 0x0FFF_FFFF,
            // The other filter registers are writable only with FINIT set (bank 0's also while it
            // is inactive).
            reg::FM1R if self.filter_init() => self.fm1r = value & 0x0FFF_FFFF,
            reg::FS1R if self.filter_init() => self.fs1r = value & 0x0FFF_FFFF,
            reg::FFA1R if self.filter_init() => self.ffa1r = value & 0x0FFF_FFFF,
            reg::F0R1 if self.fa1r & 1 == 0 || self.filter_init() => self.bank0[0] = value,
            reg::F0R2 if self.fa1r & 1 == 0 || self.filter_init() => self.bank0[1] = value,
            _ => self.ignored_writes = self.ignored_writes.saturating_add(1),
        }
        written
    }

    /// Writes the model ignored as the hardware would (a pending mailbox, BTR outside
    /// initialisation mode, a filter register outside filter initialisation, a register it does not
    /// hold): a driver that runs clean has none.
    pub fn ignored_writes(&self) -> u32 {
        self.ignored_writes
    }

    fn in_init(&self) -> bool {
        self.msr & bit::MSR_INAK != 0
    }

    fn filter_init(&self) -> bool {
        self.fmr & bit::FMR_FINIT != 0
    }

    /// Whether the controller takes part in bus activity: out of initialisation and sleep mode and
    /// not bus-off.
    pub fn on_bus(&self) -> bool {
        self.msr & (bit::MSR_INAK | MSR_SLAK) == 0 && !self.bus_off
    }

    fn write_mcr(&mut self, value: u32) {
        if value & bit::MCR_RESET != 0 {
            self.master_reset();
            return;
        }
        self.mcr = value & 0x0001_00FF;
        if self.unclocked {
            return;
        }
        let leaving_init = value & bit::MCR_INRQ == 0 && self.in_init();
        if value & bit::MCR_INRQ != 0 {
            self.msr = (self.msr | bit::MSR_INAK) & !MSR_SLAK;
        } else if value & bit::MCR_SLEEP != 0 {
            self.msr = (self.msr | MSR_SLAK) & !bit::MSR_INAK;
        } else if !(leaving_init && self.bus_held_dominant) {
            self.msr &= !(bit::MSR_INAK | MSR_SLAK);
        }
    }

    /// A master reset: every register back to its reset value, sleep mode. (Copied over from the
    /// reset block, not built beside it: a block-sized temporary costs the stack of whoever resets.)
    fn master_reset(&mut self) {
        let kept = (self.unclocked, self.bus_held_dominant, self.ignored_writes);
        *self = const { Self::new() };
        (self.unclocked, self.bus_held_dominant, self.ignored_writes) = kept;
    }

    /// TSR's write-1 bits: RQCP clears the mailbox's completion flags, ABRQ asks for an abort.
    /// Returns the mailboxes whose abort was newly requested.
    fn write_tsr(&mut self, value: u32) -> u8 {
        let mut aborts = 0;
        for (i, m) in self.tx.iter_mut().enumerate() {
            let byte = value >> (8 * i);
            if byte & bit::rqcp(0) != 0 {
                m.status &= !(bit::rqcp(0) | bit::txok(0) | TSR_ALST | TSR_TERR);
            }
            // Setting ABRQ has no effect on a mailbox that is not pending.
            if byte & bit::abrq(0) != 0 && m.pending() && m.status & bit::abrq(0) == 0 {
                m.status |= bit::abrq(0);
                aborts |= 1 << i;
            }
        }
        aborts
    }

    /// A write to mailbox `i`'s register `r` (byte offset in the mailbox); `true` if it requested
    /// a transmission.
    fn write_mailbox(&mut self, i: usize, r: usize, value: u32) -> bool {
        let requests = self.requests;
        let Some(m) = self.tx.get_mut(i) else {
            return false;
        };
        if m.pending() {
            self.ignored_writes = self.ignored_writes.saturating_add(1);
            return false;
        }
        match r {
            0x0 => {
                m.tir = value;
                if value & bit::TIR_TXRQ != 0 {
                    m.requested = requests;
                    self.requests = requests.wrapping_add(1);
                    return true;
                }
            }
            0x4 => m.tdtr = value & 0xFFFF_810F,
            0x8 => m.tdlr = value,
            _ => m.tdhr = value,
        }
        false
    }

    fn write_rf0r(&mut self, value: u32) {
        if value & RF_FULL != 0 {
            self.fifo_full = false;
        }
        if value & bit::RF_FOVR != 0 {
            self.fifo_overrun = false;
        }
        if value & bit::RF_RFOM != 0 && self.fifo_len > 0 {
            // The next frame moves up (by hand: `rotate_left` takes a buffer on the stack).
            let [first, second, third] = &mut self.fifo;
            *first = *second;
            *second = *third;
            self.fifo_len -= 1;
        }
    }

    fn tsr(&self) -> u32 {
        let mut tsr = 0;
        let (mut pending, mut code, mut last) = (0, None, None);
        for (i, m) in self.tx.iter().enumerate() {
            tsr |= m.status << (8 * i);
            if m.pending() {
                pending += 1;
                // Ties go to the lower number first, so the higher one goes last.
                let key = self.priority(m);
                if last.is_none_or(|(k, _)| key >= k) {
                    last = Some((key, i));
                }
            } else {
                tsr |= bit::TSR_TME0 << i;
                // CODE: the next free mailbox (the lowest numbered).
                code = code.or(Some(i));
            }
        }
        if let Some(free) = code {
            tsr |= (free as u32) << 24;
        }
        // LOW: with more than one pending, the one the controller would offer last.
        if let Some((_, i)) = last.filter(|_| pending > 1) {
            tsr |= 1 << (29 + i);
        }
        tsr
    }

    fn rf0r(&self) -> u32 {
        u32::from(self.fifo_len)
            | if self.fifo_full { RF_FULL } else { 0 }
            | if self.fifo_overrun { bit::RF_FOVR } else { 0 }
    }

    fn esr(&self) -> u32 {
        let warning = self.tec >= 96 || self.rec >= 96;
        let passive = self.tec > 127 || self.rec > 127;
        (u32::from(self.rec) << 24)
            | (u32::from(self.tec) << 16)
            | if self.bus_off { bit::ESR_BOFF } else { 0 }
            | if passive || self.bus_off {
                bit::ESR_EPVF
            } else {
                0
            }
            | if warning || self.bus_off {
                bit::ESR_EWGF
            } else {
                0
            }
    }

    /// The order the controller offers a pending mailbox in (lower first; ties: the lower number).
    fn priority(&self, m: &TxMailbox) -> u32 {
        if self.mcr & bit::MCR_TXFP != 0 {
            // Request order: how long ago, in requests, counted back from the newest.
            u32::MAX - self.requests.wrapping_sub(m.requested)
        } else if m.tir & bit::RIR_IDE == 0 {
            // Identifier order, as the bits go on the wire: the 11 base bits, then RTR (a data
            // frame beats a remote one), then IDE (a standard frame beats an extended one).
            (m.tir & 0xFFE0_0000) | (m.tir & bit::RIR_RTR) << 19
        } else {
            // Extended: the base bits, SRR and IDE recessive, the 18 extension bits, RTR.
            (m.tir & 0xFFE0_0000)
                | (0b11 << 19)
                | (m.tir & 0x001F_FFF8) >> 2
                | (m.tir & bit::RIR_RTR) >> 1
        }
    }
}

/// The model as the driver's tests share it: the driver's halves and the test's bus side each hold a
/// reference. A re-entrant access (none in a test) reads 0 and is not written.
impl super::Registers for &core::cell::RefCell<Model> {
    #[inline(always)]
    fn read(&self, offset: usize) -> u32 {
        self.try_borrow().map_or(0, |m| m.read(offset))
    }

    #[inline(always)]
    fn write(&self, offset: usize, value: u32) {
        if let Ok(mut m) = self.try_borrow_mut() {
            m.write(offset, value);
        }
    }
}
