//! Where a board's words go: trace events and a human log.
//!
//! On the robot both go over RTT (channel 0 `log`: the human log; channel 1 `trace`: records in the
//! `amiro_trace` format — handler events and, with `task-trace`, the task records of [`crate::tracing`]
//! — decoded on the host by `cargo xtask trace` and `cargo xtask bench`). In the QEMU build the log
//! and the handler events go to the semihosting console as text lines starting with `#`, so a run's
//! output still reads as a candump file, and the task records, in the same binary format as on
//! the robot, into the host file `trace.bin` of the run's work directory.
use amiro_sensors::trace::TraceEvent;

/// The core clock a board runs at after its clock set-up, which the trace clock counts (the
/// F103's internal-oscillator fallback says so again, see `chip::f1_clock_plan`).
#[cfg(all(not(feature = "qemu"), feature = "f1"))]
const TRACE_CLOCK_HZ: u32 = 72_000_000;
#[cfg(all(not(feature = "qemu"), not(feature = "f1")))]
const TRACE_CLOCK_HZ: u32 = 168_000_000;

/// Sets up the telemetry channels and the trace clock (RTT and the DWT cycle counter on the robot;
/// in QEMU the clock starts with the monotonic, in `mono::start_qemu`).
pub fn init() {
    #[cfg(not(feature = "qemu"))]
    {
        crate::channels::init();
        crate::tracing::start_clock(TRACE_CLOCK_HZ);
    }
}

/// The robot's first log line, right after [`init`]: the board, and whether the watchdog already
/// runs (every board starts it before anything that could spin). `cargo xtask smoke` checks the
/// boot's order from these lines. The QEMU build has no watchdog and prints nothing here.
pub fn boot_report(board: &str) {
    #[cfg(not(feature = "qemu"))]
    crate::log!(
        "boot: ",
        board,
        if crate::health::watchdog_running() {
            ", watchdog running"
        } else {
            ", watchdog NOT running"
        }
    );
    #[cfg(feature = "qemu")]
    let _ = board;
}

/// The robot's log line at the end of `init`: the tasks start next.
pub fn init_done() {
    #[cfg(not(feature = "qemu"))]
    crate::log!("init: done; RTIC starts the tasks");
}

/// Emits one trace event.
pub fn trace(event: &TraceEvent) {
    crate::tracing::event(event);
}

/// Writes a line to the human log (RTT channel 0 on the robot, a `#` line in QEMU), made of string
/// pieces: `log!("CAN set-up: ", error.as_str())`. No formatting machinery: a board's flash budget
/// has no room for `core::fmt`, and every message is static text.
#[macro_export]
macro_rules! log {
    ($($part:expr),+ $(,)?) => {
        $crate::telemetry::log_parts(&[$($part),+])
    };
}

/// The function behind [`log!`]: a line of more than [`crate::channels::LOG_PARTS_MAX`] parts is
/// refused when it is built, so the channel write's loop has a bound from the code.
#[inline]
pub fn log_parts<const N: usize>(parts: &[&str; N]) {
    const { assert!(N <= crate::channels::LOG_PARTS_MAX, "log!: too many parts") };
    crate::channels::write_log(parts);
}

/// `value` in decimal, into `buffer` (for log lines without `core::fmt`).
pub use crate::digits::decimal;
