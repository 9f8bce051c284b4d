//! The QEMU build's CAN controller: the register-level bxCAN model (`bxcan::model`, the one the
//! driver's tests run) under the robot's own driver. A board's receive path is `bxcan::Fifo0` and
//! its status monitor `bxcan::ErrorMonitor` over [`Controller`] in every QEMU run; in a robot run its
//! transmit path is `bxcan::Mailboxes` over it too (a single-board run prints each frame instead,
//! `qemu::CanTxPort`).
//!
//! The model's bus side is the platform's:
//! - a single-board run's stimulus puts its frames straight into FIFO 0 ([`stimulus_frame`]: the
//!   stimulus is what reached the FIFO, so no filter applies);
//! - in a robot run a mailbox whose TXRQ the driver sets is a frame for the host's arbitration
//!   (handed over at the next exchange, [`report`]), as is an ABRQ; the host's answer completes the
//!   mailbox ([`own_frame_sent`]) or ends its abort ([`aborts_done`]), which sets RQCP/TXOK as the
//!   controller does and raises the transmit interrupt its TMEIE enables; the frames other nodes
//!   send go through the filter bank `bxcan::configure` set into FIFO 0 ([`bus_frame`]), raising
//!   the receive interrupt.
//!
//! The link reports a frame's completion and an abort, not a lost arbitration or an error frame
//! (the bus model retransmits those itself): the model's ALST and TERR stay clear here, which the
//! driver never reads anyway (automatic retransmission is on).
use core::cell::RefCell;
use core::sync::atomic::{AtomicU16, Ordering};

use cortex_m::interrupt::InterruptNumber;
use critical_section::Mutex;

use crate::bxcan::model::{Model, RxRequest};
use crate::bxcan::{self, Mailboxes};
use crate::can::{CanRx, Completion, RxEvent, Transmit};
use amiro_trace::robot_link::{Queued, Up};

use super::robot;

/// The controller: one block, shared by the driver's halves (each in its own task) and the bus
/// side (the exchange, the stimulus replay).
static MODEL: Mutex<RefCell<Model>> = Mutex::new(RefCell::new(Model::new()));

/// The model's registers: each access is one critical section.
#[derive(Debug, Clone, Copy)]
pub struct Controller;

impl bxcan::Registers for Controller {
    #[inline(always)]
    fn read(&self, offset: usize) -> u32 {
        critical_section::with(|cs| MODEL.borrow_ref(cs).read(offset))
    }

    #[inline(always)]
    fn write(&self, offset: usize, value: u32) {
        critical_section::with(|cs| {
            let mut model = MODEL.borrow_ref_mut(cs);
            let written = model.write(offset, value);
            if written.requested != 0 {
                requested(cs, &model, written.requested);
            }
            if written.abort_requested != 0 {
                robot::to_report();
            }
        });
    }
}

/// Sets the controller up as a board's `bxcan::bring_up` does on the chip (the bit timing is the
/// bus model's, so any value does): reset, identifier order, the command filter, the interrupts.
pub(super) fn init() {
    // The model acknowledges every mode request at once: this cannot time out.
    let _ = bxcan::configure(&Controller, 0);
}

/// The robot run's transmit mailboxes: the robot's driver over the model, used by the board's
/// transmit interrupt only (`qemu::CanTxPort`).
static MAILBOXES: Mutex<RefCell<Mailboxes<Controller>>> =
    Mutex::new(RefCell::new(Mailboxes::new(Controller)));

/// Offers `frame` to the mailboxes (robot run).
pub(super) fn transmit(frame: &amiro_can::Frame) -> Transmit {
    remember_tx_interrupt();
    critical_section::with(|cs| {
        use crate::can::CanTx;
        MAILBOXES.borrow_ref_mut(cs).transmit(frame)
    })
}

/// Reports the mailboxes that completed (robot run): the frames sent, and the aborted ones for the
/// queue.
pub(super) fn completed(on_completion: &mut dyn FnMut(Completion)) {
    let mut ended: [Option<Completion>; 3] = [None; 3];
    critical_section::with(|cs| {
        use crate::can::CanTx;
        let mut slots = ended.iter_mut();
        MAILBOXES.borrow_ref_mut(cs).completed(&mut |c| {
            if let Some(slot) = slots.next() {
                *slot = Some(c);
            }
        });
    });
    // Outside the critical section: tracing a sent frame writes to the host.
    for completion in ended.into_iter().flatten() {
        on_completion(completion);
    }
}

/// Takes the next frame or overrun from FIFO 0: the driver's `bxcan::Fifo0` over the model, its
/// register accesses under one critical section (the receive interrupt's cost stays near the
/// chip's: six register accesses, not six critical sections).
pub(super) fn receive() -> Option<RxEvent> {
    critical_section::with(|cs| bxcan::Fifo0::new(MODEL.borrow(cs)).receive())
}

/// A frame of a single-board run's stimulus: into FIFO 0 as it came, and the receive interrupt.
/// `extended`: the stimulus marks a frame the protocol cannot carry.
pub(super) fn stimulus_frame(
    id: u16,
    extended: bool,
    len: u8,
    data: [u8; 8],
    rx_irq: impl InterruptNumber,
) {
    let frame = RxRequest {
        extended: extended || id > 0x7FF,
        ..RxRequest::standard(id, len, data)
    };
    let raise = critical_section::with(|cs| {
        let mut model = MODEL.borrow_ref_mut(cs);
        model.store(&frame);
        model.rx0_interrupt()
    });
    if raise {
        cortex_m::peripheral::NVIC::pend(rx_irq);
    }
}

/// Another node's frame completed on the robot's bus: through the filter into FIFO 0 (an overrun
/// if the board has not emptied it), and the receive interrupt. A frame the filter drops (every
/// sensor frame) costs the board nothing.
pub(super) fn bus_frame(id: u16, len: u8, data: [u8; 8], rx_irq: impl InterruptNumber) {
    let raise = critical_section::with(|cs| {
        let mut model = MODEL.borrow_ref_mut(cs);
        model.receive(&RxRequest::standard(id, len, data)) != bxcan::model::Reception::Filtered
            && model.rx0_interrupt()
    });
    if raise {
        cortex_m::peripheral::NVIC::pend(rx_irq);
    }
}

/// What the host knows of a mailbox's frame in a robot run.
#[derive(Clone, Copy)]
struct Offer {
    /// When its sample was released into the board's transmit queue ([`released`]).
    released_us: u64,
    /// When the driver set its TXRQ.
    queued_us: u64,
    handed_over: bool,
    abort_reported: bool,
}

static OFFERS: Mutex<RefCell<[Option<Offer>; 3]>> = Mutex::new(RefCell::new([None; 3]));

/// The driver set TXRQ on the `mailboxes` (one bit each): note when, and when its frame was
/// released, for the next report.
fn requested(cs: critical_section::CriticalSection<'_>, model: &Model, mailboxes: u8) {
    if !robot::active() {
        return;
    }
    let now = super::now_us();
    let mut offers = OFFERS.borrow_ref_mut(cs);
    for (i, offer) in offers.iter_mut().enumerate() {
        let Some(request) = model.request(i).filter(|_| mailboxes & 1 << i != 0) else {
            continue;
        };
        let key = (
            request.id as u16,
            request.payload().first().copied().unwrap_or(0),
        );
        let released_us = RELEASED.borrow_ref_mut(cs).take(key, now).unwrap_or(now);
        *offer = Some(Offer {
            released_us,
            queued_us: now,
            handed_over: false,
            abort_reported: false,
        });
    }
    robot::to_report();
}

/// Adds to the exchange's report the frames queued since the last one and the aborts asked for.
pub(super) fn report(report: &mut Up) {
    critical_section::with(|cs| {
        let model = MODEL.borrow_ref(cs);
        for (k, slot) in OFFERS.borrow_ref_mut(cs).iter_mut().enumerate() {
            let (Some(offer), Some(request)) = (slot.as_mut(), model.request(k)) else {
                continue;
            };
            if request.abort_requested && !offer.abort_reported {
                offer.abort_reported = true;
                report.aborts |= 1 << k;
            }
            if offer.handed_over {
                continue;
            }
            offer.handed_over = true;
            report.push(Queued {
                released_us: offer.released_us,
                at_us: offer.queued_us,
                id: request.id as u16,
                len: request.dlc,
                mailbox: k as u8,
                data: request.data,
            });
        }
    });
}

/// The host's bus acknowledged the board's frame in `mailbox`: RQCP and TXOK, and the transmit
/// interrupt.
pub(super) fn own_frame_sent(mailbox: u8) {
    let raise = critical_section::with(|cs| {
        let mut model = MODEL.borrow_ref_mut(cs);
        let i = usize::from(mailbox);
        if model.transmitted(i) {
            if let Some(slot) = OFFERS.borrow_ref_mut(cs).get_mut(i) {
                *slot = None;
            }
        }
        model.tx_interrupt()
    });
    if raise {
        pend_tx_interrupt();
    }
}

/// The host took the `aborted` mailboxes' frames (one bit each) off the bus before they started:
/// the controller ends their aborts (RQCP, TXOK clear), and the transmit interrupt hands them back
/// to the queue, where each keeps its release time.
pub(super) fn aborts_done(aborted: u8) {
    let raise = critical_section::with(|cs| {
        let mut model = MODEL.borrow_ref_mut(cs);
        let mut offers = OFFERS.borrow_ref_mut(cs);
        for (i, slot) in offers.iter_mut().enumerate() {
            if aborted & 1 << i == 0 {
                continue;
            }
            let request = model.request(i);
            if let (Some(request), Some(offer), true) = (request, *slot, model.abort(i)) {
                let key = (
                    request.id as u16,
                    request.payload().first().copied().unwrap_or(0),
                );
                RELEASED.borrow_ref_mut(cs).note(key, offer.released_us);
                *slot = None;
            }
        }
        model.tx_interrupt()
    });
    if raise {
        pend_tx_interrupt();
    }
}

/// The transmit interrupt (the exception that called [`transmit`]), `u16::MAX` until known.
static TX_IRQ: AtomicU16 = AtomicU16::new(u16::MAX);

fn remember_tx_interrupt() {
    const ICSR: *const u32 = 0xE000_ED04 as *const u32;
    // SAFETY: reads the number of the active exception (a read-only field of the SCB).
    let active = unsafe { core::ptr::read_volatile(ICSR) } & 0x1FF;
    if let Some(irq) = active.checked_sub(16) {
        TX_IRQ.store(irq as u16, Ordering::Relaxed);
    }
}

/// The interrupt number the transmit path ran in.
#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: the number was read from the NVIC's active exception, so it is a valid interrupt.
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// Pends the transmit interrupt (the exception that last called [`transmit`]), once it is known.
fn pend_tx_interrupt() {
    let irq = TX_IRQ.load(Ordering::Relaxed);
    if irq != u16::MAX {
        cortex_m::peripheral::NVIC::pend(Irq(irq));
    }
}

/// Frames waiting in the board's transmit queue, with the time each was put there: what the host's
/// bus report counts a frame's response from (the analysis's queuing), since the driver hands a
/// mailbox one frame of an identifier at a time. A frame is known by its identifier and first data
/// byte (a multi-frame sample's index byte), and the latest release of that key is its own (the
/// queue keeps only the newest sample of a topic). More entries than the queue holds, overwritten
/// oldest first (a frame the queue replaced or dropped leaves its entry behind); 8 bytes each, in
/// the QEMU build only.
const RELEASES: usize = 32;
static RELEASED: Mutex<RefCell<Releases>> = Mutex::new(RefCell::new(Releases {
    entries: [Release::NONE; RELEASES],
    next: 0,
}));

/// A frame's key: its identifier and first data byte.
type Key = (u16, u8);

#[derive(Clone, Copy)]
struct Release {
    id: u16,
    first: u8,
    /// Virtual µs, the low 32 bits ([`Releases::take`] widens it from now).
    at: u32,
}

impl Release {
    /// No entry (no standard identifier is `u16::MAX`).
    const NONE: Release = Release {
        id: u16::MAX,
        first: 0,
        at: 0,
    };
}

struct Releases {
    entries: [Release; RELEASES],
    next: usize,
}

impl Releases {
    fn note(&mut self, (id, first): Key, at_us: u64) {
        if let Some(slot) = self.entries.get_mut(self.next) {
            *slot = Release {
                id,
                first,
                at: at_us as u32,
            };
        }
        self.next = (self.next + 1) % RELEASES;
    }

    /// The latest release of `key` before `now_us`, taken out; `None` if there is none.
    fn take(&mut self, key: Key, now_us: u64) -> Option<u64> {
        let age = |r: &Release| (now_us as u32).wrapping_sub(r.at);
        let latest = self
            .entries
            .iter_mut()
            .filter(|r| (r.id, r.first) == key)
            .min_by_key(|r| age(r))?;
        let released = now_us.saturating_sub(u64::from(age(latest)));
        *latest = Release::NONE;
        Some(released)
    }
}

/// Notes that `frame` entered the board's transmit queue now (robot mode only).
pub fn released(frame: &amiro_can::Frame) {
    if !robot::active() {
        return;
    }
    let now = super::now_us();
    let key = (frame.id().raw(), frame.data().first().copied().unwrap_or(0));
    critical_section::with(|cs| RELEASED.borrow_ref_mut(cs).note(key, now));
}
