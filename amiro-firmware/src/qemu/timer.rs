//! The QEMU build's clock and timers: SysTick counts core cycles, and a tick is [`TICK_US`] µs of
//! them; two timer queues run over the tick count.
//!
//! - The apps' ([`AppTimer`], behind `mono::QemuClock`): every task's delay and timeout, in the
//!   boards' own queue (`crate::timer_queue`, as on the chips). Its earliest deadline is known
//!   ([`next_deadline_us`]), so a robot run can tell the host how long the board will sleep.
//! - The platform's own ([`PlatformTimer`], rtic-time's queue): the robot exchange and the stimulus
//!   replay wait in it, so their waits never hide the apps' next deadline.
//!
//! **Periodic or tickless.** A single-board run interrupts every tick (SysTick's reload is one
//! tick), as it always did: the scenarios' cost figures include that interrupt. A robot run
//! ([`set_tickless`], from `robot::connect`) interrupts only when something is due: after every
//! interrupt SysTick is restarted to end at the earlier of the two queues' deadlines (at most one
//! 24-bit reload, ≈ 100–140 ms, on), unless it already runs to that deadline; a deadline less than
//! half a tick away is waited for by pending the interrupt again, never with a period of a few
//! cycles. Under `-icount` an idle board then costs QEMU one interrupt per deadline instead of
//! 100 000 per virtual second (docs/qemu.md, "Speed").
//!
//! **An idle core skips.** In a robot run nothing but a deadline can wake an idle board (the host's
//! frames come through the exchange, which waits for a deadline of its own), so when the core goes
//! idle ([`skip_to_deadline`], from `robot::parked`) the board's clock moves to the earlier queue
//! deadline at once and SysTick is pended: no WFI for QEMU to end with a timer expiry. The clock's
//! period start moves with it (SysTick counts on as it was), and an interrupt after which the core
//! is idle again sets nothing up. A busy core still gets SysTick set up for its next deadline:
//! the running period is kept when it ends before it ([`keep_until`]), else restarted.
//!
//! **A platform wait sets itself up.** Tickless, a wait that becomes the platform queue's head
//! restarts SysTick for its deadline in its first poll ([`platform_delay_until`]) instead of
//! pending the interrupt as rtic-time's queues do (the exchange's every wait did).
//!
//! **No held reading.** Tickless, the queues' expiry checks read the clock themselves (at least
//! twice each), and the interrupt reads it once more after
//! both: a deadline that came while they ran is expired in the same interrupt. A single reading
//! taken at the interrupt's start and held for both queues' checks (a quarter fewer SysTick register
//! reads, no CPU gain measured) made DiWheelDrive's magnetometer miss samples in the 10 s thesis
//! demo — 147 gaps of over a millisecond, the longest 10.8 ms — on the tree it was merged into
//! (docs/qemu.md, "A new wait sets up its own deadline"); why is not found.
//!
//! **Few critical sections.** Under QEMU every `cpsid i` and `msr primask` ends the translation
//! block and returns to QEMU's execution loop, so a critical section costs two trips out of the
//! translated code. The clock is read and changed without masking interrupts where nothing that
//! touches it can pre-empt the caller ([`with_clock`]: SysTick's own interrupt, the highest
//! priority, or code that already masked them), and the queues' deadlines are two plain words that
//! only SysTick's interrupt writes ([`Due`]). DiWheelDrive's critical sections in the thesis demo
//! fell from 237 000 to 82 000 per virtual second (docs/qemu.md, "Critical sections and dropped records").
//!
//! Periodic, the tick count is one per wrap (COUNTFLAG, as rtic-monotonics' SysTick counts it: the
//! cheapest reading, which the scenarios' cost figures were measured with). Tickless, the clock is
//! the tick and the cycles into it where the running period started, plus how far SysTick has
//! counted down; a wrap is seen by COUNTFLAG (reading it clears it: only this module reads it), so a
//! wrap whose interrupt has not run yet is counted. A tickless reading takes the status and the
//! counter with one load instruction ([`read_systick`]): one trip out of QEMU's translated code
//! instead of two. A restart costs the few cycles between the read
//! and the write of the counter (the board's clock runs that much behind QEMU's), the same each
//! time: the run stays deterministic. No tickless reading goes below the one before (QEMU updates
//! SysTick lazily around a wrap: a reading there can come out a little early).
use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};

use portable_atomic::AtomicU64;

use critical_section::{CriticalSection, Mutex};
use rtic_time::timer_queue::{TimerQueue, TimerQueueBackend};

use super::{CORE_CLOCK_HZ, TICK_US};

/// Core cycles per tick.
pub const CYCLES_PER_TICK: u64 = CORE_CLOCK_HZ as u64 * TICK_US / 1_000_000;
/// The longest period SysTick's 24-bit reload allows, in cycles.
const MAX_PERIOD: u64 = 0x0100_0000;

const SYST_CSR: *mut u32 = 0xE000_E010 as *mut u32;
const SYST_RVR: *mut u32 = 0xE000_E014 as *mut u32;
const SYST_CVR: *mut u32 = 0xE000_E018 as *mut u32;
const CSR_COUNTFLAG: u32 = 1 << 16;

struct Clock {
    /// The tick the running period started in …
    tick: u64,
    /// … and how many cycles into it (0 in periodic mode: every period is one whole tick).
    offset: u32,
    /// The running period's reload: it wraps `reload + 1` cycles after its start (SysTick's RVR
    /// holds the same value).
    reload: u32,
    /// The latest readings in cycles (the trace clock's) and in ticks, which no later one goes
    /// below.
    last_cycles: u64,
    last_tick: u64,
    /// The due tick the running period ends at ([`NOT_ARMED`] when it ends at no deadline: after
    /// a wrap SysTick runs on with the same reload, unless the restart set up that period too,
    /// [`Clock::next_armed`]).
    armed: u64,
    /// The running period is a restart's that has wrapped once: it may be kept for one more turn.
    may_keep: bool,
    /// The reload the counter takes at the running period's wrap (SysTick's RVR; `reload` unless a
    /// restart set up the period after it as well), and the deadline that period ends at
    /// ([`NOT_ARMED`]: none).
    next_reload: u32,
    next_armed: u64,
}

/// [`Clock::armed`] when no restart set the running period up for a deadline.
const NOT_ARMED: u64 = u64::MAX - 1;

static CLOCK: Mutex<RefCell<Clock>> = Mutex::new(RefCell::new(Clock {
    tick: 0,
    offset: 0,
    reload: CYCLES_PER_TICK as u32 - 1,
    last_cycles: 0,
    last_tick: 0,
    armed: NOT_ARMED,
    may_keep: false,
    next_reload: CYCLES_PER_TICK as u32 - 1,
    next_armed: NOT_ARMED,
}));
/// The tick count of periodic mode: one per wrap, as rtic-monotonics' SysTick counts (the apps read
/// the clock often, and every instruction here is virtual time they lose; the scenarios' cost
/// figures were measured with that count).
static PERIODIC: AtomicU64 = AtomicU64::new(0);
/// The apps' earliest deadline in ticks (`u64::MAX`: none).
static APP_DUE: Due = Due::new(u64::MAX);
/// The platform's earliest deadline in ticks (`u64::MAX`: none).
static PLATFORM_DUE: Due = Due::new(u64::MAX);
static TICKLESS: AtomicBool = AtomicBool::new(false);
const PER_TICK: u32 = CYCLES_PER_TICK as u32;

/// A queue's earliest deadline in ticks, as two words that are read and written without masking
/// interrupts (a `portable_atomic::AtomicU64` masks them for every access, and in QEMU every
/// `cpsid` and every `msr primask` leaves the translated code: the deadlines' loads and stores were
/// 60 000 of DiWheelDrive's 237 000 critical sections per virtual second in the thesis demo,
/// docs/qemu.md "Critical sections and dropped records"). Only SysTick's interrupt writes it (the timer queues'
/// `set_compare` and `disable_timer`, from `on_monotonic_interrupt`), and nothing that reads it can
/// pre-empt that interrupt (the highest priority), so every store is whole to every reader; a
/// reader that the interrupt pre-empts between its two word loads reads again until two readings
/// agree, and two agreeing readings are a value the deadline had.
struct Due {
    low: AtomicU32,
    high: AtomicU32,
}

impl Due {
    const fn new(ticks: u64) -> Self {
        Self {
            low: AtomicU32::new(ticks as u32),
            high: AtomicU32::new((ticks >> 32) as u32),
        }
    }

    /// Only from SysTick's interrupt (or before interrupts are enabled).
    fn store(&self, ticks: u64, order: Ordering) {
        self.low.store(ticks as u32, order);
        self.high.store((ticks >> 32) as u32, order);
    }

    fn read(&self, order: Ordering) -> u64 {
        u64::from(self.low.load(order)) | u64::from(self.high.load(order)) << 32
    }

    /// Where the caller may be pre-empted by SysTick's interrupt (the exchange's report).
    fn load(&self, order: Ordering) -> u64 {
        let mut ticks = self.read(order);
        loop {
            let again = self.read(order);
            if again == ticks {
                return ticks;
            }
            ticks = again;
        }
    }

    /// Where SysTick's interrupt cannot run: in it, or with interrupts masked (the token: a
    /// critical section, or [`with_clock`]'s where nothing pre-empts), so one reading is whole.
    fn get(&self, _cs: CriticalSection<'_>) -> u64 {
        self.read(Ordering::Relaxed)
    }
}

/// Whether nothing that touches the clock can pre-empt the caller: interrupts are masked
/// (PRIMASK), or the caller is SysTick's interrupt, which has the highest priority (SysTick's
/// reset priority, 0, which nothing changes; the apps' interrupts sit below it) and is the only
/// exception that changes the clock. Read with `mrs`, which QEMU runs in the translated code.
#[cfg(target_arch = "arm")]
#[inline(always)]
fn unpreempted() -> bool {
    let ipsr: u32;
    // SAFETY: reads the interrupt program status register; no side effect.
    unsafe {
        core::arch::asm!("mrs {}, IPSR", out(reg) ipsr, options(nomem, nostack, preserves_flags));
    }
    ipsr & 0x1FF == 15 || cortex_m::register::primask::read().is_inactive()
}

/// No ARM core (a host check): always mask.
#[cfg(not(target_arch = "arm"))]
fn unpreempted() -> bool {
    false
}

/// Runs `f` on the clock, with interrupts masked unless nothing that touches the clock can
/// pre-empt the caller anyway ([`unpreempted`]). Under QEMU a critical section costs two trips out
/// of the translated code (`cpsid i` and `msr primask` each end the translation block and return to
/// QEMU's execution loop); most clock readings are taken in SysTick's interrupt (rtic-time's expiry
/// checks) or inside another critical section (the trace's stamps), where the mask changes nothing.
#[inline(always)]
fn with_clock<R>(f: impl FnOnce(CriticalSection<'_>, &mut Clock) -> R) -> R {
    if unpreempted() {
        // SAFETY: nothing that touches `CLOCK` can run until `f` returns (`unpreempted`), which is
        // what the critical section would ensure; the token does not leave `f`.
        let cs = unsafe { CriticalSection::new() };
        return f(cs, &mut CLOCK.borrow_ref_mut(cs));
    }
    critical_section::with(|cs| f(cs, &mut CLOCK.borrow_ref_mut(cs)))
}

/// SysTick's status (CSR) and current value (CVR), read by one instruction: a load of CSR, RVR and
/// CVR together (`ldm`). Under `-icount` every device access in the middle of a translation block
/// makes QEMU leave the translated code, restore the CPU state and run the access in a block of
/// its own (`cpu_io_recompile`) — DiWheelDrive made 168 such trips per exchange in the thesis
/// demo, 133 of them for these two registers, which every clock reading read by two loads. One
/// load of the three makes it one trip per reading, and both values are taken at the same virtual
/// instant. Reading CSR clears COUNTFLAG, as before (RVR has no side effect).
#[cfg(target_arch = "arm")]
fn read_systick() -> (u32, u32) {
    let (csr, cvr): (u32, u32);
    // SAFETY: three word reads of SysTick's registers at 0xE000_E010..=0xE000_E018 (ascending
    // registers take ascending addresses); only reading CSR has an effect (COUNTFLAG cleared),
    // which the callers account for.
    unsafe {
        core::arch::asm!(
            "ldm r0, {{r1, r2, r3}}",
            in("r0") SYST_CSR as u32,
            out("r1") csr,
            out("r2") _,
            out("r3") cvr,
            options(nostack, preserves_flags),
        );
    }
    (csr, cvr)
}

/// As on the chip: the two registers one after the other (no ARM core, e.g. a host check).
#[cfg(not(target_arch = "arm"))]
fn read_systick() -> (u32, u32) {
    // SAFETY: reads of SysTick's status and current value registers.
    unsafe {
        (
            core::ptr::read_volatile(SYST_CSR),
            core::ptr::read_volatile(SYST_CVR),
        )
    }
}

/// Counts a wrap if SysTick had wrapped before `csr` was read (reading the status clears
/// COUNTFLAG, which nothing but [`position`] reads in tickless mode); `true` if it had.
fn count_wrap(clock: &mut Clock, csr: u32) -> bool {
    if csr & CSR_COUNTFLAG == 0 {
        return false;
    }
    if clock.offset == 0 && clock.reload == PER_TICK - 1 {
        clock.tick += 1;
    } else {
        let total = u64::from(clock.offset) + u64::from(clock.reload) + 1;
        clock.tick += total / CYCLES_PER_TICK;
        clock.offset = (total % CYCLES_PER_TICK) as u32;
    }
    clock.may_keep = clock.armed != NOT_ARMED;
    clock.armed = clock.next_armed;
    clock.reload = clock.next_reload;
    clock.next_armed = NOT_ARMED;
    true
}

/// Where the clock is: the tick and the cycles into it.
fn position(_cs: CriticalSection<'_>, clock: &mut Clock) -> (u64, u32) {
    let (csr, value) = read_systick();
    let wrapped = count_wrap(clock, csr);
    // The counter reads 0 for one cycle after a wrap (then reloads), and also once its period has
    // ended but QEMU has not yet run the wrap: then the period is at its last cycle.
    let into = match value {
        0 if wrapped => 0,
        0 => clock.reload,
        v => clock.reload.saturating_sub(v) + 1,
    };
    let cycles = clock.offset + into;
    (clock.tick + u64::from(cycles / PER_TICK), cycles % PER_TICK)
}

/// Whether SysTick has wrapped since the last look (reading the status clears COUNTFLAG).
fn has_wrapped() -> bool {
    // SAFETY: a read of SysTick's status register.
    unsafe { core::ptr::read_volatile(SYST_CSR) & CSR_COUNTFLAG != 0 }
}

/// Core cycles since the clock started (the trace clock).
pub fn now_cycles() -> u64 {
    if !TICKLESS.load(Ordering::Relaxed) {
        loop {
            // The same count before and after the read of the counter: no wrap came between.
            let ticks = now_ticks();
            // SAFETY: a read of SysTick's current value, which has no side effects.
            let value = unsafe { core::ptr::read_volatile(SYST_CVR) };
            if now_ticks() == ticks {
                return ticks * CYCLES_PER_TICK
                    + (CYCLES_PER_TICK - 1).saturating_sub(u64::from(value));
            }
        }
    }
    with_clock(|cs, clock| {
        let (tick, into) = position(cs, clock);
        let now = (tick * CYCLES_PER_TICK + u64::from(into)).max(clock.last_cycles);
        clock.last_cycles = now;
        now
    })
}

/// Ticks since the clock started.
pub fn now_ticks() -> u64 {
    if !TICKLESS.load(Ordering::Relaxed) {
        if has_wrapped() {
            PERIODIC.fetch_add(1, Ordering::AcqRel);
        }
        return PERIODIC.load(Ordering::Relaxed);
    }
    read_ticks()
}

/// Tickless: ticks since the clock started, read from SysTick.
fn read_ticks() -> u64 {
    with_clock(ticks_at)
}

/// The tick count where nothing pre-empts the caller (the token).
fn ticks_at(cs: CriticalSection<'_>, clock: &mut Clock) -> u64 {
    let tick = position(cs, clock).0.max(clock.last_tick);
    clock.last_tick = tick;
    tick
}

/// Makes SysTick interrupt only when a deadline is due (robot runs); takes effect at once.
pub(super) fn set_tickless() {
    critical_section::with(|cs| {
        let clock = &mut *CLOCK.borrow_ref_mut(cs);
        if has_wrapped() {
            PERIODIC.fetch_add(1, Ordering::AcqRel);
        }
        // The running period is a periodic one: one tick from the count's last wrap.
        clock.tick = PERIODIC.load(Ordering::Relaxed);
        clock.offset = 0;
        clock.reload = PER_TICK - 1;
        clock.next_reload = PER_TICK - 1;
        clock.armed = NOT_ARMED;
        clock.next_armed = NOT_ARMED;
        TICKLESS.store(true, Ordering::SeqCst);
    });
    cortex_m::peripheral::SCB::set_pendst();
}

/// The shortest period a restart sets, in cycles. SysTick wraps again every period until the
/// interrupt restarts it, and in QEMU every wrap is a timer expiry that its main loop must run
/// (a hand-over of QEMU's global lock between its threads); the interrupt takes some hundred
/// cycles from the wrap to its restart, so a period of a few cycles wrapped hundreds of times in
/// it (96 % of DiWheelDrive's timer expiries in the thesis demo, docs/qemu.md "Speed").
const MIN_PERIOD: u64 = CYCLES_PER_TICK / 2;

/// The shortest running period a restart after its wrap keeps for one more turn, in cycles (see
/// [`restart`]).
const KEEP_PERIOD: u64 = 3 * CYCLES_PER_TICK;

/// Restarts SysTick to wrap at the earlier queue deadline (or a full reload on); leaves it alone
/// when the running period was set up for that deadline and has not wrapped. A deadline closer
/// than [`MIN_PERIOD`] is not set up: the interrupt is pended again instead, and it runs until the
/// deadline has come (the running period is at least that long, so it wraps at most once meanwhile).
///
/// Every restart costs QEMU a timer expiry of its own besides the wrap: writing the current value
/// leaves the counter at 0, and QEMU's SysTick reloads it one cycle later through its timer. So
/// right after a wrap, when the deadline lies beyond the end of the period SysTick has just begun
/// again (at least [`KEEP_PERIOD`] long), that period is kept once: a sooner deadline usually
/// comes first (the exchange's next wait, a task's delay) and restarts it, and otherwise its wrap
/// does. In the thesis demo this saves about a quarter of DiWheelDrive's restarts.
fn restart(cs: CriticalSection<'_>, clock: &mut Clock) {
    let (tick, into) = position(cs, clock);
    let due = APP_DUE.get(cs).min(PLATFORM_DUE.get(cs));
    if due == clock.armed {
        return;
    }
    if keep_until(clock, tick * CYCLES_PER_TICK + u64::from(into), due) {
        return;
    }
    let period = due
        .saturating_sub(tick)
        .saturating_mul(CYCLES_PER_TICK)
        .saturating_sub(u64::from(into));
    if clock.may_keep && u64::from(clock.reload) >= KEEP_PERIOD {
        clock.may_keep = false;
        let start = clock.tick * CYCLES_PER_TICK + u64::from(clock.offset);
        let end = start + u64::from(clock.reload) + 1;
        if due.saturating_mul(CYCLES_PER_TICK) > end {
            return;
        }
    }
    if period < MIN_PERIOD {
        cortex_m::peripheral::SCB::set_pendst();
        return;
    }
    let reload = (period.min(MAX_PERIOD) - 1) as u32;
    // SAFETY: SysTick's reload and current value; writing the current value clears it and
    // COUNTFLAG, and the counter reloads from RVR on the next cycle. The position was read before:
    // the cycles in between are the restart's cost (module docs).
    unsafe {
        core::ptr::write_volatile(SYST_RVR, reload);
        core::ptr::write_volatile(SYST_CVR, 0);
    }
    clock.tick = tick;
    clock.offset = into;
    clock.reload = reload;
    clock.next_reload = reload;
    clock.armed = due;
    clock.next_armed = NOT_ARMED;
    clock.may_keep = false;
    if period <= MAX_PERIOD {
        set_up_next(cs, clock, due);
    }
}

/// When the running period ends before the deadline `due` (at least [`MIN_PERIOD`] before it, as
/// after the board's clock went ahead while idle, `skip_to_deadline`), it is kept and the period
/// after its wrap is set up to end at `due`: a wrap costs QEMU no more than a restart would, and
/// none if the core is idle before it (the clock then skips). `false` (nothing set up) otherwise.
fn keep_until(clock: &mut Clock, now: u64, due: u64) -> bool {
    let end = clock.tick * CYCLES_PER_TICK + u64::from(clock.offset) + u64::from(clock.reload) + 1;
    let Some(gap) = due.saturating_mul(CYCLES_PER_TICK).checked_sub(end) else {
        return false;
    };
    // The reload must be written well before the wrap (SysTick takes RVR at its wrap: written
    // after it, it would set the period after the next one instead). Half a tick is far more than
    // the cycles from the reading to the write, in an interrupt nothing pre-empts.
    // SAFETY: a read of SysTick's current value, which has no side effects (0: the counter has
    // not reloaded from a restart yet, and RVR would still set the running period).
    if end < now + MIN_PERIOD
        || !(MIN_PERIOD..=MAX_PERIOD).contains(&gap)
        || unsafe { core::ptr::read_volatile(SYST_CVR) } == 0
    {
        return false;
    }
    let reload = (gap - 1) as u32;
    // SAFETY: SysTick's reload: the running period keeps its count, the next one takes this.
    unsafe { core::ptr::write_volatile(SYST_RVR, reload) };
    clock.next_reload = reload;
    clock.next_armed = due;
    clock.may_keep = false;
    true
}

/// After a restart for `due`: when the other queue's deadline follows it, the period after the
/// wrap at `due` is set up to end there too, so that wrap needs no restart of its own (which would
/// cost QEMU a reload expiry). SysTick takes a new reload at its next wrap; the counter must have
/// reloaded from the restart first (a cycle after it: it reads non-zero then), else nothing is set
/// up and the wrap restarts as before.
fn set_up_next(cs: CriticalSection<'_>, clock: &mut Clock, due: u64) {
    let second = APP_DUE.get(cs).max(PLATFORM_DUE.get(cs));
    if second == u64::MAX || second <= due {
        return;
    }
    let period = (second - due).saturating_mul(CYCLES_PER_TICK);
    if !(MIN_PERIOD..=MAX_PERIOD).contains(&period) {
        return;
    }
    // SAFETY: a read of SysTick's current value, which has no side effects.
    if unsafe { core::ptr::read_volatile(SYST_CVR) } == 0 {
        return;
    }
    let reload = (period - 1) as u32;
    // SAFETY: SysTick's reload: the running period keeps its count, the next one takes this.
    unsafe { core::ptr::write_volatile(SYST_RVR, reload) };
    clock.next_reload = reload;
    clock.next_armed = second;
}

/// An rtic-time timer queue over the tick count whose next expiry is the word `$due` (the tick
/// interrupt reads it): the platform's.
macro_rules! tick_backend {
    ($(#[$doc:meta])* $backend:ident, $queue:ident, $due:ident, $asked:ident) => {
        $(#[$doc])*
        pub struct $backend;

        static $queue: TimerQueue<$backend> = TimerQueue::new();

        impl TimerQueueBackend for $backend {
            type Ticks = u64;

            fn now() -> u64 {
                now_ticks()
            }

            fn set_compare(at: u64) {
                $due.store(at, Ordering::Relaxed);
            }

            fn clear_compare_flag() {}

            fn pend_interrupt() {
                $asked.store(true, Ordering::Relaxed);
                cortex_m::peripheral::SCB::set_pendst();
            }

            fn on_interrupt() {}

            fn enable_timer() {}

            fn disable_timer() {
                $due.store(u64::MAX, Ordering::Relaxed);
            }

            fn timer_queue() -> &'static TimerQueue<Self> {
                &$queue
            }
        }
    };
}

/// The apps' timer queue over the tick count: the boards' queue (`crate::timer_queue`), as on the
/// chips, its compare the word [`APP_DUE`].
pub struct AppTimer;

static APP_QUEUE: crate::timer_queue::TimerQueue<AppTimer> = crate::timer_queue::TimerQueue::new();

impl crate::timer_queue::Backend for AppTimer {
    fn now() -> u64 {
        now_ticks()
    }

    fn set_compare(at: u64, _now: u64) -> bool {
        APP_DUE.store(at, Ordering::Relaxed);
        now_ticks() >= at
    }

    fn disable_compare() {
        APP_DUE.store(u64::MAX, Ordering::Relaxed);
    }

    fn pend_interrupt() {
        APP_ASKED.store(true, Ordering::Relaxed);
        cortex_m::peripheral::SCB::set_pendst();
    }

    fn queue() -> &'static crate::timer_queue::TimerQueue<Self> {
        &APP_QUEUE
    }
}

tick_backend!(
    /// The platform's timer queue (the robot exchange, the stimulus replay) over the tick count.
    PlatformTimer,
    PLATFORM_QUEUE,
    PLATFORM_DUE,
    PLATFORM_ASKED
);

/// A queue's head changed since SysTick's interrupt last ran its expiries (rtic-time pends the
/// interrupt for it): the tickless interrupt runs a queue's expiries only then or when its deadline
/// has come, as nothing else changes what they would find. Set at a lower priority, cleared by the
/// interrupt, which nothing that sets them pre-empts.
static APP_ASKED: AtomicBool = AtomicBool::new(false);
static PLATFORM_ASKED: AtomicBool = AtomicBool::new(false);

/// Waits on the platform's queue until tick `at` (no trace record: the platform's wait, not a
/// task of the app's).
pub(super) async fn platform_delay_until(at: u64) {
    PLATFORM_QUEUE.delay_until(at).await;
}

/// Starts SysTick at one tick per [`TICK_US`] (periodic) and both queues.
pub(super) fn start(mut syst: cortex_m::peripheral::SYST) {
    use cortex_m::peripheral::syst::SystClkSource;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(PER_TICK - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    PLATFORM_QUEUE.initialize(PlatformTimer);
}

/// The apps' earliest deadline in µs (`u64::MAX`: none). A queue whose head changed pends SysTick,
/// which updates it, so it is current unless SysTick is pending.
pub(super) fn next_deadline_us() -> u64 {
    APP_DUE.load(Ordering::Relaxed).saturating_mul(TICK_US)
}

/// The core is idle (robot runs: the background task sleeps in `robot::parked`, nothing is pending
/// or active): nothing but SysTick can happen before the earlier queue deadline, so the board's
/// clock goes there at once and SysTick is pended, instead of a WFI that QEMU ends with a timer
/// expiry (a hand-over to its main loop, the most of a board's wall time). `false` (nothing done:
/// wait with WFI) when something is pending or there is no deadline. Called with interrupts
/// masked.
pub(super) fn skip_to_deadline() -> bool {
    if !TICKLESS.load(Ordering::Relaxed) || !super::robot::nothing_else_pending() {
        return false;
    }
    // SAFETY: called with interrupts masked: nothing touches the clock or the deadlines until it
    // returns.
    let cs = unsafe { CriticalSection::new() };
    let due = APP_DUE.get(cs).min(PLATFORM_DUE.get(cs));
    if due == u64::MAX {
        return false;
    }
    {
        let clock = &mut *CLOCK.borrow_ref_mut(cs);
        let (tick, into) = position(cs, clock);
        let now = tick * CYCLES_PER_TICK + u64::from(into);
        let target = due.saturating_mul(CYCLES_PER_TICK);
        if target > now {
            // The running period started that much later on the board's clock: SysTick's count
            // goes on as it was, and every later reading and restart are relative to it.
            let start = clock.tick * CYCLES_PER_TICK + u64::from(clock.offset) + (target - now);
            clock.tick = start / CYCLES_PER_TICK;
            clock.offset = (start % CYCLES_PER_TICK) as u32;
        }
        // The period SysTick runs no longer ends at a deadline: the interrupt keeps it for the
        // next one or restarts it (`restart`) if the core has work.
        clock.armed = NOT_ARMED;
        clock.next_armed = NOT_ARMED;
        clock.may_keep = false;
    }
    cortex_m::peripheral::SCB::set_pendst();
    true
}

/// Runs both queues' expiries.
///
/// # Safety
///
/// Only from the SysTick exception, which drives both queues.
unsafe fn run_queues() {
    // SAFETY: the caller's (the SysTick exception).
    unsafe {
        PLATFORM_QUEUE.on_monotonic_interrupt();
        APP_QUEUE.on_interrupt();
    }
}

/// A single-board run's host file `clock.bin`, where SysTick's interrupt writes the stamps of its
/// busy ticks ([`stamp_busy_ticks`]; `usize::MAX`: none, a robot run or no file).
static CLOCK_FILE: AtomicUsize = AtomicUsize::new(usize::MAX);

/// A single-board run: SysTick's periodic interrupt stamps every tick that does more than a plain
/// tick ([`busy_queues`]) into the host file `file` (see [`SysTick`]).
pub(super) fn stamp_busy_ticks(file: Option<usize>) {
    CLOCK_FILE.store(file.unwrap_or(usize::MAX), Ordering::Relaxed);
}

/// Periodic: which queues this tick must check, (platform, apps): a queue whose head changed since
/// the last tick (rtic-time pended the interrupt for it, [`APP_ASKED`]) or whose deadline has come
/// (an expiry, a task woken). A tick with neither is a plain tick: both checks would find nothing.
/// Counts the wrap that raised the interrupt (`now_ticks`), as the checks would.
fn busy_queues(cs: CriticalSection<'_>) -> (bool, bool) {
    let now = now_ticks();
    let platform = PLATFORM_ASKED.swap(false, Ordering::Relaxed) || PLATFORM_DUE.get(cs) <= now;
    let app = APP_ASKED.swap(false, Ordering::Relaxed) || APP_DUE.get(cs) <= now;
    (platform, app)
}

/// Periodic: the trace clock ([`now_cycles`]) where nothing pre-empts the caller (SysTick's
/// interrupt): the counter, then whether SysTick wrapped meanwhile (counted, and read again), with
/// one look at the tick count instead of two.
fn tick_cycles() -> u64 {
    loop {
        // SAFETY: a read of SysTick's current value, which has no side effects.
        let value = unsafe { core::ptr::read_volatile(SYST_CVR) };
        if !has_wrapped() {
            return PERIODIC.load(Ordering::Relaxed) * CYCLES_PER_TICK
                + (CYCLES_PER_TICK - 1).saturating_sub(u64::from(value));
        }
        PERIODIC.fetch_add(1, Ordering::AcqRel);
    }
}

/// The platform clock's interrupt.
///
/// **Stamped busy ticks (a single-board run).** A single-board run stays periodic (a tick every
/// [`TICK_US`]: a tickless interrupt costs some 300–600 instructions against a plain tick's
/// hundred, and DiWheelDrive's `hostile` scenario, a frame every 20 µs, overran its receive FIFO
/// tickless; docs/bench.md, "The QEMU tick"). Every tick that does more than a plain tick
/// ([`busy_queues`]) is a stamped run of its own: it reads the trace clock before and after the
/// queues' checks and writes the two readings, raw, to the host file `clock.bin`
/// (`amiro_trace::clock_run`: 16 bytes, one semihosting write, no encoding); the bench reads each
/// pair as a task-start/task-end pair of the platform clock (`amiro_trace::PLATFORM_CLOCK_TASK`)
/// and takes such a tick out of the job it interrupts like any pre-empting run. A plain tick is
/// not stamped (the bench counts it at its fewest) and leaves both queues alone, as a tickless
/// interrupt does (their checks would find nothing: no head changed, none due), so it runs a few
/// dozen instructions, not a hundred, and a busy tick checks only the queues it must:
/// `hostile` overran its FIFO with the stamps alone (10 overruns; 1 with plain ticks left alone). Two
/// encoded trace records per busy tick cost it about 1 000 instructions more, and
/// PowerManagement's `flood` then starved its ring publisher.
#[no_mangle]
#[allow(non_snake_case)]
unsafe extern "C" fn SysTick() {
    if !TICKLESS.load(Ordering::Relaxed) {
        let file = CLOCK_FILE.load(Ordering::Relaxed);
        // SAFETY: SysTick's interrupt, the highest priority: nothing that writes the deadlines
        // pre-empts it (`Due::get`).
        if file == usize::MAX {
            // SAFETY: this is the SysTick exception.
            unsafe { run_queues() };
            return;
        }
        // SAFETY: as above.
        let (platform, app) = busy_queues(unsafe { CriticalSection::new() });
        if platform || app {
            let start = tick_cycles();
            // SAFETY (both): this is the SysTick exception, which drives both queues.
            if platform {
                unsafe { PLATFORM_QUEUE.on_monotonic_interrupt() };
            }
            if app {
                unsafe { APP_QUEUE.on_interrupt() };
            }
            let end = tick_cycles();
            super::write_trace_to(file, &amiro_trace::clock_run::encode(start, end));
        }
        return;
    }
    // SAFETY: SysTick's interrupt, the highest priority: nothing that touches the clock or the
    // deadlines pre-empts it (`unpreempted`), which is all the clock's critical sections ensure.
    let cs = unsafe { CriticalSection::new() };
    // A deadline that came while the queues ran is expired in this interrupt too (module docs,
    // "No held reading").
    // A queue whose head did not change and whose deadline has not come is left alone: its expiry
    // check would read the clock twice and take rtic-time's critical section to find nothing.
    let mut now = ticks_at(cs, &mut CLOCK.borrow_ref_mut(cs));
    loop {
        if PLATFORM_ASKED.load(Ordering::Relaxed) || PLATFORM_DUE.get(cs) <= now {
            PLATFORM_ASKED.store(false, Ordering::Relaxed);
            // SAFETY: this is the SysTick exception.
            unsafe { PLATFORM_QUEUE.on_monotonic_interrupt() };
        }
        if APP_ASKED.load(Ordering::Relaxed) || APP_DUE.get(cs) <= now {
            APP_ASKED.store(false, Ordering::Relaxed);
            // SAFETY: this is the SysTick exception.
            unsafe { APP_QUEUE.on_interrupt() };
        }
        now = ticks_at(cs, &mut CLOCK.borrow_ref_mut(cs));
        let due = APP_DUE.get(cs).min(PLATFORM_DUE.get(cs));
        if due > now {
            break;
        }
    }
    // A core left idle by this interrupt goes to its next deadline at once (`skip_to_deadline`):
    // SysTick need not be set up for it (a restart costs QEMU a timer expiry).
    if !super::robot::idle_after_systick() {
        restart(cs, &mut CLOCK.borrow_ref_mut(cs));
    }
}
