//! PowerManagement firmware (STM32F405xG): the RTIC skeleton — clocks from the 8 MHz crystal to
//! 168 MHz, the TIM2 microsecond monotonic, RTT and a heartbeat task. The proximity ring, the fuel
//! gauges and the CAN side come with the PowerManagement issue.
#![no_std]
#![no_main]

use rtic_monotonics::stm32::prelude::*;

// TIM2 is the original firmware's tick timer on this board and is free for the monotonic.
stm32_tim2_monotonic!(Mono, 1_000_000);

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
        let _rcc = cx.device.RCC.freeze(
            Config::hse(8.MHz()).sysclk(168.MHz()).hclk(168.MHz()).pclk1(42.MHz()).pclk2(84.MHz()),
        );
        // APB1 timers run at 2 × PCLK1 = 84 MHz.
        Mono::start(84_000_000, Priority::new(8));
        heartbeat::spawn().ok();
        rprintln!("PowerManagement up");
        (Shared {}, Local {})
    }

    #[task(priority = 1)]
    async fn heartbeat(_cx: heartbeat::Context) {
        loop {
            rprintln!("alive at {} us", rtic_monotonics::rtic_time::monotonic::TimerQueueBasedInstant::ticks(Mono::now()));
            Mono::delay(500u64.millis()).await;
        }
    }
}
