//! Time for the sensor-data handler: a microsecond clock trait, so the same code runs on the
//! chip's monotonic timer and under a fake clock in host tests.

use core::cell::Cell;

/// A monotonic clock counting microseconds since an arbitrary start (usually boot).
///
/// The firmware implements it on its RTIC monotonic; host tests use [`FakeClock`]. A `u64` of
/// microseconds does not wrap within the life of a robot (585 000 years), so the handler never has
/// to reason about wrap-around.
pub trait Clock {
    /// The current time in microseconds. Must never go backwards.
    fn now_us(&self) -> u64;
}

impl<C: Clock + ?Sized> Clock for &C {
    fn now_us(&self) -> u64 {
        (**self).now_us()
    }
}

/// A clock that only moves when told to: deterministic time for tests and simulations.
///
/// It uses a [`Cell`] so a test can advance it while the code under test holds a shared reference.
#[derive(Debug, Default)]
pub struct FakeClock {
    now_us: Cell<u64>,
}

impl FakeClock {
    /// A fake clock that reads `start_us`.
    pub const fn new(start_us: u64) -> Self {
        Self {
            now_us: Cell::new(start_us),
        }
    }

    /// Moves the clock to `at_us`. Time never runs backwards: an earlier value is ignored.
    pub fn set(&self, at_us: u64) {
        if at_us > self.now_us.get() {
            self.now_us.set(at_us);
        }
    }

    /// Moves the clock forward by `delta_us` (saturating at the end of time).
    pub fn advance(&self, delta_us: u64) {
        self.now_us.set(self.now_us.get().saturating_add(delta_us));
    }
}

impl Clock for FakeClock {
    fn now_us(&self) -> u64 {
        self.now_us.get()
    }
}

/// `n / d` for microsecond counts, without the 64-bit division routine (about 900 bytes of
/// compiler-builtins on a Cortex-M3, which has no 64-bit divide, and a shift-and-subtract loop of
/// up to 64 passes, some 7 000 cycles at its worst on the F103): one 32-bit division while `n`
/// fits in 32 bits (the first 71 minutes of a count), the motion math's exact long division in
/// base 2¹⁶ digits after that ([`crate::motion::divide::div_u64`]: one `UDIV` for the high word
/// and two quotient digits, no loop, a few hundred cycles). `d == 0` yields `u64::MAX`.
#[inline(never)]
pub fn div_us(n: u64, d: u32) -> u64 {
    let Some(divisor) = core::num::NonZeroU64::new(u64::from(d)) else {
        return u64::MAX;
    };
    if let Ok(small) = u32::try_from(n) {
        return u64::from(small / d);
    }
    crate::motion::divide::div_u64(n, divisor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn div_us_equals_the_division_on_both_paths() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut values = vec![0, 1, u64::from(u32::MAX), u64::from(u32::MAX) + 1, u64::MAX];
        for _ in 0..2_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            values.push(x >> (x % 64));
        }
        for &n in &values {
            for d in [1u32, 2, 3, 7, 1_000, 1_000_000, u32::MAX, (n as u32) | 1] {
                assert_eq!(div_us(n, d), n / u64::from(d), "{n} / {d}");
            }
        }
        assert_eq!(div_us(5, 0), u64::MAX);
    }

    fn read_through_trait(clock: &impl Clock) -> u64 {
        clock.now_us()
    }

    #[test]
    fn fake_clock_moves_only_forward() {
        let clock = FakeClock::new(1_000);
        assert_eq!(read_through_trait(&clock), 1_000);
        clock.advance(250);
        assert_eq!(clock.now_us(), 1_250);
        clock.set(900);
        assert_eq!(clock.now_us(), 1_250, "set() must not move time backwards");
        clock.set(5_000);
        assert_eq!(read_through_trait(&&clock), 5_000);
        clock.advance(u64::MAX);
        assert_eq!(clock.now_us(), u64::MAX);
    }
}
