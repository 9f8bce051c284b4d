//! LightRing revisions 1-0 and 1-2 as the real chip sees them: the one place that names pins and
//! peripherals.
//!
//! Facts from `shared/reference/amiro-boards.md` §0, §1, §6: 8 MHz crystal → 72 MHz (APB1 36 MHz),
//! CAN1 on PA11/PA12 at 1 Mbit/s, the TLC5947 (1-0: one; 1-2: three chained) on SPI1 (SCK PA5,
//! MOSI PA7; MISO PA6 unused) at 2.25 MHz mode 0 with XLAT on PC4 driven as the chip select (its
//! rising edge at the end of a transfer latches) and BLANK on PA4 (high = dark, the reset state,
//! until the driver holds a frame), JTAG off and SWD kept, SYS_SYNC_N PD2, SYS_PD_N PC14. The
//! monotonic is TIM3 (the runtime's half-period timer backend; it claims no pin — its channels only
//! compare — so PA6/PA7 stay SPI1's).
//!
//! Revision 1-2 only (`rev-1-2`): the status LED PC3 (open drain, active low: lit while the
//! application runs, as DiWheelDrive's), SYS_UART_UP PC7 (open drain, released), and the breakout
//! connector's power switches (MIC9404x, active high) V1.8 PC5, V3.3 PB0, V4.2 PB1, V5.0 PB2,
//! VSYS PC6, driven low (off) at boot: this firmware drives no breakout module. On 1-0 these pins
//! are other things (PB2 is the laser scanner's LASER_EN) or nothing; the 1-0 image leaves them
//! in their reset state, as it always has.
use crate::Board;
use amiro_firmware::bxcan::{self, Fifo0, Mailboxes, Mmio};
use amiro_firmware::signals::Lines;
use amiro_firmware::spi;
use embedded_hal::spi::{Mode as SpiMode, Phase, Polarity};
use stm32f1xx_hal::afio::AfioExt;
use stm32f1xx_hal::gpio::{GpioExt, OpenDrain, Output, PinState, PushPull, PA4, PC14, PC4, PD2};
use stm32f1xx_hal::pac;
use stm32f1xx_hal::prelude::*;

/// The TLC5947's shift clock: 36 MHz / 16, as the original firmware.
pub const LED_SPI_HZ: u32 = 2_250_000;
/// EXTI line of SYS_PD_N (PC14).
const SYS_PD_LINE: u32 = 1 << 14;

/// The TLC5947 on SPI1, XLAT as its chip select: the runtime's device, whose write is the bus's
/// transmit-only send (one flag wait a byte, the bytes back to back) and XLAT's rise after the
/// last bit has left (`amiro_firmware::spi::Device`).
pub type LedSpi = spi::Device<Mmio, PC4<Output<PushPull>>>;
/// The CAN controller's transmit mailboxes (the runtime's register-level driver).
pub type CanTxPort = Mailboxes<Mmio>;
/// The CAN controller's error monitor.
pub type CanErrors = amiro_firmware::bxcan::ErrorMonitor<Mmio>;
/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: pac::Interrupt = pac::Interrupt::USB_HP_CAN_TX;
/// The CAN controller's receive FIFO 0 (the runtime's register-level driver).
pub type CanRxPort = Fifo0<Mmio>;
/// The board's clock: TIM3 ticks are microseconds.
pub type Clock = amiro_firmware::mono::TimerClock<Tim3Backend, 1>;

/// TIM3's registers: the same address and interrupt (29) on the F103 and on QEMU's `netduino2`.
const TIM3_BASE: usize = 0x4000_0400;

amiro_firmware::timer_monotonic!(Tim3Backend, TIM3_BASE, pac::Interrupt::TIM3, TIM3);

/// TLC5947 BLANK (PA4): high = every output off.
pub struct Blank(PA4<Output<PushPull>>);

impl Blank {
    /// Lets the latched colours show.
    pub fn show(&mut self) {
        self.0.set_low();
    }
}

/// The module's system-bus signals: SYS_SYNC_N on PD2, SYS_PD_N on PC14 (EXTI line 14).
pub type SystemSignals = Lines<PD2<Output<OpenDrain>>, PC14<Output<OpenDrain>>, 14>;

/// Brings the board up: clocks (crystal, or the internal oscillator if the crystal does not start),
/// pins, SPI1 for the LED driver, CAN.
pub fn init(dp: pac::Peripherals, _cp: cortex_m::Peripherals) -> Board {
    // The clock tree, every wait bounded (the runtime's `chip::clock_plan`): the PLL from the
    // crystal (72 MHz), else from the internal oscillator (64 MHz), else the internal oscillator
    // alone (8 MHz); each fault logged and flagged on the diagnostics. Then CAN1's reset.
    let clocks = amiro_firmware::chip::clock_plan();
    amiro_firmware::chip::reset_and_enable_can1();
    // The HAL's RCC only constrained, never frozen: its `freeze` waits for the crystal and the PLL
    // without a bound, and no driver here takes its frequencies from the HAL (they come from the
    // plan).
    let mut rcc = dp.RCC.constrain();
    amiro_firmware::chip::reset_and_enable_spi1();

    let mut afio = dp.AFIO.constrain(&mut rcc);
    let mut gpioa = dp.GPIOA.split(&mut rcc);
    #[cfg_attr(not(feature = "rev-1-2"), allow(unused_mut))]
    let mut gpiob = dp.GPIOB.split(&mut rcc);
    let mut gpioc = dp.GPIOC.split(&mut rcc);
    let mut gpiod = dp.GPIOD.split(&mut rcc);

    // BLANK first: the LEDs stay dark until the driver holds a known frame.
    let blank = gpioa
        .pa4
        .into_push_pull_output_with_state(&mut gpioa.crl, PinState::High);
    // SYS_SYNC_N stays low (as AMiRo-BLT left it) until the app is initialised.
    let sys_sync = gpiod
        .pd2
        .into_open_drain_output_with_state(&mut gpiod.crl, PinState::Low);
    // SYS_PD_N: wired-OR open drain, released high; EXTI line 14 (port C) watches its falling edge.
    let sys_pd = gpioc
        .pc14
        .into_open_drain_output_with_state(&mut gpioc.crh, PinState::High);
    #[cfg(not(feature = "rev-1-2"))]
    amiro_firmware::log!("power lines: SYS_SYNC_N held low, SYS_PD_N released, LEDs blanked");
    // Revision 1-2: the breakout connector's supplies off (no breakout module is driven), the
    // status LED lit, SYS_UART_UP released (wired-OR: another module may pull it). Set once here;
    // nothing else in the firmware names these pins (their pin values are zero-sized: the
    // configuration stays when they go out of scope).
    #[cfg(feature = "rev-1-2")]
    {
        let _breakout_power_off = (
            gpioc
                .pc5
                .into_push_pull_output_with_state(&mut gpioc.crl, PinState::Low),
            gpiob
                .pb0
                .into_push_pull_output_with_state(&mut gpiob.crl, PinState::Low),
            gpiob
                .pb1
                .into_push_pull_output_with_state(&mut gpiob.crl, PinState::Low),
            gpiob
                .pb2
                .into_push_pull_output_with_state(&mut gpiob.crl, PinState::Low),
            gpioc
                .pc6
                .into_push_pull_output_with_state(&mut gpioc.crl, PinState::Low),
        );
        let _status_led_lit = gpioc
            .pc3
            .into_open_drain_output_with_state(&mut gpioc.crl, PinState::Low);
        let _sys_uart_up_released = gpioc
            .pc7
            .into_open_drain_output_with_state(&mut gpioc.crl, PinState::High);
    }
    #[cfg(feature = "rev-1-2")]
    amiro_firmware::log!(
        "power lines: SYS_SYNC_N held low, SYS_PD_N released, LEDs blanked, breakout power off"
    );
    // SAFETY: AFIO's clock is on (constrain above); EXTICR4 bits 8..12 select the port of line 14,
    // and nothing else in this firmware uses EXTI lines 12..15.
    unsafe {
        (*pac::AFIO::ptr())
            .exticr4()
            .modify(|r, w| w.bits((r.bits() & !(0xF << 8)) | (0x2 << 8)));
    }
    dp.EXTI
        .ftsr()
        .modify(|r, w| unsafe { w.bits(r.bits() | SYS_PD_LINE) });
    dp.EXTI
        .imr()
        .modify(|r, w| unsafe { w.bits(r.bits() | SYS_PD_LINE) });

    // JTAG off, SWD kept (as the original firmware).
    let (_pa15, _pb3, _pb4) = afio.mapr.disable_jtag(gpioa.pa15, gpiob.pb3, gpiob.pb4);

    // SPI1 mode 0 at 2.25 MHz; XLAT idles high, so the end of each transfer is a rising edge.
    let xlat = gpioc
        .pc4
        .into_push_pull_output_with_state(&mut gpioc.crl, PinState::High);
    let _spi_pins = (
        gpioa.pa5.into_alternate_push_pull(&mut gpioa.crl),
        gpioa.pa6.into_floating_input(&mut gpioa.crl),
        gpioa.pa7.into_alternate_push_pull(&mut gpioa.crl),
    );
    let _ = dp.SPI1;
    // SAFETY: SPI1 is used by this value only.
    let spi = spi::Master::new(
        unsafe { Mmio::new(spi::SPI1) },
        clocks.pclk2_hz,
        LED_SPI_HZ,
        SpiMode {
            polarity: Polarity::IdleLow,
            phase: Phase::CaptureOnFirstTransition,
        },
    );
    let led_spi = spi::Device::new(spi, xlat);

    // CAN1 on PA11 (RX, floating input) and PA12 (TX, alternate push-pull), no remap; the runtime's
    // driver configures the controller.
    let _can_rx_pin = gpioa.pa11.into_floating_input(&mut gpioa.crh);
    let _can_tx_pin = gpioa.pa12.into_alternate_push_pull(&mut gpioa.crh);
    let can = bxcan::bring_up(clocks.can_btr);

    Board {
        can_tx: can.tx,
        can_rx: can.rx,
        can_errors: can.errors,
        led_spi,
        blank: Blank(blank),
        signals: SystemSignals::new(sys_sync, sys_pd),
        timer_hz: clocks.timer_hz,
    }
}

/// Starts the TIM3 monotonic (APB1 timers run at 2 × PCLK1).
pub fn start_monotonic(priority: u8, timer_hz: u32) {
    // SAFETY: init owns RCC at this point; only TIM3's enable and reset bits change.
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.apb1enr().modify(|_, w| w.tim3en().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim3rst().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim3rst().clear_bit());
    Tim3Backend::start(timer_hz, priority);
}

/// LightRing's safe state, from any context: BLANK high, every LED dark at once.
pub fn leds_dark() {
    // SAFETY: a single write of BSRR (set PA4), racing with nothing that could undo it but the
    // latch task's `Blank::show`, which the callers of this function pre-empt or have stopped.
    unsafe { (*pac::GPIOA::ptr()).bsrr().write(|w| w.bs4().set_bit()) };
}

/// Interrupt of the SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: pac::Interrupt = pac::Interrupt::EXTI15_10;
