//! DiWheelDrive's QEMU scenarios (`diwheeldrive/qemu/*.log`) and what each must show.
use amiro_firmware::admission::COMMAND_MIN_INTERVAL_US;
use anyhow::{ensure, Context, Result};

use super::{check_health, trace_time, Bounds, RunOutput, Scenario};

/// Every scenario CI runs.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "thesis-example",
        about: "0x205 01 84 03 02 (every 900 µs) and every 5 ms refused as the host decides (DiWheelDrive 1-1's polled HMC5883L: a 3.1 ms job); every 6 ms → 0x605 on its grid",
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
        name: "hostile",
        about: "hostile traffic that hung the QEMU build before the deadlock fix: the run ends, every frame accounted for",
        check: hostile,
    },
    Scenario {
        name: "admission-starvation",
        about: "issue 11: the 1 µs urgent request is refused with its reason, and every topic at every priority at 1 µs; running grids kept, lowest level alive; a 3 ms request accepted",
        check: admission_starvation,
    },
    Scenario {
        name: "admission-units",
        about: "issue 11: every topic at every priority every 1 ms and every 1 s, each decided as the host decides; odometry keeps its grid, the low level keeps sending",
        check: admission_units,
    },
    Scenario {
        name: "admission-warn",
        about: "the hard floor under accept-and-warn: magnetometer-x every 400 µs (the admission task left without a bound) and the two-frame attack (accelerometer every 1 µs at urgent) refused with verdicts; the gyroscope keeps its grid",
        check: admission_warn,
    },
    Scenario {
        name: "admission-other-board",
        about: "a request that breaks only another board's frames (PowerManagement's ring) is refused by the board that would send the new frames",
        check: admission_other_board,
    },
    Scenario {
        name: "admission-cost",
        about: "benchmark: the admission check's instructions and virtual time per decision with every topic of the robot requested, against the admission task's budget; its decisions and refresh steps those of the host's replay",
        check: admission_cost,
    },
    Scenario {
        name: "admission-search",
        about: "issue 20: the costliest command sequence a search found (amiro-firmware/examples/admission_search.rs), replayed: every step within the admission task's budget per step; the costliest reaches the check's iteration budget per decision",
        check: admission_search,
    },
    Scenario {
        name: "admission-latency",
        about: "issue 20: five requests 5 ms apart each take effect (first sample on the bus) within 5 ms of their frame; a stop takes effect within the command handler's 1 ms interval",
        check: admission_latency,
    },
    Scenario {
        name: "admission-one-shots",
        about: "issue 20: beside magnetometer-x every 3 650 µs (near its boundary on 1-1, 3 572 µs alone: its polled HMC5883L makes its job 1.35 ms and each topic has a transmit job; the thesis's 900 µs is refused alone) a gyroscope one-shot at low, a floor-sensor one-shot at medium and the accelerometer every 10 ms at low refused with verdicts within 5 ms, the magnetometer's grid untouched; with the magnetometer every 6 ms the gyroscope one-shot answered within 2 ms and the accelerometer admitted",
        check: admission_one_shots,
    },
    Scenario {
        name: "flood",
        about: "commands at full bus rate keep a publisher within its bound; the excess is counted",
        check: flood,
    },
];

/// `diwheeldrive/qemu/thesis-example.log`: the thesis's worked example (magnetometer-x every 900 µs at medium) and
/// every 2.5 ms are refused on DiWheelDrive 1-1 (its polled HMC5883L makes a magnetometer-x job 1.35 ms), each verdict
/// equal to the host's check; every 6 ms, with a clear margin, is admitted and runs on its exact grid within the
/// analysed bound.
fn thesis_example(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    use amiro_can::{Topic, Verdict};
    // (frame time, command, period µs): the two refused requests.
    const REFUSED: [(u64, &str, u64); 2] = [
        (10_000, "205#01840302", 900),
        (55_000, "205#01C40902", 2_500),
    ];
    const ADMITTED_AT: u64 = 100_000;
    const PERIOD: u64 = 6_000;
    let verdict_id = 0x600 | u32::from(amiro_can::Board::DiWheelDrive.diagnostics_topic().byte());
    ensure!(
        out.frames
            .iter()
            .all(|f| f.id == 0x605 || f.id == verdict_id),
        "only magnetometer-x frames (0x605) and the verdicts' (0x{verdict_id:03X}) expected"
    );
    ensure!(
        out.times(0x605).iter().all(|f| *f > ADMITTED_AT),
        "a magnetometer-x frame before the admitted request: a refused request started"
    );
    let verdicts = verdicts(out);
    ensure!(
        verdicts.len() == REFUSED.len(),
        "{} verdicts, expected the refusals of 900 and 2 500 µs",
        verdicts.len()
    );
    let mut refusals = Vec::new();
    for ((at, v), (sent, command, micros)) in verdicts.iter().zip(REFUSED) {
        ensure!(
            v.verdict == Verdict::Refused
                && v.topic == Topic::MagnetometerX
                && v.requested.as_micros() == micros,
            "not the refusal of magnetometer-x every {micros} µs: {v}"
        );
        ensure!(
            *at >= sent && at - sent <= 5_000,
            "the refusal of {micros} µs came {} µs after its frame",
            at.saturating_sub(sent)
        );
        let host = super::host_admission(bounds.root(), &[], command)?;
        super::same_refusal(v, &host)?;
        refusals.push(format!("{v} ({} µs after its frame)", at - sent));
    }
    ensure!(
        out.frames
            .iter()
            .all(|f| f.id != 0x605 || f.data.len() == 4),
        "magnetometer frames carry 4 bytes"
    );
    // The window ends just after the last frame: every release before it has its frame in the run
    // (one publisher's frames leave in release order), and no release after it is counted.
    let end = out
        .times(0x605)
        .last()
        .map(|t| t + 1)
        .context("no magnetometer-x frame")?;
    let stream = out.periodic_stream(0x605, "magnetometer-x", PERIOD, ADMITTED_AT, end)?;
    let answered = stream.releases[0] - ADMITTED_AT;
    let bound = bounds.publisher_latency_us("magnetometer-x", "medium", PERIOD)?;
    // The first release is the command's handling: it must come well inside one period.
    ensure!(
        answered < PERIOD,
        "the publisher started {answered} µs after the command"
    );
    let worst = stream.worst_latency;
    ensure!(
        worst <= bound,
        "release jitter {worst} µs exceeds the analysed bound {bound} µs"
    );
    Ok(format!(
        "{} (as the host decides); then {} frames 0x605 every 6 000 µs (first release {answered} µs after the command), worst latency {worst} µs ≤ analysed {bound} µs",
        refusals.join("; "),
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
    // A one-shot is decided by the admission check first (1.1 ms here since DiWheelDrive's transmit jobs are rows,
    // 2026-12-06; within 1 ms before), then sampled: within 5 ms, as the admission scenarios' verdicts.
    ensure!(
        (150_000..155_000).contains(&after_stop[0]),
        "one-shot answered at {} µs",
        after_stop[0]
    );
    let accel = out.periodic_stream(0x509, "accelerometer", 5_000, 200_000, 250_000)?;
    ensure!(
        accel.frames.len() == 10,
        "{} accelerometer frames from 200 ms, expected 10",
        accel.frames.len()
    );
    // The one-shot is decided first (an analysis, a few ms): the publisher may send once more
    // before it is stopped; then the one-shot's frame, and silence.
    let after_once: Vec<u64> = out
        .times(0x509)
        .into_iter()
        .filter(|t| *t >= 250_000)
        .collect();
    ensure!(
        (1..=3).contains(&after_once.len()) && after_once.iter().all(|&t| t < 265_000),
        "a one-shot must stop the running publisher: frames after it at {after_once:?} µs"
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

pub(super) fn malformed(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    // The releases a period before the run ends (150 ms), whose frames are on the bus before it does.
    malformed_with(out, bounds, 3_000, 147_000)
}

/// The malformed check with the gyroscope publisher every `period` µs until `end` µs (its stop, or a period before
/// the run's end): 3 ms on 1-1 (the shared log), 11 ms on 1-2 (`rev-1-2/malformed.log`).
pub(super) fn malformed_with(
    out: &RunOutput,
    _bounds: &Bounds,
    period: u64,
    end: u64,
) -> Result<String> {
    // The 10 malformed frames each rejected with its own reason, in the order of the stimulus.
    let rejected = out.expect_rejections(
        &[
            &super::MALFORMED_PUBLISH_REJECTIONS[..],
            &[
                "dlc-too-long",
                "dlc-too-short",
                "dlc-too-short",
                "period-too-long",
            ],
        ]
        .concat(),
    )?;
    let ignored = out.traces("command-ignored").len();
    ensure!(
        ignored == 1,
        "the LightRing command must be ignored, got {ignored}"
    );
    ensure!(
        out.frames.iter().all(|f| f.id == 0x608 || f.id == 0x61A),
        "a bad frame made the board send something other than the gyroscope's frames (and the diagnostics asked for)"
    );
    let gyro = out.periodic_stream(0x608, "gyroscope", period, 0, end)?;
    let health = check_health(out, amiro_can::Board::DiWheelDrive)?;
    ensure!(
        health.rejected == 10,
        "diagnostics count {} rejections, expected 10",
        health.rejected
    );
    Ok(format!(
        "{rejected} rejected, {ignored} ignored; gyroscope undisturbed: {} frames on its {} ms grid, worst latency {} µs; diagnostics: {} accepted, {} rejected",
        gyro.frames.len(),
        period / 1000,
        gyro.worst_latency,
        health.accepted,
        health.rejected
    ))
}

fn flood(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    flood_at(out, bounds, 3_000, super::FLOOD_COMMANDS)
}

/// The flood check with the gyroscope publisher every `period` µs (3 ms on 1-1, 11 ms on 1-2) and `sent` commands
/// in the log (1-2's stops the gyroscope before the health one-shot, one more).
pub(super) fn flood_at(out: &RunOutput, bounds: &Bounds, period: u64, sent: u64) -> Result<String> {
    let gyro = out.periodic_stream(0x608, "gyroscope", period, 0, 250_000)?;
    // Held to its grid by `periodic_stream`, and to the QEMU model's bound where it has one.
    let latency = super::within_flood_bound(
        gyro.worst_latency,
        bounds.publisher_latency_bound_us("gyroscope", "medium", period)?,
    )?;
    // The command handler takes at most one command per COMMAND_MIN_INTERVAL_US (the admission
    // task one per ADMISSION_MIN_INTERVAL_US, which is longer): the flood's excess waits in the
    // bounded receive queue and is dropped there, counted. Every frame is accounted for.
    let (handled, dropped) =
        super::flood_commands_sent(out, sent, ADMISSION_WAITING, COMMAND_MIN_INTERVAL_US)?;
    let health = check_health(out, amiro_can::Board::DiWheelDrive)?;
    Ok(format!(
        "{handled} commands handled at most one per {COMMAND_MIN_INTERVAL_US} µs, {dropped} dropped and counted (diagnostics agree: {} dropped); gyroscope on its {} ms grid, {latency}",
        health.rx_dropped,
        period / 1000
    ))
}

fn shutdown(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    const REQUEST: u64 = 100_000;
    let gyro = out.periodic_stream(0x208 | 0x400, "gyroscope", 2_000, 0, REQUEST)?;
    ensure!(
        gyro.frames.len() == 48,
        "{} gyroscope frames before the request, expected 48",
        gyro.frames.len()
    );
    let stop = out
        .traces("motors-stopped shutdown")
        .first()
        .map(|l| trace_time(l))
        .transpose()?
        .context("no motors-stopped shutdown trace")?;
    // Within 300 µs of the request: the shipped images stop the motors within 100 µs; the scripted-i2c trial's 1-1
    // image, whose gyroscope releases at 99 990 µs on the grid its admission left it (2026-12-06), traces the stop at
    // 100 170 µs, after that release's sample and frame (why the shutdown's interrupt at priority 7 comes after the
    // job, in QEMU, is not investigated: docs/qemu.md).
    ensure!(
        (REQUEST..REQUEST + 300).contains(&stop),
        "motors stopped at {stop} µs"
    );
    ensure!(
        out.notes
            .iter()
            .any(|n| n.contains("SYS_SYNC_N pulled low")),
        "SYS_SYNC_N was not pulled low"
    );
    let handover = super::stopped_and_handed_over(out, 0x608, REQUEST + 100, REQUEST)?;
    Ok(format!("48 frames, then motors off at {stop} µs, SYS_SYNC_N low, no frames or commands after; {handover}"))
}

fn hostile(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    // The stimulus: 7579 frames (diwheeldrive/qemu/hostile.log).
    const SENT: u64 = 7_579;
    let end = out.end_line()?;
    ensure!(
        end.starts_with("qemu: end of run"),
        "the run did not reach its end: `{end}`"
    );
    // A request the admission check refuses never reaches the handler (no command trace): it is
    // accounted for by its verdict (page 0x80 on 0x?1A).
    let handled = out.traces("command-").len() as u64;
    // Busy refusals (the admission queue full) are counted, their verdicts sent at most one per
    // 40 ms: the end line has the count.
    let busy = out.end_field("admission busy")?;
    let busy_verdicts = verdicts(out)
        .iter()
        .filter(|(_, v)| v.violation == amiro_can::Violation::Unknown && v.wcrt_us.get() == 0)
        .count() as u64;
    let refused = verdicts(out).len() as u64 - busy_verdicts + busy;
    let dropped = out.end_field("rx dropped")?;
    let overruns = out.end_field("rx overruns")?;
    // Sensor commands wait for the admission task (one per ADMISSION_MIN_INTERVAL_US) in a queue of
    // ADMISSION_QUEUE_LEN; when the run ends, up to that many (and the one being decided) are
    // still there, neither handled nor dropped.
    let waiting = SENT.saturating_sub(handled + refused + dropped);
    ensure!(
        handled + refused + dropped <= SENT && waiting <= ADMISSION_WAITING && overruns == 0,
        "{handled} handled + {refused} refused + {dropped} dropped ({overruns} overruns) != {SENT} sent (up to {ADMISSION_WAITING} may wait for the admission task)"
    );
    Ok(format!(
        "ran to its end: {handled} commands handled, {refused} refused by admission, {dropped} dropped and counted, {} frames sent",
        out.frames.len()
    ))
}

/// `diwheeldrive/qemu/admission-units.log` (issue 11): the shortest period of the ms and s units.
fn admission_units(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    use amiro_can::Verdict;
    let path = bounds.root().join("diwheeldrive/qemu/admission-units.log");
    let text = std::fs::read_to_string(&path)?;
    let mut host = super::HostAdmission::new(bounds.root())?;
    let mut expected = Vec::new();
    let mut requests = 0;
    for line in text.lines() {
        let Some(frame) = crate::qemu::parse_log_line(line)? else {
            continue;
        };
        let data: String = frame.data.iter().map(|b| format!("{b:02X}")).collect();
        let decision = host.request(&format!("{:03X}#{data}", frame.id))?;
        requests += 1;
        if decision.refusal.is_some() {
            expected.push((frame.id, frame.at_us, decision));
        }
    }
    let verdicts = verdicts(out);
    ensure!(
        verdicts.len() == expected.len(),
        "{} verdicts, the host refuses {} of the {requests} requests",
        verdicts.len(),
        expected.len()
    );
    for ((at, v), (id, sent, decision)) in verdicts.iter().zip(&expected) {
        ensure!(
            v.verdict == Verdict::Refused
                && u32::from(v.topic.byte()) == id & 0xFF
                && v.priority as u32 == (id >> 8) & 3
                && *at > *sent,
            "verdict {v} does not answer the request {id:03X} the host refuses"
        );
        super::same_refusal(v, decision)?;
    }
    // Odometry at low every 10 ms keeps its grid until it is itself requested (last in the ms round).
    let odometry_request = text
        .lines()
        .filter_map(|l| crate::qemu::parse_log_line(l).ok().flatten())
        .filter(|f| f.id == 0x001)
        .map(|f| f.at_us)
        .next()
        .context("no odometry request in the stimulus")?;
    let odometry = out.periodic_stream(0x701, "odometry", 10_000, 6_000, odometry_request)?;
    // After the last round the low level still sends (where the watchdog is fed).
    let end = out.frames.last().map_or(0, |f| f.at_us);
    let low_after = out
        .frames
        .iter()
        .filter(|f| f.id & 0x700 == 0x700 && f.at_us + 400_000 > end)
        .count();
    ensure!(
        low_after > 0,
        "no low-priority frame in the last 400 ms: the low level starved"
    );
    Ok(format!(
        "{requests} requests, {} refused exactly as the host decides (culprits and bounds equal), the rest accepted; odometry {} frames on its 10 ms grid; low level alive",
        expected.len(),
        odometry.frames.len()
    ))
}

fn admission_warn(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    use amiro_can::{Topic, Verdict};
    let verdicts = verdicts(out);
    ensure!(
        verdicts.len() == 2,
        "{} verdicts, expected the two refusals below the hard floor",
        verdicts.len()
    );
    for ((at, v), (topic, micros)) in verdicts
        .iter()
        .zip([(Topic::MagnetometerX, 400), (Topic::Accelerometer, 1)])
    {
        ensure!(
            v.verdict == Verdict::Refused && v.topic == topic && v.requested.as_micros() == micros,
            "not the refusal of {topic:?} every {micros} µs under accept-and-warn: {v}"
        );
        // Below the floor: a task without a bound, or a fixed task late.
        ensure!(
            v.wcrt_us.get() > v.deadline_us.get(),
            "a refusal whose bound holds: {v}"
        );
        ensure!(
            *at < 110_000 + 5_000 || topic == Topic::MagnetometerX,
            "the attack's verdict came {at} µs after the start, more than 5 ms after its frame"
        );
    }
    ensure!(
        out.times(0x605).is_empty() && out.times(0x409).is_empty(),
        "a refused request was started anyway"
    );
    let gyro = out.periodic_stream(0x608, "gyroscope", 2_000, 5_000, 199_000)?;
    Ok(format!(
        "refused under accept-and-warn: {} and {}; gyroscope kept its grid ({} frames, worst latency {} µs)",
        verdicts[0].1,
        verdicts[1].1,
        gyro.frames.len(),
        gyro.worst_latency,
    ))
}

fn admission_other_board(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    use amiro_can::{CanId, Topic, Verdict, Violation};
    let verdicts = verdicts(out);
    ensure!(
        verdicts.len() == 1,
        "{} verdicts, expected the one refusal of the velocity request",
        verdicts.len()
    );
    let (_, v) = &verdicts[0];
    ensure!(
        v.verdict == Verdict::Refused && v.topic == Topic::Velocity,
        "not the refusal of velocity: {v}"
    );
    let ring = CanId::try_from(0x71Fu16).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    ensure!(
        v.violation == Violation::Message { id: ring },
        "the refusal names {:?}, not PowerManagement's ring frames 0x71F: {v}",
        v.violation
    );
    ensure!(
        v.wcrt_us.get() > v.deadline_us.get(),
        "a refusal whose bound holds: {v}"
    );
    // The odometry runs from its request (47 ms) to its stop (140 ms), every 2 ms.
    let odometry = out.times(0x401);
    ensure!(
        odometry.len() >= 40,
        "{} odometry frames: the accepted request is not running",
        odometry.len()
    );
    ensure!(
        out.times(0x402).is_empty(),
        "velocity frames sent: the refused request started"
    );
    let counted = super::check_refusal_counts(out, amiro_can::Board::DiWheelDrive)?;
    Ok(format!(
        "{v}; odometry runs ({} frames), no velocity frame; {counted}",
        odometry.len()
    ))
}

/// Virtual nanoseconds per instruction in the QEMU runs (`-icount shift=N`: 2^N ns).
const NS_PER_INSTRUCTION: u64 = 1 << crate::qemu::ICOUNT_SHIFT;

/// The instructions QEMU ran in `virtual_us` µs of a task's own execution.
pub(crate) fn qemu_instructions(virtual_us: f64) -> u64 {
    (virtual_us * 1000.0) as u64 / NS_PER_INSTRUCTION
}

/// A QEMU latency at the F103's speed (the clock and cycles per instruction DiWheelDrive's timing file states for its
/// admission budget, `worst_step`), every microsecond of it scaled as if it were instructions: frames on the bus and
/// the sensors' transfers, which do not scale, are over-estimated and the transfers QEMU's simulated sensors do not
/// take are missing, so an estimate of what a robot would show, not a bound (issue 20's 2 ms and 5 ms are the
/// robot's, the scenarios check QEMU's).
fn on_f103_us(virtual_us: u64) -> Result<u64> {
    let (_, step) = admission_budget(ADMISSION_BUDGETS[0])?;
    Ok(step.us_for(virtual_us * 1000 / NS_PER_INSTRUCTION).round() as u64)
}

/// The admission task's budget and recorded worst step in the timing file `path`.
pub(crate) fn admission_budget(
    path: &str,
) -> Result<(f64, schedule_analysis::scenario::WorstStep)> {
    let text = std::fs::read_to_string(crate::workspace::workspace_root().join(path))
        .with_context(|| path.to_string())?;
    let timing: schedule_analysis::scenario::Timing =
        serde_json::from_str(&text).with_context(|| path.to_string())?;
    let task = timing
        .tasks
        .get("admit_requests")
        .with_context(|| format!("{path}: no admit_requests"))?;
    let budget = task
        .wcet_us
        .with_context(|| format!("{path}: admit_requests has no wcet_us"))?;
    let step = task
        .worst_step
        .clone()
        .with_context(|| format!("{path}: admit_requests records no worst_step"))?;
    Ok((budget, step))
}

/// Every timing file that budgets the admission task (each records the costliest step measured and the chip's clock
/// and cycles per instruction: `worst_step`).
pub(crate) const ADMISSION_BUDGETS: [&str; 6] = [
    "schedule-analysis/models/diwheeldrive.timing.json",
    "schedule-analysis/models/rev-1-2/diwheeldrive.timing.json",
    "schedule-analysis/models/lightring.timing.json",
    "schedule-analysis/models/rev-1-2/lightring.timing.json",
    "schedule-analysis/models/powermgmt.timing.json",
    "schedule-analysis/models/rev-1-2/powermgmt.timing.json",
];

/// The admission task's analysed steps of a run, `(iterations, virtual µs, line)`: its decisions (`admission id=<id>
/// <what> iterations=<n> virtual_us=<t>`) and its refresh steps (`admission refresh iterations=<n> virtual_us=<t>`).
/// The µs run from the step's start to its end, so they include whatever pre-empted it.
fn admission_steps(out: &RunOutput, prefix: &str) -> Result<Vec<(u64, u64, String)>> {
    let mut steps = Vec::new();
    for note in out.notes.iter().filter(|n| n.starts_with(prefix)) {
        let field = |name: &str| -> Result<u64> {
            note.split_whitespace()
                .find_map(|w| w.strip_prefix(name))
                .with_context(|| format!("no {name} in `{note}`"))?
                .parse()
                .with_context(|| format!("{name} in `{note}`"))
        };
        steps.push((field("iterations=")?, field("virtual_us=")?, note.clone()));
    }
    Ok(steps)
}

/// The admission task's costliest activation of the run against its budget per step (its WCET: one activation is
/// one decision, preparation or refresh step, or a cheap note) in every timing file that has one: the activation's
/// own execution (the task trace's runs, pre-emptions taken out, as the bench measures it — the analysis adds the
/// pre-emptions itself), as instructions of QEMU's virtual time, at the file's clock and cycles per instruction, may
/// not exceed the budget, nor the costliest step the file records (`worst_step`, which `cargo xtask analyze` prints)
/// by more than 2 % (a stale record); the record may not exceed the budget either. Returns a sentence with the
/// figures.
fn against_budget(out: &RunOutput, steps: &[(u64, u64, String)]) -> Result<String> {
    let (own_us, runs) = out.own_execution_us("diwheeldrive", "admit_requests")?;
    ensure!(runs > 0, "the task trace shows no run of admit_requests");
    let longest = steps.iter().map(|d| d.1).max().context("no decision")?;
    let instructions = qemu_instructions(own_us);
    let mut figures = Vec::new();
    for path in ADMISSION_BUDGETS {
        let (budget, step) = admission_budget(path)?;
        let this_run_us = step.us_for(instructions);
        ensure!(
            this_run_us <= budget,
            "the admission task's costliest activation ({own_us:.1} µs virtual of its own execution, {instructions} instructions, ≈ {this_run_us:.0} µs at {} MHz and {} cycles per instruction) exceeds the budget of {budget} µs per step in {path}",
            step.clock_mhz,
            step.cycles_per_instruction
        );
        // Code elsewhere in the image moves the count a little; more than 2 % means the record is stale.
        ensure!(
            instructions * 100 <= step.instructions * 102,
            "the admission task's costliest activation ({instructions} instructions) costs more than 2 % above the worst step {path} records ({} instructions): update the record (and the budget's note)",
            step.instructions
        );
        let on_chip_us = step.on_chip_us();
        ensure!(
            on_chip_us <= budget,
            "{path}: the recorded worst step ({} instructions, ≈ {on_chip_us:.0} µs at {} MHz and {} cycles per instruction) exceeds the budget of {budget} µs per step",
            step.instructions,
            step.clock_mhz,
            step.cycles_per_instruction
        );
        figures.push(format!(
            "{} MHz: this run ≈ {this_run_us:.0} µs, recorded worst {on_chip_us:.0} µs of {budget:.0}",
            step.clock_mhz,
        ));
    }
    figures.dedup();
    Ok(format!(
        "costliest activation of {runs}: {own_us:.1} µs virtual of own execution = {instructions} instructions ({}; the longest step from start to end, pre-emptions included, {longest} µs)",
        figures.join(", ")
    ))
}

fn admission_cost(out: &RunOutput, bounds: &Bounds) -> Result<String> {
    let mut steps = admission_steps(out, "admission id=")?;
    // 13 starts and 7 requests on the full bus, the last after two other boards' stops.
    ensure!(
        steps.len() == 20,
        "{} decisions logged, expected 13 starts and 7 requests",
        steps.len()
    );
    // A stop that removes a running stream leaves its board's kept analysis stale: the admission task refreshes
    // it as a step of its own (so no decision re-analyses more than its own board and the bus); its cost counts
    // like a decision's. A stop of a topic the robot does not run (its request was refused) leaves nothing stale
    // and is followed by no refresh. Which of the three stops remove a stream depends on the budgets in the
    // timing files (LightRing's diagnostics at low every 100 ms are refused with `admit_requests` at 16.5 ms,
    // docs/analysis.md, *A decision's cost is bounded*), so the steps expected are the host's replay of the same
    // check on the same table: the same steps in the same order, with the same fixed-point iterations.
    let host = host_admission_steps(bounds.root(), out)?;
    let refreshes = admission_steps(out, "admission refresh ")?;
    let chip: Vec<(bool, u64)> = out
        .notes
        .iter()
        .filter_map(|n| {
            let decision = n.starts_with("admission id=");
            (decision || n.starts_with("admission refresh "))
                .then(|| {
                    n.split_whitespace()
                        .find_map(|w| w.strip_prefix("iterations="))
                        .and_then(|v| v.parse().ok())
                        .map(|i| (decision, i))
                })
                .flatten()
        })
        .collect();
    same_steps(&chip, &host.steps)?;
    ensure!(
        host.stale_stops > 0 && refreshes.len() >= host.stale_stops,
        "{} refresh steps logged for {} stops that left a kept analysis stale: the scenario no longer exercises a refresh",
        refreshes.len(),
        host.stale_stops
    );
    steps.extend(refreshes);
    let verdicts = verdicts(out);
    ensure!(
        verdicts
            .iter()
            .any(|(_, v)| v.topic == amiro_can::Topic::Accelerometer),
        "the 1 µs accelerometer request on the full bus was not refused"
    );
    let most_iterations = steps.iter().map(|d| d.0).max().unwrap_or(0);
    let budget = against_budget(out, &steps)?;
    Ok(format!(
        "{} steps as the host's replay takes them (20 decisions, {} refreshes; {} of the {} stops removed a running stream, a stop of a topic whose request was refused leaves nothing to refresh), up to {} publishers running; {budget}; most fixed-point iterations {most_iterations}",
        steps.len(),
        steps.len() - 20,
        host.stale_stops,
        host.stops,
        host.most_running,
    ))
}

/// Whether the admission task took the steps the host's replay takes (`chip`, `host`: each step's kind, `true` a
/// decision, else a preparation or refresh step, and its fixed-point iterations, in order); an error naming the
/// first difference, or the steps the run ended before.
fn same_steps(chip: &[(bool, u64)], host: &[(bool, u64)]) -> Result<()> {
    let kind = |d: bool| if d { "decision" } else { "refresh" };
    let show = |s: &[(bool, u64)]| {
        s.iter()
            .map(|(d, i)| format!("{} {i}", kind(*d)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(at) = chip.iter().zip(host).position(|(c, h)| c != h) {
        anyhow::bail!(
            "the admission task's step {} is a {} of {} iterations, the host's replay of the same check takes a {} of {} there (chip: {}; host: {})",
            at + 1,
            kind(chip[at].0),
            chip[at].1,
            kind(host[at].0),
            host[at].1,
            show(chip),
            show(host)
        );
    }
    ensure!(
        chip.len() == host.len(),
        "{} admission steps logged, the host's replay takes {} (chip: {}; host: {}){}",
        chip.len(),
        host.len(),
        show(chip),
        show(host),
        if chip.len() < host.len() {
            ": the run ended before the last steps (paced past its end?)"
        } else {
            ""
        }
    );
    Ok(())
}

/// What the host's replay of DiWheelDrive's admission check takes for a run's stimulus ([`host_admission_steps`]).
struct HostSteps {
    /// Each analysed step in order: whether it is a decision (else a preparation or refresh step), and its
    /// fixed-point iterations.
    steps: Vec<(bool, u64)>,
    /// The stops heard, and those that removed a running stream (leaving a kept analysis stale).
    stops: usize,
    stale_stops: usize,
    /// The most publishers of the robot running at once.
    most_running: usize,
}

/// The admission task's steps for `out`'s stimulus (scenario `admission-cost` on DiWheelDrive 1-1) as the host
/// takes them with the same check on the 1-1 robot's table (`amiro_firmware::admission::Admission::replay`, in the
/// order `amiro_firmware::tasks::serve_admission` runs them: for each command heard, the steps preparing it, the
/// decision, the refresh steps when a stream left the running set). Requires that the board lost no command (its
/// queues dropped none), so it heard what the host replays.
fn host_admission_steps(root: &std::path::Path, out: &RunOutput) -> Result<HostSteps> {
    use amiro_firmware::admission::{Admission, State, StepKind};
    ensure!(
        out.end_field("rx dropped")? == 0 && out.end_field("admission busy")? == 0,
        "the board dropped or refused unseen a command: the host's replay would not be what it heard"
    );
    let stimulus = super::log_path(root, "diwheeldrive", "1-1", "admission-cost");
    let frames = crate::qemu::read_stimulus(&stimulus)?;
    let robot = schedule_analysis::admission_host::lower_robot_for(root, Some("1-1"))
        .map_err(|e| anyhow::anyhow!("the 1-1 robot's admission table: {e}"))?;
    ensure!(
        robot.max_tasks() <= 64 && robot.max_publishers() <= 32,
        "the 1-1 robot's table is larger than the host's replay keeps"
    );
    Ok(robot.with_table(|table| {
        let mut state = Box::new(State::<64, 32>::new());
        let mut admission = Admission::new(table, amiro_can::Board::DiWheelDrive, &mut state);
        admission.prepare();
        let mut host = HostSteps {
            steps: Vec::new(),
            stops: 0,
            stale_stops: 0,
            most_running: 0,
        };
        for frame in &frames {
            let Ok(id) = u16::try_from(frame.id) else {
                continue;
            };
            let data = frame.data.as_slice();
            let running = admission.running().len();
            let _ = admission.replay(id, data, |kind, iterations| {
                host.steps.push((kind == StepKind::Decision, iterations));
            });
            if matches!(
                amiro_can::decode_command(id, data),
                Ok(amiro_can::Command::Sensor(c)) if c.mode == amiro_can::SensorMode::Stop
            ) {
                host.stops += 1;
                if admission.running().len() < running {
                    host.stale_stops += 1;
                }
            }
            host.most_running = host.most_running.max(admission.running().len());
        }
        host
    }))
}

pub(super) fn admission_search(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    let mut steps = admission_steps(out, "admission id=")?;
    steps.extend(admission_steps(out, "admission refresh ")?);
    // A step analyses at most one board and the bus, each within the check's iteration budget
    // (schedule_analysis::admission::DECISION_ITERATIONS): no step may take more than both. The sequence was
    // chosen for the most iterations in one step: it must come within 10 % of that, or it no longer exercises
    // the worst case and must be searched again.
    let most_iterations = steps.iter().map(|d| d.0).max().unwrap_or(0);
    let cap = schedule_analysis::admission::DECISION_ITERATIONS;
    ensure!(
        most_iterations <= 2 * cap,
        "a step took {most_iterations} fixed-point iterations, more than one board's and the bus's {cap} each: a step analysed more than one board"
    );
    ensure!(
        most_iterations * 10 >= 2 * cap * 9,
        "the searched sequence's costliest step took {most_iterations} fixed-point iterations, below 90 % of a step's {}: search again (`cargo xtask admission-search --write`, docs/qemu.md)",
        2 * cap
    );
    let budget = against_budget(out, &steps)?;
    Ok(format!(
        "{} steps; {budget}; most fixed-point iterations {most_iterations} (a board's analysis and the bus's may take {cap} each)",
        steps.len(),
    ))
}

/// Commands that may still wait for DiWheelDrive's admission task when a run ends: its queue
/// (`ADMISSION_QUEUE_LEN` in diwheeldrive/src/main.rs) and the one being decided.
const ADMISSION_WAITING: u64 = 8 + 1;

/// The admission verdicts DiWheelDrive sent.
fn verdicts(out: &RunOutput) -> Vec<(u64, amiro_can::AdmissionVerdict)> {
    super::admission_verdicts(out, amiro_can::Board::DiWheelDrive)
}

/// `diwheeldrive/qemu/admission-starvation.log` (issue 11).
fn admission_starvation(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    use amiro_can::{Topic, Verdict, Violation};
    let verdicts = verdicts(out);
    // The 1 µs accelerometer request at urgent, then 9 topics × 4 priorities at 1 µs: 37 refusals.
    ensure!(
        verdicts.len() == 37,
        "{} verdicts, expected 37 refusals",
        verdicts.len()
    );
    for (_, v) in &verdicts {
        ensure!(v.verdict == Verdict::Refused, "not a refusal: {v}");
        ensure!(
            !matches!(v.violation, Violation::Unknown),
            "a refusal without its reason: {v}"
        );
        ensure!(
            v.wcrt_us.get() > v.deadline_us.get(),
            "a refusal whose bound holds: {v}"
        );
    }
    let first = &verdicts[0].1;
    ensure!(
        first.topic == Topic::Accelerometer && first.requested.as_micros() == 1,
        "the first verdict answers {first}, not the 1 µs accelerometer request"
    );
    ensure!(
        out.frames.iter().all(|f| f.id & 0x4FF != 0x409),
        "an accelerometer frame was sent: the refused request started a publisher"
    );
    // The running publishers keep their grids across every refusal; the low level keeps running.
    let gyro = out.periodic_stream(0x608, "gyroscope", 4_000, 5_000, 1_790_000)?;
    let odometry = out.periodic_stream(0x701, "odometry", 10_000, 6_000, 1_790_000)?;
    // The watchdog is fed from the lowest level: the low publisher kept its grid to the end (it
    // starts at about 45 ms: its request waits one admission interval behind the gyroscope's).
    ensure!(
        odometry.frames.len() >= 170,
        "{} odometry frames: the lowest level starved",
        odometry.frames.len()
    );
    // The 3 ms velocity request at medium (t = 1.7 s) is accepted (every 2 ms beside a gyroscope every 2 ms until
    // DiWheelDrive's transmit jobs were rows; the magnetometer every 2 ms until its polled HMC5883L made its job 3.1
    // ms, 2026-12-06).
    let mag = out.times(0x602);
    ensure!(
        mag.len() >= 20 && mag.iter().all(|&t| t >= 1_700_000),
        "the 3 ms velocity request was not served ({} frames)",
        mag.len()
    );
    // The diagnostics (every 20 ms from t = 1.742 s) count them by reason.
    let counted = super::check_refusal_counts(out, amiro_can::Board::DiWheelDrive)?;
    Ok(format!(
        "{} refusals, each with its reason (first: {first}), {counted}; gyroscope {} frames on its 4 ms grid, odometry {} on its 10 ms grid (low level alive); 3 ms velocity accepted ({} frames)",
        verdicts.len(),
        gyro.frames.len(),
        odometry.frames.len(),
        mag.len(),
    ))
}

/// `diwheeldrive/qemu/admission-latency.log` (issue 20): each request of a burst takes effect within 5 ms of its
/// frame, and a stop within the command handler's deadline.
fn admission_latency(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    const EFFECT_US: u64 = 5_000;
    let requests = [
        (0x708, "gyroscope", 10_000),
        (0x709, "accelerometer", 15_000),
        (0x705, "magnetometer-x", 20_000),
        (0x702, "velocity", 25_000),
        (0x701, "odometry", 30_000),
    ];
    let mut firsts = Vec::new();
    for (id, topic, sent) in requests {
        let first = out
            .times(id)
            .into_iter()
            .next()
            .with_context(|| format!("{topic}: no sample on the bus"))?;
        ensure!(
            first >= sent && first - sent <= EFFECT_US,
            "{topic}: first sample {} µs after its request, more than {EFFECT_US} µs",
            first.saturating_sub(sent)
        );
        firsts.push(format!(
            "{topic} {} µs (≈ {} µs at the F103's speed)",
            first - sent,
            on_f103_us(first - sent)?
        ));
    }
    ensure!(
        verdicts(out).is_empty(),
        "a verdict: one of the five requests was refused"
    );
    // The stop at 100.3 ms: handled by the command handler within its deadline (the interval), so
    // no magnetometer-x sample is released later (one already queued may still leave).
    const STOP: u64 = 100_300;
    let late: Vec<u64> = out
        .times(0x705)
        .into_iter()
        .filter(|&t| t > STOP + COMMAND_MIN_INTERVAL_US + 1_000)
        .collect();
    ensure!(
        late.is_empty(),
        "magnetometer-x samples after the stop took effect: {late:?}"
    );
    let before = out.times(0x705).into_iter().filter(|&t| t < STOP).count();
    ensure!(
        before >= 7,
        "{before} magnetometer-x samples before the stop, expected it running every 10 ms"
    );
    let others = out
        .times(0x702)
        .into_iter()
        .filter(|&t| t > 150_000)
        .count();
    ensure!(
        others >= 4,
        "the velocity stopped with magnetometer-x ({others} samples after 150 ms)"
    );
    Ok(format!(
        "first samples after their requests: {}; magnetometer-x stopped within the handler's deadline ({before} samples before), the velocity still running",
        firsts.join(", ")
    ))
}

/// `diwheeldrive/qemu/admission-one-shots.log` (issue 20): one-shots refused beside the magnetometer every 3 650 µs
/// (near its boundary on DiWheelDrive 1-1; the thesis's 900 µs is refused alone) and admitted once the magnetometer
/// runs every 6 ms (the log's header has the analysis' figures).
fn admission_one_shots(out: &RunOutput, _bounds: &Bounds) -> Result<String> {
    use amiro_can::{Topic, Verdict};
    // The requests beside the 3 650 µs magnetometer, each refused: (frame time, topic, a one-shot).
    const REFUSED: [(u64, Topic, bool); 3] = [
        (50_000, Topic::Gyroscope, true),
        (100_000, Topic::FloorProximity, true),
        (150_000, Topic::Accelerometer, false),
    ];
    const MAG_FIRST: u64 = 3_650;
    const MAG_MOVED: u64 = 200_000;
    const MAG_THEN: u64 = 6_000;
    const GYRO_ONCE: u64 = 240_000;
    const ACCEL_START: u64 = 280_000;
    let verdicts = verdicts(out);
    ensure!(
        verdicts.len() == REFUSED.len(),
        "{} verdicts, expected the {} refusals beside the 3 650 µs magnetometer",
        verdicts.len(),
        REFUSED.len()
    );
    let mut refusals = Vec::new();
    for ((at, v), (frame, topic, one_shot)) in verdicts.iter().zip(REFUSED) {
        ensure!(
            v.verdict == Verdict::Refused && v.one_shot == one_shot && v.topic == topic,
            "not the refusal of {topic:?} (one-shot {one_shot}): {v}"
        );
        ensure!(
            *at >= frame && at - frame <= 5_000,
            "the refusal of {topic:?} came {} µs after its frame",
            at.saturating_sub(frame)
        );
        refusals.push(format!("{v} ({} µs after its frame)", at - frame));
    }
    ensure!(
        out.times(0x604).is_empty(),
        "a floor-sensor sample: the refused one-shot was carried out"
    );
    let gyro = out.times(0x708);
    ensure!(
        gyro.len() == 1 && gyro[0] >= GYRO_ONCE && gyro[0] - GYRO_ONCE <= 2_000,
        "the gyroscope: samples at {gyro:?}, expected one (the second request's) within 2 ms of {GYRO_ONCE} µs"
    );
    let accel = out.times(0x709);
    ensure!(
        accel.first().is_some_and(|&t| t >= ACCEL_START && t - ACCEL_START <= 10_000),
        "the accelerometer every 10 ms at low: first sample at {:?}, expected within 10 ms of {ACCEL_START} µs (none before)",
        accel.first()
    );
    ensure!(
        accel.len() >= 6,
        "the accelerometer every 10 ms at low: {} samples in 80 ms",
        accel.len()
    );
    let mag = out.periodic_stream(
        0x605,
        "magnetometer-x",
        MAG_FIRST,
        10_000,
        MAG_MOVED - 1_000,
    )?;
    let mag_then = out.periodic_stream(
        0x605,
        "magnetometer-x",
        MAG_THEN,
        MAG_MOVED + 5_000,
        359_000,
    )?;
    Ok(format!(
        "beside magnetometer-x every 3 650 µs: {}; magnetometer-x kept its 3 650 µs grid ({} samples, worst latency {} µs); \
         moved to every 6 ms ({} samples, worst latency {} µs): the gyroscope one-shot on the bus {} µs after its frame \
         (≈ {} µs at the F103's speed, every µs scaled: an estimate, not a bound), the accelerometer every 10 ms at low \
         admitted, first sample {} µs after its frame ({} samples)",
        refusals.join("; "),
        mag.frames.len(),
        mag.worst_latency,
        mag_then.frames.len(),
        mag_then.worst_latency,
        gyro[0] - GYRO_ONCE,
        on_f103_us(gyro[0] - GYRO_ONCE)?,
        accel[0] - ACCEL_START,
        accel.len()
    ))
}

#[cfg(test)]
mod tests {
    use super::same_steps;

    #[test]
    fn a_refresh_the_host_takes_and_the_chip_does_not_fails_the_check() {
        // A stop's refresh (the `false` step) between two decisions.
        let host = [(true, 653), (false, 103), (false, 138), (true, 423)];
        assert!(same_steps(&host, &host).is_ok());
        let dropped = [(true, 653), (false, 138), (true, 423)];
        let e = same_steps(&dropped, &host).unwrap_err().to_string();
        assert!(e.contains("step 2 is a refresh of 138"), "{e}");
        // Its work done inside the next decision instead.
        let merged = [(true, 653), (false, 103), (true, 561)];
        assert!(same_steps(&merged, &host).is_err());
        let ended = [(true, 653), (false, 103), (false, 138)];
        let e = same_steps(&ended, &host).unwrap_err().to_string();
        assert!(e.contains("the run ended before"), "{e}");
        // A stop of a topic the robot does not run: no refresh on either side.
        let no_refresh = [(true, 653), (false, 138), (true, 423)];
        assert!(same_steps(&no_refresh, &no_refresh).is_ok());
    }
}
