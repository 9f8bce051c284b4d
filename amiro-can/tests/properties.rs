//! Property tests: decode(encode(x)) == x for every message type, no input panics the decoder, and the encoder
//! never produces a frame that decodes to something other than what was encoded.

mod strategies;

use amiro_can::{
    decode, decode_command, CanId, Command, DecodeError, Frame, Kind, Message, SensorData,
};
use proptest::prelude::*;
use strategies::*;

fn round_trip(message: Message) -> Result<Message, DecodeError> {
    let frame = message.encode();
    decode(frame.id().raw(), frame.data())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4096))]

    #[test]
    fn sensor_commands_round_trip(command in valid_sensor_command()) {
        let message = Message::Command(Command::Sensor(command));
        prop_assert_eq!(round_trip(message), Ok(message));
        let frame = command.encode();
        prop_assert_eq!(decode_command(frame.id().raw(), frame.data()), Ok(Command::Sensor(command)));
    }

    #[test]
    fn actuator_and_all_commands_round_trip(command in valid_command()) {
        prop_assert_eq!(round_trip(Message::Command(command)), Ok(Message::Command(command)));
        prop_assert_eq!(command.try_encode(), Ok(command.encode()));
    }

    #[test]
    fn sensor_data_round_trips(priority in priority(), data in valid_sensor_data()) {
        let frame = data.encode(priority);
        prop_assert_eq!(frame.id().kind(), Kind::Sensor);
        prop_assert_eq!(frame.dlc(), data.topic().info().dlc);
        prop_assert_eq!(
            decode(frame.id().raw(), frame.data()),
            Ok(Message::Sample { priority, data })
        );
    }

    #[test]
    fn messages_round_trip(message in valid_message()) {
        prop_assert_eq!(round_trip(message), Ok(message));
        prop_assert_eq!(message.try_encode().map(|f| f.decode()), Ok(Ok(message)));
    }

    /// Even with out-of-range fields, the encoder never makes a frame that decodes to a *different* message, and
    /// `try_encode` refuses exactly the messages whose frames would be rejected.
    #[test]
    fn encoding_never_lies(message in any_message()) {
        let decoded = round_trip(message);
        if let Ok(back) = decoded {
            prop_assert_eq!(back, message);
        }
        prop_assert_eq!(message.try_encode().is_ok(), decoded.is_ok());
    }

    #[test]
    fn odometry_survives_micrometre_units(o in odometry()) {
        let back = amiro_can::Odometry::from_micrometres(
            i64::from(o.x_um()),
            i64::from(o.y_um()),
            i64::from(o.heading_urad()),
        );
        prop_assert_eq!(back, Some(o));
    }

    #[test]
    fn decode_never_panics(id in any::<u16>(), data in prop::collection::vec(any::<u8>(), 0..=12)) {
        let result = decode(id, &data);
        let command = decode_command(id, &data);
        match result {
            Ok(message) => {
                // Anything accepted re-encodes to a frame that decodes to the same message.
                prop_assert_eq!(round_trip(message), Ok(message));
                prop_assert!(!message.to_string().is_empty());
                match message {
                    Message::Command(c) => prop_assert_eq!(command, Ok(c)),
                    Message::Sample { data, .. } => {
                        prop_assert_eq!(command, Err(DecodeError::ExpectedCommand { topic: data.topic() }))
                    }
                }
            }
            Err(e) => {
                prop_assert!(e.kind_index() < DecodeError::KINDS.len());
                prop_assert!(!e.to_string().is_empty());
                prop_assert!(command.is_err());
            }
        }
        if data.len() > 8 && id <= 0x7FF {
            prop_assert_eq!(result, Err(DecodeError::FrameTooLong { len: data.len() }));
        }
    }

    /// Valid frames of every known topic (a known topic byte, the right DLC) decode, except for the few field
    /// values the protocol forbids; those give their reason. This drives the decoder deep instead of mostly
    /// hitting "unknown topic".
    #[test]
    fn structured_frames(topic in any_topic(), priority in priority(), kind in any::<bool>(), bytes in any::<[u8; 8]>(), dlc in 0..=8usize) {
        let kind = if kind { Kind::Sensor } else { Kind::Command };
        let id = CanId::new(kind, priority, topic.byte());
        let data = &bytes[..dlc];
        match decode(id.raw(), data) {
            Ok(message) => {
                prop_assert_eq!(message.priority(), priority);
                prop_assert_eq!(message.topic(), Ok(topic));
                prop_assert_eq!(message.kind(), kind);
                let again = message.encode();
                prop_assert_eq!(again.id(), id);
                prop_assert_eq!(again.decode(), Ok(message));
                // Byte-exact except a DLC-1 publish, which is re-encoded with its (default) sample time.
                if !(kind == Kind::Command && topic.is_sensor() && dlc == 1 && bytes[0] == 1) {
                    prop_assert_eq!(again, Frame::new(id, data).unwrap());
                }
            }
            Err(e) => prop_assert!(e.kind_index() < DecodeError::KINDS.len()),
        }
    }

    #[test]
    fn sensor_data_validate_matches_decoder(priority in priority(), data in any_sensor_data()) {
        let frame = data.encode(priority);
        prop_assert_eq!(data.validate().is_ok(), frame.decode() == Ok(Message::Sample { priority, data }));
        prop_assert_eq!(SensorData::decode(data.topic(), frame.data()).is_ok(), data.validate().is_ok());
    }
}
