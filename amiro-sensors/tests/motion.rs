//! Host tests of the motion math: trigonometry, odometry, the wheel speed controller, and the
//! drive controller closed around the simulated wheel plant.

use amiro_can::{MotorCommand, SensorData, Topic};
use amiro_sensors::motion::odometry::{DeadReckoning, DriveGeometry, EncoderTracker, Pose};
use amiro_sensors::motion::speed::{PiGains, WheelSpeedController};
use amiro_sensors::motion::trig::{self, sin_cos, wrap_half_turn, ONE, TURN_NRAD};
use amiro_sensors::motion::{DriveConfig, DriveController, Duty, MotorPwm};
use amiro_sensors::sim::{MotorModel, WheelPlant};
use proptest::prelude::*;

// ---------------------------------------------------------------- trigonometry

#[test]
fn sin_cos_matches_f64_to_a_few_parts_per_billion() {
    let mut worst = 0.0f64;
    for i in -20_000i64..=20_000 {
        let angle = i * 987_654; // covers ±3.1 turns in uneven steps
        let (s, c) = sin_cos(angle);
        let a = angle as f64 * 1e-9;
        let es = (s as f64 / ONE as f64 - a.sin()).abs();
        let ec = (c as f64 / ONE as f64 - a.cos()).abs();
        worst = worst.max(es).max(ec);
    }
    assert!(worst < 5e-9, "worst error {worst}");
}

#[test]
fn sin_cos_exact_points() {
    assert_eq!(sin_cos(0), (0, ONE));
    let (s, c) = sin_cos(trig::QUARTER_TURN_NRAD);
    assert!((s - ONE).abs() <= 2 && c.abs() <= 2);
    let (s, c) = sin_cos(-trig::QUARTER_TURN_NRAD);
    assert!((s + ONE).abs() <= 2 && c.abs() <= 2);
    assert_eq!(wrap_half_turn(TURN_NRAD + 5), 5);
    assert_eq!(wrap_half_turn(-5), -5);
}

proptest! {
    #[test]
    fn sin_squared_plus_cos_squared_is_one(angle in any::<i32>()) {
        let (s, c) = sin_cos(i64::from(angle) * 3);
        let norm = (s as i128 * s as i128 + c as i128 * c as i128) >> 30;
        prop_assert!((norm - ONE as i128).abs() < 16);
    }
}

// ---------------------------------------------------------------- odometry

#[test]
fn wheel_travel_per_tick_is_pi_d_over_1408() {
    let g = DriveGeometry::AMIRO;
    // π × 55.71 mm / 1408 = 124.3026… µm.
    assert_eq!(g.pm_per_tick(), 124_302_647);
    assert_eq!(g.ticks_to_nm(1408), 175_018_127); // one revolution, 175.018 mm
    assert_eq!(g.ticks_to_nm(-1), -124_303);
}

#[test]
fn straight_line_moves_along_x_only() {
    let mut odo = DeadReckoning::new(DriveGeometry::AMIRO);
    for _ in 0..100 {
        odo.advance(14, 14);
    }
    let pose = odo.pose();
    assert_eq!(pose.x_um, 174_024, "1400 ticks = 174.0237 mm");
    assert_eq!(pose.y_um, 0);
    assert_eq!(pose.heading_urad, 0);
}

#[test]
fn turning_on_the_spot_keeps_the_position() {
    let mut odo = DeadReckoning::new(DriveGeometry::AMIRO);
    // A full turn on the spot is π × 77 mm of wheel travel each way = 1946.06 ticks.
    for _ in 0..1946 {
        odo.advance(-1, 1);
    }
    let pose = odo.pose();
    assert_eq!((pose.x_um, pose.y_um), (0, 0));
    let full_turn_urad = 6_283_185;
    // 1946 whole ticks fall 0.06 tick (≈ 230 µrad) short of the turn.
    let error = (pose.heading_urad - full_turn_urad)
        .abs()
        .min(pose.heading_urad);
    assert!(error < 300, "heading {}", pose.heading_urad);
}

#[test]
fn quarter_circle_arc_ends_where_geometry_says() {
    // Left wheel stopped, right wheel drives: pivot about the left wheel, radius = axle / 2 for the
    // centre. A quarter turn takes (π/2 × 77 mm) / 124.302 µm = 973.03 right ticks.
    let mut odo = DeadReckoning::new(DriveGeometry::AMIRO);
    for _ in 0..973 {
        odo.advance(0, 1);
    }
    let pose = odo.pose();
    // Centre starts 38.5 mm right of the pivot and ends 38.5 mm ahead... of it: (38.5, 38.5) mm.
    assert!((pose.x_um - 38_500).abs() < 40, "x {}", pose.x_um);
    assert!((pose.y_um - 38_500).abs() < 40, "y {}", pose.y_um);
    assert!((pose.heading_urad - 1_570_796).abs() < 1_000);
}

#[test]
fn the_axle_width_is_a_configuration_field() {
    let narrow = DriveGeometry {
        axle_width_um: DriveGeometry::AXLE_WIDTH_1X_UM,
        ..DriveGeometry::AMIRO
    };
    let wide = DeadReckoning::new(DriveGeometry::AMIRO)
        .step(-10, 10)
        .rotation_nrad;
    let tight = DeadReckoning::new(narrow).step(-10, 10).rotation_nrad;
    // 2 × 1 243 026 nm of wheel travel over 77 mm.
    assert_eq!(wide, 32_286_389);
    assert!(tight > wide);
}

#[test]
fn encoder_tracker_handles_the_16_bit_wrap_and_inversion() {
    let mut t = EncoderTracker::new(false);
    assert_eq!(t.delta(65_530), 0, "first count only sets the reference");
    assert_eq!(t.delta(4), 10);
    assert_eq!(t.delta(65_535), -5);
    let mut inverted = EncoderTracker::new(true);
    inverted.delta(100);
    assert_eq!(inverted.delta(90), 10);
}

#[test]
fn set_pose_wraps_the_heading() {
    let mut odo = DeadReckoning::new(DriveGeometry::AMIRO);
    odo.set_pose(Pose {
        x_um: 5,
        y_um: -7,
        heading_urad: -1_570_796,
    });
    assert_eq!(odo.pose().heading_urad, 6_283_185 - 1_570_796);
    assert_eq!((odo.pose().x_um, odo.pose().y_um), (5, -7));
}

// ---------------------------------------------------------------- duty and PI

#[test]
fn duty_saturates_and_maps_to_a_timer_compare() {
    assert_eq!(Duty::saturating(12_345), Duty::MAX);
    assert_eq!(Duty::saturating(-99_999), Duty::MIN);
    assert_eq!(Duty::new(10_001), None);
    assert_eq!(Duty::new(-2_500).map(|d| d.compare(360)), Some(90));
    assert!(Duty::saturating(-1).is_reverse());
}

#[test]
fn pi_output_is_limited_and_the_integrator_does_not_wind_up() {
    let gains = PiGains {
        kff: 0,
        kp: 10_000,
        ki: 1_000_000,
        max_duty: 5_000,
    };
    let mut pi = WheelSpeedController::new(gains);
    // A stalled wheel for two seconds: P gives 2000, I adds 2000 per step, so from the second
    // step on the output sits at the limit (the integrator stopping at 3000).
    assert_eq!(pi.update(200_000, 0, 10_000).get(), 4_000);
    for _ in 0..200 {
        assert_eq!(pi.update(200_000, 0, 10_000), Duty::new(5_000).unwrap());
    }
    // The integral stopped growing once the output reached the limit.
    assert_eq!(pi.integral_duty(), 3_000);
    // The wheel overshoots: the output must leave saturation at once, not after unwinding.
    // P = -2000, I = 3000 - 2000: the output swings to -1000 in one step.
    let after = pi.update(200_000, 400_000, 10_000);
    assert_eq!(after.get(), -1_000);
}

#[test]
fn pi_integrates_a_steady_error_and_is_quiet_without_one() {
    let mut pi = WheelSpeedController::new(PiGains {
        kff: 0,
        kp: 0,
        ki: 100_000,
        max_duty: 10_000,
    });
    assert_eq!(pi.update(0, 0, 10_000), Duty::ZERO);
    // ki × error × t = 100 000 duty/m × 0.1 m/s × 0.5 s = 5000 duty after 50 steps of 10 ms.
    let mut last = Duty::ZERO;
    for _ in 0..50 {
        last = pi.update(100_000, 0, 10_000);
    }
    assert_eq!(last.get(), 5_000);
    pi.reset();
    assert_eq!(pi.integral_duty(), 0);
}

// ---------------------------------------------------------------- drive controller

/// Runs the controller against the plant at 100 Hz from `from_us` for `duration_us`, applying
/// each output as the firmware would. Returns the time reached.
fn run(drive: &mut DriveController, plant: &mut WheelPlant, from_us: u64, duration_us: u64) -> u64 {
    let mut t = from_us;
    while t < from_us + duration_us {
        t += 10_000;
        let (l, r) = plant.counts(t);
        let out = drive.update(t, l, r);
        plant.set_power(out.motors_enabled);
        plant.set_duty(out.duty_left, out.duty_right);
    }
    t
}

#[test]
fn drives_straight_at_the_commanded_speed() {
    let mut drive = DriveController::default();
    let mut plant = WheelPlant::new();
    let command = MotorCommand {
        velocity_um_s: 100_000,
        angular_urad_s: 0,
    };
    let mut t = 0;
    // Keep commanding every 100 ms (inside the dead-man window) for 2 s.
    for _ in 0..20 {
        drive.set_target(command, t);
        t = run(&mut drive, &mut plant, t, 100_000);
    }
    let v = drive.velocity();
    assert!((v.velocity_um_s - 100_000).abs() < 3_000, "velocity {v:?}");
    assert!(v.angular_urad_s.abs() < 20_000, "velocity {v:?}");
    // Travel: about 2 s × 0.1 m/s minus the start-up lag.
    let pose = drive.pose();
    assert!((170_000..=200_000).contains(&pose.x_um), "pose {pose:?}");
    assert!(pose.y_um.abs() < 2_000, "pose {pose:?}");
    // The plant agrees with the odometry (same geometry).
    assert!((plant.left.travel_um() - pose.x_um).abs() < 500);
}

#[test]
fn default_gains_step_response_against_the_plant() {
    let mut drive = DriveController::default();
    let mut plant = WheelPlant::new();
    let go = MotorCommand {
        velocity_um_s: 100_000,
        angular_urad_s: 0,
    };
    let (mut t, mut peak) = (0u64, 0i64);
    while t < 600_000 {
        if t % 100_000 == 0 {
            drive.set_target(go, t);
        }
        t = run(&mut drive, &mut plant, t, 10_000);
        let speed = plant.left.speed_um_s();
        peak = peak.max(speed);
        if t >= 150_000 {
            assert!((speed - 100_000).abs() <= 3_000, "{speed} µm/s at {t} µs");
        }
        if t == 50_000 {
            assert!(speed >= 95_000, "{speed} µm/s at 50 ms");
        }
    }
    assert!(peak < 115_000, "overshoot to {peak}");
}

#[test]
fn turns_at_the_commanded_rate() {
    let mut drive = DriveController::default();
    let mut plant = WheelPlant::new();
    let command = MotorCommand {
        velocity_um_s: 0,
        angular_urad_s: 1_000_000, // 1 rad/s counter-clockwise
    };
    let mut t = 0;
    for _ in 0..20 {
        drive.set_target(command, t);
        t = run(&mut drive, &mut plant, t, 100_000);
    }
    let v = drive.velocity();
    assert!(
        (v.angular_urad_s - 1_000_000).abs() < 40_000,
        "velocity {v:?}"
    );
    assert!(v.velocity_um_s.abs() < 2_000, "velocity {v:?}");
    let (left, right) = drive.wheel_speeds_um_s();
    assert!(left < 0 && right > 0);
    let pose = drive.pose();
    assert!(
        pose.x_um.abs() < 1_000 && pose.y_um.abs() < 1_000,
        "on the spot: {pose:?}"
    );
}

#[test]
fn a_weaker_motor_is_compensated() {
    let weak = MotorModel {
        speed_at_full_duty_um_s: 450_000,
        ..MotorModel::AMIRO
    };
    let mut plant = WheelPlant::with(DriveGeometry::AMIRO, MotorModel::AMIRO, weak);
    let mut drive = DriveController::default();
    let command = MotorCommand {
        velocity_um_s: 150_000,
        angular_urad_s: 0,
    };
    let mut t = 0;
    for _ in 0..30 {
        drive.set_target(command, t);
        t = run(&mut drive, &mut plant, t, 100_000);
    }
    let out = drive.output();
    assert!(out.duty_right.get() > out.duty_left.get(), "{out:?}");
    // Heading drifts only during the transient.
    let heading = wrap_half_turn(drive.pose().heading_urad * 1000) / 1000;
    assert!(heading.abs() < 60_000, "heading {heading} µrad");
}

#[test]
fn fast_commands_are_scaled_down_keeping_the_curvature() {
    let config = DriveConfig {
        max_wheel_speed_um_s: 200_000,
        ..DriveConfig::AMIRO
    };
    let mut drive = DriveController::new(config);
    let mut plant = WheelPlant::new();
    let command = MotorCommand {
        velocity_um_s: 400_000,
        angular_urad_s: 2_000_000,
    };
    let mut t = 0;
    for _ in 0..20 {
        drive.set_target(command, t);
        t = run(&mut drive, &mut plant, t, 100_000);
    }
    let (left, right) = drive.wheel_speeds_um_s();
    assert!(right <= 205_000 && right > 190_000, "right {right}");
    // Curvature ω / v = 5 /m kept: left / right = (400 - 77) / (400 + 77).
    let expected_left = 200_000 * 323 / 477;
    assert!((left - expected_left).abs() < 6_000, "left {left}");
}

#[test]
fn without_a_command_the_motors_stay_off() {
    let mut drive = DriveController::default();
    for t in 0..10 {
        let out = drive.update(t * 10_000, 0, 0);
        assert!(!out.motors_enabled);
        assert_eq!((out.duty_left, out.duty_right), (Duty::ZERO, Duty::ZERO));
        assert!(!out.deadman_tripped, "nothing was commanded, nothing trips");
    }
}

#[test]
fn deadman_stops_the_motors_500_ms_after_the_last_command_and_reports_it_once() {
    let mut drive = DriveController::default();
    let mut plant = WheelPlant::new();
    drive.set_target(
        MotorCommand {
            velocity_um_s: 100_000,
            angular_urad_s: 0,
        },
        0,
    );
    let mut trips = Vec::new();
    let mut t = 0;
    while t < 1_000_000 {
        t += 10_000;
        let (l, r) = plant.counts(t);
        let out = drive.update(t, l, r);
        plant.set_power(out.motors_enabled);
        plant.set_duty(out.duty_left, out.duty_right);
        if t <= 500_000 {
            assert!(out.motors_enabled, "still commanded at {t}");
        } else {
            assert!(!out.motors_enabled, "stopped at {t}");
            assert_eq!((out.duty_left, out.duty_right), (Duty::ZERO, Duty::ZERO));
        }
        if out.deadman_tripped {
            trips.push(t);
        }
    }
    assert_eq!(trips, vec![510_000]);
    assert_eq!(drive.target(), MotorCommand::STOP);
    // The wheels coast to a stop; odometry keeps counting.
    assert!(plant.left.speed_um_s().abs() < 1_000);
    assert!(drive.pose().x_um > 40_000);
}

#[test]
fn refreshed_commands_keep_driving_and_a_new_command_restarts_after_a_trip() {
    let config = DriveConfig {
        command_timeout_us: 200_000,
        ..DriveConfig::AMIRO
    };
    let mut drive = DriveController::new(config);
    let go = MotorCommand {
        velocity_um_s: 50_000,
        angular_urad_s: 0,
    };
    drive.set_target(go, 0);
    drive.update(0, 0, 0);
    drive.set_target(go, 150_000);
    assert!(
        drive.update(300_000, 0, 0).motors_enabled,
        "refreshed at 150 ms"
    );
    assert!(drive.update(360_000, 0, 0).deadman_tripped);
    assert!(!drive.update(370_000, 0, 0).deadman_tripped);
    drive.set_target(go, 400_000);
    assert!(drive.update(410_000, 0, 0).motors_enabled);
}

#[test]
fn stop_disables_without_a_deadman_report() {
    let mut drive = DriveController::default();
    drive.set_target(
        MotorCommand {
            velocity_um_s: 50_000,
            angular_urad_s: 0,
        },
        0,
    );
    assert!(drive.update(10_000, 0, 0).motors_enabled);
    drive.stop();
    let out = drive.update(20_000, 0, 0);
    assert!(!out.motors_enabled && !out.deadman_tripped);
}

#[test]
fn a_command_stamped_after_the_update_time_counts_as_fresh() {
    // The command handler may read the clock after the control task did.
    let mut drive = DriveController::default();
    drive.set_target(MotorCommand::STOP, 1_000);
    assert!(drive.update(900, 0, 0).motors_enabled);
}

#[test]
fn odometry_and_velocity_samples_are_in_protocol_units() {
    let mut drive = DriveController::default();
    drive.update(0, 0, 0);
    drive.update(10_000, 1408, 1408); // one revolution of both wheels in 10 ms
    match drive.sample(Topic::Odometry) {
        Some(SensorData::Odometry(o)) => {
            assert_eq!(o.x_100um(), 1750); // 175.02 mm
            assert_eq!(o.y_100um(), 0);
            assert_eq!(o.heading(), 0);
        }
        other => panic!("{other:?}"),
    }
    match drive.sample(Topic::Velocity) {
        Some(SensorData::Velocity(v)) => assert_eq!(v.velocity_um_s, 17_501_812),
        other => panic!("{other:?}"),
    }
    assert_eq!(drive.sample(Topic::Gyroscope), None);
}

#[test]
fn odometry_saturates_at_the_wire_range() {
    let mut drive = DriveController::default();
    drive.set_pose(Pose {
        x_um: 2_000_000_000,
        y_um: -2_000_000_000,
        heading_urad: 0,
    });
    let o = drive.odometry();
    assert_eq!(o.x_100um(), amiro_can::Odometry::MAX_100UM);
    assert_eq!(o.y_100um(), -amiro_can::Odometry::MAX_100UM);
}

#[test]
fn velocity_is_averaged_over_the_window() {
    let mut drive = DriveController::default(); // window 4
    drive.update(0, 0, 0);
    let mut count = 0u16;
    // Alternate 1 and 2 ticks per 10 ms: single steps would read 12.4 and 24.9 mm/s.
    for i in 1..=8u64 {
        count += if i % 2 == 0 { 2 } else { 1 };
        drive.update(i * 10_000, count, count);
    }
    // 6 ticks per 40 ms = 18.6 mm/s.
    assert_eq!(drive.velocity().velocity_um_s, 18_645);
}

proptest! {
    #[test]
    fn odometry_step_never_overflows(left in any::<i32>(), right in any::<i32>()) {
        let mut odo = DeadReckoning::new(DriveGeometry::AMIRO);
        let step = odo.advance(left, right);
        prop_assert_eq!(step.distance_nm, (step.left_nm + step.right_nm) / 2);
        prop_assert!(odo.heading_nrad() >= 0 && odo.heading_nrad() < TURN_NRAD);
    }
}

/// The wheel speed limit is a limit: whatever the command (the largest and smallest the wire
/// carries, full spins, full reversals), neither simulated wheel ever runs faster than
/// `max_wheel_speed_um_s`, measured on the plant itself every millisecond.
#[test]
fn extreme_commands_never_drive_a_wheel_past_the_speed_limit() {
    let limit = i64::from(DriveConfig::AMIRO.max_wheel_speed_um_s);
    let command = |velocity_um_s, angular_urad_s| MotorCommand {
        velocity_um_s,
        angular_urad_s,
    };
    // Each phase is held for 2 s (commands refreshed every 100 ms), back to back.
    let sequences: [&[MotorCommand]; 5] = [
        &[command(i32::MAX, 0)],
        &[
            command(i32::MIN, 0),
            command(i32::MAX, 0),
            command(i32::MIN, 0),
        ],
        &[command(0, i32::MAX), command(0, i32::MIN)],
        &[
            command(500_000, 0),
            command(-500_000, 0),
            command(500_000, 0),
        ],
        &[command(i32::MAX, i32::MAX), command(i32::MIN, i32::MIN)],
    ];
    let mut findings = Vec::new();
    for sequence in sequences {
        let mut drive = DriveController::default();
        let mut plant = WheelPlant::new();
        let mut t = 0u64;
        let mut peak = 0i64;
        for &phase in sequence {
            for _ in 0..200 {
                if t.is_multiple_of(100_000) {
                    drive.set_target(phase, t);
                }
                // 1 ms steps of the plant between 10 ms control updates.
                for _ in 0..10 {
                    t += 1_000;
                    plant.advance_to(t);
                    peak = peak
                        .max(plant.left.speed_um_s().abs())
                        .max(plant.right.speed_um_s().abs());
                }
                let (l, r) = plant.counts(t);
                let out = drive.update(t, l, r);
                plant.set_power(out.motors_enabled);
                plant.set_duty(out.duty_left, out.duty_right);
            }
        }
        // Over the limit, or kept far from it by crawling (it must get within 2 %).
        if peak > limit || peak < limit * 98 / 100 {
            findings.push(format!("{sequence:?}: peak {peak} µm/s"));
        }
    }
    assert!(findings.is_empty(), "limit {limit} µm/s: {findings:#?}");
}
