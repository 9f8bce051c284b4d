//! LightRing's QEMU board: the same app, with the TLC5947 simulated.
//!
//! The platform (SysTick clock, virtual CAN, stimulus replay, stack painting, the end line,
//! simulated system signals) is the runtime's `amiro_firmware::qemu`; this file adds only the
//! LightRing's own device: amiro-sensors' `SimLedChain` (one TLC5947 on 1-0, three chained on 1-2)
//! behind the real driver. After each latch the simulator's latched outputs of the whole chain are
//! printed (`# tlc5947 latched` and every channel, chain channel 0 — part 0's OUT0 — first: 24 or
//! 72 values), so a scenario checks what the driver really shifted out, channel order included.
use crate::Board;
use amiro_sensors::sim::SimLedChain;
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

/// The simulated TLC5947 chain, printing its outputs after each latch.
pub struct LedSpi(SimLedChain<{ crate::leds::CHIPS }>);

/// Prints the latch line, `# tlc5947 latched` and each output in three hex digits, in pieces of
/// eight values from a 32-byte buffer, under one critical section (`print_line_pieces`): a buffer
/// for the whole line (305 bytes on 1-2) or core's integer formatting (a 128-byte buffer) would
/// deepen the latch task's stack, which may pre-empt the admission task's deepest.
fn print_latch(outputs: &[u16]) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    amiro_firmware::qemu::print_line_pieces(|put| {
        put(b"# tlc5947 latched");
        for values in outputs.chunks(8) {
            let mut piece = [0u8; 32];
            for (text, &value) in piece.chunks_exact_mut(4).zip(values) {
                text.copy_from_slice(&[
                    b' ',
                    HEX[usize::from(value >> 8 & 0xF)],
                    HEX[usize::from(value >> 4 & 0xF)],
                    HEX[usize::from(value & 0xF)],
                ]);
            }
            put(piece.get(..4 * values.len()).unwrap_or(&[]));
        }
    });
}

impl ErrorType for LedSpi {
    type Error = core::convert::Infallible;
}

impl SpiDevice for LedSpi {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        self.0.transaction(operations)?;
        print_latch(self.0.outputs());
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

/// Brings the simulated board up (touches no STM32 peripheral).
pub fn init(_dp: pac::Peripherals, cp: cortex_m::Peripherals) -> Board {
    amiro_firmware::mono::start_qemu(cp.SYST);
    Board {
        can_tx: CanTxPort,
        can_rx: CanRxPort,
        can_errors: amiro_firmware::qemu::can_errors(),
        led_spi: LedSpi(SimLedChain::new()),
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
