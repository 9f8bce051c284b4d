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

    /// The end-of-run line; an error if the run did not reach its end.
    pub fn end_line(&self) -> Result<&str> {
        self.notes
            .iter()
            .find(|n| {
                n.starts_with("qemu: end of run") || n.starts_with("qemu: shutdown hand-over")
            })
            .map(String::as_str)
            .context("the run did not reach its end (no end-of-run line)")
    }

    /// A number of the end-of-run line (`rx dropped`, `rx overruns`, `ram static`, `stack`).
    pub fn end_field(&self, name: &str) -> Result<u64> {
        let line = self.end_line()?;
        let at = line
            .find(name)
            .with_context(|| format!("no `{name}` in `{line}`"))?
            + name.len();
        let digits: String = line[at..]
            .trim_start()
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect();
        digits
            .parse()
            .with_context(|| format!("bad `{name}` in `{line}`"))
    }

    /// RAM the run used: static data plus the stack's high-water mark (bytes), from the end-of-run
    /// line; an error if the run did not reach its end.
    pub fn ram_used(&self) -> Result<(u64, u64)> {
        Ok((self.end_field("ram static")?, self.end_field("stack")?))
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

/// How a published topic behaved: its release grid and each frame's latency from its release.
#[derive(Debug)]
pub struct Stream {
    /// Release times (µs) the firmware traced, in order.
    pub releases: Vec<u64>,
    /// Frame times (µs), in order.
    pub frames: Vec<u64>,
    /// Largest frame time minus its release (µs).
    pub worst_latency: u64,
}

impl RunOutput {
    /// Releases traced for `topic` (`sample-taken <topic> release=s.micros`) within `[from, to)`.
    pub fn releases(&self, topic: &str, from: u64, to: u64) -> Result<Vec<u64>> {
        let key = format!("sample-taken {topic} release=");
        let mut out = Vec::new();
        for note in &self.notes {
            if let Some(at) = note.find(&key) {
                let t = parse_seconds(
                    note[at + key.len()..]
                        .split_whitespace()
                        .next()
                        .unwrap_or(""),
                )?;
                if (from..to).contains(&t) {
                    out.push(t);
                }
            }
        }
        Ok(out)
    }

    /// The stream of frames `id` for `topic` within `[from, to)`: every release on the exact grid
    /// `first + k·period` (drift-free, none skipped), one frame per release, each after its release.
    pub fn periodic_stream(
        &self,
        id: u32,
        topic: &str,
        period: u64,
        from: u64,
        to: u64,
    ) -> Result<Stream> {
        let releases = self.releases(topic, from, to)?;
        let frames: Vec<u64> = self
            .times(id)
            .into_iter()
            .filter(|t| (from..to).contains(t))
            .collect();
        let first = *releases
            .first()
            .with_context(|| format!("no {topic} releases in {from}..{to} µs"))?;
        for (k, r) in releases.iter().enumerate() {
            let grid = first + k as u64 * period;
            ensure!(
                *r == grid,
                "{topic} release {k} at {r} µs is off the {period} µs grid ({grid} µs)"
            );
        }
        let expected = (to - first).div_ceil(period);
        ensure!(
            releases.len() as u64 == expected,
            "{} {topic} releases in {first}..{to} µs, expected {expected} at {period} µs",
            releases.len()
        );
        ensure!(
            frames.len() == releases.len(),
            "{} frames {id:03X} for {} releases",
            frames.len(),
            releases.len()
        );
        let mut worst = 0;
        for (k, (f, r)) in frames.iter().zip(&releases).enumerate() {
            ensure!(f >= r, "frame {k} at {f} µs precedes its release at {r} µs");
            ensure!(
                *f < r + period,
                "frame {k} at {f} µs is a full period after its release at {r} µs"
            );
            worst = worst.max(f - r);
        }
        Ok(Stream {
            releases,
            frames,
            worst_latency: worst,
        })
    }
}

fn parse_seconds(text: &str) -> Result<u64> {
    let (s, us) = text
        .split_once('.')
        .with_context(|| format!("bad time `{text}`"))?;
    ensure!(us.len() == 6, "bad time `{text}`");
    Ok(s.parse::<u64>()? * 1_000_000 + us.parse::<u64>()?)
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
        name: "shutdown",
        about: "SYS_PD_N falls: motors off, SYS_SYNC_N low, publishers stop, hand-over",
        check: shutdown,
    },
    Scenario {
        name: "flood",
        about: "commands at full bus rate keep a publisher within its bound; the excess is counted",
        check: flood,
    },
];

fn thesis_example(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    ensure!(
        out.frames.iter().all(|f| f.id == 0x605),
        "only magnetometer-x frames (0x605) expected"
    );
    ensure!(
        out.frames.iter().all(|f| f.data.len() == 4),
        "magnetometer frames carry 4 bytes"
    );
    let stream = out.periodic_stream(0x605, "magnetometer-x", 900, 10_000, 200_000)?;
    let answered = stream.releases[0] - 10_000;
    let bound = bounds.publisher_latency_us("magnetometer-x", "medium", 900)?;
    // The first release is the command's handling: it must come well inside one period.
    ensure!(
        answered < 900,
        "the publisher started {answered} µs after the command"
    );
    let worst = stream.worst_latency;
    ensure!(
        worst <= bound,
        "release jitter {worst} µs exceeds the analysed bound {bound} µs"
    );
    Ok(format!(
        "{} frames 0x605 every 900 µs (first release {answered} µs after the command), worst latency {worst} µs ≤ analysed {bound} µs",
        stream.frames.len()
    ))
}

fn stop_and_once(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let gyro = out.periodic_stream(0x508, "gyroscope", 10_000, 0, 105_000)?;
    ensure!(
        gyro.frames.len() == 10,
        "{} gyroscope frames before the stop, expected 10",
        gyro.frames.len()
    );
    let after_stop = out
        .times(0x508)
        .into_iter()
        .filter(|t| *t >= 105_000)
        .collect::<Vec<_>>();
    ensure!(
        after_stop.len() == 1,
        "after the stop exactly the one-shot frame expected, got {}",
        after_stop.len()
    );
    ensure!(
        (150_000..151_000).contains(&after_stop[0]),
        "one-shot answered at {} µs",
        after_stop[0]
    );
    let accel = out.periodic_stream(0x509, "accelerometer", 5_000, 200_000, 250_000)?;
    ensure!(
        accel.frames.len() == 10,
        "{} accelerometer frames from 200 ms, expected 10",
        accel.frames.len()
    );
    let after_once = out
        .times(0x509)
        .into_iter()
        .filter(|t| *t >= 250_000)
        .count();
    ensure!(
        after_once == 1,
        "a one-shot must stop the running publisher: {after_once} frames after it"
    );
    Ok("10 frames then silence after stop; one-shot sends one frame; a one-shot stops a running publisher".into())
}

fn priority_move(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let low = out.periodic_stream(0x708, "gyroscope", 5_000, 0, 52_500)?;
    let urgent_frames = out.times(0x408);
    ensure!(
        urgent_frames.iter().all(|t| *t >= 52_500),
        "urgent frames before the move"
    );
    ensure!(
        out.times(0x708).iter().all(|t| *t < 52_500),
        "low-priority frames after the move"
    );
    // An update keeps the release already scheduled (on the 5 ms grid from the first command) and
    // serves it at the new level: no extra sample, no gap (docs/handler.md).
    let urgent = out.periodic_stream(0x408, "gyroscope", 5_000, 52_500, 120_000)?;
    ensure!(
        urgent.releases[0] == low.releases[0] + 9 * 5_000,
        "the move changed the grid: first urgent release at {} µs",
        urgent.releases[0]
    );
    Ok(format!(
        "{} low-priority frames (0x708), then {} urgent (0x408) on the same grid, worst latency {} µs",
        low.frames.len(),
        urgent.frames.len(),
        urgent.worst_latency
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
    // Each bad frame with its own reason, in the order of the stimulus.
    let reasons: Vec<&str> = out
        .traces("command-rejected")
        .iter()
        .filter_map(|line| line.split_whitespace().last())
        .collect();
    let expected = [
        "unknown-topic",
        "bad-mode",
        "bad-unit",
        "dlc-too-short",
        "dlc-too-long",
        "zero-sample-time",
        "dlc-too-long",
        "dlc-too-short",
        "dlc-too-short",
        "period-too-long",
    ];
    ensure!(
        reasons == expected,
        "rejection reasons {reasons:?}, expected {expected:?}"
    );
    ensure!(
        out.frames.iter().all(|f| f.id == 0x608),
        "a bad frame made the board send something other than the gyroscope's frames"
    );
    let gyro = out.periodic_stream(0x608, "gyroscope", 2_000, 0, 150_000)?;
    Ok(format!(
        "{rejected} rejected, {ignored} ignored; gyroscope undisturbed: {} frames on its 2 ms grid, worst latency {} µs",
        gyro.frames.len(),
        gyro.worst_latency
    ))
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let gyro = out.periodic_stream(0x608, "gyroscope", 1_000, 0, 250_000)?;
    let bound = bounds.publisher_latency_us("gyroscope", "medium", 1_000)?;
    let worst = gyro.worst_latency;
    ensure!(
        worst <= bound,
        "latency {worst} µs under the flood exceeds the analysed bound {bound} µs"
    );
    // The command handler takes at most one command per COMMAND_MIN_INTERVAL_US: the flood's
    // excess waits in the bounded receive queue and is dropped there, counted. Every frame is
    // accounted for, and the handled ones are at least the interval apart.
    let handled: Vec<u64> = out
        .traces("command-")
        .iter()
        .map(|line| trace_time(line))
        .collect::<Result<_>>()?;
    let dropped = out.end_field("rx dropped")?;
    let overruns = out.end_field("rx overruns")?;
    ensure!(
        overruns == 0,
        "{overruns} receive-FIFO overruns: the receive interrupt fell behind"
    );
    ensure!(
        handled.len() as u64 + dropped == 2_001,
        "{} commands handled + {dropped} dropped and counted != the 2001 sent",
        handled.len()
    );
    if let Some(gap) = handled.windows(2).map(|w| w[1] - w[0]).min() {
        ensure!(
            gap >= COMMAND_MIN_INTERVAL_US,
            "two commands handled {gap} µs apart (the handler's minimum interval is {COMMAND_MIN_INTERVAL_US} µs)"
        );
    }
    Ok(format!(
        "{} commands handled at most one per {COMMAND_MIN_INTERVAL_US} µs, {dropped} dropped and counted; gyroscope on its 1 ms grid, worst latency {worst} µs ≤ analysed {bound} µs",
        handled.len()
    ))
}

/// The boards' command handler takes at most one command per this interval (their
/// `COMMAND_MIN_INTERVAL_US`, `docs/analysis.md`).
const COMMAND_MIN_INTERVAL_US: u64 = 400;

fn shutdown(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    const REQUEST: u64 = 100_000;
    let gyro = out.periodic_stream(0x208 | 0x400, "gyroscope", 2_000, 0, REQUEST)?;
    ensure!(
        gyro.frames.len() == 48,
        "{} gyroscope frames before the request, expected 48",
        gyro.frames.len()
    );
    let late: Vec<u64> = out
        .times(0x608)
        .into_iter()
        .filter(|t| *t > REQUEST + 100)
        .collect();
    ensure!(
        late.is_empty(),
        "frames after the shutdown request: {late:?}"
    );
    let stop = out
        .traces("motors-stopped shutdown")
        .first()
        .map(|l| trace_time(l))
        .transpose()?
        .context("no motors-stopped shutdown trace")?;
    ensure!(
        (REQUEST..REQUEST + 100).contains(&stop),
        "motors stopped at {stop} µs"
    );
    ensure!(
        out.notes
            .iter()
            .any(|n| n.contains("SYS_SYNC_N pulled low")),
        "SYS_SYNC_N was not pulled low"
    );
    let accepted_after = out
        .traces("command-accepted")
        .iter()
        .filter_map(|l| trace_time(l).ok())
        .filter(|t| *t > REQUEST)
        .count();
    ensure!(
        accepted_after == 0,
        "{accepted_after} commands accepted after the shutdown request"
    );
    let handover = out
        .notes
        .iter()
        .find(|n| n.starts_with("qemu: shutdown hand-over"))
        .context("no hand-over to the bootloader")?;
    Ok(format!("48 frames, then motors off at {stop} µs, SYS_SYNC_N low, no frames or commands after; {handover}"))
}

/// The time of a trace line `(s.micros) ...`.
fn trace_time(line: &str) -> Result<u64> {
    let stamp = line
        .strip_prefix('(')
        .and_then(|r| r.split_once(')'))
        .map(|(s, _)| s)
        .with_context(|| format!("trace line without time: {line}"))?;
    parse_seconds(stamp)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(lines: &[&str]) -> RunOutput {
        RunOutput::parse(&lines.join("\n")).unwrap()
    }

    #[test]
    fn a_clean_stream_passes() {
        let out = run(&[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "(0.001020) can0 608#000000000000",
            "# (0.002000) trace sample-taken gyroscope release=0.002000",
            "(0.002005) can0 608#000000000000",
        ]);
        let s = out
            .periodic_stream(0x608, "gyroscope", 1_000, 0, 3_000)
            .unwrap();
        assert_eq!(s.worst_latency, 20);
        assert_eq!(s.releases, vec![1_000, 2_000]);
    }

    #[test]
    fn drift_a_skipped_release_or_a_missing_frame_fails() {
        let drift = run(&[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "(0.001020) can0 608#00",
            "# (0.002001) trace sample-taken gyroscope release=0.002001",
            "(0.002005) can0 608#00",
        ]);
        assert!(drift
            .periodic_stream(0x608, "gyroscope", 1_000, 0, 3_000)
            .is_err());
        let skipped = run(&[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "(0.001020) can0 608#00",
        ]);
        assert!(skipped
            .periodic_stream(0x608, "gyroscope", 1_000, 0, 3_000)
            .is_err());
        let no_frame = run(&[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "# (0.002000) trace sample-taken gyroscope release=0.002000",
            "(0.002005) can0 608#00",
        ]);
        assert!(no_frame
            .periodic_stream(0x608, "gyroscope", 1_000, 0, 3_000)
            .is_err());
    }

    #[test]
    fn reads_the_end_of_run_line() {
        let out = run(&["# qemu: end of run at 5 us; rx dropped 0; ram static 5040 stack 2056"]);
        assert_eq!(out.ram_used().unwrap(), (5040, 2056));
        assert!(run(&["(0.000001) can0 608#00"]).ram_used().is_err());
    }
}
