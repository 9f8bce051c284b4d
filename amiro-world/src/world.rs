//! The world as the host drives it: an [`Arena`] with the robot's [`Motion`] in it, the sensor
//! models and their seeded noise. The host's exchange loop needs only three calls: advance the
//! body by the wheels' travel ([`World::advance_ticks`]), take the sensors' readings
//! ([`World::readings`]) to hand to the boards' simulators, and the [`Summary`] at the end.

use std::fmt;

use crate::file::{Arena, Pose};
use crate::floor::{self, FloorReading};
use crate::imu::{self, ImuReading};
use crate::motion::{Motion, Wheels};
use crate::noise::Noise;
use crate::ring::{self, Response, RingReading};

/// Noise stream numbers: one per sensor group, so the groups' noise does not depend on how
/// often the others are read.
const RING_STREAM: u64 = 1;
const FLOOR_STREAM: u64 = 2;
const IMU_STREAM: u64 = 3;

/// Everything the sensors see at one moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Readings {
    /// The proximity ring (PowerManagement).
    pub ring: RingReading,
    /// The floor sensors (DiWheelDrive).
    pub floor: FloorReading,
    /// The IMU (DiWheelDrive, either revision).
    pub imu: ImuReading,
}

/// A world with the robot in it.
#[derive(Debug, Clone)]
pub struct World {
    arena: Arena,
    /// Virtual time since the start, s (the moving obstacles' clock).
    time_s: f64,
    motion: Motion,
    response: Response,
    ring_noise: Noise,
    floor_noise: Noise,
    imu_noise: Noise,
}

impl World {
    /// The robot at the arena's start, with the AMiRo's geometry and ring response, noise
    /// seeded from the arena's seed.
    pub fn new(arena: Arena) -> World {
        World::with_seed(arena.seed, arena)
    }

    /// As [`World::new`], with another seed (a command line's `--seed`).
    pub fn with_seed(seed: u64, arena: Arena) -> World {
        World {
            motion: Motion::new(arena.start, Wheels::amiro()),
            arena,
            time_s: 0.0,
            response: Response::AMIRO,
            ring_noise: Noise::stream(seed, RING_STREAM),
            floor_noise: Noise::stream(seed, FLOOR_STREAM),
            imu_noise: Noise::stream(seed, IMU_STREAM),
        }
    }

    /// The arena.
    pub fn arena(&self) -> &Arena {
        &self.arena
    }

    /// The body's motion state.
    pub fn motion(&self) -> &Motion {
        &self.motion
    }

    /// Where the robot is.
    pub fn pose(&self) -> Pose {
        self.motion.pose
    }

    /// The wheels turned `left` and `right` encoder ticks in `dt_s` seconds (the DiWheelDrive
    /// plant's counts since the last call).
    pub fn advance_ticks(&mut self, dt_s: f64, left: i64, right: i64) {
        self.move_obstacles(dt_s);
        self.motion.advance_ticks(&self.arena, dt_s, left, right);
    }

    /// The wheels travelled `left_m` and `right_m` in `dt_s` seconds.
    pub fn advance(&mut self, dt_s: f64, left_m: f64, right_m: f64) {
        self.move_obstacles(dt_s);
        self.motion.advance(&self.arena, dt_s, left_m, right_m);
    }

    /// The moving obstacles go on by `dt_s` (before the body moves: an obstacle that runs into
    /// the robot is a contact too).
    fn move_obstacles(&mut self, dt_s: f64) {
        if self.arena.movers.is_empty() {
            return;
        }
        self.time_s += dt_s.max(0.0);
        self.arena.move_obstacles(self.time_s);
        self.motion.touch_check(&self.arena);
    }

    /// The sensors' readings now, each with its next noise sample.
    pub fn readings(&mut self) -> Readings {
        let p = self.motion.pose;
        Readings {
            ring: ring::read(
                &self.arena,
                p.position,
                p.heading,
                &self.response,
                &mut self.ring_noise,
            ),
            floor: floor::read(&self.arena, p.position, p.heading, &mut self.floor_noise),
            imu: imu::read(&self.motion, &self.arena.lab, &mut self.imu_noise),
        }
    }

    /// The ring alone (a board that asks for nothing else).
    pub fn ring(&mut self) -> RingReading {
        let p = self.motion.pose;
        ring::read(
            &self.arena,
            p.position,
            p.heading,
            &self.response,
            &mut self.ring_noise,
        )
    }

    /// The floor sensors alone.
    pub fn floor(&mut self) -> FloorReading {
        let p = self.motion.pose;
        floor::read(&self.arena, p.position, p.heading, &mut self.floor_noise)
    }

    /// The IMU alone.
    pub fn imu(&mut self) -> ImuReading {
        imu::read(&self.motion, &self.arena.lab, &mut self.imu_noise)
    }

    /// The run's outcome so far.
    pub fn summary(&self) -> Summary {
        Summary {
            travelled_m: self.motion.travelled_m,
            contacts: self.motion.contacts,
            pose: self.motion.pose,
        }
    }
}

/// The run's outcome: its [`fmt::Display`] is the end line
/// `world: travelled X m, contacts N, pose X Y HEADING` (metres, metres, degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Distance the body moved, m.
    pub travelled_m: f64,
    /// Contact episodes.
    pub contacts: u32,
    /// Where it ended.
    pub pose: Pose,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "world: travelled {:.3} m, contacts {}, pose {:.3} {:.3} {:.1}",
            self.travelled_m,
            self.contacts,
            self.pose.position.x,
            self.pose.position.y,
            crate::motion::wrap(self.pose.heading).to_degrees()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ARENA: &str = r#"{ "seed": 11, "robot": { "x": 0.3, "y": 0.3, "heading_deg": 0 },
        "walls": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]],
        "obstacles": [ { "circle": [0.6, 0.6], "radius": 0.05 } ],
        "floor": [ { "line": [[0.1, 0.3], [0.9, 0.3]], "width": 0.03, "grey": 0 } ] }"#;

    /// A fixed wheel programme: straight, an arc, a spin, into the wall.
    fn run(world: &mut World) -> Vec<String> {
        let mut out = Vec::new();
        for step in 0..400u32 {
            let (l, r) = match step / 100 {
                0 => (0.002, 0.002),
                1 => (0.0015, 0.0025),
                2 => (-0.001, 0.001),
                _ => (0.003, 0.003),
            };
            world.advance(0.01, l, r);
            let readings = world.readings();
            out.push(format!("{readings:?} {:?}", world.pose()));
        }
        out.push(world.summary().to_string());
        out
    }

    #[test]
    fn same_world_seed_and_wheels_give_identical_outputs() {
        let arena = Arena::parse(ARENA).unwrap();
        let a = run(&mut World::new(arena.clone()));
        let b = run(&mut World::new(arena.clone()));
        assert_eq!(a, b);
        // Another seed changes the noise, not the motion.
        let c = run(&mut World::with_seed(12, arena));
        assert_ne!(a, c);
        assert_eq!(a.last(), c.last());
    }

    #[test]
    fn an_obstacle_that_runs_into_the_robot_is_a_contact() {
        // A post crossing the robot's place from left to right at 0.2 m/s; the robot stands still.
        let mut w = World::new(
            Arena::parse(
                r#"{ "robot": { "x": 1, "y": 1, "heading_deg": 90 },
                     "obstacles": [ { "circle": [0.5, 1.0], "radius": 0.05, "path": [[1.5, 1.0]], "speed": 0.2 } ] }"#,
            )
            .unwrap(),
        );
        let mut seen = false;
        for _ in 0..300 {
            w.advance(0.01, 0.0, 0.0);
            seen |= w.ring().hits.iter().any(Option::is_some);
        }
        assert!(seen, "the ring saw it coming");
        assert_eq!(w.summary().contacts, 1);
        assert_eq!(w.summary().travelled_m, 0.0);
    }

    #[test]
    fn the_end_line() {
        let mut w = World::new(Arena::parse(ARENA).unwrap());
        w.advance(1.0, 0.1, 0.1);
        assert_eq!(
            w.summary().to_string(),
            "world: travelled 0.100 m, contacts 0, pose 0.400 0.300 0.0"
        );
        // On the line: the front pair reads black, the wheel pair white.
        let f = w.floor();
        assert!(
            f.counts[0] < 10_000 && f.counts[3] < 10_000,
            "{:?}",
            f.counts
        );
        assert!(
            f.counts[1] > 25_000 && f.counts[2] > 25_000,
            "{:?}",
            f.counts
        );
    }
}
