//! PowerManagement firmware (STM32F405xG): the RTIC skeleton — clocks from the 8 MHz crystal to
//! 168 MHz, the TIM2 microsecond monotonic, RTT and a heartbeat task. The proximity ring, the fuel
//! gauges and the CAN side come with the PowerManagement issue.
#![no_std]
#![no_main]

use rtic_monotonics::stm32::prelude::*;

// TIM2 is the original firmware's tick timer on this board and is free for the monotonic.
stm32_tim2_monotonic!(Mono, 1_000_000);

/// Switches the clock tree back to the internal oscillator with the PLL off.
///
/// AMiRo-BLT hands over with the PLL already driving SYSCLK; the PLL cannot be reconfigured while
/// it is the system clock, so start from the reset state before the HAL sets the clocks up.
fn clock_tree_to_reset_state(rcc: &stm32f4xx_hal::pac::RCC) {
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

#[rtic::app(device = stm32f4xx_hal::pac, dispatchers = [UART4])]
mod app {
    use super::Mono;
    use rtic_monotonics::stm32::prelude::*;
    use rtt_target::{rprintln, rtt_init_print};
    use stm32f4xx_hal::{prelude::*, rcc::Config};

    #[shared]
    struct Shared {}

    #[local]
    struct Local {}

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        rtt_init_print!();
        super::clock_tree_to_reset_state(&cx.device.RCC);
        let mut rcc = cx.device.RCC.freeze(
            Config::hse(8.MHz())
                .sysclk(168.MHz())
                .hclk(168.MHz())
                .pclk1(42.MHz())
                .pclk2(84.MHz()),
        );
        // Initialised: release SYS_SYNC_N (PC12, open drain, wired-OR) so the robot can come up.
        // (The pin configuration outlives the HAL handle.)
        let gpioc = cx.device.GPIOC.split(&mut rcc);
        let mut sys_sync = gpioc.pc12.into_open_drain_output();
        sys_sync.set_high();
        // APB1 timers run at 2 × PCLK1 = 84 MHz.
        Mono::start(84_000_000, Priority::new(8));
        heartbeat::spawn().ok();
        rprintln!("PowerManagement up");
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
