//! Decimal and hex digits without `core::fmt` (a board's flash budget has no room for it): a leaf
//! every layer may use, the QEMU platform's frame lines and the logs alike.

/// `value` in decimal, into `buffer`.
pub fn decimal(value: u32, buffer: &mut [u8; 10]) -> &str {
    let mut at = buffer.len();
    let mut rest = value;
    loop {
        at -= 1;
        buffer[at] = b'0' + (rest % 10) as u8;
        rest /= 10;
        if rest == 0 || at == 0 {
            break;
        }
    }
    core::str::from_utf8(&buffer[at..]).unwrap_or("?")
}

/// `value` in decimal without leading zeros (as `{value}` prints it), into `buffer`: the digits.
/// Without a loop (five digits worked out one by one, the first one kept chosen by comparisons),
/// so a caller's execution-time bound needs no statement for it (the QEMU builds' control-frame
/// lines, printed in the receive interrupt).
pub fn decimal_u16(value: u16, buffer: &mut [u8; 5]) -> &[u8] {
    *buffer = [
        digit(value / 10_000),
        digit(value / 1_000 % 10),
        digit(value / 100 % 10),
        digit(value / 10 % 10),
        digit(value % 10),
    ];
    let first = match value {
        10_000.. => 0,
        1_000.. => 1,
        100.. => 2,
        10.. => 3,
        _ => 4,
    };
    buffer.get(first..).unwrap_or(&[])
}

/// The ASCII digit of `value` (0 to 9; a larger value gives a character after `9`).
fn digit(value: u16) -> u8 {
    b'0'.wrapping_add(value as u8)
}

/// `value` in hex without leading zeros and without a loop (as `{value:x}`, or `{value:X}` with
/// `upper`), into `buffer`: the digits.
pub fn hex_u8(value: u8, upper: bool, buffer: &mut [u8; 2]) -> &[u8] {
    *buffer = hex_byte(value, upper);
    buffer.get(usize::from(value < 0x10)..).unwrap_or(&[])
}

/// `value` in two hex digits (as `{value:02x}`, or `{value:02X}` with `upper`).
pub fn hex_byte(value: u8, upper: bool) -> [u8; 2] {
    const LOWER: &[u8; 16] = b"0123456789abcdef";
    const UPPER: &[u8; 16] = b"0123456789ABCDEF";
    let table = if upper { UPPER } else { LOWER };
    [
        table[usize::from(value >> 4)],
        table[usize::from(value & 0xF)],
    ]
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_u16_in_decimal_as_core_prints_it() {
        let mut b = [0u8; 5];
        for value in 0..=u16::MAX {
            assert_eq!(
                super::decimal_u16(value, &mut b),
                format!("{value}").as_bytes()
            );
        }
    }

    #[test]
    fn every_byte_in_hex_as_core_prints_it() {
        let mut b = [0u8; 2];
        for value in 0..=u8::MAX {
            assert_eq!(
                super::hex_u8(value, false, &mut b),
                format!("{value:x}").as_bytes()
            );
            assert_eq!(
                super::hex_u8(value, true, &mut b),
                format!("{value:X}").as_bytes()
            );
            assert_eq!(
                super::hex_byte(value, false),
                format!("{value:02x}").as_bytes()
            );
            assert_eq!(
                super::hex_byte(value, true),
                format!("{value:02X}").as_bytes()
            );
        }
    }

    #[test]
    fn digits() {
        let mut b = [0u8; 10];
        assert_eq!(super::decimal(0, &mut b), "0");
        assert_eq!(super::decimal(4_294_967_295, &mut b), "4294967295");
        assert_eq!(super::decimal(100_340, &mut b), "100340");
    }
}
