//! `amiro send` checks a publish request before it sends it, with the boards' own admission check
//! (`schedule_analysis::admission`, the code DiWheelDrive and PowerManagement run, on the table
//! lowered from the same apps and timing files): a request a board would refuse is named with the
//! reason and with what would be accepted — the shortest period at its priority and the least urgent
//! priority at its period, which the boards themselves do not search.
//!
//! What it knows to be running: the publish, stop and once commands this invocation sends, in
//! order (`amiro send` does not listen to the bus first), so it warns about a request that fails
//! even on an otherwise idle robot, or beside the requests sent with it.

use std::path::{Path, PathBuf};

use amiro_can::{Command, Message, SensorMode};
use anyhow::{anyhow, Result};
use schedule_analysis::admission::{self, Culprit, Refusal, Stream, TaskId};
use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;

/// The robot's admission table and the publishers known to run.
pub struct Checker {
    robot: OwnedRobot,
    running: Vec<Stream>,
}

/// Where the apps and timing files are: `$AMIRO_ROOT`, else the repository `amiro` was built in.
fn root() -> PathBuf {
    std::env::var_os("AMIRO_ROOT").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join(".."),
        PathBuf::from,
    )
}

impl Checker {
    /// The table lowered from the apps and timing files (an error names what is missing).
    pub fn load() -> Result<Checker> {
        let root = root();
        let robot = admission_host::lower(
            &root,
            &scenario::timing_files(&root),
            schedule_analysis::can::DEFAULT_BITRATE,
            FrameCostSpec::Exact,
        )
        .map_err(|e| {
            anyhow!(
                "the admission check needs the timing files under {}: {e}",
                root.display()
            )
        })?;
        Ok(Checker {
            robot,
            running: Vec::new(),
        })
    }

    /// Checks `message` as the board that owns its topic would, and records what it starts or stops:
    /// `Some(warning)` when that board would refuse it.
    pub fn check(&mut self, message: &Message) -> Option<String> {
        let Message::Command(Command::Sensor(command)) = message else {
            return None;
        };
        let topic = command.topic.info().name;
        let level = command.priority.name();
        let same = |s: &Stream, r: &Stream| {
            s.sender.map(|x| (x.board, x.topic)) == r.sender.map(|x| (x.board, x.topic))
        };
        let period = match command.mode {
            SensorMode::Publish(period) => period,
            SensorMode::Stop | SensorMode::Once => {
                let any = self
                    .robot
                    .publisher_stream(topic, level, Time::from_us(1), None)?;
                self.running.retain(|s| !same(s, &any));
                return None;
            }
        };
        let request = self.robot.publisher_stream(
            topic,
            level,
            Time::from_us(period.as_micros().max(1)),
            None,
        )?;
        let decision = self
            .robot
            .with_table(|t| admission::admit::<64, 64>(t, &self.running, &request, true));
        self.running.retain(|s| !same(s, &request));
        let Some(refusal) = decision.refusal else {
            self.running.push(request);
            return None;
        };
        let board = command.topic.info().board;
        let mut text = format!(
            "{board} would refuse \"publish {topic} every {period} at {level}\": {}",
            self.reason(&refusal)
        );
        let s = decision.suggestion;
        text.push_str(&match s.shortest_period {
            Some(p) => format!(
                " It would accept {topic} at {level} every {} or slower",
                micros(p)
            ),
            None => format!(" No period passes at {level}"),
        });
        text.push_str(&match s
            .level
            .and_then(|l| amiro_can::Priority::ALL.get(usize::from(l)))
        {
            Some(p) => format!("; every {period} it would accept it at {p} priority."),
            None => format!("; no priority makes every {period} pass."),
        });
        Some(text)
    }

    fn reason(&self, refusal: &Refusal) -> String {
        match refusal {
            Refusal::Deadline(v) => {
                let what = match v.culprit {
                    Culprit::Task { board, task } => {
                        let board = self
                            .robot
                            .boards
                            .get(usize::from(board))
                            .map_or("a board", |b| b.name.as_str());
                        match task {
                            TaskId::Fixed(i) => format!("{board}'s task #{i}"),
                            TaskId::Publisher(t) => {
                                format!("{board}'s publisher job of topic 0x{t:02X}")
                            }
                            TaskId::Timer(t) => {
                                format!("{board}'s timer job of the publisher of topic 0x{t:02X}")
                            }
                        }
                    }
                    Culprit::Frame { id } => format!("the frames 0x{id:03X} on the bus"),
                    Culprit::EndToEnd { id } => format!("the command 0x{id:03X} end to end"),
                };
                let wcrt = v.wcrt.map_or("unbounded".to_string(), |w| {
                    format!("{} in the worst case", micros(w))
                });
                format!(
                    "{what} would miss its deadline ({wcrt}, deadline {}).",
                    micros(v.deadline)
                )
            }
            Refusal::Capacity => "the robot's table cannot hold another publisher.".to_string(),
            Refusal::ZeroPeriod => "a zero period.".to_string(),
        }
    }
}

fn micros(t: Time) -> String {
    let us = t.as_ns().div_ceil(1000);
    if us >= 10_000 && us.is_multiple_of(1000) {
        format!("{} ms", us / 1000)
    } else {
        format!("{us} µs")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn publish(text: &str) -> Message {
        crate::describe::decode_frame(&crate::frame::parse_compact(text).expect("frame"))
            .expect("valid")
    }

    #[test]
    fn the_starvation_request_is_named_with_what_would_pass() {
        let mut checker = Checker::load().expect("the repository's timing files");
        // Issue 11: accelerometer every 1 µs at urgent.
        let warning = checker.check(&publish("009#01010002")).expect("refused");
        assert!(warning.contains("DiWheelDrive would refuse"), "{warning}");
        assert!(
            warning.contains("It would accept accelerometer at urgent every"),
            "{warning}"
        );
        // The thesis example passes; beside it a 2 ms gyroscope does not (the board's CPU would be
        // overloaded), once it is stopped the gyroscope does.
        assert_eq!(checker.check(&publish("205#01840302")), None);
        assert!(checker.check(&publish("208#01020000")).is_some());
        assert_eq!(checker.check(&publish("205#00")), None);
        assert_eq!(checker.check(&publish("208#01020000")), None);
    }
}
