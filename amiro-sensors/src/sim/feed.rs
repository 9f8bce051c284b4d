//! Feeding a world's readings to a board's simulators in one call per group, in the protocol's
//! sensor order: the ring's eight counts go to the sensor on the bus and mux channel the
//! PowerManagement wires that index to (`drivers::ring::WIRING`), the floor's four to the
//! DiWheelDrive's mux channels (channel = protocol index, `drivers::floor`). `None` gives every
//! sensor of the group its pattern back.

use super::SimMuxedProximity;
use crate::drivers::ring::{RingBus, RING_SENSORS, WIRING};

/// Feeds the ring: `i2c1` and `i2c2` are the muxes on the PowerManagement's two buses.
pub fn feed_ring(
    i2c1: &mut SimMuxedProximity,
    i2c2: &mut SimMuxedProximity,
    counts: Option<[u16; RING_SENSORS]>,
) {
    for (index, (bus, channel)) in WIRING.iter().enumerate() {
        let mux = match bus {
            RingBus::I2c1 => &mut *i2c1,
            RingBus::I2c2 => &mut *i2c2,
        };
        let value = counts.and_then(|c| c.get(index).copied());
        mux.set_proximity(usize::from(channel.number()), value);
    }
}

/// Feeds the four floor sensors (front-right, right-wheel, left-wheel, front-left).
pub fn feed_floor(mux: &mut SimMuxedProximity, counts: Option<[u16; 4]>) {
    for channel in 0..4 {
        mux.set_proximity(channel, counts.and_then(|c| c.get(channel).copied()));
    }
}
