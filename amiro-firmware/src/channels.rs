//! Where a board's bytes go, below everything that writes them: RTT's two up channels on the
//! robot (`log`, `trace`), the semihosting console and the host file `trace.bin` in QEMU.
//!
//! [`crate::tracing`] and [`crate::telemetry`] both write here; this module calls neither, so the
//! two never call each other in a circle (ARCHITECTURE.md, *Layers of the runtime*).

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

    /// Writes one log line made of `parts`, each cut to [`super::LOG_PART_MAX`] bytes.
    pub fn write_log(parts: &[&str]) {
        critical_section::with(|cs| {
            with_channel(cs, &LOG, |channel| {
                for part in parts {
                    let bytes = part.as_bytes();
                    channel.write(&bytes[..bytes.len().min(super::LOG_PART_MAX)]);
                }
                channel.write(b"\n");
            });
        });
    }

    /// Writes one whole trace record, or nothing when the channel has no room for all of it
    /// (`false`). Only the trace drain writes this channel (`tracing::drain`, priority 0): the
    /// channel is taken out and put back under two short critical sections and the copy runs
    /// outside them, so it blocks no task.
    pub fn write_trace(bytes: &[u8]) -> bool {
        let Some(mut channel) = critical_section::with(|cs| TRACE.borrow(cs).take()) else {
            return false;
        };
        let written = channel.write(bytes) == bytes.len();
        critical_section::with(|cs| TRACE.borrow(cs).set(Some(channel)));
        written
    }
}

/// The most bytes of one part of a log line that reach the channel (the longest message part is
/// 68 bytes): a longer part is cut. It bounds the RTT copy's length, so the log's cost has a bound
/// (docs/analysis.md, the bounds files' `rtt_target::UpChannel::write` entries).
pub const LOG_PART_MAX: usize = 96;

/// Sets up the channels (RTT on the robot; QEMU's are opened by `qemu::init`).
pub fn init() {
    #[cfg(not(feature = "qemu"))]
    rtt::init();
}

/// QEMU: one trace record as a console line, `# T ` and its bytes in hex (without the delimiter:
/// the line ends it), so a handler event keeps its place among the other lines (`cargo xtask qemu`
/// prints its text on the host; core::fmt here would cost the task thousands of instructions).
#[cfg(feature = "qemu")]
pub fn write_console_record(bytes: &[u8]) -> bool {
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
    crate::qemu::console_write(&line[..=at])
}

/// Writes one encoded trace record (`amiro_trace` wire bytes, delimiter included); `false` when it
/// did not fit and was dropped whole.
pub fn write_trace(bytes: &[u8]) -> bool {
    #[cfg(not(feature = "qemu"))]
    return rtt::write_trace(bytes);
    #[cfg(feature = "qemu")]
    return crate::qemu::write_trace_file(bytes);
}

/// Log lines a task asked for with [`defer_log`] and the drain has not written yet (a ring: the
/// oldest at `head`).
#[derive(Clone, Copy)]
struct Deferred {
    lines: [&'static str; DEFERRED_LOG_LEN],
    head: usize,
    len: usize,
}

/// Deferred log lines held at once (a power of two); one more is dropped (the lines are one-off
/// reports: a monotonic event gone missing, the watchdog's first feed).
pub const DEFERRED_LOG_LEN: usize = 4;

static DEFERRED: critical_section::Mutex<core::cell::Cell<Deferred>> =
    critical_section::Mutex::new(core::cell::Cell::new(Deferred {
        lines: [""; DEFERRED_LOG_LEN],
        head: 0,
        len: 0,
    }));

/// Queues one static log line for the trace drain to write (`tracing::drain`, priority 0): what a
/// handler logs, at the cost of a short copy instead of a channel write. A full queue drops it.
pub fn defer_log(line: &'static str) {
    critical_section::with(|cs| {
        let cell = DEFERRED.borrow(cs);
        let mut deferred = cell.get();
        if deferred.len < DEFERRED_LOG_LEN {
            let tail = (deferred.head + deferred.len) & (DEFERRED_LOG_LEN - 1);
            if let Some(slot) = deferred.lines.get_mut(tail) {
                *slot = line;
                deferred.len += 1;
            }
            cell.set(deferred);
        }
    });
}

/// Writes the oldest deferred log line, if any (one per drain job).
pub fn write_deferred_log() {
    let line = critical_section::with(|cs| {
        let cell = DEFERRED.borrow(cs);
        let mut deferred = cell.get();
        if deferred.len == 0 {
            return None;
        }
        let line = deferred.lines.get(deferred.head).copied();
        deferred.head = (deferred.head + 1) & (DEFERRED_LOG_LEN - 1);
        deferred.len -= 1;
        cell.set(deferred);
        line
    });
    if let Some(line) = line {
        write_log(&[line]);
    }
}

/// Writes one human log line made of `parts` (RTT channel 0 on the robot, a `# ` line on QEMU's
/// console).
pub fn write_log(parts: &[&str]) {
    #[cfg(not(feature = "qemu"))]
    rtt::write_log(parts);
    #[cfg(feature = "qemu")]
    {
        crate::qemu::console_write(b"# ");
        for part in parts {
            crate::qemu::console_write(part.as_bytes());
        }
        crate::qemu::console_write(b"\n");
    }
}
