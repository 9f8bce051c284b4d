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

/// The most SCL pulses a bus clear gives: one byte and its acknowledge (UM10204 §3.1.16).
pub const MAX_PULSES: u8 = 9;

/// SCL and SDA of one bus, driven open drain: `false` pulls a line low, `true` releases it to the
/// pull-up.
pub trait ClearPins {
    /// Sets SCL and SDA, then waits half an SCL period at the bus's rate.
    fn lines(&mut self, scl: bool, sda: bool);
    /// Whether SDA reads high.
    fn sda_is_high(&mut self) -> bool;
}

/// SDA still low after [`MAX_PULSES`] pulses: the bus is held by a device no clocking frees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stuck;

/// Clears the bus on `pins` (both lines released on entry, for half an SCL period at least):
/// pulses SCL while SDA reads low, at most [`MAX_PULSES`] times, then sends a STOP and leaves both
/// lines released. Returns the number of pulses given, or [`Stuck`] (no STOP: with SDA low none
/// can be made).
pub fn clear_bus(pins: &mut impl ClearPins) -> Result<u8, Stuck> {
    let mut pulses = 0;
    while !pins.sda_is_high() {
        if pulses == MAX_PULSES {
            return Err(Stuck);
        }
        pins.lines(false, true);
        pins.lines(true, true);
        pulses += 1;
    }
    // STOP: SDA low while SCL is low, then SCL high, then SDA high (a rising SDA with SCL high).
    pins.lines(false, true);
    pins.lines(false, false);
    pins.lines(true, false);
    pins.lines(true, true);
    Ok(pulses)
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

    /// A pin pair with a device that holds SDA low until it has seen `held_for` falling SCL edges
    /// (the bit it was sending ends at each).
    struct FakeBus {
        held_for: u32,
        falls: u32,
        scl_driven_low: bool,
        sda_driven_low: bool,
        half_periods: u32,
        edges: Vec<Edge>,
    }

    impl FakeBus {
        fn new(held_for: u32) -> Self {
            // The master drives nothing on entry: the adapter hands the pins over released.
            Self {
                held_for,
                falls: 0,
                scl_driven_low: false,
                sda_driven_low: false,
                half_periods: 0,
                edges: Vec::new(),
            }
        }

        fn device_holds_sda(&self) -> bool {
            self.falls < self.held_for
        }

        fn sda_line(&self) -> bool {
            !self.sda_driven_low && !self.device_holds_sda()
        }

        fn pulses(&self) -> u32 {
            self.falls
        }
    }

    impl ClearPins for FakeBus {
        fn lines(&mut self, scl: bool, sda: bool) {
            // One line changes at a time on the wire: SCL first, then SDA.
            if !scl && !self.scl_driven_low {
                self.falls += 1;
                self.edges.push(Edge::SclFall);
            }
            self.scl_driven_low = !scl;
            let before = self.sda_line();
            self.sda_driven_low = !sda;
            let after = self.sda_line();
            if !self.scl_driven_low && before != after {
                self.edges
                    .push(if after { Edge::Stop } else { Edge::Start });
            }
            self.half_periods += 1;
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
}
