//! MCAP recordings (`amiro record`, `monitor --record`, `decode --mcap`) for Foxglove and the ROS 2 tool world.
//!
//! Every frame goes to the channel `/amiro/frames` (its `decode --json` record: frame, id, data, meaning or the
//! reason it is wrong). A decoded sample also goes to its topic's channel, `/amiro/gyroscope`, …, as a flat JSON
//! object of its values in protocol units with the field names of `decode --json` plus `priority`, so Foxglove plots
//! `/amiro/gyroscope.x_dps` with no set-up; a decoded command goes to `/amiro/<topic>/command`. Every channel has a
//! JSON schema generated from amiro-can's topic table and `describe::value_fields`. A message's log time (and
//! publish time) is its frame's time in nanoseconds: the bus's reception time, or the log line's timestamp.
//!
//! A virtual robot's run in a world (`cargo xtask robot --world`, docs/world.md) adds its arena once on
//! `/world/arena` (`foxglove.SceneUpdate`: walls, obstacles, floor) and its pose at every trajectory row on
//! `/world/pose` (`foxglove.PoseInFrame`), in the frame `world`, so Foxglove's 3D panel shows the robot moving;
//! the messages are amiro-world's (`amiro_world::foxglove`), the poses interleaved with the frames by time.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use amiro_can::{Message, Priority, Topic, TOPICS};
use amiro_world::foxglove;
use amiro_world::output::Sample;
use amiro_world::{Arena, Trajectory};
use anyhow::{anyhow, Context, Result};
use serde_json::{json, Map, Value};

use crate::describe::{
    command_json, decode_frame, json_record, sample_json, value_fields, FieldType,
};
use crate::frame::{LoggedFrame, Timestamp};

/// The channel every frame is written to.
pub const FRAMES_CHANNEL: &str = "/amiro/frames";

/// The channel of a topic's decoded samples.
pub fn topic_channel(topic: Topic) -> String {
    format!("/amiro/{}", topic.name())
}

/// The channel of the commands sent to a topic.
pub fn command_channel(topic: Topic) -> String {
    format!("/amiro/{}/command", topic.name())
}

fn priorities() -> Vec<&'static str> {
    Priority::ALL.iter().map(|p| p.name()).collect()
}

/// The JSON schema of a topic's sample messages.
pub fn topic_schema(topic: Topic) -> Value {
    let info = TOPICS.iter().find(|info| info.topic == topic);
    let mut properties = Map::new();
    properties.insert(
        "priority".into(),
        json!({ "type": "string", "enum": priorities(), "description": "CAN priority of the frame" }),
    );
    let mut required = vec!["priority".to_string()];
    let fields = value_fields(topic);
    for (name, kind, unit) in fields.unwrap_or_default() {
        let mut property = match kind {
            FieldType::Integer => json!({ "type": "integer" }),
            FieldType::Boolean => json!({ "type": "boolean" }),
            FieldType::Text => json!({ "type": "string" }),
            FieldType::Integers(n) => json!({
                "type": "array", "items": { "type": "integer" }, "minItems": n, "maxItems": n
            }),
        };
        if !unit.is_empty() {
            property["description"] = json!(format!("unit: {unit}"));
        }
        properties.insert((*name).into(), property);
        required.push((*name).into());
    }
    let mut schema = json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": format!("amiro.{}", topic.name()),
        "description": info.map_or("", |info| info.layout),
        "type": "object",
        "properties": properties,
        "required": required,
    });
    if fields.is_none() {
        // Diagnostics: the fields depend on the page (docs/operator.md, JSON output).
        schema["properties"]["page"] =
            json!({ "type": "string", "description": "diagnostics page" });
        schema["additionalProperties"] = json!(true);
    } else {
        schema["additionalProperties"] = json!(false);
    }
    schema
}

/// The JSON schema of command messages (the `command` object of `decode --json`, plus `priority`).
pub fn command_schema() -> Value {
    let integer = || json!({ "type": "integer" });
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "amiro.command",
        "type": "object",
        "properties": {
            "priority": { "type": "string", "enum": priorities() },
            "action": { "type": "string", "enum": ["publish", "stop", "once", "motor", "led", "admission-policy", "shutdown"] },
            "period_us": integer(),
            "sample_time": { "type": "object", "properties": {
                "value": integer(), "unit": { "type": "string", "enum": ["us", "ms", "s"] } } },
            "reply_id": { "type": "string" },
            "velocity_um_s": { "type": "integer", "description": "unit: um/s" },
            "angular_urad_s": { "type": "integer", "description": "unit: urad/s" },
            "led": integer(), "r": integer(), "g": integer(), "b": integer(),
            "board": { "type": "string" },
            "policy": { "type": "string" },
            "mode": { "type": "string" },
            "blt_reason": integer(),
        },
        "required": ["priority", "action"],
    })
}

/// The JSON schema of `/amiro/frames` (the record of `decode --json`).
pub fn frame_schema() -> Value {
    let text = || json!({ "type": "string" });
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "amiro.frame",
        "type": "object",
        "properties": {
            "timestamp": text(), "interface": text(), "frame": text(), "id": text(), "data": text(),
            "ok": { "type": "boolean" }, "kind": text(), "priority": text(), "topic": text(),
            "command": { "type": "object" }, "values": { "type": "object" }, "text": text(),
            "error": text(), "message": text(),
        },
        "required": ["frame", "id", "data", "ok"],
    })
}

/// A channel as MCAP and Foxglove's WebSocket protocol describe it.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelSpec {
    /// The channel's topic (`/amiro/gyroscope`).
    pub name: String,
    /// The schema's name (`amiro.gyroscope`).
    pub schema_name: String,
    /// The JSON schema.
    pub schema: Value,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
}

/// `/amiro/frames`.
pub fn frames_spec() -> ChannelSpec {
    ChannelSpec {
        name: FRAMES_CHANNEL.into(),
        schema_name: "amiro.frame".into(),
        schema: frame_schema(),
        metadata: BTreeMap::new(),
    }
}

/// `/amiro/<topic>`: the topic's decoded samples.
pub fn topic_spec(topic: Topic) -> ChannelSpec {
    let info = TOPICS.iter().find(|info| info.topic == topic);
    let metadata = [
        ("topic_byte", format!("0x{:02X}", topic.byte())),
        (
            "board",
            info.map_or(String::new(), |i| i.board.name().into()),
        ),
        ("layout", info.map_or(String::new(), |i| i.layout.into())),
    ];
    ChannelSpec {
        name: topic_channel(topic),
        schema_name: format!("amiro.{}", topic.name()),
        schema: topic_schema(topic),
        metadata: metadata
            .into_iter()
            .map(|(key, value)| (key.to_string(), value))
            .collect(),
    }
}

/// `/amiro/<topic>/command`: the commands sent to the topic.
pub fn command_spec(topic: Topic) -> ChannelSpec {
    ChannelSpec {
        name: command_channel(topic),
        schema_name: "amiro.command".into(),
        schema: command_schema(),
        metadata: BTreeMap::from([("topic".to_string(), topic.name().to_string())]),
    }
}

/// `/world/arena`: a world's walls, obstacles and floor.
pub fn arena_spec() -> ChannelSpec {
    ChannelSpec {
        name: foxglove::ARENA_TOPIC.into(),
        schema_name: foxglove::SCENE_SCHEMA.into(),
        schema: foxglove::scene_schema(),
        metadata: BTreeMap::new(),
    }
}

/// `/world/pose`: the robot's pose in its world.
pub fn pose_spec() -> ChannelSpec {
    ChannelSpec {
        name: foxglove::POSE_TOPIC.into(),
        schema_name: foxglove::POSE_SCHEMA.into(),
        schema: foxglove::pose_schema(),
        metadata: BTreeMap::new(),
    }
}

/// Nanoseconds since the timestamp's origin: the log time of a frame.
pub fn time_ns(timestamp: Timestamp) -> u64 {
    timestamp
        .secs
        .saturating_mul(1_000_000_000)
        .saturating_add(u64::from(timestamp.micros) * 1000)
}

/// What a frame becomes: its record for `/amiro/frames` (as `decode --json` prints it) and, if it decodes, the
/// message for its topic's channel (`priority` first, then the fields of `decode --json`).
pub fn messages(logged: &LoggedFrame) -> (Value, Option<(ChannelSpec, Value)>) {
    let decoded = decode_frame(&logged.frame);
    let record = json_record(logged, None, &decoded);
    let Ok(message) = &decoded else {
        return (record, None);
    };
    let (spec, body) = match message {
        Message::Sample { data, .. } => (topic_spec(data.topic()), sample_json(data)),
        Message::Command(command) => {
            let Ok(topic) = message.topic() else {
                return (record, None);
            };
            (command_spec(topic), command_json(command))
        }
    };
    let mut ordered = Map::new();
    ordered.insert("priority".into(), json!(message.priority().name()));
    if let Value::Object(mut fields) = body {
        ordered.append(&mut fields);
    }
    (record, Some((spec, Value::Object(ordered))))
}

/// An MCAP file being written.
pub struct Recording<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: HashMap<String, u16>,
    sequences: HashMap<u16, u32>,
    frames: u16,
    /// The time given to a frame without one: the last frame's.
    last_time_ns: u64,
    /// Frames that had no time of their own.
    pub untimed: u64,
    /// Frames written.
    pub written: u64,
    /// A world run's poses not yet written: each goes in before the first frame after it.
    poses: VecDeque<Sample>,
    /// Poses written.
    pub poses_written: u64,
}

impl Recording<BufWriter<File>> {
    /// Creates (or replaces) the file.
    pub fn create(path: &Path) -> Result<Self> {
        let file =
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        Self::new(BufWriter::new(file))
    }
}

impl<W: Write + Seek> Recording<W> {
    /// Starts a recording into `out`.
    pub fn new(out: W) -> Result<Self> {
        let writer = mcap::WriteOptions::new()
            .library(format!("amiro {}", env!("CARGO_PKG_VERSION")))
            .create(out)
            .map_err(|error| anyhow!("cannot start the MCAP file: {error}"))?;
        let mut recording = Self {
            writer,
            channels: HashMap::new(),
            sequences: HashMap::new(),
            frames: 0,
            last_time_ns: 0,
            untimed: 0,
            written: 0,
            poses: VecDeque::new(),
            poses_written: 0,
        };
        recording.frames = recording.channel(&frames_spec())?;
        Ok(recording)
    }

    fn channel(&mut self, spec: &ChannelSpec) -> Result<u16> {
        if let Some(id) = self.channels.get(&spec.name) {
            return Ok(*id);
        }
        let schema_id = self
            .writer
            .add_schema(
                &spec.schema_name,
                "jsonschema",
                spec.schema.to_string().as_bytes(),
            )
            .map_err(|error| anyhow!("cannot add the schema {}: {error}", spec.schema_name))?;
        let id = self
            .writer
            .add_channel(schema_id, &spec.name, "json", &spec.metadata)
            .map_err(|error| anyhow!("cannot add the channel {}: {error}", spec.name))?;
        self.channels.insert(spec.name.clone(), id);
        Ok(id)
    }

    fn write(&mut self, channel: u16, time_ns: u64, message: &Value) -> Result<()> {
        let sequence = self.sequences.entry(channel).or_insert(0);
        *sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: *sequence,
            log_time: time_ns,
            publish_time: time_ns,
        };
        self.writer
            .write_to_known_channel(&header, message.to_string().as_bytes())
            .map_err(|error| anyhow!("cannot write to the MCAP file: {error}"))
    }

    /// Adds a world run: its arena on `/world/arena` (once, at time 0: the run's start) and the trajectory's
    /// poses on `/world/pose`, each written before the first frame after it (the rest at the end). The
    /// trajectory's times are the run's virtual time, as its bus log's.
    pub fn world(&mut self, arena: Option<&Arena>, trajectory: Option<Trajectory>) -> Result<()> {
        if let Some(arena) = arena {
            let channel = self.channel(&arena_spec())?;
            self.write(channel, 0, &foxglove::scene_update(arena))?;
        }
        if let Some(trajectory) = trajectory {
            self.poses.extend(trajectory.samples);
        }
        Ok(())
    }

    /// Writes the poses up to `time_ns` (all of them with `None`).
    fn poses_until(&mut self, time_ns: Option<u64>) -> Result<()> {
        while let Some(sample) = self.poses.front() {
            let at = sample.t_us.saturating_mul(1000);
            if time_ns.is_some_and(|t| at > t) {
                break;
            }
            let message = foxglove::pose_in_frame(sample.t_us, &sample.pose);
            self.poses.pop_front();
            let channel = self.channel(&pose_spec())?;
            self.write(channel, at, &message)?;
            self.poses_written += 1;
        }
        Ok(())
    }

    /// Records one frame: on `/amiro/frames`, and decoded on its topic's channel.
    pub fn record(&mut self, logged: &LoggedFrame) -> Result<()> {
        let time_ns = match logged.timestamp {
            Some(timestamp) => time_ns(timestamp),
            None => {
                self.untimed += 1;
                self.last_time_ns
            }
        };
        self.last_time_ns = time_ns;
        self.poses_until(Some(time_ns))?;
        let (record, decoded) = messages(logged);
        self.write(self.frames, time_ns, &record)?;
        if let Some((spec, body)) = decoded {
            let channel = self.channel(&spec)?;
            self.write(channel, time_ns, &body)?;
        }
        self.written += 1;
        Ok(())
    }

    /// Writes the summary and index and flushes; the file is complete after this. Returns the frames written and
    /// the output.
    pub fn finish(mut self) -> Result<(u64, W)> {
        self.poses_until(None)?;
        self.writer
            .finish()
            .map_err(|error| anyhow!("cannot finish the MCAP file: {error}"))?;
        let mut out = self.writer.into_inner();
        out.flush().context("cannot write the MCAP file")?;
        Ok((self.written, out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_line;

    fn recorded(lines: &[&str]) -> Vec<u8> {
        let mut recording = Recording::new(std::io::Cursor::new(Vec::new())).unwrap();
        for line in lines {
            recording
                .record(&parse_line(line).unwrap().unwrap())
                .unwrap();
        }
        let (written, out) = recording.finish().unwrap();
        assert_eq!(written, lines.len() as u64);
        out.into_inner()
    }

    #[test]
    fn frames_go_to_their_topics_channels_with_their_log_times() {
        let bytes = recorded(&[
            "(1700000000.000100) can0 208#01640000",
            "(1700000000.100000) can0 608#FCFF1E00FBFF",
            "(1700000000.200000) can0 608#FDFF1F00FBFF",
            "(1700000000.250000) can0 71F#037800",
            "(1700000000.300000) can0 205#0184",
        ]);
        let messages: Vec<(String, u64, Value)> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|message| {
                let message = message.unwrap();
                (
                    message.channel.topic.clone(),
                    message.log_time,
                    serde_json::from_slice(&message.data).unwrap(),
                )
            })
            .collect();
        let on = |channel: &str| -> Vec<(u64, Value)> {
            messages
                .iter()
                .filter(|(name, _, _)| name == channel)
                .map(|(_, time, value)| (*time, value.clone()))
                .collect()
        };
        let gyroscope = on("/amiro/gyroscope");
        assert_eq!(gyroscope.len(), 2);
        assert_eq!(gyroscope[0].0, 1_700_000_000_100_000_000);
        assert_eq!(
            gyroscope[0].1,
            json!({"priority": "medium", "x_dps": -4, "y_dps": 30, "z_dps": -5})
        );
        assert_eq!(gyroscope[1].1["x_dps"], json!(-3));
        let commands = on("/amiro/gyroscope/command");
        assert_eq!(commands[0].0, 1_700_000_000_000_100_000);
        assert_eq!(commands[0].1["action"], json!("publish"));
        assert_eq!(commands[0].1["period_us"], json!(100_000));
        assert_eq!(
            on("/amiro/proximity-ring")[0].1,
            json!({"priority": "low", "sensor": 3, "mm": 120})
        );
        // Every frame, also the one the robot would reject, is on the raw channel.
        let frames = on(FRAMES_CHANNEL);
        assert_eq!(frames.len(), 5);
        assert_eq!(frames[4].0, 1_700_000_000_300_000_000);
        assert_eq!(frames[4].1["error"], json!("dlc-too-short"));
        assert_eq!(frames[1].1["values"]["y_dps"], json!(30));

        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let schema = |channel: &str| -> Value {
            let channel = summary
                .channels
                .values()
                .find(|c| c.topic == channel)
                .expect(channel);
            let schema = channel.schema.as_ref().expect("a schema");
            assert_eq!(schema.encoding, "jsonschema");
            assert_eq!(channel.message_encoding, "json");
            serde_json::from_slice(&schema.data).unwrap()
        };
        let gyro = schema("/amiro/gyroscope");
        assert_eq!(gyro["properties"]["x_dps"]["type"], json!("integer"));
        assert_eq!(
            gyro["required"],
            json!(["priority", "x_dps", "y_dps", "z_dps"])
        );
        assert_eq!(schema(FRAMES_CHANNEL)["title"], json!("amiro.frame"));
        let stats = summary.stats.expect("statistics");
        assert_eq!(stats.message_count, 5 + 4);
        assert_eq!(stats.message_start_time, 1_700_000_000_000_100_000);
        assert_eq!(stats.message_end_time, 1_700_000_000_300_000_000);
    }

    #[test]
    fn every_sensor_topic_has_a_schema_that_names_its_fields() {
        for info in TOPICS.iter().filter(|info| info.is_sensor) {
            let schema = topic_schema(info.topic);
            assert_eq!(schema["description"], json!(info.layout));
            if let Some(fields) = value_fields(info.topic) {
                for (name, _, _) in fields {
                    assert!(
                        schema["properties"].get(*name).is_some(),
                        "{} {name}",
                        info.name
                    );
                }
            } else {
                assert_eq!(schema["additionalProperties"], json!(true), "{}", info.name);
            }
        }
    }

    #[test]
    fn a_world_run_adds_its_arena_once_and_its_poses_between_the_frames() {
        let arena = Arena::parse(
            r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 90 },
                 "walls": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]] }"#,
        )
        .unwrap();
        let mut trajectory = Trajectory::default();
        for k in 0..4u64 {
            trajectory.record(k * 10_000, arena.start);
        }
        let mut recording = Recording::new(std::io::Cursor::new(Vec::new())).unwrap();
        recording.world(Some(&arena), Some(trajectory)).unwrap();
        for line in [
            "(0.015000) can0 608#FCFF1E00FBFF",
            "(0.020000) can0 608#FCFF1E00FBFF",
        ] {
            recording
                .record(&parse_line(line).unwrap().unwrap())
                .unwrap();
        }
        assert_eq!(recording.poses_written, 3, "the poses up to the last frame");
        let (_, out) = recording.finish().unwrap();
        let bytes = out.into_inner();
        let order: Vec<(String, u64)> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.topic.clone(), m.log_time / 1_000_000)
            })
            .filter(|(topic, _)| topic != "/amiro/gyroscope")
            .collect();
        let topic = |t: &str, ms: u64| (t.to_string(), ms);
        assert_eq!(
            order,
            [
                topic("/world/arena", 0),
                topic("/world/pose", 0),
                topic("/world/pose", 10),
                topic(FRAMES_CHANNEL, 15),
                topic("/world/pose", 20),
                topic(FRAMES_CHANNEL, 20),
                topic("/world/pose", 30),
            ]
        );
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let schema = |name: &str| {
            summary
                .channels
                .values()
                .find(|c| c.topic == name)
                .and_then(|c| c.schema.as_ref())
                .map(|s| s.name.clone())
        };
        assert_eq!(
            schema("/world/pose").as_deref(),
            Some("foxglove.PoseInFrame")
        );
        assert_eq!(
            schema("/world/arena").as_deref(),
            Some("foxglove.SceneUpdate")
        );
        let pose: Value = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .find(|m| m.channel.topic == "/world/pose")
            .map(|m| serde_json::from_slice(&m.data).unwrap())
            .unwrap();
        assert_eq!(pose["frame_id"], json!("world"));
        assert_eq!(
            pose["pose"]["position"],
            json!({ "x": 0.5, "y": 0.5, "z": 0.0 })
        );
        let w = pose["pose"]["orientation"]["w"].as_f64().unwrap();
        assert!((w - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9, "{w}");
    }

    #[test]
    fn a_frame_without_a_time_takes_the_previous_frames() {
        let bytes = recorded(&["(5.000000) can0 608#FCFF1E00FBFF", "608#FCFF1E00FBFF"]);
        let times: Vec<u64> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap().log_time)
            .collect();
        assert_eq!(times, [5_000_000_000; 4]);
    }
}
