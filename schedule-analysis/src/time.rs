//! Time in whole nanoseconds: exact integer arithmetic for the fixed points, so every iteration terminates on an
//! exact value and no rounding error can make a ceiling count one job too few.
//!
//! Model files give microseconds as `f64`. Converting them rounds *safely*: execution times, jitters and critical
//! sections round up ([`Time::from_us_up`]), periods and deadlines round down ([`Time::from_us_down`]); values that
//! are whole nanoseconds up to float noise (12.5 µs, 545 µs) convert exactly.

use core::fmt;

/// A duration or instant in nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Time(u64);

/// How close (in ns) a converted value must be to a whole nanosecond to be taken as that nanosecond.
const SNAP_NS: f64 = 1e-6;

impl Time {
    /// No time at all.
    pub const ZERO: Time = Time(0);
    /// The largest representable time (about 584 years). The `plus`/`times` helpers saturate here; the fixed
    /// points use the checked forms ([`Time::checked_plus`], [`Time::checked_times`]) and report an overflow as
    /// unbounded, so a saturated value can never pass as a response time.
    pub const MAX: Time = Time(u64::MAX);
    /// The longest time a model may give (10^12 µs, about 11.6 days): with every input at most this, sums and
    /// multiples the analysis forms stay far from [`Time::MAX`] (a default horizon of 1000 × the longest period
    /// still fits), and the float utilisations stay exact to the nanosecond.
    pub const LIMIT: Time = Time(1_000_000_000_000_000);
    /// [`Time::LIMIT`] in microseconds, as model files write it.
    pub const LIMIT_US: f64 = 1e12;

    /// From whole nanoseconds.
    pub const fn from_ns(ns: u64) -> Time {
        Time(ns)
    }

    /// From whole microseconds.
    pub const fn from_us(us: u64) -> Time {
        Time(us.saturating_mul(1000))
    }

    /// Whole nanoseconds.
    pub const fn as_ns(self) -> u64 {
        self.0
    }

    /// Microseconds as a float, for reports.
    pub fn as_us_f64(self) -> f64 {
        self.0 as f64 / 1000.0
    }

    /// From fractional microseconds, rounding up to the next nanosecond (for costs: never optimistic).
    /// Negative and NaN give zero, values beyond the range saturate.
    pub fn from_us_up(us: f64) -> Time {
        Time::convert(us, true)
    }

    /// From fractional microseconds, rounding down (for periods and deadlines: never optimistic).
    pub fn from_us_down(us: f64) -> Time {
        Time::convert(us, false)
    }

    fn convert(us: f64, up: bool) -> Time {
        // NaN and negative values fail this test.
        if us.is_nan() || us <= 0.0 {
            return Time::ZERO;
        }
        let ns = us * 1000.0;
        if ns >= u64::MAX as f64 {
            return Time::MAX;
        }
        // `as` truncates toward zero, which is floor for positive values (core has no `f64::floor`).
        let below = ns as u64;
        let fraction = ns - below as f64;
        if fraction <= SNAP_NS {
            Time(below)
        } else if 1.0 - fraction <= SNAP_NS || up {
            Time(below.saturating_add(1))
        } else {
            Time(below)
        }
    }

    /// `self + other`, saturating at [`Time::MAX`].
    pub const fn plus(self, other: Time) -> Time {
        Time(self.0.saturating_add(other.0))
    }

    /// `self + other`, or `None` when the sum does not fit.
    pub const fn checked_plus(self, other: Time) -> Option<Time> {
        match self.0.checked_add(other.0) {
            Some(ns) => Some(Time(ns)),
            None => None,
        }
    }

    /// `self × n`, or `None` when the product does not fit.
    pub const fn checked_times(self, n: u64) -> Option<Time> {
        match self.0.checked_mul(n) {
            Some(ns) => Some(Time(ns)),
            None => None,
        }
    }

    /// From fractional microseconds rounded up like [`Time::from_us_up`], or `None` when the value is not a finite
    /// number in `0 ..= LIMIT_US` (instead of saturating).
    pub fn try_from_us_up(us: f64) -> Option<Time> {
        (us.is_finite() && (0.0..=Time::LIMIT_US).contains(&us)).then(|| Time::convert(us, true))
    }

    /// From fractional microseconds rounded down like [`Time::from_us_down`], or `None` outside `0 ..= LIMIT_US`.
    pub fn try_from_us_down(us: f64) -> Option<Time> {
        (us.is_finite() && (0.0..=Time::LIMIT_US).contains(&us)).then(|| Time::convert(us, false))
    }

    /// `self - other`, or zero when `other` is larger.
    pub const fn minus(self, other: Time) -> Time {
        Time(self.0.saturating_sub(other.0))
    }

    /// `self × n`, saturating.
    pub const fn times(self, n: u64) -> Time {
        Time(self.0.saturating_mul(n))
    }

    /// The larger of the two.
    pub const fn max_of(self, other: Time) -> Time {
        if self.0 >= other.0 {
            self
        } else {
            other
        }
    }

    /// Whether this is zero.
    pub const fn is_zero(self) -> bool {
        self.0 == 0
    }
}

impl fmt::Display for Time {
    /// Microseconds with up to three decimals, trailing zeros dropped: `12.5`, `545`, `0.333`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let whole = self.0 / 1000;
        let mut frac = self.0 % 1000;
        if frac == 0 {
            return write!(f, "{whole}");
        }
        let mut digits = 3;
        while frac.is_multiple_of(10) {
            frac /= 10;
            digits -= 1;
        }
        write!(f, "{whole}.{frac:0digits$}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_and_half_microseconds_convert_exactly() {
        assert_eq!(Time::from_us_up(12.5), Time::from_ns(12_500));
        assert_eq!(Time::from_us_down(12.5), Time::from_ns(12_500));
        assert_eq!(Time::from_us_up(545.0), Time::from_us(545));
        // 0.1 is not exact in binary; it must still be 100 ns both ways.
        assert_eq!(Time::from_us_up(0.1), Time::from_ns(100));
        assert_eq!(Time::from_us_down(0.1), Time::from_ns(100));
    }

    #[test]
    fn sub_nanosecond_fractions_round_safely() {
        assert_eq!(Time::from_us_up(0.0004), Time::from_ns(1));
        assert_eq!(Time::from_us_down(0.0004), Time::ZERO);
        assert_eq!(Time::from_us_up(1.0005), Time::from_ns(1001));
        assert_eq!(Time::from_us_down(1.0005), Time::from_ns(1000));
    }

    #[test]
    fn nonsense_inputs_do_not_panic() {
        assert_eq!(Time::from_us_up(-3.0), Time::ZERO);
        assert_eq!(Time::from_us_up(f64::NAN), Time::ZERO);
        assert_eq!(Time::from_us_up(f64::INFINITY), Time::MAX);
        assert_eq!(Time::MAX.plus(Time::from_ns(1)), Time::MAX);
        assert_eq!(Time::ZERO.minus(Time::from_ns(1)), Time::ZERO);
    }

    #[test]
    fn checked_forms_refuse_what_saturation_would_hide() {
        assert_eq!(Time::MAX.checked_plus(Time::from_ns(1)), None);
        assert_eq!(Time::from_ns(u64::MAX / 2 + 1).checked_times(2), None);
        assert_eq!(Time::from_ns(3).checked_times(2), Some(Time::from_ns(6)));
        // The reproducer: 1e300 µs and 1e17 µs are not times the analysis can represent.
        assert_eq!(Time::try_from_us_up(1e300), None);
        assert_eq!(Time::try_from_us_down(1e17), None);
        assert_eq!(Time::try_from_us_up(f64::NAN), None);
        assert_eq!(Time::try_from_us_up(-1.0), None);
        assert_eq!(Time::try_from_us_down(Time::LIMIT_US), Some(Time::LIMIT));
        assert_eq!(Time::try_from_us_up(12.5), Some(Time::from_ns(12_500)));
    }

    /// Formats into a stack buffer (the core builds without an allocator).
    fn shown(t: Time) -> ([u8; 32], usize) {
        use core::fmt::Write;
        struct Buf([u8; 32], usize);
        impl Write for Buf {
            fn write_str(&mut self, s: &str) -> core::fmt::Result {
                let end = self.1 + s.len();
                self.0
                    .get_mut(self.1..end)
                    .ok_or(core::fmt::Error)?
                    .copy_from_slice(s.as_bytes());
                self.1 = end;
                Ok(())
            }
        }
        let mut buf = Buf([0; 32], 0);
        let _ = write!(buf, "{t}");
        (buf.0, buf.1)
    }

    #[test]
    fn displays_microseconds() {
        let check = |t: Time, expected: &str| {
            let (bytes, len) = shown(t);
            assert_eq!(core::str::from_utf8(&bytes[..len]), Ok(expected));
        };
        check(Time::from_ns(12_500), "12.5");
        check(Time::from_us(545), "545");
        check(Time::from_ns(333), "0.333");
        check(Time::from_ns(1_050), "1.05");
    }
}
