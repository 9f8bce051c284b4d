//! Where a board's words go: trace events and a human log.
//!
//! On the robot both go over RTT (channel 0 `log`: the human log; channel 1 `trace`: trace events in
//! their compact binary form, decoded on the host by `cargo xtask trace`). In the QEMU build both go
//! to the semihosting console as text lines starting with `#`, so a run's output still reads as a
//! candump file.
use amiro_sensors::trace::TraceEvent;

#[cfg(not(feature = "qemu"))]
mod rtt {
    use core::cell::RefCell;
    use critical_section::Mutex;
    use rtt_target::{rtt_init, ChannelMode, UpChannel};

    static TRACE: Mutex<RefCell<Option<UpChannel>>> = Mutex::new(RefCell::new(None));

    /// Sets up the two RTT channels.
    pub fn init() {
        let channels = rtt_init! {
            up: {
                0: { size: 512, mode: ChannelMode::NoBlockSkip, name: "log" }
                1: { size: 1024, mode: ChannelMode::NoBlockSkip, name: "trace" }
            }
        };
        rtt_target::set_print_channel(channels.up.0);
        critical_section::with(|cs| TRACE.borrow_ref_mut(cs).replace(channels.up.1));
    }

    /// Writes one encoded trace event; the critical section lasts one short copy into the ring.
    pub fn write_trace(bytes: &[u8]) {
        critical_section::with(|cs| {
            if let Some(channel) = TRACE.borrow_ref_mut(cs).as_mut() {
                channel.write(bytes);
            }
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

/// Writes a line to the human log (RTT channel 0 on the robot, a `#` line in QEMU).
#[macro_export]
macro_rules! log {
    ($($arg:tt)*) => {
        $crate::telemetry::log_fmt(format_args!($($arg)*))
    };
}

/// The function behind [`log!`].
pub fn log_fmt(args: core::fmt::Arguments<'_>) {
    #[cfg(not(feature = "qemu"))]
    rtt_target::rprintln!("{}", args);
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::hprintln!("# {}", args);
}
