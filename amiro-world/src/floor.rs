//! The four floor sensors: VCNL4020s under the DiWheelDrive looking at the floor's grey level.
//!
//! **Response**, measured on an AMiRo over printed grey levels g (0 black … 255 white):
//! `counts ≈ 11010.8 · atan(0.06103 · g − 7.944) + 21783.9`, standard deviation
//! `≈ 1108.8 · tanh(0.02237 · g − 2.085) + 1503.2` — about 5.9 k counts on black and 37.6 k on
//! white (issue 35 gives the fit). Each sensor sees a spot 8 mm across: the grey it reads is the
//! mean of its centre and four points 4 mm around it, so crossing an edge is a ramp, as with the
//! real lens, not a step.
//!
//! **Where they are.** The order is the protocol's (`amiro_sensors::drivers::floor::FloorSensor`):
//! front-right, right-wheel, left-wheel, front-left. The sources do not give their positions
//! (amiro-boards.md lists them as unknown), so [`POSITIONS_M`] is a stated assumption: the front
//! pair 40 mm ahead of the axle, 12 mm either side of the centre line (a 24 mm gap for a line
//! about that wide between them), the wheel pair on the axle, 28 mm out, just inside the wheels.

use crate::file::Arena;
use crate::geometry::Vec2;
use crate::noise::Noise;

/// Number of floor sensors.
pub const SENSORS: usize = 4;
/// Each sensor's position in the robot frame (x forward, y left), m, in protocol order.
pub const POSITIONS_M: [(f64, f64); SENSORS] = [
    (0.040, -0.012),
    (0.000, -0.028),
    (0.000, 0.028),
    (0.040, 0.012),
];
/// Radius of the spot a sensor sees, m.
pub const SPOT_RADIUS_M: f64 = 0.004;

/// Mean counts for grey level `g`.
pub fn mean_counts(g: f64) -> f64 {
    11010.8 * (0.06103 * g - 7.944).atan() + 21783.9
}

/// Standard deviation of the counts at grey level `g`.
pub fn counts_sd(g: f64) -> f64 {
    1108.8 * (0.02237 * g - 2.085).tanh() + 1503.2
}

/// The grey a sensor at `p` sees: the mean over its spot.
pub fn spot_grey(arena: &Arena, p: Vec2) -> f64 {
    let r = SPOT_RADIUS_M;
    let points = [
        p,
        p.plus(Vec2::new(r, 0.0)),
        p.plus(Vec2::new(-r, 0.0)),
        p.plus(Vec2::new(0.0, r)),
        p.plus(Vec2::new(0.0, -r)),
    ];
    points
        .iter()
        .map(|&q| f64::from(arena.grey_at(q)))
        .sum::<f64>()
        / points.len() as f64
}

/// What the floor sensors see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorReading {
    /// The grey under each sensor's spot.
    pub grey: [f64; SENSORS],
    /// The counts, protocol order.
    pub counts: [u16; SENSORS],
}

/// All four sensors from a pose, with noise from `noise`.
pub fn read(arena: &Arena, position: Vec2, heading: f64, noise: &mut Noise) -> FloorReading {
    let mut grey = [0.0; SENSORS];
    let mut counts = [0u16; SENSORS];
    for ((g, c), &(x, y)) in grey.iter_mut().zip(counts.iter_mut()).zip(&POSITIONS_M) {
        *g = spot_grey(arena, Vec2::new(x, y).to_world(position, heading));
        let value = mean_counts(*g) + counts_sd(*g) * noise.normal();
        *c = value.round().clamp(0.0, 65535.0) as u16;
    }
    FloorReading { grey, counts }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_measured_curve_at_black_and_white() {
        // atan(−7.944) = −1.44560: 21783.9 − 15917.3 = 5866.6 counts on black.
        assert!(
            (mean_counts(0.0) - 5866.6).abs() < 0.5,
            "{}",
            mean_counts(0.0)
        );
        // atan(7.6187) = 1.44030: 21783.9 + 15858.9 = 37642.8 on white, inside 32–42 k.
        let white = mean_counts(255.0);
        assert!((white - 37642.8).abs() < 0.5, "{white}");
        assert!((32_000.0..42_000.0).contains(&white));
        // Spread: tanh(−2.085) = −0.96962: 428 counts on black; 2610 on white.
        assert!((counts_sd(0.0) - 428.1).abs() < 0.5, "{}", counts_sd(0.0));
        assert!(
            (counts_sd(255.0) - 2610.5).abs() < 0.5,
            "{}",
            counts_sd(255.0)
        );
        // Monotone over the whole range.
        assert!((1..=255).all(|g| mean_counts(f64::from(g)) > mean_counts(f64::from(g - 1))));
    }

    #[test]
    fn sensors_over_a_black_stripe() {
        // A black stripe along y = 0, 30 mm wide, under a robot heading +x: the front pair
        // (y = ±12 mm) is on it — one point of each spot (at ±16 mm) just past the edge, so grey
        // 255 / 5 = 51 —, the wheel pair (±28 mm) on white.
        let a = Arena::parse(
            r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 0 },
                 "floor": [ { "line": [[-1, 0], [1, 0]], "width": 0.03, "grey": 0 } ] }"#,
        )
        .unwrap();
        let mut n = Noise::new(5);
        let r = read(&a, Vec2::default(), 0.0, &mut n);
        assert_eq!(r.grey, [51.0, 255.0, 255.0, 51.0]);
        for i in [0, 3] {
            // mean_counts(51) = 9 230, sd 1 007.
            assert!((5_000..14_000).contains(&r.counts[i]), "{:?}", r.counts);
        }
        for i in [1, 2] {
            assert!((28_000..48_000).contains(&r.counts[i]), "{:?}", r.counts);
        }
        // Turned 90°, the stripe runs across the robot: the wheel pair (now at x = ±28 mm, y = 0)
        // on it, the front pair (now at y = 40 mm) on white.
        let r = read(&a, Vec2::default(), std::f64::consts::FRAC_PI_2, &mut n);
        assert_eq!(r.grey, [255.0, 0.0, 0.0, 255.0]);
        // A spot centred on the edge (y = 15 mm): four of its five points on black, a ramp.
        let g = spot_grey(&a, Vec2::new(0.0, 0.015));
        assert!((g - 51.0).abs() < 1e-9, "{g}");
    }
}
