//! Proptest strategies for every message type, shared by the property tests.
//!
//! `valid_*` strategies only produce values the decoder accepts; `any_*` strategies also produce out-of-range
//! fields (LED 0 or 9, ring sensor 8.., zero sample times, sensor commands to actuators).
#![allow(dead_code)]

use amiro_can::{
    AdmissionPolicy, Axis, Board, CanId, Command, Count, DiagnosticsPage, Kind, LedCommand,
    Message, MotorCommand, Odometry, PowerStatus, Priority, ResetCause, Rgb, SampleTime,
    SensorCommand, SensorData, SensorMode, ShutdownMode, StatusFlags, TimeUnit, Topic, Velocity,
    Verdict, VerdictBound, VerdictRequest, ViolationKind, MAX_PERIOD_US,
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

pub fn board() -> impl Strategy<Value = Board> {
    prop::sample::select(Board::ALL.to_vec())
}

fn actuator_command(led: impl Strategy<Value = u8>) -> impl Strategy<Value = Command> {
    prop_oneof![
        (priority(), motor()).prop_map(|(priority, command)| Command::Motor { priority, command }),
        (priority(), board(), any::<bool>()).prop_map(|(priority, board, warn)| Command::Policy {
            priority,
            board,
            policy: if warn {
                AdmissionPolicy::AcceptAndWarn
            } else {
                AdmissionPolicy::Refuse
            },
        }),
        (priority(), prop::sample::select(ShutdownMode::ALL.to_vec()))
            .prop_map(|(priority, mode)| Command::Shutdown { priority, mode }),
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

fn count<const BITS: u32>() -> impl Strategy<Value = Count<BITS>> {
    prop_oneof![
        Just(Count::<BITS>::ZERO),
        Just(Count::<BITS>::saturating(u32::MAX)),
        any::<u32>().prop_map(Count::saturating),
        (0..=Count::<BITS>::MAX).prop_map(Count::saturating),
    ]
}

fn verdict_request(
    time: fn() -> BoxedStrategy<SampleTime>,
) -> impl Strategy<Value = VerdictRequest> {
    (
        (
            any_topic(),
            time(),
            priority(),
            any::<bool>(),
            any::<bool>(),
        ),
        (
            prop::option::of(priority()),
            prop::option::of(time()),
            prop_oneof![
                Just(ViolationKind::Unknown),
                Just(ViolationKind::Task),
                priority().prop_map(|priority| ViolationKind::Message { priority }),
            ],
        ),
    )
        .prop_map(
            |(
                (topic, requested, priority, warn, one_shot),
                (priority_needed, shortest_period, violation),
            )| {
                // A one-shot's interval is in ms (its unit bits say "one-shot").
                let requested = match one_shot {
                    true => {
                        amiro_can::SampleTime::new(requested.value, amiro_can::TimeUnit::Millis)
                            .unwrap_or(requested)
                    }
                    false => requested,
                };
                let one_shot = one_shot && requested.unit == amiro_can::TimeUnit::Millis;
                VerdictRequest {
                    one_shot,
                    topic,
                    requested,
                    priority,
                    verdict: if warn {
                        Verdict::AcceptedWithWarning
                    } else {
                        Verdict::Refused
                    },
                    searched: priority_needed.is_some() || shortest_period.is_some() || warn,
                    priority_needed,
                    shortest_period,
                    violation,
                }
            },
        )
}

pub fn diagnostics_page(
    time: fn() -> BoxedStrategy<SampleTime>,
) -> impl Strategy<Value = DiagnosticsPage> {
    prop_oneof![
        (any::<u32>(), any::<u8>(), any::<u8>(), count::<8>()).prop_map(
            |(uptime_s, cause, flags, sensor_faults)| DiagnosticsPage::Status {
                uptime_s,
                reset_cause: ResetCause::from_bits(cause),
                flags: StatusFlags::from_bits(flags),
                sensor_faults,
            }
        ),
        (count::<24>(), count::<24>(), any::<u8>()).prop_map(|(accepted, rejected, reasons)| {
            DiagnosticsPage::Commands {
                accepted,
                rejected,
                reasons,
            }
        }),
        (any::<u8>(), count::<16>(), count::<16>(), count::<16>()).prop_map(|(first, a, b, c)| {
            DiagnosticsPage::Rejections {
                first,
                counts: [a, b, c],
            }
        }),
        (count::<16>(), count::<16>(), count::<16>(), count::<8>()).prop_map(
            |(refused, warned, rx_dropped, rx_overruns)| DiagnosticsPage::AdmissionAndReceive {
                refused,
                warned,
                rx_dropped,
                rx_overruns,
            }
        ),
        (count::<24>(), count::<16>(), count::<8>(), count::<8>()).prop_map(
            |(tx_dropped, tx_displaced, error_passive, bus_off)| DiagnosticsPage::Transmit {
                tx_dropped,
                tx_displaced,
                error_passive,
                bus_off,
            }
        ),
        (count::<14>(), count::<14>(), count::<14>(), count::<14>()).prop_map(|(a, b, c, d)| {
            DiagnosticsPage::Deadlines {
                misses: [a, b, c, d],
            }
        }),
        verdict_request(time).prop_map(DiagnosticsPage::VerdictRequest),
        (any::<u8>(), count::<24>(), count::<24>()).prop_map(|(violated, wcrt_us, deadline_us)| {
            DiagnosticsPage::VerdictBound(VerdictBound {
                violated,
                wcrt_us,
                deadline_us,
            })
        }),
    ]
}

fn boxed_valid_time() -> BoxedStrategy<SampleTime> {
    valid_sample_time().boxed()
}

fn boxed_any_time() -> BoxedStrategy<SampleTime> {
    any_sample_time().boxed()
}

/// A sensor-data identifier of a topic byte at a priority: the id of a violated message.
pub fn data_id() -> impl Strategy<Value = CanId> {
    (priority(), any::<u8>()).prop_map(|(p, t)| CanId::new(Kind::Sensor, p, t))
}

fn sensor_data(
    ring_index: impl Strategy<Value = u8>,
    percent: impl Strategy<Value = u8>,
    time: fn() -> BoxedStrategy<SampleTime>,
) -> impl Strategy<Value = SensorData> {
    prop_oneof![
        (board(), diagnostics_page(time))
            .prop_map(|(board, page)| SensorData::Diagnostics { board, page }),
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
    sensor_data(0..=7u8, 0..=100u8, boxed_valid_time)
}

pub fn any_sensor_data() -> impl Strategy<Value = SensorData> {
    sensor_data(any::<u8>(), any::<u8>(), boxed_any_time)
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
