//! Periods typed by people (`900us`, `50ms`, `1.5s`) and the exact 16-bit sample time that encodes them.
//!
//! The wire carries a sample time as a u16 count plus a unit (µs, ms or s), so `70000us` does not fit as
//! microseconds but encodes exactly as 70 ms. We never round: a period with no exact encoding is an error that
//! names the nearest ones, because a silently different publish rate is worse than a refusal.

use std::fmt;
use std::time::Duration;

/// The three units a sample time can be counted in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeriodUnit {
    /// Microseconds.
    Micros,
    /// Milliseconds.
    Millis,
    /// Seconds.
    Seconds,
}

impl PeriodUnit {
    /// Microseconds in one of this unit.
    pub fn micros(self) -> u64 {
        match self {
            Self::Micros => 1,
            Self::Millis => 1_000,
            Self::Seconds => 1_000_000,
        }
    }

    /// The symbol people read: `µs`, `ms`, `s`.
    pub fn symbol(self) -> &'static str {
        match self {
            Self::Micros => "µs",
            Self::Millis => "ms",
            Self::Seconds => "s",
        }
    }
}

/// A period as the user wrote it, converted to whole microseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Period {
    /// The length in microseconds.
    pub micros: u64,
    /// The unit the user wrote, which the encoder tries first.
    pub written_unit: PeriodUnit,
}

/// A sample time as it goes on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncodedPeriod {
    /// The 16-bit count.
    pub value: u16,
    /// Its unit.
    pub unit: PeriodUnit,
}

/// Why a period cannot be used.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PeriodError {
    /// Not a number followed by a unit.
    Malformed(String),
    /// A number without a unit: ambiguous, so refused.
    MissingUnit(String),
    /// A unit we do not know.
    UnknownUnit(String),
    /// Finer than one microsecond.
    BelowResolution(String),
    /// Zero: the firmware rejects a zero sample time.
    Zero,
    /// So long that it does not even fit a 64-bit count of microseconds (the text as written).
    Huge(String),
    /// Longer than the firmware's monotonic timer can wait.
    TooLong {
        /// The requested period in µs.
        micros: u64,
        /// The longest accepted period in µs.
        max_micros: u64,
    },
    /// Fits no unit exactly in 16 bits.
    NotExact {
        /// The requested period in µs.
        micros: u64,
    },
}

impl fmt::Display for PeriodError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Malformed(text) => write!(f, "{text:?} is not a period: write a number and a unit, e.g. 900us, 50ms, 2s"),
            Self::MissingUnit(text) => write!(f, "{text:?} has no unit: write {text}us, {text}ms or {text}s"),
            Self::UnknownUnit(unit) => write!(f, "unknown unit {unit:?}: use us (or µs), ms or s"),
            Self::BelowResolution(text) => write!(f, "{text} is finer than the 1 µs resolution of the protocol"),
            Self::Zero => f.write_str(
                "a period of zero cannot be encoded (the firmware rejects it); use `stop` to stop a publisher",
            ),
            Self::Huge(text) => write!(
                f,
                "{text} is longer than any period or duration amiro can count (the longest period the firmware \
                 can schedule is {})",
                human_micros(amiro_can::MAX_PERIOD_US)
            ),
            Self::TooLong { micros, max_micros } => write!(
                f,
                "{} is longer than the longest period the firmware can schedule ({})",
                human_micros(*micros),
                human_micros(*max_micros)
            ),
            Self::NotExact { micros } => {
                write!(
                    f,
                    "{} cannot be encoded exactly: the sample time is a 16-bit count (at most 65535) of µs, ms or s",
                    human_micros(*micros)
                )?;
                let nearest = nearest_encodings(*micros);
                if !nearest.is_empty() {
                    write!(f, "; nearest: {}", nearest.join(", "))?;
                }
                Ok(())
            }
        }
    }
}

impl std::error::Error for PeriodError {}

/// Parses `900us`, `900µs`, `50ms`, `1.5s`, `2 s` into whole microseconds (`amiro_can::duration`'s
/// decoder, which the emulation's tools read durations with too).
pub fn parse_period(text: &str) -> Result<Period, PeriodError> {
    use amiro_can::duration::DurationError;
    let (micros, unit) = amiro_can::duration::parse(text).map_err(|error| match error {
        DurationError::Malformed(text) => PeriodError::Malformed(text.to_string()),
        DurationError::MissingUnit(text) => PeriodError::MissingUnit(text.to_string()),
        DurationError::UnknownUnit(text) => PeriodError::UnknownUnit(text.to_string()),
        DurationError::BelowResolution(text) => PeriodError::BelowResolution(text.to_string()),
        DurationError::Huge(text) => PeriodError::Huge(text.to_string()),
    })?;
    let written_unit = match unit {
        amiro_can::TimeUnit::Micros => PeriodUnit::Micros,
        amiro_can::TimeUnit::Millis => PeriodUnit::Millis,
        amiro_can::TimeUnit::Seconds => PeriodUnit::Seconds,
    };
    Ok(Period {
        micros,
        written_unit,
    })
}

/// Chooses the wire encoding of a period: the unit the user wrote if it holds the period exactly, otherwise the
/// finest unit that does. `max_micros` is the longest period the firmware accepts.
pub fn encode_period(period: Period, max_micros: u64) -> Result<EncodedPeriod, PeriodError> {
    if period.micros == 0 {
        return Err(PeriodError::Zero);
    }
    if period.micros > max_micros {
        return Err(PeriodError::TooLong {
            micros: period.micros,
            max_micros,
        });
    }
    let candidates = [
        period.written_unit,
        PeriodUnit::Micros,
        PeriodUnit::Millis,
        PeriodUnit::Seconds,
    ];
    candidates
        .into_iter()
        .find_map(|unit| {
            exact_count(period.micros, unit).map(|value| EncodedPeriod { value, unit })
        })
        .ok_or(PeriodError::NotExact {
            micros: period.micros,
        })
}

/// The 16-bit count of `unit` that is exactly `micros`, if any.
fn exact_count(micros: u64, unit: PeriodUnit) -> Option<u16> {
    if !micros.is_multiple_of(unit.micros()) {
        return None;
    }
    u16::try_from(micros / unit.micros())
        .ok()
        .filter(|count| *count > 0)
}

/// The encodable periods just below and just above `micros`, written as the user would type them.
fn nearest_encodings(micros: u64) -> Vec<String> {
    let mut candidates = Vec::new();
    for unit in [PeriodUnit::Micros, PeriodUnit::Millis, PeriodUnit::Seconds] {
        let floor = (micros / unit.micros()).min(u64::from(u16::MAX));
        let ceil = micros.div_ceil(unit.micros());
        for count in [floor, ceil] {
            if (1..=u64::from(u16::MAX)).contains(&count) {
                candidates.push((
                    count * unit.micros(),
                    format!("{count}{}", unit.symbol().replace('µ', "u")),
                ));
            }
        }
    }
    let below = candidates
        .iter()
        .filter(|(c, _)| *c < micros)
        .max_by_key(|(c, _)| *c);
    let above = candidates
        .iter()
        .filter(|(c, _)| *c > micros)
        .min_by_key(|(c, _)| *c);
    below
        .into_iter()
        .chain(above)
        .map(|(_, text)| text.clone())
        .collect()
}

/// A microsecond count for people, in the largest unit not above it, exactly: `900 µs`, `62.5 ms`, `2 s`.
pub fn human_micros(micros: u64) -> String {
    let (per_unit, digits, symbol) = if micros >= 1_000_000 {
        (1_000_000, 6, "s")
    } else if micros >= 1_000 {
        (1_000, 3, "ms")
    } else {
        (1, 0, "µs")
    };
    let (whole, fraction) = (micros / per_unit, micros % per_unit);
    if fraction == 0 {
        format!("{whole} {symbol}")
    } else {
        let fraction = format!("{fraction:0digits$}");
        format!("{whole}.{} {symbol}", fraction.trim_end_matches('0'))
    }
}

/// Parses a duration for options such as `--timeout 5s` (same syntax as periods, any length).
pub fn parse_duration(text: &str) -> Result<Duration, PeriodError> {
    let period = parse_period(text)?;
    Ok(Duration::from_micros(period.micros))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAX: u64 = u32::MAX as u64;

    fn encode(text: &str) -> Result<(u16, PeriodUnit), PeriodError> {
        let encoded = encode_period(parse_period(text)?, MAX)?;
        Ok((encoded.value, encoded.unit))
    }

    #[test]
    fn the_written_unit_is_kept_when_it_fits() {
        assert_eq!(encode("900us"), Ok((900, PeriodUnit::Micros)));
        assert_eq!(encode("900µs"), Ok((900, PeriodUnit::Micros)));
        assert_eq!(encode("50ms"), Ok((50, PeriodUnit::Millis)));
        assert_eq!(encode("2s"), Ok((2, PeriodUnit::Seconds)));
        assert_eq!(encode("2000ms"), Ok((2000, PeriodUnit::Millis)));
        assert_eq!(encode("65535us"), Ok((65535, PeriodUnit::Micros)));
    }

    #[test]
    fn another_unit_is_chosen_when_it_encodes_exactly() {
        assert_eq!(encode("70000us"), Ok((70, PeriodUnit::Millis)));
        assert_eq!(encode("1.5s"), Ok((1500, PeriodUnit::Millis)));
        assert_eq!(encode("0.9ms"), Ok((900, PeriodUnit::Micros)));
        assert_eq!(encode("120000ms"), Ok((120, PeriodUnit::Seconds)));
        assert_eq!(encode("2.5ms"), Ok((2500, PeriodUnit::Micros)));
    }

    #[test]
    fn periods_without_exact_encoding_are_refused() {
        assert_eq!(
            encode("65536001us"),
            Err(PeriodError::NotExact { micros: 65_536_001 })
        );
        let message = PeriodError::NotExact { micros: 65_536_001 }.to_string();
        assert!(message.contains("nearest: 65535ms, 66s"), "{message}");
        assert_eq!(encode("0ms"), Err(PeriodError::Zero));
        assert_eq!(
            encode("0.5us"),
            Err(PeriodError::BelowResolution("0.5us".into()))
        );
        assert_eq!(
            encode("5000s"),
            Err(PeriodError::TooLong {
                micros: 5_000_000_000,
                max_micros: MAX
            })
        );
        assert_eq!(encode("900"), Err(PeriodError::MissingUnit("900".into())));
        assert_eq!(
            encode("900min"),
            Err(PeriodError::UnknownUnit("min".into()))
        );
        assert_eq!(encode("fast"), Err(PeriodError::Malformed("fast".into())));
        assert_eq!(
            encode("1.2.3s"),
            Err(PeriodError::Malformed("1.2.3s".into()))
        );
        assert!(encode("99999999999999999999s").is_err());
    }

    #[test]
    fn a_period_beyond_counting_names_the_real_limit() {
        for huge in [
            "99999999999999999999s",
            "18446744073709552s",
            "18446744073709551616us",
        ] {
            let error = encode(huge).unwrap_err();
            assert_eq!(error, PeriodError::Huge(huge.into()));
            let message = error.to_string();
            assert!(message.contains("4294.967295 s"), "{message}");
            assert!(!message.contains("18446744073709.551615"), "{message}");
        }
    }

    #[test]
    fn durations_print_in_the_largest_exact_unit() {
        assert_eq!(human_micros(900), "900 µs");
        assert_eq!(human_micros(70_000), "70 ms");
        assert_eq!(human_micros(2_000_000), "2 s");
        assert_eq!(human_micros(62_500), "62.5 ms");
        assert_eq!(human_micros(1_500_000), "1.5 s");
        assert_eq!(human_micros(u64::from(u32::MAX)), "4294.967295 s");
        assert_eq!(human_micros(0), "0 µs");
        assert_eq!(parse_duration("1.5s"), Ok(Duration::from_millis(1500)));
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn an_accepted_period_is_encoded_exactly(micros in 1u64..=MAX, unit in 0usize..3) {
                let written_unit = [PeriodUnit::Micros, PeriodUnit::Millis, PeriodUnit::Seconds][unit];
                match encode_period(Period { micros, written_unit }, MAX) {
                    Ok(encoded) => prop_assert_eq!(u64::from(encoded.value) * encoded.unit.micros(), micros),
                    Err(error) => prop_assert_eq!(error, PeriodError::NotExact { micros }),
                }
            }

            #[test]
            fn printed_periods_parse_back(micros in 1u64..=MAX) {
                let text = human_micros(micros).replace(' ', "");
                prop_assert_eq!(parse_period(&text).map(|period| period.micros), Ok(micros));
            }

            #[test]
            fn any_text_is_a_period_or_an_error(text in "\\PC{0,20}") {
                let _ = parse_period(&text);
            }
        }
    }
}
