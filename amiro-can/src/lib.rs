//! The AMiRo robot's CAN protocol: the single source of truth for identifiers, topics, commands and payloads.
//!
//! Every board, the schedule analysis and the operator tool use this crate and nothing else to build or read a
//! frame. It is `no_std`, allocation-free and HAL-free; [`decode`] never panics on anything from the bus.
//!
//! ```
//! use amiro_can::{decode, Command, Message, Priority, SampleTime, SensorCommand, SensorMode, TimeUnit, Topic};
//!
//! // The thesis's example: start the magnetometer-x publisher every 900 µs at medium priority.
//! let message = decode(0x205, &[0x01, 0x84, 0x03, 0x02]).unwrap();
//! let expected = Message::Command(Command::Sensor(SensorCommand {
//!     topic: Topic::MagnetometerX,
//!     priority: Priority::Medium,
//!     mode: SensorMode::Publish(SampleTime { value: 900, unit: TimeUnit::Micros }),
//! }));
//! assert_eq!(message, expected);
//! assert_eq!(message.encode().data(), &[0x01, 0x84, 0x03, 0x02]);
//! ```
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]

pub mod candump;
mod command;
mod diagnostics;
pub mod duration;
mod error;
mod frame;
mod id;
mod message;
mod payload;
pub mod signals;
pub mod slcan;
pub mod timing;
mod topic;
mod wire;

#[cfg(feature = "bxcan")]
pub mod bxcan_frame;
#[cfg(feature = "embedded-can")]
pub mod embedded_frame;

pub use command::{
    AdmissionPolicy, Command, LedCommand, MotorCommand, Rgb, SampleTime, SensorCommand, SensorMode,
    ShutdownMode, TimeUnit, MAX_PERIOD_US, ONE_SHOT_INTERVAL_MS, POLICY_MODE, SHUTDOWN_KEY,
};
pub use diagnostics::{
    reason_name, AdmissionVerdict, Count, Diagnostics, DiagnosticsPage, RefusalReason, ResetCause,
    StatusFlags, Verdict, VerdictBound, VerdictRequest, Violation, ViolationKind, COUNTED_REASONS,
    PAGES_PER_SAMPLE, REFUSAL_REASONS, REJECTIONS_PER_SAMPLE, REJECT_REASONS, VERDICT_BOUND_PAGE,
    VERDICT_PAGE,
};
pub use error::DecodeError;
pub use frame::Frame;
pub use id::{CanId, Kind, Priority};
pub use message::{decode, decode_command, Message};
pub use payload::{Axis, Odometry, PowerStatus, SensorData, Velocity};
pub use topic::{Board, Topic, TopicInfo, TOPICS, TOPIC_COUNT};
