//! Texas Instruments TLC5947 24-channel, 12-bit PWM LED driver: the LightRing's eight RGB LEDs.
//!
//! The part is a 288-bit shift register: 24 values of 12 bits, MSB first, the first value shifted
//! in ending up on OUT23. A rising edge on XLAT copies the shift register to the outputs. On the
//! LightRing XLAT (PC4) is driven as the SPI chip select, so one `SpiDevice::write` of the 36-byte
//! frame shifts the data in while the line is low and latches it when the device releases the line
//! at the end of the transfer. (BLANK, PA4, is the firmware's: it must go low to light the LEDs.)
//!
//! LED wiring (amiro-boards.md §6): each LED is one output triple, OUT3k = red, OUT3k+1 = green,
//! OUT3k+2 = blue, and triple k is the 1.x LED index 7 − k. The protocol's LED number n (1..=8, the
//! `Led1..Led8` topics) is the 1.x index n − 1, so LED n is triple 8 − n: LED 1 is front-right
//! (NNE, OUT21..23), LED 8 is front-left (NNW, OUT0..2).
//!
//! Colours come in as 8-bit sRGB-like values and go out through [`GAMMA`], a table computed at
//! compile time from the CIE 1931 lightness formula, so equal steps in the 8-bit value look like
//! equal steps in brightness.

use embedded_hal::spi::SpiDevice;

use super::Error;

/// Output channels of one TLC5947.
pub const CHANNELS: usize = 24;
/// Bytes shifted per frame (24 × 12 bits).
pub const FRAME_BYTES: usize = 36;
/// Largest 12-bit output value.
pub const MAX_VALUE: u16 = 4095;
/// RGB LEDs on the ring (board revision 1-0/1-1, one TLC5947).
pub const LEDS: u8 = 8;

/// Perceived lightness (CIE L*, 0..=100) to relative luminance (0..=1), CIE 1931.
const fn lightness_to_luminance(lightness: f64) -> f64 {
    if lightness <= 8.0 {
        // Linear segment near black: Y = L* / κ, κ = 24389 / 27.
        lightness * 27.0 / 24389.0
    } else {
        let t = (lightness + 16.0) / 116.0;
        t * t * t
    }
}

/// 8-bit value → 12-bit duty: the 8-bit value is read as lightness, the duty is its luminance.
const fn gamma_entry(value: u8) -> u16 {
    let luminance = lightness_to_luminance(value as f64 * 100.0 / 255.0);
    (luminance * MAX_VALUE as f64 + 0.5) as u16
}

/// 8-bit colour value → 12-bit PWM value, computed at compile time. Monotone, `GAMMA[0] == 0`,
/// `GAMMA[255] == 4095`.
pub const GAMMA: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        table[i] = gamma_entry(i as u8);
        i += 1;
    }
    table
};

/// The gamma-corrected 12-bit value for an 8-bit colour component.
pub const fn gamma(value: u8) -> u16 {
    GAMMA[value as usize]
}

/// The outputs (red, green, blue) of protocol LED `led` (1..=8), `None` outside 1..=8.
pub const fn led_outputs(led: u8) -> Option<[u8; 3]> {
    if led == 0 || led > LEDS {
        return None;
    }
    let triple = LEDS - led;
    Some([3 * triple, 3 * triple + 1, 3 * triple + 2])
}

/// Packs 24 channel values into the 36-byte shift order (OUT23 first, MSB first).
pub fn pack_frame(channels: &[u16; CHANNELS]) -> [u8; FRAME_BYTES] {
    let mut frame = [0u8; FRAME_BYTES];
    // Channel pairs from the top: (OUT23, OUT22), (OUT21, OUT20), ... each fills three bytes.
    for (bytes, pair) in frame
        .chunks_exact_mut(3)
        .zip(channels.chunks_exact(2).rev())
    {
        if let ([b0, b1, b2], [low, high]) = (bytes, pair) {
            let high = high & MAX_VALUE;
            let low = low & MAX_VALUE;
            *b0 = (high >> 4) as u8;
            *b1 = (((high & 0x0F) << 4) | (low >> 8)) as u8;
            *b2 = (low & 0xFF) as u8;
        }
    }
    frame
}

/// One TLC5947 holding the 24 values it will shift out next.
#[derive(Debug)]
pub struct Tlc5947<SPI> {
    spi: SPI,
    channels: [u16; CHANNELS],
}

impl<SPI: SpiDevice> Tlc5947<SPI> {
    /// A driver with every output at 0. Does no I/O.
    pub const fn new(spi: SPI) -> Self {
        Self {
            spi,
            channels: [0; CHANNELS],
        }
    }

    /// Sets output `out` (0..=23) to `value` (clamped to 4095) for the next [`flush`](Self::flush).
    pub fn set_channel(&mut self, out: u8, value: u16) -> Result<(), Error<SPI::Error>> {
        match self.channels.get_mut(usize::from(out)) {
            Some(slot) => {
                *slot = value.min(MAX_VALUE);
                Ok(())
            }
            None => Err(Error::OutOfRange {
                value: out.into(),
                max: (CHANNELS - 1) as u16,
            }),
        }
    }

    /// The pending values, OUT0 first.
    pub const fn channels(&self) -> &[u16; CHANNELS] {
        &self.channels
    }

    /// Sets every output to 0 (for the next flush).
    pub fn clear(&mut self) {
        self.channels = [0; CHANNELS];
    }

    /// Shifts the pending values out and latches them (one 36-byte write).
    pub fn flush(&mut self) -> Result<(), Error<SPI::Error>> {
        let frame = pack_frame(&self.channels);
        self.spi.write(&frame)?;
        Ok(())
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

/// The LightRing's eight RGB LEDs on one TLC5947.
#[derive(Debug)]
pub struct LightRing<SPI> {
    driver: Tlc5947<SPI>,
}

impl<SPI: SpiDevice> LightRing<SPI> {
    /// A ring with every LED off. Does no I/O.
    pub const fn new(spi: SPI) -> Self {
        Self {
            driver: Tlc5947::new(spi),
        }
    }

    /// Sets protocol LED `led` (1..=8) to an 8-bit colour (gamma-corrected) for the next flush.
    pub fn set_led(
        &mut self,
        led: u8,
        red: u8,
        green: u8,
        blue: u8,
    ) -> Result<(), Error<SPI::Error>> {
        let Some(outputs) = led_outputs(led) else {
            return Err(Error::OutOfRange {
                value: led.into(),
                max: LEDS.into(),
            });
        };
        for (out, value) in outputs.into_iter().zip([red, green, blue]) {
            self.driver.set_channel(out, gamma(value))?;
        }
        Ok(())
    }

    /// Turns every LED off (for the next flush).
    pub fn clear(&mut self) {
        self.driver.clear();
    }

    /// Shifts the colours out and latches them.
    pub fn flush(&mut self) -> Result<(), Error<SPI::Error>> {
        self.driver.flush()
    }

    /// The driver underneath, e.g. to read the pending channel values.
    pub fn driver(&self) -> &Tlc5947<SPI> {
        &self.driver
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.driver.release()
    }
}
