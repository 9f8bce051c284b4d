//! `cargo xtask scenarios robot`: the whole robot's CI scenarios (`robot/scenarios/*.log`), each
//! checked on what a user would see on the bus and in the boards' logs.
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};

use crate::qemu::TimedFrame;
use crate::scenarios::RunOutput;
use amiro_robot::{Outcome, Transfer, NODES, OPERATOR};

/// One robot scenario.
pub struct Scenario {
    /// File stem in `robot/scenarios/`.
    pub name: &'static str,
    /// What it shows.
    pub about: &'static str,
    /// The check.
    pub check: fn(&Run) -> Result<String>,
    /// Whether every observed response must be within the analysis's bound (not with injected
    /// faults: error frames are outside the analysis).
    pub bus_bounds: bool,
}

/// The scenarios CI runs.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "thesis-demo",
        about: "the thesis demo on three boards at once",
        check: thesis_demo,
        bus_bounds: true,
    },
    Scenario {
        name: "startup-sync",
        about: "SYS_SYNC_N rises once every module is up",
        check: startup_sync,
        bus_bounds: true,
    },
    Scenario {
        name: "shutdown",
        about: "the shutdown command reaches every board",
        check: shutdown,
        bus_bounds: true,
    },
    Scenario {
        name: "admission-other-board",
        about: "a request refused for another board's frames on the bus",
        check: admission_other_board,
        bus_bounds: true,
    },
    Scenario {
        name: "adapter-flood",
        about: "one node floods, the boards keep their grids",
        check: adapter_flood,
        bus_bounds: true,
    },
    Scenario {
        name: "babbling-board",
        about: "one board's controller babbles, the winning identifiers keep their grids",
        check: babbling_board,
        // The report reads the babbling as what it is on the bus, one burst of back-to-back
        // frames (each queued as the last completes), so even the ring's long wait has a bound.
        bus_bounds: true,
    },
    Scenario {
        name: "mailbox-abort",
        about: "a more urgent frame displaces a waiting one from full mailboxes",
        check: mailbox_abort,
        bus_bounds: true,
    },
    Scenario {
        name: "reset",
        about: "a board reset mid-run rejoins",
        check: reset,
        bus_bounds: true,
    },
    Scenario {
        name: "bus-fault",
        about: "bit errors and an unplugged board survived",
        check: bus_fault,
        bus_bounds: false,
    },
];

/// A finished robot run, as the checks read it.
pub struct Run {
    /// What the run produced.
    pub outcome: Outcome,
}

impl Run {
    /// Frames with identifier `id`, in order.
    pub fn frames(&self, id: u16) -> Vec<&Transfer> {
        self.outcome
            .transfers
            .iter()
            .filter(|t| t.frame.id == id)
            .collect()
    }

    /// Completion times of the frames with identifier `id`.
    pub fn ends(&self, id: u16) -> Vec<u64> {
        self.frames(id).iter().map(|t| t.end).collect()
    }

    /// A board's `#` lines (without `NAME: # `), in order.
    pub fn notes(&self, board: usize) -> Vec<&str> {
        let prefix = format!("{}: #", NODES[board]);
        self.outcome
            .text
            .lines()
            .filter_map(|l| l.strip_prefix(prefix.as_str()))
            .map(str::trim)
            .collect()
    }

    /// The bus's own notes (error frames, line levels, boards leaving) that mention `text`.
    pub fn bus_notes(&self, text: &str) -> Vec<&str> {
        self.outcome
            .text
            .lines()
            .filter_map(|l| l.strip_prefix("bus: #"))
            .map(str::trim)
            .filter(|n| n.contains(text))
            .collect()
    }

    /// One board's view as the single-board checks read it: the frames it sent (at their
    /// completion) and its `#` lines.
    pub fn view(&self, board: usize) -> RunOutput {
        RunOutput {
            frames: self
                .outcome
                .transfers
                .iter()
                .filter(|t| t.node == board)
                .map(|t| TimedFrame {
                    at_us: t.end,
                    id: u32::from(t.frame.id),
                    data: t.frame.payload().to_vec(),
                })
                .collect(),
            notes: self.notes(board).into_iter().map(String::from).collect(),
            work: None,
        }
    }
}

/// Every board reached its end (end of run or hand-over) without receive-FIFO overruns.
fn every_board_ended(run: &Run) -> Result<()> {
    zero_on_every_board(run, "rx overruns", "receive-FIFO overruns")
}

/// No board dropped a received frame: a flood of sensor frames (a babbling controller's) stays out
/// of every board's software, as bxCAN's filter keeps it out on the robot.
fn nothing_dropped(run: &Run) -> Result<()> {
    zero_on_every_board(run, "rx dropped", "received frames dropped")
}

/// Every board's end line has `field` at zero (`what` names it in the failure).
fn zero_on_every_board(run: &Run, field: &str, what: &str) -> Result<()> {
    for (board, name) in NODES.iter().enumerate().take(3) {
        let count = run
            .view(board)
            .end_field(field)
            .with_context(|| name.to_string())?;
        ensure!(count == 0, "{name}: {count} {what}");
    }
    Ok(())
}

/// `times` lie on a grid of `period` from the first, each at most `slack` late.
fn on_grid(what: &str, times: &[u64], period: u64, slack: u64) -> Result<()> {
    let Some(&first) = times.first() else {
        bail!("no {what} frame");
    };
    // The first frame may itself be late: the grid is the earliest it could have started on.
    let origin = times
        .iter()
        .enumerate()
        .map(|(k, &t)| t - (k as u64 * period).min(t))
        .min()
        .unwrap_or(first);
    for (k, &t) in times.iter().enumerate() {
        let due = origin + k as u64 * period;
        ensure!(
            t >= due && t - due <= slack,
            "{what} frame {k} at {t} µs, due on the {period} µs grid at {due} µs (+{slack} µs at most)"
        );
    }
    Ok(())
}

/// The magnetometer-x period every robot scenario that runs it asks DiWheelDrive for, µs: admitted by DiWheelDrive
/// 1-1 with a clear margin (host's check, 2026-12-06: 0x605 in 3 479.9 µs, 2 520.1 µs of margin, alone or beside the
/// ring every 10 ms; every 3.5 ms and the thesis's 900 µs are refused). Its publisher rows are the machine code's
/// since 2026-12-06: the HMC5883L is polled on the CPU, a magnetometer-x job 1 353.4 µs with its reads' transaction
/// caps and one bus clear a release (3 103.9 µs before), and each sample's frame waits behind a transmit job of its
/// own (DiWheelDrive's `can_tx` row used): the shortest period 3 572 µs (2 710 µs before the transmit jobs, 5 216 µs
/// before the caps). Every 1 150 µs before (the shortest in 50 µs steps on the stated budgets), every 900 µs before
/// 2026-12-05.
const MAGNETOMETER_US: u64 = 6_000;

/// DiWheelDrive's magnetometer-x frames (0x605, every [`MAGNETOMETER_US`] in every robot scenario that runs it):
/// at least `at_least` of them, each on the grid within `slack` µs.
fn magnetometer_on_grid(run: &Run, at_least: usize, slack: u64) -> Result<Vec<u64>> {
    let magnetometer = run.ends(0x605);
    ensure!(
        magnetometer.len() >= at_least,
        "{} magnetometer frames, expected at least {at_least} (one per {MAGNETOMETER_US} µs)",
        magnetometer.len()
    );
    on_grid("magnetometer", &magnetometer, MAGNETOMETER_US, slack)?;
    Ok(magnetometer)
}

/// The proximity ring's period in every robot scenario that runs it at medium, µs: thesis-demo's
/// (`schedule-analysis/models/thesis-demo.scenario.json`), [`RING`]. Every 10 ms before 2026-12-06: the
/// ring's release is 34 920.9 µs with its polled I2C waits since its row is used, and PowerManagement 1-1
/// admits the ring alone at medium every 53 060 µs or slower, beside the magnetometer every 6 000 µs every
/// 53 202 µs (host's check, `amiro send … --revision 1-1`, 2026-12-06).
const RING_US: u64 = 62_500;

/// The request for the ring every [`RING_US`] at medium (`21F`, 62 500 µs in µs units).
const RING: &str = "21F#0124F402";

/// The proximity ring's samples: bursts of eight frames `id`, one burst per period (the run's end
/// may cut the last burst short).
fn ring_samples(run: &Run, id: u16, period: u64) -> Result<usize> {
    ring_samples_of(&run.ends(id), id, period)
}

/// [`ring_samples`] of the completions `ends` of the frames `id`.
fn ring_samples_of(ends: &[u64], id: u16, period: u64) -> Result<usize> {
    let mut bursts: Vec<Vec<u64>> = Vec::new();
    for &t in ends {
        match bursts.last_mut() {
            Some(b) if t - b[b.len() - 1] < 2_000 => b.push(t),
            _ => bursts.push(vec![t]),
        }
    }
    if bursts.last().is_some_and(|b| b.len() < 8) {
        bursts.pop();
    }
    ensure!(!bursts.is_empty(), "no whole ring sample {id:03X}");
    for b in &bursts {
        ensure!(
            b.len() == 8,
            "a ring sample of {} frames {id:03X} at {} µs",
            b.len(),
            b[0]
        );
    }
    let firsts: Vec<u64> = bursts.iter().map(|b| b[0]).collect();
    on_grid("ring sample", &firsts, period, 1_000)?;
    Ok(firsts.len())
}

/// The queue times of a board's admission verdicts (its `verdict queued at_us=N` notes), in order.
fn verdicts_queued(run: &Run, board: usize) -> Result<Vec<u64>> {
    run.notes(board)
        .iter()
        .filter_map(|n| n.strip_prefix("verdict queued at_us="))
        .map(|at| {
            at.trim()
                .parse::<u64>()
                .with_context(|| format!("verdict note `{at}`"))
        })
        .collect()
}

fn thesis_demo(run: &Run) -> Result<String> {
    use amiro_can::{Topic, Verdict, Violation};
    every_board_ended(run)?;
    // The thesis's 900 µs and then 3 500 µs, 10 ms apart, both refused by DiWheelDrive 1-1, each verdict with the
    // host's culprit and figures (900 µs overloads the board: a job of its own unbounded; 3 500 µs, near the
    // shortest period of 3 572 µs, names 0x605, its frames at 3 610.1 µs), the second queued at least the verdict
    // spacing after the first; then 6 000 µs admitted.
    let root = crate::workspace::workspace_root();
    let verdicts =
        crate::scenarios::admission_verdicts(&run.view(0), amiro_can::Board::DiWheelDrive);
    ensure!(
        verdicts.len() == 2,
        "{} verdicts from DiWheelDrive, expected the refusals of 900 and 3 500 µs",
        verdicts.len()
    );
    for ((_, v), (request, us)) in verdicts
        .iter()
        .zip([("205#01840302", 900u64), ("205#01AC0D02", 3_500)])
    {
        ensure!(
            v.verdict == Verdict::Refused
                && v.topic == Topic::MagnetometerX
                && v.requested.as_micros() == us
                && (us == 900
                    || matches!(v.violation, Violation::Message { id } if id.raw() == 0x605)),
            "not the refusal of magnetometer-x every {us} µs (for 0x605 at 3 500 µs): {v}"
        );
        crate::scenarios::same_refusal(
            v,
            &crate::scenarios::host_admission(&root, &[RING], request)?,
        )?;
    }
    let queued = verdicts_queued(run, 0)?;
    ensure!(
        queued.len() == 2,
        "{} verdicts queued by DiWheelDrive, expected 2",
        queued.len()
    );
    let spacing = queued[1] - queued[0];
    ensure!(
        queued[1] >= 20_000
            && queued[1] < 20_000 + crate::scenarios::VERDICT_SPACING_US
            && spacing >= crate::scenarios::VERDICT_SPACING_US,
        "the second refusal's verdict queued at {} µs, {spacing} µs after the first: expected it held to the \
         spacing ({} µs) after the first, not to its request at 20 ms",
        queued[1],
        crate::scenarios::VERDICT_SPACING_US
    );
    ensure!(
        crate::scenarios::host_admission(&root, &[RING], "205#01701702")?
            .refusal
            .is_none(),
        "the host refuses magnetometer-x every {MAGNETOMETER_US} µs"
    );
    // Commanded at 60 ms, decided after the second verdict's window, released from DiWheelDrive's acceptance
    // every 6 000 µs until 300 ms, each frame on the bus within 300 µs. The acceptance is held to 5 ms after the
    // later of the command and the window's end, so a slow admission is caught here, not hidden in a smaller
    // count.
    let accepted = run
        .view(0)
        .traces("command-accepted 205")
        .last()
        .map(|line| crate::scenarios::trace_time(line))
        .transpose()?
        .context("DiWheelDrive did not accept the magnetometer request")?;
    let due = 60_000u64.max(queued[1] + crate::scenarios::VERDICT_SPACING_US);
    ensure!(
        (60_000..=due + 5_000).contains(&accepted),
        "DiWheelDrive accepted the magnetometer request at {accepted} µs, not within 5 ms after {due} µs"
    );
    let releases = 300_000u64.saturating_sub(accepted + 300) / MAGNETOMETER_US + 1;
    let magnetometer = magnetometer_on_grid(run, releases as usize, 300)?;
    // From the request at 8 ms, a release every 62.5 ms: five by 300 ms, the last one's frames may be cut.
    let samples = ring_samples(run, 0x61F, RING_US)?;
    ensure!(samples >= 4, "{samples} ring samples in 292 ms");
    // Each sample's eight frames in sensor order, as the robot's driver sends them (one frame of an
    // identifier in the mailboxes at a time; the controller would break ties by mailbox number).
    let order: Vec<u8> = run
        .frames(0x61F)
        .iter()
        .filter_map(|t| t.frame.payload().first().copied())
        .collect();
    ensure!(
        order
            .iter()
            .enumerate()
            .all(|(k, &i)| usize::from(i) == k % 8),
        "ring frames out of sensor order: {order:?}"
    );
    // LED 3 is on OUT 15..17 (channel order n → 3(8−n)); the others dark.
    let (latched, channels, lit) = last_latch(run)?;
    ensure!(channels == 24, "`{latched}`");
    ensure!(
        !lit.is_empty() && lit.iter().all(|k| (15..18).contains(k)),
        "LED 3 only should be lit: `{latched}`"
    );
    let others = run
        .outcome
        .transfers
        .iter()
        .filter(|t| t.node != OPERATOR && ![0x605, 0x61F, 0x61A].contains(&t.frame.id))
        .count();
    ensure!(
        others == 0,
        "{others} frames besides the magnetometer, the ring and DiWheelDrive's verdicts (0x61A)"
    );
    Ok(format!(
        "DiWheelDrive refused 900 µs and 3 500 µs ({} and {} µs), the second verdict {spacing} µs after the first; {} magnetometer frames on the {MAGNETOMETER_US} µs grid from {accepted} µs, {samples} ring samples × 8 (in sensor order) on the 62.5 ms grid, LED 3 latched, all on one bus",
        verdicts[0].1.wcrt_us.get(),
        verdicts[1].1.wcrt_us.get(),
        magnetometer.len()
    ))
}

/// LightRing's last latch (its `tlc5947 latched` note): the note, its number of OUT channels, and the channels
/// it lit.
fn last_latch(run: &Run) -> Result<(String, usize, Vec<usize>)> {
    let latched = run
        .notes(2)
        .into_iter()
        .rfind(|n| n.starts_with("tlc5947 latched"))
        .context("LightRing latched nothing")?
        .to_string();
    let outputs: Vec<&str> = latched.split_whitespace().skip(2).collect();
    let (channels, lit) = (
        outputs.len(),
        (0..outputs.len())
            .filter(|&k| outputs[k] != "000")
            .collect(),
    );
    Ok((latched, channels, lit))
}

fn startup_sync(run: &Run) -> Result<String> {
    every_board_ended(run)?;
    let sync: Vec<&str> = run.bus_notes("SYS_SYNC_N");
    ensure!(
        sync.len() == 1 && sync[0].contains("SYS_SYNC_N high"),
        "expected one rise of SYS_SYNC_N and nothing after: {sync:?}"
    );
    // It rises in the quantum after the last module released it, not before.
    let text = &run.outcome.text;
    let rise = text.find("SYS_SYNC_N high").context("no rise")?;
    for name in NODES.iter().take(3) {
        let released = text
            .find(&format!("{}: # qemu: SYS_SYNC_N released", name))
            .with_context(|| format!("{} never released SYS_SYNC_N", name))?;
        ensure!(
            released < rise,
            "{} released SYS_SYNC_N after the line rose",
            name
        );
    }
    Ok(format!(
        "SYS_SYNC_N rose once ({}) after all three modules released it",
        sync[0]
    ))
}

fn end_time(note: &str) -> Option<u64> {
    let at = note.find(" at ")? + 4;
    note[at..].split_whitespace().next()?.parse().ok()
}

fn shutdown(run: &Run) -> Result<String> {
    let pd = run
        .bus_notes("SYS_PD_N low (driven by powermgmt)")
        .first()
        .context("PowerManagement never drove SYS_PD_N")?
        .to_string();
    // The check below reads the boards' handler events: without them (none printed, or none
    // parsed) it would hold for nothing. The commands before the request were accepted.
    let accepted: usize = (0..3)
        .map(|board| run.view(board).traces("command-accepted").len())
        .sum();
    ensure!(
        accepted > 0,
        "no board's command-accepted event: the run has no handler events to check"
    );
    let mut summary = Vec::new();
    for (board, name) in NODES.iter().enumerate().take(3) {
        let view = run.view(board);
        let end = view.end_line().with_context(|| name)?;
        ensure!(
            end.starts_with("qemu: shutdown hand-over"),
            "{} did not hand over: `{end}`",
            name
        );
        let at = end_time(end).with_context(|| format!("`{end}`"))?;
        let after: Vec<&TimedFrame> = view.frames.iter().filter(|f| f.at_us > at).collect();
        ensure!(
            after.is_empty(),
            "{}: {} frames after its hand-over at {at} µs",
            name,
            after.len()
        );
        ensure!(
            view.traces("command-accepted")
                .iter()
                .all(|n| !n.contains("214")),
            "{} accepted the command after the request",
            name
        );
        summary.push(format!("{} at {at} µs", name));
    }
    let last_board_frame = run
        .outcome
        .transfers
        .iter()
        .filter(|t| t.node != OPERATOR)
        .map(|t| t.end)
        .max()
        .unwrap_or(0);
    ensure!(
        last_board_frame < 120_000,
        "a board's frame at {last_board_frame} µs, long after the shutdown command"
    );
    Ok(format!(
        "{pd}; hand-over: {}; no board's frame after its hand-over",
        summary.join(", ")
    ))
}

fn admission_other_board(run: &Run) -> Result<String> {
    every_board_ended(run)?;
    let odometry = run.ends(0x701);
    // Requested at 5 ms, every 2 ms: about 22 releases before the ring's request at 50 ms (26 at every 1.5 ms
    // until DiWheelDrive's transmit jobs, 2026-12-06, which make 1.5 ms at low refused on its own board).
    let before = odometry.iter().filter(|&&t| t < 50_000).count();
    ensure!(
        before >= 20,
        "{before} odometry frames on the bus before the request (one per 2 ms expected)"
    );
    let v = crate::scenarios::ring_refused_for_odometry(&run.view(1))?;
    ensure!(
        run.ends(0x41F).is_empty(),
        "urgent ring frames on the bus: the refused request ran"
    );
    // The ring at low every 54 ms (robot/scenarios/admission-other-board.log).
    let samples = ring_samples(run, 0x71F, 54_000)?;
    Ok(format!("{v}; {before} odometry frames on the bus before it; the ring at low runs ({samples} samples)"))
}

fn adapter_flood(run: &Run) -> Result<String> {
    every_board_ended(run)?;
    let flood = run.ends(0x3F1).len();
    ensure!(
        flood == 400,
        "{flood} of the adapter's 400 frames on the bus"
    );
    // The slack is the spread between the earliest and the latest completion on the grid: well
    // under 6 000 µs, so a skipped or an extra sample still fails. The latest: the flood command
    // DiWheelDrive is handling when its sample is due (one per 1 ms at most, ≈ 200 µs each with
    // its trace), the sample itself (≈ 240 µs), a frame already on the bus and the next flood frame,
    // which wins against 0x605 (≈ 111 µs each), then 0x605 (≈ 80 µs): ≈ 740 µs after the release;
    // the earliest ≈ 240 µs. Measured: under 400 µs while every board also spent time on a 10 µs
    // tick, on an exchange for every frame on the bus and on spinning in RTIC's priority-0
    // executor; ≈ 500 µs without them (issue 34: tickless, lookahead, the idle core asleep, as on
    // the chip), where DiWheelDrive meets the flood at other phases; 612 µs since the trace ring's
    // images (a layout change only: QEMU's trace path is the same), where one sample of 161 is
    // taken 510 µs after its release (the others at most 240 µs) — a phase of the flood the
    // estimate above does not explain, left open (docs/qemu.md). 700 µs stays under the 6 000 µs a
    // skipped or an extra sample moves a frame. Each frame's response is held to its Davis bound as
    // well (`bus_bounds`).
    // 23 of 150 ms at 6 000 µs (125 at 1 150 µs before 2026-12-06, 160 at 900 µs before 2026-12-05).
    let magnetometer = magnetometer_on_grid(run, 23, 700)?;
    let samples = ring_samples(run, 0x61F, RING_US)?;
    Ok(format!(
        "400 flood frames; {} magnetometer frames on the {MAGNETOMETER_US} µs grid, {samples} ring samples on the 62.5 ms grid",
        magnetometer.len()
    ))
}

fn babbling_board(run: &Run) -> Result<String> {
    const BABBLE: u16 = 0x610;
    const FROM: u64 = 40_000;
    const UNTIL: u64 = 90_000;
    every_board_ended(run)?;
    nothing_dropped(run)?;
    let babble = run.frames(BABBLE);
    ensure!(
        babble
            .iter()
            .all(|t| t.node == 2 && t.mailbox == amiro_bus_sim::BABBLE_MAILBOX),
        "{BABBLE:03X} from another node than LightRing's babbling controller"
    );
    let (Some(first), Some(last)) = (babble.first(), babble.last()) else {
        bail!("LightRing's controller sent no {BABBLE:03X}");
    };
    ensure!(
        first.start >= FROM && last.start < UNTIL,
        "babbling from {} to {} µs, outside {FROM}..{UNTIL}",
        first.start,
        last.start
    );
    // Back to back: the bus is never idle between two babbling frames but for a frame that won
    // against them (the magnetometer), each followed by its intermission.
    let on_bus: u64 = run
        .outcome
        .transfers
        .iter()
        .filter(|t| t.start >= first.start && t.start <= last.start)
        .map(|t| t.end - t.start + u64::from(amiro_bus_sim::INTERMISSION_BITS))
        .sum();
    ensure!(
        on_bus == last.end + u64::from(amiro_bus_sim::INTERMISSION_BITS) - first.start,
        "the bus idled while LightRing babbled"
    );
    let babble_bits: u64 = babble.iter().map(|t| t.end - t.start).sum();
    let share = babble_bits * 100 / (last.end - first.start);
    // The winner: DiWheelDrive's magnetometer keeps its grid through the babbling, and its
    // worst response stays within the Davis bound of the traffic as it was (the babbling frame
    // counts as lower-priority blocking).
    // 22 at 6 000 µs (117 at 1 150 µs before 2026-12-06, 150 at 900 µs before 2026-12-05).
    let magnetometer = magnetometer_on_grid(run, 22, 400)?;
    let report = amiro_robot::report::analyse(&run.outcome.transfers, run.outcome.ended_at);
    let line = report
        .iter()
        .find(|l| l.id == 0x605)
        .context("no 0x605 in the bus report")?;
    ensure!(
        !line.exceeds(),
        "0x605's worst response {} µs against its bound {:?}",
        line.observed_us,
        line.bound_us
    );
    let during = run
        .frames(0x605)
        .iter()
        .filter(|t| t.start >= first.start && t.start <= last.start)
        .count();
    // The loser: the ring's 0x61F waits while the babbling lasts, and its samples are back on
    // their 62.5 ms grid after it (frames that waited in PowerManagement's mailboxes go first).
    let ring = run.frames(0x61F);
    let starved = ring
        .iter()
        .filter(|t| t.start > first.start && t.start < last.end)
        .count();
    ensure!(
        starved == 0,
        "{starved} ring frames won against the babbling {BABBLE:03X}"
    );
    let waited = ring
        .iter()
        .filter(|t| t.released_at < last.end && t.end > last.end)
        .map(|t| t.end - t.released_at)
        .max()
        .unwrap_or(0);
    let before: Vec<u64> = ring
        .iter()
        .filter(|t| t.end < FROM)
        .map(|t| t.end)
        .collect();
    let after: Vec<u64> = ring
        .iter()
        .filter(|t| t.end > last.end + 5_000)
        .map(|t| t.end)
        .collect();
    let samples_before = ring_samples_of(&before, 0x61F, RING_US)?;
    let samples_after = ring_samples_of(&after, 0x61F, RING_US)?;
    Ok(format!(
        "LightRing's controller babbled {} × {BABBLE:03X} from {} to {} µs ({share} % of the bus); \
         {during} magnetometer frames won against it, {} in all on the {MAGNETOMETER_US} µs grid, worst {} µs \
         (bound {} µs); the ring lost every arbitration (longest wait {waited} µs), \
         {samples_before} samples on its grid before, {samples_after} after",
        babble.len(),
        first.start,
        last.end,
        magnetometer.len(),
        line.observed_us,
        line.bound_us.as_ref().map_or(0, |b| *b),
    ))
}

fn mailbox_abort(run: &Run) -> Result<String> {
    // The babbling's start (robot/scenarios/mailbox-abort.log).
    const FROM: u64 = 35_000;
    every_board_ended(run)?;
    nothing_dropped(run)?;
    let babble = run.frames(0x610);
    let last = babble
        .last()
        .context("LightRing's controller did not babble")?;
    // PowerManagement's power status at high, released during the babbling: each frame goes out
    // during it, within a few frame times of its release (an abort is carried to the bus at the next
    // 40 µs exchange, then a babbling frame already on the wire finishes first).
    let during: Vec<&Transfer> = run
        .frames(0x51E)
        .into_iter()
        .filter(|t| t.released_at >= FROM && t.released_at < last.start)
        .collect();
    ensure!(
        during.len() >= 2,
        "{} power-status frames at high released during the babbling",
        during.len()
    );
    let worst = during
        .iter()
        .map(|t| t.end - t.released_at)
        .max()
        .unwrap_or(0);
    ensure!(
        during.iter().all(|t| t.end < last.end) && worst <= 1_000,
        "power-status frames waited for the babbling to end (worst {worst} µs from release to sent)"
    );
    // What made room: PowerManagement aborted a waiting, less urgent frame, which went out later.
    let aborts: Vec<&str> = run.bus_notes("powermgmt aborts");
    ensure!(
        !aborts.is_empty(),
        "PowerManagement aborted no waiting frame"
    );
    let low_after = run
        .frames(0x71E)
        .iter()
        .filter(|t| t.end > last.end)
        .count();
    ensure!(
        low_after > 0,
        "the aborted power-status frame at low never went out"
    );
    Ok(format!(
        "{} power-status frames at high released while LightRing babbled went out within {worst} µs each \
         (PowerManagement aborted a less urgent waiting frame {} time(s): {}; sent after the babbling)",
        during.len(),
        aborts.len(),
        aborts.join("; ")
    ))
}

fn reset(run: &Run) -> Result<String> {
    every_board_ended(run)?;
    let ups = run
        .notes(2)
        .iter()
        .filter(|n| n.starts_with("LightRing up"))
        .count();
    ensure!(ups == 2, "LightRing came up {ups} times, expected twice");
    let sync: Vec<&str> = run.bus_notes("SYS_SYNC_N");
    ensure!(
        sync.len() == 3 && sync[1].contains("low (held by lightring)") && sync[2].contains("high"),
        "SYS_SYNC_N should rise, fall while LightRing boots, and rise again: {sync:?}"
    );
    let led_sets = run.view(2).traces("led-set").len();
    ensure!(
        led_sets == 2,
        "{led_sets} LED commands applied, expected one before and one after the reset"
    );
    // After the reset LED 3 is dark again; LED 4 (OUT 12..14) carries the new colour.
    let (latched, _, lit) = last_latch(run)?;
    ensure!(
        !lit.is_empty() && lit.iter().all(|k| (12..15).contains(k)),
        "only LED 4 should be lit after the reset: `{latched}`"
    );
    let magnetometer = magnetometer_on_grid(run, 1, 300)?;
    Ok(format!(
        "LightRing rebooted ({}), took LED 4 after; DiWheelDrive's {} frames stayed on their grid",
        sync[1],
        magnetometer.len()
    ))
}

fn bus_fault(run: &Run) -> Result<String> {
    every_board_ended(run)?;
    let errors: Vec<&str> = run
        .bus_notes("error frame")
        .into_iter()
        .filter(|n| n.contains("605"))
        .collect();
    ensure!(
        errors.len() == 3,
        "{} error frames on 0x605, expected 3",
        errors.len()
    );
    let magnetometer = run.frames(0x605);
    // A frame the bit errors hit is late by design: each error costs at most the corrupted attempt (a 4-byte
    // frame with worst-case stuffing, 98 bits), the error frame and its delimiter (20 bits) and the
    // intermission (3 bits) before it competes again. Every other frame before the unplug keeps the grid.
    let error_times: Vec<u64> = errors
        .iter()
        .filter_map(|n| {
            let seconds: f64 = n.split_once('(')?.1.split_once(')')?.0.parse().ok()?;
            Some((seconds * 1e6).round() as u64)
        })
        .collect();
    ensure!(
        error_times.len() == 3,
        "error frames without a time: {errors:?}"
    );
    const PER_ERROR_US: u64 = 98 + 20 + 3;
    let mut worst_wait = 0;
    let mut segments: Vec<Vec<u64>> = vec![Vec::new()];
    for t in magnetometer.iter().filter(|t| t.end < 100_000) {
        let hits = error_times
            .iter()
            .filter(|&&e| e > t.queued_at && e < t.end)
            .count() as u64;
        if hits == 0 {
            if let Some(segment) = segments.last_mut() {
                segment.push(t.end);
            }
            continue;
        }
        let waited = t.end - t.queued_at;
        ensure!(
            waited <= 300 + hits * PER_ERROR_US,
            "the magnetometer frame hit by {hits} bit error(s) waited {waited} µs (queued {} µs, ended {} µs), more than 300 µs + {hits} × {PER_ERROR_US} µs",
            t.queued_at,
            t.end
        );
        worst_wait = worst_wait.max(waited);
        segments.push(Vec::new());
    }
    ensure!(
        segments.len() > 1,
        "no magnetometer frame was hit by the bit errors"
    );
    for segment in segments.iter().filter(|s| !s.is_empty()) {
        on_grid(
            "magnetometer before the unplug",
            segment,
            MAGNETOMETER_US,
            300,
        )?;
    }
    let after: Vec<u64> = magnetometer
        .iter()
        .filter(|t| t.queued_at > 121_000)
        .map(|t| t.end)
        .collect();
    on_grid("magnetometer after the plug", &after, MAGNETOMETER_US, 300)?;
    let held = magnetometer
        .iter()
        .filter(|t| t.queued_at < 120_000 && t.end > 120_000)
        .count();
    ensure!(held >= 1, "no frame held over the unplugged stretch");
    ensure!(
        run.ends(0x605)
            .iter()
            .all(|&t| !(100_100..120_000).contains(&t)),
        "a magnetometer frame on the bus while DiWheelDrive was unplugged"
    );
    let samples = ring_samples(run, 0x61F, RING_US)?;
    Ok(format!(
        "3 error frames on 0x605 and retransmission (the frames they hit on the bus at most {worst_wait} µs after they were queued); {held} frames held while unplugged; grid before and after; the ring ran on ({samples} samples)"
    ))
}

/// Runs scenario `name` twice and compares everything both runs printed.
fn same_bytes_twice(
    root: &Path,
    firmware: &[amiro_robot::Firmware; 3],
    name: &str,
) -> Result<usize> {
    let path = root
        .join("robot")
        .join("scenarios")
        .join(format!("{name}.log"));
    let (actions, duration) = amiro_robot::stimulus::read(&path)?;
    let duration = duration.context("no `# duration:`")?;
    let mut texts = Vec::new();
    for k in 0..2 {
        let work = crate::workspace::qemu_target_dir(root)
            .join("scenarios")
            .join("robot")
            .join(format!("{name}-determinism-{k}"));
        let _ = std::fs::remove_dir_all(&work);
        let mut lines: Vec<String> = Vec::new();
        texts.push(amiro_robot::run(firmware, &actions, duration, &work, &mut lines, None)?.text);
    }
    if let Some(line) = texts[0]
        .lines()
        .zip(texts[1].lines())
        .position(|(a, b)| a != b)
    {
        bail!("the two runs differ from line {}", line + 1);
    }
    ensure!(texts[0] == texts[1], "the two runs differ in length");
    Ok(texts[0].len())
}

/// The thesis demo's stimulus run for [`LONG_DEMO_US`]: every magnetometer-x release ([`MAGNETOMETER_US`] from the
/// command at 60 ms, decided after the refusals' verdict window) on its grid, a ring sample every [`RING_US`], and every
/// stream within its Davis bound.
fn long_demo(root: &Path, firmware: &[amiro_robot::Firmware; 3]) -> Result<String> {
    let path = root.join("robot").join("scenarios").join("thesis-demo.log");
    let (actions, _) = amiro_robot::stimulus::read(&path)?;
    let work = crate::workspace::qemu_target_dir(root)
        .join("scenarios")
        .join("robot")
        .join("thesis-demo-10s");
    let _ = std::fs::remove_dir_all(&work);
    let (run, report) = run_and_report(firmware, &actions, LONG_DEMO_US, &work)?;
    every_board_ended(&run)?;
    // Commanded at 60 ms, accepted after the second refusal's verdict window (about 91 ms), a release every
    // 6 000 µs: about 1 650 by 10 s. The count allows 120 ms of set-up; a lost or late sample breaks the grid
    // itself.
    let expected = ((LONG_DEMO_US - 120_000) / MAGNETOMETER_US) as usize;
    let magnetometer = magnetometer_on_grid(&run, expected, 300)?;
    let samples = ring_samples(&run, 0x61F, RING_US)?;
    ensure!(
        samples as u64 >= (LONG_DEMO_US - 20_000) / RING_US,
        "{samples} ring samples in {LONG_DEMO_US} µs"
    );
    within_davis(&report)?;
    Ok(format!(
        "{} magnetometer frames on the {MAGNETOMETER_US} µs grid, {samples} ring samples; bus: {} streams within their Davis bounds",
        magnetometer.len(),
        report.len()
    ))
}

/// Runs `actions` on the robot for `duration` µs in `work`, and writes there the run's output, its
/// bus log and its bus report (observed responses against the Davis analysis of the same traffic).
fn run_and_report(
    firmware: &[amiro_robot::Firmware; 3],
    actions: &[amiro_robot::stimulus::Timed],
    duration: u64,
    work: &Path,
) -> Result<(Run, Vec<amiro_robot::report::Line>)> {
    let mut lines: Vec<String> = Vec::new();
    let outcome = amiro_robot::run(firmware, actions, duration, work, &mut lines, None)?;
    std::fs::write(work.join("output.log"), &outcome.text)?;
    let (bus, _) = crate::qemu::split_output(&outcome.text);
    std::fs::write(work.join("bus.log"), bus)?;
    let report = amiro_robot::report::analyse(&outcome.transfers, duration);
    std::fs::write(
        work.join("bus-report.txt"),
        amiro_robot::report::render(&report),
    )?;
    Ok((Run { outcome }, report))
}

/// The streams whose observed worst response is beyond their Davis bound, one line each.
fn beyond_davis(report: &[amiro_robot::report::Line]) -> Vec<String> {
    report
        .iter()
        .filter(|l| l.exceeds())
        .map(|l| format!("{:03X} {} µs > {:?}", l.id, l.observed_us, l.bound_us))
        .collect()
}

/// Fails when a stream's observed worst response is beyond its Davis bound.
fn within_davis(report: &[amiro_robot::report::Line]) -> Result<()> {
    let exceeded = beyond_davis(report);
    ensure!(
        exceeded.is_empty(),
        "observed responses beyond the Davis bound: {}",
        exceeded.join(", ")
    );
    Ok(())
}

/// How long [`long_demo`] runs the thesis demo (virtual time, µs).
const LONG_DEMO_US: u64 = 10_000_000;

/// The robot scenarios' count, each printed as it ends: `robot <name> ok: <summary>` or
/// `robot <name> FAILED (<what it checks>): <error>`.
#[derive(Default)]
struct Tally {
    passed: usize,
    failed: usize,
}

impl Tally {
    fn record(&mut self, name: &str, about: Option<&str>, result: Result<String>) {
        match result {
            Ok(summary) => {
                self.passed += 1;
                println!("robot {name:<22} ok: {summary}");
            }
            Err(e) => {
                self.failed += 1;
                match about {
                    Some(about) => println!("robot {name:<22} FAILED ({about}): {e:#}"),
                    None => println!("robot {name:<22} FAILED: {e:#}"),
                }
            }
        }
    }
}

/// Runs every robot scenario; fails if any check fails.
pub fn run_all(root: &Path) -> Result<()> {
    run_all_with(root, &[])
}

/// [`run_all`] with trial features (`super::firmware::firmware_with`).
pub fn run_all_with(root: &Path, extra: &[&str]) -> Result<()> {
    crate::workspace::ensure_qemu()?;
    let firmware = super::firmware::firmware_with(root, extra)?;
    let mut tally = Tally::default();
    for scenario in SCENARIOS {
        let path = root
            .join("robot")
            .join("scenarios")
            .join(format!("{}.log", scenario.name));
        let work = crate::workspace::qemu_target_dir(root)
            .join("scenarios")
            .join("robot")
            .join(scenario.name);
        let _ = std::fs::remove_dir_all(&work);
        let result = (|| {
            let (actions, duration) = amiro_robot::stimulus::read(&path)?;
            let duration =
                duration.with_context(|| format!("{}: no `# duration:`", path.display()))?;
            let (run, report) = run_and_report(&firmware, &actions, duration, &work)?;
            // Each board's admission verdicts at the rate the analysis charges them.
            for (board, name) in NODES.iter().enumerate().take(3) {
                crate::scenarios::verdicts_spaced(&run.view(board), name)?;
            }
            let summary = (scenario.check)(&run)?;
            if scenario.bus_bounds {
                within_davis(&report)?;
                Ok(format!(
                    "{summary}; bus: {} streams within their Davis bounds",
                    report.len()
                ))
            } else {
                Ok(format!(
                    "{summary}; bus: {} of {} streams beyond their Davis bounds (fault episode)",
                    beyond_davis(&report).len(),
                    report.len()
                ))
            }
        })();
        tally.record(scenario.name, Some(scenario.about), result);
    }
    // Determinism: the same stimulus again prints the same bytes.
    tally.record(
        "determinism",
        None,
        same_bytes_twice(root, &firmware, "thesis-demo")
            .map(|bytes| format!("thesis-demo twice, {bytes} bytes identical")),
    );
    // The thesis demo for 10 s of virtual time, not its stimulus's 200 ms: a sample lost or moved
    // late in a long run (as a SysTick change once did from 48 ms on, unseen in 200 ms) fails here.
    tally.record(
        "thesis-demo-10s",
        Some("every magnetometer release on its grid and every frame within its Davis bound for 10 s"),
        long_demo(root, &firmware),
    );
    // The robot in a world: its ring against the trajectory, twice the same.
    let about = format!(
        "the ring in {}.json against the trajectory",
        super::world_scenario::WORLD
    );
    tally.record(
        super::world_scenario::STIMULUS,
        Some(&about),
        super::world_scenario::run(root, &firmware, super::world_scenario::ring_age_us(extra)),
    );
    // A behaviour closes the loop: the obstacle-avoidance example in the arena.
    tally.record(
        super::world_scenario::AVOIDANCE,
        Some("examples/obstacle_avoidance.py in arena.json"),
        super::world_scenario::avoidance(root, &firmware),
    );
    // The line-following example round a closed line.
    tally.record(
        super::world_scenario::LINE,
        Some("examples/line_following.py in line-lap.json"),
        super::world_scenario::line_following(root, &firmware),
    );
    let Tally { passed, failed } = tally;
    println!("robot scenarios: {passed} passed, {failed} failed");
    ensure!(
        failed == 0,
        "{failed} robot scenario(s) failed (outputs in {})",
        crate::workspace::qemu_target_dir(root)
            .join("scenarios")
            .join("robot")
            .display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shutdown run without the boards' handler events fails the check instead of passing on
    /// no `command-accepted` line at all.
    #[test]
    fn shutdown_needs_the_handler_events() {
        let end = |board: &str| format!("{board}: # qemu: shutdown hand-over at 100420 µs");
        let mut text = vec!["bus: # (0.100160) SYS_PD_N low (driven by powermgmt)".to_string()];
        text.extend(NODES.iter().take(3).map(|b| end(b)));
        let run = Run {
            outcome: Outcome {
                text: text.join("\n"),
                ..Outcome::default()
            },
        };
        let error = shutdown(&run).unwrap_err().to_string();
        assert!(error.contains("no handler events"), "{error}");
        text.push("powermgmt: # (0.008420) trace command-accepted 21F".into());
        let run = Run {
            outcome: Outcome {
                text: text.join("\n"),
                ..Outcome::default()
            },
        };
        shutdown(&run).unwrap();
    }
}
