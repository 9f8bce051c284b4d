//! The register-level bxCAN driver for every AMiRo board: set-up, ID-ordered transmit mailboxes with
//! non-blocking displacement, receive FIFO 0 with DLC checks, and the error/bus-off monitor.
//!
//! The STM32F103 and the STM32F405 carry the same bxCAN IP at the same address (CAN1 at
//! `0x4000_6400`) with the same register map, so this is one driver over a [`Registers`] accessor:
//! [`Mmio`] on the chips, the register-level [`model`] in the tests and the QEMU build. Nothing here
//! depends on a HAL.
//!
//! Why not the `bxcan` crate: its receive path panics on a frame whose length code is 9–15 (legal
//! on the wire, it means 8 bytes) and its transmit displacement busy-waits for the abort (up to a
//! frame time inside an interrupt). See `docs/boards.md`.

use crate::can::{CanRx, CanTx, Completion, RxEvent, RxFrame, Transmit};

#[cfg(any(not(target_os = "none"), feature = "qemu"))]
pub mod model;

/// CAN1's base address on both chips.
pub const CAN1_BASE: usize = 0x4000_6400;

/// Register offsets (RM0008 §24.9, RM0090 §32.9: identical).
mod reg {
    pub const MCR: usize = 0x000;
    pub const MSR: usize = 0x004;
    pub const TSR: usize = 0x008;
    pub const RF0R: usize = 0x00C;
    pub const IER: usize = 0x014;
    pub const ESR: usize = 0x018;
    pub const BTR: usize = 0x01C;
    pub const fn tir(i: usize) -> usize {
        0x180 + 0x10 * i
    }
    pub const fn tdtr(i: usize) -> usize {
        0x184 + 0x10 * i
    }
    pub const fn tdlr(i: usize) -> usize {
        0x188 + 0x10 * i
    }
    pub const fn tdhr(i: usize) -> usize {
        0x18C + 0x10 * i
    }
    pub const RI0R: usize = 0x1B0;
    pub const RDT0R: usize = 0x1B4;
    pub const RDL0R: usize = 0x1B8;
    pub const RDH0R: usize = 0x1BC;
    pub const FMR: usize = 0x200;
    pub const FM1R: usize = 0x204;
    pub const FS1R: usize = 0x20C;
    pub const FFA1R: usize = 0x214;
    pub const FA1R: usize = 0x21C;
    pub const F0R1: usize = 0x240;
    pub const F0R2: usize = 0x244;
}

/// Register bits used here.
mod bit {
    pub const MCR_INRQ: u32 = 1 << 0;
    pub const MCR_SLEEP: u32 = 1 << 1;
    pub const MCR_TXFP: u32 = 1 << 2;
    pub const MCR_NART: u32 = 1 << 4;
    pub const MCR_AWUM: u32 = 1 << 5;
    pub const MCR_ABOM: u32 = 1 << 6;
    pub const MCR_RESET: u32 = 1 << 15;
    pub const MSR_INAK: u32 = 1 << 0;
    pub const MSR_ERRI: u32 = 1 << 2;
    pub const TSR_TME0: u32 = 1 << 26;
    pub const fn rqcp(i: usize) -> u32 {
        1 << (8 * i)
    }
    pub const fn txok(i: usize) -> u32 {
        1 << (8 * i + 1)
    }
    pub const fn abrq(i: usize) -> u32 {
        1 << (8 * i + 7)
    }
    pub const RF_FMP: u32 = 0b11;
    pub const RF_FOVR: u32 = 1 << 4;
    pub const RF_RFOM: u32 = 1 << 5;
    pub const IER_TMEIE: u32 = 1 << 0;
    pub const IER_FMPIE0: u32 = 1 << 1;
    pub const IER_FOVIE0: u32 = 1 << 3;
    pub const IER_EWGIE: u32 = 1 << 8;
    pub const IER_EPVIE: u32 = 1 << 9;
    pub const IER_BOFIE: u32 = 1 << 10;
    pub const IER_ERRIE: u32 = 1 << 15;
    pub const ESR_EWGF: u32 = 1 << 0;
    pub const ESR_EPVF: u32 = 1 << 1;
    pub const ESR_BOFF: u32 = 1 << 2;
    pub const RIR_IDE: u32 = 1 << 2;
    pub const RIR_RTR: u32 = 1 << 1;
    pub const TIR_TXRQ: u32 = 1 << 0;
    pub const FMR_FINIT: u32 = 1 << 0;
}

/// Access to one bxCAN block's 32-bit registers by byte offset.
pub trait Registers {
    /// Reads the register at `offset`.
    fn read(&self, offset: usize) -> u32;
    /// Writes the register at `offset`.
    fn write(&self, offset: usize, value: u32);
}

/// The memory-mapped registers of a bxCAN block.
#[derive(Debug, Clone, Copy)]
pub struct Mmio {
    base: usize,
}

impl Mmio {
    /// The block at `base`.
    ///
    /// # Safety
    /// `base` must be the address of a bxCAN block, and the caller must make sure that the halves
    /// built on it ([`Mailboxes`], [`Fifo0`], [`ErrorMonitor`]) are each owned by one task: they
    /// touch disjoint registers (TSR and the transmit mailboxes; RF0R and the FIFO mailbox; ESR and
    /// MSR.ERRI).
    pub const unsafe fn new(base: usize) -> Self {
        Self { base }
    }
}

impl Registers for Mmio {
    fn read(&self, offset: usize) -> u32 {
        // SAFETY: `new`'s contract: `base + offset` is a register of the block.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    fn write(&self, offset: usize, value: u32) {
        // SAFETY: as in `read`.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, value) }
    }
}

/// Why the controller could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitError {
    /// The controller did not acknowledge initialisation mode (no clock to the block?).
    EnterInitTimeout,
    /// The controller did not leave initialisation mode. It joins the bus once it has seen 11
    /// recessive bits, so this means the bus is held dominant (or CAN_RX is not connected): the
    /// controller stays configured and joins when the bus frees.
    LeaveInitTimeout,
}

impl InitError {
    /// The error in words, for the log.
    pub const fn as_str(self) -> &'static str {
        match self {
            InitError::EnterInitTimeout => "the controller did not enter initialisation mode",
            InitError::LeaveInitTimeout => {
                "the controller did not leave initialisation mode (bus held dominant?); it joins when the bus frees"
            }
        }
    }
}

/// The identifier bits filter bank 0 compares (the C/S bit): a frame passes when they are clear.
pub const COMMAND_FILTER_MASK: u16 = 0x400;

/// Whether the receive filter [`configure`] sets up passes a standard data frame with identifier
/// `id` to FIFO 0: command frames only; sensor frames, the other boards' and its own, never reach
/// the software.
pub const fn passes_filter(id: u16) -> bool {
    id & COMMAND_FILTER_MASK == 0
}

/// How often set-up polls a mode flag before giving up (each poll is one register read).
pub const INIT_POLLS: u32 = 100_000;

/// Resets and configures the controller: bit timing `btr`, automatic bus-off recovery, automatic
/// retransmission, transmit order by identifier (not FIFO: the analysis assumes the most urgent
/// pending frame is offered first), and one filter that passes only command frames (standard
/// data frames with the C/S bit clear) into FIFO 0; then enables the transmit, receive, overrun and
/// error interrupts and leaves initialisation mode. Never waits without bound.
pub fn configure(regs: &impl Registers, btr: u32) -> Result<(), InitError> {
    // A software master reset leaves the block in sleep mode with every register at reset value
    // (whatever AMiRo-BLT configured, mailboxes included, is gone).
    regs.write(reg::MCR, bit::MCR_RESET);
    regs.write(reg::MCR, bit::MCR_INRQ);
    wait_for(|| regs.read(reg::MSR) & bit::MSR_INAK != 0).ok_or(InitError::EnterInitTimeout)?;
    regs.write(
        reg::MCR,
        (bit::MCR_INRQ | bit::MCR_ABOM | bit::MCR_AWUM)
            & !(bit::MCR_SLEEP | bit::MCR_TXFP | bit::MCR_NART),
    );
    regs.write(reg::BTR, btr);
    // Filter bank 0: 32-bit mask mode into FIFO 0. Match: standard ID with bit 10 (C/S) clear,
    // IDE clear, RTR clear.
    let fmr = regs.read(reg::FMR);
    regs.write(reg::FMR, fmr | bit::FMR_FINIT);
    regs.write(reg::FA1R, regs.read(reg::FA1R) & !1);
    regs.write(reg::FS1R, regs.read(reg::FS1R) | 1);
    regs.write(reg::FM1R, regs.read(reg::FM1R) & !1);
    regs.write(reg::FFA1R, regs.read(reg::FFA1R) & !1);
    regs.write(reg::F0R1, 0);
    regs.write(
        reg::F0R2,
        (u32::from(COMMAND_FILTER_MASK) << 21) | bit::RIR_IDE | bit::RIR_RTR,
    );
    regs.write(reg::FA1R, regs.read(reg::FA1R) | 1);
    regs.write(reg::FMR, regs.read(reg::FMR) & !bit::FMR_FINIT);
    regs.write(
        reg::IER,
        bit::IER_TMEIE
            | bit::IER_FMPIE0
            | bit::IER_FOVIE0
            | bit::IER_EWGIE
            | bit::IER_EPVIE
            | bit::IER_BOFIE
            | bit::IER_ERRIE,
    );
    regs.write(reg::MCR, regs.read(reg::MCR) & !bit::MCR_INRQ);
    wait_for(|| regs.read(reg::MSR) & bit::MSR_INAK == 0).ok_or(InitError::LeaveInitTimeout)
}

/// CAN1's three halves, each owned by one task: the transmit mailboxes, receive FIFO 0, and the
/// error monitor.
pub struct Port {
    /// Transmit mailboxes (the CAN transmit interrupt).
    pub tx: Mailboxes<Mmio>,
    /// Receive FIFO 0 (the CAN receive interrupt).
    pub rx: Fifo0<Mmio>,
    /// Error state (the status-change interrupt, and a periodic poll).
    pub errors: ErrorMonitor<Mmio>,
}

/// Configures CAN1 (clock on and reset: `chip::reset_and_enable_can1`) with bit timing `btr` and
/// hands out its halves. A set-up that times out is logged: the controller stays configured and
/// joins the bus once it frees.
#[cfg(target_os = "none")]
pub fn bring_up(btr: u32) -> Port {
    // SAFETY: CAN1 exists at this address on both chips; each half built on it is owned by one task
    // (`Port`'s contract) and touches its own registers.
    let can = unsafe { Mmio::new(CAN1_BASE) };
    match configure(&can, btr) {
        Ok(()) => crate::log!("CAN: on the bus"),
        Err(InitError::EnterInitTimeout) => {
            crate::log!("CAN: silent: ", InitError::EnterInitTimeout.as_str())
        }
        Err(e) => crate::log!("CAN: ", e.as_str()),
    }
    Port {
        tx: Mailboxes::new(can),
        rx: Fifo0::new(can),
        errors: ErrorMonitor::new(can),
    }
}

/// Silences the controller's interrupts (before the hand-over to the bootloader).
pub fn disable_interrupts(regs: &impl Registers) {
    regs.write(reg::IER, 0);
}

fn wait_for(mut done: impl FnMut() -> bool) -> Option<()> {
    (0..INIT_POLLS).any(|_| done()).then_some(())
}

/// The three transmit mailboxes.
///
/// A more urgent frame requests the abort of the least urgent pending one and returns at once;
/// the mailbox's completion (RQCP with TXOK clear) hands the aborted frame back from `shadow`.
/// Frames with equal identifiers leave in queue order: a second one waits until the first is gone.
/// A mailbox is reused only once [`CanTx::completed`] has collected its completion: the controller
/// may empty it between that call and [`CanTx::transmit`] (the interrupt that frees a mailbox
/// comes at any time), and a frame written there before its completion is read would be reported
/// as the old one's.
pub struct Mailboxes<R> {
    regs: R,
    shadow: [Option<amiro_can::Frame>; 3],
}

impl<R: Registers> Mailboxes<R> {
    /// The mailboxes of a configured controller.
    pub const fn new(regs: R) -> Self {
        Self {
            regs,
            shadow: [None; 3],
        }
    }

    /// Frames currently in a mailbox.
    pub fn pending(&self) -> usize {
        self.shadow.iter().filter(|s| s.is_some()).count()
    }
}

// `R: Copy` (every accessor is: an address, a reference to the model, QEMU's unit `Controller`): each
// call takes its own copy, so the block's address stays in a register; read through `self`, it was
// loaded again before every register write, as a volatile write might have changed it.
impl<R: Registers + Copy> CanTx for Mailboxes<R> {
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit {
        let regs = self.regs;
        // Straight-line code over the three mailboxes, no loop: each pass of a loop costs the
        // transmit interrupt a taken branch, a pipeline refill and a flash line on the chip, three
        // loops of three passes (the same-identifier check, the free mailbox, the least urgent)
        // more than the rest of the call (docs/analysis.md, "The transmit interrupt's parts").
        let tsr = regs.read(reg::TSR);
        // Bit i: mailbox i is empty (TMEi), and mailbox i's completion is collected (its shadow
        // holds no frame).
        let empty = (tsr / bit::TSR_TME0) & 0b111;
        let [s0, s1, s2] = &self.shadow;
        let collected =
            u32::from(s0.is_none()) | u32::from(s1.is_none()) << 1 | u32::from(s2.is_none()) << 2;
        // A pending mailbox's identifier plus one, 0 for one that is empty or holds no frame (one
        // whose completion is not collected holds none): plain words, so the checks below are
        // compares, not matches on options.
        let held = |shadow: &Option<amiro_can::Frame>, i: u32| match shadow {
            Some(held) if empty & (1 << i) == 0 => u32::from(held.id().raw()) + 1,
            _ => 0,
        };
        let (h0, h1, h2) = (held(s0, 0), held(s1, 1), held(s2, 2));
        let key = u32::from(frame.id().raw()) + 1;
        if h0 == key || h1 == key || h2 == key {
            return Transmit::Busy;
        }
        let free = empty & collected;
        if free != 0 {
            // The lowest-numbered free mailbox.
            let free = free.trailing_zeros() as usize;
            // All 8 bytes, a copy of fixed size (no `memcpy` of a run-time length): the controller
            // sends as many of them as the DLC written to TDTxR says.
            let data = frame.data_buffer();
            regs.write(reg::tdtr(free), u32::from(frame.dlc()));
            regs.write(
                reg::tdlr(free),
                u32::from_le_bytes([data[0], data[1], data[2], data[3]]),
            );
            regs.write(
                reg::tdhr(free),
                u32::from_le_bytes([data[4], data[5], data[6], data[7]]),
            );
            // TXRQ last hands the mailbox to the controller.
            regs.write(
                reg::tir(free),
                (u32::from(frame.id().raw()) << 21) | bit::TIR_TXRQ,
            );
            if let Some(slot) = self.shadow.get_mut(free) {
                *slot = Some(*frame);
            }
            return Transmit::Queued;
        }
        // All three taken: abort the least urgent pending one if this frame beats it, without
        // waiting (the greatest identifier, the later mailbox among equals). None while an abort is
        // under way for it, nor while a mailbox is empty with its completion uncollected (`empty`
        // is not 0 here, as no mailbox is free): that completion pends the interrupt, whose next
        // job frees the mailbox, so no frame asks for a second abort behind one that ended unseen
        // (docs/analysis.md, "Refinements examined").
        // Two compares, no loop: the greatest held key, the later mailbox among equals (a key of 0,
        // no frame pending, is below every frame's).
        let (i, least) = if h2 >= h1 && h2 >= h0 {
            (2, h2)
        } else if h1 >= h0 {
            (1, h1)
        } else {
            (0, h0)
        };
        if key < least && tsr & bit::abrq(i) == 0 && empty == 0 {
            // Setting ABRQ; the other TSR bits are write-1-to-clear flags, written as 0.
            regs.write(reg::TSR, bit::abrq(i));
        }
        Transmit::Busy
    }

    fn completed(&mut self, on_completion: &mut dyn FnMut(Completion)) {
        let regs = self.regs;
        let tsr = regs.read(reg::TSR);
        // One write clears the completion flags (RQCP, and with it TXOK, ALST, TERR) of every
        // mailbox whose completion this read found, and only those (a completion after the read
        // stays set, its interrupt pending); ABRQ and the read-only bits are written as 0. The
        // flags read stay in `tsr` for the scan, which only reads the shadows.
        regs.write(reg::TSR, tsr & (bit::rqcp(0) | bit::rqcp(1) | bit::rqcp(2)));
        for i in 0..3 {
            if tsr & bit::rqcp(i) == 0 {
                continue;
            }
            // A completion with no frame in the shadow (none was handed over) writes nothing.
            let Some(shadow) = self.shadow.get_mut(i) else {
                continue;
            };
            let Some(frame) = *shadow else {
                continue;
            };
            *shadow = None;
            // With automatic retransmission on, a completion without TXOK is an abort.
            if tsr & bit::txok(i) != 0 {
                on_completion(Completion::Sent(frame));
            } else {
                on_completion(Completion::Aborted(frame));
            }
        }
    }
}

/// Receive FIFO 0, read at register level (length codes 9–15 clamp to 8 bytes; extended and remote
/// frames come out with `id == u16::MAX` for the handler to reject).
pub struct Fifo0<R> {
    regs: R,
}

impl<R: Registers> Fifo0<R> {
    /// FIFO 0 of a configured controller.
    pub const fn new(regs: R) -> Self {
        Self { regs }
    }
}

impl<R: Registers> CanRx for Fifo0<R> {
    fn receive(&mut self) -> Option<RxEvent> {
        let rf0r = self.regs.read(reg::RF0R);
        if rf0r & bit::RF_FOVR != 0 {
            // Frames were lost because the FIFO was full: acknowledge and report it.
            self.regs.write(reg::RF0R, bit::RF_FOVR);
            return Some(RxEvent::Overrun);
        }
        if rf0r & bit::RF_FMP == 0 {
            return None;
        }
        let rir = self.regs.read(reg::RI0R);
        let dlc = (self.regs.read(reg::RDT0R) & 0x0F).min(8);
        let low = self.regs.read(reg::RDL0R);
        let high = self.regs.read(reg::RDH0R);
        // Release the mailbox (RFOM0) so the next frame moves up.
        self.regs.write(reg::RF0R, bit::RF_RFOM);
        // An extended or remote frame comes out as `id == u16::MAX`, no length, no data: masked,
        // not branched (a taken branch costs the interrupt a pipeline refill and a flash line on
        // every frame, docs/analysis.md "The cycle model").
        let keep = 0u32.wrapping_sub(u32::from(rir & (bit::RIR_IDE | bit::RIR_RTR) == 0));
        let [d0, d1, d2, d3] = (low & keep).to_le_bytes();
        let [d4, d5, d6, d7] = (high & keep).to_le_bytes();
        let frame = RxFrame {
            id: ((rir >> 21) & 0x7FF | !keep) as u16,
            len: (dlc & keep) as u8,
            data: [d0, d1, d2, d3, d4, d5, d6, d7],
        };
        Some(RxEvent::Frame(frame))
    }
}

/// The controller's error state, as the fault confinement rules define it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusState {
    /// Both error counters below 96.
    Active,
    /// An error counter reached the warning limit (96).
    Warning,
    /// An error counter passed 127: the controller may not signal errors actively.
    Passive,
    /// The transmit error counter passed 255: the controller is off the bus until it has seen
    /// 128 × 11 recessive bits (automatic bus-off management is on).
    BusOff,
}

/// A change of [`BusState`] with the error counters at that moment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusStateChange {
    /// The state before.
    pub from: BusState,
    /// The state now.
    pub to: BusState,
    /// Transmit error counter.
    pub tec: u8,
    /// Receive error counter.
    pub rec: u8,
}

/// Counts error-passive and bus-off episodes (status-change interrupt and periodic poll).
pub struct ErrorMonitor<R> {
    regs: R,
    state: BusState,
    passive_episodes: u32,
    bus_off_episodes: u32,
}

impl<R: Registers> ErrorMonitor<R> {
    /// The monitor of a configured controller (starting error-active).
    pub const fn new(regs: R) -> Self {
        Self {
            regs,
            state: BusState::Active,
            passive_episodes: 0,
            bus_off_episodes: 0,
        }
    }

    /// Reads the error state, acknowledges the status-change interrupt, and reports a change.
    /// Recovery from bus-off is the hardware's (automatic bus-off management, set in
    /// [`configure`]); this only observes and counts.
    pub fn poll(&mut self) -> Option<BusStateChange> {
        self.regs.write(reg::MSR, bit::MSR_ERRI);
        let esr = self.regs.read(reg::ESR);
        let now = if esr & bit::ESR_BOFF != 0 {
            BusState::BusOff
        } else if esr & bit::ESR_EPVF != 0 {
            BusState::Passive
        } else if esr & bit::ESR_EWGF != 0 {
            BusState::Warning
        } else {
            BusState::Active
        };
        if now == self.state {
            return None;
        }
        match now {
            BusState::BusOff => self.bus_off_episodes = self.bus_off_episodes.saturating_add(1),
            BusState::Passive if self.state != BusState::BusOff => {
                self.passive_episodes = self.passive_episodes.saturating_add(1)
            }
            _ => {}
        }
        let change = BusStateChange {
            from: self.state,
            to: now,
            tec: (esr >> 16) as u8,
            rec: (esr >> 24) as u8,
        };
        self.state = now;
        Some(change)
    }

    /// The state at the last poll.
    pub fn state(&self) -> BusState {
        self.state
    }

    /// Times the controller became error-passive (not counting the passage through error-passive on
    /// the way back from bus-off).
    pub fn passive_episodes(&self) -> u32 {
        self.passive_episodes
    }

    /// Times the controller went bus-off.
    pub fn bus_off_episodes(&self) -> u32 {
        self.bus_off_episodes
    }
}
