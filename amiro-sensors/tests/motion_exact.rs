//! The motion math's divisions moved from `i64`'s `/` (the chip's `__aeabi_ldivmod`) to
//! `motion::divide` (the 32-bit hardware divide): the results must not change. Each test keeps the
//! formula as it was written with `/` (the reference, `old_…`) and compares it with the crate's
//! over every input the firmware can produce — exhaustively where the range is small (one wheel's
//! ticks), densely and at the edges where it is not — and the whole drive controller step by step
//! against a reference built from the old formulas.
//!
//! The ranges the firmware produces: an encoder step is an `i16` difference (±32 768 ticks,
//! `EncoderTracker::delta`), the velocity window sums at most 8 of them (±262 144); the time step
//! is a `u32` of µs (the window sums at most 8); a motor command's velocity and turn rate are any
//! `i32`; the controller's target is clamped to the speed limit and its measurement to ±10 m/s.

use amiro_can::{MotorCommand, Velocity};
use amiro_sensors::motion::odometry::{DeadReckoning, DriveGeometry, Pose};
use amiro_sensors::motion::speed::{PiGains, WheelSpeedController};
use amiro_sensors::motion::trig::{sin_cos, wrap_turn, TURN_NRAD};
use amiro_sensors::motion::{DriveConfig, DriveController, Duty};

/// A deterministic generator (xorshift64*): the same sweep on every run.
struct Sweep(u64);

impl Sweep {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in `low..=high`.
    fn range(&mut self, low: i64, high: i64) -> i64 {
        let span = (high - low) as u64 + 1;
        low + (self.next() % span) as i64
    }
}

const WINDOW_TICKS: i32 = 8 * 32_768;

fn geometries() -> [DriveGeometry; 2] {
    [
        DriveGeometry::AMIRO,
        DriveGeometry {
            axle_width_um: DriveGeometry::AXLE_WIDTH_1X_UM,
            ..DriveGeometry::AMIRO
        },
    ]
}

// ------------------------------------------------------------- the formulas as they were

fn old_pm_per_tick(g: &DriveGeometry) -> i64 {
    if g.ticks_per_revolution == 0 {
        return 0;
    }
    let circumference_fm = 3_141_592_654u64 * u64::from(g.wheel_diameter_um);
    let denominator = u64::from(g.ticks_per_revolution) * 1000;
    ((circumference_fm + denominator / 2) / denominator) as i64
}

fn old_ticks_to_nm(g: &DriveGeometry, ticks: i64) -> i64 {
    let pm = ticks.saturating_mul(old_pm_per_tick(g));
    if pm >= 0 {
        pm.saturating_add(500) / 1000
    } else {
        pm.saturating_sub(500) / 1000
    }
}

fn old_wheel_speeds(g: &DriveGeometry, velocity: i32, angular: i32) -> (i64, i64) {
    let half_difference = i64::from(angular) * i64::from(g.axle_width_um) / 2_000_000;
    (
        i64::from(velocity) - half_difference,
        i64::from(velocity) + half_difference,
    )
}

/// (left nm, right nm, distance nm, rotation nrad)
fn old_step(g: &DriveGeometry, left: i32, right: i32) -> (i64, i64, i64, i64) {
    let left_nm = old_ticks_to_nm(g, i64::from(left));
    let right_nm = old_ticks_to_nm(g, i64::from(right));
    let rotation = if g.axle_width_um == 0 {
        0
    } else {
        (right_nm - left_nm).saturating_mul(1_000_000) / i64::from(g.axle_width_um)
    };
    (left_nm, right_nm, (left_nm + right_nm) / 2, rotation)
}

fn old_wrap_turn(angle: i64) -> i64 {
    angle.rem_euclid(TURN_NRAD)
}

fn old_mul(a: i64, b: i64) -> i64 {
    (a * b + (1 << 29)) >> 30
}

fn old_sin_cos(angle: i64) -> (i64, i64) {
    const ONE: i64 = 1 << 30;
    const QUARTER: i64 = 1_570_796_327;
    let a = old_wrap_turn(angle);
    let mut quadrant = a / QUARTER;
    let mut r = a - quadrant * QUARTER;
    if r > 785_398_163 {
        r -= QUARTER;
        quadrant += 1;
    }
    let x = (r * ONE + if r >= 0 { 500_000_000 } else { -500_000_000 }) / 1_000_000_000;
    let x2 = old_mul(x, x);
    let mut s = ONE;
    let mut k = 5;
    while k > 0 {
        let d = (2 * k) * (2 * k + 1);
        s = ONE - old_mul(x2, s) / d;
        k -= 1;
    }
    let sin = old_mul(x, s);
    let mut c = ONE;
    let mut k = 6;
    while k > 0 {
        let d = (2 * k - 1) * (2 * k);
        c = ONE - old_mul(x2, c) / d;
        k -= 1;
    }
    match quadrant % 4 {
        0 => (sin, c),
        1 => (c, -sin),
        2 => (-sin, -c),
        _ => (-c, sin),
    }
}

fn old_scale(value: i64, fraction: i64) -> i64 {
    ((i128::from(value) * i128::from(fraction) + (1 << 29)) >> 30) as i64
}

fn old_round_thousandth(value: i64) -> i64 {
    if value >= 0 {
        (value + 500) / 1000
    } else {
        (value - 500) / 1000
    }
}

/// The pose integration as it was: x, y in nm, heading in nrad.
#[derive(Clone, Copy, Default)]
struct OldPose {
    x: i64,
    y: i64,
    heading: i64,
}

impl OldPose {
    fn advance(&mut self, g: &DriveGeometry, left: i32, right: i32) {
        let (_, _, distance, rotation) = old_step(g, left, right);
        let (sin, cos) = old_sin_cos(self.heading + rotation / 2);
        self.x += old_scale(distance, cos);
        self.y += old_scale(distance, sin);
        self.heading = old_wrap_turn(self.heading + rotation);
    }

    fn pose(&self) -> Pose {
        Pose {
            x_um: old_round_thousandth(self.x),
            y_um: old_round_thousandth(self.y),
            heading_urad: old_round_thousandth(self.heading),
        }
    }
}

const MAX_ERROR: i64 = 10_000_000;
const PER_DUTY: i64 = 1_000_000_000_000;

/// `WheelSpeedController` as it was.
#[derive(Clone, Copy)]
struct OldController {
    gains: PiGains,
    integral: i64,
    last_output: i64,
    last_measured: i64,
}

impl OldController {
    fn new(gains: PiGains) -> Self {
        Self {
            gains,
            integral: 0,
            last_output: 0,
            last_measured: 0,
        }
    }

    fn reset(&mut self) {
        *self = Self::new(self.gains);
    }

    fn update_limited(&mut self, target: i64, measured: i64, dt_us: u32, limit_um_s: i64) -> Duty {
        let limit = i64::from(self.gains.max_duty.clamp(0, Duty::FULL_SCALE));
        let speed_limit = limit_um_s.clamp(0, MAX_ERROR);
        let guard = speed_limit * 20 / 1000;
        let ceiling = speed_limit - guard;
        let target = target.clamp(-ceiling, ceiling);
        let measured = measured.clamp(-MAX_ERROR, MAX_ERROR);
        let predicted = measured
            .saturating_add((measured - self.last_measured).saturating_mul(2))
            .clamp(-MAX_ERROR, MAX_ERROR);
        self.last_measured = measured;
        let near_limit = target.abs() >= ceiling
            && predicted.signum() == target.signum()
            && predicted.abs() >= ceiling - 4 * guard;
        let feedback = if near_limit { predicted } else { measured };
        let error = target.saturating_sub(feedback).clamp(-MAX_ERROR, MAX_ERROR);
        let feed_forward = i64::from(self.gains.kff) * target / 1_000_000;
        let proportional = i64::from(self.gains.kp) * error / 1_000_000;
        let mut step = i64::from(self.gains.ki)
            .saturating_mul(error)
            .saturating_mul(i64::from(dt_us));
        if near_limit && step.signum() == target.signum() && predicted.abs() >= ceiling {
            step = 0;
        }
        let at_upper = (limit - feed_forward - proportional).saturating_mul(PER_DUTY);
        let at_lower = (-limit - feed_forward - proportional).saturating_mul(PER_DUTY);
        let candidate = self.integral.saturating_add(step);
        let integral = if step > 0 {
            candidate.min(at_upper.max(self.integral))
        } else {
            candidate.max(at_lower.min(self.integral))
        };
        let integral_limit = limit.saturating_mul(PER_DUTY);
        self.integral = integral.clamp(-integral_limit, integral_limit);
        let mut output =
            (feed_forward + proportional + self.integral / PER_DUTY).clamp(-limit, limit);
        if near_limit && output.signum() == target.signum() && predicted.abs() >= ceiling {
            let held = if self.last_output.signum() == output.signum() {
                self.last_output.abs()
            } else {
                0
            };
            output = output.signum() * output.abs().min(held);
        }
        self.last_output = output;
        Duty::saturating(output)
    }
}

// ------------------------------------------------------------- one formula at a time

#[test]
fn ticks_to_nm_is_unchanged_for_every_window_of_ticks() {
    for g in geometries() {
        assert_eq!(g.pm_per_tick(), old_pm_per_tick(&g));
        for ticks in -i64::from(WINDOW_TICKS)..=i64::from(WINDOW_TICKS) {
            assert_eq!(g.ticks_to_nm(ticks), old_ticks_to_nm(&g, ticks), "{ticks}");
        }
        for ticks in [i64::MIN, i64::MAX, i64::from(i32::MIN), i64::from(i32::MAX)] {
            assert_eq!(g.ticks_to_nm(ticks), old_ticks_to_nm(&g, ticks), "{ticks}");
        }
    }
}

#[test]
fn pm_per_tick_is_unchanged_for_any_geometry() {
    let mut rng = Sweep(7);
    for _ in 0..200_000 {
        let g = DriveGeometry {
            ticks_per_revolution: rng.next() as u32 >> (rng.next() % 32),
            wheel_diameter_um: rng.next() as u32 >> (rng.next() % 32),
            axle_width_um: 1,
        };
        assert_eq!(g.pm_per_tick(), old_pm_per_tick(&g), "{g:?}");
    }
}

#[test]
fn wheel_speeds_are_unchanged_for_any_command() {
    let mut rng = Sweep(11);
    let edges = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
    for g in geometries() {
        for v in edges {
            for w in edges {
                assert_eq!(g.wheel_speeds_um_s(v, w), old_wheel_speeds(&g, v, w));
            }
        }
        for _ in 0..500_000 {
            let (v, w) = (rng.next() as i32, rng.next() as i32);
            assert_eq!(g.wheel_speeds_um_s(v, w), old_wheel_speeds(&g, v, w));
        }
    }
}

#[test]
fn an_odometry_step_is_unchanged_across_the_window_range() {
    let mut rng = Sweep(13);
    for g in geometries() {
        let reckoning = DeadReckoning::new(g);
        let check = |left: i32, right: i32| {
            let step = reckoning.step(left, right);
            let old = old_step(&g, left, right);
            assert_eq!(
                (
                    step.left_nm,
                    step.right_nm,
                    step.distance_nm,
                    step.rotation_nrad
                ),
                old,
                "{left} {right}"
            );
        };
        // Every pair on a 97-tick grid over ±262 144, every single-step pair near zero, and
        // random pairs anywhere in the window range.
        for left in (-WINDOW_TICKS..=WINDOW_TICKS).step_by(97 * 13) {
            for right in (-WINDOW_TICKS..=WINDOW_TICKS).step_by(97) {
                check(left, right);
            }
        }
        for left in -300..=300 {
            for right in -300..=300 {
                check(left, right);
            }
        }
        for _ in 0..500_000 {
            let left = rng.range(-i64::from(WINDOW_TICKS), i64::from(WINDOW_TICKS)) as i32;
            let right = rng.range(-i64::from(WINDOW_TICKS), i64::from(WINDOW_TICKS)) as i32;
            check(left, right);
        }
        check(i32::MIN, i32::MAX);
        check(i32::MAX, i32::MIN);
    }
}

#[test]
fn sine_and_cosine_are_unchanged_for_every_angle_the_odometry_reaches() {
    // The odometry asks for heading (0..2π) plus half a step's rotation (a single encoder step
    // turns the robot by at most ±1.06e11 nrad): every 1 009th nrad over ±1.2e11 would be too
    // many, so a dense grid over four turns, every nrad near the quadrant boundaries, and random
    // angles anywhere.
    let mut rng = Sweep(17);
    for angle in (-2 * TURN_NRAD..=2 * TURN_NRAD).step_by(10_007) {
        assert_eq!(sin_cos(angle), old_sin_cos(angle), "{angle}");
    }
    for boundary in [
        0i64,
        785_398_163,
        1_570_796_327,
        3_141_592_654,
        4_712_388_981,
        TURN_NRAD,
    ] {
        for angle in boundary - 2_000..=boundary + 2_000 {
            assert_eq!(sin_cos(angle), old_sin_cos(angle), "{angle}");
            assert_eq!(wrap_turn(angle), old_wrap_turn(angle));
        }
    }
    for _ in 0..500_000 {
        let angle = rng.range(-120_000_000_000, 120_000_000_000);
        assert_eq!(sin_cos(angle), old_sin_cos(angle), "{angle}");
        let any = rng.next() as i64;
        assert_eq!(wrap_turn(any), old_wrap_turn(any), "{any}");
    }
    for angle in [i64::MIN, i64::MIN + 1, i64::MAX, -1] {
        assert_eq!(sin_cos(angle), old_sin_cos(angle), "{angle}");
        assert_eq!(wrap_turn(angle), old_wrap_turn(angle), "{angle}");
    }
}

#[test]
fn the_pose_is_unchanged_along_random_drives() {
    let mut rng = Sweep(19);
    for g in geometries() {
        for _ in 0..200 {
            let mut reckoning = DeadReckoning::new(g);
            let mut old = OldPose::default();
            for _ in 0..500 {
                // Mostly realistic steps (a few hundred ticks in 10 ms), now and then the extreme.
                let span = if rng.next().is_multiple_of(50) {
                    32_768
                } else {
                    400
                };
                let left = rng.range(-span, span - 1) as i32;
                let right = rng.range(-span, span - 1) as i32;
                reckoning.advance(left, right);
                old.advance(&g, left, right);
                assert_eq!(reckoning.pose(), old.pose());
                assert_eq!(reckoning.position_nm(), (old.x, old.y));
                assert_eq!(reckoning.heading_nrad(), old.heading);
            }
        }
    }
}

#[test]
fn the_speed_controller_is_unchanged_step_by_step() {
    let mut rng = Sweep(23);
    let gains = [
        PiGains::AMIRO,
        PiGains {
            max_duty: 6_000,
            ..PiGains::AMIRO
        },
    ];
    for gains in gains {
        for run in 0..2_000 {
            let mut new = WheelSpeedController::new(gains);
            let mut old = OldController::new(gains);
            // The firmware's limit (0.5 m/s) in most runs, any other now and then.
            let limit = if run % 4 == 0 {
                rng.range(-1_000, 20_000_000)
            } else {
                500_000
            };
            for _ in 0..200 {
                let target = rng.range(-1_000_000, 1_000_000);
                let measured = match rng.next() % 20 {
                    0 => rng.next() as i64 >> (rng.next() % 64),
                    1 => rng.range(-30_000_000, 30_000_000),
                    _ => rng.range(-700_000, 700_000),
                };
                let dt = match rng.next() % 20 {
                    0 => rng.next() as u32,
                    _ => rng.range(0, 50_000) as u32,
                };
                let limit = if rng.next().is_multiple_of(100) {
                    rng.next() as i64
                } else {
                    limit
                };
                assert_eq!(
                    new.update_limited(target, measured, dt, limit),
                    old.update_limited(target, measured, dt, limit),
                    "{target} {measured} {dt} {limit}"
                );
                assert_eq!(new.integral_duty(), old.integral / PER_DUTY);
            }
        }
    }
}

// ------------------------------------------------------------- the whole drive controller

/// `DriveController::update` as it was, from the formulas above.
struct OldDrive {
    config: DriveConfig,
    last_left: Option<u16>,
    last_right: Option<u16>,
    pose: OldPose,
    left: OldController,
    right: OldController,
    target: MotorCommand,
    last_command: Option<u64>,
    last_update: Option<u64>,
    window: Vec<(i32, i32, u32)>,
    velocity: Velocity,
    wheel_speeds: (i64, i64),
}

impl OldDrive {
    fn new(config: DriveConfig) -> Self {
        Self {
            config,
            last_left: None,
            last_right: None,
            pose: OldPose::default(),
            left: OldController::new(config.gains),
            right: OldController::new(config.gains),
            target: MotorCommand::STOP,
            last_command: None,
            last_update: None,
            window: Vec::new(),
            velocity: Velocity::default(),
            wheel_speeds: (0, 0),
        }
    }

    fn delta(last: &mut Option<u16>, count: u16) -> i32 {
        let delta = last.map_or(0, |last| i32::from(count.wrapping_sub(last) as i16));
        *last = Some(count);
        delta
    }

    fn update(&mut self, now: u64, left_count: u16, right_count: u16) -> (Duty, Duty, bool) {
        let g = self.config.geometry;
        let left_ticks = Self::delta(&mut self.last_left, left_count);
        let right_ticks = Self::delta(&mut self.last_right, right_count);
        let dt = self.last_update.map_or(0, |p| now.saturating_sub(p));
        self.last_update = Some(now);
        self.pose.advance(&g, left_ticks, right_ticks);
        if dt > 0 {
            let capacity = usize::from(self.config.velocity_window).clamp(1, 8);
            self.window.push((
                left_ticks,
                right_ticks,
                u32::try_from(dt).unwrap_or(u32::MAX),
            ));
            if self.window.len() > capacity {
                self.window.remove(0);
            }
            let left: i64 = self.window.iter().map(|s| i64::from(s.0)).sum();
            let right: i64 = self.window.iter().map(|s| i64::from(s.1)).sum();
            let dt: i64 = self.window.iter().map(|s| i64::from(s.2)).sum();
            let clamp = |v: i64| v.clamp(i32::MIN.into(), i32::MAX.into()) as i32;
            let (l, r, d, rot) = old_step(&g, clamp(left), clamp(right));
            let per_second = |value: i64| value.saturating_mul(1000) / dt;
            self.wheel_speeds = (per_second(l), per_second(r));
            self.velocity = Velocity {
                velocity_um_s: clamp(per_second(d)),
                angular_urad_s: clamp(per_second(rot)),
            };
        }
        let commanded = self
            .last_command
            .is_some_and(|at| now.saturating_sub(at) <= self.config.command_timeout_us);
        if commanded {
            let (left, right) =
                old_wheel_speeds(&g, self.target.velocity_um_s, self.target.angular_urad_s);
            let limit = i64::from(self.config.max_wheel_speed_um_s.max(0));
            let largest = left.abs().max(right.abs());
            let (left, right) = if largest > limit {
                (left * limit / largest, right * limit / largest)
            } else {
                (left, right)
            };
            let step = u32::try_from(dt)
                .unwrap_or(u32::MAX)
                .min(self.config.max_step_us);
            let (lm, rm) = self.wheel_speeds;
            (
                self.left.update_limited(left, lm, step, limit),
                self.right.update_limited(right, rm, step, limit),
                true,
            )
        } else {
            self.target = MotorCommand::STOP;
            self.last_command = None;
            self.left.reset();
            self.right.reset();
            (Duty::ZERO, Duty::ZERO, false)
        }
    }
}

#[test]
fn the_drive_controller_is_unchanged_along_random_runs() {
    let mut rng = Sweep(29);
    let configs = [
        DriveConfig::AMIRO,
        DriveConfig {
            geometry: DriveGeometry {
                axle_width_um: DriveGeometry::AXLE_WIDTH_1X_UM,
                ..DriveGeometry::AMIRO
            },
            velocity_window: 8,
            max_wheel_speed_um_s: 300_000,
            ..DriveConfig::AMIRO
        },
    ];
    for config in configs {
        for _ in 0..300 {
            let mut new = DriveController::new(config);
            let mut old = OldDrive::new(config);
            let (mut now, mut left, mut right) = (0u64, 0u16, 0u16);
            for _ in 0..300 {
                if rng.next().is_multiple_of(10) {
                    // Any command the wire can carry, or one near the speed limit.
                    let command = if rng.next().is_multiple_of(2) {
                        MotorCommand {
                            velocity_um_s: rng.next() as i32,
                            angular_urad_s: rng.next() as i32,
                        }
                    } else {
                        MotorCommand {
                            velocity_um_s: rng.range(-600_000, 600_000) as i32,
                            angular_urad_s: rng.range(-15_000_000, 15_000_000) as i32,
                        }
                    };
                    new.set_target(command, now);
                    old.target = command;
                    old.last_command = Some(now);
                }
                // 10 ms steps with jitter, now and then a late one or a repeated instant.
                now += match rng.next() % 40 {
                    0 => 0,
                    1 => rng.range(0, 2_000_000) as u64,
                    _ => rng.range(9_000, 11_000) as u64,
                };
                let span = if rng.next().is_multiple_of(30) {
                    32_767
                } else {
                    90
                };
                left = left.wrapping_add(rng.range(-span, span) as u16);
                right = right.wrapping_add(rng.range(-span, span) as u16);
                let output = new.update(now, left, right);
                let (duty_left, duty_right, enabled) = old.update(now, left, right);
                assert_eq!(
                    (output.duty_left, output.duty_right, output.motors_enabled),
                    (duty_left, duty_right, enabled)
                );
                assert_eq!(new.pose(), old.pose.pose());
                assert_eq!(new.velocity(), old.velocity);
                assert_eq!(new.wheel_speeds_um_s(), old.wheel_speeds);
            }
        }
    }
}
