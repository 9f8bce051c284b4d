//! The world's side of the robot link: what the robot host calls each time the DiWheelDrive
//! reports its wheels, and what it sends each board (docs/world.md, "How the readings reach the
//! boards"). The messages are `amiro_trace::world_link`'s; this module only turns them into world
//! steps and world readings into them.

use amiro_trace::world_link::{self, Wheels};

use crate::world::{Readings, World};

/// Which IMU the DiWheelDrive carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImuRevision {
    /// DiWheelDrive 1-1: L3G4200D, LIS331DLH, HMC5883L.
    Rev1_1,
    /// DiWheelDrive 1-2: BNO055.
    Rev1_2,
}

/// Follows the DiWheelDrive's wheel reports and moves the world's robot by the ticks between
/// them.
#[derive(Debug, Clone, Default)]
pub struct WheelFeed {
    last: Wheels,
}

impl WheelFeed {
    /// From boot: the plant starts at rest with both counts at zero at time zero.
    pub fn new() -> WheelFeed {
        WheelFeed::default()
    }

    /// The board reported `wheels`: the world's robot moves by the ticks since the last report,
    /// over the time between them. A report older than the last one moves nothing (and is not
    /// kept).
    pub fn report(&mut self, world: &mut World, wheels: Wheels) {
        if wheels.now_us < self.last.now_us {
            return;
        }
        let dt_s = (wheels.now_us - self.last.now_us) as f64 / 1e6;
        world.advance_ticks(
            dt_s,
            wheels.left_ticks.wrapping_sub(self.last.left_ticks),
            wheels.right_ticks.wrapping_sub(self.last.right_ticks),
        );
        self.last = wheels;
    }
}

/// The DiWheelDrive's part of `readings`: the floor counts and its revision's IMU values.
pub fn for_diwheeldrive(
    readings: &Readings,
    at_us: u64,
    revision: ImuRevision,
) -> world_link::Readings {
    let (group, rate, accel, field_nt) = match revision {
        ImuRevision::Rev1_1 => {
            let imu = readings.imu.for_rev_1_1();
            (
                world_link::IMU_1_1,
                imu.rate_mdps,
                imu.accel_ug,
                imu.field_nt,
            )
        }
        ImuRevision::Rev1_2 => {
            let imu = readings.imu.for_rev_1_2();
            (
                world_link::IMU_1_2,
                imu.rate_digits,
                imu.accel_mg,
                imu.field_nt,
            )
        }
    };
    world_link::Readings {
        at_us,
        groups: world_link::FLOOR | group,
        floor: readings.floor.counts,
        rate,
        accel,
        field_nt,
        ..world_link::Readings::default()
    }
}

/// The PowerManagement's part of `readings`: the ring's counts.
pub fn for_powermanagement(readings: &Readings, at_us: u64) -> world_link::Readings {
    world_link::Readings {
        at_us,
        groups: world_link::RING,
        ring: readings.ring.counts,
        ..world_link::Readings::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Arena;

    #[test]
    fn wheel_reports_move_the_robot_by_their_differences() {
        let arena = Arena::parse(r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 0 } }"#).unwrap();
        let mut world = World::new(arena);
        let mut feed = WheelFeed::new();
        // 1408 ticks on both wheels in the first second, 2816 in the next: 3 revolutions in all.
        for (t, ticks) in [(1_000_000, 1_408), (2_000_000, 4_224)] {
            feed.report(
                &mut world,
                Wheels {
                    now_us: t,
                    left_ticks: ticks,
                    right_ticks: ticks,
                },
            );
        }
        let x = world.pose().position.x;
        assert!(
            (x - 3.0 * std::f64::consts::PI * 0.05571).abs() < 1e-9,
            "{x}"
        );
        assert!((world.motion().forward_m_s - 2.0 * std::f64::consts::PI * 0.05571).abs() < 1e-9);
        // An old report is ignored.
        feed.report(&mut world, Wheels::default());
        assert_eq!(world.pose().position.x, x);
    }

    #[test]
    fn each_board_gets_its_groups_in_its_units() {
        let arena = Arena::parse(
            r#"{ "robot": { "x": 0, "y": 0, "heading_deg": 0 }, "walls": [[[0.1, -1], [0.1, 1]]] }"#,
        )
        .unwrap();
        let mut world = World::new(arena);
        let r = world.readings();
        let dwd = for_diwheeldrive(&r, 5, ImuRevision::Rev1_1);
        assert_eq!(dwd.groups, world_link::FLOOR | world_link::IMU_1_1);
        assert_eq!(dwd.floor, r.floor.counts);
        // Standing still: about 1 g on z in µg.
        assert!((dwd.accel[2] - 1_000_000).abs() < 50_000, "{:?}", dwd.accel);
        let dwd = for_diwheeldrive(&r, 5, ImuRevision::Rev1_2);
        assert_eq!(dwd.groups, world_link::FLOOR | world_link::IMU_1_2);
        assert!((dwd.accel[2] - 1_000).abs() < 50, "{:?}", dwd.accel);
        let pm = for_powermanagement(&r, 5);
        assert_eq!(
            (pm.groups, pm.ring, pm.at_us),
            (world_link::RING, r.ring.counts, 5)
        );
        // The wall 53.9 mm from the front pair (their cones' inner edge, see ring.rs): 2000 +
        // 1e6 / 53.9² = 2344 counts, noise 10 counts; the rear pair sees nothing: the offset.
        assert!((2_300..2_390).contains(&pm.ring[3]), "{:?}", pm.ring);
        assert!((2_300..2_390).contains(&pm.ring[4]), "{:?}", pm.ring);
        assert!((1_980..2_020).contains(&pm.ring[0]), "{:?}", pm.ring);
    }
}
