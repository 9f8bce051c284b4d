//! A live run's warm-up: before the wall clock starts, the boards run the code a client's commands
//! will run — every sensor topic's admission decision, publisher and sample, the one-shot and stop
//! paths, an LED and the motor command, and the thesis load — in virtual time, unpaced; then
//! each board restarts in its own QEMU ([`amiro_trace::robot_link::DOWN_RESTART`]). QEMU translates
//! a board's code the first time it runs it, 10–20 times slower than it runs it later (docs/qemu.md,
//! "Live"); the restart keeps the translations, so the client meets freshly booted boards whose
//! code is already translated, and the start-up's lag no longer comes from it.
use amiro_can::{CanId, Kind, Priority, TOPICS};

use crate::stimulus::{Action, Timed};

/// The boundary the boards restart at (virtual µs from the start of the run): after the last
/// request below has been decided and its stream has sampled several times.
pub const RESTART_US: u64 = 160_000;

/// When the first request goes out: the boards have booted and released SYS_SYNC_N by then.
const FIRST_US: u64 = 10_000;
/// Between two requests.
const SPACING_US: u64 = 1_000;

/// The warm-up's frames as they are planned: each request [`SPACING_US`] after the one before.
struct Plan {
    at: u64,
    frames: Vec<Timed>,
}

impl Plan {
    fn send(&mut self, priority: Priority, topic: u8, data: &[u8]) {
        self.frames.push(Timed {
            at_us: self.at,
            action: Action::Frame {
                id: CanId::new(Kind::Command, priority, topic).raw(),
                data: data.to_vec(),
            },
        });
        self.at += SPACING_US;
    }

    /// The next request not before `at_us`.
    fn from(&mut self, at_us: u64) {
        self.at = self.at.max(at_us);
    }
}

/// The operator's frames of the warm-up, in time order (all before [`RESTART_US`]).
pub fn actions() -> Vec<Timed> {
    use amiro_can::Topic;
    let mut plan = Plan {
        at: FIRST_US,
        frames: Vec::new(),
    };
    let sensors: Vec<u8> = TOPICS
        .iter()
        .filter(|t| t.is_sensor)
        .map(|t| t.topic.byte())
        .collect();
    // Every sensor topic published every 10 ms at medium: each board's admission check decides
    // request after request (accepting, then refusing once its load is full), and the accepted
    // streams sample and publish.
    for &topic in &sensors {
        plan.send(Priority::Medium, topic, &[1, 10, 0, 0]);
    }
    // Every LED, and the motor at standstill.
    for topic in Topic::Led1.byte()..=Topic::Led8.byte() {
        plan.send(Priority::Medium, topic, &[0xFF, 0x80, 0x20]);
    }
    plan.send(Priority::Medium, Topic::MotorCommand.byte(), &[0; 8]);
    // Let them run, then one sample now of each (which stops its publisher), then a stop of each.
    plan.from(60_000);
    for &topic in &sensors {
        plan.send(Priority::Medium, topic, &[2]);
    }
    for &topic in &sensors {
        plan.send(Priority::Medium, topic, &[0]);
    }
    // The live load (the thesis's example and a gyroscope beside it, as
    // `tools/interop/live_pace.py` sends it): the ring every 62.5 ms (62 500 µs: PowerManagement
    // refuses it every 10 ms since its ring row is the machine code's, 2026-12-06, so the ring's
    // sample would not run before the restart), LED 3, magnetometer-x every 900 µs at medium, the
    // gyroscope every 10 ms at low; the streams then run to the restart.
    plan.from(100_000);
    plan.send(
        Priority::Medium,
        Topic::ProximityRing.byte(),
        &[1, 0x24, 0xF4, 2],
    );
    plan.send(Priority::Medium, Topic::Led3.byte(), &[0xFF, 0x80, 0x20]);
    plan.send(
        Priority::Medium,
        Topic::MagnetometerX.byte(),
        &[1, 0x84, 0x03, 2],
    );
    plan.send(Priority::Low, Topic::Gyroscope.byte(), &[1, 10, 0, 0]);
    plan.frames
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_warm_up_ends_before_the_restart_and_asks_every_board() {
        let actions = actions();
        assert!(actions.windows(2).all(|w| w[0].at_us < w[1].at_us));
        // The last request has 40 ms to be decided and sample before the restart.
        let last = actions.last().map(|a| a.at_us).unwrap_or(0);
        assert!(last + 40_000 <= RESTART_US, "last request at {last} µs");
        assert_eq!(RESTART_US % crate::QUANTUM_US, 0);
        let ids: Vec<u16> = actions
            .iter()
            .filter_map(|a| match &a.action {
                Action::Frame { id, .. } => Some(*id),
                _ => None,
            })
            .collect();
        // Command frames only (what a client sends), to every board: the ring (PowerManagement),
        // magnetometer-x and the gyroscope at low (DiWheelDrive), LED 3 (LightRing).
        assert!(ids
            .iter()
            .all(|&id| amiro_trace::robot_link::reaches_software(id)));
        for id in [0x21F, 0x205, 0x308, 0x213] {
            assert!(ids.contains(&id), "{id:03X} missing");
        }
        // Never the shutdown command.
        let shutdown = amiro_can::Topic::Shutdown.byte();
        assert!(ids.iter().all(|&id| id & 0xFF != u16::from(shutdown)));
    }
}
