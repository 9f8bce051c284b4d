//! The proximity ring: eight VCNL4020s around the PowerManagement, each reading the nearest wall
//! or obstacle in its cone through the part's response.
//!
//! **Where they look.** Sensor `i` carries the 1.x index the protocol's ring frames use
//! (`amiro_sensors::drivers::ring`; amiro-boards.md §5): 0 rear-left (SSW), 1 left-rear (WSW),
//! 2 left-front (WNW), 3 front-left (NNW), 4 front-right (NNE), 5 right-front (ENE), 6 right-rear
//! (ESE), 7 rear-right (SSE). The sources give only these compass names, so the bearings are their
//! centres, 45° apart at ±22.5°, ±67.5°, ±112.5°, ±157.5° from forward ([`BEARINGS_DEG`],
//! counter-clockwise positive), and the sensors sit at the body's edge, [`RING_RADIUS_M`] from the
//! centre, looking outwards. Each casts [`RAYS`] rays across a cone of ±[`CONE_HALF_ANGLE_DEG`];
//! the nearest hit within [`RANGE_M`] is the sensor's distance `d`, with the reflectance of what
//! it hit.
//!
//! **Response.** The inverse-square model the firmware's driver inverts
//! (`amiro_sensors::drivers::proximity`): `counts = offset + ρ · k / d²`, with `k` = 1 000 000
//! counts·mm² (the driver's default, ≈ 10 000 counts at 10 mm from the datasheet's 200 mA curve
//! on an 18 % grey card, the reference surface ρ = 1), the offset 2000 counts its calibration
//! removes, nothing reflected beyond 200 mm (the thesis's range), `d` not below 2 mm (the driver's
//! `min_mm`), and noise of standard deviation 3 counts + 2 % of the reflected signal. So on the
//! reference surface the firmware's counts → mm conversion gives back the world's distance.

use crate::file::Arena;
use crate::geometry::Vec2;
use crate::noise::Noise;

/// Number of ring sensors.
pub const SENSORS: usize = 8;
/// Each sensor's bearing from forward, degrees, counter-clockwise positive, by protocol index.
pub const BEARINGS_DEG: [f64; SENSORS] = [157.5, 112.5, 67.5, 22.5, -22.5, -67.5, -112.5, -157.5];
/// Distance of the sensors from the robot's centre, m (at the edge of its 100 mm body).
pub const RING_RADIUS_M: f64 = 0.050;
/// Half the opening of a sensor's cone, degrees.
pub const CONE_HALF_ANGLE_DEG: f64 = 20.0;
/// Rays per cone (one on the axis, the rest spread evenly to the cone's edges).
pub const RAYS: usize = 5;
/// Nothing farther than this is seen, m.
pub const RANGE_M: f64 = 0.200;

/// The VCNL4020's response on the ring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Response {
    /// Counts with nothing in front (what the calibration removes).
    pub offset: f64,
    /// Reflected counts × mm² on the reference surface.
    pub k_counts_mm2: f64,
    /// Nearest distance the model holds for, mm.
    pub min_mm: f64,
    /// Noise: a constant part, counts.
    pub noise_counts: f64,
    /// Noise: a part proportional to the reflected signal.
    pub noise_fraction: f64,
}

impl Response {
    /// The firmware driver's default calibration, with the noise above.
    pub const AMIRO: Response = Response {
        offset: 2000.0,
        k_counts_mm2: 1_000_000.0,
        min_mm: 2.0,
        noise_counts: 3.0,
        noise_fraction: 0.02,
    };

    /// Noise-free counts for a surface of reflectance `reflectance` at `distance_m` (`None`:
    /// nothing within range).
    pub fn mean_counts(&self, hit: Option<(f64, f64)>) -> f64 {
        let Some((distance_m, reflectance)) = hit else {
            return self.offset;
        };
        if distance_m > RANGE_M {
            return self.offset;
        }
        let mm = (distance_m * 1000.0).max(self.min_mm);
        self.offset + reflectance * self.k_counts_mm2 / (mm * mm)
    }

    /// Counts with noise, as the part's 16-bit register holds them.
    pub fn counts(&self, hit: Option<(f64, f64)>, noise: &mut Noise) -> u16 {
        let mean = self.mean_counts(hit);
        let sd = self.noise_counts + self.noise_fraction * (mean - self.offset);
        (mean + sd * noise.normal()).round().clamp(0.0, 65535.0) as u16
    }
}

/// What the ring sees from a pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RingReading {
    /// Per sensor: the distance from the sensor to what it sees (m) and its reflectance, or
    /// `None` within range.
    pub hits: [Option<(f64, f64)>; SENSORS],
    /// Per sensor: the VCNL4020's proximity counts.
    pub counts: [u16; SENSORS],
}

/// The nearest hit of sensor `index` from the robot at `position`, `heading` (radians).
pub fn sense(arena: &Arena, position: Vec2, heading: f64, index: usize) -> Option<(f64, f64)> {
    let bearing = BEARINGS_DEG.get(index)?.to_radians();
    let origin = Vec2::from_angle(heading + bearing)
        .scale(RING_RADIUS_M)
        .plus(position);
    let half = CONE_HALF_ANGLE_DEG.to_radians();
    let mut nearest: Option<(f64, f64)> = None;
    for ray in 0..RAYS {
        let spread = if RAYS > 1 {
            -half + 2.0 * half * ray as f64 / (RAYS - 1) as f64
        } else {
            0.0
        };
        let direction = Vec2::from_angle(heading + bearing + spread);
        let walls = arena
            .segments
            .iter()
            .filter_map(|s| s.ray_hit(origin, direction).map(|t| (t, s.reflectance)));
        let circles = arena
            .circles
            .iter()
            .filter_map(|c| c.ray_hit(origin, direction).map(|t| (t, c.reflectance)));
        for (t, reflectance) in walls.chain(circles) {
            if t <= RANGE_M && nearest.is_none_or(|(d, _)| t < d) {
                nearest = Some((t, reflectance));
            }
        }
    }
    nearest
}

/// All eight sensors from a pose, with noise from `noise`.
pub fn read(
    arena: &Arena,
    position: Vec2,
    heading: f64,
    response: &Response,
    noise: &mut Noise,
) -> RingReading {
    let mut hits = [None; SENSORS];
    let mut counts = [0u16; SENSORS];
    for (i, (hit, count)) in hits.iter_mut().zip(counts.iter_mut()).enumerate() {
        *hit = sense(arena, position, heading, i);
        *count = response.counts(*hit, noise);
    }
    RingReading { hits, counts }
}

/// What the firmware reports for sensor `index` from the robot at `position`, `heading`, without
/// noise: the response's mean counts through the driver's default calibration
/// (`ProximityCalibration::DEFAULT::counts_to_mm`), 200 for nothing within range. A scenario that
/// checks the ring's frames against the trajectory compares them with this, within
/// [`tolerance_mm`].
pub fn expected_mm(
    arena: &Arena,
    position: Vec2,
    heading: f64,
    response: &Response,
    index: usize,
) -> u16 {
    let counts = response
        .mean_counts(sense(arena, position, heading, index))
        .round()
        .clamp(0.0, 65535.0) as u16;
    amiro_sensors::drivers::proximity::ProximityCalibration::DEFAULT.counts_to_mm(counts)
}

/// How far a noisy reading may lie from [`expected_mm`]: three standard deviations of the noise
/// carried through the inverse square (`σ_mm ≈ d / 2 · σ_counts / reflected`), plus a millimetre
/// of rounding. On the reference surface 1.6 mm at 20 mm, 8.5 mm at 100 mm, 43 mm at 200 mm.
pub fn tolerance_mm(expected_mm: u16, response: &Response) -> f64 {
    let d = f64::from(expected_mm.max(1));
    let reflected = response.k_counts_mm2 / (d * d);
    let sd_counts = response.noise_counts + response.noise_fraction * reflected;
    3.0 * d / 2.0 * sd_counts / reflected + 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_sensors::drivers::proximity::ProximityCalibration;

    fn arena(walls: &str) -> Arena {
        Arena::parse(&format!(
            r#"{{ "robot": {{ "x": 0, "y": 0, "heading_deg": 0 }}, "walls": {walls} }}"#
        ))
        .unwrap()
    }

    #[test]
    fn a_wall_ahead_is_seen_by_the_two_front_sensors() {
        // A wall across x = 0.15. Sensor 3 (front-left, 22.5°) sits at (0.0462, 0.0191); its
        // nearest ray is the cone's edge nearest the wall's normal, at 22.5° − 20° = 2.5°:
        // (0.15 − 0.0462) / cos 2.5° = 0.10389 m.
        let a = arena("[[[0.15, -1], [0.15, 1]]]");
        let (d, rho) = sense(&a, Vec2::default(), 0.0, 3).unwrap();
        let sensor_x = RING_RADIUS_M * 22.5f64.to_radians().cos();
        let expected = (0.15 - sensor_x) / 2.5f64.to_radians().cos();
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
        assert!((expected - 0.10389).abs() < 1e-4);
        assert_eq!(rho, 1.0);
        // Sensor 4 mirrors it; the side and rear sensors see nothing within 200 mm.
        let (d4, _) = sense(&a, Vec2::default(), 0.0, 4).unwrap();
        assert!((d4 - d).abs() < 1e-12);
        for i in [0, 1, 6, 7] {
            assert_eq!(sense(&a, Vec2::default(), 0.0, i), None, "sensor {i}");
        }
        // Turned by 180°, the rear sensors see it instead.
        assert!(sense(&a, Vec2::default(), std::f64::consts::PI, 0).is_some());
    }

    #[test]
    fn counts_fall_with_distance_and_the_firmware_reads_the_distance_back() {
        let r = Response::AMIRO;
        let calibration = ProximityCalibration::DEFAULT;
        let mut last = f64::INFINITY;
        for mm in [5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 199.0] {
            let counts = r.mean_counts(Some((mm / 1000.0, 1.0)));
            assert!(counts < last, "{mm} mm");
            last = counts;
            // The firmware's conversion inverts the response on the reference surface.
            let back = calibration.counts_to_mm(counts.round() as u16);
            assert!(
                (f64::from(back) - mm).abs() <= 1.0,
                "{mm} mm read as {back}"
            );
        }
        // At 10 mm: 2000 + 10 000; beyond 200 mm, the offset alone.
        assert_eq!(r.mean_counts(Some((0.010, 1.0))), 12_000.0);
        assert_eq!(r.mean_counts(Some((0.201, 1.0))), 2000.0);
        assert_eq!(r.mean_counts(None), 2000.0);
        // A darker surface reflects proportionally less.
        assert_eq!(r.mean_counts(Some((0.010, 0.5))), 7_000.0);
        // Touching: clamped at the model's 2 mm and at the register's 16 bits.
        let mut n = Noise::new(1);
        assert_eq!(r.counts(Some((0.0, 1.0)), &mut n), 65535);
    }

    #[test]
    fn noisy_frames_lie_within_the_tolerance_of_the_trajectorys_distances() {
        // The check a robot scenario makes: along a path through the example arena, every ring
        // reading the firmware would report (noisy counts through its calibration) lies within
        // `tolerance_mm` of the distance worked out from the pose.
        let a = Arena::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../robot/worlds/arena.json"
        )))
        .unwrap();
        let r = Response::AMIRO;
        let calibration = ProximityCalibration::DEFAULT;
        let mut n = Noise::new(9);
        let (mut checked, mut near, mut outside) = (0, 0, 0);
        for step in 0..2000 {
            let t = f64::from(step) / 2000.0;
            let position = Vec2::new(0.15 + 1.7 * t, 0.75 + 0.55 * (t * 13.0).sin());
            let heading = t * 40.0;
            if crate::motion::clearance(&a, position) < crate::file::BODY_RADIUS_M {
                continue;
            }
            for i in 0..SENSORS {
                let expected = expected_mm(&a, position, heading, &r, i);
                let got =
                    calibration.counts_to_mm(r.counts(sense(&a, position, heading, i), &mut n));
                checked += 1;
                near += usize::from(expected < 200);
                if (f64::from(got) - f64::from(expected)).abs() > tolerance_mm(expected, &r) {
                    outside += 1;
                }
            }
        }
        assert!(
            near > 1000,
            "the path passes walls and obstacles: {near} of {checked}"
        );
        // Three standard deviations: about 0.3 % outside.
        assert!(outside * 100 < checked, "{outside} of {checked} outside");
        assert!((tolerance_mm(100, &r) - 8.5).abs() < 1e-9);
        assert!((tolerance_mm(200, &r) - 43.0).abs() < 1e-9);
    }

    #[test]
    fn noise_is_as_large_as_stated() {
        let r = Response::AMIRO;
        let mut n = Noise::new(3);
        let samples: Vec<f64> = (0..5000)
            .map(|_| f64::from(r.counts(Some((0.05, 1.0)), &mut n)))
            .collect();
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        let sd =
            (samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / samples.len() as f64).sqrt();
        // 2000 + 1e6 / 2500 = 2400 counts; sd 3 + 0.02 × 400 = 11 counts.
        assert!((mean - 2400.0).abs() < 1.0, "{mean}");
        assert!((sd - 11.0).abs() < 0.6, "{sd}");
    }
}
