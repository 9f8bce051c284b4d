//! The drive controller: motor command in, wheel duties out, odometry and velocity on the side,
//! and a dead-man stop when commands stop coming.
//!
//! The firmware calls [`DriveController::set_target`] for every motor command and
//! [`DriveController::update`] from its periodic control task (10 ms on the AMiRo) with the two
//! encoder counts; it applies the returned [`DriveOutput`] to the PWM timer and POWER_EN, and
//! publishes [`DriveController::odometry`] / [`DriveController::velocity`] (or
//! [`DriveController::sample`]) for the protocol's odometry and velocity topics.
//!
//! Dead-man: a command older than [`DriveConfig::command_timeout_us`] (default 500 ms) no longer
//! counts. The next update then zeroes the target, the duties and the integrators, reports the
//! motors disabled, and sets [`DriveOutput::deadman_tripped`] once so the firmware can trace it.

use core::num::NonZeroU64;

use amiro_can::{MotorCommand, Odometry, SensorData, Topic, Velocity};

use super::divide::Divisor;
use super::odometry::{DeadReckoning, DriveGeometry, EncoderTracker, Pose};
use super::speed::{PiGains, WheelSpeedController};
use super::Duty;

/// Longest window the velocity estimate can average over, in control steps.
pub const MAX_VELOCITY_WINDOW: usize = 8;

/// Everything the drive controller is configured with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveConfig {
    /// Ticks per revolution, wheel diameter, axle width.
    pub geometry: DriveGeometry,
    /// Wheel speed controller gains (both wheels).
    pub gains: PiGains,
    /// A motor command stops counting after this long (µs).
    pub command_timeout_us: u64,
    /// Largest wheel speed a command may ask for (µm/s); faster commands are scaled down keeping
    /// the curvature.
    pub max_wheel_speed_um_s: i32,
    /// The left count falls when the left wheel drives forward.
    pub invert_left_encoder: bool,
    /// The right count falls when the right wheel drives forward.
    pub invert_right_encoder: bool,
    /// Control steps the velocity is averaged over (1..=8; at 10 ms, 4 = 40 ms): one tick is
    /// 124 µm, so a single 10 ms step resolves speed only in 12.4 mm/s steps.
    pub velocity_window: u8,
    /// Longest time step the integrators accept (µs): a late control task must not kick them.
    pub max_step_us: u32,
}

impl DriveConfig {
    /// The AMiRo defaults: [`DriveGeometry::AMIRO`], [`PiGains::AMIRO`], 500 ms dead-man, 0.5 m/s
    /// wheel speed limit, encoders counting up forward (the timers in plain quadrature mode, as
    /// the 2.x firmware configures them; 1.x inverted one timer input *and* negated the
    /// difference, which cancels), 4-step velocity window, 50 ms longest step.
    pub const AMIRO: DriveConfig = DriveConfig {
        geometry: DriveGeometry::AMIRO,
        gains: PiGains::AMIRO,
        command_timeout_us: 500_000,
        max_wheel_speed_um_s: 500_000,
        invert_left_encoder: false,
        invert_right_encoder: false,
        velocity_window: 4,
        max_step_us: 50_000,
    };
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self::AMIRO
    }
}

/// What the firmware applies after each control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriveOutput {
    /// Left wheel duty.
    pub duty_left: Duty,
    /// Right wheel duty.
    pub duty_right: Duty,
    /// Whether motor power (POWER_EN) should be on.
    pub motors_enabled: bool,
    /// True on the one update where the dead-man timeout stopped a commanded drive.
    pub deadman_tripped: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct WindowStep {
    left_ticks: i32,
    right_ticks: i32,
    dt_us: u32,
}

/// Odometry, velocity and wheel speed control for the DiWheelDrive.
#[derive(Debug, Clone)]
pub struct DriveController {
    config: DriveConfig,
    left_encoder: EncoderTracker,
    right_encoder: EncoderTracker,
    odometry: DeadReckoning,
    left_speed: WheelSpeedController,
    right_speed: WheelSpeedController,
    target: MotorCommand,
    last_command_us: Option<u64>,
    last_update_us: Option<u64>,
    window: [WindowStep; MAX_VELOCITY_WINDOW],
    window_len: usize,
    window_next: usize,
    velocity: Velocity,
    wheel_speeds_um_s: (i64, i64),
    output: DriveOutput,
}

impl DriveController {
    /// A controller at the origin, stopped.
    pub fn new(config: DriveConfig) -> Self {
        Self {
            config,
            left_encoder: EncoderTracker::new(config.invert_left_encoder),
            right_encoder: EncoderTracker::new(config.invert_right_encoder),
            odometry: DeadReckoning::new(config.geometry),
            left_speed: WheelSpeedController::new(config.gains),
            right_speed: WheelSpeedController::new(config.gains),
            target: MotorCommand::STOP,
            last_command_us: None,
            last_update_us: None,
            window: [WindowStep::default(); MAX_VELOCITY_WINDOW],
            window_len: 0,
            window_next: 0,
            velocity: Velocity::default(),
            wheel_speeds_um_s: (0, 0),
            output: DriveOutput::default(),
        }
    }

    /// The configuration in use.
    pub const fn config(&self) -> &DriveConfig {
        &self.config
    }

    /// A motor command arrived at `now_us`: it becomes the target until the next one or the
    /// dead-man timeout.
    pub fn set_target(&mut self, command: MotorCommand, now_us: u64) {
        self.target = command;
        self.last_command_us = Some(now_us);
    }

    /// Stops now (shutdown, emergency): target zero, and the next update disables the motors
    /// without reporting a dead-man trip.
    pub fn stop(&mut self) {
        self.target = MotorCommand::STOP;
        self.last_command_us = None;
    }

    /// The current target (zero once the dead-man has tripped).
    pub const fn target(&self) -> MotorCommand {
        self.target
    }

    /// Whether a command is in force at `now_us`.
    pub fn is_commanded(&self, now_us: u64) -> bool {
        match self.last_command_us {
            Some(at) => now_us.saturating_sub(at) <= self.config.command_timeout_us,
            None => false,
        }
    }

    /// One control step at `now_us` with the encoders' current counts.
    pub fn update(&mut self, now_us: u64, left_count: u16, right_count: u16) -> DriveOutput {
        let left_ticks = self.left_encoder.delta(left_count);
        let right_ticks = self.right_encoder.delta(right_count);
        let dt_us = match self.last_update_us {
            Some(previous) => now_us.saturating_sub(previous),
            None => 0,
        };
        self.last_update_us = Some(now_us);
        self.odometry.advance(left_ticks, right_ticks);
        if dt_us > 0 {
            self.record_step(
                left_ticks,
                right_ticks,
                u32::try_from(dt_us).unwrap_or(u32::MAX),
            );
        }

        self.output = if self.is_commanded(now_us) {
            let (left_target, right_target) = self.wheel_targets();
            let step = u32::try_from(dt_us)
                .unwrap_or(u32::MAX)
                .min(self.config.max_step_us);
            let (left_measured, right_measured) = self.wheel_speeds_um_s;
            let speed_limit = i64::from(self.config.max_wheel_speed_um_s.max(0));
            DriveOutput {
                duty_left: self.left_speed.update_limited(
                    left_target,
                    left_measured,
                    step,
                    speed_limit,
                ),
                duty_right: self.right_speed.update_limited(
                    right_target,
                    right_measured,
                    step,
                    speed_limit,
                ),
                motors_enabled: true,
                deadman_tripped: false,
            }
        } else {
            let tripped = self.last_command_us.is_some();
            self.stop();
            self.left_speed.reset();
            self.right_speed.reset();
            DriveOutput {
                deadman_tripped: tripped,
                ..DriveOutput::default()
            }
        };
        self.output
    }

    /// The last [`update`](Self::update)'s output.
    pub const fn output(&self) -> DriveOutput {
        self.output
    }

    /// The pose in µm and µrad.
    pub const fn pose(&self) -> Pose {
        self.odometry.pose()
    }

    /// Replaces the pose (the heading is wrapped into one turn).
    pub fn set_pose(&mut self, pose: Pose) {
        self.odometry.set_pose(pose);
    }

    /// The pose in the protocol's odometry units; x and y saturate at the wire's ±838.8 m:
    /// [`odometry_of`](Self::odometry_of) of the [`pose`](Self::pose). A caller that holds the
    /// controller under a lock reads the pose there and converts it after the lock (the
    /// heading's reduction to one turn takes three 64-bit divisions, which need not hold up the
    /// lock's other users).
    pub fn odometry(&self) -> Odometry {
        Self::odometry_of(self.pose())
    }

    /// The measured body velocity, averaged over the velocity window.
    pub const fn velocity(&self) -> Velocity {
        self.velocity
    }

    /// The measured wheel speeds (left, right) in µm/s, averaged over the velocity window.
    pub const fn wheel_speeds_um_s(&self) -> (i64, i64) {
        self.wheel_speeds_um_s
    }

    /// The sensor data for the odometry or velocity topic; `None` for any other topic.
    pub fn sample(&self, topic: Topic) -> Option<SensorData> {
        match topic {
            Topic::Odometry => Some(SensorData::Odometry(self.odometry())),
            Topic::Velocity => Some(SensorData::Velocity(self.velocity())),
            _ => None,
        }
    }

    /// Wheel speed targets from the command, scaled down together if one is over the limit.
    fn wheel_targets(&self) -> (i64, i64) {
        let (left, right) = self
            .config
            .geometry
            .wheel_speeds_um_s(self.target.velocity_um_s, self.target.angular_urad_s);
        let limit = i64::from(self.config.max_wheel_speed_um_s.max(0));
        let largest = left.abs().max(right.abs());
        match NonZeroU64::new(largest.unsigned_abs()) {
            Some(largest_um_s) if largest > limit => {
                let largest = Divisor::new(largest_um_s);
                (
                    largest.div_i64(left * limit),
                    largest.div_i64(right * limit),
                )
            }
            _ => (left, right),
        }
    }

    fn record_step(&mut self, left_ticks: i32, right_ticks: i32, dt_us: u32) {
        let capacity = usize::from(self.config.velocity_window).clamp(1, MAX_VELOCITY_WINDOW);
        if let Some(slot) = self.window.get_mut(self.window_next % capacity) {
            *slot = WindowStep {
                left_ticks,
                right_ticks,
                dt_us,
            };
        }
        self.window_next = (self.window_next + 1) % capacity;
        self.window_len = (self.window_len + 1).min(capacity);

        let (mut left, mut right, mut dt) = (0i64, 0i64, 0u64);
        for step in self.window.iter().take(self.window_len) {
            left += i64::from(step.left_ticks);
            right += i64::from(step.right_ticks);
            dt += u64::from(step.dt_us);
        }
        let Some(dt) = NonZeroU64::new(dt) else {
            return;
        };
        // Four quotients by the window's time: its reciprocal once.
        let dt = Divisor::new(dt);
        let motion = self.odometry.step(
            left.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
            right.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
        );
        let saturate = |value: i64| value.clamp(i32::MIN.into(), i32::MAX.into()) as i32;
        self.wheel_speeds_um_s = (
            per_second(motion.left_nm, &dt),
            per_second(motion.right_nm, &dt),
        );
        self.velocity = Velocity {
            velocity_um_s: saturate(per_second(motion.distance_nm, &dt)),
            angular_urad_s: saturate(per_second(motion.rotation_nrad, &dt)),
        };
    }
}

/// A travel over the window's time as a rate: nm per µs = mm/s, × 1000 gives µm/s (and nrad per
/// µs × 1000 gives µrad/s). Inlined: as a closure called four times, the size-optimising build
/// reached it through a register moved into an outlined helper, which the bound cannot follow.
#[inline(always)]
fn per_second(value: i64, dt_us: &Divisor) -> i64 {
    dt_us.div_i64(value.saturating_mul(1000))
}

impl Default for DriveController {
    fn default() -> Self {
        Self::new(DriveConfig::AMIRO)
    }
}

impl DriveController {
    /// A pose in the protocol's odometry units, as [`odometry`](Self::odometry) gives the
    /// controller's own; x and y saturate at the wire's ±838.8 m.
    pub fn odometry_of(pose: Pose) -> Odometry {
        let limit = i64::from(Odometry::MAX_100UM) * 100;
        let x = pose.x_um.clamp(-limit, limit);
        let y = pose.y_um.clamp(-limit, limit);
        Odometry::from_micrometres(x, y, pose.heading_urad).unwrap_or_default()
    }
}
