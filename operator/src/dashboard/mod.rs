//! The dashboard (`amiro monitor --dashboard`, F4 in the console): the robot's state at a glance instead of a
//! scrolling log. One row per topic heard — board, priority, latest values with units, the period measured beside
//! the one requested, late and missing samples, the last admission verdict, a sparkline of the first value — and
//! each board's health from its diagnostics pages. This module is the state (frames and time go in); `view` draws
//! it with ratatui (`render`), so tests render it into a buffer (`text`) and read it; `live` is the terminal loop of
//! `amiro monitor --dashboard`.

use std::collections::{BTreeMap, VecDeque};

use amiro_can::{
    Board, Command, DiagnosticsPage, Message, Priority, SensorCommand, SensorData, SensorMode,
    Topic, Verdict, TOPICS,
};

use crate::describe::decode_frame;
use crate::frame::{LoggedFrame, Timestamp};
use crate::health::BoardHealth;

/// Intervals kept per topic for the measured period.
const INTERVALS: usize = 16;
/// Values kept per topic for the sparkline.
const SPARK: usize = 6;
/// An interval this much longer than the requested period makes a sample late.
const LATE_FACTOR: f64 = 1.5;

/// What the dashboard knows about one topic.
#[derive(Clone, Debug, Default)]
struct TopicRow {
    priority: Option<Priority>,
    latest: String,
    /// Time of the last sample's start (µs).
    last_sample_us: Option<u64>,
    intervals: VecDeque<u64>,
    samples: u64,
    late: u64,
    missing: u64,
    history: VecDeque<f64>,
    /// The period of the last publish request heard or sent for the topic (µs); `None`: no publisher asked for.
    requested_us: Option<u64>,
    verdict: Option<&'static str>,
}

/// The dashboard's state.
#[derive(Clone, Debug, Default)]
pub struct Dashboard {
    rows: BTreeMap<u8, (Topic, TopicRow)>,
    health: BTreeMap<u8, (Board, BoardHealth)>,
    verdicts: BTreeMap<u8, String>,
    /// The newest time seen (µs): frames' times, or the clock of a live bus.
    now_us: u64,
}

fn board_of(topic: Topic) -> Option<Board> {
    TOPICS
        .iter()
        .find(|info| info.topic == topic)
        .map(|info| info.board)
}

fn short_board(board: Board) -> &'static str {
    match board {
        Board::DiWheelDrive => "DWD",
        Board::PowerManagement => "PM",
        Board::LightRing => "LR",
    }
}

fn is_diagnostics(topic: Topic) -> bool {
    Board::ALL
        .iter()
        .any(|board| board.diagnostics_topic() == topic)
}

/// The latest values in few characters, with units; and the first value, for the sparkline.
fn compact(data: &SensorData) -> (String, Option<f64>) {
    match data {
        SensorData::Gyroscope([x, y, z]) => (format!("{x} {y} {z} dps"), Some(f64::from(*x))),
        SensorData::Accelerometer([x, y, z]) => (format!("{x} {y} {z} mg"), Some(f64::from(*x))),
        SensorData::Magnetometer { nanotesla, .. } => {
            (format!("{nanotesla} nT"), Some(f64::from(*nanotesla)))
        }
        SensorData::FloorProximity(counts) => (
            counts
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" "),
            Some(f64::from(counts[0])),
        ),
        SensorData::Odometry(odometry) => (
            format!(
                "{:.0} {:.0} mm {:.0}°",
                f64::from(odometry.x_100um()) / 10.0,
                f64::from(odometry.y_100um()) / 10.0,
                f64::from(odometry.heading_centidegrees()) / 100.0
            ),
            Some(f64::from(odometry.x_100um()) / 10.0),
        ),
        SensorData::Velocity(velocity) => (
            format!(
                "{:.0} mm/s {:.0}°/s",
                f64::from(velocity.velocity_um_s) / 1000.0,
                crate::drive::degrees_per_second(velocity.angular_urad_s)
            ),
            Some(f64::from(velocity.velocity_um_s) / 1000.0),
        ),
        SensorData::PowerStatus(power) => (
            format!(
                "{}% {} mW{}",
                power.state_of_charge,
                power.power_mw,
                if power.charging { " chg" } else { "" }
            ),
            Some(f64::from(power.state_of_charge)),
        ),
        SensorData::ProximityRing { sensor, mm } => {
            (format!("#{sensor} {mm} mm"), Some(f64::from(*mm)))
        }
        SensorData::Diagnostics { page, .. } => (page.to_string(), None),
    }
}

/// Whether a frame starts a new sample: the ring's sensor 0 (its eight frames leave together), every other frame.
fn starts_sample(data: &SensorData) -> bool {
    !matches!(data, SensorData::ProximityRing { sensor, .. } if *sensor != 0)
}

impl Dashboard {
    /// Time passes on a live bus with nothing heard.
    pub fn tick(&mut self, now: Timestamp) {
        self.now_us = self.now_us.max(now.as_micros());
    }

    fn row(&mut self, topic: Topic) -> &mut TopicRow {
        &mut self
            .rows
            .entry(topic.byte())
            .or_insert_with(|| (topic, TopicRow::default()))
            .1
    }

    /// A frame heard on the bus (or sent by this `amiro`: a publish request sets the period asked for).
    pub fn heard(&mut self, logged: &LoggedFrame) {
        let time_us = logged.timestamp.map_or(self.now_us, |t| t.as_micros());
        self.now_us = self.now_us.max(time_us);
        let Ok(message) = decode_frame(&logged.frame) else {
            return;
        };
        match message {
            Message::Command(Command::Sensor(SensorCommand {
                topic,
                priority,
                mode,
            })) => {
                if is_diagnostics(topic) {
                    return;
                }
                let row = self.row(topic);
                row.requested_us = match mode {
                    SensorMode::Publish(time) => Some(time.as_micros()),
                    SensorMode::Stop | SensorMode::Once => None,
                };
                row.priority = Some(priority);
            }
            Message::Command(command) => {
                let Ok(topic) = message.topic() else { return };
                let latest = match command {
                    Command::Motor { command, .. } => format!(
                        "{:.0} mm/s {:.0}°/s",
                        f64::from(command.velocity_um_s) / 1000.0,
                        crate::drive::degrees_per_second(command.angular_urad_s)
                    ),
                    Command::Led { command, .. } => format!(
                        "#{:02X}{:02X}{:02X}",
                        command.rgb.r, command.rgb.g, command.rgb.b
                    ),
                    Command::Shutdown { mode, .. } => mode.name().to_string(),
                    _ => return,
                };
                let row = self.row(topic);
                row.priority = Some(message.priority());
                row.latest = latest;
            }
            Message::Sample { priority, data } => {
                let topic = data.topic();
                if let SensorData::Diagnostics { page, .. } = &data {
                    self.diagnostics(topic, page);
                    return;
                }
                let (latest, value) = compact(&data);
                let row = self.row(topic);
                row.priority = Some(priority);
                row.latest = latest;
                if let Some(value) = value {
                    if row.history.len() == SPARK {
                        row.history.pop_front();
                    }
                    row.history.push_back(value);
                }
                if !starts_sample(&data) {
                    return;
                }
                row.samples += 1;
                if let Some(last) = row.last_sample_us.replace(time_us) {
                    let interval = time_us.saturating_sub(last);
                    if row.intervals.len() == INTERVALS {
                        row.intervals.pop_front();
                    }
                    row.intervals.push_back(interval);
                    if let Some(requested) = row.requested_us.filter(|r| *r > 0) {
                        if interval as f64 > requested as f64 * LATE_FACTOR {
                            row.late += 1;
                            // Intervals of about two periods or more stand for samples that never came.
                            let periods = (interval as f64 / requested as f64).round() as u64;
                            row.missing += periods.saturating_sub(1);
                        }
                    }
                }
            }
        }
    }

    fn diagnostics(&mut self, topic: Topic, page: &DiagnosticsPage) {
        let Some(board) = Board::ALL
            .into_iter()
            .find(|board| board.diagnostics_topic() == topic)
        else {
            return;
        };
        self.health
            .entry(topic.byte())
            .or_insert_with(|| (board, BoardHealth::default()))
            .1
            .absorb(page);
        if let DiagnosticsPage::VerdictRequest(request) = page {
            let word = match request.verdict {
                Verdict::Refused => "refused",
                Verdict::AcceptedWithWarning => "warned",
            };
            let what = if request.one_shot {
                format!("once {} at {}", request.topic, request.priority.name())
            } else {
                format!(
                    "publish {} every {} at {}",
                    request.topic,
                    crate::period::human_micros(request.requested.as_micros()),
                    request.priority.name()
                )
            };
            self.verdicts
                .insert(topic.byte(), format!("{word} \"{what}\""));
            let row = self.row(request.topic);
            row.verdict = Some(word);
            if request.verdict == Verdict::Refused && !request.one_shot {
                // The board kept what ran before; the period asked for is not the one to measure against.
                row.requested_us = None;
            }
        }
    }

    /// Samples that should have come since the last one and have not (a silent publisher).
    fn overdue(&self, row: &TopicRow) -> u64 {
        match (row.requested_us.filter(|r| *r > 0), row.last_sample_us) {
            (Some(requested), Some(last)) => {
                let silent = self.now_us.saturating_sub(last) as f64;
                if silent > requested as f64 * LATE_FACTOR {
                    (silent / requested as f64).floor() as u64
                } else {
                    0
                }
            }
            _ => 0,
        }
    }
}

mod live;
mod view;

pub use live::monitor;
pub use view::buffer_text;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_line;

    fn feed(dashboard: &mut Dashboard, lines: &[String]) {
        for line in lines {
            dashboard.heard(&parse_line(line).unwrap().unwrap());
        }
    }

    /// A robot with the gyroscope asked for every 100 ms, one sample lost; the ring at 62.5 ms; power status.
    fn scene() -> Vec<String> {
        let mut lines = vec!["(100.000000) can0 108#01640000".to_string()];
        for (i, ms) in [100u64, 200, 300, 500, 600].iter().enumerate() {
            let x = -4 + i as i16;
            let [a, b] = x.to_le_bytes();
            lines.push(format!(
                "({}.{:06}) can0 508#{a:02X}{b:02X}1E00FBFF",
                100 + ms / 1000,
                (ms % 1000) * 1000
            ));
        }
        lines.push("(100.610000) can0 71E#003E4701720C".into());
        lines.push("(100.620000) can0 71F#007800".into());
        lines.push("(100.620100) can0 71F#019000".into());
        lines.push("(100.682500) can0 71F#007900".into());
        lines
    }

    #[test]
    fn rows_show_values_periods_and_losses() {
        let mut dashboard = Dashboard::default();
        feed(&mut dashboard, &scene());
        let text = dashboard.text(80, 24);
        let gyro = text
            .lines()
            .find(|line| line.contains("gyroscope"))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(gyro.contains("DWD") && gyro.contains("high"), "{gyro}");
        assert!(gyro.contains("0 30 -5 dps"), "the latest sample: {gyro}");
        // Intervals 100, 100, 200, 100 ms: mean 125 ms measured against 100 ms asked; one late, one missing.
        assert!(gyro.contains("125/100"), "{gyro}");
        assert!(gyro.contains("1/1"), "{gyro}");
        assert!(
            gyro.contains('▁') && gyro.contains('█'),
            "sparkline: {gyro}"
        );
        let ring = text.lines().find(|l| l.contains("proximity-ring")).unwrap();
        assert!(
            ring.contains("62.5/-") && ring.contains("#0 121 mm"),
            "{ring}"
        );
        let power = text.lines().find(|l| l.contains("power-status")).unwrap();
        assert!(power.contains("62% 3186 mW"), "{power}");
        assert!(
            text.contains("DiWheelDrive: no diagnostics heard"),
            "{text}"
        );
        for line in text.lines() {
            assert!(line.chars().count() <= 80, "{line}");
        }
        assert_eq!(text.lines().count(), 24);
    }

    #[test]
    fn a_silent_publisher_counts_missing_samples_as_time_passes() {
        let mut dashboard = Dashboard::default();
        feed(&mut dashboard, &scene());
        dashboard.tick(Timestamp {
            secs: 101,
            micros: 600_000,
        });
        let text = dashboard.text(80, 24);
        let gyro = text.lines().find(|l| l.contains("gyroscope")).unwrap();
        // A second of silence after the last sample at 100.6 s: ten more missing.
        assert!(gyro.contains("1/11"), "{gyro}");
    }

    #[test]
    fn health_and_verdicts_come_from_the_diagnostics_pages() {
        let mut dashboard = Dashboard::default();
        feed(
            &mut dashboard,
            &[
                "(1.000000) can0 71A#00100E0000060903".into(),
                "(1.000000) can0 71A#0302000100341207".into(),
                "(1.100000) can0 41A#8009010002FA0046".into(),
                "(1.100000) can0 41A#8106D00700E80300".into(),
            ],
        );
        let text = dashboard.text(80, 24);
        assert!(text.contains("DiWheelDrive: up"), "{text}");
        assert!(
            text.contains("last verdict: refused \"publish accelerometer every 1 µs at urgent\""),
            "{text}"
        );
        let row = text
            .lines()
            .find(|l| l.contains("accelerometer"))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(row.contains("refused"), "{row}");
        assert!(
            row.contains("-/-"),
            "a refused request is not measured against: {row}"
        );
        assert!(text.contains("LightRing: no diagnostics heard"), "{text}");
    }
}
