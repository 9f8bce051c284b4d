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

#[cfg(test)]
mod tests {
    use super::*;

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
