//! Commands from the words of the command line (`publish gyroscope --every 10ms --priority high`) to messages.
//!
//! Only the period needs more than a lookup (see `period`); everything else is validated by amiro-can's own
//! `try_encode`, so `encode` can never print a frame the robot would reject.

use amiro_can::{
    Command, LedCommand, Message, MotorCommand, Priority, SampleTime, SensorCommand, SensorMode,
    TimeUnit, Topic, MAX_PERIOD_US,
};
use anyhow::{Context, Result};

use crate::cli::MessageArgs;
use crate::frame::{FrameId, RawFrame};
use crate::period::{encode_period, parse_period, PeriodUnit};

/// The message the arguments describe.
pub fn message(args: &MessageArgs) -> Result<Message> {
    let sensor = |topic: Topic, priority: Priority, mode: SensorMode| {
        Message::Command(Command::Sensor(SensorCommand {
            topic,
            priority,
            mode,
        }))
    };
    Ok(match args {
        MessageArgs::Publish {
            topic,
            every,
            priority,
        } => {
            let sample_time = sample_time(every)
                .with_context(|| format!("cannot publish {topic} every {every}"))?;
            sensor(*topic, *priority, SensorMode::Publish(sample_time))
        }
        MessageArgs::Stop { topic, priority } => sensor(*topic, *priority, SensorMode::Stop),
        MessageArgs::Once { topic, priority } => sensor(*topic, *priority, SensorMode::Once),
        MessageArgs::Motor {
            velocity,
            angular,
            priority,
        } => Message::Command(Command::Motor {
            priority: *priority,
            command: MotorCommand {
                velocity_um_s: *velocity,
                angular_urad_s: *angular,
            },
        }),
        MessageArgs::Led { led, rgb, priority } => Message::Command(Command::Led {
            priority: *priority,
            command: LedCommand::new(*led, *rgb).map_err(|error| anyhow::anyhow!("{error}"))?,
        }),
        MessageArgs::Shutdown { mode, priority } => Message::Command(Command::Shutdown {
            priority: *priority,
            mode: *mode,
        }),
        MessageArgs::Policy {
            board,
            policy,
            priority,
        } => Message::Command(Command::Policy {
            priority: *priority,
            board: *board,
            policy: *policy,
        }),
    })
}

/// The wire sample time for a period typed by the user.
pub fn sample_time(text: &str) -> Result<SampleTime> {
    let encoded = encode_period(parse_period(text)?, MAX_PERIOD_US)?;
    let unit = match encoded.unit {
        PeriodUnit::Micros => TimeUnit::Micros,
        PeriodUnit::Millis => TimeUnit::Millis,
        PeriodUnit::Seconds => TimeUnit::Seconds,
    };
    // amiro-can has the last word on what the firmware accepts.
    SampleTime::new(encoded.value, unit).map_err(|error| anyhow::anyhow!("{error}"))
}

/// The frame of a message, refusing anything the decoder would reject.
pub fn frame(message: &Message) -> Result<RawFrame> {
    let frame = message
        .try_encode()
        .map_err(|error| anyhow::anyhow!("{error}"))?;
    RawFrame::data_frame(FrameId::Standard(frame.id().raw()), frame.data())
        .context("amiro-can produced a frame that is not a classic CAN frame")
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_can::Rgb;

    fn encoded(args: MessageArgs) -> String {
        frame(&message(&args).unwrap()).unwrap().to_string()
    }

    #[test]
    fn the_thesis_example_encodes_exactly() {
        let args = MessageArgs::Publish {
            topic: Topic::MagnetometerX,
            every: "900us".into(),
            priority: Priority::Medium,
        };
        assert_eq!(encoded(args), "205#01840302");
    }

    #[test]
    fn every_command_form_encodes() {
        assert_eq!(
            encoded(MessageArgs::Stop {
                topic: Topic::Gyroscope,
                priority: Priority::Low
            }),
            "308#00"
        );
        assert_eq!(
            encoded(MessageArgs::Once {
                topic: Topic::FloorProximity,
                priority: Priority::Medium
            }),
            "204#02"
        );
        assert_eq!(
            encoded(MessageArgs::Motor {
                velocity: 100_000,
                angular: -50_000,
                priority: Priority::High
            }),
            "110#A0860100B03CFFFF"
        );
        assert_eq!(
            encoded(MessageArgs::Led {
                led: 3,
                rgb: Rgb {
                    r: 255,
                    g: 128,
                    b: 0
                },
                priority: Priority::Low
            }),
            "313#FF8000"
        );
        let publish = MessageArgs::Publish {
            topic: Topic::PowerStatus,
            every: "70000us".into(),
            priority: Priority::Urgent,
        };
        assert_eq!(encoded(publish), "01E#01460000");
    }

    #[test]
    fn bad_periods_are_errors_with_the_reason() {
        let publish = MessageArgs::Publish {
            topic: Topic::Gyroscope,
            every: "0ms".into(),
            priority: Priority::Low,
        };
        let error = format!("{:#}", message(&publish).unwrap_err());
        assert!(
            error.contains("cannot publish gyroscope every 0ms") && error.contains("zero"),
            "{error}"
        );
    }
}
