//! Durations and periods as people type them (`900us`, `900µs`, `50ms`, `1.5s`, `2 s`), read into
//! whole microseconds: the one decoder the operator tool (publish periods, `--timeout`, `--for`)
//! and the emulation's tools (`cargo xtask qemu --duration`, a stimulus's `# duration:` header)
//! share. Exact: a fraction finer than a microsecond is an error, never rounded.
//!
//! `no_std`, allocation-free; malformed text is a [`DurationError`] naming the offending part.

use crate::TimeUnit;

/// Why text is not a duration; the `&str` is the offending part of the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DurationError<'a> {
    /// Not a number followed by a unit.
    Malformed(&'a str),
    /// A number without a unit (ambiguous, so refused).
    MissingUnit(&'a str),
    /// A unit other than `us` (`µs`), `ms`, `s`.
    UnknownUnit(&'a str),
    /// Finer than one microsecond.
    BelowResolution(&'a str),
    /// Beyond a 64-bit count of microseconds.
    Huge(&'a str),
}

impl core::fmt::Display for DurationError<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Malformed(text) => write!(
                f,
                "{text:?} is not a duration: write a number and a unit, e.g. 900us, 50ms, 2s"
            ),
            Self::MissingUnit(text) => {
                write!(
                    f,
                    "{text:?} has no unit: write {text}us, {text}ms or {text}s"
                )
            }
            Self::UnknownUnit(unit) => write!(f, "unknown unit {unit:?}: use us (or µs), ms or s"),
            Self::BelowResolution(text) => write!(f, "{text} is finer than 1 µs"),
            Self::Huge(text) => write!(f, "{text} is beyond a 64-bit count of microseconds"),
        }
    }
}

/// Parses `900us`, `900µs`, `50ms`, `1.5s`, `2 s`: the length in whole microseconds and the unit
/// it was written in.
pub fn parse(text: &str) -> Result<(u64, TimeUnit), DurationError<'_>> {
    let trimmed = text.trim();
    let number_end = trimmed
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(trimmed.len());
    let (number, unit_text) = trimmed.split_at(number_end);
    let unit_text = unit_text.trim();
    if number.is_empty() {
        return Err(DurationError::Malformed(text));
    }
    let unit = match unit_text {
        "" => return Err(DurationError::MissingUnit(number)),
        "us" | "µs" | "μs" => TimeUnit::Micros,
        "ms" => TimeUnit::Millis,
        "s" => TimeUnit::Seconds,
        other => return Err(DurationError::UnknownUnit(other)),
    };
    let (whole, fraction) = number.split_once('.').unwrap_or((number, ""));
    if whole.is_empty() && fraction.is_empty() || fraction.contains('.') {
        return Err(DurationError::Malformed(text));
    }
    let huge = DurationError::Huge(trimmed);
    let whole_value: u64 = if whole.is_empty() {
        0
    } else {
        whole.parse().map_err(|_| huge)?
    };
    let mut micros = whole_value.checked_mul(unit.micros()).ok_or(huge)?;
    // Fractional digits, exactly: each digit is worth a tenth of the previous one.
    let mut digit_worth = unit.micros();
    for digit in fraction.bytes().map(|d| u64::from(d - b'0')) {
        if digit != 0 && digit_worth < 10 {
            return Err(DurationError::BelowResolution(trimmed));
        }
        digit_worth /= 10;
        micros = micros.checked_add(digit * digit_worth).ok_or(huge)?;
    }
    Ok((micros, unit))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_their_errors() {
        assert_eq!(parse("2s"), Ok((2_000_000, TimeUnit::Seconds)));
        assert_eq!(parse("1500ms"), Ok((1_500_000, TimeUnit::Millis)));
        assert_eq!(parse("900us"), Ok((900, TimeUnit::Micros)));
        assert_eq!(parse("900µs"), Ok((900, TimeUnit::Micros)));
        assert_eq!(parse(" 1.5 s "), Ok((1_500_000, TimeUnit::Seconds)));
        assert_eq!(parse(".25ms"), Ok((250, TimeUnit::Millis)));
        assert_eq!(parse("1.000s"), Ok((1_000_000, TimeUnit::Seconds)));
        assert_eq!(parse("2"), Err(DurationError::MissingUnit("2")));
        assert_eq!(parse("2h"), Err(DurationError::UnknownUnit("h")));
        assert_eq!(parse("ms"), Err(DurationError::Malformed("ms")));
        assert_eq!(parse("1.2.3s"), Err(DurationError::Malformed("1.2.3s")));
        assert_eq!(parse("."), Err(DurationError::MissingUnit(".")));
        assert_eq!(parse("1.5us"), Err(DurationError::BelowResolution("1.5us")));
        assert_eq!(
            parse("99999999999999999999s"),
            Err(DurationError::Huge("99999999999999999999s"))
        );
        assert_eq!(
            parse("18446744073710s"),
            Err(DurationError::Huge("18446744073710s"))
        );
    }

    proptest::proptest! {
        #[test]
        fn any_text_is_a_duration_or_an_error(text in "\\PC{0,20}") {
            let _ = parse(&text);
        }
    }
}
