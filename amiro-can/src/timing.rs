//! How many bits a classic CAN data frame occupies on the bus: the one place the frame layout's bit
//! counts live. The schedule analysis (`schedule-analysis::can`, the Davis et al. 2007 frame cost) and
//! the bit-level bus model (`amiro-bus-sim`) both count with these.
//!
//! * stuffable part `g + 8s` for `s` data bytes: `g = 34` for an 11-bit identifier (SOF 1, identifier
//!   11, RTR 1, IDE 1, r0 1, DLC 4, CRC 15), `g = 54` for a 29-bit one (SOF 1, base 11, SRR 1, IDE 1,
//!   extension 18, RTR 1, r1 1, r0 1, DLC 4, CRC 15);
//! * never stuffed: the 10-bit tail (CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7), then the
//!   3-bit interframe space before the next frame may start;
//! * at most `⌊(g + 8s − 1)/4⌋` stuff bits (after the first five equal bits, one per four further
//!   bits in the worst pattern).

/// Bits of a standard data frame that are subject to stuffing, without data (SOF … CRC).
pub const STUFFABLE_BITS_STANDARD: u32 = 34;
/// Bits of an extended data frame that are subject to stuffing, without data.
pub const STUFFABLE_BITS_EXTENDED: u32 = 54;
/// Bits after the CRC that are never stuffed, up to the end of frame: CRC delimiter, ACK slot, ACK
/// delimiter, seven bits of end of frame.
pub const TAIL_BITS: u32 = 10;
/// The interframe space (intermission) every frame is followed by before the next may start.
pub const INTERMISSION_BITS: u32 = 3;
/// Bits never stuffed, interframe space included: [`TAIL_BITS`] + [`INTERMISSION_BITS`].
pub const UNSTUFFED_BITS: u32 = TAIL_BITS + INTERMISSION_BITS;

/// Bits of a data frame with `dlc` data bytes (clamped to 8) that bit stuffing applies to.
pub const fn stuffable_bits(dlc: u8, extended: bool) -> u32 {
    let g = if extended {
        STUFFABLE_BITS_EXTENDED
    } else {
        STUFFABLE_BITS_STANDARD
    };
    let dlc = if dlc > 8 { 8 } else { dlc };
    g + 8 * dlc as u32
}

/// The most stuff bits a transmitter can insert into `stuffable` bits.
pub const fn max_stuff_bits(stuffable: u32) -> u32 {
    stuffable.saturating_sub(1) / 4
}

/// Worst-case length in bits of a data frame with `dlc` data bytes (clamped to 8), interframe space
/// included: `(55 + 10s)` for a standard identifier, `(80 + 10s)` for an extended one.
pub const fn frame_bits_worst(dlc: u8, extended: bool) -> u32 {
    let stuffable = stuffable_bits(dlc, extended);
    stuffable + UNSTUFFED_BITS + max_stuff_bits(stuffable)
}

/// Length in bits of the same frame without a single stuff bit (the best case), interframe space
/// included.
pub const fn frame_bits_best(dlc: u8, extended: bool) -> u32 {
    stuffable_bits(dlc, extended) + UNSTUFFED_BITS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closed_forms() {
        for dlc in 0..=8u8 {
            let s = u32::from(dlc);
            assert_eq!(frame_bits_worst(dlc, false), 55 + 10 * s);
            assert_eq!(frame_bits_worst(dlc, true), 80 + 10 * s);
            assert_eq!(frame_bits_best(dlc, false), 47 + 8 * s);
        }
        // A length code above 8 still means 8 bytes.
        assert_eq!(frame_bits_worst(15, false), frame_bits_worst(8, false));
        assert_eq!(max_stuff_bits(0), 0);
    }
}
