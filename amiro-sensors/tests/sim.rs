//! The simulated devices against the real drivers: the drivers accept them (identity, set-up
//! read-back), the simulators store and police the configuration, and the values that come out
//! of the drivers are the simulators' documented patterns.

use amiro_sensors::drivers::bq27500::Bq27500;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::hmc5883l::{Gain, Hmc5883l};
use amiro_sensors::drivers::l3g4200d::{self, L3g4200d};
use amiro_sensors::drivers::lis331dlh::Lis331dlh;
use amiro_sensors::drivers::tlc5947::{self, LightRing, LightRing24};
use amiro_sensors::drivers::vcnl4020::{self, Vcnl4020};
use amiro_sensors::drivers::Error;
use amiro_sensors::sim::*;
use embedded_hal::i2c::I2c;

#[test]
fn simulators_fit_a_few_hundred_bytes() {
    use core::mem::size_of;
    let diwheeldrive = size_of::<SimGyroscope>()
        + size_of::<SimAccelerometer>()
        + size_of::<SimCompassBus>()
        + size_of::<SimFloorBus>()
        + size_of::<WheelPlant>();
    // 200 B with the patterns alone; the world feed (`set_measured`, `set_field`,
    // `set_proximity`: docs/world.md) adds 80 B.
    assert!(
        diwheeldrive <= 288,
        "DiWheelDrive simulators take {diwheeldrive} bytes"
    );
    let power_management = 2 * size_of::<SimPowerBus>();
    assert!(
        power_management <= 160,
        "PowerManagement simulators take {power_management} bytes"
    );
    assert!(size_of::<SimLedDriver>() <= 96);
    assert!(size_of::<SimLedChain<3>>() <= 3 * 96);
}

// ---------------------------------------------------------------- gyroscope

#[test]
fn gyroscope_driver_configures_the_simulator_and_reads_its_pattern() {
    let mut gyro = L3g4200d::new(SimGyroscope::new());
    gyro.init().unwrap();
    for n in 0..500 {
        let rate = gyro.read().unwrap();
        for (got, want) in rate
            .millidegrees_per_s
            .iter()
            .zip(SimGyroscope::pattern_at(n))
        {
            // One digit at ±500 dps is 17.5 mdps; the simulator rounds to the nearest digit.
            assert!((got - want).abs() <= 9, "sample {n}: {got} vs {want}");
        }
    }
    let sim = gyro.release();
    assert!(sim.is_configured_for_amiro());
    assert_eq!(sim.samples(), 500);
}

#[test]
fn gyroscope_simulator_encodes_at_the_range_the_driver_chose() {
    let mut gyro = L3g4200d::with_range(SimGyroscope::new(), l3g4200d::Range::Dps2000);
    gyro.init().unwrap();
    let z = gyro.read().unwrap().millidegrees_per_s[2];
    let raw = gyro.read_raw().unwrap()[2];
    assert_eq!(z, 0);
    // Sample 1: Z = 90 dps × 4 / 1000 = 360 mdps → 5 digits of 70 mdps.
    assert_eq!(raw, 5);
    assert!(!gyro.release().is_configured_for_amiro());
}

#[test]
fn gyroscope_simulator_reads_zero_until_powered() {
    let mut gyro = L3g4200d::new(SimGyroscope::new());
    assert_eq!(gyro.read_raw().unwrap(), [0, 0, 0]);
    gyro.init().unwrap();
    gyro.sleep().unwrap();
    assert_eq!(gyro.read_raw().unwrap(), [0, 0, 0], "sleep: axes off");
    gyro.wake().unwrap();
    assert_ne!(gyro.read_raw().unwrap(), [0, 0, 0]);
}

// ---------------------------------------------------------------- accelerometer

#[test]
fn accelerometer_driver_reads_one_g_down() {
    let mut accel = Lis331dlh::new(SimAccelerometer::new());
    accel.init().unwrap();
    for n in 0..300 {
        let a = accel.read().unwrap();
        for (got, want) in a.micro_g.iter().zip(SimAccelerometer::pattern_at(n)) {
            assert!((got - want).abs() <= 1_950, "sample {n}: {got} vs {want}");
        }
    }
    // Sample 300: Z = exactly 1 g = 256.4 digits of 3.9 mg → 256 digits = 998 mg.
    assert_eq!(accel.read().unwrap().milli_g()[2], 998);
    let sim = accel.release();
    assert!(sim.is_configured_for_amiro());
    assert_eq!(sim.control_registers(), [0x27, 0x00, 0x82, 0x30, 0x00]);
}

// ---------------------------------------------------------------- magnetometer

#[test]
fn compass_driver_reads_the_turning_field() {
    let mut compass = Hmc5883l::new(SimCompassBus::new());
    compass.init().unwrap();
    for n in 0..360 {
        let field = compass.read().unwrap();
        for (got, want) in field.nanotesla.iter().zip(SimHmc5883l::field_at(n)) {
            // One digit at 390 LSB/Ga is 256 nT.
            assert!((got - want).abs() <= 129, "sample {n}: {got} vs {want}");
        }
    }
    assert!(compass.release().magnetometer().is_configured_for_amiro());
}

#[test]
fn compass_simulator_follows_the_gain() {
    let mut compass = Hmc5883l::with_gain(SimCompassBus::new(), Gain::Ga0_88);
    compass.init().unwrap();
    // Sample 0: X = 20 µT = 0.2 Ga × 1370 = 274 digits.
    assert_eq!(compass.read_raw().unwrap()[0], 274);
}

#[test]
fn compass_simulator_pointer_wraps_from_0x08_to_0x03() {
    let mut bus = SimCompassBus::new();
    Hmc5883l::new(&mut bus).init().unwrap();
    let mut eight = [0u8; 8];
    bus.write_read(0x1E, &[0x03], &mut eight).unwrap();
    assert_eq!(eight[6..], eight[..2], "bytes 7 and 8 are X again");
    let mut id = [0u8; 3];
    bus.write_read(0x1E, &[0x0A], &mut id).unwrap();
    assert_eq!(&id, b"H43");
}

#[test]
fn compass_simulator_nacks_other_addresses() {
    let mut bus = SimCompassBus::new();
    assert_eq!(bus.write(0x1F, &[0]), Err(NoAcknowledge { address: 0x1F }));
}

// ---------------------------------------------------------------- proximity

#[test]
fn floor_sensors_configure_all_four_simulators_and_read_their_pattern() {
    let mut floor = FloorSensors::new(SimFloorBus::new());
    floor.init().unwrap();
    for n in 0..100u16 {
        let counts = floor.read_proximity().unwrap();
        let want = [0, 1, 2, 3].map(|i| SimVcnl4020::proximity_at(i, n));
        assert_eq!(counts, want, "sample {n}");
    }
    let bus = floor.release();
    for ch in 0..4 {
        assert!(bus
            .proximity()
            .sensor(ch)
            .is_some_and(SimVcnl4020::is_configured_for_amiro));
    }
}

#[test]
fn vcnl_simulator_refuses_a_rate_change_while_measuring() {
    let mut bus = SimFloorBus::new();
    bus.write(0x77, &[0x04]).unwrap();
    bus.write(0x13, &[0x80, 0x07]).unwrap();
    bus.write(0x13, &[0x82, 0x03]).unwrap();
    let mut rate = [0xFF];
    bus.write_read(0x13, &[0x82], &mut rate).unwrap();
    assert_eq!(rate, [0x00]);
    assert_eq!(
        bus.proximity().sensor(0).map(SimVcnl4020::rejected_writes),
        Some(1)
    );
    // And the driver, which stops measurement first, gets its rate in.
    let mut mux = amiro_sensors::drivers::pca9544a::Pca9544a::new(&mut bus);
    let channel = mux
        .select(amiro_sensors::drivers::pca9544a::Channel::Ch0)
        .unwrap();
    Vcnl4020::new(channel)
        .init(&vcnl4020::Config::AMIRO)
        .unwrap();
}

#[test]
fn sensors_behind_a_disabled_mux_do_not_answer() {
    let mut bus = SimFloorBus::new();
    assert_eq!(
        bus.write(0x13, &[0x81]),
        Err(NoAcknowledge { address: 0x13 })
    );
    bus.write(0x77, &[0x05]).unwrap();
    let mut id = [0];
    bus.write_read(0x13, &[0x81], &mut id).unwrap();
    assert_eq!(id, [0x21]);
    let mut control = [0];
    bus.read(0x77, &mut control).unwrap();
    assert_eq!(control, [0x05]);
    bus.write(0x77, &[0x00]).unwrap();
    assert!(bus.write(0x13, &[0x81]).is_err());
    // A driver surfaces that as a bus error.
    assert_eq!(
        Vcnl4020::new(&mut bus).read_proximity(),
        Err(Error::Bus(NoAcknowledge { address: 0x13 }))
    );
}

// ---------------------------------------------------------------- fuel gauge

#[test]
fn gauge_driver_accepts_the_simulator_and_follows_its_discharge() {
    let mut gauge = Bq27500::new(SimPowerBus::new(0, false), NoDelay);
    gauge.init().unwrap();
    let first = gauge.read_status().unwrap();
    assert_eq!(first.state_of_charge, 90);
    assert!(!first.charging());
    assert_eq!(first.average_current_ma, -450);
    assert_eq!(first.remaining_capacity_mah, 1_800);
    assert_eq!(first.time_to_empty_min, Some(240));
    assert_eq!(first.time_to_full_min, None);
    assert_eq!(first.voltage_mv, 4_130);
    assert_eq!(first.temperature_decicelsius, 250);
    for _ in 0..7 {
        gauge.read_status().unwrap();
    }
    assert_eq!(
        gauge.read_status().unwrap().state_of_charge,
        89,
        "one percent per eight samples"
    );
}

#[test]
fn gauge_simulator_charging() {
    let mut gauge = Bq27500::new(SimPowerBus::new(4, true), NoDelay);
    gauge.init().unwrap();
    let status = gauge.read_status().unwrap();
    assert!(status.charging());
    assert_eq!(status.time_to_full_min, Some(135)); // 1800 mAh at 800 mA
    assert_eq!(status.minutes(), 135);
    assert_eq!(status.average_power_mw, 2_856);
    let (bus, _) = gauge.release();
    assert_eq!(bus.fuel_gauge().last_subcommand(), 0x0001);
}

// ---------------------------------------------------------------- LED driver

#[test]
fn light_ring_shifts_frames_the_simulator_decodes() {
    let mut ring = LightRing::new(SimLedDriver::new());
    ring.set_led(1, 255, 128, 0).unwrap();
    ring.set_led(8, 0, 0, 10).unwrap();
    ring.flush().unwrap();
    let sim = ring.release();
    assert_eq!(sim.latches(), 1);
    // LED 1 is triple 7 (OUT21..23), LED 8 triple 0 (OUT0..2).
    assert_eq!(sim.output(21), Some(4095));
    assert_eq!(sim.output(22), Some(tlc5947::gamma(128)));
    assert_eq!(sim.output(23), Some(0));
    assert_eq!(sim.output(2), Some(tlc5947::gamma(10)));
    assert_eq!(sim.outputs().iter().filter(|&&v| v != 0).count(), 3);
}

#[test]
fn a_24_led_ring_shifts_frames_a_simulated_chain_of_three_decodes() {
    let mut ring = LightRing24::new(SimLedChain::<3>::new());
    ring.set_led(1, 255, 128, 0).unwrap();
    ring.set_led(8, 0, 0, 10).unwrap();
    ring.flush().unwrap();
    let sim = ring.release();
    assert_eq!(sim.latches(), 1);
    assert_eq!(sim.outputs().len(), 72);
    // LED 1 is triples 0..=2 (chain channels 0..=8), LED 8 triples 21..=23 (63..=71).
    for red in [0, 3, 6] {
        assert_eq!(sim.output(red), Some(4095));
        assert_eq!(sim.output(red + 1), Some(tlc5947::gamma(128)));
        assert_eq!(sim.output(red + 2), Some(0));
    }
    for blue in [65, 68, 71] {
        assert_eq!(sim.output(blue), Some(tlc5947::gamma(10)));
    }
    assert_eq!(sim.outputs().iter().filter(|&&v| v != 0).count(), 9);
}

// ---------------------------------------------------------------- determinism

#[test]
fn simulators_are_deterministic() {
    let run = || {
        let mut gyro = L3g4200d::new(SimGyroscope::new());
        let mut floor = FloorSensors::new(SimFloorBus::new());
        gyro.init().unwrap();
        floor.init().unwrap();
        (0..50)
            .map(|_| (gyro.read_raw().unwrap(), floor.read_proximity().unwrap()))
            .collect::<Vec<_>>()
    };
    assert_eq!(run(), run());
}
