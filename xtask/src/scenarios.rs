//! The QEMU scenarios CI runs against the DiWheelDrive firmware, and what each must show.
//!
//! Each scenario is a stimulus log in `diwheeldrive/qemu/` (its `# duration:` header says how long
//! the run lasts). The firmware's output — every frame it put on the bus, stamped with virtual time,
//! and its trace events — is parsed here and checked against the behaviour the protocol promises
//! and against the analysed response-time bound.
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};

use crate::qemu::{self, TimedFrame};

/// The firmware's output, split into frames and trace lines.
#[derive(Debug, Default)]
pub struct RunOutput {
    /// Frames the board put on the bus, in order.
    pub frames: Vec<TimedFrame>,
    /// Trace and log lines (without the leading `# `).
    pub notes: Vec<String>,
}

impl RunOutput {
    /// Parses the console output of a QEMU run.
    pub fn parse(text: &str) -> Result<Self> {
        let mut out = RunOutput::default();
        for line in text.lines() {
            let line = line.trim();
            if let Some(note) = line.strip_prefix('#') {
                out.notes.push(note.trim().to_string());
            } else if let Some(frame) = qemu::parse_log_line(line)? {
                out.frames.push(frame);
            }
        }
        Ok(out)
    }

    /// Timestamps of the frames with identifier `id`.
    pub fn times(&self, id: u32) -> Vec<u64> {
        self.frames
            .iter()
            .filter(|f| f.id == id)
            .map(|f| f.at_us)
            .collect()
    }

    /// RAM the run used: static data plus the stack's high-water mark (bytes), from the end-of-run
    /// line; an error if the run did not reach its end.
    pub fn ram_used(&self) -> Result<(u64, u64)> {
        let line = self
            .notes
            .iter()
            .find(|n| n.starts_with("qemu: end of run"))
            .context("the run did not reach its end (no end-of-run line)")?;
        let field = |name: &str| -> Result<u64> {
            let at = line.find(name).with_context(|| format!("no `{name}` in `{line}`"))? + name.len();
            let digits: String = line[at..].trim_start().chars().take_while(|c| c.is_ascii_digit()).collect();
            digits.parse().with_context(|| format!("bad `{name}` in `{line}`"))
        };
        Ok((field("ram static")?, field("stack")?))
    }

    /// Trace lines of one kind (e.g. `command-rejected`).
    pub fn traces(&self, kind: &str) -> Vec<&str> {
        self.notes
            .iter()
            .filter(|n| n.contains(kind))
            .map(String::as_str)
            .collect()
    }
}

/// The `# duration:` header of a stimulus log.
pub fn duration_of(path: &Path) -> Result<u64> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    for line in text.lines() {
        if let Some(d) = line.trim().strip_prefix("# duration:") {
            return qemu::parse_duration(d.trim());
        }
    }
    bail!("{} has no `# duration:` header", path.display())
}

/// Release jitter of a periodic stream: for frames at `times`, released on the grid
/// `first_release + k·period`, the largest `time − release` (µs). Fails if a release has no frame.
pub fn worst_latency(times: &[u64], first_release: u64, period: u64) -> Result<u64> {
    let mut worst = 0;
    for (k, t) in times.iter().enumerate() {
        let release = first_release + k as u64 * period;
        ensure!(
            *t >= release,
            "frame {k} at {t} µs precedes its release at {release} µs"
        );
        ensure!(
            *t < release + period,
            "frame {k} at {t} µs is a full period late (release {release} µs): a release was skipped"
        );
        worst = worst.max(t - release);
    }
    Ok(worst)
}

/// A named scenario and its check.
pub struct Scenario {
    /// File stem in `diwheeldrive/qemu/`.
    pub name: &'static str,
    /// What it shows.
    pub about: &'static str,
    /// The check.
    pub check: fn(&RunOutput, &Bounds) -> Result<String>,
}

/// Response-time bounds from the analysis, per published topic of the scenarios.
pub struct Bounds {
    root: std::path::PathBuf,
}

impl Bounds {
    /// Bounds computed by the schedule analysis from the DiWheelDrive app's own source.
    pub fn from_analysis(root: &Path) -> Result<Self> {
        Ok(Self {
            root: root.to_path_buf(),
        })
    }

    /// Worst-case latency from a publisher's release to its frame in a mailbox, as analysed for
    /// `topic` published alone at CAN priority `level` every `period_us`.
    pub fn publisher_latency_us(&self, topic: &str, level: &str, period_us: u64) -> Result<u64> {
        crate::bounds::publisher_bound_us(&self.root, topic, level, period_us)
    }
}

/// Every scenario CI runs.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "thesis-example",
        about: "0x205 01 84 03 02 → 0x605 every 900 µs",
        check: thesis_example,
    },
    Scenario {
        name: "stop-and-once",
        about: "stop, one-shot, one-shot stops a publisher",
        check: stop_and_once,
    },
    Scenario {
        name: "priority-move",
        about: "a topic moves from low to urgent",
        check: priority_move,
    },
    Scenario {
        name: "motor-deadman",
        about: "motor command, then silence → motors stop",
        check: motor_deadman,
    },
    Scenario {
        name: "malformed",
        about: "bad frames are counted and harmless",
        check: malformed,
    },
    Scenario {
        name: "flood",
        about: "commands at full bus rate keep a publisher within its bound",
        check: flood,
    },
];

fn thesis_example(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let times = out.times(0x605);
    ensure!(
        out.frames.iter().all(|f| f.id == 0x605),
        "only magnetometer-x frames expected"
    );
    ensure!(
        out.frames.iter().all(|f| f.data.len() == 4),
        "magnetometer frames carry 4 bytes"
    );
    // Commanded at 10 ms; publishing until 200 ms: releases at 10 ms + k·900 µs.
    let expected = (200_000 - 10_000) / 900 + 1;
    ensure!(
        times.len() as u64 >= expected - 1 && times.len() as u64 <= expected,
        "{} frames of 0x605, expected {expected}",
        times.len()
    );
    let worst = worst_latency(&times, times[0].min(10_000 + 900).max(10_000), 900)?;
    let first = times[0] - 10_000;
    let bound = bounds.publisher_latency_us("magnetometer-x", "medium", 900)?;
    ensure!(
        worst <= bound,
        "release jitter {worst} µs exceeds the analysed bound {bound} µs"
    );
    Ok(format!("{} frames 0x605 every 900 µs, first {first} µs after the command, worst latency {worst} µs ≤ analysed {bound} µs", times.len()))
}

fn stop_and_once(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let gyro = out.times(0x508);
    let before_stop = gyro.iter().filter(|t| **t < 105_000).count();
    ensure!(
        before_stop == 10,
        "{before_stop} gyroscope frames before the stop, expected 10 (10..100 ms)"
    );
    let after_stop: Vec<_> = gyro.iter().filter(|t| **t >= 105_000).collect();
    ensure!(
        after_stop.len() == 1,
        "after the stop exactly the one-shot frame expected, got {}",
        after_stop.len()
    );
    ensure!(
        (150_000..151_000).contains(after_stop[0]),
        "one-shot answered at {} µs",
        after_stop[0]
    );
    let accel = out.times(0x509);
    let before_once = accel.iter().filter(|t| **t < 250_000).count();
    ensure!(
        before_once == 10,
        "{before_once} accelerometer frames at 5 ms from 200 ms, expected 10"
    );
    let after_once = accel.iter().filter(|t| **t >= 250_000).count();
    ensure!(
        after_once == 1,
        "a one-shot must stop the running publisher: {after_once} frames after it"
    );
    Ok("stop silences, one-shot sends exactly one frame and stops a running publisher".into())
}

fn priority_move(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let low = out.times(0x708);
    let urgent = out.times(0x408);
    ensure!(
        !low.is_empty() && !urgent.is_empty(),
        "frames at both priorities expected"
    );
    ensure!(
        low.iter().all(|t| *t < 52_500),
        "low-priority frames after the move"
    );
    ensure!(
        urgent.iter().all(|t| *t >= 52_500),
        "urgent frames before the move"
    );
    // An update keeps the release already scheduled (55 ms, on the 5 ms grid from 10 ms) and
    // serves it at the new level: no extra sample, no gap (docs/handler.md).
    let worst = worst_latency(&urgent, 55_000, 5_000)?;
    ensure!(
        urgent.len() == 14,
        "{} urgent frames, expected 14 (55..120 ms)",
        urgent.len()
    );
    let last_low = low.last().copied().unwrap_or(0);
    ensure!(
        urgent[0] - last_low < 5_000 + worst,
        "gap of {} µs at the move",
        urgent[0] - last_low
    );
    Ok(format!(
        "{} low-priority frames (0x708), then {} urgent (0x408), worst latency {worst} µs",
        low.len(),
        urgent.len()
    ))
}

fn motor_deadman(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let stops = out.traces("motors-stopped");
    ensure!(
        stops.len() == 1,
        "one dead-man stop expected, got {}",
        stops.len()
    );
    let stop_at = trace_time(stops[0])?;
    ensure!(
        (510_000..=530_000).contains(&stop_at),
        "dead-man stop at {stop_at} µs; the command came at 10 ms, the timeout is 500 ms, control runs every 10 ms"
    );
    // Velocity frames (0x502, i32 µm/s first) show the robot moving, then standing.
    let velocity: Vec<(u64, i32)> = out
        .frames
        .iter()
        .filter(|f| f.id == 0x502 && f.data.len() == 8)
        .map(|f| {
            (
                f.at_us,
                i32::from_le_bytes([f.data[0], f.data[1], f.data[2], f.data[3]]),
            )
        })
        .collect();
    let moving = velocity
        .iter()
        .filter(|(t, v)| *t > 200_000 && *t < 500_000 && *v > 50_000)
        .count();
    ensure!(moving > 0, "the robot never reached speed: {velocity:?}");
    let last = velocity.last().map(|(_, v)| *v).unwrap_or(i32::MAX);
    ensure!(last.abs() < 5_000, "still moving at the end: {last} µm/s");
    Ok(format!(
        "drove, then the dead-man stopped the motors at {stop_at} µs; final velocity {last} µm/s"
    ))
}

fn malformed(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let rejected = out.traces("command-rejected").len();
    ensure!(
        rejected == 10,
        "10 malformed frames must each be rejected and counted, got {rejected}"
    );
    let ignored = out.traces("command-ignored").len();
    ensure!(
        ignored == 1,
        "the LightRing command must be ignored, got {ignored}"
    );
    let gyro = out.times(0x608);
    let worst = worst_latency(&gyro, gyro.first().copied().unwrap_or(5_000), 2_000)?;
    let expected = (150_000 - 5_000) / 2_000;
    ensure!(
        gyro.len() as u64 >= expected,
        "{} gyroscope frames, expected {expected}: the publisher was disturbed",
        gyro.len()
    );
    Ok(format!("{rejected} rejected, {ignored} ignored, gyroscope undisturbed ({} frames, worst latency {worst} µs)", gyro.len()))
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let gyro = out.times(0x608);
    let first = gyro.first().copied().context("no gyroscope frames")?;
    let worst = worst_latency(&gyro, first.min(5_000 + 1_000).max(5_000), 1_000)?;
    let bound = bounds.publisher_latency_us("gyroscope", "medium", 1_000)?;
    ensure!(
        worst <= bound,
        "latency {worst} µs under the flood exceeds the analysed bound {bound} µs"
    );
    let handled = out.traces("command-").len();
    ensure!(
        handled >= 1_900,
        "only {handled} of the 2000 flood frames were handled"
    );
    Ok(format!(
        "{handled} flood frames handled; gyroscope worst latency {worst} µs ≤ analysed {bound} µs"
    ))
}

/// The time of a trace line `(s.micros) ...`.
fn trace_time(line: &str) -> Result<u64> {
    let stamp = line
        .strip_prefix('(')
        .and_then(|r| r.split_once(')'))
        .map(|(s, _)| s)
        .with_context(|| format!("trace line without time: {line}"))?;
    let (s, us) = stamp.split_once('.').context("bad trace time")?;
    Ok(s.parse::<u64>()? * 1_000_000 + us.parse::<u64>()?)
}
