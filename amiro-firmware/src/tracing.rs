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
//! Timestamps: the DWT cycle counter on the robot, stamped raw (32 bits) and widened to 64 by the
//! drain, which takes the records in the order of their stamps (`trace_ring::Widen`; the watchdog
//! task's run every 100 ms is far inside the counter's 59 s wrap at 72 MHz); in QEMU, SysTick's
//! ticks and its current value (core cycles of the QEMU machine, in virtual time).
//!
//! The cargo feature `task-trace` (on by default in every board) compiles the task records in;
//! without it [`job`], [`enter`], [`suspend`], [`resume`] and [`frame_acked`] are empty and only the
//! handler events and the boot record remain on the channel. Its cost per job is a term of each
//! board's timing file (`trace` in schedule-analysis/models/*.timing.json).
//!
//! Two halves, so a task's cost for its records is a constant: a task stamps each record and copies
//! it raw (its stamp and its kind, or the handler event unencoded: 40 bytes) into a static ring of
//! [`RING_LEN`] — no encoding, no loop of unknown length, no channel. Only the slot's reservation
//! and the stamp run with interrupts off (a few instructions); the copy runs after, outside the
//! critical section, and marks the slot complete (`crate::trace_ring`, which argues why a
//! preempting writer and the drain never touch a slot being copied). The board's `drain_trace`
//! task, at priority 0 (thread mode, beside `admit_requests`), calls [`serve_drain`]: each of its
//! jobs ([`drain`]) takes at most [`DRAIN_BATCH`] complete records out of the ring (each copied out
//! between two short critical sections), COBS-encodes them and writes them to the trace channel
//! (RTT on the robot), and writes at most one log line a handler deferred
//! (`channels::defer_log`); before its batch it stamps the handler event a handler deferred
//! ([`defer_event`]: `can_status`' bus-state change, four words stored under a short critical
//! section, so the most urgent handler pays no record). A full ring counts the record as lost, and the drain reports the count
//! (`Kind::Lost`) before the next record it writes.
//!
//! The QEMU build writes through instead: each record is encoded and written to `trace.bin` or the
//! console as it is stamped, as before the ring, and its drain finds nothing to do. The bench needs
//! every record, the scenarios read the handler events in their place among the console's other
//! lines (LightRing's latch lines), and under the scenarios' floods thread mode gets no time for
//! a drain; a QEMU job's trace cost is the timing file's `trace.qemu` term (docs/analysis.md,
//! "The trace path", says why and how the analysis counts either build).
use core::cell::UnsafeCell;
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};

use amiro_sensors::trace::TraceEvent;
use amiro_trace::{Kind, Record};
use critical_section::{CriticalSection, Mutex};

#[cfg(not(feature = "qemu"))]
use crate::trace_ring::{Claim, Ring, Widen};

/// The task number of "no task" (init or idle).
pub const NO_TASK: u8 = u8::MAX;

/// Tasks a board may have (task numbers are below this).
pub const MAX_TASKS: usize = 32;

/// Records the ring holds (a power of two): 32, 1.25 KiB of RAM. The drain runs whenever thread
/// mode is free, so the ring holds what the tasks stamp while an admission step (up to 8.6 ms on
/// the F103) keeps it from running; beyond 32 records the ring loses them (counted and reported).
pub const RING_LEN: usize = 32;

/// The most records one drain job ([`drain`]) writes: the bound of its loop, and so of its job.
pub const DRAIN_BATCH: usize = 4;

/// What a record says before it is encoded: a record's kind, or a handler event whose 18 bytes
/// the drain encodes (`TraceEvent::encode`, whose field loops so stay out of the task).
#[derive(Clone, Copy)]
#[repr(u8)]
enum What {
    Kind(Kind) = 0,
    /// Written by [`event`] as an [`EventWhat`], never built as a `What`.
    #[cfg(not(feature = "qemu"))]
    #[allow(dead_code)]
    Event(TraceEvent) = EVENT_TAG,
}

/// [`What::Event`]'s tag.
#[cfg(not(feature = "qemu"))]
const EVENT_TAG: u8 = 1;

/// [`What::Event`] as the language lays it out (a `repr(u8)` enum's variant is a `repr(C)` struct
/// of its tag and its fields), so [`event`] can write the tag and copy the event into a slot
/// without building the whole `What` first.
#[cfg(not(feature = "qemu"))]
#[repr(C)]
struct EventWhat {
    tag: u8,
    event: TraceEvent,
}

/// One record as the tasks stamp it: when, and what (raw, fixed size).
#[cfg(not(feature = "qemu"))]
#[derive(Clone, Copy)]
struct Slot {
    /// The DWT counter as read under the reservation; the drain widens it.
    cycles: u32,
    what: What,
}

/// A free slot's contents (never written out: only complete slots are read). All zero bytes, so
/// the ring lives in `.bss`, not in `.data` with its image in flash.
#[cfg(not(feature = "qemu"))]
const EMPTY: Slot = Slot {
    cycles: 0,
    what: What::Kind(Kind::Hello { clock_hz: 0 }),
};

struct State {
    #[cfg(feature = "task-trace")]
    current: u8,
    #[cfg(feature = "task-trace")]
    preempted: [u8; MAX_TASKS],
    /// The drain's widening of the raw stamps (only the drain uses it).
    #[cfg(not(feature = "qemu"))]
    clock: Widen,
    #[cfg(feature = "qemu")]
    last: u64,
}

static STATE: Mutex<UnsafeCell<State>> = Mutex::new(UnsafeCell::new(State {
    #[cfg(feature = "task-trace")]
    current: NO_TASK,
    #[cfg(feature = "task-trace")]
    preempted: [NO_TASK; MAX_TASKS],
    #[cfg(not(feature = "qemu"))]
    clock: Widen::new(),
    #[cfg(feature = "qemu")]
    last: 0,
}));

/// The records stamped and not yet written: reserved under a writer's critical section, written
/// by that writer and read by the drain outside any (`crate::trace_ring`).
#[cfg(not(feature = "qemu"))]
// SAFETY: both chips are single-core; the ring's writers and drain run on that core.
static RING: Ring<Slot, RING_LEN> = unsafe { Ring::new(EMPTY) };

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

/// The trace clock as a record's writer stamps it (robot: DWT CYCCNT, 32 bits; the drain widens
/// it): one load, where widening it here was a call and a read-modify-write of the state.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn raw_cycles() -> u32 {
    const DWT_CYCCNT: *const u32 = 0xE000_1004 as *const u32;
    // SAFETY: a read of the DWT cycle counter, enabled by `start_clock`.
    unsafe { core::ptr::read_volatile(DWT_CYCCNT) }
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
    emit(What::Kind(Kind::Hello { clock_hz }));
}

/// Stamps one record into the ring.
// QEMU's `Reserved` is `()`: the record went through in the critical section.
#[cfg_attr(feature = "qemu", allow(clippy::let_unit_value))]
fn emit(what: What) {
    let reserved = critical_section::with(|cs| write(state_in(cs), &what));
    fill(reserved, &what);
}

/// A slot reserved for a record and its stamp, to fill outside the critical section ([`fill`]);
/// `None` when the full ring counted the record as lost.
#[cfg(not(feature = "qemu"))]
type Reserved = Option<(Claim<'static, Slot, RING_LEN>, u32)>;
/// QEMU: the record was written through ([`write`]); nothing to fill.
#[cfg(feature = "qemu")]
type Reserved = ();

/// Stamps one record and reserves its slot, in the caller's critical section (so a task record's
/// state change, its stamp and its place in the ring are one step): a few instructions, no copy.
/// A full ring counts it as lost.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn write(_state: &mut State, _what: &What) -> Reserved {
    reserve()
}

/// [`write`]'s reservation and stamp, which do not depend on the record. Call it under a critical
/// section: the stamps are then in the order of the slots, which the drain's widening needs.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn reserve() -> Reserved {
    // SAFETY: every reservation runs under a critical section (the caller's).
    let claim = unsafe { RING.reserve() }?;
    Some((claim, raw_cycles()))
}

/// Copies a record into the slot [`write`] reserved and marks it complete, outside any critical
/// section: a fixed-size copy, no loop of unknown length. Inlined: the production image has one
/// writer ([`emit`]), the traced one three.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn fill(reserved: Reserved, what: &What) {
    if let Some((claim, cycles)) = reserved {
        claim.fill(|slot| {
            slot.cycles = cycles;
            copy_words(what, &mut slot.what);
        });
    }
}

/// QEMU: the record was written through.
#[cfg(feature = "qemu")]
fn fill(_reserved: Reserved, _what: &What) {}

/// Words of a [`What`].
#[cfg(not(feature = "qemu"))]
const WHAT_WORDS: usize = core::mem::size_of::<What>() / 4;

/// Copies `from` into `to`: two 4-word `LDM`/`STM` pairs, 4 instructions of straight-line code (a
/// `memcpy` call would be charged by the execution-time bound at its byte loop's cost, as it
/// cannot know the alignment; a loop of words costs a taken branch per word).
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn copy_words(from: &What, to: &mut What) {
    const {
        assert!(WHAT_WORDS == 8 && core::mem::size_of::<What>() == 4 * WHAT_WORDS);
        assert!(core::mem::align_of::<What>() >= 4);
    }
    // SAFETY: both point to a `What`: word-aligned (LDM/STM need it), 8 whole words, `to` unique;
    // the words are moved as they are (padding included), read from `from` and written to `to`
    // only. r0-r3 are declared clobbered, the pointers consumed.
    unsafe {
        core::arch::asm!(
            "ldm {from}!, {{r0, r1, r2, r3}}",
            "stm {to}!, {{r0, r1, r2, r3}}",
            "ldm {from}, {{r0, r1, r2, r3}}",
            "stm {to}, {{r0, r1, r2, r3}}",
            from = inout(reg) core::ptr::from_ref(from) => _,
            to = inout(reg) core::ptr::from_mut(to) => _,
            out("r0") _,
            out("r1") _,
            out("r2") _,
            out("r3") _,
            options(nostack, preserves_flags),
        );
    }
}

/// Copies a handler event (6 words) into a slot: two 3-word `LDM`/`STM` pairs of straight-line
/// code, where the compiler called `memcpy` ([`copy_words`] says why not that).
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn copy_event(from: &TraceEvent, to: &mut TraceEvent) {
    const {
        assert!(core::mem::size_of::<TraceEvent>() == 24);
        assert!(core::mem::align_of::<TraceEvent>() >= 4);
    }
    // SAFETY: both point to a `TraceEvent`: word-aligned, 6 whole words, `to` unique; the words
    // are moved as they are (padding included), read from `from` and written to `to` only. r0-r2
    // are declared clobbered, the pointers consumed.
    unsafe {
        core::arch::asm!(
            "ldm {from}!, {{r0, r1, r2}}",
            "stm {to}!, {{r0, r1, r2}}",
            "ldm {from}, {{r0, r1, r2}}",
            "stm {to}, {{r0, r1, r2}}",
            from = inout(reg) core::ptr::from_ref(from) => _,
            to = inout(reg) core::ptr::from_mut(to) => _,
            out("r0") _,
            out("r1") _,
            out("r2") _,
            options(nostack, preserves_flags),
        );
    }
}

/// QEMU: stamps one record and writes it through, in the caller's critical section: a handler
/// event to the console as a `# T` line, the rest to `trace.bin` (a handler event arrives encoded:
/// [`event`]).
#[cfg(feature = "qemu")]
#[inline(never)]
fn write(state: &mut State, what: &What) {
    // A task record with nowhere to go (a robot run writes no `trace.bin`) is neither stamped nor
    // encoded: the stamp is a clock reading, which QEMU runs outside its translated code, and the
    // encoding some hundred instructions of the board's virtual time, for a record dropped anyway
    // (about 10 000 per virtual second on DiWheelDrive in the thesis demo). The handler events'
    // `# T` lines are written as before. The file is looked up once, here, where
    // `channels::write_trace` looked it up before, and the record is looked at in place (a copy of
    // it cost a single-board run's every record a byte-wise copy: the hostile scenario's receive
    // path is close enough to overrunning its FIFO that it did, 38 times).
    let file = crate::qemu::trace_file();
    if file.is_none() && !matches!(what, What::Kind(Kind::Event { .. })) {
        return;
    }
    let What::Kind(kind) = *what;
    let record = Record {
        cycles: cycles(state),
        kind,
    };
    let mut wire = [0u8; amiro_trace::MAX_WIRE];
    let n = record.encode_into(&mut wire);
    let bytes = wire.get(..n).unwrap_or(&[]);
    if let Kind::Event { .. } = record.kind {
        crate::channels::write_console_record(bytes);
    } else if let Some(fd) = file {
        crate::qemu::write_trace_to(fd, bytes);
    }
}

/// Encodes one record (a handler event's fields first) and writes it to the trace channel; `false`
/// when the channel had no room for it. One copy of the encoders (flash).
#[cfg(not(feature = "qemu"))]
#[inline(never)]
fn write_out(cycles: u64, what: &What) -> bool {
    let record = Record {
        cycles,
        kind: match *what {
            What::Kind(kind) => kind,
            What::Event(event) => Kind::Event {
                record: event.encode(),
            },
        },
    };
    let mut wire = [0u8; amiro_trace::MAX_WIRE];
    let n = record.encode_into(&mut wire);
    crate::channels::write_trace(wire.get(..n).unwrap_or(&[]))
}

/// One job of the drain: writes at most [`DRAIN_BATCH`] records from the ring to the trace channel
/// (a `Lost` report, when the ring turned some away, is one of them) and at most one deferred log
/// line. Called by [`serve_drain`]; bounded by its batch.
#[inline(never)]
pub fn drain() {
    #[cfg(not(feature = "qemu"))]
    emit_deferred_event();
    for _ in 0..DRAIN_BATCH {
        if !drain_one() {
            break;
        }
    }
    crate::channels::write_deferred_log();
}

/// The handler event a handler left for the drain ([`defer_event`]), as four words: its `at_us`
/// (low, high), [`DEFERRED_HELD`] with the bus state and the error counters, and how many events
/// it replaced before the drain took it (each counted as a lost record). Words, so that its
/// critical sections move four words at known addresses (a `TraceEvent` would be a byte copy).
#[cfg(not(feature = "qemu"))]
static DEFERRED: Mutex<core::cell::Cell<[u32; 4]>> = Mutex::new(core::cell::Cell::new([0; 4]));

/// The third word's mark of a deferred event waiting.
#[cfg(not(feature = "qemu"))]
const DEFERRED_HELD: u32 = 1 << 24;

/// Stamps the handler event a handler deferred into the ring, as [`event`] would have (the drain,
/// once per job, before its batch): its record's stamp is the drain's, its `at_us` the handler's.
/// The events it replaced are reported as lost.
#[cfg(not(feature = "qemu"))]
fn emit_deferred_event() {
    let [low, high, held, replaced] =
        critical_section::with(|cs| DEFERRED.borrow(cs).replace([0; 4]));
    if replaced > 0 {
        // SAFETY: the drain is the ring's only drain (`drain_trace`, one task).
        unsafe { RING.count_lost(replaced) };
    }
    if held & DEFERRED_HELD != 0 {
        let kind = amiro_sensors::trace::TraceKind::CanBusState {
            state: (held >> 16) as u8,
            tec: (held >> 8) as u8,
            rec: held as u8,
        };
        event(&TraceEvent::new(
            u64::from(high) << 32 | u64::from(low),
            kind,
        ));
    }
}

/// Writes one record: a `Lost` report when the ring turned records away since the last one, else
/// the oldest record of the ring once its writer has completed it; `false` when there was none.
/// The record is copied out of the ring without a critical section (`crate::trace_ring`; only a
/// `Lost` report's stamp takes one), then encoded and written (the drain is the trace channel's
/// only writer); one the channel has no room for is counted as lost.
#[cfg(not(feature = "qemu"))]
fn drain_one() -> bool {
    let mut slot = EMPTY;
    // SAFETY (the three calls on `RING`): this is its only drain (`drain_trace`, one task).
    let count = unsafe { RING.take_lost() };
    let cycles = if count > 0 {
        // Stamped now, later than the records still in the ring: widened without moving the
        // widening past them.
        let now = raw_cycles();
        slot.what = What::Kind(Kind::Lost { count });
        critical_section::with(|cs| state_in(cs).clock.peek(now))
    } else if unsafe { RING.take(&mut slot) } {
        // The records leave in the order of their stamps (`reserve`).
        critical_section::with(|cs| state_in(cs).clock.advance(slot.cycles))
    } else {
        // Empty, or its oldest record's writer was preempted mid-copy: the next job takes it.
        return false;
    };
    if !write_out(cycles, &slot.what) {
        let count = match slot.what {
            What::Kind(Kind::Lost { count }) => count,
            _ => 1,
        };
        unsafe { RING.count_lost(count) };
    }
    true
}

/// QEMU: the records were written as they were stamped; nothing waits.
#[cfg(feature = "qemu")]
fn drain_one() -> bool {
    false
}

/// The drain task's body (priority 0): a future that never completes, each poll one [`drain`]
/// job; it wakes its own task before it returns, so the thread-mode executor polls it again after
/// `admit_requests`. A job that finds the ring empty is a few instructions and no critical section
/// but the deferred lines' short one. Parking while the ring is empty would save nothing: RTIC's
/// priority-0 executor polls its tasks in a loop with no `WFI`, so the core would spin there
/// instead (docs/analysis.md, "The trace path").
pub fn serve_drain() -> Drain {
    Drain
}

/// The future [`serve_drain`] returns.
pub struct Drain;

impl Future for Drain {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        drain();
        // QEMU writes every record and deferred line through as it comes: the drain's one poll
        // finds nothing and parks for good, so thread mode still sleeps between events (a
        // self-waking drain kept the emulated core busy and shifted the campaign's timing).
        #[cfg(not(feature = "qemu"))]
        cx.waker().wake_by_ref();
        #[cfg(feature = "qemu")]
        let _ = cx;
        Poll::Pending
    }
}

/// A handler event, with the trace clock's stamp: copied raw, encoded by the drain (QEMU: at once,
/// as a `# T` line on the console, in order with the other lines).
#[inline(never)]
pub fn event(event: &TraceEvent) {
    // One copy, from the caller's event into the slot: not through a `What` on the stack and
    // [`emit`], which would copy it twice (each word loaded and stored at an address the
    // execution-time bound cannot place, so charged as a peripheral's) and a call deeper.
    #[cfg(not(feature = "qemu"))]
    {
        let reserved = critical_section::with(|_| reserve());
        if let Some((claim, cycles)) = reserved {
            claim.fill(|slot| fill_event(slot, cycles, event));
        }
    }
    // QEMU: encoded before the critical section, as the robot's drain does outside it.
    #[cfg(feature = "qemu")]
    emit(What::Kind(Kind::Event {
        record: event.encode(),
    }));
}

/// [`event`]'s record in `slot`.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn fill_event(slot: &mut Slot, cycles: u32, event: &TraceEvent) {
    slot.cycles = cycles;
    let what = core::ptr::from_mut(&mut slot.what).cast::<EventWhat>();
    // SAFETY: `what` is the slot's `What`, laid out as `EventWhat` once its tag says `Event`
    // (`repr(u8)`): the tag is written and the event copied whole.
    unsafe {
        (*what).tag = EVENT_TAG;
        copy_event(event, &mut (*what).event);
    }
}

/// The transmit interrupt's event for a frame put into a mailbox (`TraceKind::FrameSent`): the
/// record [`event`] writes for it, with the event's fields stored straight into the slot, where
/// [`event`] copies a whole event built on the caller's stack (six words loaded through a pointer
/// the execution-time bound cannot place, so charged at a peripheral's latency, on every frame the
/// interrupt sends; docs/analysis.md, "The transmit interrupt's parts"). The slot's other bytes
/// are the event's padding for that kind, which the drain's encoding never reads. QEMU prints the
/// frame itself as it enters the (virtual) mailbox, so its build has no such event.
#[cfg(not(feature = "qemu"))]
#[inline(never)]
pub fn frame_sent(at_us: u64, id: u16) {
    let reserved = critical_section::with(|_| reserve());
    if let Some((claim, cycles)) = reserved {
        claim.fill(|slot| fill_frame_sent(slot, cycles, at_us, id));
    }
}

/// [`frame_sent`]'s record in `slot`.
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn fill_frame_sent(slot: &mut Slot, cycles: u32, at_us: u64, id: u16) {
    slot.cycles = cycles;
    let what = core::ptr::from_mut(&mut slot.what).cast::<EventWhat>();
    // SAFETY: as in [`event`]: the tag is written, and the event as a whole value.
    unsafe {
        (*what).tag = EVENT_TAG;
        (*what).event = TraceEvent::new(at_us, amiro_sensors::trace::TraceKind::FrameSent { id });
    }
}

/// The events for a frame a publisher pushed into the transmit queue
/// ([`TraceKind::for_push`](amiro_sensors::trace::TraceKind::for_push)'s one or two, stamped
/// `at_us`): [`event`]'s records, with both slots reserved under one critical section and each
/// event's fields stored straight into its slot, where two calls of [`event`] took two critical
/// sections and copied each event from one built on the caller's stack (the copy's loads charged
/// at a peripheral's latency, as [`frame_sent`] says). QEMU writes each through as [`event`] does.
#[inline(never)]
pub fn frame_pushed(at_us: u64, id: u16, outcome: &amiro_sensors::tx_queue::PushOutcome) {
    let (first, second) = amiro_sensors::trace::TraceKind::push_kinds(id, outcome);
    #[cfg(not(feature = "qemu"))]
    {
        let (reserved, reserved_second) = critical_section::with(|_| {
            let first = reserve();
            // The second's slot after the first's, so their stamps are in the slots' order.
            (first, second.and_then(|_| reserve()))
        });
        if let Some((claim, cycles)) = reserved {
            claim.fill(|slot| fill_kind(slot, cycles, at_us, first));
        }
        if let (Some((claim, cycles)), Some(second)) = (reserved_second, second) {
            claim.fill(|slot| fill_kind(slot, cycles, at_us, second));
        }
    }
    #[cfg(feature = "qemu")]
    {
        event(&TraceEvent::new(at_us, first));
        if let Some(second) = second {
            event(&TraceEvent::new(at_us, second));
        }
    }
}

/// An event of `kind` at `at_us` in `slot`, stored in place ([`fill_frame_sent`]'s way).
#[cfg(not(feature = "qemu"))]
#[inline(always)]
fn fill_kind(slot: &mut Slot, cycles: u32, at_us: u64, kind: amiro_sensors::trace::TraceKind) {
    slot.cycles = cycles;
    let what = core::ptr::from_mut(&mut slot.what).cast::<EventWhat>();
    // SAFETY: as in [`event`]: the tag is written, and the event as a whole value.
    unsafe {
        (*what).tag = EVENT_TAG;
        (*what).event = TraceEvent::new(at_us, kind);
    }
}

/// A handler event for the drain to stamp ([`drain`], priority 0), for the handlers whose bound
/// the analysis uses at the most urgent priority (`can_status`'s bus-state change): four words
/// stored into a static under a short critical section, where [`event`]'s stamp, reservation and
/// 40-byte copy into the ring were half of the handler's bound (docs/analysis.md, *Held bounds*).
/// The event keeps its own `at_us`; its record is stamped when the drain writes it. One waits at
/// most: a later one replaces it, and the replaced one is reported as a lost record. Any other
/// kind is written at once ([`event`]); QEMU writes every event through at once, as every record
/// there (in its place among the console's lines).
#[inline(always)]
pub fn defer_event(event: &TraceEvent) {
    #[cfg(not(feature = "qemu"))]
    if let amiro_sensors::trace::TraceKind::CanBusState { state, tec, rec } = event.kind {
        let held = DEFERRED_HELD | u32::from(state) << 16 | u32::from(tec) << 8 | u32::from(rec);
        critical_section::with(|cs| {
            let latch = DEFERRED.borrow(cs);
            let [_, _, waiting, replaced] = latch.get();
            let replaced = replaced.wrapping_add(u32::from(waiting & DEFERRED_HELD != 0));
            latch.set([
                event.at_us as u32,
                (event.at_us >> 32) as u32,
                held,
                replaced,
            ]);
        });
        return;
    }
    self::event(event);
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
// QEMU's `Reserved` is `()`: the record went through in the critical section.
#[cfg_attr(feature = "qemu", allow(clippy::let_unit_value))]
fn start(task: u8) {
    let what = What::Kind(Kind::TaskStart { task });
    let reserved = critical_section::with(|cs| {
        let state = state_in(cs);
        if let Some(slot) = state.preempted.get_mut(usize::from(task)) {
            *slot = state.current;
            state.current = task;
        }
        write(state, &what)
    });
    fill(reserved, &what);
}

#[cfg(feature = "task-trace")]
#[inline(never)]
// QEMU's `Reserved` is `()`: the record went through in the critical section.
#[cfg_attr(feature = "qemu", allow(clippy::let_unit_value))]
fn end(task: u8, next_release_in_us: u32) {
    let what = What::Kind(Kind::TaskEnd {
        task,
        next_release_in_us,
    });
    let reserved = critical_section::with(|cs| {
        let state = state_in(cs);
        if let Some(&before) = state.preempted.get(usize::from(task)) {
            state.current = before;
        }
        write(state, &what)
    });
    fill(reserved, &what);
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

/// [`suspend`] for a timer wait until `at_us`, the clock read through `now_us` only where the trace
/// records the wait (`task-trace`): a build without task tracing reads no clock for it (the
/// timer waits of the periodic tasks and every publisher release, `mono::Clock::delay_until_us`
/// and `timeout_at_us`).
#[inline(always)]
pub fn suspend_until(at_us: u64, now_us: impl FnOnce() -> u64) -> u8 {
    #[cfg(feature = "task-trace")]
    return suspend(Some((at_us, now_us())));
    #[cfg(not(feature = "task-trace"))]
    {
        let _ = (at_us, now_us);
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
    emit(What::Kind(Kind::FrameAcked { id }));
    #[cfg(not(feature = "task-trace"))]
    let _ = id;
}
