//! Proptest strategies for every message type, shared by the property tests.
//!
//! `valid_*` strategies only produce values the decoder accepts; `any_*` strategies also produce out-of-range
//! fields (LED 0 or 9, ring sensor 8.., zero sample times, sensor commands to actuators).
#![allow(dead_code)]

use amiro_can::{
    Axis, Command, LedCommand, Message, MotorCommand, Odometry, PowerStatus, Priority, Rgb,
    SampleTime, SensorCommand, SensorData, SensorMode, TimeUnit, Topic, Velocity, MAX_PERIOD_US,
};
use proptest::prelude::*;

pub fn priority() -> impl Strategy<Value = Priority> {
    prop::sample::select(Priority::ALL.to_vec())
}

pub fn unit() -> impl Strategy<Value = TimeUnit> {
    prop::sample::select(vec![TimeUnit::Millis, TimeUnit::Seconds, TimeUnit::Micros])
}

pub fn any_sample_time() -> impl Strategy<Value = SampleTime> {
    (any::<u16>(), unit()).prop_map(|(value, unit)| SampleTime { value, unit })
}

pub fn valid_sample_time() -> impl Strategy<Value = SampleTime> {
    any_sample_time().prop_filter("zero or too long", |t| {
        t.as_micros() > 0 && t.as_micros() <= MAX_PERIOD_US
    })
}

fn mode(time: impl Strategy<Value = SampleTime>) -> impl Strategy<Value = SensorMode> {
    prop_oneof![
        Just(SensorMode::Stop),
        Just(SensorMode::Once),
        time.prop_map(SensorMode::Publish)
    ]
}

pub fn sensor_topic() -> impl Strategy<Value = Topic> {
    prop::sample::select(
        Topic::ALL
            .into_iter()
            .filter(|t| t.is_sensor())
            .collect::<Vec<_>>(),
    )
}

pub fn any_topic() -> impl Strategy<Value = Topic> {
    prop::sample::select(Topic::ALL.to_vec())
}

pub fn valid_sensor_command() -> impl Strategy<Value = SensorCommand> {
    (sensor_topic(), priority(), mode(valid_sample_time())).prop_map(|(topic, priority, mode)| {
        SensorCommand {
            topic,
            priority,
            mode,
        }
    })
}

pub fn any_sensor_command() -> impl Strategy<Value = SensorCommand> {
    (any_topic(), priority(), mode(any_sample_time())).prop_map(|(topic, priority, mode)| {
        SensorCommand {
            topic,
            priority,
            mode,
        }
    })
}

pub fn rgb() -> impl Strategy<Value = Rgb> {
    any::<[u8; 3]>().prop_map(|[r, g, b]| Rgb { r, g, b })
}

pub fn motor() -> impl Strategy<Value = MotorCommand> {
    any::<(i32, i32)>().prop_map(|(velocity_um_s, angular_urad_s)| MotorCommand {
        velocity_um_s,
        angular_urad_s,
    })
}

fn actuator_command(led: impl Strategy<Value = u8>) -> impl Strategy<Value = Command> {
    prop_oneof![
        (priority(), motor()).prop_map(|(priority, command)| Command::Motor { priority, command }),
        (priority(), led, rgb()).prop_map(|(priority, led, rgb)| Command::Led {
            priority,
            command: LedCommand { led, rgb }
        }),
    ]
}

pub fn valid_command() -> impl Strategy<Value = Command> {
    prop_oneof![
        valid_sensor_command().prop_map(Command::Sensor),
        actuator_command(1..=8u8)
    ]
}

pub fn any_command() -> impl Strategy<Value = Command> {
    prop_oneof![
        any_sensor_command().prop_map(Command::Sensor),
        actuator_command(any::<u8>())
    ]
}

pub fn odometry() -> impl Strategy<Value = Odometry> {
    (
        Odometry::MIN_100UM..=Odometry::MAX_100UM,
        Odometry::MIN_100UM..=Odometry::MAX_100UM,
        any::<u16>(),
    )
        .prop_map(|(x, y, h)| Odometry::new(x, y, h).expect("in range by construction"))
}

fn axis() -> impl Strategy<Value = Axis> {
    prop::sample::select(Axis::ALL.to_vec())
}

fn sensor_data(
    ring_index: impl Strategy<Value = u8>,
    percent: impl Strategy<Value = u8>,
) -> impl Strategy<Value = SensorData> {
    prop_oneof![
        any::<[i16; 3]>().prop_map(SensorData::Gyroscope),
        any::<[i16; 3]>().prop_map(SensorData::Accelerometer),
        (axis(), any::<i32>())
            .prop_map(|(axis, nanotesla)| SensorData::Magnetometer { axis, nanotesla }),
        any::<[u16; 4]>().prop_map(SensorData::FloorProximity),
        odometry().prop_map(SensorData::Odometry),
        any::<(i32, i32)>().prop_map(|(velocity_um_s, angular_urad_s)| SensorData::Velocity(
            Velocity {
                velocity_um_s,
                angular_urad_s
            }
        )),
        (any::<bool>(), percent, any::<u16>(), any::<u16>()).prop_map(
            |(charging, state_of_charge, minutes, power_mw)| SensorData::PowerStatus(PowerStatus {
                charging,
                state_of_charge,
                minutes,
                power_mw
            })
        ),
        (ring_index, any::<u16>())
            .prop_map(|(sensor, mm)| SensorData::ProximityRing { sensor, mm }),
    ]
}

pub fn valid_sensor_data() -> impl Strategy<Value = SensorData> {
    sensor_data(0..=7u8, 0..=100u8)
}

pub fn any_sensor_data() -> impl Strategy<Value = SensorData> {
    sensor_data(any::<u8>(), any::<u8>())
}

pub fn valid_message() -> impl Strategy<Value = Message> {
    prop_oneof![
        valid_command().prop_map(Message::Command),
        (priority(), valid_sensor_data())
            .prop_map(|(priority, data)| Message::Sample { priority, data }),
    ]
}

pub fn any_message() -> impl Strategy<Value = Message> {
    prop_oneof![
        any_command().prop_map(Message::Command),
        (priority(), any_sensor_data())
            .prop_map(|(priority, data)| Message::Sample { priority, data }),
    ]
}
