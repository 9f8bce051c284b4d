//! The robot's motion: its pose integrated from the two wheels' travel with the DiWheelDrive's
//! odometry geometry (`amiro_sensors::motion::DriveGeometry::AMIRO`: 1408 ticks per revolution,
//! 55.71 mm wheels, 77 mm axle), and its round body (100 mm across, the thesis's figure) stopped
//! by walls and obstacles.
//!
//! Integration is the midpoint rule the firmware's odometry uses — travel `d = (dl + dr) / 2`
//! along the heading halfway through the turn `dθ = (dr − dl) / axle` — in sub-steps of at most
//! 1 mm and 1°, so a collision is found within a millimetre. A sub-step that would bring the body
//! closer than its radius to a wall is not taken (the wheels slip; the heading still turns, a
//! round body can always turn on the spot), and a step that moves away from a touching wall is
//! taken, so a robot can back off. A contact is one episode: counted when the body first
//! touches, over when it is 1 mm clear again.

use amiro_sensors::motion::DriveGeometry;

use crate::file::{Arena, Pose, BODY_RADIUS_M};
use crate::geometry::Vec2;

/// Longest sub-step of travel, m.
const SUB_STEP_M: f64 = 0.001;
/// Largest sub-step of turn, rad.
const SUB_STEP_RAD: f64 = std::f64::consts::PI / 180.0;
/// Clearance past the body's radius that ends a contact, m.
const CONTACT_RELEASE_M: f64 = 0.001;

/// The drive's geometry in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wheels {
    /// Wheel travel per encoder tick, m.
    pub metres_per_tick: f64,
    /// Distance between the wheels' contact points, m.
    pub axle_m: f64,
}

impl Wheels {
    /// The firmware's geometry.
    pub fn from_geometry(g: &DriveGeometry) -> Wheels {
        Wheels {
            metres_per_tick: std::f64::consts::PI * f64::from(g.wheel_diameter_um)
                / 1e6
                / f64::from(g.ticks_per_revolution.max(1)),
            axle_m: f64::from(g.axle_width_um) / 1e6,
        }
    }

    /// The AMiRo's: 124.3 µm per tick, 77 mm axle.
    pub fn amiro() -> Wheels {
        Wheels::from_geometry(&DriveGeometry::AMIRO)
    }
}

/// The body's motion state.
#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    /// Where the robot is.
    pub pose: Pose,
    /// Its geometry.
    pub wheels: Wheels,
    /// Distance the body moved (not the wheels: a blocked robot travels nothing), m.
    pub travelled_m: f64,
    /// Contact episodes with walls and obstacles.
    pub contacts: u32,
    /// Whether the body touches something now.
    pub in_contact: bool,
    /// Forward speed over the last step, m/s.
    pub forward_m_s: f64,
    /// Turn rate over the last step, rad/s (counter-clockwise positive).
    pub angular_rad_s: f64,
    /// Forward acceleration over the last step, m/s².
    pub forward_accel_m_s2: f64,
}

impl Motion {
    /// At the arena's start, standing still.
    pub fn new(start: Pose, wheels: Wheels) -> Motion {
        Motion {
            pose: start,
            wheels,
            travelled_m: 0.0,
            contacts: 0,
            in_contact: false,
            forward_m_s: 0.0,
            angular_rad_s: 0.0,
            forward_accel_m_s2: 0.0,
        }
    }

    /// Something moved into the body (a moving obstacle): a contact if it touches now.
    pub fn touch_check(&mut self, arena: &Arena) {
        let c = clearance(arena, self.pose.position);
        if c < BODY_RADIUS_M && !self.in_contact {
            self.contacts += 1;
            self.in_contact = true;
        } else if c > BODY_RADIUS_M + CONTACT_RELEASE_M {
            self.in_contact = false;
        }
    }

    /// The wheels turned by `left_ticks` and `right_ticks` encoder ticks in `dt_s` seconds.
    pub fn advance_ticks(&mut self, arena: &Arena, dt_s: f64, left_ticks: i64, right_ticks: i64) {
        let k = self.wheels.metres_per_tick;
        self.advance(arena, dt_s, left_ticks as f64 * k, right_ticks as f64 * k);
    }

    /// The wheels travelled `left_m` and `right_m` in `dt_s` seconds.
    pub fn advance(&mut self, arena: &Arena, dt_s: f64, left_m: f64, right_m: f64) {
        let d = (left_m + right_m) / 2.0;
        let turn = if self.wheels.axle_m > 0.0 {
            (right_m - left_m) / self.wheels.axle_m
        } else {
            0.0
        };
        let steps = ((d.abs() / SUB_STEP_M).ceil())
            .max((turn.abs() / SUB_STEP_RAD).ceil())
            .clamp(1.0, 1e6) as u32;
        let (step_d, step_turn) = (d / f64::from(steps), turn / f64::from(steps));
        let mut moved = 0.0;
        for _ in 0..steps {
            moved += self.sub_step(arena, step_d, step_turn);
        }
        self.travelled_m += moved.abs();
        let forward = if dt_s > 0.0 { moved / dt_s } else { 0.0 };
        if dt_s > 0.0 {
            self.forward_accel_m_s2 = (forward - self.forward_m_s) / dt_s;
            self.angular_rad_s = turn / dt_s;
        }
        self.forward_m_s = forward;
    }

    /// One sub-step; the signed distance actually moved.
    fn sub_step(&mut self, arena: &Arena, d: f64, turn: f64) -> f64 {
        let mid = self.pose.heading + turn / 2.0;
        let here = self.pose.position;
        let there = here.plus(Vec2::from_angle(mid).scale(d));
        let clearance_here = clearance(arena, here);
        let clearance_there = clearance(arena, there);
        self.pose.heading = wrap(self.pose.heading + turn);
        let blocked = clearance_there < BODY_RADIUS_M && clearance_there < clearance_here;
        if blocked {
            if !self.in_contact {
                self.contacts += 1;
                self.in_contact = true;
            }
            return 0.0;
        }
        self.pose.position = there;
        if clearance_there > BODY_RADIUS_M + CONTACT_RELEASE_M {
            self.in_contact = false;
        }
        d
    }
}

/// The distance from `p` to the nearest wall or obstacle edge (infinite in an empty world).
pub fn clearance(arena: &Arena, p: Vec2) -> f64 {
    let walls = arena.segments.iter().map(|s| s.distance_to(p));
    let circles = arena.circles.iter().map(|c| c.distance_to(p));
    walls.chain(circles).fold(f64::INFINITY, f64::min)
}

/// An angle in (−π, π].
pub fn wrap(angle: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let a = angle.rem_euclid(tau);
    if a > std::f64::consts::PI {
        a - tau
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arena(walls: &str, x: f64, y: f64, heading: f64) -> Arena {
        Arena::parse(&format!(
            r#"{{ "robot": {{ "x": {x}, "y": {y}, "heading_deg": {heading} }}, "walls": {walls} }}"#
        ))
        .unwrap()
    }

    #[test]
    fn the_amiro_geometry() {
        let w = Wheels::amiro();
        // π × 55.71 mm / 1408 = 124.30 µm per tick.
        assert!(
            (w.metres_per_tick - 124.302_6e-6).abs() < 1e-9,
            "{}",
            w.metres_per_tick
        );
        assert!((w.axle_m - 0.077).abs() < 1e-12);
    }

    #[test]
    fn straight_ahead_one_wheel_turn() {
        let a = arena("[]", 0.0, 0.0, 30.0);
        let mut m = Motion::new(a.start, Wheels::amiro());
        // One revolution of both wheels, 1408 ticks: π × 55.71 mm = 175.02 mm along 30°.
        m.advance_ticks(&a, 1.0, 1408, 1408);
        let d = std::f64::consts::PI * 0.05571;
        assert!((m.pose.position.x - d * 30f64.to_radians().cos()).abs() < 1e-9);
        assert!((m.pose.position.y - d * 0.5).abs() < 1e-9);
        assert!((m.pose.heading - 30f64.to_radians()).abs() < 1e-12);
        assert!((m.travelled_m - d).abs() < 1e-9);
        assert!((m.forward_m_s - d).abs() < 1e-9);
    }

    #[test]
    fn turning_on_the_spot_and_on_an_arc() {
        let a = arena("[]", 0.0, 0.0, 0.0);
        let mut m = Motion::new(a.start, Wheels::amiro());
        // Wheels ±π × 77 mm / 4 turn the robot a quarter turn on the spot, counter-clockwise.
        let q = std::f64::consts::PI * 0.077 / 4.0;
        m.advance(&a, 0.5, -q, q);
        assert!((m.pose.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(m.pose.position.length() < 1e-12);
        assert!((m.angular_rad_s - std::f64::consts::PI).abs() < 1e-9);
        // An arc of radius 0.2 m through a quarter turn: the left wheel on 0.1615 m, the right on
        // 0.2385 m; the robot ends at (0.2, 0.2) from (0, 0), heading +y, within the sub-steps' chord error.
        let mut m = Motion::new(a.start, Wheels::amiro());
        let quarter = std::f64::consts::FRAC_PI_2;
        m.advance(&a, 1.0, quarter * (0.2 - 0.0385), quarter * (0.2 + 0.0385));
        assert!((m.pose.position.x - 0.2).abs() < 1e-6, "{:?}", m.pose);
        assert!((m.pose.position.y - 0.2).abs() < 1e-6, "{:?}", m.pose);
        assert!((m.travelled_m - quarter * 0.2).abs() < 1e-6);
    }

    #[test]
    fn a_wall_stops_the_body_and_counts_one_contact() {
        // A wall at x = 0.5; the robot at x = 0 drives 1 m towards it: it stops with its centre
        // one body radius (within a sub-step) before the wall.
        let a = arena("[[[0.5, -1], [0.5, 1]]]", 0.0, 0.0, 0.0);
        let mut m = Motion::new(a.start, Wheels::amiro());
        for _ in 0..10 {
            m.advance(&a, 0.1, 0.1, 0.1);
        }
        let x = m.pose.position.x;
        assert!(x <= 0.45 + 1e-12 && x > 0.449, "{x}");
        assert_eq!(m.contacts, 1, "one episode, however long it is pushed");
        assert!(m.in_contact);
        assert!((m.travelled_m - x).abs() < 1e-9);
        assert_eq!(m.forward_m_s, 0.0);
        // Backing off is allowed, and ends the contact; driving in again is a second one.
        m.advance(&a, 0.1, -0.05, -0.05);
        assert!(!m.in_contact);
        assert!((m.pose.position.x - (x - 0.05)).abs() < 1e-9);
        m.advance(&a, 0.1, 0.2, 0.2);
        assert_eq!(m.contacts, 2);
    }

    #[test]
    fn angles_wrap_into_a_half_open_turn() {
        assert!((wrap(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap(-0.25) + 0.25).abs() < 1e-12);
    }
}
