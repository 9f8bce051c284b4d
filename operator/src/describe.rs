//! What a frame means, for people (one plain-English line) and for programs (one JSON object).
//!
//! The meaning itself comes from `amiro_can::decode`; this module only chooses words, units and field names.
//! Values are printed from the decoded signed integers, never from raw bytes, so −4 dps prints as `-4 dps`
//! (the thesis's receiver printed 65532).

use amiro_can::{
    AdmissionPolicy, Command, DecodeError, DiagnosticsPage, Kind, Message, SensorData, SensorMode,
    TimeUnit, Topic, Verdict, ViolationKind,
};
use serde_json::{json, Map, Value};

use crate::frame::{FrameId, FrameTextError, LoggedFrame, RawFrame};

/// Decodes a frame as an AMiRo message. Frames the protocol never uses (extended identifiers, remote frames)
/// get amiro-can's own reasons, so every rejection reads the same way.
pub fn decode_frame(frame: &RawFrame) -> Result<Message, DecodeError> {
    match frame.id() {
        FrameId::Extended(id) => Err(DecodeError::ExtendedId { id }),
        FrameId::Standard(_) if frame.is_remote() => Err(DecodeError::RemoteFrame),
        FrameId::Standard(id) => amiro_can::decode(id, frame.data()),
    }
}

/// `medium command magnetometer-x: publish every 900 µs (samples arrive on 605)`.
pub fn describe_message(message: &Message) -> String {
    let (priority, kind, what) = meaning(message);
    format!("{priority} {kind} {what}")
}

/// Priority, kind and the words for what the message says, for callers that align them in columns.
fn meaning(message: &Message) -> (&'static str, &'static str, String) {
    let kind = match message.kind() {
        Kind::Command => "command",
        Kind::Sensor => "sensor",
    };
    let what = match message {
        Message::Command(command) => describe_command(command),
        Message::Sample { data, .. } => describe_sample(data),
    };
    (message.priority().name(), kind, what)
}

fn describe_command(command: &Command) -> String {
    match command {
        Command::Sensor(sensor) => {
            let reply = sensor.reply_id();
            match sensor.mode {
                SensorMode::Stop => format!("{}: stop publishing", sensor.topic),
                SensorMode::Publish(time) => format!(
                    "{}: publish every {} (samples arrive on {reply})",
                    sensor.topic,
                    crate::period::human_micros(time.as_micros())
                ),
                SensorMode::Once => {
                    format!(
                        "{}: send one sample now and stop publishing (it arrives on {reply})",
                        sensor.topic
                    )
                }
            }
        }
        Command::Motor { command, .. } => format!(
            "motor: drive at {} µm/s forward, {} µrad/s turning (counter-clockwise positive)",
            command.velocity_um_s, command.angular_urad_s
        ),
        Command::Led { command, .. } => {
            let rgb = command.rgb;
            format!(
                "led-{}: set colour red {}, green {}, blue {}",
                command.led, rgb.r, rgb.g, rgb.b
            )
        }
        Command::Policy { board, policy, .. } => match policy {
            AdmissionPolicy::Refuse => format!(
                "{}: admission policy refuse — {board} refuses requests that would break a deadline",
                board.diagnostics_topic()
            ),
            AdmissionPolicy::AcceptAndWarn => format!(
                "{}: admission policy accept-and-warn — {board} carries out requests that break a deadline and warns",
                board.diagnostics_topic()
            ),
        },
        Command::Shutdown { mode, .. } => format!(
            "shutdown: shut the robot down ({mode}; AMiRo-BLT reason {})",
            mode.blt_reason()
        ),
    }
}

fn describe_sample(data: &SensorData) -> String {
    let topic = data.topic();
    let values = match data {
        SensorData::Gyroscope([x, y, z]) => format!("x {x} dps, y {y} dps, z {z} dps"),
        SensorData::Accelerometer([x, y, z]) => {
            format!("x {x} milli-g, y {y} milli-g, z {z} milli-g")
        }
        SensorData::Magnetometer { axis, nanotesla } => format!("{} {nanotesla} nT", axis.name()),
        SensorData::FloorProximity([a, b, c, d]) => {
            // Numbered from 0 like the ring's sensor index and `amiro monitor`'s named positions.
            format!("sensor 0 {a}, sensor 1 {b}, sensor 2 {c}, sensor 3 {d} (raw proximity counts)")
        }
        SensorData::Odometry(odometry) => format!(
            "x {} mm, y {} mm, heading {}°",
            // The wire resolution is 100 µm, so one decimal of a millimetre is exact.
            fixed_point(i64::from(odometry.x_100um()), 1),
            fixed_point(i64::from(odometry.y_100um()), 1),
            fixed_point(i64::from(odometry.heading_centidegrees()), 2)
        ),
        SensorData::Velocity(velocity) => format!(
            "{} µm/s forward, {} µrad/s turning",
            velocity.velocity_um_s, velocity.angular_urad_s
        ),
        SensorData::PowerStatus(power) => {
            let (state, until) = power.direction();
            format!(
                "{state}, {} % charged, {} min to {until}, drawing {} mW",
                power.state_of_charge, power.minutes, power.power_mw
            )
        }
        SensorData::ProximityRing { sensor, mm } => format!("sensor {sensor} sees {mm} mm"),
        SensorData::Diagnostics { page, .. } => page.to_string(),
    };
    format!("{topic}: {values}")
}

/// `value / 10^decimals` with exactly `decimals` digits and the sign kept for values between −1 and 0.
fn fixed_point(value: i64, decimals: u32) -> String {
    let scale = 10u64.pow(decimals);
    let magnitude = value.unsigned_abs();
    let sign = if value < 0 { "-" } else { "" };
    let width = decimals as usize;
    format!("{sign}{}.{:0width$}", magnitude / scale, magnitude % scale)
}

/// Width the frame column is padded to: the longest standard frame, `7FF#0102030405060708`.
const FRAME_COLUMN: usize = 20;

/// One human-readable line for a frame: where it came from, the frame, and what it means or why it is wrong.
pub fn text_line(logged: &LoggedFrame, decoded: &Result<Message, DecodeError>) -> String {
    let frame = logged.frame.to_string();
    let meaning = match decoded {
        Ok(message) => {
            let (priority, kind, what) = meaning(message);
            format!("{priority:<6} {kind:<7} {what}")
        }
        Err(error) => format!("error: {error} [{}]", error.kind_name()),
    };
    format!(
        "{}{frame:<FRAME_COLUMN$}  {meaning}",
        logged.origin_prefix()
    )
}

/// The line for input that is not a frame at all.
pub fn text_unreadable(line: Option<usize>, error: &FrameTextError) -> String {
    match line {
        Some(line) => format!("line {line}: cannot read: {error}"),
        None => format!("cannot read: {error}"),
    }
}

/// One JSON object for a frame (the schema is in docs/operator.md).
pub fn json_record(
    logged: &LoggedFrame,
    line: Option<usize>,
    decoded: &Result<Message, DecodeError>,
) -> Value {
    let mut record = Map::new();
    if let Some(line) = line {
        record.insert("line".into(), json!(line));
    }
    if let Some(timestamp) = logged.timestamp {
        record.insert("timestamp".into(), json!(timestamp.to_string()));
    }
    if let Some(interface) = &logged.interface {
        record.insert("interface".into(), json!(interface));
    }
    record.insert("frame".into(), json!(logged.frame.to_string()));
    record.insert("id".into(), json!(logged.frame.id_hex().to_string()));
    record.insert("data".into(), json!(logged.frame.data_hex().to_string()));
    match decoded {
        Ok(message) => {
            record.insert("ok".into(), json!(true));
            let kind = match message.kind() {
                Kind::Command => "command",
                Kind::Sensor => "sensor",
            };
            record.insert("kind".into(), json!(kind));
            record.insert("priority".into(), json!(message.priority().name()));
            if let Ok(topic) = message.topic() {
                record.insert("topic".into(), json!(topic.name()));
            }
            match message {
                Message::Command(command) => record.insert("command".into(), command_json(command)),
                Message::Sample { data, .. } => record.insert("values".into(), sample_json(data)),
            };
            record.insert("text".into(), json!(describe_message(message)));
        }
        Err(error) => {
            record.insert("ok".into(), json!(false));
            record.insert("error".into(), json!(error.kind_name()));
            record.insert("message".into(), json!(error.to_string()));
        }
    }
    Value::Object(record)
}

/// The JSON object for input that is not a frame.
pub fn json_unreadable(line: Option<usize>, input: &str, error: &FrameTextError) -> Value {
    let mut record = Map::new();
    if let Some(line) = line {
        record.insert("line".into(), json!(line));
    }
    record.insert("input".into(), json!(input.trim()));
    record.insert("ok".into(), json!(false));
    record.insert("error".into(), json!(error.kind_name()));
    record.insert("message".into(), json!(error.to_string()));
    Value::Object(record)
}

fn unit_name(unit: TimeUnit) -> &'static str {
    match unit {
        TimeUnit::Micros => "us",
        TimeUnit::Millis => "ms",
        TimeUnit::Seconds => "s",
    }
}

/// The command as `decode --json` prints it under `command`.
pub fn command_json(command: &Command) -> Value {
    match command {
        Command::Sensor(sensor) => {
            let reply_id = sensor.reply_id().to_string();
            match sensor.mode {
                SensorMode::Stop => json!({ "action": "stop" }),
                SensorMode::Once => json!({ "action": "once", "reply_id": reply_id }),
                SensorMode::Publish(time) => json!({
                    "action": "publish",
                    "period_us": time.as_micros(),
                    "sample_time": { "value": time.value, "unit": unit_name(time.unit) },
                    "reply_id": reply_id,
                }),
            }
        }
        Command::Motor { command, .. } => json!({
            "action": "motor",
            "velocity_um_s": command.velocity_um_s,
            "angular_urad_s": command.angular_urad_s,
        }),
        Command::Led { command, .. } => json!({
            "action": "led",
            "led": command.led,
            "r": command.rgb.r,
            "g": command.rgb.g,
            "b": command.rgb.b,
        }),
        Command::Policy { board, policy, .. } => json!({
            "action": "admission-policy",
            "board": board.name(),
            "policy": policy.name(),
        }),
        Command::Shutdown { mode, .. } => json!({
            "action": "shutdown",
            "mode": mode.name(),
            "blt_reason": mode.blt_reason(),
        }),
    }
}

fn diagnostics_json(page: &DiagnosticsPage) -> Value {
    let mut fields = match page {
        DiagnosticsPage::Status {
            uptime_s,
            reset_cause,
            flags,
            sensor_faults,
        } => json!({
            "uptime_s": uptime_s,
            "reset_cause": reset_cause.bits(),
            "reset_cause_names": reset_cause.to_string(),
            "flags": flags.bits(),
            "flag_names": flags.to_string(),
            "sensor_faults": sensor_faults.get(),
        }),
        DiagnosticsPage::Commands {
            accepted,
            rejected,
            reasons,
        } => json!({
            "accepted": accepted.get(),
            "rejected": rejected.get(),
            "reasons": reasons,
        }),
        DiagnosticsPage::Rejections { first, counts } => {
            let mut by_reason = Map::new();
            for (i, count) in counts.iter().enumerate() {
                let index = usize::from(*first) + i;
                if let Some(name) = amiro_can::reason_name(index) {
                    by_reason.insert(name.into(), json!(count.get()));
                }
            }
            json!({ "first": first, "counts": counts.map(|c| c.get()), "by_reason": by_reason })
        }
        DiagnosticsPage::AdmissionAndReceive {
            refused,
            warned,
            rx_dropped,
            rx_overruns,
        } => json!({
            "admission_refused": refused.get(),
            "admission_warned": warned.get(),
            "rx_dropped_at_least": rx_dropped.get(),
            "rx_overruns": rx_overruns.get(),
        }),
        DiagnosticsPage::Transmit {
            tx_dropped,
            tx_displaced,
            error_passive,
            bus_off,
        } => json!({
            "tx_dropped": tx_dropped.get(),
            "tx_displaced": tx_displaced.get(),
            "error_passive": error_passive.get(),
            "bus_off": bus_off.get(),
        }),
        DiagnosticsPage::Deadlines { misses } => json!({
            "deadline_misses": {
                "urgent": misses[0].get(),
                "high": misses[1].get(),
                "medium": misses[2].get(),
                "low": misses[3].get(),
            }
        }),
        DiagnosticsPage::VerdictRequest(request) => json!({
            "topic": request.topic.name(),
            "requested_us": request.requested.as_micros(),
            "requested_value": request.requested.value,
            // As the DBC signal: unit 3 marks a one-shot request analysed at an interval in ms.
            "requested_unit": if request.one_shot { "one-shot-ms" } else { unit_name(request.requested.unit) },
            "one_shot": request.one_shot,
            "priority": request.priority.name(),
            "verdict": match request.verdict {
                Verdict::Refused => "refused",
                Verdict::AcceptedWithWarning => "accepted-with-warning",
            },
            "priority_needed": request.priority_needed.map(|p| p.name()),
            // As the DBC signal (bit 7 of page 0x80): set when the board did not search.
            "not_searched": !request.searched,
            "shortest_period_us": request.shortest_period.map(|t| t.as_micros()),
            "shortest_period_value": request.shortest_period.map_or(0, |t| t.value),
            "shortest_period_unit": unit_name(request.shortest_period.map_or(TimeUnit::Millis, |t| t.unit)),
            "has_shortest_period": request.shortest_period.is_some(),
            "violation": match request.violation {
                ViolationKind::Unknown => "unknown",
                ViolationKind::Task => "task",
                ViolationKind::Message { .. } => "message",
            },
            "violated_priority": match request.violation {
                ViolationKind::Message { priority } => priority.name(),
                ViolationKind::Unknown | ViolationKind::Task => "urgent",
            },
        }),
        DiagnosticsPage::VerdictBound(bound) => json!({
            "violated": bound.violated,
            "wcrt_us": bound.wcrt_us.get(),
            "deadline_us": bound.deadline_us.get(),
        }),
    };
    if let Value::Object(map) = &mut fields {
        map.insert("page".into(), json!(page.name()));
    }
    fields
}

/// The values of a sample as `decode --json` prints them under `values` (and MCAP recordings carry them).
pub fn sample_json(data: &SensorData) -> Value {
    match data {
        SensorData::Gyroscope([x, y, z]) => json!({ "x_dps": x, "y_dps": y, "z_dps": z }),
        SensorData::Accelerometer([x, y, z]) => {
            json!({ "x_milli_g": x, "y_milli_g": y, "z_milli_g": z })
        }
        SensorData::Magnetometer { axis, nanotesla } => {
            json!({ "axis": axis.name(), "nanotesla": nanotesla })
        }
        SensorData::FloorProximity(counts) => json!({ "counts": counts }),
        SensorData::Odometry(odometry) => json!({
            "x_um": odometry.x_um(),
            "y_um": odometry.y_um(),
            "heading_urad": odometry.heading_urad(),
            "heading_counts": odometry.heading(),
        }),
        SensorData::Velocity(velocity) => json!({
            "velocity_um_s": velocity.velocity_um_s,
            "angular_urad_s": velocity.angular_urad_s,
        }),
        SensorData::PowerStatus(power) => json!({
            "charging": power.charging,
            "state_of_charge_percent": power.state_of_charge,
            "minutes": power.minutes,
            "power_mw": power.power_mw,
        }),
        SensorData::ProximityRing { sensor, mm } => json!({ "sensor": sensor, "mm": mm }),
        SensorData::Diagnostics { page, .. } => diagnostics_json(page),
    }
}

/// The JSON type of a value field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// A whole number.
    Integer,
    /// true or false.
    Boolean,
    /// Text.
    Text,
    /// An array of this many whole numbers.
    Integers(usize),
}

/// One field of a sample's values: its name in `sample_json`, its type and its unit (empty: none).
pub type ValueField = (&'static str, FieldType, &'static str);

/// The fields `sample_json` writes for a sensor topic's data, in order; `None` for topics whose fields depend on
/// the frame (the diagnostics pages) and for actuators. Checked against `sample_json` by the tests.
pub fn value_fields(topic: Topic) -> Option<&'static [ValueField]> {
    use FieldType::{Boolean, Integer, Integers, Text};
    Some(match topic {
        Topic::Gyroscope => &[
            ("x_dps", Integer, "deg/s"),
            ("y_dps", Integer, "deg/s"),
            ("z_dps", Integer, "deg/s"),
        ],
        Topic::Accelerometer => &[
            ("x_milli_g", Integer, "milli-g"),
            ("y_milli_g", Integer, "milli-g"),
            ("z_milli_g", Integer, "milli-g"),
        ],
        Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
            &[("axis", Text, ""), ("nanotesla", Integer, "nT")]
        }
        Topic::FloorProximity => &[("counts", Integers(4), "raw proximity counts")],
        Topic::Odometry => &[
            ("x_um", Integer, "um"),
            ("y_um", Integer, "um"),
            ("heading_urad", Integer, "urad"),
            ("heading_counts", Integer, "1/65536 turn"),
        ],
        Topic::Velocity => &[
            ("velocity_um_s", Integer, "um/s"),
            ("angular_urad_s", Integer, "urad/s"),
        ],
        Topic::PowerStatus => &[
            ("charging", Boolean, ""),
            ("state_of_charge_percent", Integer, "%"),
            ("minutes", Integer, "min"),
            ("power_mw", Integer, "mW"),
        ],
        Topic::ProximityRing => &[("sensor", Integer, "index 0-7"), ("mm", Integer, "mm")],
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{parse_compact, parse_line};

    #[test]
    fn the_value_fields_are_what_sample_json_writes() {
        for text in [
            "701#393000FDFFFF0040",
            "502#A0860100B03CFFFF",
            "404#360127010C00D403",
            "605#08520000",
            "706#F8ADFFFF",
            "407#10270000",
            "508#FCFF1E000500",
            "609#1A00FEFF0E04",
            "71E#003E4701720C",
            "71F#037800",
        ] {
            let Ok(Message::Sample { data, .. }) = decode_frame(&parse_compact(text).unwrap())
            else {
                panic!("{text}")
            };
            let Value::Object(values) = sample_json(&data) else {
                panic!("{text}")
            };
            let fields = value_fields(data.topic()).expect(text);
            let names: Vec<&str> = fields.iter().map(|(name, _, _)| *name).collect();
            assert_eq!(values.keys().map(String::as_str).collect::<Vec<_>>(), names);
            for (name, kind, _) in fields {
                let value = &values[*name];
                let fits = match kind {
                    FieldType::Integer => value.is_i64() || value.is_u64(),
                    FieldType::Boolean => value.is_boolean(),
                    FieldType::Text => value.is_string(),
                    FieldType::Integers(n) => value.as_array().is_some_and(|a| a.len() == *n),
                };
                assert!(fits, "{text}: {name} = {value}");
            }
        }
    }

    fn describe(text: &str) -> String {
        let logged = parse_line(text).unwrap().unwrap();
        text_line(&logged, &decode_frame(&logged.frame))
    }

    #[test]
    fn the_thesis_example_reads_as_a_publish_command() {
        let line = describe("205#01840302");
        assert_eq!(
            line,
            "205#01840302          medium command magnetometer-x: publish every 900 µs (samples arrive on 605)"
        );
    }

    #[test]
    fn sensor_values_keep_their_sign() {
        let line = describe("608#FCFF1E00FBFF");
        assert!(
            line.ends_with("gyroscope: x -4 dps, y 30 dps, z -5 dps"),
            "{line}"
        );
        let line = describe("605#D8ADFFFF");
        assert!(line.ends_with("magnetometer-x: x -21032 nT"), "{line}");
        // Odometry: x = -1 (×100 µm), y = 12345, heading a quarter turn.
        let line = describe("601#FFFFFF393000");
        assert!(
            line.contains("error"),
            "a 6-byte odometry frame is too short: {line}"
        );
        let line = describe("601#FFFFFF3930000040");
        assert!(
            line.ends_with("odometry: x -0.1 mm, y 1234.5 mm, heading 90.00°"),
            "{line}"
        );
    }

    #[test]
    fn every_kind_of_message_has_words() {
        assert!(describe("204#02").ends_with(
            "floor-proximity: send one sample now and stop publishing (it arrives on 604)"
        ));
        assert!(describe("308#00").ends_with("gyroscope: stop publishing"));
        assert!(describe("010#A086010000000000")
            .contains("motor: drive at 100000 µm/s forward, 0 µrad/s turning"));
        assert!(describe("313#0A3278").ends_with("led-3: set colour red 10, green 50, blue 120"));
        assert!(describe("71E#003E4701720C").ends_with(
            "power-status: discharging, 62 % charged, 327 min to empty, drawing 3186 mW"
        ));
        assert!(describe("71F#037800").ends_with("proximity-ring: sensor 3 sees 120 mm"));
        assert!(describe("602#A0860100B03CFFFF")
            .ends_with("velocity: 100000 µm/s forward, -50000 µrad/s turning"));
        assert!(describe("609#1A00FEFF0E04")
            .ends_with("accelerometer: x 26 milli-g, y -2 milli-g, z 1038 milli-g"));
        assert!(describe("604#0100020003000400")
            .contains("sensor 0 1, sensor 1 2, sensor 2 3, sensor 3 4 (raw proximity counts)"));
    }

    #[test]
    fn bad_frames_give_the_typed_reason() {
        assert!(describe("205#0184").ends_with("[dlc-too-short]"));
        assert!(describe("203#00").ends_with("[unknown-topic]"));
        assert!(describe("205#03").ends_with("[bad-mode]"));
        assert!(describe("12345678#00").ends_with("[extended-id]"));
        assert!(describe("205#R").ends_with("[remote-frame]"));
    }

    #[test]
    fn json_records_carry_the_values() {
        let logged = parse_line("(1700000000.123456) can0 608#FCFF1E00FBFF")
            .unwrap()
            .unwrap();
        let record = json_record(&logged, Some(3), &decode_frame(&logged.frame));
        assert_eq!(record["line"], 3);
        assert_eq!(record["timestamp"], "1700000000.123456");
        assert_eq!(record["interface"], "can0");
        assert_eq!(record["id"], "608");
        assert_eq!(record["ok"], true);
        assert_eq!(record["kind"], "sensor");
        assert_eq!(record["priority"], "medium");
        assert_eq!(record["topic"], "gyroscope");
        assert_eq!(record["values"]["x_dps"], -4);

        let frame = parse_compact("205#01840302").unwrap();
        let record = json_record(&LoggedFrame::bare(frame), None, &decode_frame(&frame));
        assert!(record.get("line").is_none());
        assert_eq!(record["command"]["action"], "publish");
        assert_eq!(record["command"]["period_us"], 900);
        assert_eq!(record["command"]["sample_time"]["unit"], "us");
        assert_eq!(record["command"]["reply_id"], "605");

        let frame = parse_compact("205#0184").unwrap();
        let record = json_record(&LoggedFrame::bare(frame), None, &decode_frame(&frame));
        assert_eq!(record["ok"], false);
        assert_eq!(record["error"], "dlc-too-short");
    }
}
