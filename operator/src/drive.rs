//! Driving the robot from the operator's computer: speeds in the units people think in (`100mm/s`, `30deg/s`),
//! and the keep-alive that repeats the motor command within the DiWheelDrive's dead-man window.
//!
//! The board zeroes the motors when no motor command arrived for 500 ms (`DriveConfig::command_timeout_us`,
//! docs/sensors.md), so a single `motor` frame drives for half a second. [`KeepAlive`] repeats the command every
//! `every` (default 200 ms, at most half the window so one lost frame is survived) and sends one stop when the
//! command becomes zero. [`drive`] runs a timed drive on a bus and always ends with a stop: at the end, on
//! Ctrl-C, and (if the bus still takes it) when the connection fails. The schedule takes its time from a
//! [`Clock`], so tests check it in simulated time.

use std::time::{Duration, Instant};

use amiro_can::{Command, Message, MotorCommand, Priority};
use anyhow::{bail, Context, Result};

use crate::bus::{interrupted, Bus, Reception};
use crate::encode;
use crate::frame::{LoggedFrame, RawFrame};

/// The DiWheelDrive's dead-man: no motor command for this long stops the motors.
pub const DEADMAN: Duration = Duration::from_millis(500);
/// The default keep-alive period.
pub const DEFAULT_EVERY: Duration = Duration::from_millis(200);
/// The longest keep-alive period accepted: half the dead-man, so one lost frame does not stop the robot.
pub const MAX_EVERY: Duration = Duration::from_millis(250);

/// Parses a forward speed: `100mm/s`, `0.1m/s`, `10cm/s`, `100000um/s` (or `µm/s`); negative is backwards.
/// Rounded to the wire's 1 µm/s.
pub fn parse_speed(text: &str) -> Result<i32> {
    let units = [
        ("um/s", 1.0),
        ("µm/s", 1.0),
        ("mm/s", 1e3),
        ("cm/s", 1e4),
        ("m/s", 1e6),
    ];
    parse_rate(text, &units, "a speed such as 100mm/s, 0.1m/s or -50mm/s")
}

/// µrad/s in one °/s: the one conversion between the wire's turning rate and the degrees people read.
pub const URAD_S_PER_DEG_S: f64 = std::f64::consts::PI / 180.0 * 1e6;

/// A turning rate on the wire (µrad/s) in °/s.
pub fn degrees_per_second(urad_s: i32) -> f64 {
    f64::from(urad_s) / URAD_S_PER_DEG_S
}

/// Parses a turning rate: `30deg/s` (or `°/s`), `0.5rad/s`, `500mrad/s`, `500000urad/s`; positive is
/// counter-clockwise seen from above. Rounded to the wire's 1 µrad/s.
pub fn parse_turn(text: &str) -> Result<i32> {
    let per_degree = URAD_S_PER_DEG_S;
    let units = [
        ("urad/s", 1.0),
        ("µrad/s", 1.0),
        ("mrad/s", 1e3),
        ("rad/s", 1e6),
        ("deg/s", per_degree),
        ("°/s", per_degree),
    ];
    parse_rate(
        text,
        &units,
        "a turning rate such as 30deg/s, 0.5rad/s or -30deg/s",
    )
}

fn parse_rate(text: &str, units: &[(&str, f64)], example: &str) -> Result<i32> {
    let trimmed = text.trim();
    // Longest unit first, so `mrad/s` is not read as `m` + `rad/s`.
    let mut by_length: Vec<_> = units.to_vec();
    by_length.sort_by_key(|(unit, _)| std::cmp::Reverse(unit.len()));
    let Some((number, scale)) = by_length.iter().find_map(|(unit, scale)| {
        trimmed
            .strip_suffix(unit)
            .map(|number| (number.trim(), *scale))
    }) else {
        bail!("{text:?} has no unit I know: write {example}");
    };
    let value: f64 = number
        .parse()
        .ok()
        .filter(|value: &f64| value.is_finite())
        .with_context(|| format!("{text:?} is not a number with a unit: write {example}"))?;
    let wire = (value * scale).round();
    if wire < f64::from(i32::MIN) || wire > f64::from(i32::MAX) {
        bail!("{text} does not fit the motor command (at most ±2147 m/s or ±2147 rad/s)");
    }
    Ok(wire as i32)
}

/// Checks a keep-alive period against the dead-man.
pub fn check_every(every: Duration) -> Result<Duration> {
    if every.is_zero() || every > MAX_EVERY {
        bail!(
            "the motor command must be repeated more often than the board's {} ms dead-man: give --every between \
             1ms and {} ms (one lost frame must not stop the robot)",
            DEADMAN.as_millis(),
            MAX_EVERY.as_millis()
        );
    }
    Ok(every)
}

/// Time for the drive schedule: the host's monotonic clock, or a simulated one in tests.
pub trait Clock {
    /// Time since an arbitrary origin that never goes backwards.
    fn now(&self) -> Duration;
}

/// The host's monotonic clock.
pub struct HostClock(Instant);

impl HostClock {
    /// A clock whose origin is now.
    pub fn start() -> Self {
        Self(Instant::now())
    }
}

impl Clock for HostClock {
    fn now(&self) -> Duration {
        self.0.elapsed()
    }
}

/// What the motor should do and when the next frame is due.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KeepAlive {
    every: Duration,
    command: MotorCommand,
    /// When the next motor frame is due; `None` when stopped and the stop has been sent.
    next_due: Option<Duration>,
}

impl KeepAlive {
    /// Stopped, nothing due.
    pub fn new(every: Duration) -> Self {
        Self {
            every,
            command: MotorCommand {
                velocity_um_s: 0,
                angular_urad_s: 0,
            },
            next_due: None,
        }
    }

    /// The command being kept alive.
    pub fn command(&self) -> MotorCommand {
        self.command
    }

    /// Whether the robot is being driven (a non-zero command).
    pub fn driving(&self) -> bool {
        self.command.velocity_um_s != 0 || self.command.angular_urad_s != 0
    }

    /// Sets a new command, due at once. A zero command is sent once and not repeated.
    pub fn set(&mut self, command: MotorCommand, now: Duration) {
        self.command = command;
        self.next_due = Some(now);
    }

    /// Stops: one zero command, due at once.
    pub fn stop(&mut self, now: Duration) {
        self.set(
            MotorCommand {
                velocity_um_s: 0,
                angular_urad_s: 0,
            },
            now,
        );
    }

    /// When the next frame is due, if any.
    pub fn next_due(&self) -> Option<Duration> {
        self.next_due
    }

    /// The command to send now, if one is due. Repeats are scheduled from the due time (no drift), but a late
    /// caller does not get a burst of catch-up frames.
    pub fn due(&mut self, now: Duration) -> Option<MotorCommand> {
        let due = self.next_due?;
        if now < due {
            return None;
        }
        self.next_due = if self.driving() {
            let next = due + self.every;
            Some(if next <= now { now + self.every } else { next })
        } else {
            None
        };
        Some(self.command)
    }
}

/// The frame of a motor command.
pub fn motor_frame(command: MotorCommand, priority: Priority) -> Result<RawFrame> {
    encode::frame(&Message::Command(Command::Motor { priority, command }))
}

/// A timed drive.
#[derive(Clone, Debug)]
pub struct DrivePlan {
    /// What to drive.
    pub command: MotorCommand,
    /// Priority of the motor frames.
    pub priority: Priority,
    /// How long; `None` until Ctrl-C.
    pub duration: Option<Duration>,
    /// Keep-alive period.
    pub every: Duration,
}

impl DrivePlan {
    /// How it reads to the user: `V µm/s, A µrad/s, repeated every N ms`, then ` for D ms`, or `open_end` without
    /// a duration.
    pub fn describe(&self, open_end: &str) -> String {
        format!(
            "{} µm/s, {} µrad/s, repeated every {} ms{}",
            self.command.velocity_um_s,
            self.command.angular_urad_s,
            self.every.as_millis(),
            self.duration
                .map(|duration| format!(" for {} ms", duration.as_millis()))
                .unwrap_or_else(|| open_end.into())
        )
    }
}

/// How a drive ended (the stop was sent in every case).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveEnd {
    /// The duration ran out.
    Finished,
    /// Ctrl-C.
    Interrupted,
}

/// Drives on `bus` as planned, handing every frame heard meanwhile (and every frame sent, as `true`) to
/// `show`, and sends a stop at the end, on Ctrl-C, and, if the bus still takes it, after a bus error.
pub fn drive(
    bus: &mut dyn Bus,
    clock: &dyn Clock,
    plan: &DrivePlan,
    show: &mut dyn FnMut(&LoggedFrame, bool) -> Result<()>,
) -> Result<DriveEnd> {
    let start = clock.now();
    let end = plan.duration.map(|duration| start + duration);
    let mut keep_alive = KeepAlive::new(plan.every);
    keep_alive.set(plan.command, start);
    let outcome = keep_driving(bus, clock, plan.priority, end, &mut keep_alive, show);
    let stop = motor_frame(
        MotorCommand {
            velocity_um_s: 0,
            angular_urad_s: 0,
        },
        plan.priority,
    )?;
    match outcome {
        Ok(end) => {
            bus.send(&stop).context("sending the stop")?;
            show(&LoggedFrame::bare(stop), true)?;
            Ok(end)
        }
        Err(error) => {
            let stopped = bus.send(&stop).is_ok();
            let note = if stopped {
                "the robot was stopped".to_string()
            } else {
                format!(
                    "the stop could not be sent; the board's dead-man stops the motors within {} ms of the last \
                     motor command",
                    DEADMAN.as_millis()
                )
            };
            Err(error.context(format!("driving ended early ({note})")))
        }
    }
}

fn keep_driving(
    bus: &mut dyn Bus,
    clock: &dyn Clock,
    priority: Priority,
    end: Option<Duration>,
    keep_alive: &mut KeepAlive,
    show: &mut dyn FnMut(&LoggedFrame, bool) -> Result<()>,
) -> Result<DriveEnd> {
    loop {
        if interrupted() {
            return Ok(DriveEnd::Interrupted);
        }
        let now = clock.now();
        if end.is_some_and(|end| now >= end) {
            return Ok(DriveEnd::Finished);
        }
        if let Some(command) = keep_alive.due(now) {
            let frame = motor_frame(command, priority)?;
            bus.send(&frame)?;
            show(&LoggedFrame::bare(frame), true)?;
        }
        let wake = [keep_alive.next_due(), end].into_iter().flatten().min();
        let wait = wake.map(|wake| wake.saturating_sub(clock.now()));
        match bus.receive(wait)? {
            Reception::Frame(frame) => show(&frame, false)?,
            Reception::Interrupted => return Ok(DriveEnd::Interrupted),
            Reception::TimedOut => {}
            // A log file has nothing more to say; keep time by the clock.
            Reception::Ended => {
                if let Some(wait) = wait {
                    std::thread::sleep(wait.min(Duration::from_millis(50)));
                }
            }
        }
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;
    use std::cell::Cell;
    use std::rc::Rc;

    /// A bus in simulated time: receiving waits by advancing the clock; sends are recorded with their time.
    pub struct SimulatedBus {
        pub clock: Rc<Cell<Duration>>,
        pub sent: Vec<(Duration, RawFrame)>,
        /// Sends fail from this time on (a lost connection).
        pub fail_from: Option<Duration>,
        /// Frames the "robot" sends, at their times.
        pub incoming: Vec<(Duration, RawFrame)>,
    }

    pub struct SimulatedClock(pub Rc<Cell<Duration>>);

    #[test]
    fn degrees_per_second_is_the_inverse_of_parsing_degrees() {
        for text in ["30deg/s", "-90°/s", "0.5deg/s", "360deg/s"] {
            let urad_s = parse_turn(text).unwrap();
            let degrees: f64 = text
                .trim_end_matches("deg/s")
                .trim_end_matches("°/s")
                .parse()
                .unwrap();
            // The wire rounds to 1 µrad/s, about 5.7e-5 °/s.
            assert!(
                (degrees_per_second(urad_s) - degrees).abs() < 1e-4,
                "{text}: {urad_s}"
            );
        }
        assert_eq!(degrees_per_second(1_000_000).round(), 57.0);
    }

    impl Clock for SimulatedClock {
        fn now(&self) -> Duration {
            self.0.get()
        }
    }

    impl Bus for SimulatedBus {
        fn send(&mut self, frame: &RawFrame) -> Result<()> {
            let now = self.clock.get();
            if self.fail_from.is_some_and(|from| now >= from) {
                bail!("adapter unplugged");
            }
            // Sending takes a little time, as on a real adapter.
            self.clock.set(now + Duration::from_micros(300));
            self.sent.push((now, *frame));
            Ok(())
        }

        fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
            let now = self.clock.get();
            let until = now + timeout.unwrap_or(Duration::from_secs(3600));
            if let Some(index) = self.incoming.iter().position(|(at, _)| *at <= until) {
                let (at, frame) = self.incoming.remove(index);
                self.clock.set(at.max(now));
                return Ok(Reception::Frame(LoggedFrame::bare(frame)));
            }
            // Host scheduling makes waits a bit late.
            self.clock.set(until + Duration::from_micros(700));
            Ok(Reception::TimedOut)
        }
    }

    fn simulated(fail_from: Option<Duration>) -> (SimulatedBus, SimulatedClock) {
        let clock = Rc::new(Cell::new(Duration::from_secs(100)));
        let bus = SimulatedBus {
            clock: Rc::clone(&clock),
            sent: Vec::new(),
            fail_from,
            incoming: vec![(
                Duration::from_millis(100_150),
                crate::frame::parse_compact("502#A0860100B03CFFFF").unwrap(),
            )],
        };
        (bus, SimulatedClock(clock))
    }

    #[test]
    fn speeds_and_turns_parse_in_people_units() {
        assert_eq!(parse_speed("100mm/s").unwrap(), 100_000);
        assert_eq!(parse_speed("0.1m/s").unwrap(), 100_000);
        assert_eq!(parse_speed("-5cm/s").unwrap(), -50_000);
        assert_eq!(parse_speed("250µm/s").unwrap(), 250);
        assert_eq!(parse_turn("30deg/s").unwrap(), 523_599);
        assert_eq!(parse_turn("-0.5rad/s").unwrap(), -500_000);
        assert_eq!(parse_turn("500mrad/s").unwrap(), 500_000);
        assert_eq!(parse_turn("90°/s").unwrap(), 1_570_796);
        assert!(parse_speed("100").is_err());
        assert!(parse_speed("fast mm/s").is_err());
        assert!(parse_speed("3000m/s").is_err());
        assert!(parse_turn("30deg").is_err());
    }

    #[test]
    fn keep_alive_periods_must_beat_the_deadman() {
        assert!(check_every(Duration::from_millis(200)).is_ok());
        assert!(check_every(MAX_EVERY).is_ok());
        assert!(check_every(Duration::from_millis(251)).is_err());
        assert!(check_every(Duration::from_millis(500)).is_err());
        assert!(check_every(Duration::ZERO).is_err());
    }

    #[test]
    fn the_keep_alive_repeats_a_command_without_drift_and_sends_one_stop() {
        let ms = Duration::from_millis;
        let mut keep_alive = KeepAlive::new(ms(200));
        assert_eq!(keep_alive.due(ms(0)), None);
        let forward = MotorCommand {
            velocity_um_s: 100_000,
            angular_urad_s: 0,
        };
        keep_alive.set(forward, ms(10));
        assert_eq!(keep_alive.due(ms(10)), Some(forward));
        assert_eq!(keep_alive.due(ms(209)), None);
        assert_eq!(keep_alive.due(ms(215)), Some(forward));
        // Due at 410 (from 210, not from the late 215).
        assert_eq!(keep_alive.next_due(), Some(ms(410)));
        // A caller late by more than a period gets one frame, not a burst.
        assert_eq!(keep_alive.due(ms(1000)), Some(forward));
        assert_eq!(keep_alive.due(ms(1000)), None);
        assert_eq!(keep_alive.next_due(), Some(ms(1200)));
        keep_alive.stop(ms(1100));
        assert_eq!(keep_alive.due(ms(1100)).map(|c| c.velocity_um_s), Some(0));
        assert_eq!(keep_alive.next_due(), None, "a stop is sent once");
    }

    #[test]
    fn a_timed_drive_keeps_every_gap_inside_the_deadman_and_ends_with_a_stop() {
        let (mut bus, clock) = simulated(None);
        let plan = DrivePlan {
            command: MotorCommand {
                velocity_um_s: 100_000,
                angular_urad_s: 523_599,
            },
            priority: Priority::High,
            duration: Some(Duration::from_secs(3)),
            every: DEFAULT_EVERY,
        };
        let mut heard = Vec::new();
        let end = drive(&mut bus, &clock, &plan, &mut |frame, sent| {
            if !sent {
                heard.push(frame.frame);
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(end, DriveEnd::Finished);
        assert_eq!(
            heard.len(),
            1,
            "the velocity frame heard meanwhile is shown"
        );
        let times: Vec<Duration> = bus.sent.iter().map(|(at, _)| *at).collect();
        let start = Duration::from_secs(100);
        assert_eq!(times[0], start, "the first command goes out at once");
        for pair in times.windows(2) {
            let gap = pair[1] - pair[0];
            assert!(
                gap <= DEFAULT_EVERY + Duration::from_millis(2),
                "gap {gap:?}"
            );
            assert!(gap < DEADMAN);
        }
        // 3 s at 200 ms: commands at 0, 0.2, ..., 2.8 s, then the stop at 3 s.
        assert_eq!(bus.sent.len(), 16, "{times:?}");
        let (last_at, last) = bus.sent.last().unwrap();
        assert_eq!(last.to_string(), "110#0000000000000000");
        assert!(*last_at >= start + Duration::from_secs(3));
        assert!(bus.sent[..15]
            .iter()
            .all(|(_, frame)| frame.to_string() == "110#A08601004FFD0700"));
    }

    #[test]
    fn a_lost_connection_ends_the_drive_with_an_error_that_names_the_deadman() {
        let (mut bus, clock) = simulated(Some(Duration::from_millis(100_500)));
        let plan = DrivePlan {
            command: MotorCommand {
                velocity_um_s: 50_000,
                angular_urad_s: 0,
            },
            priority: Priority::High,
            duration: None,
            every: DEFAULT_EVERY,
        };
        let error = drive(&mut bus, &clock, &plan, &mut |_, _| Ok(())).unwrap_err();
        let message = format!("{error:#}");
        assert!(
            message.contains("dead-man") && message.contains("500 ms"),
            "{message}"
        );
        assert!(message.contains("adapter unplugged"), "{message}");
        assert_eq!(bus.sent.len(), 3, "commands at 0, 200 and 400 ms");
    }
}
