//! Where the board's words go: the handler's trace events and a human log.
//!
//! On the robot both go over RTT (channel 0: the human log, channel 1: trace events in their compact
//! binary form, decoded on the host); in QEMU both go to the semihosting console as text lines that
//! start with `#`, so a log of the run still reads as a candump file.

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

    /// Writes one encoded trace event. The critical section lasts one short copy into the RTT ring.
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
pub fn trace(event: &amiro_sensors::trace::TraceEvent) {
    #[cfg(not(feature = "qemu"))]
    rtt::write_trace(&event.encode());
    #[cfg(feature = "qemu")]
    crate::qemu::print_trace(event);
}

/// Writes a line to the human log.
#[macro_export]
macro_rules! log {
    ($($arg:tt)*) => {{
        #[cfg(not(feature = "qemu"))]
        rtt_target::rprintln!($($arg)*);
        #[cfg(feature = "qemu")]
        cortex_m_semihosting::hprintln!("# {}", format_args!($($arg)*));
    }};
}
