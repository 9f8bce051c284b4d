//! A dead sensor is noticed (issue 12): a stuck MISO or data line, a part that stopped answering
//! its identity, an I2C part that NACKs. The drivers return a typed error instead of the stuck
//! bytes as data, the suite groups check identities periodically, and `Supervised` counts the
//! faults, stops publishing and retries with back-off (1 s → 2 → 4 → 8 s).

use amiro_can::Topic;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::hmc5883l::Hmc5883l;
use amiro_sensors::drivers::l3g4200d::L3g4200d;
use amiro_sensors::drivers::suite::{
    Compass, Device, InertialSensors, InitStep, SampleError, SensorGroup, Supervised,
    FAILURES_BEFORE_RETRY, INERTIAL_PART_SET_UP_STEPS, INERTIAL_SET_UP_STEPS, RETRY_FIRST_US,
    RETRY_MAX_US,
};
use amiro_sensors::drivers::vcnl4020::Vcnl4020;
use amiro_sensors::drivers::{Error, IDENTITY_CHECK_EVERY};
use amiro_sensors::sim::*;
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cT};
use embedded_hal_mock::eh1::spi::Mock as SpiMock;

mod common;
use common::read_tx;

fn inertial() -> InertialSensors<SimGyroscope, SimAccelerometer> {
    let mut group = InertialSensors::new(SimGyroscope::new(), SimAccelerometer::new());
    group.init().unwrap();
    group
}

#[test]
fn a_gyroscope_with_miso_stuck_low_or_high_is_an_error_not_zero_data() {
    for level in [0x00, 0xFF] {
        let mut group = inertial();
        group.sample(Topic::Gyroscope, 0).unwrap();
        group.gyroscope.bus_mut().set_stuck_miso(Some(level));
        assert_eq!(
            group.sample(Topic::Gyroscope, 10_000),
            Err(SampleError::Device {
                device: Device::Gyroscope,
                error: Error::WrongIdentity {
                    expected: 0xD3,
                    found: level.into()
                },
            }),
            "MISO stuck at {level:#04x}"
        );
        // The accelerometer on its own chip select is unaffected.
        assert!(group.sample(Topic::Accelerometer, 10_000).is_ok());
    }
}

#[test]
fn an_accelerometer_with_miso_stuck_low_is_an_error() {
    let mut group = inertial();
    group.accelerometer.bus_mut().set_stuck_miso(Some(0x00));
    assert!(matches!(
        group.sample(Topic::Accelerometer, 0),
        Err(SampleError::Device {
            device: Device::Accelerometer,
            error: Error::WrongIdentity { found: 0, .. }
        })
    ));
}

/// A line stuck at a plausible level (0x5A5A… reads as valid numbers) is caught by the periodic
/// identity check, within `IDENTITY_CHECK_EVERY` samples.
#[test]
fn a_plausible_stuck_pattern_is_caught_by_the_periodic_identity_check() {
    let mut group = inertial();
    group.gyroscope.bus_mut().set_stuck_miso(Some(0x5A));
    let failed_at = (0..2 * u32::from(IDENTITY_CHECK_EVERY)).position(|n| {
        group
            .sample(Topic::Gyroscope, u64::from(n) * 2_000)
            .is_err()
    });
    assert!(
        failed_at.is_some_and(|n| n < usize::from(IDENTITY_CHECK_EVERY)),
        "{failed_at:?}"
    );
}

/// Each part's identity is checked over its own topic's samples: a plausible stuck line on the
/// accelerometer is caught within `IDENTITY_CHECK_EVERY` accelerometer samples however often the
/// gyroscope is sampled between them, and never fails a gyroscope sample.
#[test]
fn each_part_is_checked_over_its_own_samples_and_fails_only_its_own_topic() {
    let mut group = inertial();
    group.accelerometer.bus_mut().set_stuck_miso(Some(0x5A));
    let mut failed_at = None;
    for n in 0..2 * u32::from(IDENTITY_CHECK_EVERY) {
        for k in 0..3 {
            let t = u64::from(n * 4 + k) * 1_000;
            assert!(
                group.sample(Topic::Gyroscope, t).is_ok(),
                "gyroscope at {t}"
            );
        }
        let t = u64::from(n * 4 + 3) * 1_000;
        if group.sample(Topic::Accelerometer, t).is_err() {
            failed_at = Some(n);
            break;
        }
    }
    assert!(
        failed_at.is_some_and(|n| n < u32::from(IDENTITY_CHECK_EVERY)),
        "{failed_at:?}"
    );
}

/// The periodic check and the reading in one: a reading of all zeros right after a passed identity
/// check is taken as it is (two accesses, not three).
#[test]
fn a_zero_reading_right_after_the_periodic_check_is_not_checked_again() {
    let mut script = read_tx(0x8F, &[0xD3]);
    script.extend(read_tx(0xE8, &[0; 6]));
    let mut spi = SpiMock::new(&script);
    let mut gyro = L3g4200d::new(spi.clone());
    assert_eq!(
        gyro.read_after_identity_check()
            .map(|r| r.millidegrees_per_s),
        Ok([0, 0, 0])
    );
    spi.done();
}

#[test]
fn a_real_zero_reading_passes_after_the_identity_check() {
    // A gyroscope at rest that reads exactly zero: the driver checks WHO_AM_I and returns it.
    let mut script = read_tx(0xE8, &[0; 6]);
    script.extend(read_tx(0x8F, &[0xD3]));
    let mut spi = SpiMock::new(&script);
    let mut gyro = L3g4200d::new(spi.clone());
    assert_eq!(gyro.read_raw(), Ok([0, 0, 0]));
    spi.done();
}

#[test]
fn a_magnetometer_reading_all_ones_with_a_wrong_identity_is_an_error() {
    let mut i2c = I2cMock::new(&[
        I2cT::write_read(0x1E, vec![0x03], vec![0xFF; 6]),
        I2cT::write_read(0x1E, vec![0x0A], vec![0xFF; 3]),
    ]);
    let mut compass = Hmc5883l::new(i2c.clone());
    assert_eq!(
        compass.read_raw(),
        Err(Error::WrongIdentity {
            expected: 0x48_3433,
            found: 0xFF_FFFF
        })
    );
    i2c.done();
}

#[test]
fn a_proximity_sensor_reading_zero_with_a_wrong_identity_is_an_error() {
    let mut i2c = I2cMock::new(&[
        I2cT::write_read(0x13, vec![0x87], vec![0, 0]),
        I2cT::write_read(0x13, vec![0x81], vec![0]),
    ]);
    let mut vcnl = Vcnl4020::new(i2c.clone());
    assert_eq!(
        vcnl.read_proximity(),
        Err(Error::WrongIdentity {
            expected: 0x21,
            found: 0
        })
    );
    i2c.done();
}

#[test]
fn a_fuel_gauge_reading_zero_kelvin_at_zero_volts_is_checked() {
    use amiro_sensors::drivers::bq27500::Bq27500;
    // Temperature 0, voltage 0, then the DEVICE_TYPE check answers all zeros too.
    let mut i2c = I2cMock::new(&[
        I2cT::write_read(0x55, vec![0x06], vec![0, 0]),
        I2cT::write_read(0x55, vec![0x08], vec![0, 0]),
        I2cT::write(0x55, vec![0x00, 0x01]),
        I2cT::write(0x55, vec![0x01, 0x00]),
        I2cT::write_read(0x55, vec![0x00], vec![0, 0]),
    ]);
    let mut gauge = Bq27500::new(i2c.clone(), NoDelay);
    assert_eq!(
        gauge.read_status().map(|_| ()),
        Err(Error::WrongIdentity {
            expected: 0x0500,
            found: 0
        })
    );
    i2c.done();
}

#[test]
fn floor_sensors_whose_bus_stops_acknowledging_fail_and_the_periodic_check_reads_every_id() {
    let mut floor = FloorSensors::new(SimFloorBus::new());
    SensorGroup::init(&mut floor).unwrap();
    for n in 0..u64::from(IDENTITY_CHECK_EVERY) + 1 {
        SensorGroup::sample(&mut floor, Topic::FloorProximity, n * 62_500).unwrap();
    }
    floor.mux_mut().bus_mut().set_nack(true);
    assert!(matches!(
        SensorGroup::sample(&mut floor, Topic::FloorProximity, 0),
        Err(SampleError::Device {
            device: Device::FloorSensor(0),
            error: Error::Bus(_)
        })
    ));
}

/// `Supervised`: a gyroscope whose MISO sticks stops publishing, is counted, and is retried
/// after 1, 2, 4, 8, 8 s; once repaired it publishes again and the wait is back to 1 s.
#[test]
fn a_dead_group_stops_publishing_is_counted_and_retried_with_back_off() {
    let mut group = Supervised::new(inertial());
    assert!(group.is_ready());
    assert_eq!(group.sample(Topic::Gyroscope, 0).len(), 1);
    group
        .group_mut()
        .gyroscope
        .bus_mut()
        .set_stuck_miso(Some(0x00));
    // Three failed samples in a row (one every 2 ms): nothing published, then missing.
    for n in 1..=3u64 {
        assert!(group.sample(Topic::Gyroscope, n * 2_000).is_empty());
    }
    assert!(!group.is_ready());
    assert_eq!(group.faults(), 3);
    let mut now = 6_000;
    let mut attempts = Vec::new();
    // Sample every 2 ms for 30 s: record when a (failing) re-initialisation happened.
    while now < 30_000_000 {
        now += 2_000;
        let before = group.faults();
        assert!(group.sample(Topic::Gyroscope, now).is_empty());
        if group.faults() != before {
            attempts.push(now);
        }
    }
    let waits: Vec<u64> = std::iter::once(6_000)
        .chain(attempts.iter().copied())
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| (w[1] - w[0]).div_ceil(1_000_000) * 1_000_000)
        .collect();
    assert_eq!(
        waits,
        [
            RETRY_FIRST_US,
            2 * RETRY_FIRST_US,
            4 * RETRY_FIRST_US,
            RETRY_MAX_US,
            RETRY_MAX_US
        ]
    );
    assert_eq!(group.faults(), 3 + 5);
    assert!(matches!(
        group.last_error(),
        Some(SampleError::Device {
            device: Device::Gyroscope,
            ..
        })
    ));
    // Repaired: the next attempt brings the gyroscope alone back in three steps, one access each
    // (its identity checked, its configuration written, then read back), each release a step
    // alone, and the release after the last publishes again. The accelerometer stayed in service.
    assert!(group.is_part_ready(1));
    group.group_mut().gyroscope.bus_mut().set_stuck_miso(None);
    let back = group.retry_at_us();
    for step in 0..u64::from(INERTIAL_PART_SET_UP_STEPS) - 1 {
        let now = back + step * 2_000;
        assert!(group.sample(Topic::Gyroscope, now).is_empty());
        assert!(!group.is_ready(), "still missing after set-up step {step}");
        assert_eq!(group.retry_at_us(), now, "the next step at the next sample");
    }
    let last = back + (u64::from(INERTIAL_PART_SET_UP_STEPS) - 1) * 2_000;
    assert!(group.sample(Topic::Gyroscope, last).is_empty());
    assert!(group.is_ready());
    assert_eq!(group.sample(Topic::Gyroscope, last + 2_000).len(), 1);
    // Not served topics are no fault.
    assert!(group.sample(Topic::PowerStatus, back).is_empty());
    assert_eq!(group.faults(), 8);
}

#[test]
fn a_compass_that_nacks_from_now_on_is_counted_and_taken_out() {
    let mut compass = Compass::new(SimCompassBus::new());
    compass.set_reuse_window_us(0);
    let mut group = Supervised::new(compass);
    assert_eq!(group.sample(Topic::MagnetometerX, 0).len(), 1);
    group.group_mut().magnetometer.bus_mut().set_nack(true);
    for n in 1..=3 {
        assert!(group.sample(Topic::MagnetometerY, n * 1_000).is_empty());
    }
    assert!(!group.is_ready());
    assert_eq!(group.faults(), 3);
    group.group_mut().magnetometer.bus_mut().set_nack(false);
    assert!(group.sample(Topic::MagnetometerZ, 1_000_000).is_empty());
    // The retry's release sets the part up (one step) and answers nothing; the next samples it.
    assert!(group
        .sample(Topic::MagnetometerZ, 3_000 + RETRY_FIRST_US)
        .is_empty());
    assert!(group.is_ready());
    assert_eq!(
        group
            .sample(Topic::MagnetometerZ, 4_000 + RETRY_FIRST_US)
            .len(),
        1
    );
}

/// The SPI pair through `Supervised`, sampled as two publishers would: `gyroscope_every_us` and
/// `accelerometer_every_us` apart (the gyroscope first where both fall due), from `from_us` until
/// `until_us`. Returns the frames each topic published.
fn run_pair(
    group: &mut Supervised<InertialSensors<SimGyroscope, SimAccelerometer>>,
    from_us: u64,
    until_us: u64,
    gyroscope_every_us: u64,
    accelerometer_every_us: u64,
) -> (usize, usize) {
    let step = 1_000;
    let (mut gyroscope, mut accelerometer) = (0, 0);
    let mut now = from_us;
    while now < until_us {
        if (now - from_us).is_multiple_of(gyroscope_every_us) {
            gyroscope += group.sample(Topic::Gyroscope, now).len();
        }
        if (now - from_us).is_multiple_of(accelerometer_every_us) {
            accelerometer += group.sample(Topic::Accelerometer, now).len();
        }
        now += step;
    }
    (gyroscope, accelerometer)
}

/// The waits between a part's failed re-initialisations, rounded up to whole seconds, as
/// `Supervised` counts them in `faults`: 1, 2, 4, 8 s in a 20 s run.
const RETRIES_IN_20_S: u32 = 4;

/// Review finding (a): an accelerometer whose MISO sticks high, sampled every 5 ms, beside a
/// gyroscope sampled every 20 ms. The accelerometer is taken out and retried with back-off on
/// its own; every gyroscope sample publishes, before and after, and no retry of the
/// accelerometer costs the gyroscope a frame.
#[test]
fn a_dead_accelerometer_sampled_more_often_never_stops_the_gyroscope() {
    let mut group = Supervised::new(inertial());
    assert_eq!(run_pair(&mut group, 0, 100_000, 20_000, 5_000), (5, 20));
    group
        .group_mut()
        .accelerometer
        .bus_mut()
        .set_stuck_miso(Some(0xFF));
    let (gyroscope, accelerometer) = run_pair(&mut group, 100_000, 20_100_000, 20_000, 5_000);
    assert_eq!(gyroscope, 1_000, "every gyroscope sample of 20 s publishes");
    assert_eq!(accelerometer, 0);
    assert!(!group.is_ready(), "the group reports a sensor fault now");
    assert_eq!(
        group.faults(),
        u32::from(FAILURES_BEFORE_RETRY) + RETRIES_IN_20_S,
        "three failed samples, then one failed identity check per retry"
    );
    // Repaired: the accelerometer comes back within its wait (8 s) and its three steps.
    group
        .group_mut()
        .accelerometer
        .bus_mut()
        .set_stuck_miso(None);
    let (gyroscope, accelerometer) = run_pair(&mut group, 20_100_000, 29_100_000, 20_000, 5_000);
    assert_eq!(gyroscope, 450);
    assert!(accelerometer > 0);
    assert!(group.is_ready());
}

/// Review finding (b): the same fault with the gyroscope sampled every 10 ms and the accelerometer
/// every 20 ms. The gyroscope's successes do not keep the accelerometer in service: after its
/// third failure in a row it is out (the "sensor fault now" flag set), retried with back-off (one
/// fault per retry, not one per sample), and publishes again once repaired.
#[test]
fn a_dead_accelerometer_sampled_less_often_is_taken_out_and_retried() {
    let mut group = Supervised::new(inertial());
    group
        .group_mut()
        .accelerometer
        .bus_mut()
        .set_stuck_miso(Some(0xFF));
    let (gyroscope, accelerometer) = run_pair(&mut group, 0, 60_000, 10_000, 20_000);
    assert_eq!((gyroscope, accelerometer), (6, 0));
    assert!(!group.is_ready(), "out after its third failed sample");
    let (gyroscope, accelerometer) = run_pair(&mut group, 60_000, 20_060_000, 10_000, 20_000);
    assert_eq!(gyroscope, 2_000);
    assert_eq!(accelerometer, 0);
    assert_eq!(
        group.faults(),
        u32::from(FAILURES_BEFORE_RETRY) + RETRIES_IN_20_S
    );
    assert!(matches!(
        group.last_error(),
        Some(SampleError::Device {
            device: Device::Accelerometer,
            ..
        })
    ));
    group
        .group_mut()
        .accelerometer
        .bus_mut()
        .set_stuck_miso(None);
    let (gyroscope, accelerometer) = run_pair(&mut group, 20_060_000, 29_060_000, 10_000, 20_000);
    assert_eq!(gyroscope, 900);
    assert!(accelerometer > 0, "re-initialised and publishing");
    assert!(group.is_ready());
}

/// A part dead at boot leaves the other part's topic working from its first sample, and joins
/// when it answers again.
#[test]
fn a_part_dead_at_boot_leaves_the_other_publishing() {
    for dead_gyroscope in [false, true] {
        let mut parts = InertialSensors::new(SimGyroscope::new(), SimAccelerometer::new());
        if dead_gyroscope {
            parts.gyroscope.bus_mut().set_stuck_miso(Some(0x00));
        } else {
            parts.accelerometer.bus_mut().set_stuck_miso(Some(0x00));
        }
        let mut group = Supervised::new(parts);
        assert!(!group.is_ready());
        assert_eq!(group.faults(), 1, "the dead part's set-up failed");
        let (gyroscope, accelerometer) = run_pair(&mut group, 0, 5_000_000, 10_000, 10_000);
        let (dead, alive) = if dead_gyroscope {
            (gyroscope, accelerometer)
        } else {
            (accelerometer, gyroscope)
        };
        assert_eq!((dead, alive), (0, 500), "dead gyroscope: {dead_gyroscope}");
        if dead_gyroscope {
            group.group_mut().gyroscope.bus_mut().set_stuck_miso(None);
        } else {
            group
                .group_mut()
                .accelerometer
                .bus_mut()
                .set_stuck_miso(None);
        }
        let (gyroscope, accelerometer) =
            run_pair(&mut group, 5_000_000, 15_000_000, 10_000, 10_000);
        assert!(gyroscope > 0 && accelerometer > 0);
        assert!(group.is_ready());
    }
}

/// The whole pair's stepwise set-up (as `DiWheelDriveSensors` runs it): the gyroscope's three
/// steps, then the accelerometer's; a failed step starts it again from the gyroscope.
#[test]
fn the_whole_pair_sets_up_in_six_steps_and_starts_again_after_a_failure() {
    let mut group = InertialSensors::new(SimGyroscope::new(), SimAccelerometer::new());
    group.accelerometer.bus_mut().set_stuck_miso(Some(0xFF));
    for step in 0..INERTIAL_PART_SET_UP_STEPS {
        assert_eq!(
            group.init_step(u64::from(step)),
            InitStep::Pending {
                next_us: u64::from(step)
            }
        );
    }
    assert!(matches!(
        group.init_step(3),
        InitStep::Failed(SampleError::Device {
            device: Device::Accelerometer,
            ..
        })
    ));
    group.accelerometer.bus_mut().set_stuck_miso(None);
    for _ in 0..INERTIAL_SET_UP_STEPS - 1 {
        assert!(matches!(group.init_step(10), InitStep::Pending { .. }));
    }
    assert_eq!(group.init_step(10), InitStep::Done);
    assert!(group.gyroscope.bus_mut().is_configured_for_amiro());
    assert!(group.accelerometer.bus_mut().is_configured_for_amiro());
}
