//! Fault policy, in one place: on a panic or a HardFault the motors stop before anything else,
//! then the board parks with interrupts off until the independent watchdog resets it.

/// Stops the motors and parks the CPU (the watchdog, if running, resets the board).
pub fn halt() -> ! {
    cortex_m::interrupt::disable();
    motors_off();
    #[cfg(feature = "qemu")]
    crate::qemu::exit(false);
    loop {
        cortex_m::asm::nop();
    }
}

fn motors_off() {
    #[cfg(not(feature = "qemu"))]
    crate::board::emergency_motors_off();
    #[cfg(feature = "qemu")]
    crate::qemu::emergency_motors_off();
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    // Motors first: nothing below may run before they are off.
    cortex_m::interrupt::disable();
    motors_off();
    #[cfg(not(feature = "qemu"))]
    rtt_target::rprintln!("panic: {}", info);
    #[cfg(feature = "qemu")]
    crate::qemu::log_panic(info);
    halt()
}

#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    halt()
}
