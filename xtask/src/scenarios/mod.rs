//! The QEMU scenarios CI runs against each board's firmware, and what each must show.
//!
//! Each scenario is a stimulus log in `<board>/qemu/` (its `# duration:` header says how long the
//! run lasts); the checks live in one module per board. The firmware's output — every frame it put on the bus, stamped with virtual time,
//! and its trace events — is parsed here and checked against the behaviour the protocol promises
//! and against the analysed response-time bound.
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};

use crate::qemu::{self, TimedFrame};
pub use amiro_robot::log::duration_of;

pub mod diwheeldrive;
pub mod diwheeldrive_1_2;
pub mod lightring;
pub mod lightring_1_2;
pub mod powermgmt;

/// The RAM goal of a board revision in QEMU, static data plus the painted stack's high-water mark
/// (bytes).
pub fn ram_goal(board: &str, revision: &str) -> u64 {
    match (board, revision) {
        // LightRing 1-2: 1-0's goal plus a stated 256 B. Its scenarios measure 12 656 B, but the
        // same image deciding (and refusing) the shared admission log's 2 ms request reached
        // 12 904 B against 1-0's 12 416 B: its 108-byte frame where 1-0 keeps 36 (+72 B, on the
        // chip too), the QEMU build's simulator of three TLC5947 (+168 B, not on the chip), and that
        // decision's analysis of a 1-2 robot (+248 B of stack, on the chip too).
        ("lightring", "1-2") => 8 * 1024 + ADMISSION_RAM_ALLOWANCE + LIGHTRING_1_2_RAM_ALLOWANCE,
        // LightRing's own 8 KiB, plus what the on-chip admission analysis needs (its state and the
        // stack of one whole-robot analysis, about 7.4 KB; 4.5 KiB since issue 20 bounded the decisions and
        // issue 23 added the robot platform: 12 368 B measured then, 12 416 B with issue 22's
        // revisions): a stated allowance, as for flash (`boards::Board::admission_allowance`); the
        // chip has 64 KiB. 512 B more since the check takes sensor-bus scripts (issue 33): the board
        // analysis is out of line (`admission::board::run_view`, one instance for the board and the
        // scripts' views), a decision's stack about 256 B deeper (1-0: 12 672 B measured), and where the
        // interrupts nest on it moves with the code's layout by 248 B (12 920 B with the final image). The shipped
        // images no longer link the rounds (`schedule-analysis/sensor-buses`), but the board analysis stays out of
        // line: 1-0 12 904 B, 1-2 12 816 B (2026-12-04), still above 4.5 KiB's 12 800 B, so the 5 KiB stay.
        // 6.5 KiB since DiWheelDrive's transmit jobs are rows (2026-12-06): the check's arrays hold 43 jobs, not 32
        // (the static thread-mode bound 488 B deeper), and its decisions take up to 1 000 iterations, so more of
        // them nest the interrupts on their deepest frames: 1-0 14 292 B, 1-2 13 684 B measured.
        ("lightring", _) => 8 * 1024 + ADMISSION_RAM_ALLOWANCE,
        // DiWheelDrive's 16 KiB had 56 B left with the admission check (16 328 B in `admission-search`, the
        // admission task's deepest analysis with every priority nested on it); a shift in timing moves where the
        // interrupts nest on that analysis (16 640 B after issue 20's reservation change, the same decisions):
        // a stated allowance instead of a goal met by luck: 1 KiB, then 2 KiB when the costliest sequence a search
        // with policy changes found (accept-and-warn starts publishers the check refuses, so more priority levels
        // run at once) nested them deeper: 17 792 B (a stack of 11 736 B).
        ("diwheeldrive", _) => 16 * 1024 + DIWHEELDRIVE_ADMISSION_RAM_ALLOWANCE,
        // PowerManagement kept its 16 KiB with the admission check until its tables held 43 jobs (DiWheelDrive's
        // transmit jobs as rows, 2026-12-06): 16 592 B measured then, so 1 KiB for the check as well.
        ("powermgmt", _) => 16 * 1024 + POWERMGMT_ADMISSION_RAM_ALLOWANCE,
        _ => 16 * 1024,
    }
}

/// What LightRing 1-2's RAM goal adds to 1-0's (see [`ram_goal`]).
pub const LIGHTRING_1_2_RAM_ALLOWANCE: u64 = 256;

/// What the on-chip admission analysis may add to LightRing's RAM goal (docs/analysis.md, "The on-chip
/// admission check"); PowerManagement's is [`POWERMGMT_ADMISSION_RAM_ALLOWANCE`].
pub const ADMISSION_RAM_ALLOWANCE: u64 = 6 * 1024 + 512;

/// What the on-chip admission analysis may add to PowerManagement's 16 KiB RAM goal (see [`ram_goal`]).
pub const POWERMGMT_ADMISSION_RAM_ALLOWANCE: u64 = 1024;

/// What the on-chip admission analysis may add to DiWheelDrive's 16 KiB RAM goal (docs/analysis.md).
pub const DIWHEELDRIVE_ADMISSION_RAM_ALLOWANCE: u64 = 2 * 1024;

/// The scenarios of one board revision (`boards::Revision::name`): DiWheelDrive 1-1's and LightRing
/// 1-0's are the board's original set (`<board>/qemu/`), the 1-2 boards' their own
/// (`<board>/qemu/rev-1-2/`, with the shared logs where a scenario reuses one). PowerManagement's
/// two images have the same code but their admission tables (docs/boards.md, "Revisions"): its set
/// runs on the shipped newest, 1-2; its 1-1 image runs in every robot scenario (a 1-1 robot,
/// `robot::firmware::ROBOT_REVISION`) and in the smoke runs, and a second run of its set on 1-1
/// would cost CI a QEMU build and 13 runs for the same code (docs/qemu.md).
pub fn for_revision(board: &str, revision: &str) -> &'static [Scenario] {
    match (board, revision) {
        ("diwheeldrive", "1-2") => diwheeldrive_1_2::SCENARIOS,
        ("diwheeldrive", _) => diwheeldrive::SCENARIOS,
        ("lightring", "1-2") => lightring_1_2::SCENARIOS,
        ("powermgmt", "1-2") => powermgmt::SCENARIOS,
        ("powermgmt", _) => &[],
        _ => for_board(board),
    }
}

/// The stimulus log of a board revision's scenario: in the revision's folder
/// (`diwheeldrive/qemu/rev-1-2/`) if it has its own, else the board's shared one (`<board>/qemu/`).
pub fn log_path(root: &Path, board: &str, revision: &str, scenario: &str) -> PathBuf {
    let base = root.join(board).join("qemu");
    let own = base
        .join(format!("rev-{revision}"))
        .join(format!("{scenario}.log"));
    if own.is_file() {
        own
    } else {
        base.join(format!("{scenario}.log"))
    }
}

/// The scenarios of a board's original set (for DiWheelDrive the 1-1 ones, for LightRing the 1-0
/// ones; see [`for_revision`]).
pub fn for_board(board: &str) -> &'static [Scenario] {
    match board {
        "diwheeldrive" => diwheeldrive::SCENARIOS,
        "lightring" => lightring::SCENARIOS,
        "powermgmt" => powermgmt::SCENARIOS,
        _ => &[],
    }
}

/// The firmware's output, split into frames and trace lines.
#[derive(Debug, Default)]
pub struct RunOutput {
    /// Frames the board put on the bus, in order.
    pub frames: Vec<TimedFrame>,
    /// Trace and log lines (without the leading `# `).
    pub notes: Vec<String>,
    /// The QEMU run's work directory (its `output.log` and `trace.bin`), when the run kept one: what
    /// [`RunOutput::own_execution_us`] reads.
    pub work: Option<std::path::PathBuf>,
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

    /// Checks that the board rejected exactly the commands `expected` names, in order (the reason each
    /// `command-rejected` trace line ends with); their number.
    pub fn expect_rejections(&self, expected: &[&str]) -> Result<usize> {
        let reasons: Vec<&str> = self
            .traces("command-rejected")
            .iter()
            .filter_map(|line| line.split_whitespace().last())
            .collect();
        ensure!(
            reasons == expected,
            "rejection reasons {reasons:?}, expected {expected:?}"
        );
        Ok(reasons.len())
    }
}

/// What a board's last diagnostics sample in a run said (the fields the scenarios check).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Health {
    /// Commands accepted.
    pub accepted: u32,
    /// Commands rejected, every reason.
    pub rejected: u32,
    /// Receive drops (a lower bound on frames lost).
    pub rx_dropped: u32,
    /// Receive-FIFO overruns.
    pub rx_overruns: u32,
    /// Deadline misses per level, urgent first.
    pub deadline_misses: [u32; 4],
}

/// Decodes the last diagnostics sample `board` put on the bus (its six pages, in order).
pub fn last_health(out: &RunOutput, board: amiro_can::Board) -> Result<Health> {
    use amiro_can::{DiagnosticsPage, Message, SensorData};
    let topic = u32::from(board.diagnostics_topic().byte());
    let frames: Vec<&TimedFrame> = out
        .frames
        .iter()
        .filter(|f| f.id & 0x4FF == 0x400 | topic)
        .collect();
    ensure!(
        frames.len() >= 6,
        "{} diagnostics frames from {board}, expected a sample of six",
        frames.len()
    );
    let mut health = Health::default();
    for f in &frames[frames.len() - 6..] {
        let id = amiro_can::CanId::try_from(f.id as u16).map_err(|e| anyhow::anyhow!("{e}"))?;
        let frame = amiro_can::Frame::new(id, &f.data).map_err(|e| anyhow::anyhow!("{e}"))?;
        let Ok(Message::Sample {
            data: SensorData::Diagnostics { page, .. },
            ..
        }) = frame.decode()
        else {
            bail!("{id:?}: not a diagnostics page");
        };
        match page {
            DiagnosticsPage::Commands {
                accepted, rejected, ..
            } => {
                health.accepted = accepted.get();
                health.rejected = rejected.get();
            }
            DiagnosticsPage::AdmissionAndReceive {
                rx_dropped,
                rx_overruns,
                ..
            } => {
                health.rx_dropped = rx_dropped.get();
                health.rx_overruns = rx_overruns.get();
            }
            DiagnosticsPage::Deadlines { misses } => {
                health.deadline_misses = misses.map(|m| m.get());
            }
            _ => {}
        }
    }
    Ok(health)
}

/// Checks a board's last diagnostics sample against what the run shows: accepted and rejected
/// commands as traced (up to the request that asked for the sample), receive drops and overruns as
/// the end line says.
pub fn check_health(out: &RunOutput, board: amiro_can::Board) -> Result<Health> {
    let health = last_health(out, board)?;
    let accepted = out.traces("command-accepted").len() as u32;
    let rejected = out.traces("command-rejected").len() as u32;
    ensure!(
        health.accepted == accepted && health.rejected == rejected,
        "diagnostics say {} accepted / {} rejected, the trace shows {accepted} / {rejected}",
        health.accepted,
        health.rejected
    );
    let dropped = out.end_field("rx dropped")? as u32;
    let overruns = out.end_field("rx overruns")? as u32;
    ensure!(
        health.rx_dropped == dropped.min(0xFFFF) && health.rx_overruns == overruns.min(0xFF),
        "diagnostics say {} dropped / {} overruns, the end line {dropped} / {overruns}",
        health.rx_dropped,
        health.rx_overruns
    );
    Ok(health)
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
    /// The longest own execution (pre-emptions taken out: the bench's `exec max`) of any run of `board`'s task
    /// `task` in this QEMU run, virtual µs, and how many runs it had; read from the run's task trace.
    pub fn own_execution_us(&self, board: &str, task: &str) -> Result<(f64, usize)> {
        let work = self
            .work
            .as_deref()
            .context("the run kept no work directory (no task trace to read)")?;
        let root = crate::workspace::workspace_root();
        let spec = crate::boards::by_name(board).with_context(|| format!("no board {board}"))?;
        let names = amiro_firmware::trace_ids::board_names(&root, board)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .context("the board's task numbers")?;
        let number = names
            .iter()
            .position(|n| n == task)
            .with_context(|| format!("{board} has no task {task}"))?;
        let capture = crate::bench::read_scenario_run(spec, work)?;
        let runs: Vec<_> = capture
            .runs
            .iter()
            .filter(|r| usize::from(r.task) == number)
            .collect();
        let most = runs.iter().map(|r| r.execution_ns()).max().unwrap_or(0);
        Ok((most as f64 / 1000.0, runs.len()))
    }

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

    /// The releases of `topic` within `[from, to)`, checked to be on the exact grid `first + k·period`
    /// (drift-free, none skipped; at least one).
    pub fn releases_on_grid(
        &self,
        topic: &str,
        period: u64,
        from: u64,
        to: u64,
    ) -> Result<Vec<u64>> {
        let releases = self.releases(topic, from, to)?;
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
        Ok(releases)
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
        self.periodic_stream_of(id, topic, period, from, to, 1)
    }

    /// [`Self::periodic_stream`] for a topic whose sample is `per_sample` frames on `id` (the
    /// latency is the release to the sample's last frame, which must leave within the period).
    pub fn periodic_stream_of(
        &self,
        id: u32,
        topic: &str,
        period: u64,
        from: u64,
        to: u64,
        per_sample: usize,
    ) -> Result<Stream> {
        let per_sample = per_sample.max(1);
        let releases = self.releases_on_grid(topic, period, from, to)?;
        let first = releases[0];
        let last = *releases.last().unwrap_or(&first);
        // The frames of these releases: from the first release to a period after the last (a sample's frames are on
        // the bus within its period, checked below), not the window's end, which a last frame may fall just past.
        let frames: Vec<u64> = self
            .times(id)
            .into_iter()
            .filter(|t| (first..last + period).contains(t))
            .collect();
        ensure!(
            frames.len() == releases.len() * per_sample,
            "{} frames {id:03X} for {} releases of {per_sample} frame(s) each",
            frames.len(),
            releases.len()
        );
        let lasts: Vec<u64> = frames.chunks(per_sample).map(|c| c[c.len() - 1]).collect();
        let frames: Vec<u64> = frames.chunks(per_sample).map(|c| c[0]).collect();
        let mut worst = 0;
        for (k, ((f, last), r)) in frames.iter().zip(&lasts).zip(&releases).enumerate() {
            ensure!(f >= r, "frame {k} at {f} µs precedes its release at {r} µs");
            ensure!(
                *last < r + period,
                "sample {k}'s last frame at {last} µs is a full period after its release at {r} µs"
            );
            worst = worst.max(last - r);
        }
        Ok(Stream {
            releases,
            frames,
            worst_latency: worst,
        })
    }
}

/// A time `s.micros` in µs (`amiro_can::candump`'s timestamp text).
pub fn parse_seconds(text: &str) -> Result<u64> {
    amiro_can::candump::parse_seconds(text)
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .checked_micros()
        .with_context(|| format!("time `{text}` beyond u64 microseconds"))
}

/// A named scenario and its check.
pub struct Scenario {
    /// File stem in `<board>/qemu/`.
    pub name: &'static str,
    /// What it shows.
    pub about: &'static str,
    /// The check.
    pub check: fn(&RunOutput, &Bounds) -> Result<String>,
}

/// Response-time bounds from the analysis, per published topic of the scenarios.
pub struct Bounds {
    root: std::path::PathBuf,
    /// The run's received frames no closer than this, µs (its stimulus); `None`: a full-rate bus.
    received_gap_us: Option<f64>,
}

impl Bounds {
    /// Bounds computed by the schedule analysis from the DiWheelDrive app's own source.
    pub fn from_analysis(root: &Path) -> Result<Self> {
        Ok(Self {
            root: root.to_path_buf(),
            received_gap_us: None,
        })
    }

    /// The bounds of one run whose stimulus (`stimulus.bin`, as QEMU replayed it) is `encoded`: its received
    /// frames no closer than they came.
    pub fn for_run(&self, encoded: &[u8]) -> Result<Self> {
        Ok(Self {
            root: self.root.clone(),
            received_gap_us: Some(crate::qemu::received_gap_us(encoded)? as f64),
        })
    }

    /// The run's received frames no closer than this, µs (`None`: a full-rate bus).
    pub fn received_gap_us(&self) -> Option<f64> {
        self.received_gap_us
    }

    /// The workspace root the analysis reads its models from.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Worst-case latency from a publisher's release to its frame in a mailbox, as analysed for
    /// `topic` published alone at CAN priority `level` every `period_us`.
    pub fn publisher_latency_us(&self, topic: &str, level: &str, period_us: u64) -> Result<u64> {
        self.publisher_latency_bound_us(topic, level, period_us)?
            .with_context(|| {
                format!("publish_{level}[{topic}]: the analysis bounds nothing (its busy window never closes)")
            })
    }

    /// [`Self::publisher_latency_us`], `None` where the analysis bounds nothing (its busy window never closes).
    pub fn publisher_latency_bound_us(
        &self,
        topic: &str,
        level: &str,
        period_us: u64,
    ) -> Result<Option<u64>> {
        crate::bounds::publisher_bound_us(
            &self.root,
            "diwheeldrive",
            (topic, level, period_us),
            self.received_gap_us,
        )
    }
}

/// A flood run's worst latency held to its analysed `bound`, and how it reads. In QEMU every received frame
/// costs its replay job beside the receive interrupt (the QEMU model has both): at a flood's rate the traced QEMU
/// build's model can be overloaded and bound nothing (`None`); then the run is held to its grid only (checked by
/// the caller) and the chip's bound is `cargo xtask analyze`'s, which has no replay.
pub fn within_flood_bound(worst: u64, bound: Option<u64>) -> Result<String> {
    match bound {
        Some(bound) => {
            ensure!(
                worst <= bound,
                "latency {worst} µs under the flood exceeds the analysed bound {bound} µs"
            );
            Ok(format!("worst latency {worst} µs ≤ analysed {bound} µs"))
        }
        None => Ok(format!(
            "worst latency {worst} µs (no bound: the replay of frames at this rate overloads the traced QEMU build's model)"
        )),
    }
}

/// The commands a flood scenario sends (`diwheeldrive/qemu/flood.log`, `powermgmt/qemu/flood.log`).
pub const FLOOD_COMMANDS: u64 = 2_002;

/// A command flood's accounting: (commands handled, commands dropped and counted at the bounded receive queue).
/// The receive FIFO must never have overrun; every command sent is handled or dropped (up to `admission_waiting`
/// sensor commands may still wait for the admission task when the run ends); and, as two tasks handle commands
/// (the command handler and the admission task), each at most one per `min_interval_us`, no three are handled
/// within that interval.
pub fn flood_commands(
    out: &RunOutput,
    admission_waiting: u64,
    min_interval_us: u64,
) -> Result<(usize, u64)> {
    flood_commands_sent(out, FLOOD_COMMANDS, admission_waiting, min_interval_us)
}

/// [`flood_commands`] for a flood log that sends `sent` commands in all (DiWheelDrive 1-2's stops its publisher
/// before the health one-shot: [`FLOOD_COMMANDS`] and that stop).
pub fn flood_commands_sent(
    out: &RunOutput,
    sent: u64,
    admission_waiting: u64,
    min_interval_us: u64,
) -> Result<(usize, u64)> {
    let mut handled: Vec<u64> = out
        .traces("command-")
        .iter()
        .map(|line| trace_time(line))
        .collect::<Result<_>>()?;
    // In time order: a record stamped by the admission task (priority 0) can be written after
    // one the command handler stamped later, when the handler pre-empts it in between.
    handled.sort_unstable();
    let dropped = out.end_field("rx dropped")?;
    let overruns = out.end_field("rx overruns")?;
    ensure!(
        overruns == 0,
        "{overruns} receive-FIFO overruns: the receive interrupt fell behind"
    );
    ensure!(
        (sent - admission_waiting..=sent).contains(&(handled.len() as u64 + dropped)),
        "{} commands handled + {dropped} dropped and counted != the {sent} sent (up to {admission_waiting} may wait for the admission task)",
        handled.len()
    );
    if let Some(gap) = handled.windows(3).map(|w| w[2] - w[0]).min() {
        ensure!(
            gap >= min_interval_us,
            "three commands handled within {gap} µs (the command handler and the admission task each take at most one per {min_interval_us} µs)"
        );
    }
    Ok((handled.len(), dropped))
}

/// The time of a trace line `(s.micros) ...`.
pub fn trace_time(line: &str) -> Result<u64> {
    let stamp = line
        .strip_prefix('(')
        .and_then(|r| r.split_once(')'))
        .map(|(s, _)| s)
        .with_context(|| format!("trace line without time: {line}"))?;
    parse_seconds(stamp)
}

/// The boards' admission check run on the host (the same code and table, `schedule_analysis::admission`), fed
/// with publish requests in the order a board hears them: each is decided beside the streams kept so far and kept
/// (in place of the topic's stream, as the boards keep them) when admitted — `cargo xtask analyze --check`'s
/// decision for the same configuration. A scenario compares a board's verdicts with it.
pub struct HostAdmission {
    robot: schedule_analysis::admission_host::OwnedRobot,
    streams: Vec<schedule_analysis::admission::Stream>,
}

impl HostAdmission {
    /// The table from the apps and timing files under `root`, nothing running.
    pub fn new(root: &Path) -> Result<Self> {
        let robot = schedule_analysis::admission_host::lower_robot(root)
            .map_err(|e| anyhow::anyhow!("admission table: {e}"))?;
        Ok(Self {
            robot,
            streams: Vec::new(),
        })
    }

    /// Decides the publish request `frame` (`ID#DATA`, e.g. `21F#01050000`) and keeps it when admitted.
    pub fn request(&mut self, frame: &str) -> Result<schedule_analysis::admission::Decision> {
        use schedule_analysis::{admission, time::Time};
        let raw = amiro_can::candump::parse_compact(frame).map_err(|e| anyhow::anyhow!("{e}"))?;
        let amiro_can::candump::FrameId::Standard(id) = raw.id() else {
            bail!("{frame} is not a standard frame");
        };
        let Ok(amiro_can::Command::Sensor(command)) = amiro_can::decode_command(id, raw.data())
        else {
            bail!("{frame} is not a sensor command");
        };
        let amiro_can::SensorMode::Publish(period) = command.mode else {
            bail!("{frame} is not a publish request");
        };
        let stream = self
            .robot
            .publisher_stream(
                command.topic.info().name,
                command.priority.name(),
                Time::from_us(period.as_micros().max(1)),
                None,
            )
            .with_context(|| format!("{frame}: no stream in the table"))?;
        let streams = &self.streams;
        let decision = self
            .robot
            .with_table(|t| admission::admit::<64, 64>(t, streams, &stream, false));
        if decision.refusal.is_none() {
            let key = |s: &admission::Stream| s.sender.map(|x| (x.board, x.topic));
            match self.streams.iter().position(|s| key(s) == key(&stream)) {
                Some(i) => self.streams[i] = stream,
                None => self.streams.push(stream),
            }
        }
        Ok(decision)
    }
}

/// [`HostAdmission`] for one request beside `running` (requests in the order heard).
pub fn host_admission(
    root: &Path,
    running: &[&str],
    request: &str,
) -> Result<schedule_analysis::admission::Decision> {
    let mut host = HostAdmission::new(root)?;
    for frame in running {
        host.request(frame)?;
    }
    host.request(request)
}

/// Whether a board's verdict names what the host's check names, with the same bound (µs, rounded up).
pub fn same_refusal(
    verdict: &amiro_can::AdmissionVerdict,
    host: &schedule_analysis::admission::Decision,
) -> Result<()> {
    use schedule_analysis::admission::{Culprit, Refusal};
    let v = match host.refusal {
        Some(Refusal::Deadline(v)) => v,
        // Refused without a verdict on a deadline: the board sends no culprit and no bound.
        Some(other) => {
            ensure!(
                verdict.violation == amiro_can::Violation::Unknown
                    && verdict.wcrt_us.get() == 0
                    && verdict.deadline_us.get() == 0,
                "the host refuses on {other:?} (no deadline named), the board answered with {verdict}"
            );
            return Ok(());
        }
        None => bail!("the host admits what the board answered with {verdict}"),
    };
    let us = |t: schedule_analysis::time::Time| t.as_ns().div_ceil(1000);
    let wcrt = v.wcrt.map_or(u64::from(u32::MAX), us).min(0xFF_FFFF);
    ensure!(
        u64::from(verdict.wcrt_us.get()) == wcrt
            && u64::from(verdict.deadline_us.get()) == us(v.deadline).min(0xFF_FFFF),
        "the board says {} of {} µs, the host {wcrt} of {} µs ({verdict})",
        verdict.wcrt_us.get(),
        verdict.deadline_us.get(),
        us(v.deadline)
    );
    if let (Culprit::Frame { id }, amiro_can::Violation::Message { id: named }) =
        (v.culprit, verdict.violation)
    {
        ensure!(
            u32::from(named.raw()) == id,
            "the board names frames 0x{:03X}, the host 0x{id:03X}",
            named.raw()
        );
    }
    Ok(())
}

/// The reasons of the six bad publish commands a sensor board's `malformed.log` starts with (DiWheelDrive's and
/// PowerManagement's, each on its own topic): an unknown topic, a bad mode, a bad unit, too short, too long, a
/// zero sample time.
pub const MALFORMED_PUBLISH_REJECTIONS: [&str; 6] = [
    "unknown-topic",
    "bad-mode",
    "bad-unit",
    "dlc-too-short",
    "dlc-too-long",
    "zero-sample-time",
];

/// Common to every shutdown: no frame on `id` (the board's publisher) after `frames_by` µs, no command accepted
/// after `commands_by` µs, and the hand-over to the bootloader (its note).
pub fn stopped_and_handed_over(
    out: &RunOutput,
    id: u32,
    frames_by: u64,
    commands_by: u64,
) -> Result<&str> {
    let late: Vec<u64> = out
        .times(id)
        .into_iter()
        .filter(|t| *t > frames_by)
        .collect();
    ensure!(
        late.is_empty(),
        "frames {id:03X} after the shutdown started: {late:?}"
    );
    let accepted_after = out
        .traces("command-accepted")
        .iter()
        .filter_map(|l| trace_time(l).ok())
        .filter(|t| *t > commands_by)
        .count();
    ensure!(
        accepted_after == 0,
        "{accepted_after} commands accepted after the shutdown started"
    );
    out.notes
        .iter()
        .find(|n| n.starts_with("qemu: shutdown hand-over"))
        .map(String::as_str)
        .context("no hand-over to the bootloader")
}

/// Scenario admission-other-board's verdict, on PowerManagement alone (the odometry replayed) and in the whole
/// robot alike: PowerManagement's one verdict, refusing the ring at urgent for DiWheelDrive's odometry 0x701.
pub fn ring_refused_for_odometry(out: &RunOutput) -> Result<amiro_can::AdmissionVerdict> {
    use amiro_can::{Priority, Topic, Verdict, Violation};
    let verdicts = admission_verdicts(out, amiro_can::Board::PowerManagement);
    ensure!(
        verdicts.len() == 1,
        "{} verdicts from PowerManagement, expected the one refusal of the ring at urgent",
        verdicts.len()
    );
    let (_, v) = verdicts[0];
    ensure!(
        v.verdict == Verdict::Refused
            && v.topic == Topic::ProximityRing
            && v.priority == Priority::Urgent,
        "not the refusal of the ring at urgent: {v}"
    );
    ensure!(
        matches!(v.violation, Violation::Message { id } if id.raw() == 0x701),
        "the refusal names {:?}, not DiWheelDrive's odometry frames 0x701: {v}",
        v.violation
    );
    Ok(v)
}

/// The shortest time between two admission verdicts of one board the analysis charges
/// (`can_tx[admit_requests]`'s `at_least_us` in the timing files): the admission task sends every
/// verdict, a decision's or a busy one, at least 40 × 1024 µs after the one before
/// (`amiro_firmware::admission::BusyWindow`).
pub const VERDICT_SPACING_US: u64 = 39_936;

/// Checks that a board queued its admission verdicts at least [`VERDICT_SPACING_US`] apart: the QEMU build
/// notes each as it queues it (`verdict queued at_us=N`; its frames' completions may bunch on a flooded bus,
/// so the bus log does not tell). Every scenario's run is held to it; `board` names the board in the message.
pub fn verdicts_spaced(out: &RunOutput, board: &str) -> Result<()> {
    let mut times = Vec::new();
    for note in &out.notes {
        if let Some(at) = note.strip_prefix("verdict queued at_us=") {
            times.push(
                at.trim()
                    .parse::<u64>()
                    .with_context(|| format!("{board}: `{note}`"))?,
            );
        }
    }
    // Every verdict on the bus was noted as queued (the notes are the build's, not a format that went
    // silent).
    let can_board = match board {
        "diwheeldrive" => amiro_can::Board::DiWheelDrive,
        "powermgmt" => amiro_can::Board::PowerManagement,
        "lightring" => amiro_can::Board::LightRing,
        other => bail!("no CAN board for `{other}`"),
    };
    let sent = admission_verdicts(out, can_board).len();
    ensure!(
        times.len() >= sent,
        "{board}: {sent} admission verdicts on the bus, {} noted as queued",
        times.len()
    );
    if let Some(w) = times
        .windows(2)
        .find(|w| w[1].saturating_sub(w[0]) < VERDICT_SPACING_US)
    {
        bail!(
            "{board}: two admission verdicts queued {} µs apart (at {} and {} µs), closer than the {VERDICT_SPACING_US} µs the analysis charges",
            w[1].saturating_sub(w[0]),
            w[0],
            w[1]
        );
    }
    Ok(())
}

/// The admission verdicts `board` sent (pages 0x80 + 0x81 on its diagnostics topic), joined, with
/// the time of the second frame.
pub fn admission_verdicts(
    out: &RunOutput,
    board: amiro_can::Board,
) -> Vec<(u64, amiro_can::AdmissionVerdict)> {
    use amiro_can::{decode, DiagnosticsPage, Message, SensorData};
    let topic = u32::from(board.diagnostics_topic().byte());
    let mut joined = Vec::new();
    let mut request = None;
    for f in out.frames.iter().filter(|f| f.id & 0x4FF == 0x400 | topic) {
        let Ok(Message::Sample {
            data: SensorData::Diagnostics { board, page },
            ..
        }) = decode(f.id as u16, &f.data)
        else {
            continue;
        };
        match page {
            DiagnosticsPage::VerdictRequest(r) => request = Some(r),
            DiagnosticsPage::VerdictBound(b) => {
                if let Some(r) = request.take() {
                    joined.push((
                        f.at_us,
                        amiro_can::AdmissionVerdict::from_pages(board, &r, &b),
                    ));
                }
            }
            _ => {}
        }
    }
    joined
}

/// Checks `board`'s admission counters by reason (diagnostics page 2, reasons after the malformed
/// ones) and totals (page 3) against the verdicts it sent: every refusal reason's window must have
/// been heard after the last verdict, tasks counted as task deadlines, messages as message or
/// end-to-end deadlines, unnamed ones as capacity or zero period.
pub fn check_refusal_counts(out: &RunOutput, board: amiro_can::Board) -> Result<String> {
    use amiro_can::{
        decode, reason_name, Diagnostics, DiagnosticsPage, Message, RefusalReason, SensorData,
        Verdict, Violation, REJECTIONS_PER_SAMPLE,
    };
    let verdicts = admission_verdicts(out, board);
    let last_verdict = verdicts.last().map_or(0, |(t, _)| *t);
    let topic = u32::from(board.diagnostics_topic().byte());
    let mut heard = Diagnostics::ZERO;
    let mut covered = std::collections::BTreeSet::new();
    for f in out
        .frames
        .iter()
        .filter(|f| f.id & 0x4FF == 0x400 | topic && f.at_us > last_verdict)
    {
        let Ok(Message::Sample {
            data: SensorData::Diagnostics { page, .. },
            ..
        }) = decode(f.id as u16, &f.data)
        else {
            continue;
        };
        if let DiagnosticsPage::Rejections { first, .. } = page {
            covered.extend(usize::from(first)..usize::from(first) + REJECTIONS_PER_SAMPLE);
        }
        heard.absorb(&page);
    }
    for reason in RefusalReason::ALL {
        ensure!(
            covered.contains(&reason.counted_index()),
            "no diagnostics sample after the last verdict carried {}",
            reason.name()
        );
    }
    let count = |r: RefusalReason| heard.refusals[r as usize];
    let kind =
        |f: fn(&Violation) -> bool| verdicts.iter().filter(|(_, v)| f(&v.violation)).count() as u32;
    let tasks = kind(|v| matches!(v, Violation::Task { .. }));
    let messages = kind(|v| matches!(v, Violation::Message { .. }));
    let unnamed = kind(|v| matches!(v, Violation::Unknown));
    ensure!(
        count(RefusalReason::TaskDeadline) == tasks
            && count(RefusalReason::MessageDeadline) + count(RefusalReason::EndToEndDeadline)
                == messages
            && count(RefusalReason::Capacity)
                + count(RefusalReason::ZeroPeriod)
                + count(RefusalReason::Busy)
                == unnamed,
        "counted by reason {:?}, the verdicts name {tasks} tasks, {messages} messages, {unnamed} unnamed",
        heard.refusals
    );
    let refused = verdicts
        .iter()
        .filter(|(_, v)| v.verdict == Verdict::Refused)
        .count() as u32;
    let warned = verdicts.len() as u32 - refused;
    ensure!(
        heard.admission_refused == refused && heard.admission_warned == warned,
        "page 3 says {} refused / {} warned, the verdicts {refused} / {warned}",
        heard.admission_refused,
        heard.admission_warned
    );
    let named: Vec<String> = RefusalReason::ALL
        .iter()
        .filter(|r| count(**r) > 0)
        .map(|r| {
            format!(
                "{} {}",
                reason_name(r.counted_index()).unwrap_or("?"),
                count(*r)
            )
        })
        .collect();
    Ok(format!("counted by reason: {}", named.join(", ")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_queued_closer_than_the_charged_spacing_fail_the_run() {
        let run = |notes: &[&str]| RunOutput {
            frames: Vec::new(),
            notes: notes.iter().map(|n| n.to_string()).collect(),
            work: None,
        };
        let spaced = run(&[
            "verdict queued at_us=1000",
            "x",
            "verdict queued at_us=40936",
        ]);
        assert!(verdicts_spaced(&spaced, "lightring").is_ok());
        let close = run(&["verdict queued at_us=1000", "verdict queued at_us=40935"]);
        let e = verdicts_spaced(&close, "lightring")
            .unwrap_err()
            .to_string();
        assert!(e.contains("39935 µs apart"), "{e}");
        assert!(verdicts_spaced(&run(&["verdict queued at_us=x"]), "lightring").is_err());
        assert!(verdicts_spaced(&spaced, "nowhere").is_err());
    }

    /// A board's refusal without a culprit (0 µs / 0 µs) matches the host's refusal on its iteration budget or
    /// capacity, and no other; a deadline the host names must be the board's.
    #[test]
    fn a_refusal_without_a_deadline_matches_only_the_hosts_own() {
        use amiro_can::{
            AdmissionVerdict, Board, Count, Priority, SampleTime, TimeUnit, Topic, Verdict,
            Violation,
        };
        use schedule_analysis::admission::{Culprit, Decision, Refusal, Suggestion, TaskId};
        let board = AdmissionVerdict {
            board: Board::DiWheelDrive,
            topic: Topic::FloorProximity,
            requested: SampleTime {
                value: 1,
                unit: TimeUnit::Millis,
            },
            priority: Priority::Urgent,
            verdict: Verdict::Refused,
            violation: Violation::Unknown,
            wcrt_us: Count::saturating(0),
            deadline_us: Count::saturating(0),
            shortest_period: None,
            priority_needed: None,
            searched: false,
            one_shot: false,
        };
        let host = |refusal| Decision {
            refusal,
            floor: refusal,
            suggestion: Suggestion::default(),
            iterations: 0,
            evaluations: 1,
            boards: 1,
        };
        assert!(same_refusal(&board, &host(Some(Refusal::Budget))).is_ok());
        assert!(same_refusal(&board, &host(Some(Refusal::Capacity))).is_ok());
        assert!(same_refusal(&board, &host(None)).is_err());
        let deadline = Refusal::Deadline(schedule_analysis::admission::Violation {
            culprit: Culprit::Task {
                board: 0,
                task: TaskId::Fixed(5),
            },
            wcrt: Some(schedule_analysis::time::Time::from_us(55)),
            deadline: schedule_analysis::time::Time::from_us(47),
        });
        assert!(same_refusal(&board, &host(Some(deadline))).is_err());
        let named = AdmissionVerdict {
            violation: Violation::Task { index: 5 },
            wcrt_us: Count::saturating(55),
            deadline_us: Count::saturating(47),
            ..board
        };
        assert!(same_refusal(&named, &host(Some(deadline))).is_ok());
        assert!(same_refusal(&named, &host(Some(Refusal::Budget))).is_err());
    }

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
        let drift: &[&str] = &[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "(0.001020) can0 608#00",
            "# (0.002001) trace sample-taken gyroscope release=0.002001",
            "(0.002005) can0 608#00",
        ];
        let skipped: &[&str] = &[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "(0.001020) can0 608#00",
        ];
        let no_frame: &[&str] = &[
            "# (0.001000) trace sample-taken gyroscope release=0.001000",
            "# (0.002000) trace sample-taken gyroscope release=0.002000",
            "(0.002005) can0 608#00",
        ];
        for (case, lines) in [
            ("drift", drift),
            ("skipped", skipped),
            ("no frame", no_frame),
        ] {
            assert!(
                run(lines)
                    .periodic_stream(0x608, "gyroscope", 1_000, 0, 3_000)
                    .is_err(),
                "{case}"
            );
        }
    }

    #[test]
    fn reads_the_end_of_run_line() {
        let out = run(&["# qemu: end of run at 5 us; rx dropped 0; ram static 5040 stack 2056"]);
        assert_eq!(out.ram_used().unwrap(), (5040, 2056));
        assert!(run(&["(0.000001) can0 608#00"]).ram_used().is_err());
    }

    /// Every timing file models the command handler at the firmware's one interval
    /// (`amiro_firmware::admission::COMMAND_MIN_INTERVAL_US`): released at most once per interval, done within it.
    #[test]
    fn every_timing_file_models_the_command_interval() {
        use amiro_firmware::admission::COMMAND_MIN_INTERVAL_US;
        let models = crate::workspace::workspace_root().join("schedule-analysis/models");
        let mut files: Vec<std::path::PathBuf> = Vec::new();
        for dir in std::iter::once(models.clone()).chain(
            std::fs::read_dir(&models)
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.is_dir()),
        ) {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.to_string_lossy().ends_with(".timing.json") {
                    files.push(path);
                }
            }
        }
        assert!(files.len() >= 5, "timing files: {files:?}");
        for path in files {
            let json: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            let handler = &json["tasks"]["handle_commands"];
            for field in [&handler["arrival"]["sporadic_us"], &handler["deadline_us"]] {
                assert_eq!(
                    field.as_u64(),
                    Some(COMMAND_MIN_INTERVAL_US),
                    "{}",
                    path.display()
                );
            }
        }
    }
}
