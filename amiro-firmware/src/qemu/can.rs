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
use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicBool, AtomicU16, Ordering};

use cortex_m::interrupt::InterruptNumber;
use critical_section::Mutex;

use crate::bxcan::model::{Model, RxRequest};
use crate::bxcan::{self, Mailboxes};
use crate::can::{CanRx, Completion, RxEvent, Transmit};
use amiro_trace::robot_link::{reaches_software, Done, Queued, Up, MAX_DONE};

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
    /// Under a grant ([`grant`]): the board arbitrates and completes it itself.
    local: Local,
}

/// A mailbox's frame the board completes itself under a grant.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Local {
    /// The host arbitrates it (it is handed over at the next report).
    No,
    /// Waiting for the board's own arbitration.
    Waiting,
    /// Started; it completes at this time (virtual µs), when the board delivers it itself.
    OnBus(u64),
}

/// A grant of the bus from the host (robot run; docs/qemu.md, "Lookahead"): until `free_until`
/// (virtual µs; 0: no grant) no other node can have a frame pending, and the bus is idle from
/// `idle_from` (after the frame in progress, and after each frame the board completes itself).
#[derive(Clone, Copy)]
struct Grant {
    free_until: u64,
    idle_from: u64,
}

/// A grant is in force or a frame is the board's own to complete ([`local_run`] has work): the
/// exchange's every turn skips the board's own arbitration otherwise.
static LOCAL: AtomicBool = AtomicBool::new(false);

static GRANT: Mutex<Cell<Grant>> = Mutex::new(Cell::new(Grant {
    free_until: 0,
    idle_from: 0,
}));

/// A frame the board completed itself since its last report, kept compact (24 bytes: the QEMU
/// build's RAM counts against the boards' goals): times as the low 32 bits of virtual µs, widened
/// from now at the report (a report follows within far less than 2^31 µs).
#[derive(Clone, Copy)]
struct LocalDone {
    id: u16,
    len: u8,
    mailbox: u8,
    data: [u8; 8],
    queued: u32,
    released: u32,
    completed: u32,
}

impl LocalDone {
    const NONE: LocalDone = LocalDone {
        id: 0,
        len: 0,
        mailbox: 0,
        data: [0; 8],
        queued: 0,
        released: 0,
        completed: 0,
    };
}

/// The frames completed under the grant since the last report, in the order they started.
static DONE: Mutex<RefCell<([LocalDone; MAX_DONE], usize)>> =
    Mutex::new(RefCell::new(([LocalDone::NONE; MAX_DONE], 0)));

/// `low`, the low 32 bits of a virtual time within 2^31 µs of `now`, widened.
fn widen(low: u32, now: u64) -> u64 {
    now.wrapping_add_signed(i64::from(low.wrapping_sub(now as u32) as i32))
}

/// The host granted the bus until `free_until` (the board's virtual µs), idle from `idle_from`;
/// `held`: the mailboxes whose frames the host's bus model still holds (the board cannot
/// arbitrate against those, so it takes no grant then).
pub(super) fn grant(free_until: u64, idle_from: u64, held: u8) {
    let free_until = if held != 0 { 0 } else { free_until };
    if free_until > 0 {
        LOCAL.store(true, Ordering::Relaxed);
    }
    critical_section::with(|cs| {
        GRANT.borrow(cs).set(Grant {
            free_until,
            idle_from,
        })
    });
}

/// Something the host must hear of happened at `now` (`robot::to_report`): frames starting from
/// here on are the host's to arbitrate again (a command frame queued now would take part).
pub(super) fn close_grant(now: u64) {
    critical_section::with(|cs| {
        let g = GRANT.borrow(cs);
        let mut grant = g.get();
        grant.free_until = grant.free_until.min(now);
        g.set(grant);
    });
}

/// The board's own arbitration under a grant, at `now`: delivers each frame it completed itself
/// whose completion has come (the mailbox completes, the transmit interrupt), and decides every
/// start before `now` exactly as the host's bus model (`amiro_bus_sim::Bus::run_until`) would: the
/// start is the earliest queueing time or the idle bus, whichever is later; the lowest identifier
/// among the frames queued by then wins (the lower mailbox on a tie); it completes after
/// `amiro_can::timing::frame_bits`, and the bus is idle again after the intermission. A start at or
/// after the grant's end, or with the record full, ends the grant: those frames go to the host at
/// the next report (`robot::to_report`). Returns when it next needs to run (`u64::MAX`: nothing
/// local is pending).
pub(super) fn local_run(now: u64) -> u64 {
    if !LOCAL.load(Ordering::Relaxed) {
        return u64::MAX;
    }
    let mut delivered = false;
    let mut report = false;
    let next = critical_section::with(|cs| {
        let mut model = MODEL.borrow_ref_mut(cs);
        let mut offers = OFFERS.borrow_ref_mut(cs);
        for (i, slot) in offers.iter_mut().enumerate() {
            if let Some(Offer {
                local: Local::OnBus(end),
                ..
            }) = *slot
            {
                if end <= now {
                    model.transmitted(i);
                    *slot = None;
                    delivered = true;
                }
            }
        }
        let cell = GRANT.borrow(cs);
        let mut grant = cell.get();
        let mut guard = DONE.borrow_ref_mut(cs);
        let (records, count) = &mut *guard;
        loop {
            let waiting = offers
                .iter()
                .flatten()
                .filter(|o| o.local == Local::Waiting)
                .map(|o| o.queued_us)
                .min();
            let Some(first) = waiting else { break };
            let start = first.max(grant.idle_from);
            if start >= grant.free_until || *count >= MAX_DONE {
                // The host arbitrates these: handed over at the next report.
                for o in offers.iter_mut().flatten() {
                    if o.local == Local::Waiting {
                        o.local = Local::No;
                        o.handed_over = false;
                    }
                }
                grant.free_until = 0;
                report = true;
                break;
            }
            if now <= start {
                // Frames queued up to `start` still take part: decided once it has passed.
                break;
            }
            let winner = offers
                .iter()
                .enumerate()
                .filter_map(|(k, o)| o.map(|o| (k, o)))
                .filter(|(_, o)| o.local == Local::Waiting && o.queued_us <= start)
                .filter_map(|(k, o)| model.request(k).map(|r| (r.id as u16, k, o, r)))
                .min_by_key(|&(id, k, ..)| (id, k));
            let Some((id, k, offer, request)) = winner else {
                break;
            };
            let len = request.dlc.min(8);
            let end = start
                + u64::from(amiro_can::timing::frame_bits(
                    id,
                    &request.data[..usize::from(len)],
                ));
            grant.idle_from = end + u64::from(amiro_can::timing::INTERMISSION_BITS);
            if let Some(record) = records.get_mut(*count) {
                *record = LocalDone {
                    id,
                    len,
                    mailbox: k as u8,
                    data: request.data,
                    queued: offer.queued_us as u32,
                    released: offer.released_us as u32,
                    completed: end as u32,
                };
            }
            *count += 1;
            if let Some(o) = offers[k].as_mut() {
                o.local = Local::OnBus(end);
            }
        }
        cell.set(grant);
        let decide = offers
            .iter()
            .flatten()
            .filter(|o| o.local == Local::Waiting)
            .map(|o| o.queued_us.max(grant.idle_from) + 1)
            .min();
        let complete = offers
            .iter()
            .flatten()
            .filter_map(|o| match o.local {
                Local::OnBus(end) => Some(end),
                _ => None,
            })
            .min();
        // Nothing local left, no grant, no record to report: the exchange skips this until the
        // next grant.
        if decide.is_none() && complete.is_none() && grant.free_until == 0 && *count == 0 {
            LOCAL.store(false, Ordering::Relaxed);
        }
        decide.into_iter().chain(complete).min().unwrap_or(u64::MAX)
    });
    if delivered && critical_section::with(|cs| MODEL.borrow_ref(cs).tx_interrupt()) {
        pend_tx_interrupt();
    }
    if report {
        robot::to_report();
    }
    next
}

static OFFERS: Mutex<RefCell<[Option<Offer>; 3]>> = Mutex::new(RefCell::new([None; 3]));

/// The driver set TXRQ on the `mailboxes` (one bit each): note when, and when its frame was
/// released, for the next report.
fn requested(cs: critical_section::CriticalSection<'_>, model: &Model, mailboxes: u8) {
    if !robot::active() {
        return;
    }
    let now = super::now_us();
    let granted = GRANT.borrow(cs).get().free_until > now;
    let (mut host, mut local) = (false, false);
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
        // Under a grant a sensor frame (no board's software hears it) is the board's own to
        // arbitrate and complete; anything else goes to the host at the next boundary.
        let mine =
            granted && !request.extended && !request.remote && !reaches_software(request.id as u16);
        *offer = Some(Offer {
            released_us,
            queued_us: now,
            handed_over: mine,
            abort_reported: false,
            local: if mine { Local::Waiting } else { Local::No },
        });
        host |= !mine;
        local |= mine;
    }
    if host {
        robot::to_report();
    } else if local {
        robot::poke();
    }
}

/// Adds to the exchange's report the frames queued since the last one and the aborts asked for,
/// and the number of frames the board completed itself under the grant since the last report
/// (`report.done`; [`take_done`] writes them). The grant ends here (the answer may give a new one);
/// frames still waiting for the board's own arbitration go to the host with the others.
pub(super) fn report(report: &mut Up) {
    if LOCAL.load(Ordering::Relaxed) {
        local_run(report.now_us);
        critical_section::with(|cs| {
            GRANT.borrow(cs).set(Grant {
                free_until: 0,
                idle_from: 0,
            });
            report.done = DONE.borrow_ref(cs).1.min(MAX_DONE) as u8;
        });
    }
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
            if offer.local == Local::Waiting {
                offer.local = Local::No;
                offer.handed_over = false;
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

/// Writes the frames the board completed itself since the last report into `out` (the
/// [`Done`] records that follow the report, `DONE_LEN` bytes each, in the order they started) and
/// forgets them; `now` widens their times. Returns the bytes written.
pub(super) fn take_done(out: &mut [u8], now: u64) -> usize {
    use amiro_trace::robot_link::DONE_LEN;
    critical_section::with(|cs| {
        let mut local = DONE.borrow_ref_mut(cs);
        let count = local.1.min(MAX_DONE);
        let mut written = 0;
        for (d, chunk) in local.0[..count].iter().zip(out.chunks_exact_mut(DONE_LEN)) {
            let record = Done {
                frame: Queued {
                    at_us: widen(d.queued, now),
                    released_us: widen(d.released, now),
                    id: d.id,
                    len: d.len,
                    mailbox: d.mailbox,
                    data: d.data,
                },
                completed_us: widen(d.completed, now),
            };
            chunk.copy_from_slice(&record.encode());
            written += DONE_LEN;
        }
        local.1 = 0;
        written
    })
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
