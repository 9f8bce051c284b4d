//! The bxCAN driver against a register-level model of the controller: set-up, ID-ordered
//! mailboxes with non-blocking displacement, equal-ID order, FIFO reads with DLC and frame-type
//! checks, overruns, and the error-state monitor.
use std::cell::{Cell, RefCell};
use std::collections::VecDeque;

use amiro_can::{CanId, Frame, Kind};
use amiro_firmware::bxcan::{self, BusState, ErrorMonitor, Fifo0, InitError, Mailboxes, Registers};
use amiro_firmware::can::{CanRx, CanTx, Completion, RxEvent, Transmit};

/// The parts of a bxCAN block the driver uses, with the hardware's side effects.
#[derive(Default)]
struct Model {
    mcr: Cell<u32>,
    init_mode: Cell<bool>,
    /// The controller never leaves init mode (bus held dominant).
    stuck_in_init: Cell<bool>,
    /// The controller never enters init mode (no clock).
    dead: Cell<bool>,
    btr: Cell<u32>,
    ier: Cell<u32>,
    esr: Cell<u32>,
    msr_erri: Cell<bool>,
    filters: RefCell<Vec<u32>>,
    /// Per mailbox: (TIR, TDTR, TDLR, TDHR), pending, and completion flags.
    tx: RefCell<[[u32; 4]; 3]>,
    pending: Cell<[bool; 3]>,
    rqcp: Cell<[bool; 3]>,
    txok: Cell<[bool; 3]>,
    abrq: Cell<[bool; 3]>,
    /// Frames the bus delivered: (RIR, RDTR, RDLR, RDHR).
    fifo: RefCell<VecDeque<[u32; 4]>>,
    overrun: Cell<bool>,
    /// Every frame the controller put on the bus, as (id, data).
    sent: RefCell<Vec<(u16, Vec<u8>)>>,
}

impl Model {
    fn tsr(&self) -> u32 {
        let mut v = 0;
        for i in 0..3 {
            if !self.pending.get()[i] {
                v |= 1 << (26 + i);
            }
            if self.rqcp.get()[i] {
                v |= 1 << (8 * i);
            }
            if self.txok.get()[i] {
                v |= 1 << (8 * i + 1);
            }
            if self.abrq.get()[i] {
                v |= 1 << (8 * i + 7);
            }
        }
        v
    }

    /// The bus takes the most urgent pending mailbox (lowest ID) and acknowledges it.
    fn bus_sends_one(&self) -> Option<u16> {
        let tx = self.tx.borrow();
        let i = (0..3)
            .filter(|&i| self.pending.get()[i])
            .min_by_key(|&i| (tx[i][0] >> 21, i))?;
        let id = (tx[i][0] >> 21) as u16;
        let len = (tx[i][1] & 0xF) as usize;
        let mut bytes = tx[i][2].to_le_bytes().to_vec();
        bytes.extend_from_slice(&tx[i][3].to_le_bytes());
        bytes.truncate(len);
        self.sent.borrow_mut().push((id, bytes));
        self.finish(i, true);
        Some(id)
    }

    fn finish(&self, i: usize, ok: bool) {
        let mut p = self.pending.get();
        p[i] = false;
        self.pending.set(p);
        let mut r = self.rqcp.get();
        r[i] = true;
        self.rqcp.set(r);
        let mut t = self.txok.get();
        t[i] = ok;
        self.txok.set(t);
        let mut a = self.abrq.get();
        a[i] = false;
        self.abrq.set(a);
    }

    fn deliver(&self, rir: u32, dlc: u32, data: [u8; 8]) {
        let mut fifo = self.fifo.borrow_mut();
        if fifo.len() == 3 {
            self.overrun.set(true);
            return;
        }
        fifo.push_back([
            rir,
            dlc,
            u32::from_le_bytes([data[0], data[1], data[2], data[3]]),
            u32::from_le_bytes([data[4], data[5], data[6], data[7]]),
        ]);
    }
}

impl Registers for &Model {
    fn read(&self, offset: usize) -> u32 {
        match offset {
            0x000 => self.mcr.get(),
            0x004 => u32::from(self.init_mode.get()) | (u32::from(self.msr_erri.get()) << 2),
            0x008 => self.tsr(),
            0x00C => {
                let fifo = self.fifo.borrow();
                fifo.len() as u32
                    | (u32::from(fifo.len() == 3) << 3)
                    | (u32::from(self.overrun.get()) << 4)
            }
            0x014 => self.ier.get(),
            0x018 => self.esr.get(),
            0x01C => self.btr.get(),
            0x1B0..=0x1BC => self
                .fifo
                .borrow()
                .front()
                .map(|m| m[(offset - 0x1B0) / 4])
                .unwrap_or(0),
            0x200..=0x2FC => self
                .filters
                .borrow()
                .get((offset - 0x200) / 4)
                .copied()
                .unwrap_or(0),
            _ => 0,
        }
    }

    fn write(&self, offset: usize, value: u32) {
        match offset {
            0x000 => {
                self.mcr.set(value & !(1 << 15));
                if value & (1 << 15) != 0 {
                    // Master reset: sleep mode, registers at reset value.
                    self.mcr.set(0x0001_0002);
                    return;
                }
                if self.dead.get() {
                    return;
                }
                if value & 1 != 0 {
                    self.init_mode.set(true);
                } else if !self.stuck_in_init.get() {
                    self.init_mode.set(false);
                }
            }
            0x004 if value & (1 << 2) != 0 => self.msr_erri.set(false),
            0x008 => {
                for i in 0..3 {
                    if value & (1 << (8 * i)) != 0 {
                        let mut r = self.rqcp.get();
                        r[i] = false;
                        self.rqcp.set(r);
                        let mut t = self.txok.get();
                        t[i] = false;
                        self.txok.set(t);
                    }
                    if value & (1 << (8 * i + 7)) != 0 && self.pending.get()[i] {
                        let mut a = self.abrq.get();
                        a[i] = true;
                        self.abrq.set(a);
                    }
                }
            }
            0x00C => {
                if value & (1 << 4) != 0 {
                    self.overrun.set(false);
                }
                if value & (1 << 5) != 0 {
                    self.fifo.borrow_mut().pop_front();
                }
            }
            0x014 => self.ier.set(value),
            0x01C => {
                assert!(self.init_mode.get(), "BTR is writable only in init mode");
                self.btr.set(value)
            }
            0x180..=0x1AC => {
                let i = (offset - 0x180) / 0x10;
                let r = (offset - 0x180) % 0x10 / 4;
                assert!(!self.pending.get()[i], "writing a pending mailbox");
                self.tx.borrow_mut()[i][r] = value;
                if r == 0 && value & 1 != 0 {
                    let mut p = self.pending.get();
                    p[i] = true;
                    self.pending.set(p);
                }
            }
            0x200..=0x2FC => {
                let mut f = self.filters.borrow_mut();
                let i = (offset - 0x200) / 4;
                if f.len() <= i {
                    f.resize(i + 1, 0);
                }
                f[i] = value;
            }
            _ => {}
        }
    }
}

fn frame(id: u16, data: &[u8]) -> Frame {
    let id = CanId::try_from(id).unwrap();
    assert_eq!(id.kind(), Kind::Sensor);
    Frame::new(id, data).unwrap()
}

fn drain_completions(tx: &mut Mailboxes<&Model>) -> Vec<Completion> {
    let mut out = Vec::new();
    tx.completed(&mut |c| out.push(c));
    out
}

#[test]
fn configure_sets_timing_filter_interrupts_and_auto_recovery() {
    let model = Model::default();
    bxcan::configure(&&model, 0x012D_0001).unwrap();
    assert_eq!(model.btr.get(), 0x012D_0001);
    let mcr = model.mcr.get();
    assert_ne!(mcr & (1 << 6), 0, "automatic bus-off management");
    assert_eq!(mcr & (1 << 2), 0, "transmit order by identifier, not FIFO");
    assert_eq!(mcr & (1 << 4), 0, "automatic retransmission");
    assert_eq!(mcr & 0b11, 0, "left init and sleep");
    assert!(!model.init_mode.get());
    let f = model.filters.borrow();
    assert_eq!(f[(0x21C - 0x200) / 4] & 1, 1, "bank 0 active");
    assert_eq!(
        f[(0x244 - 0x200) / 4],
        (0x400 << 21) | 0b110,
        "mask: C/S, IDE, RTR"
    );
    assert_eq!(f[(0x240 - 0x200) / 4], 0);
    // The filter the QEMU robot applies to what it delivers is the one these registers make: a
    // standard data frame passes bank 0 in mask mode when its RIR bits agree with F0R1 wherever
    // F0R2 has a one.
    let (id_bits, mask) = (f[(0x240 - 0x200) / 4], f[(0x244 - 0x200) / 4]);
    for id in 0..0x800u16 {
        let rir = u32::from(id) << 21;
        assert_eq!(
            (rir ^ id_bits) & mask == 0,
            bxcan::passes_filter(id),
            "{id:03X}"
        );
        // The robot host's lookahead reads the same rule off the link (amiro-trace::robot_link).
        assert_eq!(
            amiro_trace::robot_link::reaches_software(id),
            bxcan::passes_filter(id),
            "{id:03X}"
        );
    }
    assert!(bxcan::passes_filter(0x205) && !bxcan::passes_filter(0x610));
    let ier = model.ier.get();
    for (bit, what) in [
        (0, "TMEIE"),
        (1, "FMPIE0"),
        (3, "FOVIE0"),
        (9, "EPVIE"),
        (10, "BOFIE"),
        (15, "ERRIE"),
    ] {
        assert_ne!(ier & (1 << bit), 0, "{what}");
    }
}

#[test]
fn configure_never_waits_for_ever() {
    let dead = Model::default();
    dead.dead.set(true);
    assert_eq!(
        bxcan::configure(&&dead, 1),
        Err(InitError::EnterInitTimeout)
    );
    let stuck = Model::default();
    stuck.stuck_in_init.set(true);
    assert_eq!(
        bxcan::configure(&&stuck, 1),
        Err(InitError::LeaveInitTimeout)
    );
}

#[test]
fn frames_leave_most_urgent_first_and_are_reported_sent() {
    let model = Model::default();
    let mut tx = Mailboxes::new(&model);
    for id in [0x630u16, 0x610, 0x620] {
        assert_eq!(tx.transmit(&frame(id, &[1, 2, 3])), Transmit::Queued);
    }
    assert_eq!(tx.pending(), 3);
    assert_eq!(model.bus_sends_one(), Some(0x610));
    let done = drain_completions(&mut tx);
    assert_eq!(done, vec![Completion::Sent(frame(0x610, &[1, 2, 3]))]);
    assert_eq!(model.sent.borrow()[0], (0x610, vec![1, 2, 3]));
}

#[test]
fn an_urgent_frame_displaces_the_least_urgent_without_waiting() {
    let model = Model::default();
    let mut tx = Mailboxes::new(&model);
    for id in [0x630u16, 0x640, 0x620] {
        tx.transmit(&frame(id, &[0]));
    }
    // Full: the urgent frame asks for an abort of 0x640 and returns at once.
    assert_eq!(tx.transmit(&frame(0x508, &[9])), Transmit::Busy);
    assert!(
        model.abrq.get()[1],
        "abort requested on the least urgent mailbox"
    );
    // A second offer does not request a second abort of a mailbox already aborting.
    assert_eq!(tx.transmit(&frame(0x509, &[9])), Transmit::Busy);
    // The controller completes the abort: the aborted frame comes back for the queue.
    model.finish(1, false);
    assert_eq!(
        drain_completions(&mut tx),
        vec![Completion::Aborted(frame(0x640, &[0]))]
    );
    assert_eq!(tx.transmit(&frame(0x508, &[9])), Transmit::Queued);
    assert_eq!(model.bus_sends_one(), Some(0x508));
}

#[test]
fn a_less_urgent_frame_never_displaces() {
    let model = Model::default();
    let mut tx = Mailboxes::new(&model);
    for id in [0x610u16, 0x611, 0x612] {
        tx.transmit(&frame(id, &[0]));
    }
    assert_eq!(tx.transmit(&frame(0x700, &[0])), Transmit::Busy);
    assert_eq!(model.abrq.get(), [false; 3]);
}

#[test]
fn equal_identifiers_leave_in_queue_order() {
    let model = Model::default();
    let mut tx = Mailboxes::new(&model);
    assert_eq!(tx.transmit(&frame(0x61F, &[0, 1, 2])), Transmit::Queued);
    // The second sample of the same topic must wait: mailboxes with equal IDs go by number.
    assert_eq!(tx.transmit(&frame(0x61F, &[1, 1, 2])), Transmit::Busy);
    model.bus_sends_one();
    drain_completions(&mut tx);
    assert_eq!(tx.transmit(&frame(0x61F, &[1, 1, 2])), Transmit::Queued);
}

#[test]
fn fifo_clamps_long_length_codes_and_marks_foreign_frames() {
    let model = Model::default();
    let mut rx = Fifo0::new(&model);
    assert_eq!(rx.receive(), None);
    model.deliver(0x205 << 21, 15, [1, 2, 3, 4, 5, 6, 7, 8]);
    model.deliver((0x205 << 21) | 0b100, 2, [0; 8]); // extended
    model.deliver((0x205 << 21) | 0b010, 0, [0; 8]); // remote
    match rx.receive() {
        Some(RxEvent::Frame(f)) => {
            assert_eq!(f.id, 0x205);
            assert_eq!(f.payload(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        }
        other => panic!("{other:?}"),
    }
    for _ in 0..2 {
        match rx.receive() {
            Some(RxEvent::Frame(f)) => assert_eq!((f.id, f.len), (u16::MAX, 0)),
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(rx.receive(), None);
}

#[test]
fn an_overrun_is_reported_once_per_event_and_cleared() {
    let model = Model::default();
    let mut rx = Fifo0::new(&model);
    for i in 0..5u8 {
        model.deliver(0x205 << 21, 1, [i, 0, 0, 0, 0, 0, 0, 0]);
    }
    assert_eq!(rx.receive(), Some(RxEvent::Overrun));
    let mut frames = 0;
    while let Some(event) = rx.receive() {
        assert!(matches!(event, RxEvent::Frame(_)));
        frames += 1;
    }
    assert_eq!(frames, 3, "the three frames that fitted are still read");
    assert!(!model.overrun.get());
}

#[test]
fn error_monitor_counts_passive_and_bus_off_episodes() {
    let model = Model::default();
    let mut monitor = ErrorMonitor::new(&model);
    assert_eq!(monitor.poll(), None);
    model.esr.set((100 << 16) | 0b001);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Warning));
    model.esr.set((130 << 16) | 0b011);
    let change = monitor.poll().unwrap();
    assert_eq!(
        (change.from, change.to, change.tec),
        (BusState::Warning, BusState::Passive, 130)
    );
    model.esr.set((255 << 16) | 0b111);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::BusOff));
    // Hardware recovery: back through passive to active; that passive is not a new episode.
    model.esr.set((120 << 16) | 0b011);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Passive));
    model.esr.set(0);
    assert_eq!(monitor.poll().map(|c| c.to), Some(BusState::Active));
    assert_eq!(monitor.passive_episodes(), 1);
    assert_eq!(monitor.bus_off_episodes(), 1);
    model.msr_erri.set(true);
    monitor.poll();
    assert!(
        !model.msr_erri.get(),
        "the status-change interrupt is acknowledged"
    );
}
