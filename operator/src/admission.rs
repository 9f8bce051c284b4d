//! The robot's admission check on the operator's computer: the boards' own check
//! (`schedule_analysis::admission`, the code the boards run, on the table lowered from the same apps and
//! timing files), fed with what `amiro` has heard on the bus.
//!
//! * **What runs** is learned as the boards learn it: every publish, stop and once command heard (or sent by
//!   this `amiro`) is decided as the owner board decides it and kept when the owner would start it; each board's
//!   policy comes from the policy commands heard. A publisher whose command was never heard (started before
//!   `amiro` listened) is learned from its sensor data: its topic and CAN priority from the identifier, its
//!   period from the samples' spacing (three samples at least; kept while it keeps sending). Those periods are
//!   measurements, and the text says so.
//! * **Before a request is sent** (`amiro send`, the console) a request the owner board would refuse is named
//!   with the reason and with what would be accepted — the shortest period at its priority and the least urgent
//!   priority at its period, which the boards do not search.
//! * **A verdict heard** (the two pages 0x80/0x81 on a board's diagnostics topic) becomes one sentence, the task
//!   named from the table and, when the board did not search, what would be accepted searched here.

use std::path::{Path, PathBuf};

use amiro_can::{
    AdmissionPolicy, AdmissionVerdict, Board, Command, DiagnosticsPage, Message, Priority,
    SensorData, SensorMode, Topic, Verdict, VerdictRequest, Violation,
};
use anyhow::{anyhow, Result};
use schedule_analysis::admission::{self, Culprit, Refusal, Stream, Suggestion, TaskId};
use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::scenario;
use schedule_analysis::time::Time;

use crate::describe::decode_frame;
use crate::frame::LoggedFrame;

/// A one-shot request is decided as a sample every this long (the boards' one-shot interval).
const ONE_SHOT_PERIOD: Time = Time::from_us(amiro_can::ONE_SHOT_INTERVAL_MS as u64 * 1000);

/// Samples of a publisher heard before its period is taken from their spacing.
const SAMPLES_FOR_A_PERIOD: u64 = 3;

/// Capacities of the host's check (far above the protocol's limit of running publishers).
const JOBS: usize = 64;
const STREAMS: usize = 64;

/// A publisher learned from its sensor data.
#[derive(Debug, Clone, Copy)]
struct Observed {
    topic: Topic,
    priority: Priority,
    frames: u64,
    first_sample_us: u64,
    last_sample_us: u64,
    last_frame_us: u64,
}

impl Observed {
    /// The first frame of a publisher heard at `now`.
    fn first(topic: Topic, priority: Priority, now: u64) -> Self {
        Self {
            topic,
            priority,
            frames: 1,
            first_sample_us: now,
            last_sample_us: now,
            last_frame_us: now,
        }
    }

    fn samples(&self) -> u64 {
        self.frames / u64::from(self.topic.info().frames_per_sample.max(1))
    }

    /// The mean spacing of the samples heard, once there are enough.
    fn period_us(&self) -> Option<u64> {
        let samples = self.samples();
        (samples >= SAMPLES_FOR_A_PERIOD)
            .then(|| (self.last_sample_us - self.first_sample_us) / (samples - 1))
            .filter(|p| *p > 0)
    }
}

/// The robot's admission table and what `amiro` knows to be running on it.
pub struct Checker {
    robot: OwnedRobot,
    /// Publishers started by commands, in the order the boards keep them.
    running: Vec<Stream>,
    /// Publishers learned from their data alone.
    observed: Vec<Observed>,
    policies: [AdmissionPolicy; 3],
    /// A verdict's first page, per board, until its second arrives.
    pending: [Option<VerdictRequest>; 3],
    /// The robot revision whose tables the check lowered (`--revision`; the texts name it).
    revision: String,
}

/// The robot revisions whose boards the check knows (`--revision`): a 1-1 robot's boards are the models
/// folder's timing files, a 1-2 robot's their namesakes in `models/rev-1-2/` (docs/boards.md).
pub const REVISIONS: [&str; 2] = ["1-1", "1-2"];

/// The robot revision the check uses: `revision` (`--revision`), else `AMIRO_REVISION` where it names one of
/// [`REVISIONS`], else 1-1 (the models folder's files).
fn revision_or_default(revision: Option<&str>) -> String {
    let env = std::env::var(scenario::REVISION_ENV).ok();
    revision
        .or(env.as_deref().filter(|r| REVISIONS.contains(r)))
        .unwrap_or(REVISIONS[0])
        .to_string()
}

/// Where the apps and timing files are: `$AMIRO_ROOT`, else the repository `amiro` was built in.
fn root() -> PathBuf {
    std::env::var_os("AMIRO_ROOT").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join(".."),
        PathBuf::from,
    )
}

fn slot(board: Board) -> usize {
    match board {
        Board::DiWheelDrive => 0,
        Board::PowerManagement => 1,
        Board::LightRing => 2,
    }
}

fn sender_of(stream: &Stream) -> Option<(u8, u8)> {
    stream.sender.map(|s| (s.board, s.topic))
}

impl Checker {
    /// The table of a robot of `revision` (`--revision`, else `AMIRO_REVISION` where it names one of
    /// [`REVISIONS`], else 1-1) lowered from the apps and timing files, as the boards' build scripts lower it (an
    /// error names what is missing).
    pub fn load(revision: Option<&str>) -> Result<Checker> {
        let root = root();
        let revision = revision_or_default(revision);
        if !REVISIONS.contains(&revision.as_str()) {
            return Err(anyhow!(
                "unknown robot revision {revision:?} (known: {})",
                REVISIONS.join(", ")
            ));
        }
        let robot = admission_host::lower_robot_for(&root, Some(&revision)).map_err(|e| {
            anyhow!(
                "the admission check needs the timing files under {}: {e}",
                root.display()
            )
        })?;
        Ok(Checker {
            revision,
            robot,
            running: Vec::new(),
            observed: Vec::new(),
            policies: [AdmissionPolicy::Refuse; 3],
            pending: [None; 3],
        })
    }

    /// What the check assumes runs: `(topic, priority, period, measured)` per publisher, commanded ones first.
    pub fn known(&self) -> Vec<(Topic, Priority, Time, bool)> {
        let commanded = self.running.iter().filter_map(|s| {
            let sender = s.sender?;
            let topic = Topic::from_byte(sender.topic)?;
            let priority = *Priority::ALL.get(usize::from(sender.level))?;
            Some((topic, priority, s.period, false))
        });
        let measured = self.observed.iter().filter_map(|o| {
            let period = o.period_us()?;
            self.commanded(o.topic).is_none().then_some((
                o.topic,
                o.priority,
                Time::from_us(period),
                true,
            ))
        });
        commanded.chain(measured).collect()
    }

    fn commanded(&self, topic: Topic) -> Option<usize> {
        self.running
            .iter()
            .position(|s| s.sender.is_some_and(|x| x.topic == topic.byte()))
    }

    fn stream(&self, topic: Topic, priority: Priority, period: Time) -> Option<Stream> {
        self.robot
            .publisher_stream(topic.info().name, priority.name(), period, None)
    }

    /// Every publisher the check assumes, as streams: the commanded ones in the boards' order, then the ones
    /// learned from their data.
    fn streams(&self) -> Vec<Stream> {
        let mut streams = self.running.clone();
        for o in &self.observed {
            if self.commanded(o.topic).is_some() {
                continue;
            }
            if let Some(stream) = o
                .period_us()
                .and_then(|p| self.stream(o.topic, o.priority, Time::from_us(p)))
            {
                streams.push(stream);
            }
        }
        streams
    }

    fn remove(&mut self, topic: Topic) {
        self.running
            .retain(|s| s.sender.is_none_or(|x| x.topic != topic.byte()));
        self.observed.retain(|o| o.topic != topic);
    }

    /// In place when it runs already (the boards keep their order), else at the end.
    fn upsert(&mut self, stream: Stream) {
        self.observed
            .retain(|o| Some(o.topic.byte()) != stream.sender.map(|s| s.topic));
        match self
            .running
            .iter()
            .position(|s| sender_of(s) == sender_of(&stream))
        {
            Some(i) => self.running[i] = stream,
            None => self.running.push(stream),
        }
    }

    fn decide(&self, request: &Stream, suggest: bool) -> admission::Decision {
        let streams = self.streams();
        self.robot
            .with_table(|t| admission::admit::<JOBS, STREAMS>(t, &streams, request, suggest))
    }

    /// Applies a command as the boards do: a publish request is decided as its owner decides it and kept when
    /// the owner starts it (admitted, or refused under accept-and-warn); stop and once end the publisher.
    /// Returns the request's decision, when it was one.
    fn apply(&mut self, command: &Command, suggest: bool) -> Option<(Stream, admission::Decision)> {
        let command = match command {
            Command::Policy { board, policy, .. } => {
                self.policies[slot(*board)] = *policy;
                return None;
            }
            Command::Sensor(command) => command,
            _ => return None,
        };
        let period = match command.mode {
            SensorMode::Publish(period) => Time::from_us(period.as_micros().max(1)),
            // Decided as the boards decide it: a sample every one-shot interval, in place of the
            // topic's publisher (which it stops).
            SensorMode::Once => ONE_SHOT_PERIOD,
            SensorMode::Stop => {
                self.remove(command.topic);
                return None;
            }
        };
        let request = self.stream(command.topic, command.priority, period)?;
        let decision = self.decide(&request, suggest);
        // Accept-and-warn starts a refused request only above the hard floor (a bounded publisher miss).
        let warn = self.policies[slot(command.topic.info().board)]
            == AdmissionPolicy::AcceptAndWarn
            && decision.floor.is_none();
        if decision.refusal.is_none() || warn {
            match command.mode {
                SensorMode::Once => self.remove(command.topic),
                _ => self.upsert(request),
            }
        }
        Some((request, decision))
    }

    /// Checks `message` (about to be sent) as the board that owns its topic would, and records what it starts
    /// or stops: `Some(warning)` when that board would refuse it (or start it only with a warning).
    pub fn check(&mut self, message: &Message) -> Option<String> {
        let Message::Command(command) = message else {
            return None;
        };
        let (request, decision) = self.apply(command, true)?;
        let first = decision.refusal?;
        let Command::Sensor(sensor) = command else {
            return None;
        };
        let board = sensor.topic.info().board;
        let topic = sensor.topic.info().name;
        let level = sensor.priority.name();
        let (decided, refusal) = match (self.policies[slot(board)], decision.floor) {
            (AdmissionPolicy::AcceptAndWarn, None) => ("would start, with a warning,", first),
            (AdmissionPolicy::AcceptAndWarn, Some(floor)) => (
                "would refuse (below the hard floor, whatever the policy)",
                floor,
            ),
            (AdmissionPolicy::Refuse, _) => ("would refuse", first),
        };
        let mut text = match sensor.mode {
            SensorMode::Publish(period) => {
                let mut text = format!(
                    "{board} on a {} robot {decided} \"publish {topic} every {period} at {level}\": {}",
                    self.revision,
                    self.reason(&refusal, &request)
                );
                text.push_str(&self.suggestion_text(
                    &decision.suggestion,
                    sensor.priority,
                    &period.to_string(),
                ));
                text
            }
            _ => {
                let mut text = format!(
                    "{board} on a {} robot {decided} \"once {topic} at {level}\" (a sample every {}): {}",
                    self.revision,
                    micros(ONE_SHOT_PERIOD),
                    self.reason(&refusal, &request)
                );
                text.push_str(&self.level_text(&decision.suggestion));
                text
            }
        };
        text.push_str(&self.measured_note());
        Some(text)
    }

    /// A frame heard on the bus: commands and sensor data teach what runs; the second page of an admission
    /// verdict returns the verdict in plain English.
    pub fn heard(&mut self, logged: &LoggedFrame) -> Option<String> {
        let message = decode_frame(&logged.frame).ok()?;
        match message {
            Message::Command(command) => {
                self.apply(&command, false);
                None
            }
            Message::Sample {
                data: SensorData::Diagnostics { board, page },
                ..
            } => match page {
                DiagnosticsPage::VerdictRequest(request) => {
                    self.pending[slot(board)] = Some(request);
                    None
                }
                DiagnosticsPage::VerdictBound(bound) => {
                    let request = self.pending[slot(board)].take()?;
                    let verdict = AdmissionVerdict::from_pages(board, &request, &bound);
                    Some(self.explain(&verdict))
                }
                // A diagnostics publisher: six pages per sample.
                _ => {
                    self.observe(board.diagnostics_topic(), message.priority(), logged);
                    None
                }
            },
            Message::Sample { priority, data } => {
                self.observe(data.topic(), priority, logged);
                None
            }
        }
    }

    fn observe(&mut self, topic: Topic, priority: Priority, logged: &LoggedFrame) {
        let Some(now) = logged.timestamp.map(|t| t.as_micros()) else {
            return;
        };
        // Publishers that fell silent for three periods (and a second) are gone.
        self.observed.retain(|o| {
            o.period_us()
                .is_none_or(|p| now.saturating_sub(o.last_frame_us) <= 3 * p + 1_000_000)
        });
        let per_sample = u64::from(topic.info().frames_per_sample.max(1));
        match self.observed.iter_mut().find(|o| o.topic == topic) {
            Some(o) if o.priority == priority && now >= o.last_frame_us => {
                if o.frames.is_multiple_of(per_sample) {
                    o.last_sample_us = now;
                }
                o.frames += 1;
                o.last_frame_us = now;
            }
            // Re-prioritised (or a log that goes back in time): start over.
            Some(o) => *o = Observed::first(topic, priority, now),
            None => self.observed.push(Observed::first(topic, priority, now)),
        }
    }

    /// A verdict heard from a board, in plain English: what would miss its deadline, named from the table, and
    /// what would be accepted (the board's search, or one made here from what `amiro` has heard).
    pub fn explain(&self, verdict: &AdmissionVerdict) -> String {
        let decided = match verdict.verdict {
            Verdict::Refused => "refused",
            Verdict::AcceptedWithWarning => "started, with a warning,",
        };
        let what = match verdict.violation {
            Violation::Unknown => "a task or frame".to_string(),
            Violation::Task { index } => self.task_name(verdict, index),
            Violation::Message { id } => match Topic::from_byte(id.topic_byte()) {
                Some(topic) => format!(
                    "the {} {topic} frames (0x{:03X}) on the bus",
                    id.priority(),
                    id.raw()
                ),
                None => format!("the frames 0x{:03X} on the bus", id.raw()),
            },
        };
        let request = if verdict.one_shot {
            format!(
                "once {} at {}\" (a sample every {})",
                verdict.topic, verdict.priority, verdict.requested
            )
        } else {
            format!(
                "publish {} every {} at {}\"",
                verdict.topic, verdict.requested, verdict.priority
            )
        };
        let mut text = format!(
            "{} {decided} \"{request}: {what} would miss its deadline (worst case {}, deadline {}).",
            verdict.board,
            micros_u24(verdict.wcrt_us.get()),
            micros_u24(verdict.deadline_us.get()),
        );
        if verdict.searched {
            text.push_str(&match verdict.shortest_period {
                Some(p) => format!(" At {} it accepts every {p} or slower;", verdict.priority),
                None => format!(" No period passes at {};", verdict.priority),
            });
            text.push_str(&match verdict.priority_needed {
                Some(p) => format!(" every {} needs {p} priority.", verdict.requested),
                None => format!(" no priority makes every {} pass.", verdict.requested),
            });
            return text;
        }
        let searched = self
            .stream(
                verdict.topic,
                verdict.priority,
                Time::from_us(verdict.requested.as_micros().max(1)),
            )
            .map(|request| self.decide(&request, true).suggestion);
        match searched {
            Some(s) => {
                text.push_str(" Searched by amiro from what it has heard on the bus:");
                if verdict.one_shot {
                    text.push_str(&self.level_text(&s));
                } else {
                    text.push_str(&self.suggestion_text(
                        &s,
                        verdict.priority,
                        &verdict.requested.to_string(),
                    ));
                }
                text.push_str(&self.measured_note());
            }
            None => text.push_str(" The board did not search for what it would accept."),
        }
        text
    }

    /// The task a verdict names by its index in the board's analysis: a fixed task of the table, or the job or
    /// timer job of one of the board's publishers (in the order the board keeps them, the request last).
    fn task_name(&self, verdict: &AdmissionVerdict, index: u8) -> String {
        let folder = scenario::board_folder(verdict.board);
        let Some((b, table)) = self
            .robot
            .boards
            .iter()
            .enumerate()
            .find(|(_, t)| t.name == folder)
        else {
            return format!("its task #{index}");
        };
        let index = usize::from(index);
        if let Some(name) = table.task_names.get(index) {
            return format!("its task {name}");
        }
        let per_stream = 1 + usize::from(table.monotonic.is_some());
        let mut topics: Vec<u8> = self
            .streams()
            .iter()
            .filter_map(|s| {
                s.sender
                    .filter(|x| usize::from(x.board) == b)
                    .map(|x| x.topic)
            })
            .filter(|t| *t != verdict.topic.byte())
            .collect();
        topics.push(verdict.topic.byte());
        let k = index - table.task_names.len();
        let topic = topics
            .get(k / per_stream)
            .and_then(|t| Topic::from_byte(*t))
            .map_or_else(
                || "a publisher".to_string(),
                |t| format!("the {t} publisher"),
            );
        if per_stream == 2 && k % per_stream == 0 {
            format!("the timer job of {topic}")
        } else {
            format!("the job of {topic}")
        }
    }

    fn reason(&self, refusal: &Refusal, request: &Stream) -> String {
        match refusal {
            Refusal::Deadline(v) => {
                let what = match v.culprit {
                    Culprit::Task { board, task } => {
                        let table = self.robot.boards.get(usize::from(board));
                        let board = table.map_or("a board".to_string(), |t| board_name(&t.name));
                        let topic = |t: u8| {
                            Topic::from_byte(t).map_or(format!("0x{t:02X}"), |t| t.to_string())
                        };
                        match task {
                            TaskId::Fixed(i) => {
                                match table.and_then(|t| t.task_names.get(usize::from(i))) {
                                    Some(name) => format!("{board}'s task {name}"),
                                    None => format!("{board}'s task #{i}"),
                                }
                            }
                            TaskId::Publisher(t) => {
                                format!("{board}'s publisher job of {}", topic(t))
                            }
                            TaskId::Timer(t) => {
                                format!("{board}'s timer job of the {} publisher", topic(t))
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
            Refusal::ZeroPeriod => format!("a zero period (frames 0x{:03X}).", request.id),
            Refusal::Budget => format!(
                "its analysis needs more than the boards' {} fixed-point iterations per decision (a load this close to 100 % is refused without a verdict on its deadlines).",
                schedule_analysis::admission::DECISION_ITERATIONS
            ),
        }
    }

    fn suggestion_text(&self, s: &Suggestion, priority: Priority, requested: &str) -> String {
        let level = priority.name();
        let mut text = match s.shortest_period {
            Some(p) => format!(" At {level} it would accept every {} or slower", micros(p)),
            None => format!(" No period passes at {level}"),
        };
        text.push_str(
            &match s.level.and_then(|l| Priority::ALL.get(usize::from(l))) {
                Some(p) => format!("; every {requested} it would accept at {p} priority."),
                None => format!("; no priority makes every {requested} pass."),
            },
        );
        text
    }

    /// What a one-shot would need: the least urgent level that passes.
    fn level_text(&self, s: &Suggestion) -> String {
        match s.level.and_then(|l| Priority::ALL.get(usize::from(l))) {
            Some(p) => format!(" It would accept it at {p} priority."),
            None => " No priority makes it pass.".to_string(),
        }
    }

    /// Says which running publishers' periods were measured rather than commanded.
    fn measured_note(&self) -> String {
        let measured: Vec<String> = self
            .known()
            .into_iter()
            .filter(|k| k.3)
            .map(|(topic, priority, period, _)| {
                format!("{topic} at {priority} every ~{}", micros(period))
            })
            .collect();
        if measured.is_empty() {
            String::new()
        } else {
            format!(
                " (Periods measured from the bus, not commanded: {}.)",
                measured.join(", ")
            )
        }
    }
}

/// A board's name as the project spells it (`DiWheelDrive`), from the table's firmware folder.
fn board_name(folder: &str) -> String {
    [
        Board::DiWheelDrive,
        Board::PowerManagement,
        Board::LightRing,
    ]
    .into_iter()
    .find(|b| scenario::board_folder(*b) == folder)
    .map_or_else(|| folder.to_string(), |b| b.to_string())
}

/// A [`Checker`] made only when it is needed: `amiro monitor` keeps the frames that teach what runs (commands and
/// sensor data, the newest [`Lazy::HISTORY`]) and lowers the table and replays them when the first admission verdict
/// completes, so watching a bus starts at once.
#[derive(Default)]
pub struct Lazy {
    /// `--revision` (see [`Checker::load`]).
    revision: Option<String>,
    history: std::collections::VecDeque<LoggedFrame>,
    checker: Option<Checker>,
    unavailable: bool,
}

impl Lazy {
    /// Frames kept before the first verdict.
    pub const HISTORY: usize = 50_000;

    /// A check of a robot of `revision` (`--revision`; see [`Checker::load`]), lowered at the first verdict.
    pub fn new(revision: Option<&str>) -> Self {
        Self {
            revision: revision.map(str::to_string),
            ..Self::default()
        }
    }

    /// A frame heard: the verdict in one sentence when it completes one (see [`Checker::heard`]).
    pub fn heard(&mut self, logged: &LoggedFrame) -> Option<String> {
        if let Some(checker) = self.checker.as_mut() {
            return checker.heard(logged);
        }
        if self.unavailable {
            return None;
        }
        let completes_a_verdict = matches!(
            decode_frame(&logged.frame),
            Ok(Message::Sample {
                data: SensorData::Diagnostics {
                    page: DiagnosticsPage::VerdictBound(_),
                    ..
                },
                ..
            })
        );
        if self.history.len() == Self::HISTORY {
            self.history.pop_front();
        }
        self.history.push_back(logged.clone());
        if !completes_a_verdict {
            return None;
        }
        let Ok(mut checker) = Checker::load(self.revision.as_deref()) else {
            self.unavailable = true;
            self.history.clear();
            return None;
        };
        let mut said = None;
        for frame in std::mem::take(&mut self.history) {
            said = checker.heard(&frame);
        }
        self.checker = Some(checker);
        said
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

/// A verdict's 24-bit microsecond field (saturated at 16.78 s: that long or longer, or unbounded).
fn micros_u24(us: u32) -> String {
    if us >= 0xFF_FFFF {
        "16.78 s or more".to_string()
    } else {
        micros(Time::from_us(u64::from(us)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{parse_compact, Timestamp};

    fn message(text: &str) -> Message {
        decode_frame(&parse_compact(text).expect("frame")).expect("valid")
    }

    fn at(us: u64, text: &str) -> LoggedFrame {
        LoggedFrame {
            timestamp: Some(Timestamp {
                secs: us / 1_000_000,
                micros: (us % 1_000_000) as u32,
            }),
            interface: None,
            frame: parse_compact(text).expect("frame"),
        }
    }

    #[test]
    fn the_starvation_request_is_named_with_what_would_pass() {
        let mut checker = Checker::load(None).expect("the repository's timing files");
        // Issue 11: accelerometer every 1 µs at urgent.
        let warning = checker.check(&message("009#01010002")).expect("refused");
        assert!(
            warning.contains("DiWheelDrive on a 1-1 robot would refuse"),
            "{warning}"
        );
        assert!(
            warning.contains("At urgent it would accept every"),
            "{warning}"
        );
        // The thesis example (magnetometer-x every 900 µs) does not fit (on a 1-1 robot it needs at least 3 572 µs
        // since DiWheelDrive 1-1's publisher rows and its transmit jobs are the machine code's, 2026-12-06); every
        // 7 ms it passes, and beside it
        // a gyroscope every 2 ms at medium does not (the magnetometer's job at its level delays its frames past
        // their deadline); once it is stopped the gyroscope does.
        assert!(checker.check(&message("205#01840302")).is_some());
        assert_eq!(checker.check(&message("205#01581B02")), None);
        assert!(checker.check(&message("208#01D00702")).is_some());
        assert_eq!(checker.check(&message("205#00")), None);
        assert_eq!(checker.check(&message("208#01D00702")), None);
    }

    #[test]
    fn the_check_uses_the_named_revisions_tables() {
        // The two robots' tables no longer dominate one another (DiWheelDrive 1-1's rows are the machine code's,
        // 1-2's BNO055 budgets stated; docs/boards.md): some request on a DiWheelDrive topic is decided one way on
        // a 1-1 robot and the other way on a 1-2 robot, so the check must know which robot it speaks for.
        let decided_on = |revision: &str| {
            let checker = Checker::load(Some(revision)).expect("the repository's timing files");
            let mut decisions = Vec::new();
            for topic in [Topic::MagnetometerX, Topic::Gyroscope, Topic::Odometry] {
                for priority in Priority::ALL {
                    for ms in 1..=10 {
                        let Some(request) =
                            checker.stream(topic, priority, Time::from_us(ms * 1000))
                        else {
                            continue;
                        };
                        decisions.push(checker.decide(&request, false).refusal.is_none());
                    }
                }
            }
            decisions
        };
        let (one_one, one_two) = (decided_on("1-1"), decided_on("1-2"));
        assert_eq!(one_one.len(), one_two.len());
        assert!(!one_one.is_empty());
        assert_ne!(one_one, one_two);
        // The texts name the robot.
        let mut checker = Checker::load(Some("1-2")).expect("the repository's timing files");
        let warning = checker.check(&message("009#01010002")).expect("refused");
        assert!(
            warning.contains("DiWheelDrive on a 1-2 robot would refuse"),
            "{warning}"
        );
        // A revision the check does not know is a typed error, not the 1-1 tables.
        let error = Checker::load(Some("1-3")).err().expect("refused");
        assert!(
            error.to_string().contains("unknown robot revision \"1-3\""),
            "{error}"
        );
    }

    #[test]
    fn what_runs_is_learned_from_commands_and_data_heard() {
        let mut checker = Checker::load(None).expect("the repository's timing files");
        // Magnetometer-x every 7 ms heard as a command: the gyroscope every 2 ms is then refused.
        assert_eq!(checker.heard(&at(0, "205#01581B02")), None);
        assert!(checker.check(&message("208#01D00702")).is_some());

        // Without the command: magnetometer-x data at medium every 7 ms teaches the same.
        let mut checker = Checker::load(None).expect("the repository's timing files");
        assert_eq!(checker.check(&message("208#01D00702")), None, "idle robot");
        checker.heard(&at(0, "208#00"));
        for k in 0..10 {
            checker.heard(&at(1_000 + k * 7_000, "605#00000000"));
        }
        let known = checker.known();
        assert_eq!(known.len(), 1, "{known:?}");
        assert_eq!(known[0].0, Topic::MagnetometerX);
        assert_eq!(known[0].1, Priority::Medium);
        assert_eq!(known[0].2, Time::from_us(7_000));
        assert!(known[0].3, "measured");
        let warning = checker.check(&message("208#01D00702")).expect("refused");
        assert!(warning.contains("measured from the bus"), "{warning}");
        // A stop heard ends it.
        checker.heard(&at(70_000, "205#00"));
        assert!(checker.known().is_empty());
    }

    #[test]
    fn a_policy_heard_decides_whether_a_refused_request_runs() {
        let mut checker = Checker::load(None).expect("the repository's timing files");
        checker.heard(&at(0, "21A#0301")); // DiWheelDrive: accept-and-warn
                                           // The two-frame attack: below the hard floor, refused whatever the policy.
        let refusal = checker.check(&message("009#01010002")).expect("refused");
        assert!(refusal.contains("below the hard floor"), "{refusal}");
        assert!(checker.known().is_empty(), "not started");
        // A bounded publisher miss is started with a warning: beside magnetometer-x every 7 ms, PowerManagement's
        // ring every 65 ms (15 ms until its ring row, 34.9 ms a release with the polled buses' waits, was used,
        // 2026-12-06; 6 ms and 10 ms until DiWheelDrive's `can_tx` was used), then its power status every 5 ms under accept-and-warn (after scenario
        // admission-decisions, whose thesis request and 7 ms ring the sound transmit path refuses, 2026-12-05;
        // every 1.2 ms until DiWheelDrive 1-1's publisher rows were the machine code's, 2026-12-06).
        checker.heard(&at(0, "205#01581B02"));
        assert!(checker.check(&message("21F#01410000")).is_none());
        checker.heard(&at(0, "21B#0301"));
        let warning = checker.check(&message("21E#01050000")).expect("warned");
        assert!(
            warning.contains("would start, with a warning,"),
            "{warning}"
        );
        assert_eq!(checker.known().len(), 3, "started anyway");
    }

    #[test]
    fn a_verdict_heard_is_one_sentence_with_the_task_named_and_a_search() {
        let mut checker = Checker::load(None).expect("the repository's timing files");
        let verdict = AdmissionVerdict {
            board: Board::DiWheelDrive,
            topic: Topic::Accelerometer,
            requested: amiro_can::SampleTime::from_micros(1).expect("1 µs"),
            priority: Priority::Urgent,
            verdict: Verdict::Refused,
            violation: Violation::Task { index: 0 },
            wcrt_us: amiro_can::Count::saturating(u32::MAX),
            deadline_us: amiro_can::Count::saturating(1),
            shortest_period: None,
            priority_needed: None,
            searched: false,
            one_shot: false,
        };
        let frames = verdict.frames(Priority::Urgent);
        let mut said = Vec::new();
        for (k, frame) in frames.iter().enumerate() {
            let raw = crate::frame::RawFrame::data_frame(
                crate::frame::FrameId::Standard(frame.id().raw()),
                frame.data(),
            )
            .expect("frame");
            said.extend(checker.heard(&LoggedFrame {
                timestamp: Some(Timestamp {
                    secs: 1,
                    micros: k as u32,
                }),
                interface: None,
                frame: raw,
            }));
        }
        assert_eq!(said.len(), 1, "{said:?}");
        let text = &said[0];
        let first = &checker.robot.boards[0].task_names[0];
        assert!(
            text.starts_with("DiWheelDrive refused \"publish accelerometer every 1 µs at urgent\""),
            "{text}"
        );
        assert!(text.contains(&format!("its task {first}")), "{text}");
        assert!(text.contains("16.78 s or more"), "{text}");
        assert!(text.contains("Searched by amiro"), "{text}");
        assert!(text.contains("At urgent it would accept every"), "{text}");
    }
}
