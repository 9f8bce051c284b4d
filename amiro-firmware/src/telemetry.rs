//! Where a board's words go: trace events and a human log.
//!
//! On the robot both go over RTT (channel 0 `log`: the human log; channel 1 `trace`: trace events in
//! their compact binary form, decoded on the host by `cargo xtask trace`). In the QEMU build both go
//! to the semihosting console as text lines starting with `#`, so a run's output still reads as a
//! candump file.
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
                0: { size: 512, mode: ChannelMode::NoBlockSkip, name: "log" }
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

    /// Writes one encoded trace event; the critical section lasts one short copy into the ring.
    pub fn write_trace(bytes: &[u8]) {
        critical_section::with(|cs| {
            with_channel(cs, &TRACE, |channel| {
                channel.write(bytes);
            });
        });
    }
}

/// Sets up the telemetry channels (RTT on the robot; nothing to do in QEMU).
pub fn init() {
    #[cfg(not(feature = "qemu"))]
    rtt::init();
}

/// Emits one trace event.
pub fn trace(event: &TraceEvent) {
    #[cfg(not(feature = "qemu"))]
    rtt::write_trace(&event.encode());
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::hprintln!("# {}", event);
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
pub fn decimal(value: u32, buffer: &mut [u8; 10]) -> &str {
    let mut at = buffer.len();
    let mut rest = value;
    loop {
        at -= 1;
        buffer[at] = b'0' + (rest % 10) as u8;
        rest /= 10;
        if rest == 0 || at == 0 {
            break;
        }
    }
    core::str::from_utf8(&buffer[at..]).unwrap_or("?")
}
