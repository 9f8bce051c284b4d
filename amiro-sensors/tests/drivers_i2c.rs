//! Mock-transaction tests of the I2C drivers: HMC5883L, VCNL4020, PCA9544A, the floor and ring
//! groups, and the bq27500.

use amiro_sensors::drivers::bq27500::{BatteryStatus, Bq27500, Flags, PowerSummary, StatusRead};
use amiro_sensors::drivers::floor::{FloorSensor, FloorSensors, GroupError};
use amiro_sensors::drivers::hmc5883l::{Gain, Hmc5883l};
use amiro_sensors::drivers::pca9544a::{Channel, Control, Pca9544a};
use amiro_sensors::drivers::ring::{ProximityRing, WIRING};
use amiro_sensors::drivers::vcnl4020::{Config, Vcnl4020};
use amiro_sensors::drivers::{Axis, Error};
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as D};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as T};

const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

// ---------------------------------------------------------------- HMC5883L

fn compass_init_script(readback: [u8; 3]) -> Vec<T> {
    vec![
        T::write_read(0x1E, vec![0x0A], b"H43".to_vec()),
        T::write(0x1E, vec![0x00, 0x74]),
        T::write(0x1E, vec![0x01, 0xA0]),
        T::write(0x1E, vec![0x02, 0x00]),
        T::write_read(0x1E, vec![0x00], readback.to_vec()),
    ]
}

#[test]
fn compass_init_writes_cra_crb_mode_and_reads_them_back() {
    let mut i2c = I2cMock::new(&compass_init_script([0x74, 0xA0, 0x00]));
    let mut compass = Hmc5883l::new(i2c.clone());
    compass.init().unwrap();
    i2c.done();
}

#[test]
fn compass_read_back_ignores_bits_that_read_as_zero() {
    // CRB bits 4..0 are zero on the part whatever; MODE bit 7 is HS and written 0.
    let mut i2c = I2cMock::new(&compass_init_script([0x74, 0xA0, 0x00]));
    Hmc5883l::new(i2c.clone()).init().unwrap();
    i2c.done();
    let mut i2c = I2cMock::new(&compass_init_script([0x74, 0x20, 0x00]));
    assert_eq!(
        Hmc5883l::new(i2c.clone()).init(),
        Err(Error::ConfigMismatch {
            register: 0x01,
            expected: 0xA0,
            found: 0x20
        })
    );
    i2c.done();
}

#[test]
fn compass_rejects_a_wrong_identity() {
    let mut i2c = I2cMock::new(&[T::write_read(0x1E, vec![0x0A], b"H42".to_vec())]);
    assert_eq!(
        Hmc5883l::new(i2c.clone()).init(),
        Err(Error::WrongIdentity {
            expected: 0x0048_3433,
            found: 0x0048_3432
        })
    );
    i2c.done();
}

#[test]
fn compass_reorders_x_z_y_and_converts_to_nanotesla() {
    // X = 390 digits (1 Ga), Z = -195 (-0.5 Ga), Y = 39 (0.1 Ga); big-endian, register order X Z Y.
    let data = vec![0x01, 0x86, 0xFF, 0x3D, 0x00, 0x27];
    let mut i2c = I2cMock::new(&[T::write_read(0x1E, vec![0x03], data)]);
    let mut compass = Hmc5883l::new(i2c.clone());
    let field = compass.read().unwrap();
    assert_eq!(field.nanotesla, [100_000, 10_000, -50_000]);
    assert_eq!(field.axis(Axis::Z), -50_000);
    i2c.done();
}

#[test]
fn compass_gain_sets_crb_and_scale() {
    assert_eq!(Gain::Ga1_3.config_b(), 0x20);
    assert_eq!(Gain::Ga8_1.config_b(), 0xE0);
    let mut i2c = I2cMock::new(&[T::write_read(
        0x1E,
        vec![0x03],
        vec![0x04, 0x44, 0, 0, 0, 0],
    )]);
    let mut compass = Hmc5883l::with_gain(i2c.clone(), Gain::Ga1_3);
    // 1092 digits at 1090 LSB/Ga = 100 183.5 nT → rounds to 100 183 or 100 184.
    assert_eq!(compass.read().unwrap().nanotesla[0], 100_183);
    i2c.done();
}

#[test]
fn compass_overflow_is_a_typed_error_naming_the_axis() {
    // Y (last pair) reads -4096.
    let data = vec![0x00, 0x10, 0x00, 0x10, 0xF0, 0x00];
    let mut i2c = I2cMock::new(&[T::write_read(0x1E, vec![0x03], data)]);
    assert_eq!(
        Hmc5883l::new(i2c.clone()).read(),
        Err(Error::Overflow { axis: Axis::Y })
    );
    i2c.done();
}

#[test]
fn compass_bus_error_and_idle() {
    let mut i2c = I2cMock::new(&[
        T::write_read(0x1E, vec![0x0A], vec![0, 0, 0]).with_error(NACK),
        T::write(0x1E, vec![0x02, 0x03]),
    ]);
    let mut compass = Hmc5883l::new(i2c.clone());
    assert_eq!(compass.init(), Err(Error::Bus(NACK)));
    compass.idle().unwrap();
    i2c.done();
}

// ---------------------------------------------------------------- VCNL4020

/// The set-up of one VCNL4020 at the AMiRo settings, LED register showing fuse bits 01.
fn vcnl_init_script() -> Vec<T> {
    vec![
        T::write_read(0x13, vec![0x81], vec![0x21]),
        T::write(0x13, vec![0x80, 0x00]),
        T::write_read(0x13, vec![0x80], vec![0x80]),
        T::write(0x13, vec![0x82, 0x06]),
        T::write_read(0x13, vec![0x82], vec![0x06]),
        T::write(0x13, vec![0x83, 20]),
        T::write_read(0x13, vec![0x83], vec![0x40 | 20]),
        T::write(0x13, vec![0x84, 0x15]),
        T::write_read(0x13, vec![0x84], vec![0x15]),
        T::write(0x13, vec![0x80, 0x07]),
        T::write_read(0x13, vec![0x80], vec![0xE7]),
    ]
}

#[test]
fn vcnl_init_stops_configures_then_starts_self_timed_mode() {
    let mut i2c = I2cMock::new(&vcnl_init_script());
    Vcnl4020::new(i2c.clone()).init(&Config::AMIRO).unwrap();
    i2c.done();
}

#[test]
fn vcnl_rejects_a_wrong_product_id() {
    let mut i2c = I2cMock::new(&[T::write_read(0x13, vec![0x81], vec![0x11])]);
    assert_eq!(
        Vcnl4020::new(i2c.clone()).init(&Config::AMIRO),
        Err(Error::WrongIdentity {
            expected: 0x21,
            found: 0x11
        })
    );
    i2c.done();
}

#[test]
fn vcnl_reports_a_rate_that_was_not_taken() {
    let mut script = vcnl_init_script();
    script.truncate(5);
    script[4] = T::write_read(0x13, vec![0x82], vec![0x00]);
    let mut i2c = I2cMock::new(&script);
    assert_eq!(
        Vcnl4020::new(i2c.clone()).init(&Config::AMIRO),
        Err(Error::ConfigMismatch {
            register: 0x82,
            expected: 0x06,
            found: 0x00
        })
    );
    i2c.done();
}

#[test]
fn vcnl_reads_big_endian_results() {
    let mut i2c = I2cMock::new(&[
        T::write_read(0x13, vec![0x87], vec![0x12, 0x34]),
        T::write_read(0x13, vec![0x85], vec![0x00, 0x64]),
    ]);
    let reading = Vcnl4020::new(i2c.clone()).read().unwrap();
    assert_eq!(reading.proximity, 0x1234);
    assert_eq!(reading.ambient, 100);
    assert_eq!(reading.ambient_millilux(), 25_000);
    i2c.done();
}

#[test]
fn vcnl_bus_error() {
    let mut i2c = I2cMock::new(&[T::write_read(0x13, vec![0x87], vec![0, 0]).with_error(NACK)]);
    assert_eq!(
        Vcnl4020::new(i2c.clone()).read_proximity(),
        Err(Error::Bus(NACK))
    );
    i2c.done();
}

// ---------------------------------------------------------------- PCA9544A

#[test]
fn mux_select_writes_enable_and_channel_then_passes_transfers_through() {
    let mut i2c = I2cMock::new(&[
        T::write(0x77, vec![0x06]),
        T::write_read(0x13, vec![0x87], vec![0x00, 0x2A]),
        T::write(0x77, vec![0x00]),
        T::read(0x77, vec![0x35]),
    ]);
    let mut mux = Pca9544a::new(i2c.clone());
    {
        let bus = mux.select(Channel::Ch2).unwrap();
        assert_eq!(bus.channel(), Channel::Ch2);
        assert_eq!(Vcnl4020::new(bus).read_proximity().unwrap(), 42);
    }
    mux.disable().unwrap();
    assert_eq!(
        mux.control().unwrap(),
        Control {
            selected: Some(Channel::Ch1),
            interrupts: 0x3
        }
    );
    i2c.done();
}

#[test]
fn mux_control_decoding() {
    assert_eq!(Control::from_byte(0x00).selected, None);
    assert_eq!(
        Control::from_byte(0x03).selected,
        None,
        "channel bits without enable"
    );
    for ch in Channel::ALL {
        assert_eq!(Control::from_byte(ch.control_byte()).selected, Some(ch));
        assert_eq!(Channel::from_number(ch.number()), Some(ch));
    }
    assert_eq!(Channel::from_number(4), None);
}

#[test]
fn mux_select_error_is_the_bus_error() {
    let mut i2c = I2cMock::new(&[T::write(0x77, vec![0x04]).with_error(NACK)]);
    let mut mux = Pca9544a::new(i2c.clone());
    assert!(matches!(mux.select(Channel::Ch0), Err(Error::Bus(NACK))));
    i2c.done();
}

// ---------------------------------------------------------------- floor group

#[test]
fn floor_init_configures_channels_0_to_3_in_order() {
    let mut script = Vec::new();
    for ch in 0..4u8 {
        script.push(T::write(0x77, vec![0x04 | ch]));
        script.extend(vcnl_init_script());
    }
    let mut i2c = I2cMock::new(&script);
    let mut floor = FloorSensors::new(i2c.clone());
    floor.init().unwrap();
    i2c.done();
}

#[test]
fn floor_read_is_in_protocol_order_front_right_first() {
    let mut script = Vec::new();
    for ch in 0..4u8 {
        script.push(T::write(0x77, vec![0x04 | ch]));
        script.push(T::write_read(0x13, vec![0x87], vec![0x10 * (ch + 1), 0x00]));
    }
    let mut i2c = I2cMock::new(&script);
    let mut floor = FloorSensors::new(i2c.clone());
    assert_eq!(
        floor.read_proximity().unwrap(),
        [0x1000, 0x2000, 0x3000, 0x4000]
    );
    assert_eq!(FloorSensor::ALL.map(|s| s.channel().number()), [0, 1, 2, 3]);
    i2c.done();
}

#[test]
fn floor_error_names_the_sensor() {
    let mut i2c = I2cMock::new(&[
        T::write(0x77, vec![0x04]),
        T::write_read(0x13, vec![0x87], vec![0, 1]),
        T::write(0x77, vec![0x05]),
        T::write_read(0x13, vec![0x87], vec![0, 0]).with_error(NACK),
    ]);
    let mut floor = FloorSensors::new(i2c.clone());
    assert_eq!(
        floor.read_proximity(),
        Err(GroupError {
            sensor: FloorSensor::RightWheel as u8,
            error: Error::Bus(NACK)
        })
    );
    i2c.done();
}

// ---------------------------------------------------------------- proximity ring

#[test]
fn ring_reads_each_index_through_its_bus_and_channel() {
    // Sensor i answers 100 * (i + 1) counts; each bus sees its own sensors in index order.
    let mut bus1 = Vec::new();
    let mut bus2 = Vec::new();
    for (i, (bus, channel)) in WIRING.iter().enumerate() {
        let counts = (100 * (i as u16 + 1)).to_be_bytes().to_vec();
        let script = [
            T::write(0x77, vec![channel.control_byte()]),
            T::write_read(0x13, vec![0x87], counts),
        ];
        match bus {
            amiro_sensors::drivers::ring::RingBus::I2c1 => bus1.extend(script),
            amiro_sensors::drivers::ring::RingBus::I2c2 => bus2.extend(script),
        }
    }
    let (mut i1, mut i2) = (I2cMock::new(&bus1), I2cMock::new(&bus2));
    let mut ring = ProximityRing::new(i1.clone(), i2.clone());
    assert_eq!(
        ring.read_counts().unwrap(),
        [100, 200, 300, 400, 500, 600, 700, 800]
    );
    i1.done();
    i2.done();
}

#[test]
fn ring_wiring_matches_the_boards_table() {
    use amiro_sensors::drivers::ring::RingBus::{I2c1, I2c2};
    assert_eq!(
        WIRING.map(|(bus, ch)| (bus, ch.number())),
        [
            (I2c1, 1),
            (I2c1, 3),
            (I2c1, 2),
            (I2c2, 0),
            (I2c2, 1),
            (I2c2, 3),
            (I2c2, 2),
            (I2c1, 0)
        ]
    );
}

#[test]
fn ring_error_names_the_sensor_and_keeps_the_error_kind() {
    // Sensor 0 (I2C1 ch1) fails at the mux.
    let mut i1 = I2cMock::new(&[T::write(0x77, vec![0x05]).with_error(ErrorKind::ArbitrationLoss)]);
    let mut i2 = I2cMock::new(&[]);
    let mut ring = ProximityRing::new(i1.clone(), i2.clone());
    assert_eq!(
        ring.read_counts(),
        Err(GroupError {
            sensor: 0,
            error: Error::Bus(ErrorKind::ArbitrationLoss)
        })
    );
    assert_eq!(
        ring.set_calibration(8, Default::default()),
        Err(Error::OutOfRange { value: 8, max: 7 })
    );
    i1.done();
    i2.done();
}

// ---------------------------------------------------------------- bq27500

fn gauge_read(cmd: u8, value: u16) -> T {
    T::write_read(0x55, vec![cmd], value.to_le_bytes().to_vec())
}

#[test]
fn gauge_init_sends_device_type_as_two_single_byte_writes_and_paces_the_bus() {
    let mut i2c = I2cMock::new(&[
        T::write(0x55, vec![0x00, 0x01]),
        T::write(0x55, vec![0x01, 0x00]),
        gauge_read(0x00, 0x0500),
    ]);
    let mut delay = CheckedDelay::new(&[
        D::delay_ns(66_000),
        D::delay_ns(66_000),
        D::delay_ns(66_000),
    ]);
    Bq27500::new(i2c.clone(), &mut delay).init().unwrap();
    i2c.done();
    delay.done();
}

#[test]
fn gauge_rejects_another_device_type() {
    let mut i2c = I2cMock::new(&[
        T::write(0x55, vec![0x00, 0x01]),
        T::write(0x55, vec![0x01, 0x00]),
        gauge_read(0x00, 0x0541),
    ]);
    assert_eq!(
        Bq27500::new(i2c.clone(), NoopDelay::new()).init(),
        Err(Error::WrongIdentity {
            expected: 0x0500,
            found: 0x0541
        })
    );
    i2c.done();
}

fn status_script(flags: u16, current: i16, tte: u16, ttf: u16, power: i16) -> Vec<T> {
    vec![
        gauge_read(0x06, 2981),  // 25.0 °C
        gauge_read(0x08, 3_900), // mV
        gauge_read(0x0A, flags),
        gauge_read(0x10, 1_200), // remaining mAh
        gauge_read(0x12, 2_000), // full mAh
        gauge_read(0x14, current as u16),
        gauge_read(0x16, tte),
        gauge_read(0x18, ttf),
        gauge_read(0x24, power as u16),
        gauge_read(0x2C, 60),
    ]
}

#[test]
fn gauge_status_while_discharging() {
    let mut i2c = I2cMock::new(&status_script(
        Flags::DISCHARGING,
        -450,
        160,
        0xFFFF,
        -1_755,
    ));
    let status = Bq27500::new(i2c.clone(), NoopDelay::new())
        .read_status()
        .unwrap();
    assert_eq!(status.temperature_decicelsius, 250);
    assert_eq!(status.voltage_mv, 3_900);
    assert_eq!(status.average_current_ma, -450);
    assert_eq!(status.time_to_empty_min, Some(160));
    assert_eq!(status.time_to_full_min, None);
    assert_eq!(status.state_of_charge, 60);
    assert!(!status.charging());
    assert_eq!(status.minutes(), 160);
    assert_eq!(status.power_mw(), 1_755);
    i2c.done();
}

#[test]
fn gauge_status_while_charging() {
    let mut i2c = I2cMock::new(&status_script(
        Flags::CHARGE_ALLOWED,
        800,
        0xFFFF,
        60,
        3_120,
    ));
    let status = Bq27500::new(i2c.clone(), NoopDelay::new())
        .read_status()
        .unwrap();
    assert!(status.charging());
    assert_eq!(status.minutes(), 60);
    assert_eq!(PowerSummary::of(&status).power_mw, 3_120);
    i2c.done();
}

/// Steps `read` to its end on `gauge`: the result and how many steps (one transfer each) it took.
fn step_to_end(
    read: &mut StatusRead,
    gauge: &mut Bq27500<I2cMock, NoopDelay>,
) -> (Result<BatteryStatus, Error<ErrorKind>>, usize) {
    for steps in 1..=StatusRead::MAX_TRANSFERS {
        if let Some(done) = read.step(gauge) {
            return (done, steps);
        }
    }
    panic!(
        "a status read took more than {} steps",
        StatusRead::MAX_TRANSFERS
    );
}

#[test]
fn a_stepped_status_read_makes_one_transfer_a_step_and_decodes_every_register() {
    let script = status_script(Flags::DISCHARGING, -450, 160, 0xFFFF, -1_755);
    let mut i2c = I2cMock::new(&script);
    let mut gauge = Bq27500::new(i2c.clone(), NoopDelay::new());
    let (stepped, steps) = step_to_end(&mut StatusRead::new(), &mut gauge);
    assert_eq!(steps, 10);
    // The script's ten registers, each in its field (the mock fails a transfer out of order).
    let status = stepped.unwrap();
    assert_eq!(status.temperature_decicelsius, 250);
    assert_eq!(status.voltage_mv, 3_900);
    assert_eq!(status.flags, Flags(Flags::DISCHARGING));
    assert_eq!(status.remaining_capacity_mah, 1_200);
    assert_eq!(status.full_charge_capacity_mah, 2_000);
    assert_eq!(status.average_current_ma, -450);
    assert_eq!(status.time_to_empty_min, Some(160));
    assert_eq!(status.time_to_full_min, None);
    assert_eq!(status.average_power_mw, -1_755);
    assert_eq!(status.state_of_charge, 60);
    i2c.done();
}

#[test]
fn a_stepped_status_read_checks_the_identity_after_a_dead_lines_pattern_in_three_more_steps() {
    let mut script = vec![
        gauge_read(0x06, 0xFFFF),
        gauge_read(0x08, 0xFFFF),
        T::write(0x55, vec![0x00, 0x01]),
        T::write(0x55, vec![0x01, 0x00]),
        gauge_read(0x00, 0x0500),
    ];
    script.extend(status_script(0, 0, 0xFFFF, 0xFFFF, 0).into_iter().skip(2));
    let mut i2c = I2cMock::new(&script);
    let mut gauge = Bq27500::new(i2c.clone(), NoopDelay::new());
    let (status, steps) = step_to_end(&mut StatusRead::new(), &mut gauge);
    assert_eq!(steps, StatusRead::MAX_TRANSFERS);
    assert_eq!(status.map(|s| s.voltage_mv), Ok(0xFFFF));
    i2c.done();
}

#[test]
fn a_restarted_status_read_begins_again_without_the_last_reads_identity_check() {
    let mut script = vec![
        gauge_read(0x06, 0),
        gauge_read(0x08, 0),
        T::write(0x55, vec![0x00, 0x01]),
        T::write(0x55, vec![0x01, 0x00]),
        gauge_read(0x00, 0x0500),
    ];
    script.extend(status_script(0, 0, 0xFFFF, 0xFFFF, 0).into_iter().skip(2));
    script.extend(status_script(Flags::DISCHARGING, -450, 160, 0xFFFF, -1_755));
    let mut i2c = I2cMock::new(&script);
    let mut gauge = Bq27500::new(i2c.clone(), NoopDelay::new());
    let mut read = StatusRead::new();
    let (first, steps) = step_to_end(&mut read, &mut gauge);
    assert_eq!((first.map(|s| s.voltage_mv), steps), (Ok(0), 13));
    read.restart();
    let (second, steps) = step_to_end(&mut read, &mut gauge);
    assert_eq!((second.map(|s| s.voltage_mv), steps), (Ok(3_900), 10));
    i2c.done();
}

#[test]
fn a_stepped_status_read_ends_at_the_first_failed_transfer() {
    let mut i2c = I2cMock::new(&[gauge_read(0x06, 2981), gauge_read(0x08, 0).with_error(NACK)]);
    let mut gauge = Bq27500::new(i2c.clone(), NoopDelay::new());
    let (status, steps) = step_to_end(&mut StatusRead::new(), &mut gauge);
    assert_eq!((status, steps), (Err(Error::Bus(NACK)), 2));
    i2c.done();
}

#[test]
fn gauge_bus_error_still_waits_the_bus_free_time() {
    let mut i2c = I2cMock::new(&[gauge_read(0x06, 0).with_error(NACK)]);
    let mut delay = CheckedDelay::new(&[D::delay_ns(66_000)]);
    assert_eq!(
        Bq27500::new(i2c.clone(), &mut delay).read_status(),
        Err(Error::Bus(NACK))
    );
    i2c.done();
    delay.done();
}

fn battery(
    soc: u8,
    remaining: u16,
    full: u16,
    current: i16,
    tte: Option<u16>,
    ttf: Option<u16>,
    power: i16,
) -> BatteryStatus {
    BatteryStatus {
        state_of_charge: soc,
        remaining_capacity_mah: remaining,
        full_charge_capacity_mah: full,
        average_current_ma: current,
        time_to_empty_min: tte,
        time_to_full_min: ttf,
        average_power_mw: power,
        flags: Flags(if current < 0 { Flags::DISCHARGING } else { 0 }),
        ..BatteryStatus::default()
    }
}

#[test]
fn two_batteries_combine_capacity_weighted_with_the_longer_time() {
    let a = battery(50, 1000, 2000, -400, Some(150), None, -1_500);
    let b = battery(100, 1000, 1000, -300, Some(200), None, -1_100);
    let sum = PowerSummary::of_pair(&a, &b);
    assert!(!sum.charging);
    assert_eq!(sum.state_of_charge, 66); // 2000 of 3000 mAh
    assert_eq!(sum.minutes, 200);
    assert_eq!(sum.power_mw, 2_600);
}

#[test]
fn two_batteries_one_charging_counts_as_charging() {
    let a = battery(40, 800, 2000, 700, None, Some(90), 2_700);
    let b = battery(40, 800, 2000, 0, None, None, 0);
    let sum = PowerSummary::of_pair(&a, &b);
    assert!(sum.charging);
    assert_eq!(sum.minutes, 90, "an unknown estimate is ignored");
    let unknown = PowerSummary::of_pair(&b, &b);
    assert_eq!(unknown.minutes, 0xFFFF);
}

#[test]
fn two_batteries_without_capacity_average_the_percentages() {
    let a = battery(30, 0, 0, -1, None, None, 0);
    let b = battery(71, 0, 0, -1, None, None, 0);
    assert_eq!(PowerSummary::of_pair(&a, &b).state_of_charge, 50);
}
