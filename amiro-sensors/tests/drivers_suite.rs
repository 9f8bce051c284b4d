//! The board suites: `sample(topic)` against the simulators (values, frames per sample, the
//! magnetometer's one-read-three-frames policy) and against failing buses (typed errors naming
//! the device).

use std::cell::RefCell;

use amiro_can::{Axis, LedCommand, PowerStatus, Rgb, SensorData, Topic};
use amiro_sensors::drivers::proximity::ProximityCalibration;
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::suite::{
    Battery, BusFault, Compass, Device, DiWheelDriveSensors, PowerManagementSensors, SampleError,
    SensorGroup,
};
use amiro_sensors::drivers::tlc5947::{self, LightRing, LightRing24};
use amiro_sensors::drivers::Error;
use amiro_sensors::sim::*;
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as T};

type DiWheelDriveSim =
    DiWheelDriveSensors<SimGyroscope, SimAccelerometer, SimCompassBus, SimFloorBus>;

fn diwheeldrive() -> DiWheelDriveSim {
    let mut sensors = DiWheelDriveSensors::new(
        SimGyroscope::new(),
        SimAccelerometer::new(),
        SimCompassBus::new(),
        SimFloorBus::new(),
    );
    sensors.init().unwrap();
    sensors
}

#[test]
fn diwheeldrive_samples_each_topic_in_protocol_units() {
    let mut s = diwheeldrive();
    let gyro = s.sample(Topic::Gyroscope, 0).unwrap();
    // Sample 0 of the gyroscope pattern: (0, 5, 0) dps.
    assert_eq!(gyro.as_slice(), [SensorData::Gyroscope([0, 5, 0])]);
    let accel = s.sample(Topic::Accelerometer, 0).unwrap();
    assert_eq!(accel.as_slice(), [SensorData::Accelerometer([0, 0, 998])]);
    let floor = s.sample(Topic::FloorProximity, 0).unwrap();
    let want = [0, 1, 2, 3].map(|i| SimVcnl4020::proximity_at(i, 0));
    assert_eq!(floor.as_slice(), [SensorData::FloorProximity(want)]);
    let x = s.sample(Topic::MagnetometerX, 0).unwrap();
    // 20 µT = 0.2 Ga = 78 digits at 390 LSB/Ga, and back.
    assert_eq!(
        x.as_slice(),
        [SensorData::Magnetometer {
            axis: Axis::X,
            nanotesla: 20_000
        }]
    );
}

/// The simulated compass bus shared with the test, so the test can count the part's reads while
/// the compass group owns a handle to it.
struct SharedBus<'a>(&'a RefCell<SimCompassBus>);

impl embedded_hal::i2c::ErrorType for SharedBus<'_> {
    type Error = NoAcknowledge;
}

impl embedded_hal::i2c::I2c for SharedBus<'_> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [embedded_hal::i2c::Operation<'_>],
    ) -> Result<(), NoAcknowledge> {
        self.0.borrow_mut().transaction(address, operations)
    }
}

#[test]
fn one_magnetometer_read_serves_x_y_and_z() {
    let bus = RefCell::new(SimCompassBus::new());
    let reads = || bus.borrow().magnetometer().samples();
    let mut compass = Compass::new(SharedBus(&bus));
    compass.init().unwrap();
    let mut values = Vec::new();
    for topic in [
        Topic::MagnetometerX,
        Topic::MagnetometerY,
        Topic::MagnetometerZ,
    ] {
        values.extend(compass.sample(topic, 1_000).unwrap());
    }
    let axes: Vec<_> = values.iter().map(SensorData::topic).collect();
    assert_eq!(
        axes,
        [
            Topic::MagnetometerX,
            Topic::MagnetometerY,
            Topic::MagnetometerZ
        ]
    );
    assert_eq!(reads(), 1, "X, Y and Z came from one read");
    // X again: that axis was already sent, so the part is read again.
    compass.sample(Topic::MagnetometerX, 1_000).unwrap();
    assert_eq!(reads(), 2);
    // Y within the 33 ms window takes that reading; Z after the window reads once more.
    compass.sample(Topic::MagnetometerY, 30_000).unwrap();
    assert_eq!(reads(), 2);
    compass.sample(Topic::MagnetometerZ, 40_000).unwrap();
    assert_eq!(reads(), 3);
    // With no window every sample reads the part.
    compass.set_reuse_window_us(0);
    compass.sample(Topic::MagnetometerX, 40_000).unwrap();
    compass.sample(Topic::MagnetometerY, 40_001).unwrap();
    assert_eq!(reads(), 5);
}

#[test]
fn magnetometer_sample_all_is_three_frames_from_one_read() {
    let mut compass = Compass::new(SimCompassBus::new());
    compass.init().unwrap();
    let frames = compass.sample_all(0).unwrap();
    assert_eq!(frames.len(), 3);
    assert_eq!(
        frames.iter().map(SensorData::topic).collect::<Vec<_>>(),
        [
            Topic::MagnetometerX,
            Topic::MagnetometerY,
            Topic::MagnetometerZ
        ]
    );
    assert_eq!(
        frames[2],
        SensorData::Magnetometer {
            axis: Axis::Z,
            nanotesla: -40_000
        }
    );
    assert_eq!(compass.magnetometer.release().magnetometer().samples(), 1);
}

#[test]
fn topics_of_other_groups_and_boards_are_not_served() {
    let mut s = diwheeldrive();
    assert_eq!(
        s.sample(Topic::Odometry, 0),
        Err(SampleError::NotServed(Topic::Odometry))
    );
    assert_eq!(
        s.sample(Topic::ProximityRing, 0),
        Err(SampleError::NotServed(Topic::ProximityRing))
    );
    assert_eq!(
        s.inertial.sample(Topic::FloorProximity, 0),
        Err(SampleError::NotServed(Topic::FloorProximity))
    );
    assert!(s.serves(Topic::MagnetometerY));
    assert!(!s.serves(Topic::Led1));
    assert!(SensorGroup::serves(&s.floor, Topic::FloorProximity));
}

#[test]
fn a_failing_floor_sensor_is_named_in_the_error() {
    let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data);
    let mut floor_bus = I2cMock::new(&[
        T::write(0x77, vec![0x04]),
        T::write_read(0x13, vec![0x87], vec![0, 9]),
        T::write(0x77, vec![0x05]),
        T::write_read(0x13, vec![0x87], vec![0, 9]),
        T::write(0x77, vec![0x06]).with_error(nack),
    ]);
    let mut s = DiWheelDriveSensors::new(
        SimGyroscope::new(),
        SimAccelerometer::new(),
        SimCompassBus::new(),
        floor_bus.clone(),
    );
    assert_eq!(
        s.sample(Topic::FloorProximity, 0),
        Err(SampleError::Device {
            device: Device::FloorSensor(2),
            error: Error::Bus(BusFault::I2c(nack)),
        })
    );
    floor_bus.done();
}

#[test]
fn an_unpowered_bus_fails_init_with_the_device_and_reason() {
    // A compass bus with nothing on it: the identity read is not acknowledged.
    let mut s = DiWheelDriveSensors::new(
        SimGyroscope::new(),
        SimAccelerometer::new(),
        SimFloorBus::new(), // no HMC5883L at 0x1E here
        SimFloorBus::new(),
    );
    assert_eq!(
        s.init(),
        Err(SampleError::Device {
            device: Device::Magnetometer,
            error: Error::Bus(BusFault::I2c(ErrorKind::NoAcknowledge(
                NoAcknowledgeSource::Address
            ))),
        })
    );
}

// ---------------------------------------------------------------- PowerManagement

fn power_management() -> PowerManagementSensors<SimPowerBus, SimPowerBus, NoDelay> {
    // I2C1 carries ring sensors 0..3 of the simulator numbering and the rear gauge (discharging),
    // I2C2 sensors 4..7 and the front gauge (discharging).
    let mut s = PowerManagementSensors::new(
        SimPowerBus::new(0, false),
        SimPowerBus::new(4, false),
        NoDelay,
    );
    s.init().unwrap();
    s
}

#[test]
fn ring_sample_is_eight_frames_in_millimetres_by_index() {
    let mut s = power_management();
    let frames = s.sample(Topic::ProximityRing, 0).unwrap();
    assert_eq!(frames.len(), 8);
    let cal = ProximityCalibration::DEFAULT;
    for (index, frame) in frames.iter().enumerate() {
        let (bus, channel) = WIRING[index];
        let sim_index = channel.number() + if bus == RingBus::I2c1 { 0 } else { 4 };
        let mm = cal.counts_to_mm(SimVcnl4020::proximity_at(sim_index, 0));
        assert_eq!(
            *frame,
            SensorData::ProximityRing {
                sensor: index as u8,
                mm
            }
        );
        assert!(frame.validate().is_ok());
    }
}

#[test]
fn ring_calibration_applies_per_sensor() {
    let mut s = power_management();
    let counts = SimVcnl4020::proximity_at(1, 0); // sensor 0 is I2C1 channel 1
    let cal = ProximityCalibration::from_reference(counts - 1_000, counts, 50).unwrap();
    s.ring.set_calibration(0, cal).unwrap();
    let frames = s.sample(Topic::ProximityRing, 0).unwrap();
    assert_eq!(frames[0], SensorData::ProximityRing { sensor: 0, mm: 50 });
}

#[test]
fn power_status_combines_both_gauges() {
    let mut s = power_management();
    let frames = s.sample(Topic::PowerStatus, 0).unwrap();
    // Both packs: 90 %, 1800 of 2000 mAh, 240 min to empty, 450 mA at 4.13 V = 1858 mW each.
    assert_eq!(
        frames.as_slice(),
        [SensorData::PowerStatus(PowerStatus {
            charging: false,
            state_of_charge: 90,
            minutes: 240,
            power_mw: 2 * 1_858,
        })]
    );
    assert_eq!(s.gauge_faults(), [0, 0]);
}

#[test]
fn power_status_charging_when_one_pack_charges() {
    let mut s = PowerManagementSensors::new(
        SimPowerBus::new(0, false),
        SimPowerBus::new(4, true),
        NoDelay,
    );
    s.init().unwrap();
    let power = s.read_power().unwrap();
    assert!(power.charging);
    assert_eq!(power.minutes, 135, "time to full of the charging pack");
    assert_eq!(power.state_of_charge, 50, "(1800 + 200) of 4000 mAh");
}

#[test]
fn a_missing_gauge_degrades_to_the_other_one_and_is_counted() {
    // I2C1 without a gauge (just the mux and sensors).
    let mut s = PowerManagementSensors::new(SimFloorBus::new(), SimPowerBus::new(4, true), NoDelay);
    assert_eq!(
        s.init(),
        Err(SampleError::Device {
            device: Device::FuelGauge(Battery::Rear),
            error: Error::Bus(BusFault::I2c(ErrorKind::NoAcknowledge(
                NoAcknowledgeSource::Address
            ))),
        })
    );
    let power = s.read_power().unwrap();
    assert!(power.charging);
    assert_eq!(power.state_of_charge, 10);
    assert_eq!(s.gauge_faults(), [0, 1]);
    let (front, rear) = s.read_batteries();
    assert!(front.is_ok() && rear.is_err());
    assert_eq!(
        s.sample(Topic::Gyroscope, 0),
        Err(SampleError::NotServed(Topic::Gyroscope))
    );
}

// ---------------------------------------------------------------- LightRing

/// LED 3 to (10, 20, 30): the command both ring sizes are tested with.
fn led_3_command() -> LedCommand {
    LedCommand::new(
        3,
        Rgb {
            r: 10,
            g: 20,
            b: 30,
        },
    )
    .unwrap()
}

#[test]
fn led_command_sets_and_latches_the_ring() {
    let mut ring = LightRing::new(SimLedDriver::new());
    let command = led_3_command();
    ring.apply(&command).unwrap();
    let sim = ring.release();
    assert_eq!(sim.latches(), 1);
    // LED 3 = triple 5 = OUT15..17.
    assert_eq!(sim.outputs()[15..18], [10, 20, 30].map(tlc5947::gamma));
}

#[test]
fn led_command_on_the_24_led_ring_sets_the_leds_group_and_latches() {
    let mut ring = LightRing24::new(SimLedChain::<3>::new());
    let command = led_3_command();
    ring.apply(&command).unwrap();
    let sim = ring.release();
    assert_eq!(sim.latches(), 1);
    // LED 3 = RGB LEDs 6..=8 = chain channels 18..=26.
    for red in [18, 21, 24] {
        assert_eq!(
            sim.outputs()[red..red + 3],
            [10, 20, 30].map(tlc5947::gamma)
        );
    }
    assert_eq!(sim.outputs().iter().filter(|&&v| v != 0).count(), 9);
}

#[test]
fn led_command_for_a_missing_led_is_an_error() {
    let mut ring = LightRing::new(SimLedDriver::new());
    let bad = LedCommand {
        led: 9,
        rgb: Rgb::OFF,
    };
    assert_eq!(
        ring.apply(&bad),
        Err(SampleError::Device {
            device: Device::LedDriver,
            error: Error::OutOfRange { value: 9, max: 8 },
        })
    );
    assert_eq!(ring.release().latches(), 0, "nothing latched");
}
