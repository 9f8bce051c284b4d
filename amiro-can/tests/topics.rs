//! Every topic encoded and decoded both ways against hand-computed bytes, the thesis example, and one bad frame for
//! every reason the decoder can give.

use amiro_can::{
    decode, decode_command, AdmissionPolicy, AdmissionVerdict, Axis, Board, CanId, Command, Count,
    DecodeError, Diagnostics, DiagnosticsPage, Frame, Kind, LedCommand, Message, MotorCommand,
    Odometry, PowerStatus, Priority, ResetCause, Rgb, SampleTime, SensorCommand, SensorData,
    SensorMode, ShutdownMode, StatusFlags, TimeUnit, Topic, Velocity, Verdict, Violation,
    REJECT_REASONS, TOPICS,
};

/// A payload of the topic's DLC the decoder accepts: all zeros, except where zero is not a valid value.
fn valid_payload(topic: Topic, dlc: u8) -> Vec<u8> {
    if topic == Topic::Shutdown {
        return vec![1, 0x55, 0xAA];
    }
    vec![0; usize::from(dlc)]
}

fn frame(id: u16, data: &[u8]) -> Frame {
    Frame::new(CanId::try_from(id).unwrap(), data).unwrap()
}

/// Asserts both directions: the bytes decode to the message, and the message encodes to the bytes.
fn both_ways(id: u16, data: &[u8], message: Message) {
    assert_eq!(decode(id, data), Ok(message), "decode {id:03X}#{data:02X?}");
    assert_eq!(message.encode(), frame(id, data), "encode {message}");
    assert_eq!(message.try_encode(), Ok(frame(id, data)));
}

fn sample(priority: Priority, data: SensorData) -> Message {
    Message::Sample { priority, data }
}

fn sensor_command(topic: Topic, priority: Priority, mode: SensorMode) -> Message {
    Message::Command(Command::Sensor(SensorCommand {
        topic,
        priority,
        mode,
    }))
}

#[test]
fn thesis_example() {
    // ID 0x205, DLC 4, 01 84 03 02: publish magnetometer x every 900 µs at medium priority.
    let expected = SensorCommand {
        topic: Topic::MagnetometerX,
        priority: Priority::Medium,
        mode: SensorMode::Publish(SampleTime {
            value: 900,
            unit: TimeUnit::Micros,
        }),
    };
    assert_eq!(
        decode_command(0x205, &[0x01, 0x84, 0x03, 0x02]),
        Ok(Command::Sensor(expected))
    );
    both_ways(
        0x205,
        &[0x01, 0x84, 0x03, 0x02],
        Message::Command(Command::Sensor(expected)),
    );
    // The board answers on 0x605 ...
    assert_eq!(expected.reply_id().raw(), 0x605);
    // ... and such a frame decodes as magnetometer-x data at medium priority.
    let answer = SensorData::Magnetometer {
        axis: Axis::X,
        nanotesla: 21_000,
    }
    .encode(Priority::Medium);
    assert_eq!(answer.id().raw(), 0x605);
    assert_eq!(
        decode(0x605, answer.data()),
        Ok(sample(
            Priority::Medium,
            SensorData::Magnetometer {
                axis: Axis::X,
                nanotesla: 21_000
            }
        ))
    );
    assert_eq!(answer.to_string(), "605#08520000");
}

#[test]
fn thesis_stop_and_once_examples() {
    // "the id of the CAN frame should be '0x204' with DLC 0: 2" — one floor-proximity sample.
    both_ways(
        0x204,
        &[2],
        sensor_command(Topic::FloorProximity, Priority::Medium, SensorMode::Once),
    );
    // "the same '0x205', with DLC 0: 0" — stop the magnetometer x publisher.
    both_ways(
        0x205,
        &[0],
        sensor_command(Topic::MagnetometerX, Priority::Medium, SensorMode::Stop),
    );
    // Mode 1 with only the mode byte: the default 50 ms (encoded back with its sample time).
    let default = sensor_command(
        Topic::Gyroscope,
        Priority::High,
        SensorMode::Publish(SampleTime::DEFAULT),
    );
    assert_eq!(decode(0x108, &[1]), Ok(default));
    assert_eq!(default.encode(), frame(0x108, &[1, 50, 0, 0]));
}

#[test]
fn every_sensor_topic_with_known_bytes() {
    use Priority::*;
    both_ways(
        0x508,
        &[0xFC, 0xFF, 0x1E, 0x00, 0x05, 0x00],
        sample(High, SensorData::Gyroscope([-4, 30, 5])),
    );
    both_ways(
        0x509,
        &[0x1A, 0x00, 0xFE, 0xFF, 0x0E, 0x04],
        sample(High, SensorData::Accelerometer([26, -2, 1038])),
    );
    both_ways(
        0x605,
        &[0xF8, 0xAD, 0xFF, 0xFF],
        sample(
            Medium,
            SensorData::Magnetometer {
                axis: Axis::X,
                nanotesla: -21_000,
            },
        ),
    );
    both_ways(
        0x706,
        &[0x00, 0x00, 0x00, 0x80],
        sample(
            Low,
            SensorData::Magnetometer {
                axis: Axis::Y,
                nanotesla: i32::MIN,
            },
        ),
    );
    both_ways(
        0x407,
        &[0xFF, 0xFF, 0xFF, 0x7F],
        sample(
            Urgent,
            SensorData::Magnetometer {
                axis: Axis::Z,
                nanotesla: i32::MAX,
            },
        ),
    );
    both_ways(
        0x504,
        &[0x01, 0x00, 0x02, 0x00, 0x03, 0x00, 0xFF, 0xFF],
        sample(High, SensorData::FloorProximity([1, 2, 3, 65_535])),
    );
    both_ways(
        0x501,
        &[0x39, 0x30, 0x00, 0xFD, 0xFF, 0xFF, 0x00, 0x40],
        sample(
            High,
            SensorData::Odometry(Odometry::new(12_345, -3, 16_384).unwrap()),
        ),
    );
    both_ways(
        0x502,
        &[0xA0, 0x86, 0x01, 0x00, 0xB0, 0x3C, 0xFF, 0xFF],
        sample(
            High,
            SensorData::Velocity(Velocity {
                velocity_um_s: 100_000,
                angular_urad_s: -50_000,
            }),
        ),
    );
    both_ways(
        0x51E,
        &[0x00, 0x3E, 0x47, 0x01, 0x72, 0x0C],
        sample(
            High,
            SensorData::PowerStatus(PowerStatus {
                charging: false,
                state_of_charge: 62,
                minutes: 327,
                power_mw: 3186,
            }),
        ),
    );
    both_ways(
        0x51E,
        &[0x01, 0x64, 0x00, 0x00, 0x00, 0x00],
        sample(
            High,
            SensorData::PowerStatus(PowerStatus {
                charging: true,
                state_of_charge: 100,
                minutes: 0,
                power_mw: 0,
            }),
        ),
    );
    for sensor in 0..8u8 {
        both_ways(
            0x51F,
            &[sensor, 0x78, 0x00],
            sample(High, SensorData::ProximityRing { sensor, mm: 120 }),
        );
    }
}

#[test]
fn every_actuator_topic_with_known_bytes() {
    both_ways(
        0x010,
        &[0xA0, 0x86, 0x01, 0x00, 0xB0, 0x3C, 0xFF, 0xFF],
        Message::Command(Command::Motor {
            priority: Priority::Urgent,
            command: MotorCommand {
                velocity_um_s: 100_000,
                angular_urad_s: -50_000,
            },
        }),
    );
    for led in 1..=8u8 {
        both_ways(
            0x310 + u16::from(led),
            &[10, 50, 120],
            Message::Command(Command::Led {
                priority: Priority::Low,
                command: LedCommand {
                    led,
                    rgb: Rgb {
                        r: 10,
                        g: 50,
                        b: 120,
                    },
                },
            }),
        );
    }
}

#[test]
fn every_topic_every_priority_every_mode() {
    for info in TOPICS {
        for priority in Priority::ALL {
            let command_id = CanId::new(Kind::Command, priority, info.topic.byte()).raw();
            let data_id = CanId::new(Kind::Sensor, priority, info.topic.byte()).raw();
            if info.is_sensor {
                for mode in [
                    SensorMode::Stop,
                    SensorMode::Once,
                    SensorMode::Publish(SampleTime {
                        value: 1,
                        unit: TimeUnit::Micros,
                    }),
                    SensorMode::Publish(SampleTime {
                        value: 65_535,
                        unit: TimeUnit::Millis,
                    }),
                    SensorMode::Publish(SampleTime {
                        value: 4_294,
                        unit: TimeUnit::Seconds,
                    }),
                ] {
                    let m = sensor_command(info.topic, priority, mode);
                    let f = m.encode();
                    assert_eq!(f.id().raw(), command_id);
                    assert_eq!(decode(command_id, f.data()), Ok(m));
                }
                // A data frame of the table's DLC decodes (all-zero is valid for every sensor payload).
                let zeros = [0u8; 8];
                let data = &zeros[..usize::from(info.dlc)];
                let m = decode(data_id, data).unwrap();
                assert_eq!(m.topic(), Ok(info.topic));
                assert_eq!(m.priority(), priority);
                assert_eq!(m.encode(), frame(data_id, data));
                assert_eq!(
                    decode_command(data_id, data),
                    Err(DecodeError::ExpectedCommand { topic: info.topic })
                );
            } else {
                let payload = valid_payload(info.topic, info.dlc);
                let data = &payload[..];
                let m = decode(command_id, data).unwrap();
                assert_eq!(m.topic(), Ok(info.topic));
                assert_eq!(m.encode(), frame(command_id, data));
                assert_eq!(
                    decode(data_id, data),
                    Err(DecodeError::SensorDataOnActuator { topic: info.topic })
                );
            }
        }
    }
}

#[test]
fn wrong_lengths_for_every_topic() {
    for info in TOPICS {
        let (id, kind) = if info.is_sensor {
            (
                CanId::new(Kind::Sensor, Priority::Low, info.topic.byte()),
                Kind::Sensor,
            )
        } else {
            (
                CanId::new(Kind::Command, Priority::Low, info.topic.byte()),
                Kind::Command,
            )
        };
        for dlc in 0..=8u8 {
            let mut data = [0u8; 8];
            let valid = valid_payload(info.topic, info.dlc);
            data[..valid.len()].copy_from_slice(&valid);
            let result = decode(id.raw(), &data[..usize::from(dlc)]);
            let topic = info.topic;
            let expected = info.dlc;
            match dlc.cmp(&info.dlc) {
                core::cmp::Ordering::Less => {
                    assert_eq!(
                        result,
                        Err(DecodeError::DlcTooShort {
                            topic,
                            frame: kind,
                            dlc,
                            expected
                        })
                    )
                }
                core::cmp::Ordering::Greater => {
                    assert_eq!(
                        result,
                        Err(DecodeError::DlcTooLong {
                            topic,
                            frame: kind,
                            dlc,
                            expected
                        })
                    )
                }
                core::cmp::Ordering::Equal => assert!(result.is_ok()),
            }
        }
    }
}

/// The DLC errors: `dlc` bytes in a `frame` on `topic`, which needs `expected`.
fn too_short(topic: Topic, frame: Kind, dlc: u8, expected: u8) -> DecodeError {
    DecodeError::DlcTooShort {
        topic,
        frame,
        dlc,
        expected,
    }
}

/// See [`too_short`].
fn too_long(topic: Topic, frame: Kind, dlc: u8, expected: u8) -> DecodeError {
    DecodeError::DlcTooLong {
        topic,
        frame,
        dlc,
        expected,
    }
}

/// Reserved bits in `byte` of a verdict request on DiWheelDrive's diagnostics topic.
fn verdict_reserved(byte: u8) -> DecodeError {
    DecodeError::ReservedBits {
        topic: Topic::DiWheelDriveDiagnostics,
        byte,
    }
}

#[test]
fn every_decode_error_reason() {
    use DecodeError as E;
    let cases: &[(u16, &[u8], DecodeError)] = &[
        (0x800, &[], E::IdOutOfRange { id: 0x800 }),
        (0xFFFF, &[1], E::IdOutOfRange { id: 0xFFFF }),
        (0x205, &[0; 9], E::FrameTooLong { len: 9 }),
        (0x203, &[0], E::UnknownTopic { topic: 0x03 }),
        (0x6FF, &[0], E::UnknownTopic { topic: 0xFF }),
        (
            0x610,
            &[0; 8],
            E::SensorDataOnActuator {
                topic: Topic::MotorCommand,
            },
        ),
        (
            0x611,
            &[0; 3],
            E::SensorDataOnActuator { topic: Topic::Led1 },
        ),
        (
            0x205,
            &[],
            too_short(Topic::MagnetometerX, Kind::Command, 0, 1),
        ),
        (
            0x205,
            &[1, 0x84],
            too_short(Topic::MagnetometerX, Kind::Command, 2, 4),
        ),
        (
            0x205,
            &[1, 0x84, 0x03],
            too_short(Topic::MagnetometerX, Kind::Command, 3, 4),
        ),
        (
            0x205,
            &[1, 0x84, 0x03, 0x02, 0],
            too_long(Topic::MagnetometerX, Kind::Command, 5, 4),
        ),
        (
            0x205,
            &[0, 0],
            too_long(Topic::MagnetometerX, Kind::Command, 2, 1),
        ),
        (
            0x204,
            &[2, 0, 0, 0],
            too_long(Topic::FloorProximity, Kind::Command, 4, 1),
        ),
        (0x208, &[3], E::BadMode { mode: 3 }),
        (0x208, &[1, 1, 0, 3], E::BadUnit { unit: 3 }),
        (0x208, &[1, 0, 0, 0], E::ZeroSampleTime),
        (0x208, &[1, 0, 0, 2], E::ZeroSampleTime),
        (
            0x208,
            &[1, 0xFF, 0xFF, 1],
            E::PeriodTooLong {
                micros: 65_535_000_000,
            },
        ),
        (0x51F, &[8, 0, 0], E::SensorIndexOutOfRange { index: 8 }),
        (
            0x51F,
            &[0xFF, 0, 0],
            E::SensorIndexOutOfRange { index: 0xFF },
        ),
        (0x51E, &[2, 50, 0, 0, 0, 0], E::BadChargingFlag { value: 2 }),
        (
            0x51E,
            &[0, 101, 0, 0, 0, 0],
            E::StateOfChargeOutOfRange { percent: 101 },
        ),
        (
            0x51A,
            &[6, 0, 0, 0, 0, 0, 0, 0],
            E::UnknownPage {
                topic: Topic::DiWheelDriveDiagnostics,
                page: 6,
            },
        ),
        (
            0x51B,
            &[0x82, 0, 0, 0, 0, 0, 0, 0],
            E::UnknownPage {
                topic: Topic::PowerManagementDiagnostics,
                page: 0x82,
            },
        ),
        // Verdict: priority-needed code 5, violation kind 3, bit 7, a shortest period without its flag.
        (
            0x41A,
            &[0x80, 0x09, 1, 0, 0b1010_0010, 0, 0, 0],
            verdict_reserved(4),
        ),
        (
            0x41A,
            &[0x80, 0x09, 1, 0, 2, 0, 0, 0b0000_1100],
            verdict_reserved(7),
        ),
        (
            0x41A,
            &[0x80, 0x09, 1, 0, 0x22, 0, 0, 0x80],
            verdict_reserved(7),
        ),
        (0x41A, &[0x80, 0x09, 1, 0, 2, 5, 0, 0], verdict_reserved(7)),
        (
            0x41A,
            &[0x80, 0x09, 1, 0, 2, 0, 0, 0b0001_0100],
            verdict_reserved(7),
        ),
        (
            0x41A,
            &[0x80, 0x03, 1, 0, 2, 0, 0, 0],
            E::UnknownTopic { topic: 0x03 },
        ),
        (0x41A, &[0x80, 0x09, 0, 0, 2, 0, 0, 0], E::ZeroSampleTime),
        (
            0x41A,
            // The shortest period's unit (the requested unit's 3 marks a one-shot request).
            &[0x80, 0x09, 1, 0, 2, 1, 0, 0x43],
            E::BadUnit { unit: 3 },
        ),
        (0x41A, &[0x80, 0x09, 1, 0, 2, 0, 0, 0x40], E::ZeroSampleTime),
        (0x21A, &[3, 2], E::BadPolicy { value: 2 }),
        (
            0x21C,
            &[3],
            too_short(Topic::LightRingDiagnostics, Kind::Command, 1, 2),
        ),
        (0x208, &[3, 1], E::BadMode { mode: 3 }),
        (0x01D, &[0, 0x55, 0xAA], E::BadShutdownMode { value: 0 }),
        (0x01D, &[5, 0x55, 0xAA], E::BadShutdownMode { value: 5 }),
        (0x01D, &[3, 0xAA, 0x55], E::BadShutdownKey { key: 0x55AA }),
        (0x01D, &[2], too_short(Topic::Shutdown, Kind::Command, 1, 3)),
        (
            0x41D,
            &[3, 0x55, 0xAA],
            E::SensorDataOnActuator {
                topic: Topic::Shutdown,
            },
        ),
    ];
    for (id, data, expected) in cases {
        assert_eq!(decode(*id, data), Err(*expected), "{id:03X}#{data:02X?}");
        // Every error has a reason name and a non-empty message.
        assert!(expected.kind_index() < DecodeError::KINDS.len());
        assert!(!expected.to_string().is_empty());
    }
    assert_eq!(
        decode_command(0x605, &[0; 4]),
        Err(E::ExpectedCommand {
            topic: Topic::MagnetometerX
        })
    );
}

#[test]
fn kinds_cover_every_variant_once() {
    use DecodeError as E;
    let t = Topic::Gyroscope;
    let all = [
        E::IdOutOfRange { id: 0 },
        E::ExtendedId { id: 0 },
        E::RemoteFrame,
        E::FrameTooLong { len: 9 },
        E::BadPriority { value: 4 },
        E::UnknownTopic { topic: 0 },
        E::SensorDataOnActuator { topic: t },
        E::ExpectedCommand { topic: t },
        E::NotASensor { topic: t },
        E::DlcTooShort {
            topic: t,
            frame: Kind::Sensor,
            dlc: 0,
            expected: 6,
        },
        E::DlcTooLong {
            topic: t,
            frame: Kind::Sensor,
            dlc: 8,
            expected: 6,
        },
        E::BadMode { mode: 9 },
        E::BadUnit { unit: 9 },
        E::ZeroSampleTime,
        E::PeriodTooLong { micros: u64::MAX },
        E::PeriodNotEncodable { micros: 65_537 },
        E::LedOutOfRange { led: 0 },
        E::SensorIndexOutOfRange { index: 8 },
        E::BadChargingFlag { value: 2 },
        E::StateOfChargeOutOfRange { percent: 101 },
        E::UnknownPage { topic: t, page: 9 },
        E::ReservedBits { topic: t, byte: 7 },
        E::BadPolicy { value: 2 },
        E::BadShutdownMode { value: 0 },
        E::BadShutdownKey { key: 0 },
    ];
    assert_eq!(all.len(), DecodeError::KINDS.len());
    for (i, e) in all.iter().enumerate() {
        assert_eq!(e.kind_index(), i, "{e:?}");
        assert_eq!(e.kind_name(), DecodeError::KINDS[i]);
    }
}

#[test]
fn display_of_decoded_frames() {
    let show = |id: u16, data: &[u8]| decode(id, data).unwrap().to_string();
    assert_eq!(
        show(0x508, &[0xFC, 0xFF, 0x1E, 0x00, 0x05, 0x00]),
        "high gyroscope x=-4 y=30 z=5 dps"
    );
    assert_eq!(
        show(0x205, &[1, 0x84, 3, 2]),
        "medium command: publish magnetometer-x every 900 µs"
    );
    assert_eq!(show(0x204, &[2]), "medium command: once floor-proximity");
    assert_eq!(show(0x31F, &[0]), "low command: stop proximity-ring");
    assert_eq!(
        show(0x113, &[10, 50, 120]),
        "high command: led 3 rgb(10,50,120)"
    );
    assert_eq!(
        show(0x010, &[0xA0, 0x86, 0x01, 0x00, 0xB0, 0x3C, 0xFF, 0xFF]),
        "urgent command: motor 100000 µm/s, -50000 µrad/s"
    );
    assert_eq!(
        show(0x71E, &[0x00, 0x3E, 0x47, 0x01, 0x72, 0x0C]),
        "low power-status discharging, 62 %, 327 min to empty, 3186 mW"
    );
    assert_eq!(
        decode(0x205, &[1, 0, 0, 0]).unwrap_err().to_string(),
        "sample time of zero"
    );
    assert_eq!(
        decode(0x205, &[1, 0x84]).unwrap_err().to_string(),
        "DLC 2 too short for magnetometer-x command frame (needs 4)"
    );
}

#[test]
fn policy_and_shutdown_commands_with_known_bytes() {
    both_ways(
        0x21A,
        &[3, 1],
        Message::Command(Command::Policy {
            priority: Priority::Medium,
            board: Board::DiWheelDrive,
            policy: AdmissionPolicy::AcceptAndWarn,
        }),
    );
    both_ways(
        0x31C,
        &[3, 0],
        Message::Command(Command::Policy {
            priority: Priority::Low,
            board: Board::LightRing,
            policy: AdmissionPolicy::Refuse,
        }),
    );
    // Modes 0..2 on a diagnostics topic stay sensor commands.
    both_ways(
        0x21B,
        &[2],
        sensor_command(
            Topic::PowerManagementDiagnostics,
            Priority::Medium,
            SensorMode::Once,
        ),
    );
    for (code, mode) in (1u8..).zip(ShutdownMode::ALL) {
        assert_eq!(mode.blt_reason(), code);
        both_ways(
            0x01D,
            &[code, 0x55, 0xAA],
            Message::Command(Command::Shutdown {
                priority: Priority::Urgent,
                mode,
            }),
        );
    }
    assert_eq!(
        decode(0x01D, &[3, 0x55, 0xAA]).unwrap().to_string(),
        "urgent command: shut the robot down (transportation)"
    );
    assert_eq!(
        decode(0x21A, &[3, 1]).unwrap().to_string(),
        "medium command: admission policy of DiWheelDrive: accept-and-warn"
    );
}

fn diagnostics(board: Board, page: DiagnosticsPage) -> SensorData {
    SensorData::Diagnostics { board, page }
}

#[test]
fn diagnostics_pages_with_known_bytes() {
    let b = Board::DiWheelDrive;
    both_ways(
        0x71A,
        &[0, 0x10, 0x0E, 0, 0, 0b0000_0110, 0b0000_1001, 3],
        sample(
            Priority::Low,
            diagnostics(
                b,
                DiagnosticsPage::Status {
                    uptime_s: 3600,
                    reset_cause: ResetCause::PIN.with(ResetCause::INDEPENDENT_WATCHDOG),
                    flags: StatusFlags::WATCHDOG.with(StatusFlags::ACCEPT_AND_WARN),
                    sensor_faults: Count::saturating(3),
                },
            ),
        ),
    );
    both_ways(
        0x71B,
        &[1, 0x40, 0x42, 0x0F, 0xFF, 0xFF, 0xFF, 25],
        sample(
            Priority::Low,
            diagnostics(
                Board::PowerManagement,
                DiagnosticsPage::Commands {
                    accepted: Count::saturating(1_000_000),
                    rejected: Count::saturating(u32::MAX),
                    reasons: 25,
                },
            ),
        ),
    );
    both_ways(
        0x61C,
        &[2, 9, 1, 0, 0, 1, 0xFF, 0xFF],
        sample(
            Priority::Medium,
            diagnostics(
                Board::LightRing,
                DiagnosticsPage::Rejections {
                    first: 9,
                    counts: [
                        Count::saturating(1),
                        Count::saturating(256),
                        Count::saturating(70_000),
                    ],
                },
            ),
        ),
    );
    both_ways(
        0x71A,
        &[3, 2, 0, 1, 0, 0x34, 0x12, 7],
        sample(
            Priority::Low,
            diagnostics(
                b,
                DiagnosticsPage::AdmissionAndReceive {
                    refused: Count::saturating(2),
                    warned: Count::saturating(1),
                    rx_dropped: Count::saturating(0x1234),
                    rx_overruns: Count::saturating(7),
                },
            ),
        ),
    );
    both_ways(
        0x71A,
        &[4, 0x01, 0x00, 0x01, 5, 0, 2, 1],
        sample(
            Priority::Low,
            diagnostics(
                b,
                DiagnosticsPage::Transmit {
                    tx_dropped: Count::saturating(0x01_0001),
                    tx_displaced: Count::saturating(5),
                    error_passive: Count::saturating(2),
                    bus_off: Count::saturating(1),
                },
            ),
        ),
    );
    // urgent 1, high 2, medium 3, low 16383: 1 | 2 << 14 | 3 << 28 | 0x3FFF << 42.
    let packed: u64 = 1 | 2 << 14 | 3 << 28 | 0x3FFF << 42;
    let mut bytes = vec![5];
    bytes.extend_from_slice(&packed.to_le_bytes()[..7]);
    both_ways(
        0x71A,
        &bytes,
        sample(
            Priority::Low,
            diagnostics(
                b,
                DiagnosticsPage::Deadlines {
                    misses: [1, 2, 3, 99_999].map(Count::saturating),
                },
            ),
        ),
    );
    assert_eq!(
        decode(0x71A, &bytes).unwrap().to_string(),
        "low diwheeldrive-diagnostics deadline misses: urgent=1 high=2 medium=3 low=16383+"
    );
}

/// The verdict example in docs/protocol.md, byte for byte.
#[test]
fn admission_verdict_example_from_the_docs() {
    let verdict = AdmissionVerdict {
        board: Board::DiWheelDrive,
        topic: Topic::Accelerometer,
        requested: SampleTime {
            value: 1,
            unit: TimeUnit::Micros,
        },
        priority: Priority::Urgent,
        verdict: Verdict::Refused,
        violation: Violation::Task { index: 6 },
        wcrt_us: Count::saturating(2000),
        deadline_us: Count::saturating(1000),
        shortest_period: Some(SampleTime {
            value: 250,
            unit: TimeUnit::Micros,
        }),
        priority_needed: None,
        searched: true,
        one_shot: false,
    };
    let [a, b] = verdict.frames(Priority::Urgent);
    assert_eq!(a.to_string(), "41A#8009010002FA0046");
    assert_eq!(b.to_string(), "41A#8106D00700E80300");
    let (
        Ok(Message::Sample {
            data:
                SensorData::Diagnostics {
                    board,
                    page: DiagnosticsPage::VerdictRequest(request),
                },
            ..
        }),
        Ok(Message::Sample {
            data:
                SensorData::Diagnostics {
                    page: DiagnosticsPage::VerdictBound(bound),
                    ..
                },
            ..
        }),
    ) = (a.decode(), b.decode())
    else {
        panic!("verdict frames decode to verdict pages");
    };
    assert_eq!(
        AdmissionVerdict::from_pages(board, &request, &bound),
        verdict
    );
    assert_eq!(
        verdict.to_string(),
        "DiWheelDrive refused \"publish accelerometer every 1 µs at urgent\": its task #6 would miss its \
         deadline (worst-case response 2000 µs, deadline 1000 µs). At urgent it accepts every 250 µs or slower; \
         no priority makes every 1 µs pass."
    );
    // A bus message violation names the frame by identifier.
    let on_bus = AdmissionVerdict {
        violation: Violation::Message {
            id: Topic::Gyroscope.data_id(Priority::High),
        },
        priority_needed: Some(Priority::Urgent),
        searched: true,
        one_shot: false,
        verdict: Verdict::AcceptedWithWarning,
        ..verdict
    };
    let [a, b] = on_bus.frames(Priority::Urgent);
    let pages = on_bus.pages();
    let (DiagnosticsPage::VerdictRequest(r), DiagnosticsPage::VerdictBound(bd)) =
        (pages[0], pages[1])
    else {
        panic!("verdict pages in order");
    };
    assert_eq!(
        AdmissionVerdict::from_pages(Board::DiWheelDrive, &r, &bd),
        on_bus
    );
    assert!(a.decode().is_ok() && b.decode().is_ok());
    assert!(on_bus.to_string().contains("high gyroscope frames (0x508)"));
    assert!(on_bus.to_string().contains("needs priority urgent"));
    // A refusal that names no deadline (the board's check out of capacity or iterations: the firmware sends no
    // culprit and 0 µs / 0 µs) does not claim a deadline would be missed at 0 µs.
    let no_verdict = AdmissionVerdict {
        violation: Violation::Unknown,
        wcrt_us: Count::saturating(0),
        deadline_us: Count::saturating(0),
        shortest_period: None,
        searched: false,
        ..verdict
    };
    assert_eq!(
        no_verdict.to_string(),
        "DiWheelDrive refused \"publish accelerometer every 1 µs at urgent\": its check reached no verdict on a \
         deadline (the set is beyond its capacity or its iteration budget, or the period is zero; the diagnostics' \
         admission reasons say which), so it refuses. The board did not search for what it would accept."
    );
    // An unnamed culprit with its bounds still says what misses.
    let unnamed = AdmissionVerdict {
        violation: Violation::Unknown,
        searched: false,
        ..verdict
    };
    assert!(unnamed
        .to_string()
        .contains("a deadline would be missed (worst-case response 2000 µs, deadline 1000 µs)"));
}

/// A board's counters survive the trip over the bus: after one full cycle of rejection windows the host's
/// picture equals the board's.
#[test]
fn diagnostics_round_trip_through_frames() {
    let mut board = Diagnostics {
        uptime_s: 42,
        reset_cause: ResetCause::POWER_ON,
        flags: StatusFlags::WATCHDOG,
        sensor_faults: 4,
        accepted: 1234,
        admission_refused: 3,
        admission_warned: 1,
        rx_dropped: 17,
        rx_overruns: 2,
        tx_dropped: 99,
        tx_displaced: 5,
        error_passive: 1,
        bus_off: 0,
        deadline_misses: [0, 1, 2, 3],
        ..Diagnostics::ZERO
    };
    for (i, count) in board.rejected.iter_mut().enumerate() {
        *count = (i as u32 + 1) * 10;
    }
    let mut host = Diagnostics::ZERO;
    let mut window = 0;
    for _ in 0..REJECT_REASONS.div_ceil(3) {
        let frames = board.frames(Board::PowerManagement, Priority::Low, window);
        assert_eq!(
            frames.len(),
            usize::from(Topic::PowerManagementDiagnostics.info().frames_per_sample)
        );
        for (page, frame) in frames.iter().enumerate() {
            assert_eq!(frame.id().raw(), 0x71B);
            assert_eq!(frame.data()[0], page as u8);
            match frame.decode() {
                Ok(Message::Sample {
                    data: SensorData::Diagnostics { board: from, page },
                    ..
                }) => {
                    assert_eq!(from, Board::PowerManagement);
                    if let DiagnosticsPage::Commands { rejected, .. } = page {
                        assert_eq!(rejected.get(), board.rejected_total());
                    }
                    host.absorb(&page);
                }
                other => panic!("diagnostics frame decoded to {other:?}"),
            }
        }
        window = Diagnostics::next_window(window);
    }
    assert_eq!(host, board);
    // Saturation, not wrap-around.
    board.deadline_misses[3] = 1 << 20;
    board.accepted = u32::MAX;
    let mut host = Diagnostics::ZERO;
    for frame in board.frames(Board::PowerManagement, Priority::Low, 0) {
        if let Ok(Message::Sample {
            data: SensorData::Diagnostics { page, .. },
            ..
        }) = frame.decode()
        {
            host.absorb(&page);
        }
    }
    assert_eq!(host.deadline_misses[3], 16_383);
    assert_eq!(host.accepted, 0xFF_FFFF);
}
