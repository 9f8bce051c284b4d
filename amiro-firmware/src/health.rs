//! The board's health, counted where it happens and answered on the board's diagnostics topic.
//!
//! Every board publishes its diagnostics topic (DiWheelDrive `0x1A`, PowerManagement `0x1B`,
//! LightRing `0x1C`) like any sensor topic: a one-shot or a periodic publisher, six frames per
//! sample (`amiro_can::Diagnostics`, `docs/protocol.md`). The publisher loop builds the sample here
//! from the handler's command counters, the transmit queue's counters and the counters below.
use core::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};

use amiro_can::{
    Board, Diagnostics, Frame, Priority, RefusalReason, ResetCause, StatusFlags, PAGES_PER_SAMPLE,
    REFUSAL_REASONS,
};
use amiro_sensors::handler::SensorDataHandler;
use amiro_sensors::tx_queue::TxCounters;

static DEADLINE_MISSES: [AtomicU32; 4] = [const { AtomicU32::new(0) }; 4];
static LATE_FRAMES: AtomicU32 = AtomicU32::new(0);
static ADMISSION_REFUSED: AtomicU32 = AtomicU32::new(0);
static ADMISSION_WARNED: AtomicU32 = AtomicU32::new(0);
static REFUSALS: [AtomicU32; REFUSAL_REASONS] = [const { AtomicU32::new(0) }; REFUSAL_REASONS];
/// Sensor groups a board may report (one per bus or device group).
pub const SENSOR_GROUPS: usize = 8;
static GROUP_FAULTS: [AtomicU32; SENSOR_GROUPS] = [const { AtomicU32::new(0) }; SENSOR_GROUPS];
static GROUPS_FAULTY: AtomicU8 = AtomicU8::new(0);
static ERROR_PASSIVE: AtomicU32 = AtomicU32::new(0);
static BUS_OFF: AtomicU32 = AtomicU32::new(0);
static PASSIVE_NOW: AtomicBool = AtomicBool::new(false);
static CLOCK_FALLBACK: AtomicBool = AtomicBool::new(false);
static WATCHDOG_RUNNING: AtomicBool = AtomicBool::new(false);
static RESET_CAUSE: AtomicU8 = AtomicU8::new(0);
static WINDOW: AtomicU8 = AtomicU8::new(0);

/// Counts `n` deadline misses at CAN priority `level`: releases skipped because a publisher fell
/// a full period behind, or a frame that reached its mailbox after its release's deadline.
pub fn count_deadline_misses(level: Priority, n: u32) {
    if let Some(counter) = DEADLINE_MISSES.get(level as usize) {
        counter.fetch_add(n, Ordering::Relaxed);
    }
}

/// Counts a frame that left its publisher after the deadline of its release (also counted as a
/// deadline miss of its level).
pub fn count_late_frame(level: Priority) {
    LATE_FRAMES.fetch_add(1, Ordering::Relaxed);
    count_deadline_misses(level, 1);
}

/// Frames that left after their release's deadline.
pub fn late_frames() -> u32 {
    LATE_FRAMES.load(Ordering::Relaxed)
}

/// Counts an admission verdict: refused, or accepted with a warning, and its reason.
pub fn count_admission(refused: bool, reason: RefusalReason) {
    if refused {
        ADMISSION_REFUSED.fetch_add(1, Ordering::Relaxed);
    } else {
        ADMISSION_WARNED.fetch_add(1, Ordering::Relaxed);
    }
    if let Some(counter) = REFUSALS.get(reason as usize) {
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// Requests refused by the admission check or for a full admission queue (not those warned about), since boot.
pub fn admission_refused() -> u32 {
    ADMISSION_REFUSED.load(Ordering::Relaxed)
}

static RX_DROPPED: AtomicU32 = AtomicU32::new(0);
static RX_OVERRUNS: AtomicU32 = AtomicU32::new(0);

/// Counts a received frame the board could not queue for the command handler.
pub fn count_rx_dropped() {
    RX_DROPPED.fetch_add(1, Ordering::Relaxed);
}

/// Counts a receive-FIFO overrun event.
pub fn count_rx_overrun() {
    RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
}

/// Frames the board received but could not queue for the command handler (queue full).
pub fn rx_dropped() -> u32 {
    RX_DROPPED.load(Ordering::Relaxed)
}

/// Receive-FIFO overrun events: each lost at least one frame (a lower bound on frames lost).
pub fn rx_overruns() -> u32 {
    RX_OVERRUNS.load(Ordering::Relaxed)
}

/// Requests refused because the admission queue was full ([`RefusalReason::Busy`]), since boot.
pub fn admission_busy() -> u32 {
    REFUSALS
        .get(RefusalReason::Busy as usize)
        .map_or(0, |c| c.load(Ordering::Relaxed))
}

/// Reports sensor group `group` (0..[`SENSOR_GROUPS`]): its failures since boot and whether it
/// is out of service now. Diagnostics page 0 carries the sum and a "sensor fault now" flag.
pub fn report_sensor_group(group: usize, faults: u32, faulty_now: bool) {
    if let Some(counter) = GROUP_FAULTS.get(group) {
        counter.store(faults, Ordering::Relaxed);
        let bit = 1u8 << group;
        if faulty_now {
            GROUPS_FAULTY.fetch_or(bit, Ordering::Relaxed);
        } else {
            GROUPS_FAULTY.fetch_and(!bit, Ordering::Relaxed);
        }
    }
}

fn sensor_faults() -> u32 {
    GROUP_FAULTS
        .iter()
        .fold(0u32, |sum, c| sum.saturating_add(c.load(Ordering::Relaxed)))
}

/// Records the CAN controller's error episodes (from its `ErrorMonitor`).
pub fn set_can_errors(passive_episodes: u32, bus_off_episodes: u32, passive_now: bool) {
    ERROR_PASSIVE.store(passive_episodes, Ordering::Relaxed);
    BUS_OFF.store(bus_off_episodes, Ordering::Relaxed);
    PASSIVE_NOW.store(passive_now, Ordering::Relaxed);
}

/// Records whether the board runs on anything but the crystal's PLL (`chip::clock_plan`): a
/// clock fault, flagged on diagnostics page 0.
pub fn set_clock_fallback(fallback: bool) {
    CLOCK_FALLBACK.store(fallback, Ordering::Relaxed);
}

/// Notes that the independent watchdog runs.
pub fn watchdog_started() {
    WATCHDOG_RUNNING.store(true, Ordering::Relaxed);
}

/// Whether the independent watchdog runs (`watchdog::start` was called).
pub fn watchdog_running() -> bool {
    WATCHDOG_RUNNING.load(Ordering::Relaxed)
}

/// Records why the chip last reset (read once at boot).
pub fn set_reset_cause(cause: ResetCause) {
    RESET_CAUSE.store(cause.bits(), Ordering::Relaxed);
}

/// The board's health now.
pub fn snapshot(handler: &SensorDataHandler, tx: &TxCounters, now_us: u64) -> Diagnostics {
    let counters = handler.counters();
    let mut flags = StatusFlags::NONE;
    if handler.admission_policy() == amiro_can::AdmissionPolicy::AcceptAndWarn {
        flags = flags.with(StatusFlags::ACCEPT_AND_WARN);
    }
    if PASSIVE_NOW.load(Ordering::Relaxed) {
        flags = flags.with(StatusFlags::ERROR_PASSIVE);
    }
    if GROUPS_FAULTY.load(Ordering::Relaxed) != 0 {
        flags = flags.with(StatusFlags::SENSOR_FAULT);
    }
    if CLOCK_FALLBACK.load(Ordering::Relaxed) {
        flags = flags.with(StatusFlags::CLOCK_FALLBACK);
    }
    if WATCHDOG_RUNNING.load(Ordering::Relaxed) {
        flags = flags.with(StatusFlags::WATCHDOG);
    }
    if crate::signals::shutting_down() {
        flags = flags.with(StatusFlags::SHUTTING_DOWN);
    }
    Diagnostics {
        uptime_s: u32::try_from(amiro_sensors::clock::div_us(now_us, 1_000_000))
            .unwrap_or(u32::MAX),
        reset_cause: ResetCause::from_bits(RESET_CAUSE.load(Ordering::Relaxed)),
        flags,
        sensor_faults: sensor_faults(),
        accepted: counters.accepted,
        rejected: counters.rejected,
        admission_refused: ADMISSION_REFUSED.load(Ordering::Relaxed),
        admission_warned: ADMISSION_WARNED.load(Ordering::Relaxed),
        refusals: [
            REFUSALS[0].load(Ordering::Relaxed),
            REFUSALS[1].load(Ordering::Relaxed),
            REFUSALS[2].load(Ordering::Relaxed),
            REFUSALS[3].load(Ordering::Relaxed),
            REFUSALS[4].load(Ordering::Relaxed),
            REFUSALS[5].load(Ordering::Relaxed),
            REFUSALS[6].load(Ordering::Relaxed),
        ],
        rx_dropped: rx_dropped(),
        rx_overruns: rx_overruns(),
        tx_dropped: tx.dropped,
        tx_displaced: tx.requeued,
        error_passive: ERROR_PASSIVE.load(Ordering::Relaxed),
        bus_off: BUS_OFF.load(Ordering::Relaxed),
        deadline_misses: [
            DEADLINE_MISSES[0].load(Ordering::Relaxed),
            DEADLINE_MISSES[1].load(Ordering::Relaxed),
            DEADLINE_MISSES[2].load(Ordering::Relaxed),
            DEADLINE_MISSES[3].load(Ordering::Relaxed),
        ],
    }
}

/// One sample of `board`'s diagnostics topic at `priority` from the health now (its
/// [`snapshot`], which the caller takes under the handler's lock): its six frames, the rejection
/// window moving on by three reasons per sample. The frames are made outside the lock.
#[inline(never)]
pub fn frames_now(
    diagnostics: &Diagnostics,
    board: Board,
    priority: Priority,
) -> [Frame; PAGES_PER_SAMPLE as usize] {
    let window = WINDOW.load(Ordering::Relaxed);
    WINDOW.store(Diagnostics::next_window(window), Ordering::Relaxed);
    diagnostics.frames(board, priority, window)
}
