//! The CAN forwarding a main board's AMiRo-BLT does for the modules behind it (its `can.c`).
//!
//! After a CONNECT to another board's id, the main board sends every packet it receives on the
//! UART to the CAN bus and every packet that comes back to the UART. A packet travels as a first
//! frame and follow-up frames on standard ids; each frame waits for an acknowledgement
//! (stop-and-wait, id | 0x001, one byte: the bytes still to come). The host never builds these
//! frames itself, but the session must know which packets survive the trip ([`is_forwardable`])
//! and what the trip costs ([`packet_time`]).
use std::time::Duration;

/// Gateway → module, first frame of a packet.
pub const TO_MODULE: u16 = 0x600;
/// Module → gateway, first frame of a packet.
pub const TO_GATEWAY: u16 = 0x700;
/// Added to the id of every follow-up frame.
pub const FOLLOW_UP: u16 = 0x002;
/// Added to a frame's id for its acknowledgement.
pub const ACK: u16 = 0x001;
/// The bus bit rate of the bootloaders.
pub const BIT_RATE: u32 = 1_000_000;

/// Which way a packet travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the main board to the selected module (carries the module's id).
    ToModule,
    /// From the module back (carries id 0).
    ToGateway,
}

/// One frame as the gateway puts it on the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanFrame {
    /// 11-bit identifier.
    pub id: u16,
    /// The DLC field as the bootloader writes it (it can exceed 8, see [`is_forwardable`]).
    pub dlc: u8,
    /// The eight data bytes of the mailbox (zero-padded).
    pub data: [u8; 8],
}

/// Splits a packet into frames the way `CanTransmitPacket` does, DLC quirk included.
pub fn split(packet: &[u8], device_id: u32, direction: Direction) -> Vec<CanFrame> {
    let base = match direction {
        Direction::ToModule => TO_MODULE,
        Direction::ToGateway => TO_GATEWAY,
    };
    let id_bytes = match direction {
        Direction::ToModule => device_id.to_le_bytes(),
        Direction::ToGateway => [0; 4],
    };
    let len = packet.len();
    let mut frames = Vec::new();
    let mut rest = len;
    while rest > 0 {
        let mut data = [0u8; 8];
        let (id, dlc, mut at) = if rest == len {
            data[..4].copy_from_slice(&id_bytes);
            data[4] = rest as u8;
            // The bootloader writes `rest + 5` for short packets: 9 for a 4-byte packet.
            let dlc = if rest > 4 { 8 } else { rest as u8 + 5 };
            (base, dlc, 5)
        } else {
            data[0] = rest as u8;
            let dlc = if rest > 7 { 8 } else { rest as u8 + 1 };
            (base | FOLLOW_UP, dlc, 1)
        };
        while rest > 0 && at < 8 {
            data[at] = packet[len - rest];
            at += 1;
            rest -= 1;
        }
        frames.push(CanFrame { id, dlc, data });
    }
    frames
}

/// Whether a packet of this length crosses the gateway intact. A 4-byte packet does not: its
/// first frame gets DLC 9, the receiver takes four bytes from it (one past the frame) and never
/// acknowledges the follow-up, so the gateway waits forever.
pub fn is_forwardable(len: usize) -> bool {
    (1..=255).contains(&len) && len != 4
}

/// Bits one data frame of `dlc` bytes takes on the bus, with typical bit stuffing.
pub fn frame_bits(dlc: u8) -> u32 {
    let bytes = u32::from(dlc.min(8));
    let unstuffed = 47 + 8 * bytes;
    // Stuffing can add one bit per four of the 34 + 8n stuffable bits; data rarely needs half.
    unstuffed + (34 + 8 * bytes) / 8
}

/// Bus time for one packet of `len` bytes, its frames and their acknowledgements.
pub fn packet_time(len: usize) -> Duration {
    let frames = split(&vec![0; len], 0, Direction::ToModule);
    let bits: u32 = frames
        .iter()
        .map(|f| frame_bits(f.dlc) + frame_bits(1))
        .sum();
    Duration::from_nanos(u64::from(bits) * 1_000_000_000 / u64::from(BIT_RATE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_packet_is_a_first_frame_and_follow_ups_counting_down() {
        let packet: Vec<u8> = (1..=12).collect();
        let frames = split(&packet, 0x0101_0102, Direction::ToModule);
        assert_eq!(frames.len(), 3);
        assert_eq!(frames[0].id, 0x600);
        assert_eq!(frames[0].dlc, 8);
        assert_eq!(frames[0].data, [0x02, 0x01, 0x01, 0x01, 12, 1, 2, 3]);
        assert_eq!(frames[1].id, 0x602);
        assert_eq!(frames[1].data, [9, 4, 5, 6, 7, 8, 9, 10]);
        assert_eq!(frames[2].dlc, 3);
        assert_eq!(&frames[2].data[..3], &[2, 11, 12]);
    }

    #[test]
    fn replies_carry_id_zero_and_four_byte_packets_are_broken() {
        let frames = split(&[0xFF], 0x017F_0102, Direction::ToGateway);
        assert_eq!(frames.len(), 1);
        assert_eq!((frames[0].id, frames[0].dlc), (0x700, 6));
        assert_eq!(&frames[0].data[..6], &[0, 0, 0, 0, 1, 0xFF]);
        let broken = split(&[1, 2, 3, 4], 7, Direction::ToModule);
        assert_eq!(broken[0].dlc, 9);
        assert!(!is_forwardable(4));
        assert!(is_forwardable(3) && is_forwardable(5) && is_forwardable(255));
        assert!(!is_forwardable(0) && !is_forwardable(256));
    }

    #[test]
    fn a_full_packet_costs_about_forty_frames_and_their_acks() {
        // 255 bytes: 3 in the first frame, then 36 follow-ups of 7 bytes.
        assert_eq!(split(&[0; 255], 1, Direction::ToModule).len(), 37);
        let t = packet_time(255);
        assert!(
            t > Duration::from_millis(5) && t < Duration::from_millis(8),
            "{t:?}"
        );
    }
}
