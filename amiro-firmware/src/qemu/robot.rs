//! The robot mode of the QEMU platform: this board as one of three on a simulated bus that
//! `cargo xtask robot` runs (docs/qemu.md, "The whole robot").
//!
//! When the run's work directory holds the named pipes `robot-down` and `robot-up`, the board
//! trades with the host's bus model every [`QUANTUM_US`] of its virtual time instead of replaying
//! a stimulus: it hands over the frames it put into its three mailboxes since the last exchange
//! (with the time it queued them) and what it drives on the system lines, and gets back the one
//! frame, if any, that completes on the bus in the coming quantum (a frame needs at least 44 bit
//! times, so no two complete within 40 µs; the board's own frame, which the host may answer when it
//! starts, possibly later: the board keeps it until its time) and the levels of SYS_SYNC_N and
//! SYS_PD_N. The read
//! blocks, and a blocked QEMU's virtual clock stands still, so no board runs ahead of the others.
//!
//! The mailboxes, the receive FIFO and the filter are the bxCAN model's under the robot's driver
//! (`qemu::can`): the exchange hands the model's requests to the host and its answers back to the
//! model. A frame is delivered at its completion time: another node's through the filter into FIFO
//! 0 (command frames only, as on the robot), the board's own as a completed mailbox and a
//! transmit-complete interrupt.
use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};

use cortex_m::interrupt::InterruptNumber;
use critical_section::Mutex;

use super::{HostFile, TICK_US};

pub use amiro_trace::robot_link::QUANTUM_US;
use amiro_trace::robot_link::{
    Down, Up, DONE_LEN, DOWN_EARLY, DOWN_END, DOWN_FRAME, DOWN_LEN, DOWN_OWN, DOWN_PD_LOW,
    DOWN_READINGS, DOWN_RESTART, DOWN_SYNC_LOW, DRIVES_PD_LOW, DRIVES_SYNC_LOW, MAX_DONE, UP_LEN,
    UP_WHEELS,
};
pub use amiro_trace::world_link;
use world_link::{Readings, Wheels, READINGS_LEN};

const NO_FILE: usize = usize::MAX;
static DOWN: AtomicUsize = AtomicUsize::new(NO_FILE);
static UP: AtomicUsize = AtomicUsize::new(NO_FILE);
/// The lines this board drives (a module holds SYS_SYNC_N low until it is initialised).
static DRIVES: AtomicU8 = AtomicU8::new(DRIVES_SYNC_LOW);
static SYNC_READS_LOW: AtomicBool = AtomicBool::new(true);

/// Opens the pipes to the host's bus if this run has them (`init` calls it); `true` in robot mode.
pub(super) fn connect() -> bool {
    // A FIFO the host holds open opens at once; without `robot-down` this is a single-board run.
    let Some(down) = HostFile::open(b"robot-down\0") else {
        return false;
    };
    let Some(up) = HostFile::create(b"robot-up\0") else {
        return false;
    };
    DOWN.store(down.0, Ordering::Relaxed);
    UP.store(up.0, Ordering::Relaxed);
    // The host's exchange says when the board next trades: no tick needed in between.
    super::timer::set_tickless();
    true
}

/// The board's wheels: whole ticks (left, right) at the given virtual µs.
type WheelTicks = fn(u64) -> (i64, i64);
/// The board's wheels in a run with a world ([`report_wheels`]).
static WHEELS: Mutex<Cell<Option<WheelTicks>>> = Mutex::new(Cell::new(None));
/// The world's latest readings for this board (`None` without a world, or before the first).
static READINGS: Mutex<Cell<Option<Readings>>> = Mutex::new(Cell::new(None));
/// Whether the host runs a world (it sent readings once): only then the wheels go up, so a run
/// without a world trades not a byte more.
static WORLD: AtomicBool = AtomicBool::new(false);

/// Registers the board's wheel ticks (the DiWheelDrive's plant), reported at every exchange of
/// a run with a world (docs/world.md, "How the readings reach the boards").
pub fn report_wheels(ticks: WheelTicks) {
    critical_section::with(|cs| WHEELS.borrow(cs).set(Some(ticks)));
}

/// The world's latest readings for this board: its simulators take them before each read.
pub fn readings() -> Option<Readings> {
    // Without a world, one load and no critical section: a single-board run's sensor reads
    // block nothing more than before (the hostile scenario's can_tx sits at its bound).
    if !WORLD.load(Ordering::Relaxed) {
        return None;
    }
    critical_section::with(|cs| READINGS.borrow(cs).get())
}

/// The wheels to report after this exchange's report: only in a run with a world.
#[inline(never)]
fn world_wheels(now_us: u64) -> Option<Wheels> {
    if !WORLD.load(Ordering::Relaxed) {
        return None;
    }
    let ticks = critical_section::with(|cs| WHEELS.borrow(cs).get())?;
    let (left_ticks, right_ticks) = ticks(now_us);
    Some(Wheels {
        now_us,
        left_ticks,
        right_ticks,
    })
}

/// Reads the world's readings that follow an answer and keeps them; `false` if the pipe failed.
#[inline(never)]
fn take_readings(down: &HostFile) -> bool {
    let mut readings = [0u8; READINGS_LEN];
    if !down.read_exact(&mut readings) {
        return false;
    }
    WORLD.store(true, Ordering::Relaxed);
    let r = Readings::decode(&readings);
    critical_section::with(|cs| READINGS.borrow(cs).set(Some(r)));
    true
}

/// Whether this board runs as part of the robot.
pub fn active() -> bool {
    UP.load(Ordering::Relaxed) != NO_FILE
}

/// Records what this board drives on SYS_SYNC_N (`true`: pulled low).
pub(super) fn drive_sync(low: bool) {
    let before = if low {
        DRIVES.fetch_or(DRIVES_SYNC_LOW, Ordering::SeqCst)
    } else {
        DRIVES.fetch_and(!DRIVES_SYNC_LOW, Ordering::SeqCst)
    };
    if (before & DRIVES_SYNC_LOW != 0) != low {
        to_report();
    }
}

/// Drives SYS_PD_N low (PowerManagement's shutdown request); it stays low.
pub fn drive_power_down() {
    if DRIVES.fetch_or(DRIVES_PD_LOW, Ordering::SeqCst) & DRIVES_PD_LOW == 0 {
        to_report();
    }
}

/// Something the host must hear of at the next boundary happened (a frame into a mailbox, an
/// abort request, a line driven): a board sent ahead ([`DOWN_EARLY`]) reports there.
static TO_REPORT: AtomicBool = AtomicBool::new(false);
/// The exchange's waker while it waits ahead.
static REPORT_WAKER: Mutex<RefCell<Option<core::task::Waker>>> = Mutex::new(RefCell::new(None));

pub(super) fn to_report() {
    TO_REPORT.store(true, Ordering::SeqCst);
    // Starts from here on are the host's again (a command frame queued now takes part in them).
    super::can::close_grant(super::now_us());
    if let Some(waker) = critical_section::with(|cs| REPORT_WAKER.borrow_ref_mut(cs).take()) {
        waker.wake();
    }
}

/// A sensor frame went into a mailbox under the grant: the exchange, waiting ahead, looks at its
/// own arbitration again (`can::local_run`).
static POKED: AtomicBool = AtomicBool::new(false);

pub(super) fn poke() {
    POKED.store(true, Ordering::SeqCst);
    if let Some(waker) = critical_section::with(|cs| REPORT_WAKER.borrow_ref_mut(cs).take()) {
        waker.wake();
    }
}

/// Waits until `at_us`, or until there is something [`to_report`] or the board's own arbitration
/// has a new frame ([`poke`]); `true`: `at_us` was reached.
async fn wait_until_or_report(at_us: u64) -> bool {
    use core::future::Future;
    let mut delay = core::pin::pin!(super::timer::platform_delay_until(at_us.div_ceil(TICK_US)));
    let reached = core::future::poll_fn(|cx| {
        critical_section::with(|cs| *REPORT_WAKER.borrow_ref_mut(cs) = Some(cx.waker().clone()));
        if TO_REPORT.load(Ordering::SeqCst) || POKED.swap(false, Ordering::SeqCst) {
            return core::task::Poll::Ready(false);
        }
        delay.as_mut().poll(cx).map(|()| true)
    })
    .await;
    critical_section::with(|cs| REPORT_WAKER.borrow_ref_mut(cs).take());
    reached
}

/// Whether SYS_SYNC_N reads low on the robot's line (the wired-AND of every module), as of the
/// last exchange.
pub fn sync_reads_low() -> bool {
    SYNC_READS_LOW.load(Ordering::SeqCst)
}

/// Waits for the tick at `at_us` without a trace record: the exchange is the platform's, not a
/// task of the app's.
async fn wait_until(at_us: u64) {
    super::timer::platform_delay_until(at_us.div_ceil(TICK_US)).await;
}

/// How long this board will do nothing, in µs from now: until the apps' earliest deadline, or 0
/// if an interrupt is pending, a task other than the exchange is running (pre-empted) or the
/// background task is not [`parked`]. Nothing
/// else wakes a board in a robot run but a frame or a line level from the host, which the host
/// sees coming. `u32::MAX`: no deadline.
fn sleeps_for() -> u32 {
    const ISPR: *const u32 = 0xE000_E200 as *const u32;
    const IABR: *const u32 = 0xE000_E300 as *const u32;
    const PENDSTSET: u32 = 1 << 26;
    // SAFETY: reads of the SCB's and NVIC's status registers.
    let icsr = unsafe { core::ptr::read_volatile(ICSR) };
    if icsr & PENDSTSET != 0 {
        return 0;
    }
    let own = (icsr & 0x1FF).checked_sub(16);
    for word in 0..3 {
        // SAFETY: as above (the first 96 interrupts cover both chips).
        let (pending, mut active) = unsafe {
            (
                core::ptr::read_volatile(ISPR.add(word)),
                core::ptr::read_volatile(IABR.add(word)),
            )
        };
        if let Some(own) = own.filter(|&n| n as usize / 32 == word) {
            active &= !(1 << (own % 32));
        }
        if pending != 0 || active != 0 {
            return 0;
        }
    }
    if !PARKED.load(Ordering::SeqCst) {
        return 0;
    }
    let (next, now) = (super::timer::next_deadline_us(), super::now_us());
    if next == u64::MAX {
        return u32::MAX;
    }
    u32::try_from(next.saturating_sub(now)).unwrap_or(u32::MAX - 1)
}

/// The exchange loop (in place of the stimulus replay): until the host ends the run.
pub(super) async fn run(rx_irq: impl InterruptNumber, shutdown_irq: impl InterruptNumber) {
    let (up, down) = (
        HostFile(UP.load(Ordering::Relaxed)),
        HostFile(DOWN.load(Ordering::Relaxed)),
    );
    let mut boundary = 0;
    let mut pd_seen = false;
    let mut early = false;
    // The frame of the last answer, delivered at its completion time: before the next boundary,
    // or (the host answered its own frame's completion ahead, docs/qemu.md) after an earlier
    // report if the board has something to report before it completes.
    let mut pending: Option<Down> = None;
    loop {
        boundary += QUANTUM_US;
        loop {
            // The frames the board completes itself under a grant: delivered at their
            // completion, started as the bus model would start them (`can::local_run`; one that
            // can no longer be asks for a report).
            let local = super::can::local_run(super::now_us());
            // Sent ahead: back at the first boundary after something to report — found now, or
            // already there when the wait starts (set while the last exchange was being made: the
            // wait must not then run on to the far boundary the host allowed).
            if early && TO_REPORT.load(Ordering::SeqCst) {
                let first = (super::now_us() / QUANTUM_US + 1) * QUANTUM_US;
                if first < boundary {
                    boundary = first;
                    continue;
                }
            }
            let deliver_at = pending.map(|p| p.at_us).filter(|&at| at < boundary);
            let until = deliver_at.unwrap_or(boundary).min(local);
            let reached = if early && !TO_REPORT.load(Ordering::SeqCst) {
                wait_until_or_report(until).await
            } else {
                wait_until(until).await;
                true
            };
            if !reached {
                continue;
            }
            match (deliver_at, pending.take()) {
                (Some(at), Some(answer)) if at <= until => deliver(&answer, rx_irq),
                (_, kept) => {
                    pending = kept;
                    if until >= boundary {
                        break;
                    }
                }
            }
        }
        TO_REPORT.store(false, Ordering::SeqCst);
        let mut report = Up {
            now_us: super::now_us(),
            at_us: boundary,
            ..Up::default()
        };
        super::can::report(&mut report);
        report.drives = DRIVES.load(Ordering::SeqCst);
        // A frame still to be delivered (the host's answer kept, or one the board completes
        // itself) wakes the board at its completion time.
        let completes = pending
            .map_or(u64::MAX, |p| p.at_us)
            .min(super::can::local_run(report.now_us));
        let delivery = if completes == u64::MAX {
            u32::MAX
        } else {
            u32::try_from(completes.saturating_sub(report.now_us)).unwrap_or(u32::MAX - 1)
        };
        report.sleeps_us = sleeps_for().min(delivery);
        let wheels = world_wheels(report.now_us);
        if wheels.is_some() {
            report.flags |= UP_WHEELS;
        }
        let mut answer = [0u8; DOWN_LEN];
        let sent = if report.done == 0 {
            // The usual report: as it always was (the exchange's cost is the apps' lost time).
            up.write_all(&report.encode()) && wheels.is_none_or(|w| up.write_all(&w.encode()))
        } else {
            // After a grant: the report, the frames completed under it, the wheels, in one write.
            let mut message = [0u8; UP_LEN + MAX_DONE * DONE_LEN + world_link::WHEELS_LEN];
            message[..UP_LEN].copy_from_slice(&report.encode());
            let mut len = UP_LEN;
            if let Some(rest) = message.get_mut(UP_LEN..UP_LEN + MAX_DONE * DONE_LEN) {
                len += super::can::take_done(rest, report.now_us);
            }
            if let Some(w) = wheels {
                if let Some(out) = message.get_mut(len..len + world_link::WHEELS_LEN) {
                    out.copy_from_slice(&w.encode());
                }
                len += world_link::WHEELS_LEN;
            }
            up.write_all(message.get(..len).unwrap_or(&message))
        } && down.read_exact(&mut answer);
        let answer = Down::decode(&answer);
        let flags = answer.flags;
        if !sent || (flags & DOWN_READINGS != 0 && !take_readings(&down)) {
            super::print_line("# qemu: the robot's bus is gone");
            super::exit(false);
            return;
        }
        if flags & DOWN_RESTART != 0 {
            // A system reset in the same QEMU (the end of a live run's warm-up): everything the
            // board set up goes, the code QEMU translated for it stays.
            cortex_m::peripheral::SCB::sys_reset();
        }
        early = flags & DOWN_EARLY != 0;
        if early && answer.free_until_us > 0 {
            super::can::grant(answer.free_until_us, answer.idle_from_us, answer.held);
        }
        // The host skips quanta in which no board can act: the next exchange is further on.
        boundary = boundary.max(answer.next_us.saturating_sub(QUANTUM_US));
        SYNC_READS_LOW.store(flags & DOWN_SYNC_LOW != 0, Ordering::SeqCst);
        if flags & DOWN_PD_LOW != 0 && !pd_seen {
            // SYS_PD_N falls: the same interrupt the real pin raises.
            pd_seen = true;
            super::SYS_PD_LOW.store(true, Ordering::SeqCst);
            cortex_m::peripheral::NVIC::pend(shutdown_irq);
        }
        if flags & DOWN_END != 0 {
            super::finish("end of run");
            return;
        }
        if answer.aborted != 0 {
            super::can::aborts_done(answer.aborted);
        }
        if flags & DOWN_FRAME != 0 {
            // One frame completes at a time on the bus: one still held is due before this one.
            if let Some(held) = pending.replace(answer) {
                deliver(&held, rx_irq);
            }
        }
    }
}

/// Delivers the answer's frame at its completion time (now): the board's own frame's mailbox
/// completes (the register model raises the transmit interrupt), another node's frame goes to the
/// model's receive side, through the filter `configure` set.
fn deliver(answer: &Down, rx_irq: impl InterruptNumber) {
    if answer.flags & DOWN_OWN != 0 {
        super::can::own_frame_sent(answer.mailbox);
    } else {
        super::can::bus_frame(answer.id, answer.len, answer.data, rx_irq);
    }
}

const ICSR: *const u32 = 0xE000_ED04 as *const u32;
const ICSR_VECTPENDING: u32 = 0x1FF << 12;
const ICSR_RETTOBASE: u32 = 1 << 11;

/// No exception or interrupt is pending (the caller's own, if it is one, aside).
pub(super) fn nothing_else_pending() -> bool {
    // SAFETY: a read of the SCB's interrupt control and state register.
    unsafe { core::ptr::read_volatile(ICSR) & ICSR_VECTPENDING == 0 }
}

/// Called at the end of SysTick's interrupt: the core goes idle when it returns (nothing pending,
/// no other handler pre-empted, the background task [`parked`]), so the next deadline is reached
/// by `timer::skip_to_deadline`, not by SysTick.
pub(super) fn idle_after_systick() -> bool {
    // SAFETY: as above.
    let icsr = unsafe { core::ptr::read_volatile(ICSR) };
    icsr & ICSR_VECTPENDING == 0 && icsr & ICSR_RETTOBASE != 0 && PARKED.load(Ordering::SeqCst)
}

/// Whether the board's background task (priority 0, thread mode, which no NVIC bit shows) waits
/// in [`parked`]; `false` from its wake-up until it waits again.
static PARKED: AtomicBool = AtomicBool::new(false);
/// The background task's own waker while it is parked.
static PARKED_WAKER: Mutex<RefCell<Option<core::task::Waker>>> = Mutex::new(RefCell::new(None));

/// A wake-up of the background task came since its last poll (so it must not be marked idle).
static WOKEN: AtomicBool = AtomicBool::new(false);

fn parked_wake() {
    WOKEN.store(true, Ordering::SeqCst);
    PARKED.store(false, Ordering::SeqCst);
    if let Some(waker) = critical_section::with(|cs| PARKED_WAKER.borrow_ref_mut(cs).take()) {
        waker.wake();
    }
}

static PARKED_VTABLE: core::task::RawWakerVTable = core::task::RawWakerVTable::new(
    |_| core::task::RawWaker::new(core::ptr::null(), &PARKED_VTABLE),
    |_| parked_wake(),
    |_| parked_wake(),
    |_| {},
);

/// Runs `future`, a wait of the board's one priority-0 task, marking the task idle while it is
/// pending: a wake-up clears the mark before the task runs, so an exchange between the two sees a
/// board with work ([`sleeps_for`]). The mark is set only once a poll found the wait pending and no
/// wake-up came since: set before the poll, an exchange that pre-empted a poll about to end the
/// wait (its deadline already taken from the timer queue) saw an idle board with no deadline near,
/// and the host left it running unseen to a far boundary (robot `thesis-demo`: DiWheelDrive's
/// first magnetometer frames held 2.6 ms in its mailboxes).
pub async fn parked<F: core::future::Future>(future: F) -> F::Output {
    let mut future = core::pin::pin!(future);
    core::future::poll_fn(|cx| {
        critical_section::with(|cs| *PARKED_WAKER.borrow_ref_mut(cs) = Some(cx.waker().clone()));
        // SAFETY: the vtable's functions ignore the data pointer.
        let waker = unsafe {
            core::task::Waker::from_raw(core::task::RawWaker::new(
                core::ptr::null(),
                &PARKED_VTABLE,
            ))
        };
        loop {
            WOKEN.store(false, Ordering::SeqCst);
            let result = future
                .as_mut()
                .poll(&mut core::task::Context::from_waker(&waker));
            if result.is_ready() {
                PARKED.store(false, Ordering::SeqCst);
                return result;
            }
            critical_section::with(|_| {
                if !WOKEN.load(Ordering::SeqCst) {
                    PARKED.store(true, Ordering::SeqCst);
                }
            });
            if !active() {
                return result;
            }
            // In a robot run the core sleeps here until the wait ends. RTIC's priority-0 executor
            // would otherwise spin in thread mode, and QEMU would emulate that spin for every
            // virtual µs of the board's idle time (the most of its wall time in a robot run); this
            // task is the board's only one at priority 0, so there is nothing else to poll. An
            // interrupt that ends the wait (its waker clears PARKED) ends the sleep; the check and
            // the WFI are under PRIMASK so no wake-up falls between them.
            loop {
                cortex_m::interrupt::disable();
                if !PARKED.load(Ordering::SeqCst) {
                    // SAFETY: re-enables what the line above disabled, outside any critical section.
                    unsafe { cortex_m::interrupt::enable() };
                    break;
                }
                // Idle: the clock goes to the next deadline at once (`timer::skip_to_deadline`).
                if !super::timer::skip_to_deadline() {
                    cortex_m::asm::wfi();
                }
                // SAFETY: as above; the pending interrupt that ended the WFI runs now.
                unsafe { cortex_m::interrupt::enable() };
            }
        }
    })
    .await
}
