//! The world on the robot link (docs/world.md, "How the readings reach the boards"): the
//! DiWheelDrive's wheel reports move the robot in `amiro_world`'s arena, and the DiWheelDrive
//! (floor, IMU) and the PowerManagement (ring) are answered with the sensors' readings there.
//!
//! **Lock-step and determinism.** Everything is keyed to the coordinator's virtual boundaries:
//! the world advances at each DiWheelDrive report (by the plant's ticks since the last one),
//! the readings are taken again at most once per [`FEED_PERIOD_US`] of virtual time (at the first
//! answer to a sensor board after the period is over), and a board gets them with its next answer
//! if it has not had them yet. The trajectory gets a row every [`ROW_PERIOD_US`], the pose as of
//! the boundary the coordinator is at. Nothing reads a clock, so a run is a function of its
//! world, seed and stimulus.
//!
//! **Lookahead.** A sensor board that sleeps is woken only by what the coordinator sees coming;
//! with a world it is also brought to the last boundary *before* its next deadline
//! (`WorldRun::wake_boundary`), so the readings it samples there are at most one feed period
//! (plus the DiWheelDrive's time since its last report) old, at the cost of one exchange per
//! wake-up.
use std::path::Path;

use amiro_trace::robot_link::QUANTUM_US;
use amiro_trace::world_link::{self, Wheels};
use amiro_world::controller::{self, Controller};
use amiro_world::feed::{self, ImuRevision, WheelFeed};
use amiro_world::output::Trajectory;
use amiro_world::world::{Readings, Summary, World};
use amiro_world::Arena;

/// How often the world's readings are taken again (virtual µs): the floor's 8 ms sample period
/// is the fastest a board reads; at 0.6 m/s the robot moves 0.6 mm in it.
pub const FEED_PERIOD_US: u64 = 1_000;
/// The trajectory's row period without a controller (virtual µs).
pub const ROW_PERIOD_US: u64 = 10_000;

/// The boards that read the world: the DiWheelDrive and the PowerManagement (indices into
/// `NODES`).
const DIWHEELDRIVE: usize = 0;
const POWERMGMT: usize = 1;

/// A world carried on the robot link for one run.
pub struct WorldRun {
    world: World,
    /// Whether the sensor boards read the world (false: a controller without a world, the
    /// boards' own simulators answer and the robot moves in an empty plane).
    feeds: bool,
    wheels: WheelFeed,
    /// The DiWheelDrive's clock zero the wheel feed follows (a restart begins a new feed).
    wheels_offset: u64,
    revision: ImuRevision,
    /// The readings and the boundary they were taken at.
    readings: Option<(u64, Readings)>,
    /// Per board, the boundary of the readings it was sent last.
    sent: [Option<u64>; 2],
    trajectory: Trajectory,
    next_row: u64,
    /// The trajectory's row period: the controller's, or [`ROW_PERIOD_US`].
    row_period: u64,
    /// The operator-side behaviour in lock-step (`--controller`), its period and next tick.
    controller: Option<Control>,
    /// Wall time the world's hooks took (motion, readings, rows; not the controller's wait).
    pub wall: std::time::Duration,
}

struct Control {
    program: Controller,
    period: u64,
    next: u64,
}

impl WorldRun {
    /// The robot at `arena`'s start, the noise from `seed` (the file's if `None`), the
    /// DiWheelDrive's IMU of `revision`.
    pub fn new(arena: Arena, seed: Option<u64>, revision: ImuRevision) -> WorldRun {
        let seed = seed.unwrap_or(arena.seed);
        WorldRun {
            world: World::with_seed(seed, arena),
            feeds: true,
            wheels: WheelFeed::new(),
            wheels_offset: 0,
            revision,
            readings: None,
            sent: [None; 2],
            trajectory: Trajectory::default(),
            next_row: 0,
            row_period: ROW_PERIOD_US,
            controller: None,
            wall: std::time::Duration::ZERO,
        }
    }

    /// No world: the sensor boards keep reading their own simulators, as without `--world`,
    /// and the robot moves in an empty plane from the origin (the trajectory still follows the
    /// wheels). What a controller (`--controller`) needs on its own.
    pub fn without_world() -> WorldRun {
        let arena = Arena {
            seed: 0,
            start: amiro_world::Pose {
                position: amiro_world::geometry::Vec2::new(0.0, 0.0),
                heading: 0.0,
            },
            segments: Vec::new(),
            circles: Vec::new(),
            movers: Vec::new(),
            floor: Vec::new(),
            lab: amiro_world::file::LabField::BIELEFELD,
            wall_segments: 0,
        };
        WorldRun {
            feeds: false,
            ..WorldRun::new(arena, None, ImuRevision::Rev1_1)
        }
    }

    /// Whether the sensor boards read the world (there is one).
    pub fn feeds(&self) -> bool {
        self.feeds
    }

    /// Closes the loop with `program` (the controller protocol, `amiro_world::controller`): every
    /// frame on the bus to its stdin, a tick every `period_us` (a multiple of the quantum, the
    /// first at `period_us`), its frames queued on the bus at the tick; the trajectory gets a
    /// row at every tick.
    pub fn with_controller(&mut self, program: &str, period_us: u64) -> anyhow::Result<()> {
        anyhow::ensure!(
            period_us >= QUANTUM_US && period_us.is_multiple_of(QUANTUM_US),
            "--controller-period: {period_us} µs is not a multiple of the {QUANTUM_US} µs quantum"
        );
        let program = Controller::spawn(program, controller::DEFAULT_TIMEOUT)?;
        self.controller = Some(Control {
            program,
            period: period_us,
            next: period_us,
        });
        self.row_period = period_us;
        Ok(())
    }

    /// The next controller tick (a boundary the coordinator must stop at), if there is a
    /// controller.
    pub(crate) fn next_tick(&self) -> Option<u64> {
        self.controller.as_ref().map(|c| c.next)
    }

    /// The controller's ticks due by boundary `t`: the frames it sends, to queue at `t`.
    pub(crate) fn ticks(&mut self, t: u64) -> anyhow::Result<Vec<amiro_bus_sim::Frame>> {
        let mut out = Vec::new();
        let Some(c) = self.controller.as_mut() else {
            return Ok(out);
        };
        while c.next <= t {
            for f in c.program.tick(c.next)? {
                out.extend(amiro_bus_sim::Frame::new(f.id, f.payload()));
            }
            c.next += c.period;
        }
        Ok(out)
    }

    /// A frame completed on the bus at `end`: to the controller's stdin.
    pub(crate) fn frame(&mut self, end: u64, frame: &amiro_bus_sim::Frame) -> anyhow::Result<()> {
        if let Some(c) = self.controller.as_mut() {
            if let Some(f) = controller::Frame::new(frame.id, frame.payload()) {
                c.program.frame(end, &f)?;
            }
        }
        Ok(())
    }

    /// Ends the controller (closes its stdin, stops it if it does not finish).
    pub fn finish(&mut self) {
        if let Some(c) = self.controller.take() {
            c.program.finish();
        }
    }

    /// The world file at `path` (a `WorldError` naming the field if it is malformed).
    pub fn load(path: &Path, seed: Option<u64>, revision: ImuRevision) -> anyhow::Result<WorldRun> {
        let arena = Arena::load(path).map_err(|e| {
            let text = e.to_string();
            let shown = path.display().to_string();
            // A file that cannot be read names itself; a field error gets the file in front.
            if text.contains(&shown) {
                anyhow::anyhow!("{text}")
            } else {
                anyhow::anyhow!("{shown}: {text}")
            }
        })?;
        Ok(WorldRun::new(arena, seed, revision))
    }

    /// The coordinator's hook at boundary `t`, after the boards' reports: the DiWheelDrive's
    /// latest wheel ticks move the robot (they are cumulative, so the last report of a step is
    /// all it needs), and the trajectory gets its rows up to `t`.
    pub(crate) fn step(&mut self, t: u64, boards: &mut [crate::board::Board]) {
        let started = std::time::Instant::now();
        if let Some(b) = boards.get_mut(DIWHEELDRIVE) {
            if let Some(w) = b.wheels.take() {
                self.wheels(b.offset, w);
            }
        }
        self.at(t);
        self.wall += started.elapsed();
    }

    /// The DiWheelDrive (clock zero at global `offset`) reported `wheels`.
    pub(crate) fn wheels(&mut self, offset: u64, wheels: Wheels) {
        if offset != self.wheels_offset {
            // The board restarted: its plant and clock begin again from zero.
            self.wheels = WheelFeed::new();
            self.wheels_offset = offset;
        }
        self.wheels.report(&mut self.world, wheels);
    }

    /// The coordinator is at boundary `t`: the trajectory's rows up to it.
    pub(crate) fn at(&mut self, t: u64) {
        while self.next_row <= t {
            self.trajectory.record(self.next_row, self.world.pose());
            self.next_row += self.row_period;
        }
    }

    /// What board `k` (clock zero at global `offset`) gets with its answer at boundary `t`: the
    /// world's readings for it if it has not had the latest.
    pub(crate) fn readings_for(
        &mut self,
        k: usize,
        t: u64,
        offset: u64,
    ) -> Option<world_link::Readings> {
        if !self.feeds || (k != DIWHEELDRIVE && k != POWERMGMT) {
            return None;
        }
        let stale = self
            .readings
            .as_ref()
            .is_none_or(|(at, _)| t >= at + FEED_PERIOD_US);
        if stale {
            let started = std::time::Instant::now();
            self.readings = Some((t, self.world.readings()));
            self.wall += started.elapsed();
        }
        let (at, readings) = self.readings.as_ref()?;
        if self.sent[k] == Some(*at) {
            return None;
        }
        self.sent[k] = Some(*at);
        let local = t.saturating_sub(offset);
        Some(if k == DIWHEELDRIVE {
            feed::for_diwheeldrive(readings, local, self.revision)
        } else {
            feed::for_powermanagement(readings, local)
        })
    }

    /// The boundary a sleeping board `k` that wakes at `wakes_at` is next brought to: for a
    /// sensor board the last one before its deadline (to take the latest readings first), for
    /// the others the one its deadline falls in; never before `t + QUANTUM_US`.
    pub(crate) fn wake_boundary(k: usize, t: u64, wakes_at: u64) -> u64 {
        let boundary = if k == DIWHEELDRIVE || k == POWERMGMT {
            wakes_at.saturating_sub(1) / QUANTUM_US * QUANTUM_US
        } else {
            wakes_at.div_ceil(QUANTUM_US).saturating_mul(QUANTUM_US)
        };
        boundary.max(t + QUANTUM_US)
    }

    /// The trajectory so far.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The world (its arena, the robot's pose).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The end line's figures.
    pub fn summary(&self) -> Summary {
        self.world.summary()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ARENA: &str = r#"{ "walls": [[[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]],
        "robot": { "x": 0, "y": 0, "heading_deg": 0 } }"#;

    fn run() -> WorldRun {
        WorldRun::new(
            Arena::parse(ARENA).expect("the test arena"),
            None,
            ImuRevision::Rev1_2,
        )
    }

    #[test]
    fn readings_go_to_each_sensor_board_once_per_feed_period() {
        let mut w = run();
        assert!(
            w.readings_for(2, 40, 0).is_none(),
            "LightRing reads nothing"
        );
        let dwd = w.readings_for(0, 40, 0).expect("the first readings");
        assert!(dwd.has(world_link::FLOOR) && dwd.has(world_link::IMU_1_2));
        let pm = w
            .readings_for(1, 80, 0)
            .expect("the same readings for the ring");
        assert!(pm.has(world_link::RING) && !pm.has(world_link::FLOOR));
        assert_eq!(pm.at_us, 80);
        assert!(
            w.readings_for(0, 520, 0).is_none(),
            "within the feed period"
        );
        assert!(w.readings_for(0, 1_040, 0).is_some(), "a feed period later");
        // A board restarted at 2 ms gets its own clock's time.
        assert_eq!(w.readings_for(1, 2_080, 2_000).map(|r| r.at_us), Some(80));
    }

    /// DiWheelDrive's wheels turn one revolution straight ahead in the first second: the robot is 175 mm on
    /// (returned, m).
    fn one_revolution_ahead(w: &mut WorldRun) -> f64 {
        w.wheels(
            0,
            Wheels {
                now_us: 1_000_000,
                left_ticks: 1408,
                right_ticks: 1408,
            },
        );
        w.at(1_000_000);
        let x = w.world().pose().position.x;
        assert!((x - 0.175).abs() < 0.001, "{x}");
        x
    }

    #[test]
    fn the_wheels_move_the_robot_and_the_rows_follow_the_boundaries() {
        let mut w = run();
        w.at(0);
        let x = one_revolution_ahead(&mut w);
        assert_eq!(w.trajectory().samples.len(), 101);
        // A restart: the fresh plant's ticks do not move the robot back.
        w.wheels(
            1_000_000,
            Wheels {
                now_us: 100,
                left_ticks: 0,
                right_ticks: 0,
            },
        );
        assert!((w.world().pose().position.x - x).abs() < 1e-9);
    }

    #[test]
    fn a_controller_ticks_at_its_period_and_its_frames_come_back() {
        let dir = std::env::temp_dir().join(format!("amiro-robot-world-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temp dir");
        let script = dir.join("controller.sh");
        // Echoes the frames it sees as a count, sends a motor frame at every tick.
        std::fs::write(
            &script,
            "#!/bin/sh\nn=0\nwhile read -r l; do case \"$l\" in *tick) echo 110#0$n; echo ok; n=0;; *) n=$((n+1));; esac; done\n",
        )
        .expect("the script");
        let mut w = run();
        assert!(
            w.with_controller("/bin/sh x", 30).is_err(),
            "not a multiple of 40 µs"
        );
        w.with_controller(&format!("/bin/sh {}", script.display()), 10_000)
            .expect("the controller");
        assert_eq!(w.next_tick(), Some(10_000));
        assert!(w.ticks(9_960).expect("no tick yet").is_empty());
        let frame = amiro_bus_sim::Frame::new(0x61F, &[0, 200, 0]).expect("a frame");
        w.frame(9_990, &frame).expect("written");
        w.frame(9_995, &frame).expect("written");
        let sent = w.ticks(20_000).expect("two ticks");
        let data: Vec<&[u8]> = sent.iter().map(|f| f.payload()).collect();
        assert_eq!(
            data,
            [&[0x02][..], &[0x00][..]],
            "two frames before the first tick, none before the second"
        );
        assert_eq!(w.next_tick(), Some(30_000));
        w.at(20_000);
        assert_eq!(w.trajectory().samples.len(), 3, "a row at every tick");
        w.finish();
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn without_a_world_the_boards_keep_their_simulators_and_the_wheels_still_move_it() {
        let mut w = WorldRun::without_world();
        assert!(!w.feeds());
        assert!(w.readings_for(0, 40, 0).is_none());
        assert!(w.readings_for(1, 40, 0).is_none());
        one_revolution_ahead(&mut w);
        assert_eq!(w.summary().contacts, 0);
    }

    #[test]
    fn sensor_boards_wake_a_boundary_before_their_deadline() {
        assert_eq!(WorldRun::wake_boundary(1, 0, 10_000), 9_960);
        assert_eq!(WorldRun::wake_boundary(1, 0, 10_001), 10_000);
        assert_eq!(WorldRun::wake_boundary(2, 0, 10_001), 10_040);
        assert_eq!(WorldRun::wake_boundary(0, 9_960, 10_000), 10_000);
    }
}
