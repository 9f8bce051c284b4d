//! The hostile-bus campaign (issue 12): seeded stimulus logs of random and targeted frames run
//! through every board's QEMU build, checked against an independent model of the verdicts.
//!
//! The model is written from `docs/protocol.md` (its topic table, the command rules and the
//! error names), not from amiro-can's decoder, so the two can disagree and a test catches it.
//! Every generated frame carries exactly one fault (or none), so its verdict is unambiguous.
//! Board-specific parts are one row of [`MODELS`]; a board with QEMU scenarios and no row fails.
//!
//! Per run: a reference publisher at urgent priority, then frames spaced 1 125–2 250 µs apart (more
//! than the command handler's 1 ms interval), then a burst 20 µs apart whose excess the handler drops,
//! then SYS_PD_N. Checks: the run ends; the reference keeps its exact grid; nothing unrequested is
//! sent; every traced verdict matches the model in order; handled + `rx dropped` + `rx overruns` = sent (the burst, 20 µs apart, is faster than any bus: its FIFO may overrun); the
//! stack's high-water mark is reported.

use std::path::Path;

use amiro_firmware::admission::COMMAND_MIN_INTERVAL_US;
use anyhow::{bail, ensure, Context, Result};
use schedule_analysis::rng::Rng;

use crate::boards::Board;
use crate::qemu::{self, TimedFrame, SIGNAL_SYS_PD_N};
use crate::scenarios::{self, RunOutput};

/// The spaced phase's gaps between frames: more than the command handler's interval
/// (`amiro_firmware::admission::COMMAND_MIN_INTERVAL_US`, 1 ms), so no spaced frame waits for a
/// command before it and none is dropped; up to twice that plus its margin.
const SPACED_MIN_US: u64 = COMMAND_MIN_INTERVAL_US + COMMAND_MIN_INTERVAL_US / 8;
const SPACED_MAX_US: u64 = 2 * SPACED_MIN_US;

/// Whose topic a byte is, from docs/protocol.md's topic table: (byte, board, actuator DLC or 0
/// for a sensor topic).
const PROTOCOL_TOPICS: &[(u8, &str, usize)] = &[
    (0x01, "diwheeldrive", 0),
    (0x02, "diwheeldrive", 0),
    (0x04, "diwheeldrive", 0),
    (0x05, "diwheeldrive", 0),
    (0x06, "diwheeldrive", 0),
    (0x07, "diwheeldrive", 0),
    (0x08, "diwheeldrive", 0),
    (0x09, "diwheeldrive", 0),
    (0x10, "diwheeldrive", 8),
    (0x11, "lightring", 3),
    (0x12, "lightring", 3),
    (0x13, "lightring", 3),
    (0x14, "lightring", 3),
    (0x15, "lightring", 3),
    (0x16, "lightring", 3),
    (0x17, "lightring", 3),
    (0x18, "lightring", 3),
    (0x1A, "diwheeldrive", 0),
    (0x1B, "powermgmt", 0),
    (0x1C, "lightring", 0),
    (0x1D, "powermgmt", 3),
    (0x1E, "powermgmt", 0),
    (0x1F, "powermgmt", 0),
];

/// What the campaign must know of a board beyond the protocol table.
pub struct BoardModel {
    /// Folder name, as in `boards.rs`.
    pub board: &'static str,
    /// The board's diagnostics topic (mode 3 sets the admission policy).
    pub diagnostics: u8,
    /// The reference publisher: topic byte, its trace name, period (µs). It runs at urgent
    /// priority for the whole run and no random frame addresses it.
    pub reference: (u8, &'static str, u64),
    /// Frames per sample of the reference topic (docs/protocol.md's topic table).
    pub reference_frames: usize,
    /// Actuator topics whose commands are harmless to accept at any value (not shutdown).
    pub actuators: &'static [u8],
    /// The identifier the board's QEMU build takes for its simulator's control frames (they never
    /// reach the app), which the campaign must therefore not send as an unknown topic.
    pub qemu_control_id: Option<u32>,
    /// Whether the board runs admission control (sensor commands go to its admission task).
    pub admission_task: bool,
}

/// One row per board with a QEMU build.
pub const MODELS: &[BoardModel] = &[
    BoardModel {
        board: "diwheeldrive",
        diagnostics: 0x1A,
        // Every 20 ms: on a 1-2 robot (the campaign runs the newest image) the gyroscope at urgent needs 10 494 µs
        // since DiWheelDrive 1-2's publisher rows are the machine code's (the BNO055 polled, 2026-12-06): every
        // 10 ms, the period before, is refused (`handle_commands` at 1 006 of 1 000 µs), and the run had no reference.
        reference: (0x08, "gyroscope", 20_000),
        reference_frames: 1,
        actuators: &[0x10],
        // amiro_firmware::qemu::SIM_CONTROL_ID (revision 1-2's dead BNO055)
        qemu_control_id: Some(0x3F0),
        admission_task: true,
    },
    BoardModel {
        board: "lightring",
        diagnostics: 0x1C,
        reference: (0x1C, "lightring-diagnostics", 100_000),
        reference_frames: 6,
        actuators: &[0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18],
        qemu_control_id: None,
        admission_task: true,
    },
    // The shutdown topic (0x1D) is not harmless: no random frame addresses it (it has a DLC, so it
    // is no sensor topic either); the scenarios test it.
    BoardModel {
        board: "powermgmt",
        diagnostics: 0x1B,
        reference: (0x1E, "power-status", 50_000),
        reference_frames: 1,
        actuators: &[],
        // amiro_firmware::qemu::SIM_CONTROL_ID
        qemu_control_id: Some(0x3F0),
        admission_task: true,
    },
];

/// The verdict the model expects for one frame.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Verdict {
    Accepted,
    Rejected(&'static str),
    Ignored,
}

/// A generated stimulus with what the model expects of it.
struct Plan {
    frames: Vec<TimedFrame>,
    /// Expected verdicts of the spaced phase, in order.
    expected: Vec<(u32, Verdict)>,
    /// Frames in the burst phase (all valid: accepted or dropped).
    burst: usize,
    /// Topics the stimulus may legitimately make the board publish (besides the reference).
    requested: Vec<u8>,
    /// When SYS_PD_N falls.
    shutdown_us: u64,
    /// When the burst starts.
    burst_us: u64,
}

fn command_id(priority: u64, topic: u8) -> u32 {
    ((priority as u32 & 3) << 8) | u32::from(topic)
}

/// Builds one run's stimulus of `count` spaced frames.
fn plan(model: &BoardModel, rng: &mut Rng, count: usize) -> Plan {
    let owner = |byte: u8| PROTOCOL_TOPICS.iter().find(|t| t.0 == byte);
    let own_sensors: Vec<u8> = PROTOCOL_TOPICS
        .iter()
        .filter(|t| {
            t.1 == model.board && t.2 == 0 && t.0 != model.reference.0 && t.0 != model.diagnostics
        })
        .map(|t| t.0)
        .collect();
    let others: Vec<u8> = PROTOCOL_TOPICS
        .iter()
        .filter(|t| t.1 != model.board)
        .map(|t| t.0)
        .collect();
    let unknown: Vec<u8> = (0u8..=0xFF).filter(|b| owner(*b).is_none()).collect();
    let mut frames = Vec::new();
    let mut expected = Vec::new();
    let mut requested = Vec::new();
    let (ref_topic, _, ref_period) = model.reference;
    // The reference publisher, urgent, period in ms.
    frames.push(TimedFrame {
        at_us: 1_000,
        id: command_id(0, ref_topic),
        data: vec![
            1,
            (ref_period / 1000) as u8,
            ((ref_period / 1000) >> 8) as u8,
            0,
        ],
    });
    expected.push((command_id(0, ref_topic), Verdict::Accepted));
    let mut t = 5_000u64;
    let mut push = |t: u64, id: u32, data: Vec<u8>, v: Verdict, exp: &mut Vec<(u32, Verdict)>| {
        frames.push(TimedFrame { at_us: t, id, data });
        exp.push((id, v));
    };
    let mut n = 0;
    while n < count {
        t += rng.range(SPACED_MIN_US, SPACED_MAX_US);
        let prio = rng.below(4);
        let class = rng.below(16);
        let sensor = if own_sensors.is_empty() {
            None
        } else {
            Some(rng.pick(&own_sensors))
        };
        match (class, sensor) {
            // Unknown topic, any DLC and data.
            (0 | 1, _) => {
                let dlc = rng.below(9) as usize;
                let mut id = command_id(prio, rng.pick(&unknown));
                if Some(id) == model.qemu_control_id {
                    id ^= 0x100;
                }
                push(
                    t,
                    id,
                    rng.bytes(dlc),
                    Verdict::Rejected("unknown-topic"),
                    &mut expected,
                );
            }
            // Another board's topic (also its shutdown): ignored whatever the data.
            (2 | 3, _) => {
                let dlc = rng.below(9) as usize;
                let id = command_id(prio, rng.pick(&others));
                push(t, id, rng.bytes(dlc), Verdict::Ignored, &mut expected);
            }
            // Sensor data (C/S = 1) on any topic byte: ignored.
            (4, _) => {
                let dlc = rng.below(9) as usize;
                let id = 0x400 | command_id(prio, rng.next_u64() as u8);
                push(t, id, rng.bytes(dlc), Verdict::Ignored, &mut expected);
            }
            // Bad mode with DLC 1 (3 only off the diagnostics topic).
            (5, Some(topic)) => {
                let mode = loop {
                    let m = rng.range(3, 255) as u8;
                    if m != 3 || topic != model.diagnostics {
                        break m;
                    }
                };
                push(
                    t,
                    command_id(prio, topic),
                    vec![mode],
                    Verdict::Rejected("bad-mode"),
                    &mut expected,
                );
            }
            // Bad unit.
            (6, Some(topic)) => {
                let time = rng.range(1, 0xFFFF) as u16;
                let unit = rng.range(3, 255) as u8;
                let [lo, hi] = time.to_le_bytes();
                push(
                    t,
                    command_id(prio, topic),
                    vec![1, lo, hi, unit],
                    Verdict::Rejected("bad-unit"),
                    &mut expected,
                );
            }
            // Wrong DLC for the mode.
            (7, Some(topic)) => {
                let (data, reason) = match rng.below(4) {
                    0 => (vec![], "dlc-too-short"),
                    1 => {
                        let len = rng.range(2, 3) as usize;
                        let mut d = rng.bytes(len);
                        d[0] = 1;
                        (d, "dlc-too-short")
                    }
                    2 => {
                        let len = rng.range(2, 8) as usize;
                        let mut d = rng.bytes(len);
                        d[0] = rng.pick(&[0u8, 2]);
                        (d, "dlc-too-long")
                    }
                    _ => {
                        let len = rng.range(5, 8) as usize;
                        let mut d = rng.bytes(len);
                        d[0] = 1;
                        (d, "dlc-too-long")
                    }
                };
                push(
                    t,
                    command_id(prio, topic),
                    data,
                    Verdict::Rejected(reason),
                    &mut expected,
                );
            }
            // Zero sample time in every unit.
            (8, Some(topic)) => {
                let unit = rng.below(3) as u8;
                push(
                    t,
                    command_id(prio, topic),
                    vec![1, 0, 0, unit],
                    Verdict::Rejected("zero-sample-time"),
                    &mut expected,
                );
            }
            // Period beyond 2^32 - 1 µs: only seconds reach it.
            (9, Some(topic)) => {
                let [lo, hi] = (rng.range(4295, 0xFFFF) as u16).to_le_bytes();
                push(
                    t,
                    command_id(prio, topic),
                    vec![1, lo, hi, 1],
                    Verdict::Rejected("period-too-long"),
                    &mut expected,
                );
            }
            // Huge valid periods (minutes to 71 minutes), low priority: accepted.
            (10, Some(topic)) => {
                let (time, unit) = if rng.below(2) == 0 {
                    (rng.range(600, 4294), 1)
                } else {
                    (rng.range(60_000, 0xFFFF), 0)
                };
                let [lo, hi] = (time as u16).to_le_bytes();
                push(
                    t,
                    command_id(3, topic),
                    vec![1, lo, hi, unit],
                    Verdict::Accepted,
                    &mut expected,
                );
                requested.push(topic);
            }
            // Stop, or one sample now, low priority: accepted.
            (11, Some(topic)) => {
                let mode = rng.pick(&[0u8, 2]);
                push(
                    t,
                    command_id(3, topic),
                    vec![mode],
                    Verdict::Accepted,
                    &mut expected,
                );
                if mode == 2 {
                    requested.push(topic);
                }
            }
            // A tiny period (500–999 µs) at low priority, stopped again 2–4 frames later.
            (12, Some(topic)) => {
                let [lo, hi] = (rng.range(500, 999) as u16).to_le_bytes();
                push(
                    t,
                    command_id(3, topic),
                    vec![1, lo, hi, 2],
                    Verdict::Accepted,
                    &mut expected,
                );
                t += rng.range(SPACED_MIN_US, SPACED_MAX_US);
                push(
                    t,
                    command_id(3, topic),
                    vec![0],
                    Verdict::Accepted,
                    &mut expected,
                );
                requested.push(topic);
                n += 1;
            }
            // Actuators: extreme values at the exact DLC (accepted), or a wrong DLC.
            (13 | 14, _) if !model.actuators.is_empty() => {
                let topic = rng.pick(model.actuators);
                let dlc = owner(topic).map_or(0, |t| t.2);
                let extreme = [0x00u8, 0xFF, 0x7F, 0x80];
                if class == 13 {
                    let data = (0..dlc).map(|_| rng.pick(&extreme)).collect();
                    push(
                        t,
                        command_id(prio, topic),
                        data,
                        Verdict::Accepted,
                        &mut expected,
                    );
                } else {
                    let wrong = loop {
                        let d = rng.below(9) as usize;
                        if d != dlc {
                            break d;
                        }
                    };
                    let reason = if wrong < dlc {
                        "dlc-too-short"
                    } else {
                        "dlc-too-long"
                    };
                    push(
                        t,
                        command_id(prio, topic),
                        rng.bytes(wrong),
                        Verdict::Rejected(reason),
                        &mut expected,
                    );
                }
            }
            // Admission policy on the diagnostics topic: 0/1 accepted, others bad-policy.
            _ => {
                let policy = rng.pick(&[0u8, 1, 2, 0x55, 0xFF]);
                let v = if policy <= 1 {
                    Verdict::Accepted
                } else {
                    Verdict::Rejected("bad-policy")
                };
                push(
                    t,
                    command_id(prio, model.diagnostics),
                    vec![3, policy],
                    v,
                    &mut expected,
                );
            }
        }
        n += 1;
    }
    // The burst: 40 valid admission-policy commands (harmless, accepted) 20 µs apart, faster
    // than one frame time; the handler takes one per 1 ms and drops what its queue cannot hold.
    let burst_us = t + 20_000;
    let burst = 40;
    for k in 0..burst as u64 {
        frames.push(TimedFrame {
            at_us: burst_us + 20 * k,
            id: command_id(3, model.diagnostics),
            data: vec![3, 0],
        });
    }
    let shutdown_us = burst_us + 40_000 + rng.below(20_000);
    frames.push(TimedFrame {
        at_us: shutdown_us,
        id: SIGNAL_SYS_PD_N,
        data: vec![],
    });
    Plan {
        frames,
        expected,
        burst,
        requested,
        shutdown_us,
        burst_us,
    }
}

/// The verdicts the board traced, in order: (identifier, verdict).
fn traced_verdicts(out: &RunOutput) -> Result<Vec<(u32, String)>> {
    let mut verdicts = Vec::new();
    for note in &out.notes {
        for kind in ["command-accepted", "command-rejected", "command-ignored"] {
            if let Some(at) = note.find(&format!("trace {kind} ")) {
                let rest = &note[at + kind.len() + 7..];
                let mut words = rest.split_whitespace();
                let id = u32::from_str_radix(words.next().unwrap_or(""), 16)
                    .with_context(|| format!("bad verdict line `{note}`"))?;
                let verdict = match kind {
                    "command-rejected" => format!(
                        "rejected {}",
                        words.next().unwrap_or("").trim_start_matches("reason=")
                    ),
                    "command-accepted" => "accepted".into(),
                    _ => "ignored".into(),
                };
                verdicts.push((id, verdict));
            }
        }
    }
    Ok(verdicts)
}

fn describe(v: &Verdict) -> String {
    match v {
        Verdict::Accepted => "accepted".into(),
        Verdict::Rejected(r) => format!("rejected {r}"),
        Verdict::Ignored => "ignored".into(),
    }
}

/// Checks one run's output against its plan; returns a one-line summary.
fn check(model: &BoardModel, plan: &Plan, out: &RunOutput) -> Result<String> {
    out.end_line()?;
    // Verdicts, in order, for the spaced phase; then the burst's.
    let traced = traced_verdicts(out)?;
    let spaced = plan.expected.len();
    // On a board with admission control (`admission_task`), valid commands to sensor topics (and
    // admission-policy commands) go to its admission task, which takes at most one publish request
    // per 40 ms from a queue of four: they are traced later than the command handler's frames
    // (each sequence stays in order), or refused with a verdict, or dropped and counted. Every other
    // frame must be traced in order, as the model says.
    // Which frames the firmware routes there (a routing rule of the firmware, not a verdict: so
    // amiro-can's decoder may decide it; the verdicts stay the model's).
    let routed = |frame: &TimedFrame| {
        model.admission_task
            && u16::try_from(frame.id).is_ok_and(|id| {
                // A stop is applied (and traced) by the command handler itself (issue 20).
                !amiro_firmware::admission::is_stop(id, &frame.data)
                    && matches!(
                        amiro_can::decode_command(id, &frame.data),
                        Ok(amiro_can::Command::Sensor(_) | amiro_can::Command::Policy { .. })
                    )
            })
    };
    let mut handler: Vec<&(u32, Verdict)> = Vec::new();
    let mut admission: Vec<&(u32, Verdict)> = Vec::new();
    for (expected, frame) in plan.expected.iter().zip(&plan.frames) {
        if routed(frame) {
            admission.push(expected);
        } else {
            handler.push(expected);
        }
    }
    let (mut h, mut a, mut burst_handled) = (0usize, 0usize, 0usize);
    for (k, (got_id, got)) in traced.iter().enumerate() {
        if let Some((id, want)) = handler.get(h) {
            if id == got_id && describe(want) == *got {
                h += 1;
                continue;
            }
        }
        if let Some(j) = (a..admission.len()).find(|&j| {
            admission
                .get(j)
                .is_some_and(|(id, want)| id == got_id && describe(want) == *got)
        }) {
            a = j + 1;
            continue;
        }
        // The burst: valid admission-policy commands, all accepted.
        ensure!(
            got == "accepted" && h == handler.len(),
            "traced verdict {k} ({got_id:03X} `{got}`) matches neither the model's next command ({}) nor a later admitted one",
            handler
                .get(h)
                .map_or("none left".to_string(), |(id, want)| format!("{id:03X} `{}`", describe(want)))
        );
        burst_handled += 1;
    }
    ensure!(
        h == handler.len(),
        "command {h} of the handler's {} ({}) was never traced",
        handler.len(),
        handler.get(h).map_or(String::new(), |(id, want)| format!(
            "{id:03X}: model says `{}`",
            describe(want)
        ))
    );
    ensure!(
        model.admission_task || traced.len() >= spaced,
        "{} verdicts traced, the spaced phase alone sent {spaced}",
        traced.len()
    );
    // Refused by the check or for a full admission queue (issue 20: busy refusals are counted, their
    // verdicts sent at most one per 40 ms), as the board counts them; a warning is traced as accepted.
    let verdicts = out
        .frames
        .iter()
        .filter(|f| {
            f.id & 0x4FF == 0x400 | u32::from(model.diagnostics) && f.data.first() == Some(&0x80)
        })
        .filter(|f| f.data.get(4).is_some_and(|b| b & 0x10 == 0))
        .count();
    let refused = if model.admission_task {
        out.end_field("admission refused")? as usize
    } else {
        verdicts
    };
    // Lost in the receive FIFO (bxCAN's overrun, counted per frame by the board) or by the software
    // queue: both are frames the board counted and did not handle.
    let overruns = out.end_field("rx overruns")? as usize;
    let dropped = out.end_field("rx dropped")? as usize;
    let sent = spaced + plan.burst;
    let accounted = traced.len() + refused + dropped + overruns;
    // Up to the admission queue and the request being decided may still wait when the run ends.
    ensure!(
        accounted <= sent && sent - accounted <= if model.admission_task { 9 } else { 0 },
        "counters: {} traced + {refused} refused by admission + {dropped} dropped + {overruns} overrun != {sent} sent",
        traced.len()
    );
    // The reference publisher's grid, from its first release to a period before SYS_PD_N.
    let (topic, name, period) = model.reference;
    let id = 0x400 | u32::from(topic);
    let first = *out
        .releases(name, 0, plan.shutdown_us)?
        .first()
        .with_context(|| format!("the reference publisher {name} never ran"))?;
    let stream = out.periodic_stream_of(
        id,
        name,
        period,
        first,
        plan.shutdown_us - period,
        model.reference_frames,
    )?;
    // Nothing unrequested.
    for frame in &out.frames {
        let byte = (frame.id & 0xFF) as u8;
        // Admission verdicts (pages 0x80, 0x81 of the board's diagnostics topic) answer refused requests.
        let verdict = byte == model.diagnostics && matches!(frame.data.first(), Some(0x80 | 0x81));
        let ok = frame.id == id
            || (frame.id & 0x400 != 0 && (plan.requested.contains(&byte) || verdict));
        ensure!(
            ok,
            "unrequested frame {:03X} at {} µs",
            frame.id,
            frame.at_us
        );
    }
    let (ram, stack) = out.ram_used()?;
    Ok(format!(
        "{} frames sent ({spaced} spaced, {} burst: {burst_handled} handled, {dropped} dropped, {overruns} overrun); \
         {} reference releases on the {period} µs grid, worst latency {} µs; burst at {} µs; \
         RAM static {ram} B, stack high-water {stack} B",
        spaced + plan.burst,
        plan.burst,
        stream.releases.len(),
        stream.worst_latency,
        plan.burst_us
    ))
}

/// Runs the campaign on every board that has QEMU scenarios: `runs` runs of `frames` spaced
/// frames each, seeds `seed`, `seed + 1`, ….
pub fn run(
    root: &Path,
    boards: &[&'static Board],
    seed: u64,
    frames: usize,
    runs: usize,
) -> Result<()> {
    let boards = boards
        .iter()
        .filter(|b| !scenarios::for_board(b.name).is_empty());
    // Every board's image built and every run planned first, then run.
    let mut jobs = Vec::new();
    for board in boards {
        let model = MODELS
            .iter()
            .find(|m| m.board == board.name)
            .with_context(|| {
                format!("board {} has QEMU scenarios but no campaign model (xtask/src/campaign.rs MODELS)", board.name)
            })?;
        // The board's newest revision (its default build).
        let elf = crate::workspace::build_qemu(
            root,
            &crate::revision::Build {
                board,
                revision: board.newest(),
            },
        )?;
        for k in 0..runs {
            let seed = seed.wrapping_add(k as u64);
            let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
            let plan = plan(model, &mut rng, frames);
            let work = qemu::fresh_work_dir(root, board.name);
            jobs.push((*board, model, elf.clone(), seed, plan, work));
        }
    }
    // The runs side by side (`qemu::run_each`: one per core, each in virtual time), checked in order.
    let outputs = qemu::run_each(&jobs, |(board, _, elf, _, plan, work)| {
        let duration = plan.shutdown_us + 100_000;
        let started = std::time::Instant::now();
        let text = qemu::run(elf, board.qemu_machine, &plan.frames, duration, work);
        (text, started.elapsed())
    })?;
    for ((board, model, _, seed, plan, work), (text, took)) in jobs.iter().zip(outputs) {
        let out = RunOutput::parse(&text?)?;
        match check(model, plan, &out) {
            Ok(summary) => println!(
                "campaign {} seed {seed}: ok in {:.1} s: {summary}",
                board.name,
                took.as_secs_f64()
            ),
            Err(e) => bail!(
                "campaign {} seed {seed} failed (output in {}): {e:#}",
                board.name,
                work.display()
            ),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_are_seeded_spaced_and_single_fault() {
        let model = &MODELS[0];
        let a = plan(model, &mut Rng::new(7), 500);
        let b = plan(model, &mut Rng::new(7), 500);
        assert_eq!(a.frames, b.frames);
        assert_eq!(a.expected.len(), 501);
        // The spaced phase keeps the command handler's interval.
        let spaced: Vec<u64> = a
            .frames
            .iter()
            .take(a.expected.len())
            .map(|f| f.at_us)
            .collect();
        assert!(spaced
            .windows(2)
            .all(|w| w[1] - w[0] > COMMAND_MIN_INTERVAL_US));
        assert!(a.frames.iter().all(|f| f.data.len() <= 8));
    }

    #[test]
    fn the_model_follows_the_protocol_document() {
        // Every row of the topic table in docs/protocol.md is in PROTOCOL_TOPICS.
        let doc = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/protocol.md"),
        )
        .unwrap();
        let rows = doc.lines().filter(|l| l.starts_with("| 0x")).count();
        assert_eq!(rows, PROTOCOL_TOPICS.len());
        for (byte, _, dlc) in PROTOCOL_TOPICS {
            let row = doc
                .lines()
                .find(|l| l.starts_with(&format!("| 0x{byte:02X} ")))
                .unwrap();
            let actuator = row.contains("| actuator |");
            assert_eq!(actuator, *dlc > 0, "{row}");
        }
    }
}
