//! The BNO055 driver (DiWheelDrive 1-2): mock-transaction tests of its bus traffic, and the driver
//! and the board suite against the register-level simulator.

use amiro_can::{Axis as CanAxis, SensorData, Topic};
use amiro_sensors::drivers::bno055::{self, Bno055};
use amiro_sensors::drivers::suite::{
    BusFault, Device, ImuSensors, SampleError, SensorGroup, Supervised,
};
use amiro_sensors::drivers::Error;
use amiro_sensors::sim::*;
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as D};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as T};

const A: u8 = 0x28;
const IDS: [u8; 4] = [0xA0, 0xFB, 0x32, 0x0F];
/// What a part that is not there (or not yet booted) answers: no acknowledge of its address.
const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

/// A part found in configuration mode (OPR_MODE 0) where the driver set AMG (7): it reset.
const NOT_RUNNING: Error<ErrorKind> = Error::ConfigMismatch {
    register: 0x3D,
    expected: 0x07,
    found: 0x00,
};

/// `count` identity reads of `len` bytes that the part does not acknowledge.
fn unanswered_identity_reads(count: usize, len: usize) -> Vec<T> {
    vec![T::write_read(A, vec![0x00], vec![0; len]).with_error(NACK); count]
}

fn init_script(config_readback: [u8; 4], units: u8, mode: u8) -> Vec<T> {
    vec![
        T::write(A, vec![0x07, 0]),
        T::write_read(A, vec![0x00], IDS.to_vec()),
        T::write_read(A, vec![0x36], vec![0x0F]),
        T::write(A, vec![0x3D, 0x00]),
        T::write(A, vec![0x3E, 0x00]),
        T::write(A, vec![0x3B, 0x01]),
        T::write(A, vec![0x07, 1]),
        T::write(A, vec![0x08, 0x0E, 0x0F, 0x22, 0x00]),
        T::write_read(A, vec![0x08], config_readback.to_vec()),
        T::write(A, vec![0x07, 0]),
        T::write_read(A, vec![0x3B], vec![units]),
        T::write(A, vec![0x3D, 0x07]),
        T::write_read(A, vec![0x3D], vec![mode]),
    ]
}

#[test]
fn init_checks_identity_and_self_test_configures_page_1_and_starts_amg() {
    let mut i2c = I2cMock::new(&init_script([0x0E, 0x0F, 0x22, 0x00], 0x01, 0x07));
    // The datasheet's switching times: 19 ms into configuration mode, 7 ms out of it.
    let mut delay = CheckedDelay::new(&[D::delay_ms(19), D::delay_ms(7)]);
    Bno055::new(i2c.clone()).init(&mut delay).unwrap();
    i2c.done();
    delay.done();
}

#[test]
fn init_rejects_a_wrong_part() {
    let mut i2c = I2cMock::new(&[
        T::write(A, vec![0x07, 0]),
        T::write_read(A, vec![0x00], vec![0xA0, 0xFB, 0x32, 0x00]),
    ]);
    assert_eq!(
        Bno055::new(i2c.clone()).init(&mut NoopDelay::new()),
        Err(Error::WrongIdentity {
            expected: 0xA0FB_320F,
            found: 0xA0FB_3200
        })
    );
    i2c.done();
}

#[test]
fn init_rejects_a_failed_self_test() {
    let mut i2c = I2cMock::new(&[
        T::write(A, vec![0x07, 0]),
        T::write_read(A, vec![0x00], IDS.to_vec()),
        T::write_read(A, vec![0x36], vec![0x0B]),
    ]);
    assert_eq!(
        Bno055::new(i2c.clone()).init(&mut NoopDelay::new()),
        Err(Error::SelfTest { result: 0x0B })
    );
    i2c.done();
}

#[test]
fn init_reports_a_setting_the_part_did_not_take() {
    // The read-back is checked at once: the script ends there, the part left on page 1 (the
    // next set-up's first step selects page 0 before it reads the identities).
    let script = init_script([0x0E, 0x0F, 0x38, 0x00], 0x01, 0x07);
    let mut i2c = I2cMock::new(&script[..9]);
    assert_eq!(
        Bno055::new(i2c.clone()).init(&mut NoopDelay::new()),
        Err(Error::ConfigMismatch {
            register: 0x0A,
            expected: 0x22,
            found: 0x38
        })
    );
    i2c.done();
    // A mode that did not switch is caught too.
    let mut i2c = I2cMock::new(&init_script([0x0E, 0x0F, 0x22, 0x00], 0x01, 0x00));
    assert_eq!(
        Bno055::new(i2c.clone()).init(&mut NoopDelay::new()),
        Err(NOT_RUNNING)
    );
    i2c.done();
}

#[test]
fn an_absent_part_is_a_bus_error() {
    type Attempt = fn(&mut Bno055<I2cMock>) -> Result<(), Error<ErrorKind>>;
    let attempts: [(Vec<T>, Attempt); 2] = [
        // `init` stops at its first transfer, page 0's selection.
        (vec![T::write(A, vec![0x07, 0]).with_error(NACK)], |imu| {
            imu.init(&mut NoopDelay::new())
        }),
        // `wait_for_boot` is bounded and returns the last error.
        (unanswered_identity_reads(3, 1), |imu| {
            imu.wait_for_boot(&mut NoopDelay::new(), 20)
        }),
    ];
    for (script, attempt) in attempts {
        let mut i2c = I2cMock::new(&script);
        assert_eq!(
            attempt(&mut Bno055::new(i2c.clone())),
            Err(Error::Bus(NACK))
        );
        i2c.done();
    }
}

#[test]
fn burst_reads_convert_to_the_protocol_units() {
    // Gyroscope: 1/16 °/s, rounded to nearest: 160 → 10, −24 → −1.5 → −2, 7 → 0.4375 → 0.
    // Accelerometer: 1 mg per digit. Magnetometer: 1/16 µT = 62.5 nT per digit.
    let mut i2c = I2cMock::new(&[
        T::write_read(A, vec![0x14], vec![160, 0, 0xE8, 0xFF, 7, 0]),
        T::write_read(A, vec![0x08], vec![0x10, 0, 0xF6, 0xFF, 0xE8, 0x03]),
        T::write_read(A, vec![0x0E], vec![0x32, 0x01, 0x01, 0x00, 0x2E, 0xFD]),
    ]);
    let mut imu = Bno055::new(i2c.clone());
    assert_eq!(imu.read_gyroscope().unwrap(), [10, -2, 0]);
    assert_eq!(imu.read_accelerometer().unwrap(), [16, -10, 1000]);
    // 306 → 19 125 nT, 1 → 62.5 → 63 nT, −722 → −45 125 nT.
    assert_eq!(imu.read_magnetometer().unwrap(), [19_125, 63, -45_125]);
    i2c.done();
}

#[test]
fn one_burst_reads_all_nine_axes() {
    let mut data = vec![0u8; 18];
    data[4..6].copy_from_slice(&1000i16.to_le_bytes());
    data[6..8].copy_from_slice(&306i16.to_le_bytes());
    data[10..12].copy_from_slice(&(-722i16).to_le_bytes());
    data[12..14].copy_from_slice(&(-32i16).to_le_bytes());
    let mut i2c = I2cMock::new(&[T::write_read(A, vec![0x08], data)]);
    let motion = Bno055::new(i2c.clone()).read().unwrap();
    assert_eq!(motion.milli_g, [0, 0, 1000]);
    assert_eq!(motion.nanotesla, [19_125, 0, -45_125]);
    assert_eq!(motion.degrees_per_s, [-2, 0, 0]);
    i2c.done();
}

#[test]
fn a_dead_bus_pattern_is_checked_against_the_identity() {
    // All zeros: the driver asks the identity again; a part that answers keeps its data …
    let mut i2c = I2cMock::new(&[
        T::write_read(A, vec![0x14], vec![0; 6]),
        T::write_read(A, vec![0x00], IDS.to_vec()),
    ]);
    assert_eq!(Bno055::new(i2c.clone()).read_gyroscope().unwrap(), [0; 3]);
    i2c.done();
    // … a line stuck low does not.
    let mut i2c = I2cMock::new(&[
        T::write_read(A, vec![0x14], vec![0; 6]),
        T::write_read(A, vec![0x00], vec![0; 4]),
    ]);
    assert_eq!(
        Bno055::new(i2c.clone()).read_gyroscope(),
        Err(Error::WrongIdentity {
            expected: 0xA0FB_320F,
            found: 0
        })
    );
    i2c.done();
}

#[test]
fn wait_for_boot_polls_until_the_part_answers() {
    let mut script = unanswered_identity_reads(2, 1);
    script.push(T::write_read(A, vec![0x00], vec![0xA0]));
    let mut i2c = I2cMock::new(&script);
    let mut delay = CheckedDelay::new(&[D::delay_ms(10), D::delay_ms(10)]);
    Bno055::new(i2c.clone())
        .wait_for_boot(&mut delay, 800)
        .unwrap();
    i2c.done();
    delay.done();
    // A part that never answers: `an_absent_part_is_a_bus_error`.
}

#[test]
fn a_verified_read_checks_the_operating_mode_after_the_data() {
    let mut i2c = I2cMock::new(&[
        T::write_read(A, vec![0x14], vec![16, 0, 0, 0, 0, 0]),
        T::write_read(A, vec![0x3D], vec![0x07]),
        // A part that reset is back in configuration mode, its data zero.
        T::write_read(A, vec![0x14], vec![0; 6]),
        T::write_read(A, vec![0x3D], vec![0x00]),
    ]);
    let mut imu = Bno055::new(i2c.clone());
    assert_eq!(imu.read_verified(0x14).unwrap(), [16, 0, 0]);
    assert_eq!(imu.read_verified(0x14), Err(NOT_RUNNING));
    i2c.done();
}

// ---------------------------------------------------------------- simulator

#[test]
fn the_driver_configures_the_simulator() {
    let mut bus = SimImuBus::new();
    assert!(!bus.imu().is_configured_for_amiro());
    let mut imu = Bno055::new(&mut bus);
    imu.wait_for_boot(&mut NoDelay, 800).unwrap();
    imu.init(&mut NoDelay).unwrap();
    assert!(bus.imu().is_configured_for_amiro());
    assert_eq!(bus.imu().operating_mode(), bno055::mode::AMG);
}

#[test]
fn the_simulator_takes_sensor_settings_only_in_configuration_mode() {
    let mut bus = SimImuBus::new();
    use embedded_hal::i2c::I2c;
    bus.write(A, &[0x3D, 0x07]).unwrap(); // AMG first
    bus.write(A, &[0x07, 1]).unwrap();
    bus.write(A, &[0x0A, 0x22]).unwrap();
    assert_eq!(bus.imu().sensor_config()[2], 0x38, "ignored outside CONFIG");
    bus.write(A, &[0x07, 0]).unwrap();
    bus.write(A, &[0x3D, 0x00]).unwrap();
    bus.write(A, &[0x07, 1]).unwrap();
    bus.write(A, &[0x0A, 0x22]).unwrap();
    assert_eq!(bus.imu().sensor_config()[2], 0x22);
}

#[test]
fn the_simulated_robot_rests_level_in_bielefelds_field() {
    let mut bus = SimImuBus::new();
    let mut imu = Bno055::new(&mut bus);
    imu.init(&mut NoDelay).unwrap();
    for _ in 0..16 {
        let m = imu.read().unwrap();
        // Gravity on Z within a few mg, nothing on X and Y.
        assert!((m.milli_g[2] - 1000).abs() <= 2, "{m:?}");
        assert!(m.milli_g[0].abs() <= 2 && m.milli_g[1].abs() <= 2, "{m:?}");
        // At rest: below 1 °/s on every axis.
        assert!(m.degrees_per_s.iter().all(|r| r.abs() <= 1), "{m:?}");
        // The field: about 49 µT, 67° below the horizontal, pointing down (−Z).
        let [x, y, z] = m.nanotesla.map(f64::from);
        let total = (x * x + y * y + z * z).sqrt();
        let horizontal = (x * x + y * y).sqrt();
        let inclination = (-z).atan2(horizontal).to_degrees();
        assert!((total - 49_000.0).abs() < 500.0, "total {total} nT");
        assert!(
            (inclination - 67.0).abs() < 1.0,
            "inclination {inclination}°"
        );
    }
}

#[test]
fn the_simulator_encodes_with_the_datasheet_lsb() {
    let mut bus = SimImuBus::new();
    Bno055::new(&mut bus).init(&mut NoDelay).unwrap();
    let raw = Bno055::new(&mut bus).read_raw().unwrap();
    let (accel, field, rate) = SimBno055::physical_at(0);
    // 1 mg, 1/16 µT, 1/16 °/s per digit.
    assert_eq!(raw.accelerometer.map(i32::from), accel);
    for (digits, nanotesla) in raw.magnetometer.into_iter().zip(field) {
        assert_eq!(i32::from(digits), (nanotesla * 16 + 500).div_euclid(1000));
    }
    assert_eq!(raw.gyroscope.map(i32::from), rate);
    // Without UNIT_SEL's mg bit the accelerometer reads 0.01 m/s² per digit: 1 g = 981.
    let mut bus = SimImuBus::new();
    use embedded_hal::i2c::I2c;
    bus.write(A, &[0x3D, 0x07]).unwrap();
    let raw = Bno055::new(&mut bus).read_raw().unwrap();
    assert_eq!(raw.accelerometer[2], 981);
}

#[test]
fn the_simulator_reads_zero_in_configuration_mode() {
    let mut bus = SimImuBus::new();
    let raw = {
        use embedded_hal::i2c::I2c;
        let mut out = [0xAAu8; 18];
        bus.write_read(A, &[0x08], &mut out).unwrap();
        out
    };
    assert_eq!(raw, [0; 18]);
}

#[test]
fn an_absent_or_failing_simulated_part_is_reported() {
    let mut bus = SimImuBus::new();
    bus.imu_mut().set_fault(Bno055Fault::Absent);
    assert!(matches!(
        Bno055::new(&mut bus).init(&mut NoDelay),
        Err(Error::Bus(NoAcknowledge { address: 0x28 }))
    ));
    let mut bus = SimImuBus::new();
    bus.imu_mut().set_fault(Bno055Fault::StuckLow);
    assert!(matches!(
        Bno055::new(&mut bus).init(&mut NoDelay),
        Err(Error::WrongIdentity { found: 0, .. })
    ));
    let mut bus = SimImuBus::new();
    bus.imu_mut().set_fault(Bno055Fault::SelfTestFailed);
    assert_eq!(
        Bno055::new(&mut bus).init(&mut NoDelay),
        Err(Error::SelfTest { result: 0x0B })
    );
}

// ---------------------------------------------------------------- board suite

#[test]
fn the_suite_publishes_the_1_1_topics_in_the_1_1_units() {
    let mut group = ImuSensors::new(SimImuBus::new(), NoDelay);
    group.wait_for_boot(800).unwrap();
    group.init().unwrap();
    let gyro = group.sample(Topic::Gyroscope, 0).unwrap();
    assert!(matches!(gyro[..], [SensorData::Gyroscope(r)] if r.iter().all(|v| v.abs() <= 1)));
    let accel = group.sample(Topic::Accelerometer, 0).unwrap();
    assert!(matches!(accel[..], [SensorData::Accelerometer([x, y, z])]
        if x.abs() <= 2 && y.abs() <= 2 && (998..=1002).contains(&z)));
    let mut field = [0i32; 3];
    for (topic, axis) in [
        (Topic::MagnetometerX, CanAxis::X),
        (Topic::MagnetometerY, CanAxis::Y),
        (Topic::MagnetometerZ, CanAxis::Z),
    ] {
        let s = group.sample(topic, 1_000).unwrap();
        match s[..] {
            [SensorData::Magnetometer { axis: a, nanotesla }] => {
                assert_eq!(a, axis);
                field[axis as usize] = nanotesla;
            }
            ref other => panic!("{other:?}"),
        }
    }
    assert!((18_000..20_500).contains(&field[0]), "{field:?}");
    assert!(field[1].abs() < 200, "{field:?}");
    assert!((-46_500..-44_000).contains(&field[2]), "{field:?}");
    assert_eq!(
        group.sample(Topic::FloorProximity, 0),
        Err(SampleError::NotServed(Topic::FloorProximity))
    );
}

#[test]
fn the_three_magnetometer_axes_share_one_burst() {
    let mut group = ImuSensors::new(SimImuBus::new(), NoDelay);
    group.init().unwrap();
    let before = group.imu.bus_mut().imu().samples();
    for topic in [
        Topic::MagnetometerX,
        Topic::MagnetometerY,
        Topic::MagnetometerZ,
    ] {
        group.sample(topic, 5_000).unwrap();
    }
    assert_eq!(group.imu.bus_mut().imu().samples(), before + 1);
    // The same axis again reads the part again.
    group.sample(Topic::MagnetometerX, 6_000).unwrap();
    assert_eq!(group.imu.bus_mut().imu().samples(), before + 2);
}

#[test]
fn a_dead_bno055_stops_its_topics_and_is_counted() {
    let mut bus = SimImuBus::new();
    bus.imu_mut().set_fault(Bno055Fault::Absent);
    let mut group = Supervised::new(ImuSensors::new(bus, NoDelay));
    assert!(!group.is_ready());
    assert_eq!(group.faults(), 1);
    assert!(matches!(
        group.last_error(),
        Some(SampleError::Device {
            device: Device::Imu,
            error: Error::Bus(BusFault::I2c(_))
        })
    ));
    assert!(group.sample(Topic::Gyroscope, 10_000).is_empty());
    // A part that dies while running: three failed samples, then it is missing and retried.
    let mut group = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    assert!(group.is_ready());
    assert_eq!(group.sample(Topic::Gyroscope, 0).len(), 1);
    group.group_mut().imu.bus_mut().set_nack(true);
    for t in 1..=3 {
        assert!(group.sample(Topic::Gyroscope, t * 10_000).is_empty());
    }
    assert!(!group.is_ready());
    assert_eq!(group.faults(), 3);
    // It comes back: the retry after the back-off initialises it again in six steps, one a
    // release, whose waits (19 ms into configuration mode, 7 ms into AMG mode) pass between the
    // calls, outside the bus lock; no step counts as a fault.
    group.group_mut().imu.bus_mut().set_nack(false);
    // 1: page 0, the identities; 2: the self-test, configuration mode requested.
    assert!(group.sample(Topic::Gyroscope, 2_000_000).is_empty());
    assert_eq!(
        group.retry_at_us(),
        2_000_000,
        "the next step at the next release"
    );
    assert!(group.sample(Topic::Gyroscope, 2_001_000).is_empty());
    assert_eq!(group.retry_at_us(), 2_020_000);
    assert!(group.sample(Topic::Gyroscope, 2_010_000).is_empty());
    // 3: the power mode, the units, page 1; 4: the configuration and its read-back; 5: page 0,
    // the units read back, AMG mode requested.
    for t in [2_020_000, 2_021_000, 2_022_000] {
        assert!(group.sample(Topic::Gyroscope, t).is_empty());
    }
    assert_eq!(group.retry_at_us(), 2_029_000);
    assert!(!group.is_ready());
    // 6: AMG mode checked. The last step's release takes the step alone (a release is a step
    // or a sample, never both); the group is ready and its next release samples it.
    assert!(group.sample(Topic::Gyroscope, 2_029_000).is_empty());
    assert!(group.is_ready());
    assert_eq!(group.sample(Topic::Gyroscope, 2_030_000).len(), 1);
    assert_eq!(group.faults(), 3);
}

/// Releases of `topic` every 10 ms from `from` until the group is ready: each answers nothing.
/// Returns the steps taken (releases before a step's wait has passed take none) and the time of
/// the last release.
fn set_up_again<I2C, D>(
    group: &mut Supervised<ImuSensors<I2C, D>>,
    topic: Topic,
    from: u64,
) -> (u32, u64)
where
    ImuSensors<I2C, D>: SensorGroup,
{
    let mut steps = 0;
    let mut now = from;
    loop {
        let due = group.retry_at_us() <= now;
        assert!(
            group.sample(topic, now).is_empty(),
            "a step's release at {now}"
        );
        steps += u32::from(due);
        if group.is_ready() {
            return (steps, now);
        }
        now += 10_000;
    }
}

#[test]
fn a_step_of_the_re_initialisation_that_fails_starts_the_back_off_again() {
    let mut group = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    group.group_mut().imu.bus_mut().set_nack(true);
    for t in 1..=3 {
        assert!(group.sample(Topic::Gyroscope, t * 10_000).is_empty());
    }
    // Steps 1 and 2 answer, then the part is gone again before step 3.
    group.group_mut().imu.bus_mut().set_nack(false);
    assert!(group.sample(Topic::Gyroscope, 2_000_000).is_empty());
    assert!(group.sample(Topic::Gyroscope, 2_010_000).is_empty());
    group.group_mut().imu.bus_mut().set_nack(true);
    assert!(group.sample(Topic::Gyroscope, 2_029_000).is_empty());
    assert_eq!(group.faults(), 4);
    assert!(group.retry_at_us() > 2_029_000 + 1_000_000);
    // Back: the next retry starts at step 1.
    group.group_mut().imu.bus_mut().set_nack(false);
    let retry = group.retry_at_us();
    let (steps, done) = set_up_again(&mut group, Topic::Gyroscope, retry);
    assert_eq!(steps, 6);
    assert_eq!(group.sample(Topic::Gyroscope, done + 10_000).len(), 1);
}

#[test]
fn a_bno055_that_reset_is_noticed_on_its_next_sample_and_configured_again() {
    use embedded_hal::i2c::I2c;
    let mut group = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    assert_eq!(group.sample(Topic::Accelerometer, 0).len(), 1);
    // SYS_TRIGGER RST_SYS: the part is back in configuration mode (data zero).
    group
        .group_mut()
        .imu
        .bus_mut()
        .write(A, &[0x3F, 0x20])
        .unwrap();
    for t in 1..=3 {
        assert!(group.sample(Topic::Accelerometer, t * 10_000).is_empty());
    }
    assert!(matches!(
        group.last_error(),
        Some(SampleError::Device {
            device: Device::Imu,
            error: Error::ConfigMismatch { register: 0x3D, .. }
        })
    ));
    // After the back-off the supervisor initialises it again (six steps, the mode switches
    // waited between them) and its next release publishes 1 g.
    let (steps, done) = set_up_again(&mut group, Topic::Accelerometer, 2_000_000);
    assert_eq!(steps, 6);
    let samples = group.sample(Topic::Accelerometer, done + 10_000);
    assert!(
        matches!(samples[..], [SensorData::Accelerometer([_, _, z])] if (998..=1002).contains(&z))
    );
    assert!(group
        .group_mut()
        .imu
        .bus_mut()
        .imu()
        .is_configured_for_amiro());
}
