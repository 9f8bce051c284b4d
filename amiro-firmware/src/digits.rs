//! Decimal digits without `core::fmt` (a board's flash budget has no room for it): a leaf every
//! layer may use, the QEMU platform's frame lines and the logs alike.

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

#[cfg(test)]
mod tests {
    #[test]
    fn digits() {
        let mut b = [0u8; 10];
        assert_eq!(super::decimal(0, &mut b), "0");
        assert_eq!(super::decimal(4_294_967_295, &mut b), "4294967295");
        assert_eq!(super::decimal(100_340, &mut b), "100340");
    }
}
