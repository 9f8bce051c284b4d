//! LightRing firmware (STM32F103xE): the RTIC skeleton — clocks, the TIM3 microsecond monotonic,
//! RTT and a heartbeat task. The LED ring (TLC5947) and the CAN side come with the LightRing issue.
#![no_std]
#![no_main]

use rtic_monotonics::stm32::prelude::*;

// TIM3 is free on LightRing (the original firmware ticks on TIM2), so rtic-monotonics' TIM3 serves.
stm32_tim3_monotonic!(Mono, 1_000_000);

/// Switches the clock tree back to the internal oscillator with the PLL off.
///
/// AMiRo-BLT hands over with the PLL already driving SYSCLK; the PLL cannot be reconfigured while
/// it is the system clock, so start from the reset state before the HAL sets the clocks up.
fn clock_tree_to_reset_state(rcc: &stm32f1xx_hal::pac::RCC) {
    rcc.cr().modify(|_, w| w.hsion().set_bit());
    while rcc.cr().read().hsirdy().bit_is_clear() {}
    rcc.cfgr().modify(|_, w| w.sw().hsi());
    while !rcc.cfgr().read().sws().is_hsi() {}
    rcc.cr().modify(|_, w| w.pllon().clear_bit());
    while rcc.cr().read().pllrdy().bit_is_set() {}
}

/// The AMiRo-BLT checksum slot (see `memory.x`): erased flash until the bootloader or
/// `cargo xtask flash` writes the word that makes the first vector words sum to zero.
#[cfg(not(feature = "bare-chip"))]
#[link_section = ".blt_checksum"]
#[used]
static BLT_CHECKSUM: u32 = 0xFFFF_FFFF;

#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    cortex_m::interrupt::disable();
    loop {
        cortex_m::asm::nop();
    }
}

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [UART4])]
mod app {
    use super::Mono;
    use rtic_monotonics::stm32::prelude::*;
    use rtt_target::{rprintln, rtt_init_print};
    use stm32f1xx_hal::{prelude::*, rcc};

    #[shared]
    struct Shared {}

    #[local]
    struct Local {}

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        rtt_init_print!();
        super::clock_tree_to_reset_state(&cx.device.RCC);
        let mut flash = cx.device.FLASH.constrain();
        let mut rcc = cx.device.RCC.freeze(
            rcc::Config::hse(8u32.MHz())
                .sysclk(72u32.MHz())
                .pclk1(36u32.MHz())
                .pclk2(36u32.MHz()),
            &mut flash.acr,
        );
        // TLC5947 BLANK (PA4) stays high — LEDs dark — until the LED driver is configured.
        let mut gpioa = cx.device.GPIOA.split(&mut rcc);
        let _blank = gpioa
            .pa4
            .into_push_pull_output_with_state(&mut gpioa.crl, stm32f1xx_hal::gpio::PinState::High);
        // Initialised: release SYS_SYNC_N (PD2, open drain, wired-OR) so the robot can come up.
        // (The pin configuration outlives the HAL handle.)
        let mut gpiod = cx.device.GPIOD.split(&mut rcc);
        let mut sys_sync = gpiod.pd2.into_open_drain_output(&mut gpiod.crl);
        sys_sync.set_high();
        // APB1 timers run at 2 × PCLK1 = 72 MHz.
        Mono::start(72_000_000, Priority::new(8));
        heartbeat::spawn().ok();
        rprintln!("LightRing up");
        (Shared {}, Local {})
    }

    #[task(priority = 1)]
    async fn heartbeat(_cx: heartbeat::Context) {
        loop {
            rprintln!(
                "alive at {} us",
                rtic_monotonics::rtic_time::monotonic::TimerQueueBasedInstant::ticks(Mono::now())
            );
            Mono::delay(500u64.millis()).await;
        }
    }
}
