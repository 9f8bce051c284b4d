//! A closed loop without the firmware: a behaviour (through the [`crate::controller`] protocol)
//! drives the world's robot, and a small stand-in answers for the three boards at the level a
//! behaviour sees them — so behaviours can be tried and tested before the emulated robot carries
//! the world (docs/world.md says what the full loop adds).
//!
//! The stand-in is deliberately thin, and uses the protocol crate for every frame:
//! - a publish request (`amiro_can::SensorCommand`) for `proximity-ring` or `floor-proximity`
//!   starts a publisher at the requested period and priority (a stop stops it, a once sends one
//!   sample); ring frames carry the distance the firmware's driver computes from the world's
//!   counts (`ProximityCalibration::DEFAULT`, the same conversion), floor frames the counts;
//! - a motor command sets the body's velocity (ideal wheels: reached at once, the wheels'
//!   speeds `v ∓ ω · axle / 2`), and as on the DiWheelDrive a command older than 500 ms stops it;
//! - an LED command is remembered ([`Outcome::leds`]).
//!
//! It does not model the bus's timing, the boards' schedules or the wheel plant's lag: that is
//! what the emulated robot adds.

use amiro_can::{Command, Priority, SensorData, SensorMode, Topic};
use amiro_sensors::drivers::proximity::ProximityCalibration;

use crate::controller::{Controller, ControllerError, Frame};
use crate::output::Trajectory;
use crate::world::{Summary, World};

/// The DiWheelDrive's dead-man: a motor command older than this stops the robot, µs.
pub const DEADMAN_US: u64 = 500_000;

/// What a closed-loop run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The pose at every tick.
    pub trajectory: Trajectory,
    /// The end line's figures.
    pub summary: Summary,
    /// Controller ticks.
    pub ticks: u64,
    /// Ticks at which at least one floor sensor's spot was mostly dark (grey below 128).
    pub ticks_over_dark: u64,
    /// The eight LEDs' last colours, led-1 first.
    pub leds: [[u8; 3]; 8],
    /// Frames the behaviour sent that were not protocol commands the stand-in knows (counted,
    /// not fatal: a real board would ignore them too).
    pub ignored_frames: u64,
    /// Every frame of the loop, both ways, in time order, as `candump -l` lines (the bus log
    /// a robot run writes).
    pub bus_log: Vec<String>,
}

#[derive(Debug, Clone, Copy)]
struct Publisher {
    priority: Priority,
    period_us: u64,
    next_us: u64,
}

/// Runs `controller` against `world` for `duration_us` of virtual time with a tick every
/// `period_us`.
pub fn run(
    world: &mut World,
    controller: &mut Controller,
    duration_us: u64,
    period_us: u64,
) -> Result<Outcome, ControllerError> {
    let period_us = period_us.max(1);
    let calibration = ProximityCalibration::DEFAULT;
    let axle = world.motion().wheels.axle_m;
    let mut ring: Option<Publisher> = None;
    let mut floor: Option<Publisher> = None;
    let mut once: Vec<(Topic, Priority)> = Vec::new();
    let mut velocity = (0.0f64, 0.0f64);
    let mut last_motor_us: Option<u64> = None;
    let mut outcome = Outcome {
        trajectory: Trajectory::default(),
        summary: world.summary(),
        ticks: 0,
        ticks_over_dark: 0,
        leds: [[0; 3]; 8],
        ignored_frames: 0,
        bus_log: Vec::new(),
    };
    let mut t = 0u64;
    outcome.trajectory.record(t, world.pose());
    while t < duration_us {
        let dt_us = period_us.min(duration_us - t);
        if last_motor_us.is_some_and(|at| t.saturating_sub(at) > DEADMAN_US) {
            velocity = (0.0, 0.0);
            last_motor_us = None;
        }
        let dt = dt_us as f64 / 1e6;
        let (v, w) = velocity;
        world.advance(dt, (v - w * axle / 2.0) * dt, (v + w * axle / 2.0) * dt);
        t += dt_us;
        outcome.trajectory.record(t, world.pose());

        // Sensor frames due up to now, in time order (ring before floor at equal times).
        let mut due: Vec<(u64, Topic, Priority)> = Vec::new();
        for (publisher, topic) in [
            (&mut ring, Topic::ProximityRing),
            (&mut floor, Topic::FloorProximity),
        ] {
            if let Some(p) = publisher.as_mut() {
                while p.next_us <= t {
                    due.push((p.next_us, topic, p.priority));
                    p.next_us += p.period_us;
                }
            }
        }
        for (topic, priority) in once.drain(..) {
            due.push((t, topic, priority));
        }
        due.sort_by_key(|&(at, topic, _)| (at, topic as u8));
        for (at, topic, priority) in due {
            for data in sample(world, topic, &calibration) {
                let encoded = data.encode(priority);
                // A protocol frame always has an 11-bit identifier and at most 8 bytes.
                if let Some(frame) = Frame::new(encoded.id().raw(), encoded.data()) {
                    outcome.bus_log.push(candump_line(at, &frame));
                    controller.frame(at, &frame)?;
                }
            }
        }
        if world.floor().grey.iter().any(|&g| g < 128.0) {
            outcome.ticks_over_dark += 1;
        }
        outcome.ticks += 1;

        for frame in controller.tick(t)? {
            outcome.bus_log.push(candump_line(t, &frame));
            match amiro_can::decode_command(frame.id, frame.payload()) {
                Ok(Command::Motor { command, .. }) => {
                    velocity = (
                        f64::from(command.velocity_um_s) / 1e6,
                        f64::from(command.angular_urad_s) / 1e6,
                    );
                    last_motor_us = Some(t);
                }
                Ok(Command::Led { command, .. }) => {
                    if let Some(slot) = outcome
                        .leds
                        .get_mut(usize::from(command.led).wrapping_sub(1))
                    {
                        *slot = [command.rgb.r, command.rgb.g, command.rgb.b];
                    }
                }
                Ok(Command::Sensor(c)) => {
                    let target = match c.topic {
                        Topic::ProximityRing => &mut ring,
                        Topic::FloorProximity => &mut floor,
                        _ => {
                            outcome.ignored_frames += 1;
                            continue;
                        }
                    };
                    match c.mode {
                        SensorMode::Publish(sample_time) => {
                            let period_us = sample_time.as_micros().max(1);
                            *target = Some(Publisher {
                                priority: c.priority,
                                period_us,
                                next_us: t + period_us,
                            });
                        }
                        SensorMode::Stop => *target = None,
                        SensorMode::Once => {
                            *target = None;
                            once.push((c.topic, c.priority));
                        }
                    }
                }
                _ => outcome.ignored_frames += 1,
            }
        }
    }
    outcome.summary = world.summary();
    Ok(outcome)
}

/// A frame at `t_us` as `candump -l` writes it.
fn candump_line(t_us: u64, frame: &Frame) -> String {
    format!(
        "{} can0 {}",
        crate::controller::timestamp(t_us),
        frame.to_cansend()
    )
}

/// One sample of `topic` as the boards would publish it.
fn sample(world: &mut World, topic: Topic, calibration: &ProximityCalibration) -> Vec<SensorData> {
    match topic {
        Topic::ProximityRing => {
            let ring = world.ring();
            (0u8..)
                .zip(ring.counts)
                .map(|(sensor, counts)| SensorData::ProximityRing {
                    sensor,
                    mm: calibration.counts_to_mm(counts),
                })
                .collect()
        }
        Topic::FloorProximity => vec![SensorData::FloorProximity(world.floor().counts)],
        _ => Vec::new(),
    }
}
