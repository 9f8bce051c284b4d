//! LightRing's QEMU board: the same app, with the TLC5947 simulated.
//!
//! The platform (SysTick clock, virtual CAN, stimulus replay, stack painting, the end line,
//! simulated system signals) is the runtime's `amiro_firmware::qemu`; this file adds only the
//! LightRing's own device: amiro-sensors' `SimLedDriver` behind the real TLC5947 driver. After each
//! latch the simulator's latched outputs are printed (`# tlc5947 OUT0..23 = …`), so a scenario
//! checks what the driver really shifted out, channel order included.
use core::fmt::Write as _;

use amiro_sensors::sim::SimLedDriver;
use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use stm32f1xx_hal::pac::{self, Interrupt};

pub use amiro_firmware::mono::QemuClock as Clock;
pub use amiro_firmware::qemu::{CanErrors, CanRxPort, CanTxPort, Signals as SystemSignals};

/// Interrupt of the (simulated) SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: Interrupt = Interrupt::EXTI15_10;
/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: Interrupt = Interrupt::USB_HP_CAN_TX;
/// Interrupt of the CAN receive FIFO 0 (pended by the stimulus replay).
pub const CAN_RX_INTERRUPT: Interrupt = Interrupt::USB_LP_CAN_RX0;

/// The simulated TLC5947, printing its outputs after each latch.
pub struct LedSpi(SimLedDriver);

impl ErrorType for LedSpi {
    type Error = core::convert::Infallible;
}

impl SpiDevice for LedSpi {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        self.0.transaction(operations)?;
        let mut line: heapless::String<160> = heapless::String::new();
        let _ = write!(line, "# tlc5947 latched");
        for value in self.0.outputs() {
            let _ = write!(line, " {value:03X}");
        }
        amiro_firmware::qemu::print_line(&line);
        Ok(())
    }
}

/// BLANK, printed.
pub struct Blank;

impl Blank {
    /// Lets the latched colours show.
    pub fn show(&mut self) {
        amiro_firmware::qemu::print_line("# qemu: BLANK low (LEDs on)");
    }
}

/// What `init` hands on to the tasks (same shape as the real board's).
pub struct Board {
    /// Virtual transmit mailboxes.
    pub can_tx: CanTxPort,
    /// Virtual receive FIFO.
    pub can_rx: CanRxPort,
    /// No CAN errors in QEMU.
    pub can_errors: CanErrors,
    /// Simulated LED driver.
    pub led_spi: LedSpi,
    /// Simulated BLANK.
    pub blank: Blank,
    /// Simulated system signals.
    pub signals: SystemSignals,
    /// Unused in QEMU (SysTick runs from the core clock).
    pub timer_hz: u32,
}

/// Brings the simulated board up (touches no STM32 peripheral).
pub fn init(_dp: pac::Peripherals, cp: cortex_m::Peripherals) -> Board {
    amiro_firmware::mono::start_qemu(cp.SYST);
    Board {
        can_tx: CanTxPort,
        can_rx: CanRxPort,
        can_errors: amiro_firmware::qemu::can_errors(),
        led_spi: LedSpi(SimLedDriver::new()),
        blank: Blank,
        signals: SystemSignals,
        timer_hz: 0,
    }
}

/// The SysTick monotonic already runs (started in `init`).
pub fn start_monotonic(_priority: u8, _timer_hz: u32) {}

/// The safe state: BLANK high (printed).
pub fn leds_dark() {
    amiro_firmware::qemu::print_line("# qemu: BLANK high (LEDs dark)");
}
