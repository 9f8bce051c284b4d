//! Where a board's words go: trace events and a human log.
//!
//! On the robot both go over RTT (channel 0 `log`: the human log; channel 1 `trace`: records in the
//! `amiro_trace` format — handler events and, with `task-trace`, the task records of [`crate::tracing`]
//! — decoded on the host by `cargo xtask trace` and `cargo xtask bench`). In the QEMU build the log
//! and the handler events go to the semihosting console as text lines starting with `#`, so a run's
//! output still reads as a candump file, and the task records, in the same binary format as on
//! the robot, into the host file `trace.bin` of the run's work directory.
use amiro_sensors::trace::TraceEvent;

#[cfg(not(feature = "qemu"))]
mod rtt {
    use core::cell::Cell;
    use critical_section::{CriticalSection, Mutex};
    use rtt_target::{rtt_init, ChannelMode, UpChannel};

    // `Cell`, not `RefCell`: taken out and put back inside one critical section, so there is no
    // borrow that could fail (and no panic message machinery in the flash).
    static TRACE: Mutex<Cell<Option<UpChannel>>> = Mutex::new(Cell::new(None));
    static LOG: Mutex<Cell<Option<UpChannel>>> = Mutex::new(Cell::new(None));

    fn with_channel(
        cs: CriticalSection<'_>,
        slot: &Mutex<Cell<Option<UpChannel>>>,
        f: impl FnOnce(&mut UpChannel),
    ) {
        let cell = slot.borrow(cs);
        if let Some(mut channel) = cell.take() {
            f(&mut channel);
            cell.set(Some(channel));
        }
    }

    /// Sets up the two RTT channels.
    pub fn init() {
        let channels = rtt_init! {
            up: {
                0: { size: 1024, mode: ChannelMode::NoBlockSkip, name: "log" }
                1: { size: 1024, mode: ChannelMode::NoBlockSkip, name: "trace" }
            }
        };
        critical_section::with(|cs| {
            LOG.borrow(cs).set(Some(channels.up.0));
            TRACE.borrow(cs).set(Some(channels.up.1));
        });
    }

    /// Writes one log line made of `parts`.
    pub fn write_log(parts: &[&str]) {
        critical_section::with(|cs| {
            with_channel(cs, &LOG, |channel| {
                for part in parts {
                    channel.write(part.as_bytes());
                }
                channel.write(b"\n");
            });
        });
    }

    /// Writes one whole trace record, or nothing when the channel has no room for all of it
    /// (`false`); the critical section lasts one short copy into the ring.
    pub fn write_trace(bytes: &[u8]) -> bool {
        critical_section::with(|cs| {
            let mut written = false;
            with_channel(cs, &TRACE, |channel| {
                written = channel.write(bytes) == bytes.len();
            });
            written
        })
    }
}

/// The core clock a board runs at after its clock set-up, which the trace clock counts (the
/// F103's internal-oscillator fallback says so again, see `chip::f1_clock_plan`).
#[cfg(all(not(feature = "qemu"), feature = "f1"))]
const TRACE_CLOCK_HZ: u32 = 72_000_000;
#[cfg(all(not(feature = "qemu"), not(feature = "f1")))]
const TRACE_CLOCK_HZ: u32 = 168_000_000;

/// Sets up the telemetry channels and the trace clock (RTT and the DWT cycle counter on the robot;
/// in QEMU the clock starts with the monotonic, in `qemu::init`).
pub fn init() {
    #[cfg(not(feature = "qemu"))]
    {
        rtt::init();
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
    #[cfg(not(feature = "qemu"))]
    crate::tracing::event(&event.encode());
    #[cfg(feature = "qemu")]
    crate::tracing::event(&event.encode());
}

/// QEMU: one trace record as a console line, `# T ` and its bytes in hex (without the delimiter:
/// the line ends it), so a handler event keeps its place among the other lines (`cargo xtask qemu`
/// prints its text on the host; core::fmt here would cost the task thousands of instructions).
#[cfg(feature = "qemu")]
pub(crate) fn write_console_record(bytes: &[u8]) -> bool {
    const HEX: &[u8; 16] = b"0123456789abcdef";
    let mut line = [0u8; 4 + 2 * amiro_trace::MAX_WIRE + 1];
    line[..4].copy_from_slice(b"# T ");
    let mut at = 4;
    for &b in bytes.iter().take_while(|&&b| b != 0) {
        line[at] = HEX[usize::from(b >> 4)];
        line[at + 1] = HEX[usize::from(b & 15)];
        at += 2;
    }
    line[at] = b'\n';
    match cortex_m_semihosting::hio::hstdout() {
        Ok(mut out) => out.write_all(&line[..=at]).is_ok(),
        Err(_) => false,
    }
}

/// Writes one encoded trace record (`amiro_trace` wire bytes, delimiter included); `false` when it
/// did not fit and was dropped whole.
pub(crate) fn write_trace(bytes: &[u8]) -> bool {
    #[cfg(not(feature = "qemu"))]
    return rtt::write_trace(bytes);
    #[cfg(feature = "qemu")]
    return crate::qemu::write_trace_file(bytes);
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

/// The function behind [`log!`].
pub fn log_parts(parts: &[&str]) {
    #[cfg(not(feature = "qemu"))]
    rtt::write_log(parts);
    #[cfg(feature = "qemu")]
    {
        if let Ok(mut out) = cortex_m_semihosting::hio::hstdout() {
            let _ = out.write_all(b"# ");
            for part in parts {
                let _ = out.write_all(part.as_bytes());
            }
            let _ = out.write_all(b"\n");
        }
    }
}

/// `value` in decimal, into `buffer` (for log lines without `core::fmt`).
pub use crate::digits::decimal;
