//! The IMU from the motion: the gyroscope's z axis reads the turn rate, the accelerometer the
//! body's acceleration plus gravity, the magnetometer the lab's field turned into the robot's
//! frame by its heading. Axes are the robot's (x forward, y left, z up), which is how both
//! revisions' parts are mounted in amiro-sensors' simulators (a part flat and face up).
//!
//! The readings come in the units the register-level simulators of `amiro_sensors::sim` take
//! before they encode for the configured range:
//! - revision 1-1: L3G4200D in millidegrees per second, LIS331DLH in micro-g, HMC5883L in nT;
//! - revision 1-2: BNO055 accelerometer in mg, magnetometer in nT, gyroscope in 1/16 °/s digits.
//!
//! Noise (seeded, standard deviations): gyroscope 0.2 °/s (the L3G4200D's 0.03 °/s/√Hz over its
//! 50 Hz bandwidth), accelerometer 5 mg, magnetometer 100 nT. The robot stands level: no pitch
//! or roll, so gravity is +1 g on z, and the field's vertical part is −field · sin(inclination).

use crate::file::LabField;
use crate::motion::Motion;
use crate::noise::Noise;

/// Standard gravity, m/s².
pub const G: f64 = 9.806_65;
/// Gyroscope noise, °/s.
pub const GYRO_NOISE_DPS: f64 = 0.2;
/// Accelerometer noise, g.
pub const ACCEL_NOISE_G: f64 = 0.005;
/// Magnetometer noise, nT.
pub const FIELD_NOISE_NT: f64 = 100.0;

/// The IMU's physical reading, before any part's encoding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuReading {
    /// Angular rate, °/s, x y z.
    pub rate_dps: [f64; 3],
    /// Acceleration including gravity, g, x y z.
    pub accel_g: [f64; 3],
    /// Magnetic field, nT, x y z.
    pub field_nt: [f64; 3],
}

/// Revision 1-1's three parts, in the simulators' units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Imu11 {
    /// L3G4200D: millidegrees per second.
    pub rate_mdps: [i32; 3],
    /// LIS331DLH: micro-g.
    pub accel_ug: [i32; 3],
    /// HMC5883L: nanotesla.
    pub field_nt: [i32; 3],
}

/// Revision 1-2's BNO055, in its simulator's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Imu12 {
    /// Accelerometer, mg.
    pub accel_mg: [i32; 3],
    /// Magnetometer, nT.
    pub field_nt: [i32; 3],
    /// Gyroscope, 1/16 °/s digits.
    pub rate_digits: [i32; 3],
}

fn each(v: [f64; 3], scale: f64) -> [i32; 3] {
    v.map(|x| {
        (x * scale)
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    })
}

impl ImuReading {
    /// In the 1-1 simulators' units.
    pub fn for_rev_1_1(&self) -> Imu11 {
        Imu11 {
            rate_mdps: each(self.rate_dps, 1000.0),
            accel_ug: each(self.accel_g, 1e6),
            field_nt: each(self.field_nt, 1.0),
        }
    }

    /// In the BNO055 simulator's units.
    pub fn for_rev_1_2(&self) -> Imu12 {
        Imu12 {
            accel_mg: each(self.accel_g, 1000.0),
            field_nt: each(self.field_nt, 1.0),
            rate_digits: each(self.rate_dps, 16.0),
        }
    }
}

/// The noise-free reading for the motion's last step.
pub fn ideal(motion: &Motion, lab: &LabField) -> ImuReading {
    let heading = motion.pose.heading;
    let w = motion.angular_rad_s;
    let horizontal = lab.total_nt * lab.inclination_deg.to_radians().cos();
    let down = lab.total_nt * lab.inclination_deg.to_radians().sin();
    // North as seen from the robot: its world direction minus the robot's heading.
    let north = lab.north_deg.to_radians() - heading;
    ImuReading {
        rate_dps: [0.0, 0.0, w.to_degrees()],
        accel_g: [
            motion.forward_accel_m_s2 / G,
            // Centripetal: towards the centre of the turn, to the left for a counter-clockwise turn.
            motion.forward_m_s * w / G,
            1.0,
        ],
        field_nt: [horizontal * north.cos(), horizontal * north.sin(), -down],
    }
}

/// The reading with seeded noise.
pub fn read(motion: &Motion, lab: &LabField, noise: &mut Noise) -> ImuReading {
    let mut r = ideal(motion, lab);
    for v in &mut r.rate_dps {
        *v += GYRO_NOISE_DPS * noise.normal();
    }
    for v in &mut r.accel_g {
        *v += ACCEL_NOISE_G * noise.normal();
    }
    for v in &mut r.field_nt {
        *v += FIELD_NOISE_NT * noise.normal();
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::file::{Arena, LabField};
    use crate::motion::Wheels;

    #[test]
    fn a_turn_on_the_spot_and_the_field_facing_north() {
        // Heading +y (= magnetic north by default), turning at π/2 rad/s on the spot.
        let a = Arena::parse(r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 90 } }"#).unwrap();
        let mut m = crate::motion::Motion::new(a.start, Wheels::amiro());
        let q = std::f64::consts::PI * 0.077 / 8.0; // wheels for an eighth of a turn
        m.advance(&a, 0.25, -q, q);
        let r = ideal(&m, &LabField::BIELEFELD);
        assert!((r.rate_dps[2] - 180.0).abs() < 1e-9, "{:?}", r.rate_dps);
        assert_eq!(r.accel_g[2], 1.0);
        // Now heading 135°: north (90°) lies 45° to the right: x = H cos(−45°), y = H sin(−45°).
        let h = 49_000.0 * 67f64.to_radians().cos();
        assert!(
            (h - 19_146.0).abs() < 1.0,
            "the BNO055 simulator's horizontal component"
        );
        assert!((r.field_nt[0] - h * 45f64.to_radians().cos()).abs() < 1e-6);
        assert!((r.field_nt[1] + h * 45f64.to_radians().sin()).abs() < 1e-6);
        assert!((r.field_nt[2] + 45_105.0).abs() < 1.0, "{:?}", r.field_nt);
        let r11 = r.for_rev_1_1();
        assert_eq!(r11.rate_mdps[2], 180_000);
        assert_eq!(r11.accel_ug[2], 1_000_000);
        let r12 = r.for_rev_1_2();
        assert_eq!(r12.rate_digits[2], 2880);
        assert_eq!(r12.accel_mg[2], 1000);
    }

    #[test]
    fn driving_an_arc_pulls_sideways() {
        // 0.2 m/s on an arc turning at 1 rad/s: 0.2 m/s² to the left, 0.0204 g.
        let a = Arena::parse(r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 0 } }"#).unwrap();
        let mut m = crate::motion::Motion::new(a.start, Wheels::amiro());
        let dt = 0.01;
        for _ in 0..2 {
            m.advance(&a, dt, (0.2 - 0.0385) * dt, (0.2 + 0.0385) * dt);
        }
        let r = ideal(&m, &LabField::BIELEFELD);
        assert!((r.accel_g[1] - 0.2 / G).abs() < 1e-4, "{:?}", r.accel_g);
        assert!(r.accel_g[0].abs() < 1e-3, "steady speed: {:?}", r.accel_g);
    }
}
