//! The fault policy, in one place for every board: on a panic or a HardFault the board's safe
//! state comes first (motors off, LEDs dark, …), then the CPU parks with interrupts off until the
//! independent watchdog resets the board (in QEMU: the run ends with a failure).
//!
//! Each board states its safe state once with [`safe_state!`]; a board that forgets does not
//! link. The safe state must work from any context: it writes "off" values straight to registers.

extern "Rust" {
    /// The board's safe state, defined by [`safe_state!`].
    fn __amiro_board_safe_state();
}

/// Declares the board's safe state: a `fn()` that switches every actuator off from any context.
#[macro_export]
macro_rules! safe_state {
    ($f:path) => {
        #[doc(hidden)]
        #[no_mangle]
        fn __amiro_board_safe_state() {
            $f()
        }
    };
}

/// Puts the board into its safe state (callable from any context).
pub fn enter_safe_state() {
    // SAFETY: `safe_state!` defines the symbol with this exact signature.
    unsafe { __amiro_board_safe_state() }
}

/// Safe state, then park the CPU for the watchdog (or end a QEMU run with a failure).
pub fn halt() -> ! {
    cortex_m::interrupt::disable();
    enter_safe_state();
    #[cfg(feature = "qemu")]
    crate::qemu::exit(false);
    loop {
        cortex_m::asm::nop();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    // The safe state first: nothing below may run before the actuators are off.
    cortex_m::interrupt::disable();
    enter_safe_state();
    // Where, not what: the message would need `core::fmt`, which the boards' flash budgets leave out
    // (the QEMU build prints the whole message).
    #[cfg(not(feature = "qemu"))]
    {
        let mut line = [0u8; 10];
        match info.location() {
            Some(at) => crate::log!(
                "panic at ",
                at.file(),
                ":",
                crate::telemetry::decimal(at.line(), &mut line)
            ),
            None => crate::log!("panic"),
        }
    }
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::hprintln!("# panic: {}", info);
    halt()
}

#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    halt()
}
