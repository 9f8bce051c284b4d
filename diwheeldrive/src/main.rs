//! DiWheelDrive firmware (STM32F103xE): minimal RTIC app, grows into the full board app.
#![no_std]
#![no_main]

mod mono;


/// NVIC priority bits implemented on the STM32F1/F4.
const NVIC_PRIO_BITS: u8 = 4;

/// Converts an RTIC logical priority (1 = least urgent) to the NVIC's hardware encoding.
pub(crate) const fn hw_priority(logical: u8) -> u8 {
    ((1 << NVIC_PRIO_BITS) - logical) << (8 - NVIC_PRIO_BITS)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    cortex_m::interrupt::disable();
    loop {
        cortex_m::asm::nop();
    }
}

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [UART4])]
mod app {
    use crate::mono;
    use rtt_target::{rprintln, rtt_init_print};
    use stm32f1xx_hal::{prelude::*, rcc};

    #[shared]
    struct Shared {}

    #[local]
    struct Local {}

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        rtt_init_print!();
        let mut flash = cx.device.FLASH.constrain();
        let rcc_regs = unsafe { &*stm32f1xx_hal::pac::RCC::ptr() };
        let _rcc = cx.device.RCC.freeze(
            rcc::Config::hse(8.MHz()).sysclk(72.MHz()).pclk1(36.MHz()).pclk2(36.MHz()),
            &mut flash.acr,
        );
        crate::mono::Tim5Backend::start(cx.device.TIM5, rcc_regs, 72_000_000, 8);
        heartbeat::spawn().ok();
        (Shared {}, Local {})
    }

    #[task(priority = 1)]
    async fn heartbeat(_cx: heartbeat::Context) {
        loop {
            let now = mono::now_us();
            rprintln!("alive at {} us", now);
            mono::delay_until_us(now + 500_000).await;
        }
    }
}
