//! The RTT log channel read out of a RAM image.
use anyhow::{ensure, Context, Result};

use super::RAM_BASE;

/// The up-channel `channel`'s bytes in a RAM image (`ram` starts at [`RAM_BASE`]), from the RTT
/// control block at `control` (or, if `None`, wherever RAM holds its ID), read from the channel's
/// read to its write offset (nothing on the host reads it, so that is everything written, up to
/// the channel's size).
pub fn rtt_up_channel(ram: &[u8], control: Option<u32>, channel: u32) -> Result<Vec<u8>> {
    const ID: &[u8] = b"SEGGER RTT";
    let word = |addr: u32| -> Result<u32> {
        let at = addr
            .checked_sub(RAM_BASE)
            .context("an RTT address below RAM")? as usize;
        let bytes = ram
            .get(at..at + 4)
            .with_context(|| format!("RTT address {addr:#x} beyond the saved RAM"))?;
        Ok(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
    };
    let control = match control {
        Some(at) => at,
        None => {
            let at = ram
                .windows(ID.len())
                .position(|w| w == ID)
                .context("no RTT control block in RAM (did the firmware set up its log?)")?;
            RAM_BASE + at as u32
        }
    };
    let at = control
        .checked_sub(RAM_BASE)
        .context("the RTT control block lies below RAM")? as usize;
    ensure!(
        ram.get(at..at + ID.len()) == Some(ID),
        "no RTT control block at {control:#x} yet (the firmware has not set up its log)"
    );
    let max_up = word(control + 16)?;
    ensure!(
        channel < max_up,
        "the firmware has {max_up} RTT up-channels, not {}",
        channel + 1
    );
    let desc = control + 24 + 24 * channel;
    let (buffer, size, write, read) = (
        word(desc + 4)?,
        word(desc + 8)?,
        word(desc + 12)?,
        word(desc + 16)?,
    );
    ensure!(
        size > 0 && write < size && read < size,
        "RTT up-channel {channel} is damaged (size {size}, write {write}, read {read})"
    );
    let byte = |offset: u32| -> Result<u8> {
        let at = (buffer + offset)
            .checked_sub(RAM_BASE)
            .context("RTT buffer below RAM")? as usize;
        ram.get(at)
            .copied()
            .context("RTT buffer beyond the saved RAM")
    };
    let mut out = Vec::new();
    let mut offset = read;
    while offset != write {
        out.push(byte(offset)?);
        offset = (offset + 1) % size;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ram_with_log(text: &[u8], read: u32) -> Vec<u8> {
        let mut ram = vec![0u8; 0x400];
        ram[0x10..0x1A].copy_from_slice(b"SEGGER RTT");
        let put = |ram: &mut Vec<u8>, at: usize, v: u32| {
            ram[at..at + 4].copy_from_slice(&v.to_le_bytes())
        };
        put(&mut ram, 0x10 + 16, 2);
        put(&mut ram, 0x10 + 20, 0);
        let desc = 0x10 + 24;
        put(&mut ram, desc + 4, RAM_BASE + 0x200);
        put(&mut ram, desc + 8, 16);
        let write = (read + text.len() as u32) % 16;
        put(&mut ram, desc + 12, write);
        put(&mut ram, desc + 16, read);
        for (i, b) in text.iter().enumerate() {
            ram[0x200 + (read as usize + i) % 16] = *b;
        }
        ram
    }

    #[test]
    fn the_rtt_log_is_read_by_symbol_or_by_scan_and_wraps() {
        let ram = ram_with_log(b"boot: x\n", 0);
        assert_eq!(
            rtt_up_channel(&ram, Some(RAM_BASE + 0x10), 0).unwrap(),
            b"boot: x\n"
        );
        assert_eq!(rtt_up_channel(&ram, None, 0).unwrap(), b"boot: x\n");
        let wrapped = ram_with_log(b"0123456789", 10);
        assert_eq!(rtt_up_channel(&wrapped, None, 0).unwrap(), b"0123456789");
        assert!(rtt_up_channel(&ram, None, 2).is_err(), "only two channels");
        assert!(rtt_up_channel(&[0u8; 64], None, 0).is_err());
    }
}
