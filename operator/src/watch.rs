//! The receiver's view of a bus, shared by `monitor`, `run`, `drive` and the console: which frames to show
//! (filters), when they arrived (seconds since the start, as the thesis's receiver prints, or absolute), where a
//! proximity sensor sits (named positions), and what the traffic looked like (frames, period and jitter per topic).

use std::collections::BTreeMap;

use amiro_can::{Board, Message, SensorData, Topic, TOPICS};
use serde_json::{json, Value};

use crate::describe::{decode_frame, json_record, text_line};
use crate::frame::{FrameId, LoggedFrame, RawFrame, Timestamp};
use crate::period::human_micros;

/// Floor sensors by their index in the protocol's floor frame (amiro-boards.md §4a: mux channel = index).
pub const FLOOR_POSITIONS: [&str; 4] = ["front-right", "right-wheel", "left-wheel", "front-left"];

/// Proximity-ring sensors by the index their frames carry (amiro-boards.md §5, the 1.x index).
pub const RING_POSITIONS: [&str; 8] = [
    "rear-left",
    "left-rear",
    "left-front",
    "front-left",
    "front-right",
    "right-front",
    "right-rear",
    "rear-right",
];

/// The position of floor sensor `index` (0..3), or `?` for an index no frame can carry.
pub fn floor_position(index: usize) -> &'static str {
    FLOOR_POSITIONS.get(index).copied().unwrap_or("?")
}

/// The position of ring sensor `index` (0..7).
pub fn ring_position(index: u8) -> &'static str {
    RING_POSITIONS
        .get(usize::from(index))
        .copied()
        .unwrap_or("?")
}

/// Which frames to show. Empty lists admit everything.
#[derive(Clone, Debug, Default)]
pub struct Filter {
    /// Only frames of topics these boards own.
    pub boards: Vec<Board>,
    /// Only frames of these topics.
    pub topics: Vec<Topic>,
    /// Only sensor data (C/S = 1), as the thesis's receiver shows.
    pub sensor_data_only: bool,
}

impl Filter {
    /// Whether the frame passes. Judged on the identifier alone, so a malformed frame of a watched topic is
    /// still shown (with its error).
    pub fn admits(&self, frame: &RawFrame) -> bool {
        let FrameId::Standard(id) = frame.id() else {
            return self.boards.is_empty() && self.topics.is_empty() && !self.sensor_data_only;
        };
        if self.sensor_data_only && id & 0x400 == 0 {
            return false;
        }
        let topic = Topic::try_from((id & 0xFF) as u8).ok();
        if !self.topics.is_empty() && !topic.is_some_and(|topic| self.topics.contains(&topic)) {
            return false;
        }
        if !self.boards.is_empty() {
            let board = topic.and_then(owner);
            if !board.is_some_and(|board| self.boards.contains(&board)) {
                return false;
            }
        }
        true
    }
}

/// The board that owns a topic, from amiro-can's table.
pub fn owner(topic: Topic) -> Option<Board> {
    TOPICS
        .iter()
        .find(|info| info.topic == topic)
        .map(|info| info.board)
}

/// How arrival times are printed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeBase {
    /// Seconds since `origin` (the start of the session, or the first frame of a log).
    Relative {
        /// `None` until the first frame sets it.
        origin: Option<Timestamp>,
    },
    /// The timestamps as received (seconds since the epoch on a live bus).
    Absolute,
}

/// Microseconds from `origin` to `at`, never negative.
fn since(origin: Timestamp, at: Timestamp) -> u64 {
    at.as_micros().saturating_sub(origin.as_micros())
}

/// `12.345678`: seconds with six decimals.
pub fn seconds(micros: u64) -> String {
    Timestamp::from_micros(micros).to_string()
}

/// Formats frames for people or programs.
#[derive(Clone, Debug)]
pub struct View {
    /// How times are printed.
    pub time: TimeBase,
    /// JSON Lines instead of English.
    pub json: bool,
}

impl View {
    /// The line for one frame (English or one JSON object).
    pub fn line(&mut self, logged: &LoggedFrame) -> String {
        let decoded = decode_frame(&logged.frame);
        let elapsed = match (&mut self.time, logged.timestamp) {
            (TimeBase::Relative { origin }, Some(at)) => Some(since(*origin.get_or_insert(at), at)),
            _ => None,
        };
        if self.json {
            let mut record = json_record(logged, None, &decoded);
            if let (Value::Object(map), Some(elapsed)) = (&mut record, elapsed) {
                map.insert("elapsed".into(), json!(seconds(elapsed)));
            }
            if let (Value::Object(map), Ok(Message::Sample { data, .. })) = (&mut record, &decoded)
            {
                match data {
                    SensorData::FloorProximity(_) => {
                        map.insert("positions".into(), json!(FLOOR_POSITIONS));
                    }
                    SensorData::ProximityRing { sensor, .. } => {
                        map.insert("position".into(), json!(ring_position(*sensor)));
                    }
                    _ => {}
                }
            }
            return record.to_string();
        }
        let mut line = match elapsed {
            Some(elapsed) => {
                let bare = LoggedFrame {
                    timestamp: None,
                    ..logged.clone()
                };
                format!("({:>11}) {}", seconds(elapsed), text_line(&bare, &decoded))
            }
            None => text_line(logged, &decoded),
        };
        if let Ok(Message::Sample { data, .. }) = &decoded {
            if let Some(named) = named_values(data) {
                let marker = format!("{}: ", data.topic());
                if let Some(start) = line.find(&marker) {
                    line.truncate(start + marker.len());
                    line.push_str(&named);
                }
            }
        }
        line
    }
}

/// The values of floor and ring frames with each sensor's number and position; `None` for other data.
/// Both use the protocol's index, from 0, so "floor 3" and "ring 3" are read the same way.
pub fn named_values(data: &SensorData) -> Option<String> {
    match data {
        SensorData::FloorProximity(counts) => Some(format!(
            "{} (raw proximity counts)",
            counts
                .iter()
                .enumerate()
                .map(|(index, count)| format!("{index} {} {count}", floor_position(index)))
                .collect::<Vec<_>>()
                .join(", ")
        )),
        SensorData::ProximityRing { sensor, mm } => Some(format!(
            "sensor {sensor} {} sees {mm} mm",
            ring_position(*sensor)
        )),
        _ => None,
    }
}

/// What is counted together: one identifier, and for the proximity ring one sensor (its eight frames share an
/// identifier and leave together, so their period is per sensor).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct StreamKey {
    id: String,
    ring_sensor: Option<u8>,
}

#[derive(Clone, Debug)]
struct Stream {
    label: String,
    frames: u64,
    last: Option<Timestamp>,
    intervals: u64,
    interval_sum: u64,
    interval_min: u64,
    interval_max: u64,
}

/// Frames, observed period and jitter per stream, for the summary a monitor prints on exit.
#[derive(Clone, Debug, Default)]
pub struct Statistics {
    streams: BTreeMap<StreamKey, Stream>,
    first: Option<Timestamp>,
    last: Option<Timestamp>,
    frames: u64,
}

impl Statistics {
    /// Counts one frame.
    pub fn record(&mut self, logged: &LoggedFrame) {
        self.frames += 1;
        let decoded = decode_frame(&logged.frame);
        let ring_sensor = match &decoded {
            Ok(Message::Sample {
                data: SensorData::ProximityRing { sensor, .. },
                ..
            }) => Some(*sensor),
            _ => None,
        };
        let label = match &decoded {
            Ok(message) => {
                let kind = match message {
                    Message::Command(_) => "command",
                    Message::Sample { .. } => "sensor",
                };
                let topic = message.topic().map(Topic::name).unwrap_or("?");
                match ring_sensor {
                    Some(sensor) => format!(
                        "{topic} {sensor} {} ({kind}, {})",
                        ring_position(sensor),
                        message.priority().name()
                    ),
                    None => format!("{topic} ({kind}, {})", message.priority().name()),
                }
            }
            Err(error) => format!("invalid: {}", error.kind_name()),
        };
        let key = StreamKey {
            id: logged.frame.id_hex().to_string(),
            ring_sensor,
        };
        let stream = self.streams.entry(key).or_insert_with(|| Stream {
            label,
            frames: 0,
            last: None,
            intervals: 0,
            interval_sum: 0,
            interval_min: u64::MAX,
            interval_max: 0,
        });
        stream.frames += 1;
        if let Some(at) = logged.timestamp {
            if let Some(last) = stream.last {
                let interval = since(last, at);
                stream.intervals += 1;
                stream.interval_sum += interval;
                stream.interval_min = stream.interval_min.min(interval);
                stream.interval_max = stream.interval_max.max(interval);
            }
            stream.last = Some(at);
            self.first.get_or_insert(at);
            self.last = Some(at);
        }
    }

    /// Number of frames counted.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The summary as lines of text: one per identifier (per sensor for the ring) with its count, mean period,
    /// shortest and longest interval, and jitter (longest minus shortest interval).
    pub fn summary(&self) -> Vec<String> {
        let span = match (self.first, self.last) {
            (Some(first), Some(last)) => format!(" in {} s", seconds(since(first, last))),
            _ => String::new(),
        };
        let mut lines = vec![format!("summary: {} frames{span}", self.frames)];
        if self.streams.is_empty() {
            return lines;
        }
        lines.push(format!(
            "  {:<4} {:<44} {:>7} {:>12} {:>12} {:>12} {:>12}",
            "id", "topic", "frames", "period", "shortest", "longest", "jitter"
        ));
        for (key, stream) in &self.streams {
            let (period, shortest, longest, jitter) =
                match stream.interval_sum.checked_div(stream.intervals) {
                    None => ("-".into(), "-".into(), "-".into(), "-".into()),
                    Some(mean) => (
                        human_micros(mean),
                        human_micros(stream.interval_min),
                        human_micros(stream.interval_max),
                        human_micros(stream.interval_max - stream.interval_min),
                    ),
                };
            lines.push(format!(
                "  {:<4} {:<44} {:>7} {:>12} {:>12} {:>12} {:>12}",
                key.id, stream.label, stream.frames, period, shortest, longest, jitter
            ));
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_line;

    fn logged(text: &str) -> LoggedFrame {
        parse_line(text).unwrap().unwrap()
    }

    #[test]
    fn times_are_relative_to_the_first_frame_unless_absolute() {
        let mut view = View {
            time: TimeBase::Relative { origin: None },
            json: false,
        };
        let first = view.line(&logged("(1700000010.000000) can0 608#FCFF1E00FBFF"));
        let second = view.line(&logged("(1700000012.500100) can0 608#FCFF1E00FBFF"));
        assert!(first.starts_with("(   0.000000) can0 608#"), "{first}");
        assert!(second.starts_with("(   2.500100) can0 608#"), "{second}");
        let mut absolute = View {
            time: TimeBase::Absolute,
            json: false,
        };
        let line = absolute.line(&logged("(1700000012.500100) can0 608#FCFF1E00FBFF"));
        assert!(line.starts_with("(1700000012.500100) can0"), "{line}");
        let mut json = View {
            time: TimeBase::Relative { origin: None },
            json: true,
        };
        let record: Value =
            serde_json::from_str(&json.line(&logged("(5.000000) can0 205#00"))).unwrap();
        assert_eq!(record["elapsed"], "0.000000");
        assert_eq!(record["timestamp"], "5.000000");
    }

    #[test]
    fn floor_and_ring_sensors_are_named_with_one_numbering() {
        let mut view = View {
            time: TimeBase::Absolute,
            json: false,
        };
        let floor = view.line(&logged("604#0100020003000400"));
        assert!(
            floor.ends_with(
                "floor-proximity: 0 front-right 1, 1 right-wheel 2, 2 left-wheel 3, 3 front-left 4 (raw proximity counts)"
            ),
            "{floor}"
        );
        let ring = view.line(&logged("71F#037800"));
        assert!(
            ring.ends_with("proximity-ring: sensor 3 front-left sees 120 mm"),
            "{ring}"
        );
        let ring = view.line(&logged("71F#007800"));
        assert!(ring.contains("sensor 0 rear-left"), "{ring}");
        let mut json = View {
            time: TimeBase::Absolute,
            json: true,
        };
        let record: Value = serde_json::from_str(&json.line(&logged("71F#047800"))).unwrap();
        assert_eq!(record["position"], "front-right");
        let record: Value =
            serde_json::from_str(&json.line(&logged("604#0100020003000400"))).unwrap();
        assert_eq!(record["positions"][3], "front-left");
    }

    #[test]
    fn filters_select_by_board_topic_and_kind() {
        let frame = |text: &str| crate::frame::parse_compact(text).unwrap();
        let gyro_data = frame("608#FCFF1E00FBFF");
        let gyro_command = frame("108#010A0000");
        let ring = frame("71F#037800");
        let led = frame("313#FF8000");
        let by_board = Filter {
            boards: vec![Board::PowerManagement],
            ..Filter::default()
        };
        assert!(by_board.admits(&ring) && !by_board.admits(&gyro_data) && !by_board.admits(&led));
        let by_topic = Filter {
            topics: vec![Topic::Gyroscope],
            ..Filter::default()
        };
        assert!(
            by_topic.admits(&gyro_data)
                && by_topic.admits(&gyro_command)
                && !by_topic.admits(&ring)
        );
        let sensor_only = Filter {
            sensor_data_only: true,
            ..Filter::default()
        };
        assert!(sensor_only.admits(&gyro_data) && !sensor_only.admits(&gyro_command));
        assert!(!sensor_only.admits(&frame("12345678#00")));
        assert!(Filter::default().admits(&frame("12345678#00")));
        // A malformed frame of a watched topic is still shown.
        assert!(by_topic.admits(&frame("608#FC")));
    }

    #[test]
    fn the_summary_gives_period_and_jitter_per_stream() {
        let mut statistics = Statistics::default();
        for (time, frame) in [
            ("10.000000", "608#FCFF1E00FBFF"),
            ("10.000000", "71F#037800"),
            ("10.000000", "71F#047800"),
            ("10.010000", "608#FCFF1E00FBFF"),
            ("10.021000", "608#FCFF1E00FBFF"),
            ("10.062500", "71F#037800"),
            ("10.062500", "71F#047800"),
        ] {
            statistics.record(&logged(&format!("({time}) can0 {frame}")));
        }
        let summary = statistics.summary();
        assert_eq!(summary[0], "summary: 7 frames in 0.062500 s");
        let gyro = summary
            .iter()
            .find(|line| line.contains("gyroscope"))
            .unwrap();
        // Intervals 10 ms and 11 ms: mean 10.5 ms, jitter 1 ms.
        for expected in ["608", "3", "10.5 ms", "10 ms", "11 ms", "1 ms"] {
            assert!(gyro.contains(expected), "{expected} in {gyro}");
        }
        let ring: Vec<_> = summary
            .iter()
            .filter(|line| line.contains("proximity-ring"))
            .collect();
        assert_eq!(ring.len(), 2, "{summary:#?}");
        assert!(
            ring[0].contains("3 front-left") && ring[0].contains("62.5 ms"),
            "{}",
            ring[0]
        );
        assert!(ring[0].ends_with("0 µs"), "no jitter: {}", ring[0]);
    }
}
