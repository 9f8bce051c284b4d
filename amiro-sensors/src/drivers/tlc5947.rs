//! Texas Instruments TLC5947 24-channel, 12-bit PWM LED driver, alone or chained: the LightRing's
//! RGB LEDs (revision 1-0: one part, eight LEDs; revision 1-2: three parts, 24 LEDs).
//!
//! The part is a 288-bit shift register: 24 values of 12 bits, MSB first, the first value shifted
//! in ending up on OUT23. A rising edge on XLAT copies the shift register to the outputs. Chained
//! parts (SOUT of one into SIN of the next) are one longer register: with `CHIPS` parts the frame
//! is `36 × CHIPS` bytes, the first value shifted in lands on the last part's OUT23, the last value
//! on the first part's OUT0. Here the chain's outputs are numbered as one: chain channel
//! `24 k + j` is OUT`j` of part `k`, part 0 the one whose SIN the MCU drives (AMiRo-LLD's
//! `TLC5947_LLD_CHAINED` numbering). On the LightRing XLAT (PC4) is driven as the SPI chip select,
//! so one `SpiDevice::write` of the whole frame shifts the data in while the line is low and
//! latches every part when the device releases the line at the end of the transfer. (BLANK, PA4,
//! is the firmware's: it must go low to light the LEDs.)
//!
//! LED wiring (docs/boards.md, docs/protocol.md): each RGB LED is one output triple, chain channels
//! `3t` = red, `3t + 1` = green, `3t + 2` = blue. Which triples a protocol LED n (1..=8, the
//! `Led1..Led8` topics) lights depends on the ring, [`led_triples`]:
//! - one TLC5947 (1-0): triple k is the 1.x LED index 7 − k, and LED n is the 1.x index n − 1, so
//!   LED n is triple 8 − n: LED 1 is front-right (NNE, OUT21..23), LED 8 front-left (NNW, OUT0..2);
//! - three TLC5947 (1-2): the 24 LEDs run clockwise (seen from above) from just right of the
//!   front, LED t centred 7.5° + 15° t from straight ahead; protocol LED n lights its own group of
//!   three neighbours, triples 3(n − 1) .. 3n − 1, centred where the 1-0 ring's LED n sits (LED 1
//!   NNE on triples 0..2, chain channels 0..8; LED 8 NNW on triples 21..23, channels 63..71).
//!
//! Colours come in as 8-bit sRGB-like values and go out through [`GAMMA`], a table computed at
//! compile time from the CIE 1931 lightness formula, so equal steps in the 8-bit value look like
//! equal steps in brightness.

use embedded_hal::spi::SpiDevice;

use super::Error;

/// Output channels of one TLC5947.
pub const CHANNELS: usize = 24;
/// Bytes shifted per part (24 × 12 bits).
pub const FRAME_BYTES: usize = 36;
/// Largest 12-bit output value.
pub const MAX_VALUE: u16 = 4095;
/// The protocol's LEDs (topics `Led1..Led8`), on either ring.
pub const LEDS: u8 = 8;
/// RGB LEDs one TLC5947 drives (24 outputs, three per LED).
pub const RGB_PER_CHIP: usize = CHANNELS / 3;

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

/// The chain's RGB LEDs (output triples: triple t is chain channels 3t, 3t + 1, 3t + 2) that
/// protocol LED `led` (1..=8) lights on a ring of `chips` chained TLC5947; `None` outside 1..=8 or
/// for a chain length no LightRing has. One part (revision 1-0): the one triple 8 − `led`. Three
/// parts (revision 1-2): the three neighbouring triples 3(`led` − 1) .. 3 `led` − 1 (see the module
/// documentation for where they sit).
pub const fn led_triples(chips: usize, led: u8) -> Option<core::ops::Range<u8>> {
    if led == 0 || led > LEDS {
        return None;
    }
    match chips {
        1 => Some(LEDS - led..LEDS - led + 1),
        3 => Some(3 * (led - 1)..3 * led),
        _ => None,
    }
}

/// The outputs (red, green, blue) of protocol LED `led` (1..=8) on the one-part ring (1-0),
/// `None` outside 1..=8.
pub const fn led_outputs(led: u8) -> Option<[u8; 3]> {
    match led_triples(1, led) {
        Some(triples) => {
            let t = triples.start;
            Some([3 * t, 3 * t + 1, 3 * t + 2])
        }
        None => None,
    }
}

/// Packs the chain's channel values (part 0's first, OUT0 first) into the shift order: the last
/// part's OUT23 first, MSB first, part 0's OUT0 last.
pub fn pack_chain<const CHIPS: usize>(
    channels: &[[u16; CHANNELS]; CHIPS],
) -> [[u8; FRAME_BYTES]; CHIPS] {
    let mut frame = [[0u8; FRAME_BYTES]; CHIPS];
    // Channel pairs from the top of the chain: (71, 70), (69, 68), ... each fills three bytes.
    for (bytes, pair) in frame
        .as_flattened_mut()
        .chunks_exact_mut(3)
        .zip(channels.as_flattened().chunks_exact(2).rev())
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

/// Packs one part's 24 channel values into its 36-byte shift order (OUT23 first, MSB first).
pub fn pack_frame(channels: &[u16; CHANNELS]) -> [u8; FRAME_BYTES] {
    let [frame] = pack_chain(&[*channels]);
    frame
}

/// `CHIPS` chained TLC5947 holding the `24 × CHIPS` values they will shift out next.
///
/// The values are kept packed in shift order (the frame [`pack_chain`] would make), so a flush
/// writes them as they are: no second copy on the stack, and 1.5 bytes per channel instead of 2
/// (LightRing's RAM is tight: docs/boards.md).
#[derive(Debug)]
pub struct Tlc5947Chain<SPI, const CHIPS: usize> {
    spi: SPI,
    frame: [[u8; FRAME_BYTES]; CHIPS],
}

/// One TLC5947 (LightRing 1-0).
pub type Tlc5947<SPI> = Tlc5947Chain<SPI, 1>;

impl<SPI: SpiDevice, const CHIPS: usize> Tlc5947Chain<SPI, CHIPS> {
    /// Output channels of the chain.
    pub const OUTPUTS: usize = CHANNELS * CHIPS;
    /// Bytes one flush shifts.
    pub const FRAME_BYTES: usize = FRAME_BYTES * CHIPS;

    /// A driver with every output at 0. Does no I/O.
    pub const fn new(spi: SPI) -> Self {
        Self {
            spi,
            frame: [[0; FRAME_BYTES]; CHIPS],
        }
    }

    /// Where chain channel `out` sits in the frame: its first byte, and whether it is the first
    /// (upper) value of its three-byte pair (shifted first: the pair's higher channel).
    fn place(out: usize) -> Option<(usize, bool)> {
        let from_top = Self::OUTPUTS.checked_sub(out + 1)?;
        Some((from_top * 3 / 2, from_top % 2 == 0))
    }

    /// Sets chain channel `out` (0..24 × `CHIPS`) to `value` (clamped to 4095) for the next
    /// [`flush`](Self::flush).
    pub fn set_channel(&mut self, out: u8, value: u16) -> Result<(), Error<SPI::Error>> {
        let value = value.min(MAX_VALUE);
        let frame = self.frame.as_flattened_mut();
        match Self::place(usize::from(out)) {
            Some((at, true)) => {
                if let Some([first, second, ..]) = frame.get_mut(at..) {
                    *first = (value >> 4) as u8;
                    *second = (*second & 0x0F) | ((value & 0x0F) << 4) as u8;
                }
                Ok(())
            }
            Some((at, false)) => {
                if let Some([first, second, ..]) = frame.get_mut(at..) {
                    *first = (*first & 0xF0) | (value >> 8) as u8;
                    *second = (value & 0xFF) as u8;
                }
                Ok(())
            }
            None => Err(Error::OutOfRange {
                value: out.into(),
                max: (Self::OUTPUTS - 1) as u16,
            }),
        }
    }

    /// The pending value of chain channel `out`, `None` past the chain's end.
    pub fn channel(&self, out: usize) -> Option<u16> {
        let (at, upper) = Self::place(out)?;
        let frame = self.frame.as_flattened();
        let (first, second) = (u16::from(*frame.get(at)?), u16::from(*frame.get(at + 1)?));
        Some(if upper {
            first << 4 | second >> 4
        } else {
            (first & 0x0F) << 8 | second
        })
    }

    /// The pending values, chain channel 0 first.
    pub fn channels(&self) -> impl Iterator<Item = u16> + '_ {
        (0..Self::OUTPUTS).filter_map(|out| self.channel(out))
    }

    /// Sets every output to 0 (for the next flush).
    pub fn clear(&mut self) {
        self.frame = [[0; FRAME_BYTES]; CHIPS];
    }

    /// Shifts the pending values out and latches them (one write of `36 × CHIPS` bytes).
    pub fn flush(&mut self) -> Result<(), Error<SPI::Error>> {
        self.spi.write(self.frame.as_flattened())?;
        Ok(())
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

/// The LightRing's RGB LEDs on `CHIPS` chained TLC5947, addressed by the protocol's eight LEDs
/// ([`led_triples`]): [`LightRing`] (1-0) or [`LightRing24`] (1-2).
#[derive(Debug)]
pub struct LedRing<SPI, const CHIPS: usize> {
    driver: Tlc5947Chain<SPI, CHIPS>,
}

/// LightRing 1-0: eight RGB LEDs on one TLC5947.
pub type LightRing<SPI> = LedRing<SPI, 1>;
/// LightRing 1-2: 24 RGB LEDs on three chained TLC5947, three per protocol LED.
pub type LightRing24<SPI> = LedRing<SPI, 3>;

impl<SPI: SpiDevice, const CHIPS: usize> LedRing<SPI, CHIPS> {
    /// RGB LEDs on the ring.
    pub const RGB_LEDS: usize = RGB_PER_CHIP * CHIPS;
    /// RGB LEDs (output triples) one protocol LED lights: the length of every [`led_triples`]
    /// range of this chain.
    const TRIPLES_PER_LED: u8 = (CHIPS as u8 * RGB_PER_CHIP as u8) / LEDS;
    /// A chain length no LightRing has does not build.
    const KNOWN: () = {
        assert!(
            led_triples(CHIPS, 1).is_some(),
            "no LightRing revision has this many TLC5947"
        );
        let mut led = 1;
        while led <= LEDS {
            match led_triples(CHIPS, led) {
                Some(triples) => assert!(
                    triples.end - triples.start == Self::TRIPLES_PER_LED,
                    "every protocol LED lights TRIPLES_PER_LED triples"
                ),
                None => panic!("no LightRing revision has this many TLC5947"),
            }
            led += 1;
        }
    };

    /// A ring with every LED off. Does no I/O.
    pub const fn new(spi: SPI) -> Self {
        let () = Self::KNOWN;
        Self {
            driver: Tlc5947Chain::new(spi),
        }
    }

    /// Sets protocol LED `led` (1..=8) to an 8-bit colour (gamma-corrected) for the next flush:
    /// every RGB LED of its group.
    pub fn set_led(
        &mut self,
        led: u8,
        red: u8,
        green: u8,
        blue: u8,
    ) -> Result<(), Error<SPI::Error>> {
        let Some(triples) = led_triples(CHIPS, led) else {
            return Err(Error::OutOfRange {
                value: led.into(),
                max: LEDS.into(),
            });
        };
        let values = [gamma(red), gamma(green), gamma(blue)];
        // A count fixed by the chain length (1 or 3), not the range's run-time length: the loop
        // is gone on one part and a counted loop of three on three, so the execution-time
        // analysis finds its bound in the machine code of each revision.
        for k in 0..Self::TRIPLES_PER_LED {
            let triple = triples.start + k;
            for (out, value) in (3 * triple..).zip(values) {
                self.driver.set_channel(out, value)?;
            }
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
    pub fn driver(&self) -> &Tlc5947Chain<SPI, CHIPS> {
        &self.driver
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.driver.release()
    }
}
