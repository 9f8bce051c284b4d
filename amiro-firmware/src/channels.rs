//! Where a board's bytes go, below everything that writes them: RTT's two up channels on the
//! robot (`log`, `trace`), the semihosting console and the host file `trace.bin` in QEMU.
//!
//! [`crate::tracing`] and [`crate::telemetry`] both write here; this module calls neither, so the
//! two never call each other in a circle (ARCHITECTURE.md, *Layers of the runtime*).

#[cfg(not(feature = "qemu"))]
mod rtt {
    use core::cell::Cell;
    use critical_section::Mutex;
    use rtt_target::{rtt_init, ChannelMode, UpChannel};

    // `Cell`, not `RefCell`: a channel is taken out, written and put back (the writer that finds
    // the slot empty writes nothing), so there is no borrow that could fail (and no panic message
    // machinery in the flash).
    static TRACE: Mutex<Cell<Option<UpChannel>>> = Mutex::new(Cell::new(None));
    static LOG: Mutex<Cell<Option<UpChannel>>> = Mutex::new(Cell::new(None));

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

    /// Writes one log line made of `parts`, at most [`super::LOG_PARTS_MAX`] of them, each cut to
    /// [`super::LOG_PART_MAX`] bytes. The channel is taken out and put back under two short
    /// critical sections and the copies run outside them (as [`write_outside`]), so a log line
    /// masks no interrupt for its copies; a line logged while a pre-empted task holds the channel
    /// finds none and is dropped.
    pub fn write_log(parts: &[&str]) {
        let Some(mut channel) = critical_section::with(|cs| LOG.borrow(cs).take()) else {
            return;
        };
        for part in parts.iter().take(super::LOG_PARTS_MAX) {
            let bytes = part.as_bytes();
            channel.write(&bytes[..bytes.len().min(super::LOG_PART_MAX)]);
        }
        channel.write(b"\n");
        critical_section::with(|cs| LOG.borrow(cs).set(Some(channel)));
    }

    /// Writes `first` and then `second` into the channel in `slot`, or nothing of what finds no
    /// room (`false`). The channel is taken out and put back under two short critical sections
    /// and the copies run outside them, so the writer blocks no task; a task that logs while a
    /// pre-empted writer holds the channel finds none and its line is dropped.
    fn write_outside(slot: &Mutex<Cell<Option<UpChannel>>>, first: &[u8], second: &[u8]) -> bool {
        let Some(mut channel) = critical_section::with(|cs| slot.borrow(cs).take()) else {
            return false;
        };
        let written = channel.write(first) == first.len() && channel.write(second) == second.len();
        critical_section::with(|cs| slot.borrow(cs).set(Some(channel)));
        written
    }

    /// Writes one log line for the trace drain (`super::write_deferred_log`), cut to
    /// [`super::LOG_PART_MAX`] bytes.
    pub fn write_deferred(line: &str) {
        let bytes = line.as_bytes();
        write_outside(&LOG, &bytes[..bytes.len().min(super::LOG_PART_MAX)], b"\n");
    }

    /// Writes one whole trace record, or nothing when the channel has no room for all of it
    /// (`false`): only the trace drain writes this channel (`tracing::drain`).
    pub fn write_trace(bytes: &[u8]) -> bool {
        write_outside(&TRACE, bytes, &[])
    }
}

/// The most bytes of one part of a log line that reach the channel (the longest message part is
/// 68 bytes): a longer part is cut. It bounds the RTT copy's length, so the log's cost has a bound
/// (docs/analysis.md, the bounds files' `rtt_target::UpChannel::write` entries).
pub const LOG_PART_MAX: usize = 96;
/// The most parts of one log line that reach the channel (`log!` refuses more when it is built):
/// it bounds `write_log`'s loop (the bounds files' `write_log` entries).
#[cfg(not(feature = "qemu"))]
pub const LOG_PARTS_MAX: usize = 5;
/// The most parts of one log line (QEMU: its admission notes have eight, `tasks::note_decision`).
#[cfg(feature = "qemu")]
pub const LOG_PARTS_MAX: usize = 8;

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

/// How many deferred log lines wait at most for the drain.
pub const DEFERRED_LINES: usize = 2;

/// The log lines tasks asked for with [`defer_log`] and the drain has not written yet: one-off
/// reports (a monotonic event gone missing, the watchdog's first feed, which can come together at
/// boot; LightRing's failed LED transfer; PowerManagement's shutdown sequence's two lines, which
/// come together when the other modules answer at once); a line that finds both slots taken is
/// dropped. (One slot lost the watchdog's first feed behind the monotonic's report at boot.) Two
/// straight-line slots: PowerManagement's flash has no room for a loop over more.
static DEFERRED: critical_section::Mutex<[core::cell::Cell<Option<&'static str>>; DEFERRED_LINES]> =
    critical_section::Mutex::new([const { core::cell::Cell::new(None) }; DEFERRED_LINES]);

/// Queues one static log line for the trace drain to write (`tracing::drain`, priority 0): what a
/// handler or a bounded job logs, at the cost of a short store instead of a channel write under
/// interrupts off.
pub fn defer_log(line: &'static str) {
    // QEMU: written through, as its trace records are (the drain does not run there).
    #[cfg(feature = "qemu")]
    return write_log(&[line]);
    #[cfg(not(feature = "qemu"))]
    critical_section::with(|cs| {
        let [first, second] = DEFERRED.borrow(cs);
        if first.get().is_none() {
            first.set(Some(line));
        } else if second.get().is_none() {
            second.set(Some(line));
        }
    });
}

/// Writes the deferred log lines, in the order they were deferred (the drain, once per job).
pub fn write_deferred_log() {
    let lines = critical_section::with(|cs| {
        let [first, second] = DEFERRED.borrow(cs);
        [first.take(), second.take()]
    });
    for line in lines.into_iter().flatten() {
        #[cfg(not(feature = "qemu"))]
        rtt::write_deferred(line);
        #[cfg(feature = "qemu")]
        write_log(&[line]);
    }
}

/// Writes one human log line made of `parts`, at most [`LOG_PARTS_MAX`] of them (RTT channel 0 on
/// the robot, a `# ` line on QEMU's console).
pub fn write_log(parts: &[&str]) {
    #[cfg(not(feature = "qemu"))]
    rtt::write_log(parts);
    #[cfg(feature = "qemu")]
    {
        crate::qemu::console_write(b"# ");
        for part in parts.iter().take(LOG_PARTS_MAX) {
            crate::qemu::console_write(part.as_bytes());
        }
        crate::qemu::console_write(b"\n");
    }
}
