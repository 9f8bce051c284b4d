//! The I2C bus clear (NXP UM10204 §3.1.16): a device left driving SDA low in the middle of a byte
//! (the master's block reset under it after a timeout or a bus error) is clocked out of that byte
//! with up to nine SCL pulses, then a STOP frees the bus. Hardware-free: the pins are a
//! [`ClearPins`] (the polled master's GPIO adapter on the chips, a fake pin pair in the tests).
//!
//! A device that drives SDA low is sending a 0 bit of a byte it was reading out, or its
//! acknowledge: each SCL pulse ends one bit, so within nine pulses (eight data bits and the
//! acknowledge) it reaches the acknowledge bit, which the master leaves high (a NACK), and lets go
//! of SDA. A bus whose SDA is still low after nine pulses is held by something no clocking frees
//! ([`Stuck`]).
//!
//! A device may hold SCL low after the master releases it, to stretch the clock (UM10204 §3.1.9):
//! each release waits for SCL to read high before the high half period starts, as the I2C block
//! itself does, so no pulse is counted that the device did not see. The wait is counted in half
//! periods (the adapter's cycle-counted [`ClearPins::half_period`]), at most [`MAX_STRETCH`] a
//! release; SCL still low then is [`Stuck`] as well.

/// The most SCL pulses a bus clear gives: one byte and its acknowledge (UM10204 §3.1.16).
pub const MAX_PULSES: u8 = 9;

/// The most half periods a release of SCL waits for it to read high: 8, 10 µs at 400 kHz (four SCL
/// periods). Bit-level stretching fits (a slow device extending each clock LOW period, UM10204
/// §3.1.9); a longer hold during a clear, a byte-level stretch or a line stuck low, is [`Stuck`], and
/// the next transfer's wait for a free bus (the master's flag timeout, 200 µs) meets it again. Kept
/// short because every release of a clear is charged it in the execution-time bounds: at the flag
/// timeout (160) PowerManagement's bus section, which holds a clear, grew by 3 ms and the
/// proximity ring's jitter went over its budget (docs/i2c.md, "The bus clear").
pub const MAX_STRETCH: u8 = 8;

/// SCL and SDA of one bus, driven open drain: `false` pulls a line low, `true` releases it to the
/// pull-up.
pub trait ClearPins {
    /// Sets SCL and SDA.
    fn lines(&mut self, scl: bool, sda: bool);
    /// Waits half an SCL period at the bus's rate.
    fn half_period(&mut self);
    /// Whether SCL reads high.
    fn scl_is_high(&mut self) -> bool;
    /// Whether SDA reads high.
    fn sda_is_high(&mut self) -> bool;
}

/// SDA still low after [`MAX_PULSES`] pulses, or SCL held low [`MAX_STRETCH`] half periods after
/// its release: the bus is held by a device no clocking frees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stuck;

/// Clears the bus on `pins` (both lines released on entry, for half an SCL period at least):
/// pulses SCL while SDA reads low, at most [`MAX_PULSES`] times, each high half period counted from
/// SCL's rise, then sends a STOP and leaves both lines released. Returns the number of pulses given,
/// or [`Stuck`] (no STOP: with SDA or SCL held low none can be made).
pub fn clear_bus(pins: &mut impl ClearPins) -> Result<u8, Stuck> {
    let mut pulses = 0;
    // One pass a pulse (SDA low), or the STOP (SDA high): SCL low, then released (SDA released for a
    // pulse; in the STOP, SDA low under SCL first, and released once SCL is high: a rising SDA with
    // SCL high).
    loop {
        let stop = pins.sda_is_high();
        if !stop && pulses == MAX_PULSES {
            return Err(Stuck);
        }
        pins.lines(false, true);
        pins.half_period();
        if stop {
            pins.lines(false, false);
            pins.half_period();
        }
        pins.lines(true, !stop);
        let mut stretched = 0;
        let held = loop {
            if pins.scl_is_high() {
                break false;
            }
            if stretched == MAX_STRETCH {
                break true;
            }
            stretched += 1;
            pins.half_period();
        };
        if !held {
            pins.half_period();
            if !stop {
                pulses += 1;
                continue;
            }
        }
        // The STOP's rising SDA, or both lines released where a device holds SCL.
        pins.lines(true, true);
        pins.half_period();
        return if held { Err(Stuck) } else { Ok(pulses) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the fake bus saw, in order.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Edge {
        /// SCL went low.
        SclFall,
        /// SDA rose while SCL was high.
        Stop,
        /// SDA fell while SCL was high.
        Start,
    }

    /// Time on the fake bus, in steps: a half period is [`HALF`] of them.
    const HALF: u64 = 4;

    /// [`MAX_STRETCH`] half periods in steps: the longest a release waits for SCL.
    const BOUND: u64 = MAX_STRETCH as u64 * HALF;

    /// A pin pair with a device that holds SDA low until it has seen `held_for` falling SCL edges
    /// (the bit it was sending ends at each), and holds SCL low for `stretch` steps after each falling
    /// edge (clock stretching).
    struct FakeBus {
        held_for: u32,
        stretch: u64,
        now: u64,
        scl_held_until: u64,
        falls: u32,
        scl_driven_low: bool,
        sda_driven_low: bool,
        half_periods: u32,
        edges: Vec<Edge>,
    }

    impl FakeBus {
        fn new(held_for: u32) -> Self {
            Self::stretching(held_for, 0)
        }

        fn stretching(held_for: u32, stretch: u64) -> Self {
            // The master drives nothing on entry: the adapter hands the pins over released.
            Self {
                held_for,
                stretch,
                now: 0,
                scl_held_until: 0,
                falls: 0,
                scl_driven_low: false,
                sda_driven_low: false,
                half_periods: 0,
                edges: Vec::new(),
            }
        }

        fn scl_line(&self) -> bool {
            !self.scl_driven_low && self.now >= self.scl_held_until
        }

        fn device_holds_sda(&self) -> bool {
            self.falls < self.held_for
        }

        fn sda_line(&self) -> bool {
            !self.sda_driven_low && !self.device_holds_sda()
        }

        /// The falling SCL edges the device saw.
        fn pulses(&self) -> u32 {
            self.falls
        }
    }

    impl ClearPins for FakeBus {
        fn lines(&mut self, scl: bool, sda: bool) {
            // One line changes at a time on the wire: SCL first, then SDA.
            let scl_before = self.scl_line();
            self.scl_driven_low = !scl;
            if scl_before && !self.scl_line() {
                self.falls += 1;
                self.edges.push(Edge::SclFall);
                self.scl_held_until = self.now + self.stretch;
            }
            let before = self.sda_line();
            self.sda_driven_low = !sda;
            let after = self.sda_line();
            if self.scl_line() && before != after {
                self.edges
                    .push(if after { Edge::Stop } else { Edge::Start });
            }
        }

        fn half_period(&mut self) {
            self.now += HALF;
            self.half_periods += 1;
        }

        fn scl_is_high(&mut self) -> bool {
            self.scl_line()
        }

        fn sda_is_high(&mut self) -> bool {
            self.sda_line()
        }
    }

    /// The STOP's edges: SCL low once more, then SDA low (with SCL low: no edge), then SDA rising
    /// with SCL high.
    fn ends_with_stop(bus: &FakeBus) -> bool {
        bus.edges.ends_with(&[Edge::SclFall, Edge::Stop])
    }

    #[test]
    fn a_free_bus_gets_no_pulse_and_a_stop() {
        let mut bus = FakeBus::new(0);
        assert_eq!(clear_bus(&mut bus), Ok(0));
        assert_eq!(bus.edges, [Edge::SclFall, Edge::Stop]);
        assert!(!bus.scl_driven_low && !bus.sda_driven_low);
        // The STOP's four.
        assert_eq!(bus.half_periods, 4);
    }

    #[test]
    fn a_device_holding_sda_for_k_bits_gets_k_pulses_then_a_stop() {
        for k in 1..=u32::from(MAX_PULSES) {
            let mut bus = FakeBus::new(k);
            assert_eq!(clear_bus(&mut bus), Ok(k as u8), "held for {k}");
            // k pulses, then the STOP's falling SCL: the clear stops as soon as SDA reads high.
            assert_eq!(bus.pulses(), k + 1, "held for {k}");
            assert!(ends_with_stop(&bus), "held for {k}: {:?}", bus.edges);
            assert!(!bus.edges.contains(&Edge::Start), "held for {k}");
            assert!(!bus.scl_driven_low && !bus.sda_driven_low);
            assert_eq!(bus.half_periods, 2 * k + 4);
        }
    }

    #[test]
    fn a_device_holding_sda_past_nine_pulses_is_stuck_without_a_stop() {
        for held in [u32::from(MAX_PULSES) + 1, 100, u32::MAX] {
            let mut bus = FakeBus::new(held);
            assert_eq!(clear_bus(&mut bus), Err(Stuck), "held for {held}");
            assert_eq!(bus.pulses(), u32::from(MAX_PULSES), "held for {held}");
            assert!(!bus.edges.contains(&Edge::Stop));
            // Both lines left released for the block.
            assert!(!bus.scl_driven_low && !bus.sda_driven_low);
            assert_eq!(bus.half_periods, 2 * u32::from(MAX_PULSES));
        }
    }

    #[test]
    fn a_device_stretching_the_clock_sees_every_pulse_and_the_stop() {
        // Each low period stretched past the master's whole pulse (three half periods: SCL would
        // still be low when the master pulls it low again), well within the bound: every pulse the
        // clear counts is one the device saw.
        for k in 1..=u32::from(MAX_PULSES) {
            let mut bus = FakeBus::stretching(k, 3 * HALF);
            assert_eq!(clear_bus(&mut bus), Ok(k as u8), "held for {k}");
            assert_eq!(
                bus.pulses(),
                k + 1,
                "held for {k}: each pulse seen, and the STOP's fall"
            );
            assert!(ends_with_stop(&bus), "held for {k}: {:?}", bus.edges);
            assert!(!bus.edges.contains(&Edge::Start), "held for {k}");
            assert!(!bus.scl_driven_low && !bus.sda_driven_low);
        }
        // Stretched to the last half period a release waits.
        let mut bus = FakeBus::stretching(2, BOUND);
        assert_eq!(clear_bus(&mut bus), Ok(2));
        assert!(ends_with_stop(&bus), "{:?}", bus.edges);
    }

    #[test]
    fn scl_held_low_past_the_bound_is_stuck_with_both_lines_released() {
        // SDA held for three bits, SCL stretched for longer than a release waits.
        let mut bus = FakeBus::stretching(3, BOUND + 3 * HALF);
        assert_eq!(clear_bus(&mut bus), Err(Stuck));
        assert_eq!(
            bus.pulses(),
            1,
            "no pulse after the one SCL stayed low behind"
        );
        assert!(!bus.edges.contains(&Edge::Stop));
        assert!(!bus.scl_driven_low && !bus.sda_driven_low);
        // Held low past the bound only in the STOP (SDA free at once, a device stretching then).
        let mut bus = FakeBus::stretching(0, BOUND + 3 * HALF);
        assert_eq!(clear_bus(&mut bus), Err(Stuck));
        assert!(
            !bus.edges.contains(&Edge::Stop),
            "no STOP on the wire: {:?}",
            bus.edges
        );
        assert!(!bus.scl_driven_low && !bus.sda_driven_low);
    }
}
