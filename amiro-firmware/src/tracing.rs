//! The task-level trace: which task ran when, on the trace channel in the `amiro_trace` record
//! format (docs/bench.md), for `cargo xtask bench`.
//!
//! One guard per task in the board's app, nothing else: a bound interrupt opens a [`job`] whose
//! drop ends it; an async task calls [`enter`] once, and the runtime's await points (the
//! monotonic's waits, the command queue, the publisher's wake-up) end the task's run before they
//! suspend it — with its next timer release, so the host knows when the next job was due — and
//! start it again when it resumes. The running task is kept here (`current`, and for each task the
//! one it pre-empted), which is exact on one core: a task only runs while everything it pre-empted
//! waits.
//!
//! Timestamps: the DWT cycle counter widened to 64 bits on the robot (the watchdog task's run every
//! 100 ms is far inside the counter's 59 s wrap at 72 MHz); in QEMU, SysTick's ticks and its
//! current value (core cycles of the QEMU machine, in virtual time).
//!
//! The cargo feature `task-trace` (on by default in every board) compiles the task records in;
//! without it [`job`], [`enter`], [`suspend`], [`resume`] and [`frame_acked`] are empty and only the
//! handler events and the boot record remain on the channel. Its cost per job is a term of each
//! board's timing file (`trace` in schedule-analysis/models/*.timing.json).
use core::cell::UnsafeCell;

use amiro_trace::{Kind, Record};
use critical_section::{CriticalSection, Mutex};

/// The task number of "no task" (init or idle).
pub const NO_TASK: u8 = u8::MAX;

/// Tasks a board may have (task numbers are below this).
pub const MAX_TASKS: usize = 32;

struct State {
    #[cfg(feature = "task-trace")]
    current: u8,
    #[cfg(feature = "task-trace")]
    preempted: [u8; MAX_TASKS],
    #[cfg(not(feature = "qemu"))]
    high: u32,
    #[cfg(not(feature = "qemu"))]
    last: u32,
    #[cfg(feature = "qemu")]
    last: u64,
    lost: u32,
    wire: [u8; amiro_trace::MAX_WIRE],
}

static STATE: Mutex<UnsafeCell<State>> = Mutex::new(UnsafeCell::new(State {
    #[cfg(feature = "task-trace")]
    current: NO_TASK,
    #[cfg(feature = "task-trace")]
    preempted: [NO_TASK; MAX_TASKS],
    #[cfg(not(feature = "qemu"))]
    high: 0,
    #[cfg(not(feature = "qemu"))]
    last: 0,
    #[cfg(feature = "qemu")]
    last: 0,
    lost: 0,
    wire: [0; amiro_trace::MAX_WIRE],
}));

/// The trace state, inside a critical section. Not a `RefCell`: its borrow check would bring a
/// panic path (and the formatting machinery) into every image for a borrow that cannot fail.
/// Each critical section below takes it once and nothing it calls takes it again (the sinks write
/// to RTT or the console), so the reference is unique.
#[allow(clippy::mut_from_ref)]
fn state_in(cs: CriticalSection<'_>) -> &mut State {
    // SAFETY: interrupts are off for `cs`'s lifetime (one core), and every caller takes the state
    // once per critical section and does not re-enter (see above).
    unsafe { &mut *STATE.borrow(cs).get() }
}

/// The trace clock, widened to 64 bits (robot: DWT CYCCNT).
#[cfg(not(feature = "qemu"))]
fn cycles(state: &mut State) -> u64 {
    const DWT_CYCCNT: *const u32 = 0xE000_1004 as *const u32;
    // SAFETY: a read of the DWT cycle counter, enabled by `start_clock`.
    let now = unsafe { core::ptr::read_volatile(DWT_CYCCNT) };
    if now < state.last {
        state.high = state.high.wrapping_add(1);
    }
    state.last = now;
    u64::from(state.high) << 32 | u64::from(now)
}

/// The trace clock in QEMU: the platform clock's cycles (`qemu::timer`: the start of SysTick's
/// running period plus how far it has counted down). QEMU updates its SysTick lazily, so around a
/// wrap a reading can come out a little early: the clock holds every reading at or above the one
/// before, so the records stay in order.
#[cfg(feature = "qemu")]
fn cycles(state: &mut State) -> u64 {
    let now = crate::qemu::timer::now_cycles().max(state.last);
    state.last = now;
    now
}

/// Enables the DWT cycle counter (robot) and writes the boot record with the clock's rate.
pub fn start_clock(clock_hz: u32) {
    #[cfg(not(feature = "qemu"))]
    // SAFETY: DEMCR.TRCENA and DWT_CTRL.CYCCNTENA only enable the cycle counter; nothing else in
    // the firmware uses the DWT.
    unsafe {
        const DEMCR: *mut u32 = 0xE000_EDFC as *mut u32;
        const DWT_CTRL: *mut u32 = 0xE000_1000 as *mut u32;
        core::ptr::write_volatile(DEMCR, core::ptr::read_volatile(DEMCR) | 1 << 24);
        core::ptr::write_volatile(DWT_CTRL, core::ptr::read_volatile(DWT_CTRL) | 1);
    }
    hello(clock_hz);
}

/// Writes the boot record again (the clock plan changed: DiWheelDrive's internal-oscillator
/// fallback runs at 64 MHz).
pub fn hello(clock_hz: u32) {
    emit(Kind::Hello { clock_hz });
}

/// Stamps and writes one record into the trace channel.
fn emit(kind: Kind) {
    critical_section::with(|cs| write(state_in(cs), kind, crate::channels::write_trace));
}

/// Stamps and writes one record into `sink`, in the caller's critical section (so a task record's
/// state change and its record are one step). A record that does not fit is counted and reported
/// by the next one that does. One copy for every kind (flash).
#[inline(never)]
fn write(state: &mut State, kind: Kind, sink: fn(&[u8]) -> bool) {
    let at = cycles(state);
    // The buffer lives in the state: a stack array would be cleared on every record.
    let wire = &mut state.wire;
    if state.lost > 0 {
        let lost = Record {
            cycles: at,
            kind: Kind::Lost { count: state.lost },
        };
        let n = lost.encode_into(wire);
        if sink(&wire[..n]) {
            state.lost = 0;
        }
    }
    let n = Record { cycles: at, kind }.encode_into(wire);
    if !sink(&wire[..n]) {
        state.lost = state.lost.saturating_add(1);
    }
}

/// A handler event (`amiro_sensors::trace` record), with the trace clock's stamp. (QEMU sends it to
/// the console, in order with the other lines.)
pub fn event(record: &[u8; amiro_trace::EVENT_LEN]) {
    let kind = Kind::Event { record: *record };
    #[cfg(not(feature = "qemu"))]
    emit(kind);
    #[cfg(feature = "qemu")]
    critical_section::with(|cs| write(state_in(cs), kind, crate::channels::write_console_record));
}

/// A running job of a bound interrupt; dropping it ends the job.
#[must_use = "the job ends when this is dropped"]
pub struct Job(#[cfg(feature = "task-trace")] u8);

/// Starts the job of task `task` (a bound interrupt's first line: `let _job = tracing::job(..)`).
#[inline(always)]
pub fn job(task: u8) -> Job {
    enter(task);
    #[cfg(feature = "task-trace")]
    return Job(task);
    #[cfg(not(feature = "task-trace"))]
    Job()
}

impl Drop for Job {
    #[inline(always)]
    fn drop(&mut self) {
        #[cfg(feature = "task-trace")]
        end(self.0, u32::MAX);
    }
}

/// Task `task` starts (or resumes) running: an async task's first line.
#[inline(always)]
pub fn enter(task: u8) {
    #[cfg(feature = "task-trace")]
    start(task);
    #[cfg(not(feature = "task-trace"))]
    let _ = task;
}

#[cfg(feature = "task-trace")]
#[inline(never)]
fn start(task: u8) {
    critical_section::with(|cs| {
        let state = state_in(cs);
        if let Some(slot) = state.preempted.get_mut(usize::from(task)) {
            *slot = state.current;
            state.current = task;
        }
        write(
            state,
            Kind::TaskStart { task },
            crate::channels::write_trace,
        );
    });
}

#[cfg(feature = "task-trace")]
#[inline(never)]
fn end(task: u8, next_release_in_us: u32) {
    critical_section::with(|cs| {
        let state = state_in(cs);
        if let Some(&before) = state.preempted.get(usize::from(task)) {
            state.current = before;
        }
        let kind = Kind::TaskEnd {
            task,
            next_release_in_us,
        };
        write(state, kind, crate::channels::write_trace);
    });
}

/// The running task is about to wait (its run ends): for a timer, its next release `at_us` with
/// the clock at `now_us`; for a message, `None`. Returns the task, for [`resume`].
#[inline(always)]
pub fn suspend(release: Option<(u64, u64)>) -> u8 {
    #[cfg(feature = "task-trace")]
    {
        let task = critical_section::with(|cs| state_in(cs).current);
        if task != NO_TASK {
            let next = release.map_or(u32::MAX, |(at, now)| {
                u32::try_from(at.saturating_sub(now)).map_or(u32::MAX - 1, |d| d.min(u32::MAX - 1))
            });
            end(task, next);
        }
        task
    }
    #[cfg(not(feature = "task-trace"))]
    {
        let _ = release;
        NO_TASK
    }
}

/// The task [`suspend`] returned runs again.
#[inline(always)]
pub fn resume(task: u8) {
    #[cfg(feature = "task-trace")]
    if task != NO_TASK {
        start(task);
    }
    #[cfg(not(feature = "task-trace"))]
    let _ = task;
}

/// A frame's transmission completed (acknowledged on the bus).
#[inline(always)]
pub fn frame_acked(id: u16) {
    #[cfg(feature = "task-trace")]
    emit(Kind::FrameAcked { id });
    #[cfg(not(feature = "task-trace"))]
    let _ = id;
}
