//! The ring's colour state between the command handler and the latch task, and the latch itself.
//!
//! The state is the protocol's eight LEDs on either revision; [`Ring`] is the revision's driver
//! (1-0: one TLC5947; 1-2: three chained, each protocol LED lighting its group of three).
//!
//! The command handler only records each LED command (fast, in command order); the latch task
//! shifts the whole state into the TLC5947 and latches it. A burst of commands faster than a latch
//! takes is therefore applied in order and shown together by the next latch — no command is lost,
//! and the latch's cost does not grow with the burst.
use amiro_can::LedCommand;
use amiro_firmware::mono::Clock;
use amiro_firmware::telemetry;
use amiro_sensors::drivers::tlc5947::{LedRing, LEDS};
use amiro_sensors::trace::{TraceEvent, TraceKind};
use embedded_hal::spi::SpiDevice;

/// TLC5947 parts chained on this revision's ring.
pub const CHIPS: usize = if cfg!(feature = "rev-1-2") { 3 } else { 1 };

/// This revision's ring: protocol LEDs onto its chain (`amiro_sensors::drivers::tlc5947`).
pub type Ring<SPI> = LedRing<SPI, CHIPS>;

/// The commanded colours and which LEDs changed since the last latch.
pub struct LedState {
    colours: [[u8; 3]; LEDS as usize],
    changed: u8,
}

impl LedState {
    /// Every LED dark, nothing to latch.
    pub const fn new() -> Self {
        Self {
            colours: [[0; 3]; LEDS as usize],
            changed: 0,
        }
    }

    /// Records an LED command (the decoder has checked `led` is 1..=8) and traces it.
    pub fn apply(&mut self, now: u64, command: &LedCommand) {
        let rgb = [command.rgb.r, command.rgb.g, command.rgb.b];
        let index = usize::from(command.led.saturating_sub(1));
        if let Some(slot) = self.colours.get_mut(index) {
            if *slot != rgb {
                *slot = rgb;
                self.changed |= 1 << index;
            }
        }
        telemetry::trace(&TraceEvent::new(
            now,
            TraceKind::LedSet {
                led: command.led,
                rgb,
            },
        ));
    }

    /// The colours to latch now, and which LEDs changed since the last call.
    pub fn take(&mut self) -> ([[u8; 3]; LEDS as usize], u8) {
        (self.colours, core::mem::take(&mut self.changed))
    }

    /// Every LED dark (the shutdown path).
    pub fn clear(&mut self) {
        self.colours = [[0; 3]; LEDS as usize];
        self.changed = 0xFF;
    }
}

impl Default for LedState {
    fn default() -> Self {
        Self::new()
    }
}

/// Shifts `colours` into the driver and latches them; traces the latch with the LEDs that changed.
/// A failed transfer is logged (deferred to the trace drain, as a handler's one-off report: a
/// store here instead of the RTT channel write, which was the latch job's longest path); the next
/// latch writes the whole state again.
pub fn latch<C: Clock, SPI: SpiDevice>(
    ring: &mut Ring<SPI>,
    colours: &[[u8; 3]; LEDS as usize],
    changed: u8,
) {
    for (led, [r, g, b]) in (1..=LEDS).zip(colours.iter().copied()) {
        // `led` is in 1..=LEDS by construction: set_led cannot fail here.
        let _ = ring.set_led(led, r, g, b);
    }
    match ring.flush() {
        // Stamped when XLAT has risen: the colours are on the LEDs from this moment.
        Ok(()) => telemetry::trace(&TraceEvent::new(
            C::now_us(),
            TraceKind::LedsLatched { changed },
        )),
        Err(_) => amiro_firmware::channels::defer_log("LED driver transfer failed"),
    }
}
