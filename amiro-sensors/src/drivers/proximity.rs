//! Proximity counts to millimetres for the VCNL4020 ring sensors: a documented, monotone and
//! calibratable model, because the part itself measures reflected light, not distance.
//!
//! # Model and assumptions
//! A VCNL4020 count is `offset + reflected`: `offset` is what the sensor reads with nothing in
//! front (dark current plus LED light leaking through the cover and housing), `reflected` is light
//! that came back from an object. For a diffuse object that fills the sensor's field of view the
//! reflected light falls with the square of the distance, so
//!
//! ```text
//! counts = offset + k / d²      ⇒      d = sqrt(k / (counts - offset))
//! ```
//!
//! `k` (counts·mm²) lumps together LED current, the object's reflectance and the optics. The
//! inverse-square law is the far-field approximation; very close (a few mm) the curve flattens,
//! which [`ProximityCalibration::min_mm`] clamps. Readings at or below `offset + k / max_mm²` report
//! `max_mm`, which therefore means "nothing within range" (the thesis gives 200 mm as the part's
//! useful range).
//!
//! The default `k` comes from the shape of the datasheet's proximity-versus-distance curve at
//! 200 mA with an 18 % grey card (about 10 000 counts above offset at 10 mm); the default offset is
//! a typical covered-sensor value. Both depend on the individual sensor, its window and the
//! obstacle, so a robot should be calibrated: read the counts with nothing in front (`offset`) and
//! with a reference object at a known distance, then use [`ProximityCalibration::from_reference`].
//!
//! The conversion is monotone by construction: more counts never give a larger distance.

/// Per-sensor calibration of the counts → mm model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProximityCalibration {
    /// Counts read with nothing in front of the sensor.
    pub offset: u16,
    /// Reflected-signal constant `k` in counts·mm²: reflected counts at distance `d` are `k / d²`.
    pub k_counts_mm2: u32,
    /// Nearest distance reported; the inverse-square model is not valid closer than this.
    pub min_mm: u16,
    /// Farthest distance reported; also the value for "nothing seen".
    pub max_mm: u16,
}

impl ProximityCalibration {
    /// The uncalibrated default (see the module documentation for where the numbers come from).
    pub const DEFAULT: ProximityCalibration = ProximityCalibration {
        offset: 2_000,
        k_counts_mm2: 1_000_000,
        min_mm: 2,
        max_mm: 200,
    };

    /// A calibration from two measurements: `offset` counts with nothing in front, and
    /// `counts_at_reference` with the reference object `reference_mm` away. `None` if the reference
    /// reading is not above the offset (the object was not seen) or `reference_mm` is zero.
    pub const fn from_reference(
        offset: u16,
        counts_at_reference: u16,
        reference_mm: u16,
    ) -> Option<Self> {
        if counts_at_reference <= offset || reference_mm == 0 {
            return None;
        }
        let reflected = (counts_at_reference - offset) as u64;
        let mm = reference_mm as u64;
        let k = reflected * mm * mm;
        let k_counts_mm2 = if k > u32::MAX as u64 {
            u32::MAX
        } else {
            k as u32
        };
        Some(Self {
            offset,
            k_counts_mm2,
            ..Self::DEFAULT
        })
    }

    /// Distance in millimetres for a proximity reading, clamped to `min_mm..=max_mm`.
    pub const fn counts_to_mm(&self, counts: u16) -> u16 {
        let reflected = counts.saturating_sub(self.offset) as u32;
        // No reflected light at all: nothing in range.
        let mm = match self.k_counts_mm2.checked_div(reflected) {
            Some(square) => isqrt(square),
            None => self.max_mm as u32,
        };
        if mm > self.max_mm as u32 {
            self.max_mm
        } else if mm < self.min_mm as u32 {
            self.min_mm
        } else {
            mm as u16
        }
    }
}

impl Default for ProximityCalibration {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Integer square root, rounded down.
pub const fn isqrt(n: u32) -> u32 {
    // Digit-by-digit method: no division, no overflow, exact for every u32.
    let mut remainder = n;
    let mut root = 0u32;
    let mut bit = 1u32 << 30;
    while bit > n {
        bit >>= 2;
    }
    while bit != 0 {
        if remainder >= root + bit {
            remainder -= root + bit;
            root = (root >> 1) + bit;
        } else {
            root >>= 1;
        }
        bit >>= 2;
    }
    root
}
