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

/// CRC-15 of the CAN standard (polynomial 0x4599) over `bits`, most significant first.
pub fn crc15(bits: impl IntoIterator<Item = bool>) -> u16 {
    let mut crc: u16 = 0;
    for bit in bits {
        let feedback = bit ^ (crc & 0x4000 != 0);
        crc = (crc << 1) & 0x7FFF;
        if feedback {
            crc ^= 0x4599;
        }
    }
    crc
}

/// Stuff bits a transmitter inserts into `bits`: after five equal bits, one of the opposite
/// value, which itself starts the next run.
pub fn stuff_bit_count(bits: impl IntoIterator<Item = bool>) -> u32 {
    let mut count = 0;
    let mut last = None;
    let mut run = 0;
    for bit in bits {
        if Some(bit) == last {
            run += 1;
        } else {
            last = Some(bit);
            run = 1;
        }
        if run == 5 {
            count += 1;
            last = Some(!bit);
            run = 1;
        }
    }
    count
}

/// The bits of a standard data frame with identifier `id` (11 bits) and `payload` (its first 8
/// bytes) before the CRC, unstuffed: start of frame, identifier, RTR, IDE, r0, DLC, data.
fn standard_head_and_data(id: u16, payload: &[u8]) -> impl Iterator<Item = bool> + Clone + '_ {
    let payload = &payload[..payload.len().min(8)];
    // SOF (dominant), the identifier, RTR, IDE and r0 (dominant), the length code: 19 bits.
    let head = (u32::from(id & 0x7FF) << 7) | payload.len() as u32;
    (0..19u32).rev().map(move |k| head >> k & 1 != 0).chain(
        payload
            .iter()
            .flat_map(|&byte| (0..8u32).rev().map(move |k| byte >> k & 1 != 0)),
    )
}

/// The bits of a standard data frame that bit stuffing applies to, unstuffed (start of frame …
/// CRC), without allocating: `id`'s 11 bits, `payload`'s first 8 bytes.
pub fn standard_stuffable_bits(id: u16, payload: &[u8]) -> impl Iterator<Item = bool> + '_ {
    let head = standard_head_and_data(id, payload);
    let crc = crc15(head.clone());
    head.chain((0..15u32).rev().map(move |k| crc >> k & 1 != 0))
}

/// Bits of the standard data frame `id`/`payload` (its first 8 bytes) on the bus from start of
/// frame to the end of its end-of-frame field (its completion): the stuffable bits, the stuff bits
/// the transmitter inserts among them (computed from the frame's own bits, CRC included), the
/// tail; the interframe space not. Between [`frame_bits_best`] and [`frame_bits_worst`] less the
/// interframe space. The bus model (`amiro-bus-sim`) and the QEMU platform's local completion
/// both count with this.
pub fn frame_bits(id: u16, payload: &[u8]) -> u32 {
    let stuffable = stuffable_bits(payload.len().min(8) as u8, false);
    stuffable + stuff_bit_count(standard_stuffable_bits(id, payload)) + TAIL_BITS
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

    #[test]
    fn crc15_matches_the_standard_check_value() {
        // CRC-15/CAN over the ASCII bytes "123456789", most significant bit first: 0x059E.
        let bits = b"123456789"
            .iter()
            .flat_map(|&b| (0..8).rev().map(move |k| b >> k & 1 != 0));
        assert_eq!(crc15(bits), 0x059E);
    }

    #[test]
    fn a_stuff_bit_starts_the_next_run() {
        assert_eq!(stuff_bit_count([false; 4]), 0);
        assert_eq!(stuff_bit_count([false; 5]), 1);
        assert_eq!(stuff_bit_count([false; 10]), 2);
        // 11111 → stuff 0, and that 0 with the next four zeros is a run of five → stuff 1.
        assert_eq!(
            stuff_bit_count([true, true, true, true, true, false, false, false, false]),
            2
        );
        // Alternating bits are never stuffed.
        assert_eq!(stuff_bit_count((0..40).map(|k| k % 2 == 0)), 0);
    }

    #[test]
    fn frame_bits_of_known_frames() {
        // Identifier 0, no data: SOF … DLC are 19 dominant bits and the CRC of zeros is zero, so
        // 34 zeros carry 6 stuff bits (after the 5th, 10th, … 30th); + 10 tail bits = 50.
        assert_eq!(frame_bits(0, &[]), 50);
        assert_eq!(standard_stuffable_bits(0, &[]).count(), 34);
        // Frames of the robot's traffic, counted bit by bit from their written-out bit strings
        // (the CRC from the standard's polynomial; see the expectations' comments).
        for (id, payload, stuffed, bits) in KNOWN {
            let sequence: std::vec::Vec<bool> = standard_stuffable_bits(id, payload).collect();
            let written: std::vec::Vec<bool> = stuffed.chars().map(|c| c == '1').collect();
            assert_eq!(stuff(&sequence), written, "{id:03X}");
            assert_eq!(frame_bits(id, payload), bits, "{id:03X} {payload:02X?}");
        }
        // More than 8 bytes count as 8; the length is within the Davis bounds.
        assert_eq!(frame_bits(0x605, &[7; 12]), frame_bits(0x605, &[7; 8]));
        for len in 0..=8u8 {
            let payload = [0x55u8; 8];
            let bits = frame_bits(0x2AA, &payload[..usize::from(len)]);
            assert!(bits + INTERMISSION_BITS >= frame_bits_best(len, false));
            assert!(bits + INTERMISSION_BITS <= frame_bits_worst(len, false));
        }
    }

    /// Frames with their whole stuffed bit string (start of frame … CRC, written out with the
    /// CRC-15 of the standard and a stuff bit after every five equal bits) and their length to
    /// the end of frame (+ 10 tail bits): an all-recessive identifier, a magnetometer-x sample,
    /// a gyroscope sample of zeros (a stuff bit every fifth bit), the thesis's command, and the
    /// densest run of ones.
    const KNOWN: [(u16, &[u8], &str, u32); 5] = [
        (0x7FF, &[], "0111110111110100000100010011100101111", 47),
        (
            0x605,
            &[0x12, 0x34],
            "0110000010101000001100001001000110100010111101011000",
            62,
        ),
        (
            0x108,
            &[0; 6],
            "000100001000001001100000100000100000100000100000100000100000100000100000100001111100001001001",
            103,
        ),
        (
            0x205,
            &[0x01, 0x84, 0x03, 0x02],
            "00100000101010000100000100001100001000001000110000010101001100000110011",
            81,
        ),
        (
            0x000,
            &[0xFF; 8],
            "000001000001000001100011111011111011111011111011111011111011111011111011111011111011111011111011111011001010010001",
            124,
        ),
    ];

    /// Inserts the stuff bits into `bits` (the test's own writing-out, to compare a frame's whole
    /// stuffed bit string with the expectation).
    fn stuff(bits: &[bool]) -> std::vec::Vec<bool> {
        let mut out = std::vec::Vec::new();
        let (mut last, mut run) = (None, 0);
        for &bit in bits {
            out.push(bit);
            if Some(bit) == last {
                run += 1;
            } else {
                (last, run) = (Some(bit), 1);
            }
            if run == 5 {
                out.push(!bit);
                (last, run) = (Some(!bit), 1);
            }
        }
        out
    }
}
