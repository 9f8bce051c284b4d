//! SerialBoot framing on the UART: one length byte, then the XCP packet, no checksum.
//!
//! A length byte of 0 is an empty packet that the bootloader ignores; a burst of zero bytes
//! therefore completes any packet the bootloader is still waiting for (after a lost byte) and is
//! otherwise harmless, which is how the session resynchronises the line.

/// The longest packet one length byte can announce.
pub const MAX_PACKET: usize = 255;

/// Frames one XCP packet for the UART, or `None` when it is empty or longer than [`MAX_PACKET`].
pub fn encode(packet: &[u8]) -> Option<Vec<u8>> {
    if packet.is_empty() || packet.len() > MAX_PACKET {
        return None;
    }
    let mut framed = Vec::with_capacity(packet.len() + 1);
    framed.push(packet.len() as u8);
    framed.extend_from_slice(packet);
    Some(framed)
}

/// Reassembles length-prefixed packets from the bytes the bootloader sends.
#[derive(Debug, Default, Clone)]
pub struct Deframer {
    expected: Option<usize>,
    packet: Vec<u8>,
}

impl Deframer {
    /// An empty reassembler.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes one byte; returns a packet when this byte completes one.
    pub fn push(&mut self, byte: u8) -> Option<Vec<u8>> {
        match self.expected {
            None if byte == 0 => None,
            None => {
                self.expected = Some(usize::from(byte));
                self.packet.clear();
                None
            }
            Some(len) => {
                self.packet.push(byte);
                if self.packet.len() == len {
                    self.expected = None;
                    Some(std::mem::take(&mut self.packet))
                } else {
                    None
                }
            }
        }
    }

    /// Forgets a partly received packet (after a timeout the rest is not coming).
    pub fn clear(&mut self) {
        self.expected = None;
        self.packet.clear();
    }

    /// Whether a packet is partly received.
    pub fn is_mid_packet(&self) -> bool {
        self.expected.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_round_trips_and_empty_packets_are_skipped() {
        let framed = encode(&[0xFF, 0x00]).unwrap();
        assert_eq!(framed, [2, 0xFF, 0x00]);
        let mut d = Deframer::new();
        let mut out = Vec::new();
        for b in [0u8, 0].iter().chain(&framed) {
            if let Some(p) = d.push(*b) {
                out.push(p);
            }
        }
        assert_eq!(out, vec![vec![0xFF, 0x00]]);
        assert!(!d.is_mid_packet());
    }

    #[test]
    fn lengths_outside_one_byte_are_refused() {
        assert!(encode(&[]).is_none());
        assert!(encode(&[0; 256]).is_none());
        assert_eq!(encode(&[7; 255]).unwrap()[0], 255);
    }
}
