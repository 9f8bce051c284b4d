//! `cargo xtask timeline`: several boards' captures and a `candump -l` log of the bus on one time
//! base — the bus log's — aligned by the frames both sides saw (a board's `frame-acked` records and
//! the same identifiers in the log), so one sample can be followed from its release on a board to
//! the bus.
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::capture::{self, Capture};
use crate::qemu::TimedFrame;

/// Arguments of `cargo xtask timeline`.
#[derive(clap::Args, Debug)]
pub struct TimelineArgs {
    /// A board's capture of its trace channel: `board=FILE` (repeat for each board).
    #[arg(long = "capture", value_name = "BOARD=FILE", required = true)]
    pub captures: Vec<String>,
    /// The bus, as `candump -l` logged it.
    #[arg(long, value_name = "FILE")]
    pub candump: PathBuf,
    /// Write the merged timeline here instead of standard output.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// How one board's clock maps onto the bus log's.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    /// Add this to the board's time (ns) to get the bus log's (ns).
    pub offset_ns: i128,
    /// Acknowledged frames of the board that found their frame in the log.
    pub matched: usize,
    /// Acknowledged frames of the board.
    pub frames: usize,
    /// Matches of the best other offset (equal to `matched`: the alignment is ambiguous).
    pub runner_up: usize,
    /// Largest |log − (board + offset)| over the matched frames, ns.
    pub residual_ns: u64,
}

/// Frames closer than this (ns) count as the same frame once aligned: a frame's acknowledgement
/// and candump's time stamp of it differ by the receiver's latency.
const TOLERANCE_NS: i128 = 200_000;

/// Finds the offset that makes the most of `acked` (identifier, board ns) land on a frame of
/// the same identifier in `bus` (identifier, log ns).
pub fn align(acked: &[(u16, u64)], bus: &[(u16, u64)]) -> Option<Alignment> {
    let mut by_id: BTreeMap<u16, Vec<u64>> = BTreeMap::new();
    for &(id, t) in bus {
        by_id.entry(id).or_default().push(t);
    }
    let matches = |offset: i128| -> (usize, u64, i128) {
        let mut n = 0;
        let mut worst = 0u64;
        let mut sum = 0i128;
        for &(id, t) in acked {
            let Some(times) = by_id.get(&id) else {
                continue;
            };
            let want = i128::from(t) + offset;
            let at = times.partition_point(|&x| i128::from(x) < want);
            let best = [at.checked_sub(1), Some(at)]
                .into_iter()
                .flatten()
                .filter_map(|i| times.get(i))
                .map(|&x| i128::from(x) - want)
                .min_by_key(|d| d.abs());
            if let Some(d) = best.filter(|d| d.abs() <= TOLERANCE_NS) {
                n += 1;
                worst = worst.max(d.unsigned_abs() as u64);
                sum += d;
            }
        }
        (n, worst, sum)
    };
    // Candidate offsets: every pairing of one of the first acknowledged frames with a logged frame
    // of its identifier.
    let mut candidates: Vec<i128> = Vec::new();
    for &(id, t) in acked.iter().take(16) {
        for &x in by_id.get(&id).map(Vec::as_slice).unwrap_or(&[]) {
            candidates.push(i128::from(x) - i128::from(t));
        }
    }
    candidates.sort_unstable();
    candidates.dedup();
    let mut scored: Vec<(usize, u64, i128)> = candidates
        .iter()
        .map(|&o| {
            let (n, worst, sum) = matches(o);
            // Centre the offset on the matched frames' mean difference.
            let refined = if n > 0 { o + sum / n as i128 } else { o };
            (n, worst, refined)
        })
        .collect();
    // Most matches first, then the tightest fit.
    scored.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    let &(matched, _, offset) = scored.first()?;
    let (matched_refined, residual, _) = matches(offset);
    let runner_up = scored
        .iter()
        .find(|s| (s.2 - offset).abs() > 2 * TOLERANCE_NS)
        .map_or(0, |s| s.0);
    Some(Alignment {
        offset_ns: offset,
        matched: matched_refined.max(matched),
        frames: acked.len(),
        runner_up,
        residual_ns: residual,
    })
}

/// One board's capture on the bus log's time base.
pub struct Aligned<'a> {
    /// Board name.
    pub board: String,
    /// Its capture.
    pub capture: &'a Capture,
    /// Its alignment.
    pub alignment: Alignment,
}

fn shift(t: u64, offset: i128) -> i128 {
    i128::from(t) + offset
}

/// A `candump -l` timestamp of a time that may lie before the capture's origin (negative after the
/// alignment), which `amiro_can::candump::Timestamp` cannot hold: floor division keeps the digits
/// of such a time in the same form.
fn stamp(ns: i128) -> String {
    let us = ns.div_euclid(1_000);
    format!(
        "({}.{:06})",
        us.div_euclid(1_000_000),
        us.rem_euclid(1_000_000)
    )
}

/// The merged timeline: every board's task runs, samples and acknowledgements and every logged
/// frame, in the bus log's time; then per topic the largest release → logged-on-the-bus latency.
pub fn merge(
    boards: &[Aligned<'_>],
    bus: &[TimedFrame],
    names: &BTreeMap<String, Vec<String>>,
) -> String {
    let mut lines: Vec<(i128, String)> = Vec::new();
    let mut summary = String::new();
    for b in boards {
        let a = &b.alignment;
        let task = |n: u8| {
            names
                .get(&b.board)
                .and_then(|v| v.get(usize::from(n)))
                .cloned()
                .unwrap_or_else(|| format!("task{n}"))
        };
        for run in &b.capture.runs {
            lines.push((
                shift(run.start_ns, a.offset_ns),
                format!(
                    "{} run {} ({:.1} µs)",
                    b.board,
                    task(run.task),
                    run.execution_ns() as f64 / 1e3
                ),
            ));
        }
        let mut worst: BTreeMap<String, i128> = BTreeMap::new();
        for s in &b.capture.samples {
            let release = shift(s.release_ns, a.offset_ns);
            lines.push((release, format!("{} release {}", b.board, s.topic.name())));
            if let Some(acked) = s.acked_ns {
                // The logged frame this acknowledgement matched.
                let t = shift(acked, a.offset_ns);
                let logged = bus
                    .iter()
                    .map(|f| i128::from(f.at_us) * 1_000)
                    .filter(|x| (x - t).abs() <= TOLERANCE_NS)
                    .min_by_key(|x| (x - t).abs());
                if let Some(logged) = logged {
                    let e = worst.entry(s.topic.name().to_string()).or_default();
                    *e = (*e).max(logged - release);
                }
            }
        }
        for &(id, t) in &b.capture.acked {
            lines.push((shift(t, a.offset_ns), format!("{} acked {id:03X}", b.board)));
        }
        let _ = writeln!(
            summary,
            "# {}: offset {:+.3} ms, {} of {} acknowledged frames found in the bus log (next best offset: {}), residual ≤ {:.1} µs{}",
            b.board,
            a.offset_ns as f64 / 1e6,
            a.matched,
            a.frames,
            a.runner_up,
            a.residual_ns as f64 / 1e3,
            if a.runner_up >= a.matched { " — AMBIGUOUS (periodic traffic only?)" } else { "" }
        );
        for (topic, ns) in worst {
            let _ = writeln!(
                summary,
                "# {}: {topic}: release → logged on the bus ≤ {:.1} µs",
                b.board,
                ns as f64 / 1e3
            );
        }
    }
    for f in bus {
        let data: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
        lines.push((
            i128::from(f.at_us) * 1_000,
            format!("bus {:03X}#{data}", f.id),
        ));
    }
    lines.sort_by_key(|l| l.0);
    let mut out = summary;
    for (t, text) in lines {
        let _ = writeln!(out, "{} {text}", stamp(t));
    }
    out
}

/// `cargo xtask timeline`.
pub fn run(root: &std::path::Path, args: &TimelineArgs) -> Result<()> {
    let bus = crate::qemu::read_stimulus(&args.candump)?;
    let bus_ids: Vec<(u16, u64)> = bus
        .iter()
        .filter_map(|f| Some((u16::try_from(f.id).ok()?, f.at_us * 1_000)))
        .collect();
    let mut captures = Vec::new();
    let mut names = BTreeMap::new();
    for spec in &args.captures {
        let (board, file) = spec
            .split_once('=')
            .with_context(|| format!("`{spec}`: expected BOARD=FILE"))?;
        let b =
            crate::boards::by_name(board).with_context(|| format!("unknown board `{board}`"))?;
        let bytes = std::fs::read(file).with_context(|| format!("reading {file}"))?;
        captures.push((
            board.to_string(),
            capture::read(&bytes, super::default_clock_hz(b, false))?,
        ));
        if let Ok(list) = amiro_firmware::trace_ids::board_names(root, board) {
            names.insert(board.to_string(), list);
        }
    }
    let mut aligned = Vec::new();
    for (board, capture) in &captures {
        let Some(alignment) = align(&capture.acked, &bus_ids) else {
            bail!("{board}: no acknowledged frame of its capture is in the bus log: nothing to align by");
        };
        aligned.push(Aligned {
            board: board.clone(),
            capture,
            alignment,
        });
    }
    let text = merge(&aligned, &bus, &names);
    match &args.out {
        Some(path) => {
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_sensors::trace::{TraceEvent, TraceKind};
    use amiro_trace::{Kind, Record};

    /// A board's capture: its clock, its frames (identifier, board µs, release µs).
    fn capture(clock_hz: u64, frames: &[(u16, u64, u64)]) -> Vec<u8> {
        let cycles = |us: u64| us * clock_hz / 1_000_000;
        let mut records = vec![Record {
            cycles: 0,
            kind: Kind::Hello {
                clock_hz: clock_hz as u32,
            },
        }];
        for &(id, at, release) in frames {
            let topic = amiro_can::Topic::from_byte((id & 0xFF) as u8).unwrap();
            let taken = TraceEvent::new(
                release + 5,
                TraceKind::SampleTaken {
                    topic,
                    release_us: release,
                },
            );
            let queued = TraceEvent::new(release + 20, TraceKind::FrameQueued { id });
            records.push(Record {
                cycles: cycles(release + 5),
                kind: Kind::Event {
                    record: taken.encode(),
                },
            });
            records.push(Record {
                cycles: cycles(release + 20),
                kind: Kind::Event {
                    record: queued.encode(),
                },
            });
            records.push(Record {
                cycles: cycles(at),
                kind: Kind::FrameAcked { id },
            });
        }
        records
            .iter()
            .flat_map(|r| r.encode().as_bytes().to_vec())
            .collect()
    }

    #[test]
    fn two_boards_with_known_offsets_land_on_the_bus_log() {
        // DiWheelDrive (72 MHz) publishes the gyroscope every 10 ms and, once, the accelerometer;
        // PowerManagement (168 MHz) the power status every 50 ms, the ring once. Their clocks started
        // 1.234567 s and 0.5 s before the bus log's zero; candump stamps each frame 40–90 µs late.
        let (dwd_offset, pm_offset) = (1_234_567u64, 500_000u64);
        let mut dwd = Vec::new();
        for k in 0..40u64 {
            let release = 3_000 + k * 10_000;
            dwd.push((0x508u16, release + 140 + (k * 37) % 60, release));
        }
        dwd.push((0x509u16, 123_456, 123_300));
        let mut pm = Vec::new();
        for k in 0..8u64 {
            let release = 7_000 + k * 50_000;
            pm.push((0x51Eu16, release + 200 + (k * 13) % 40, release));
        }
        pm.push((0x61Fu16, 234_567, 234_400));
        let mut bus: Vec<TimedFrame> = Vec::new();
        for (frames, offset) in [(&dwd, dwd_offset), (&pm, pm_offset)] {
            for (k, &(id, at, _)) in frames.iter().enumerate() {
                bus.push(TimedFrame {
                    at_us: 10_000_000 + at + offset + 40 + (k as u64 * 7) % 50,
                    id: u32::from(id),
                    data: vec![1, 2],
                });
            }
        }
        // A command from the operator that no board acknowledged.
        bus.push(TimedFrame {
            at_us: 10_100_000,
            id: 0x205,
            data: vec![1],
        });
        bus.sort_by_key(|f| f.at_us);
        let bus_ids: Vec<(u16, u64)> = bus.iter().map(|f| (f.id as u16, f.at_us * 1_000)).collect();

        let a = capture::read(&capture(72_000_000, &dwd), 1).unwrap();
        let b = capture::read(&capture(168_000_000, &pm), 1).unwrap();
        let align_a = align(&a.acked, &bus_ids).unwrap();
        let align_b = align(&b.acked, &bus_ids).unwrap();
        for (al, offset, n) in [
            (&align_a, dwd_offset, dwd.len()),
            (&align_b, pm_offset, pm.len()),
        ] {
            let expected = i128::from(10_000_000 + offset) * 1_000;
            // Recovered to within candump's latency (40–90 µs, centred by the mean).
            assert!(
                (al.offset_ns - expected - 65_000).abs() <= 30_000,
                "{al:?} vs {expected}"
            );
            assert_eq!((al.matched, al.frames), (n, n));
            assert!(al.runner_up < al.matched, "{al:?}");
        }
        let text = merge(
            &[
                Aligned {
                    board: "diwheeldrive".into(),
                    capture: &a,
                    alignment: align_a,
                },
                Aligned {
                    board: "powermgmt".into(),
                    capture: &b,
                    alignment: align_b,
                },
            ],
            &bus,
            &BTreeMap::new(),
        );
        // Release → logged: 140..200 µs on the board + 40..90 µs of candump, minus the centring.
        let line = text
            .lines()
            .find(|l| l.contains("diwheeldrive: gyroscope"))
            .unwrap();
        let us: f64 = line
            .split("≤ ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!((150.0..=300.0).contains(&us), "{line}");
        // The bus lines and both boards' releases are on one time base, in order.
        let first_release = text
            .lines()
            .position(|l| l.ends_with("diwheeldrive release gyroscope"))
            .unwrap();
        let its_frame = text
            .lines()
            .skip(first_release)
            .position(|l| l.contains("bus 508#"))
            .unwrap();
        assert!(its_frame > 0);
        assert!(text.contains("powermgmt release power-status"));
    }

    #[test]
    fn periodic_traffic_alone_is_reported_ambiguous() {
        let frames: Vec<(u16, u64, u64)> = (0..10)
            .map(|k| (0x508u16, 1_000 + k * 10_000, 900 + k * 10_000))
            .collect();
        let c = capture::read(&capture(72_000_000, &frames), 1).unwrap();
        // The log runs longer than the capture: shifted by a period it matches as well.
        let bus: Vec<(u16, u64)> = (0..30u64)
            .map(|k| (0x508u16, (5_000 + k * 10_000) * 1_000))
            .collect();
        let al = align(&c.acked, &bus).unwrap();
        assert!(al.runner_up >= al.matched);
    }
}
