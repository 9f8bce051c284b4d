//! From trace bytes to runs and samples: decodes `amiro_trace` records (a raw RTT capture, or the
//! `# T` lines of a QEMU run), rebuilds every task run with its pre-emptions and its release, and
//! follows every sample from its release to its frames in the queue and on the bus.
use std::collections::BTreeMap;

use amiro_sensors::trace::{TraceEvent, TraceKind};
use amiro_trace::{Kind, Reader, ReaderStats, Record};
use anyhow::{Context, Result};

/// Where the release of a run came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReleaseFrom {
    /// The timer release the task's previous run announced (exact).
    Timer,
    /// The run's own start (interrupts, message wake-ups): the time before the first instruction
    /// is not seen, so the response is a lower bound.
    Start,
}

/// One run of a task: from its start (or resumption) to its end (or suspension).
#[derive(Debug, Clone, Copy)]
pub struct Run {
    /// Task number.
    pub task: u8,
    /// Release, start and end, ns of the trace clock.
    pub release_ns: u64,
    /// Start.
    pub start_ns: u64,
    /// End.
    pub end_ns: u64,
    /// Time spent in runs that pre-empted it, ns.
    pub preempted_ns: u64,
    /// Traced runs that pre-empted it directly (each ran part of its records outside its own stamps,
    /// inside this run: docs/bench.md, "A pre-empting run's unstamped part").
    pub preemptions: u32,
    /// The tasks of those runs, one bit per task number (below 32).
    pub preempted_by: u32,
    /// How many of those runs each task had, by task number (below 32): a hardware task's run and a dispatched
    /// one leave different unstamped parts inside this run (docs/bench.md, "A pre-empting run's unstamped part").
    pub preempted_runs: [u16; 32],
    /// Handler events stamped while this run was the innermost (its own, not a pre-empting run's): in QEMU each
    /// is encoded and written to the console inside the run (`amiro_firmware::tracing::event`), which the release
    /// image does not do.
    pub events: u32,
    /// Of [`Run::preemptions`], the runs of the QEMU platform clock's interrupt
    /// ([`amiro_trace::PLATFORM_CLOCK_TASK`]: SysTick's busy ticks in a single-board run, stamped in the run's
    /// `clock.bin`; docs/bench.md, "The QEMU tick"). 0 for a robot capture.
    pub clock_preemptions: u32,
    /// QEMU only: the platform's plain ticks (unstamped: `amiro_firmware::qemu::timer`'s SysTick, every
    /// [`QEMU_TICK_US`], when it checks no queue) that surely ran inside this run while it was the innermost: per
    /// stretch in which it ran innermost, the tick boundaries in it less one (the last one's interrupt may be taken
    /// after the stretch ends, once a critical section lets it; a busy tick, stamped, ends the stretch it falls in).
    /// 0 for a robot capture.
    pub ticks: u32,
    /// QEMU only: the stretches (as for [`Run::ticks`]) that held a tick boundary whose tick was not counted
    /// (the last one's): each may have run inside this run, a plain tick the bench did not take off.
    pub uncounted_ticks: u32,
    /// Where the release came from.
    pub release_from: ReleaseFrom,
}

/// The QEMU build's tick, µs (`amiro_firmware::qemu::TICK_US`): a single-board run's SysTick interrupts every
/// tick, inside whatever runs; its plain ticks are not stamped.
pub const QEMU_TICK_US: u64 = 10;

impl Run {
    /// Execution time (pre-emptions taken out), ns.
    pub fn execution_ns(&self) -> u64 {
        self.end_ns
            .saturating_sub(self.start_ns)
            .saturating_sub(self.preempted_ns)
    }

    /// Response time from the release, ns (everything that pre-empted it included: in QEMU the
    /// stimulus replay too, which the QEMU model has as a task of its own).
    pub fn response_ns(&self) -> u64 {
        self.end_ns.saturating_sub(self.release_ns)
    }
}

/// One sample of a topic: released, taken, its frames queued and acknowledged.
#[derive(Debug, Clone)]
pub struct Sample {
    /// The topic.
    pub topic: amiro_can::Topic,
    /// CAN priority level of its frames (0 urgent … 3 low), once a frame was queued.
    pub level: Option<u8>,
    /// Release (ns), and when the sample was taken.
    pub release_ns: u64,
    /// Taken.
    pub taken_ns: u64,
    /// The last of its frames entered the transmit queue.
    pub queued_ns: Option<u64>,
    /// The last of its frames was acknowledged on the bus.
    pub acked_ns: Option<u64>,
    frames_queued: u32,
    frames_acked: u32,
}

/// Everything read from one capture.
#[derive(Debug, Default)]
pub struct Capture {
    /// The trace clock (from the boot record, else the default given).
    pub clock_hz: u64,
    /// Runs in the order they ended.
    pub runs: Vec<Run>,
    /// Samples in release order.
    pub samples: Vec<Sample>,
    /// Frames acknowledged on the bus: identifier and time (ns).
    pub acked: Vec<(u16, u64)>,
    /// Handler events with their record times (ns).
    pub events: Vec<(u64, TraceEvent)>,
    /// Reader counts (records, damaged stretches, skipped bytes).
    pub reader: ReaderStats,
    /// Records the board reported lost (channel full).
    pub lost: u64,
    /// Ends that did not match the running task (a damaged or lossy stream): the run stack was reset.
    pub unbalanced: u64,
    /// Time of the last record, ns.
    pub end_ns: u64,
    /// A QEMU run's received frames, as its stimulus replays them: the shortest time between two of them, µs
    /// (the whole run when it has fewer than two). `None`: not known (a capture from a robot).
    pub received_gap_us: Option<f64>,
    /// A QEMU run's admission verdicts (diagnostics pages 0x80 and 0x81): the topics whose last verdict was
    /// "accepted with a warning" (policy accept-and-warn), for which the board promised nothing.
    pub warned: Vec<amiro_can::Topic>,
}

impl Capture {
    /// The runs of each release of the topic whose row is `row` (`publisher[<topic>]`): per sample taken of it, the
    /// runs of the task that took it (the innermost run at its `SampleTaken` event) from the one running at the
    /// release's instant, or the first to start after it, to the one that took it (docs/analysis.md, "A suspending
    /// release: the sum of its polls"), but none before the run that took the task's previous sample (of any
    /// topic): two topics of one task due together are taken one after the other, and the second's release owns
    /// only the runs after the first was taken. A run that ended one release and took the next is in both.
    pub fn release_runs(&self, row: &str) -> Vec<Vec<&Run>> {
        let Some(topic) = row
            .strip_prefix("publisher[")
            .and_then(|t| t.strip_suffix(']'))
        else {
            return Vec::new();
        };
        let took = |s: &Sample| {
            self.runs
                .iter()
                .filter(|r| r.start_ns <= s.taken_ns && s.taken_ns <= r.end_ns)
                .min_by_key(|r| r.end_ns - r.start_ns)
        };
        self.samples
            .iter()
            .filter(|s| s.topic.name() == topic)
            .filter_map(|s| {
                let took_it = took(s)?;
                // The task's sample taken last before this one, by the run that took it.
                let after = self
                    .samples
                    .iter()
                    .filter(|o| o.taken_ns < s.taken_ns)
                    .filter_map(|o| took(o).filter(|r| r.task == took_it.task))
                    .map(|r| r.start_ns)
                    .max()
                    .unwrap_or(0);
                Some(
                    self.runs
                        .iter()
                        .filter(|r| r.task == took_it.task)
                        .filter(|r| r.end_ns >= s.release_ns && r.start_ns >= after)
                        .filter(|r| r.start_ns <= took_it.start_ns)
                        .collect(),
                )
            })
            .collect()
    }
}

/// Builds a [`Capture`] from records, events and acknowledgements in time order.
struct Builder {
    capture: Capture,
    hz: u64,
    base_cycles: u64,
    base_ns: u64,
    stack: Vec<Open>,
    /// QEMU: the tick in trace-clock cycles (ticks are counted), and since when the innermost open run runs.
    tick_cycles: Option<u64>,
    top_since: u64,
    next_release: BTreeMap<u8, u64>,
    open_samples: BTreeMap<u8, usize>,
}

struct Open {
    task: u8,
    start_ns: u64,
    release_ns: u64,
    release_from: ReleaseFrom,
    preempted_ns: u64,
    preemptions: u32,
    preempted_by: u32,
    preempted_runs: [u16; 32],
    events: u32,
    clock_preemptions: u32,
    ticks: u32,
    uncounted_ticks: u32,
}

impl Builder {
    fn new(default_hz: u64) -> Self {
        Self {
            capture: Capture {
                clock_hz: default_hz,
                ..Capture::default()
            },
            hz: default_hz.max(1),
            base_cycles: 0,
            base_ns: 0,
            stack: Vec::new(),
            tick_cycles: None,
            top_since: 0,
            next_release: BTreeMap::new(),
            open_samples: BTreeMap::new(),
        }
    }

    /// Cycles to ns with the clock in force (a later boot record changes it from there on).
    fn ns(&self, cycles: u64) -> u64 {
        self.base_ns
            + (u128::from(cycles.saturating_sub(self.base_cycles)) * 1_000_000_000
                / u128::from(self.hz)) as u64
    }

    /// QEMU: the ticks that surely ran inside the innermost open run from `top_since` to `cycles` (the tick
    /// boundaries after the first less one), counted to it; the next stretch starts at `cycles`.
    fn close_stretch(&mut self, cycles: u64) {
        if let (Some(tick), Some(top)) =
            (self.tick_cycles.filter(|t| *t > 0), self.stack.last_mut())
        {
            let boundaries = (cycles / tick).saturating_sub(self.top_since / tick);
            top.ticks += u32::try_from(boundaries.saturating_sub(1)).unwrap_or(u32::MAX);
            top.uncounted_ticks += u32::from(boundaries > 0);
        }
        self.top_since = cycles;
    }

    fn record(&mut self, record: Record) {
        let t = self.ns(record.cycles);
        if matches!(record.kind, Kind::TaskStart { .. } | Kind::TaskEnd { .. }) {
            self.close_stretch(record.cycles);
        }
        self.capture.end_ns = self.capture.end_ns.max(t);
        match record.kind {
            Kind::Hello { clock_hz } => {
                if clock_hz > 0 {
                    if self.tick_cycles.is_some() {
                        self.tick_cycles = Some(u64::from(clock_hz) * QEMU_TICK_US / 1_000_000);
                    }
                    self.base_ns = t;
                    self.base_cycles = record.cycles;
                    self.hz = u64::from(clock_hz);
                    self.capture.clock_hz = self.hz;
                }
            }
            Kind::TaskStart { task } => {
                let (release_ns, release_from) = match self.next_release.remove(&task) {
                    Some(r) if r <= t => (r, ReleaseFrom::Timer),
                    _ => (t, ReleaseFrom::Start),
                };
                self.stack.push(Open {
                    task,
                    start_ns: t,
                    release_ns,
                    release_from,
                    preempted_ns: 0,
                    preemptions: 0,
                    preempted_by: 0,
                    preempted_runs: [0; 32],
                    events: 0,
                    clock_preemptions: 0,
                    ticks: 0,
                    uncounted_ticks: 0,
                });
            }
            Kind::TaskEnd {
                task,
                next_release_in_us,
            } => {
                match self.stack.pop() {
                    Some(open) if open.task == task => {
                        let took = t.saturating_sub(open.start_ns);
                        if let Some(parent) = self.stack.last_mut() {
                            parent.preempted_ns += took;
                            parent.preemptions += 1;
                            if task == amiro_trace::PLATFORM_CLOCK_TASK {
                                parent.clock_preemptions += 1;
                            }
                            parent.preempted_by |= 1u32.checked_shl(u32::from(task)).unwrap_or(0);
                            if let Some(n) = parent.preempted_runs.get_mut(usize::from(task)) {
                                *n = n.saturating_add(1);
                            }
                        }
                        self.capture.runs.push(Run {
                            task,
                            release_ns: open.release_ns,
                            start_ns: open.start_ns,
                            end_ns: t,
                            preempted_ns: open.preempted_ns,
                            preemptions: open.preemptions,
                            preempted_by: open.preempted_by,
                            preempted_runs: open.preempted_runs,
                            events: open.events,
                            clock_preemptions: open.clock_preemptions,
                            ticks: open.ticks,
                            uncounted_ticks: open.uncounted_ticks,
                            release_from: open.release_from,
                        });
                    }
                    _ => {
                        self.capture.unbalanced += 1;
                        self.stack.clear();
                    }
                }
                if next_release_in_us != u32::MAX {
                    self.next_release
                        .insert(task, t + u64::from(next_release_in_us) * 1_000);
                }
            }
            Kind::Event { record } => {
                if let Ok(event) = TraceEvent::decode(&record) {
                    self.event(t, event);
                }
            }
            Kind::FrameAcked { id } => self.acked(id, t),
            Kind::Lost { count } => self.capture.lost += u64::from(count),
        }
    }

    fn event(&mut self, t: u64, event: TraceEvent) {
        self.capture.end_ns = self.capture.end_ns.max(t);
        self.capture.events.push((t, event));
        if let Some(open) = self.stack.last_mut() {
            open.events += 1;
        }
        match event.kind {
            TraceKind::SampleTaken { topic, release_us } => {
                let behind = event.at_us.saturating_sub(release_us) * 1_000;
                self.open_samples
                    .insert(topic.byte(), self.capture.samples.len());
                self.capture.samples.push(Sample {
                    topic,
                    level: None,
                    release_ns: t.saturating_sub(behind),
                    taken_ns: t,
                    queued_ns: None,
                    acked_ns: None,
                    frames_queued: 0,
                    frames_acked: 0,
                });
            }
            TraceKind::FrameQueued { id } | TraceKind::FrameReplaced { id } => {
                if let Some(&i) = self.open_samples.get(&((id & 0xFF) as u8)) {
                    let s = &mut self.capture.samples[i];
                    // A sample has its topic's frames; a frame beyond them on the same identifier is not the
                    // sample's: an admission verdict on the board's diagnostics topic (two frames after a
                    // refusal or a warning, queued by the admission task whenever it decides).
                    if s.frames_queued >= u32::from(s.topic.frames_per_sample()) {
                        return;
                    }
                    s.level = Some(((id >> 8) & 3) as u8);
                    s.queued_ns = Some(t);
                    s.frames_queued += 1;
                }
            }
            _ => {}
        }
    }

    fn acked(&mut self, id: u16, t: u64) {
        self.capture.end_ns = self.capture.end_ns.max(t);
        self.capture.acked.push((id, t));
        // The oldest sample of this topic with frames still unacknowledged (sensor data only).
        let topic = (id & 0xFF) as u8;
        if let Some(s) =
            self.capture.samples.iter_mut().find(|s| {
                id >= 0x400 && s.topic.byte() == topic && s.frames_acked < s.frames_queued
            })
        {
            s.frames_acked += 1;
            if s.frames_acked == s.frames_queued {
                s.acked_ns = Some(t);
            }
        }
    }
}

/// A capture of the trace channel read as it arrives (the live bench): bytes in any chunks, the
/// capture so far at any time. Fed the same bytes, it ends where [`read`] does.
pub struct Stream {
    reader: Reader,
    builder: Builder,
    bytes: u64,
}

impl Stream {
    /// A stream on the trace clock `default_hz` unless a boot record says otherwise.
    pub fn new(default_hz: u64) -> Self {
        Self {
            reader: Reader::new(),
            builder: Builder::new(default_hz),
            bytes: 0,
        }
    }

    /// Takes the next bytes of the channel.
    pub fn push(&mut self, bytes: &[u8]) {
        self.bytes += bytes.len() as u64;
        for &b in bytes {
            if let Some(record) = self.reader.push(b) {
                self.builder.record(record);
            }
        }
    }

    /// Bytes taken so far.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The capture so far.
    pub fn capture(&mut self) -> &Capture {
        self.builder.capture.reader = self.reader.stats();
        &self.builder.capture
    }

    /// The whole capture.
    pub fn finish(mut self) -> Capture {
        self.builder.capture.reader = self.reader.stats();
        self.builder.capture
    }
}

/// Reads a capture of the trace channel (robot): `bytes` as captured, the trace clock
/// `default_hz` unless the capture's boot record says otherwise.
pub fn read(bytes: &[u8], default_hz: u64) -> Result<Capture> {
    let mut stream = Stream::new(default_hz);
    stream.push(bytes);
    Ok(stream.finish())
}

pub use amiro_robot::log::console_record_bytes;

/// Reads a QEMU run: the task records from its `trace.bin`, the handler events from the `# T`
/// lines of its console `text` (records in the same format, on the same clock, merged in time
/// order), and the frames on QEMU's virtual bus, acknowledged when printed (µs).
#[cfg(test)]
pub fn read_qemu(trace_bin: &[u8], text: &str, default_hz: u64) -> Result<Capture> {
    read_qemu_clocked(trace_bin, &[], text, default_hz)
}

/// `read_qemu`, with the platform clock's stamps (`clock.bin`, [`amiro_trace::clock_run`]): each activation of
/// its interrupt a run of [`amiro_trace::PLATFORM_CLOCK_TASK`], which pre-empts whatever ran.
pub fn read_qemu_clocked(
    trace_bin: &[u8],
    clock_bin: &[u8],
    text: &str,
    default_hz: u64,
) -> Result<Capture> {
    let mut reader = Reader::new();
    let mut records: Vec<Record> = trace_bin.iter().filter_map(|&b| reader.push(b)).collect();
    let mut console = Reader::new();
    records.extend(
        console_record_bytes(text)
            .iter()
            .filter_map(|&b| console.push(b)),
    );
    let task = amiro_trace::PLATFORM_CLOCK_TASK;
    for (start, end) in amiro_trace::clock_run::decode(clock_bin) {
        records.push(Record {
            cycles: start,
            kind: Kind::TaskStart { task },
        });
        records.push(Record {
            cycles: end,
            kind: Kind::TaskEnd {
                task,
                next_release_in_us: u32::MAX,
            },
        });
    }
    // A stable sort: records of one stream stay in their order.
    records.sort_by_key(|r| r.cycles);
    let mut builder = Builder::new(default_hz);
    builder.tick_cycles = Some(default_hz * QEMU_TICK_US / 1_000_000);
    for record in records {
        builder.record(record);
    }
    let (a, b) = (reader.stats(), console.stats());
    builder.capture.reader = ReaderStats {
        records: a.records + b.records,
        damaged: a.damaged + b.damaged,
        skipped_bytes: a.skipped_bytes + b.skipped_bytes,
    };
    for line in text.lines() {
        if let Ok(Some(frame)) = crate::qemu::parse_log_line(line) {
            if let Ok(id) = u16::try_from(frame.id) {
                builder.acked(id, frame.at_us * 1_000);
            }
        }
    }
    builder.capture.warned = warned_topics(text)?;
    Ok(builder.capture)
}

/// The topics whose last admission verdict in a QEMU run's output was "accepted with a warning" (a single-board
/// run's verdict frames are its board's own; a later refusal of the same topic changed nothing it runs, so only the
/// last verdict of a topic counts).
fn warned_topics(text: &str) -> Result<Vec<amiro_can::Topic>> {
    let out = crate::scenarios::RunOutput::parse(text)?;
    let mut verdicts: Vec<(u64, amiro_can::AdmissionVerdict)> = [
        amiro_can::Board::DiWheelDrive,
        amiro_can::Board::PowerManagement,
        amiro_can::Board::LightRing,
    ]
    .into_iter()
    .flat_map(|board| crate::scenarios::admission_verdicts(&out, board))
    .collect();
    verdicts.sort_by_key(|(at, _)| *at);
    let mut last: BTreeMap<u8, amiro_can::Verdict> = BTreeMap::new();
    for (_, v) in &verdicts {
        last.insert(v.topic.byte(), v.verdict);
    }
    Ok(last
        .into_iter()
        .filter(|(_, v)| *v == amiro_can::Verdict::AcceptedWithWarning)
        .filter_map(|(t, _)| amiro_can::Topic::from_byte(t))
        .collect())
}

/// Reads a QEMU run's work directory (`output.log` and `trace.bin`).
pub fn read_qemu_dir(dir: &std::path::Path, default_hz: u64) -> Result<Capture> {
    let text = std::fs::read_to_string(dir.join("output.log"))
        .with_context(|| format!("reading {}", dir.join("output.log").display()))?;
    let bin = std::fs::read(dir.join("trace.bin")).with_context(|| {
        format!(
            "reading {} (a QEMU build without task-trace?)",
            dir.join("trace.bin").display()
        )
    })?;
    // The platform clock's stamps (a single-board run since 2026-12-03), as its runs.
    let clock = match std::fs::read(dir.join("clock.bin")) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => {
            return Err(e).with_context(|| format!("reading {}", dir.join("clock.bin").display()))
        }
    };
    let mut capture = read_qemu_clocked(&bin, &clock, &text, default_hz)?;
    // The stimulus the run replayed (its only received frames), when the directory keeps it.
    if let Ok(stimulus) = std::fs::read(dir.join("stimulus.bin")) {
        capture.received_gap_us = Some(
            crate::qemu::received_gap_us(&stimulus)
                .with_context(|| format!("reading {}", dir.join("stimulus.bin").display()))?
                as f64,
        );
    }
    Ok(capture)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's output with one admission verdict of PowerManagement's (its two diagnostics pages as candump lines).
    fn verdict_output(verdict: amiro_can::Verdict, at_us: u64) -> String {
        use amiro_can::{
            AdmissionVerdict, Board, Count, Priority, SampleTime, SensorData, TimeUnit, Topic,
            Violation,
        };
        let v = AdmissionVerdict {
            board: Board::PowerManagement,
            topic: Topic::PowerStatus,
            requested: SampleTime {
                value: 20,
                unit: TimeUnit::Millis,
            },
            priority: Priority::Medium,
            verdict,
            violation: Violation::Unknown,
            wcrt_us: Count::saturating(6_090),
            deadline_us: Count::saturating(6_000),
            shortest_period: None,
            priority_needed: None,
            searched: false,
            one_shot: false,
        };
        v.pages()
            .iter()
            .enumerate()
            .map(|(i, &page)| {
                let frame = SensorData::Diagnostics {
                    board: Board::PowerManagement,
                    page,
                }
                .encode(Priority::Low);
                let data: String = frame.data().iter().map(|b| format!("{b:02X}")).collect();
                format!(
                    "(0.{:06}) can0 {:03X}#{data}",
                    at_us + i as u64,
                    frame.id().raw()
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    #[test]
    fn a_run_whose_board_warned_is_told_from_one_that_refused() {
        use amiro_can::{Topic, Verdict};
        let warned = verdict_output(Verdict::AcceptedWithWarning, 1_000);
        assert_eq!(warned_topics(&warned).unwrap(), vec![Topic::PowerStatus]);
        let refused = verdict_output(Verdict::Refused, 1_000);
        assert!(warned_topics(&refused).unwrap().is_empty());
        assert!(warned_topics("(0.001000) can0 608#000000000000")
            .unwrap()
            .is_empty());
        // Only a topic's last verdict counts.
        let then_refused = format!("{warned}\n{}", verdict_output(Verdict::Refused, 2_000));
        assert!(warned_topics(&then_refused).unwrap().is_empty());
    }

    fn wire(records: &[(u64, Kind)]) -> Vec<u8> {
        records
            .iter()
            .flat_map(|&(cycles, kind)| Record { cycles, kind }.encode().as_bytes().to_vec())
            .collect()
    }

    /// The capture's first record: the board's trace clock.
    fn hello(clock_hz: u32) -> (u64, Kind) {
        (0, Kind::Hello { clock_hz })
    }

    /// A handler event recorded at `at` (cycles, and the event's µs on a 1 MHz clock).
    fn event(at: u64, kind: TraceKind) -> (u64, Kind) {
        let record = TraceEvent::new(at, kind).encode();
        (at, Kind::Event { record })
    }

    /// Magnetometer-x's sample, released at `release_us`.
    fn magnetometer_taken(release_us: u64) -> TraceKind {
        TraceKind::SampleTaken {
            topic: amiro_can::Topic::MagnetometerX,
            release_us,
        }
    }

    #[test]
    fn runs_with_preemption_and_timer_releases() {
        // 1 MHz clock: one cycle per µs.
        let bytes = wire(&[
            hello(1_000_000),
            (10, Kind::TaskStart { task: 4 }),
            (20, Kind::TaskStart { task: 0 }),
            (
                25,
                Kind::TaskEnd {
                    task: 0,
                    next_release_in_us: u32::MAX,
                },
            ),
            (
                40,
                Kind::TaskEnd {
                    task: 4,
                    next_release_in_us: 1_000,
                },
            ),
            (1_050, Kind::TaskStart { task: 4 }),
            (
                1_070,
                Kind::TaskEnd {
                    task: 4,
                    next_release_in_us: u32::MAX,
                },
            ),
        ]);
        let c = read(&bytes, 72_000_000).unwrap();
        assert_eq!(c.clock_hz, 1_000_000);
        assert_eq!(c.runs.len(), 3);
        let isr = c.runs[0];
        assert_eq!(
            (isr.task, isr.execution_ns(), isr.response_ns()),
            (0, 5_000, 5_000)
        );
        let first = c.runs[1];
        assert_eq!(first.execution_ns(), 25_000);
        assert_eq!(first.release_from, ReleaseFrom::Start);
        // The receive interrupt pre-empted it once; nothing pre-empted the interrupt or the next run.
        assert_eq!((isr.preemptions, first.preemptions), (0, 1));
        assert_eq!((first.preempted_runs[0], first.preempted_runs[4]), (1, 0));
        let second = c.runs[2];
        assert_eq!(second.release_from, ReleaseFrom::Timer);
        // Due at 40 + 1000 µs, done at 1070 µs.
        assert_eq!(second.response_ns(), 30_000);
        assert_eq!(c.unbalanced, 0);
    }

    #[test]
    fn the_clocks_busy_ticks_pre_empt_and_plain_ticks_are_counted_per_stretch() {
        // 1.2 MHz: one tick (10 µs) is 12 cycles. Task 3 runs from cycle 10 to 100; the clock's busy tick
        // (clock.bin) from 40 to 46 inside it.
        let bin = wire(&[
            hello(1_200_000),
            (10, Kind::TaskStart { task: 3 }),
            (
                100,
                Kind::TaskEnd {
                    task: 3,
                    next_release_in_us: u32::MAX,
                },
            ),
        ]);
        let clock = amiro_trace::clock_run::encode(40, 46);
        let c = read_qemu_clocked(&bin, &clock, "", 1_200_000).unwrap();
        let (tick, job) = (c.runs[0], c.runs[1]);
        assert_eq!(tick.task, amiro_trace::PLATFORM_CLOCK_TASK);
        assert_eq!(
            (job.preemptions, job.clock_preemptions, job.preempted_by),
            (1, 1, 0)
        );
        // 90 cycles less the tick's 6: 84 cycles = 70 µs.
        assert_eq!(job.execution_ns(), 70_000);
        // Stretch 10..40 holds the boundaries 12, 24, 36: two surely inside (36's may come after 40); stretch
        // 46..100 holds 48, 60, 72, 84, 96: four. The busy tick itself is a run, not a plain tick.
        assert_eq!((job.ticks, job.uncounted_ticks), (6, 2));
        // Without clock.bin (a robot capture's format, or an older run) the same span is the job's own.
        let plain = read_qemu_clocked(&bin, &[], "", 1_200_000).unwrap();
        assert_eq!((plain.runs.len(), plain.runs[0].clock_preemptions), (1, 0));
    }

    #[test]
    fn a_suspending_releases_runs_are_those_from_its_instant_to_the_one_that_took_it() {
        // 1 MHz clock. The publisher (task 4) takes magnetometer-x's release of 1 000 µs at 1 002 and suspends on
        // its script (run 1 002–1 010), resumes after it (1 100–1 110, a pre-empting run of task 0 inside) and
        // after its second (1 200–1 215), where it traces the sample; an earlier run (900–950) is the release
        // before's, and the next release (2 000) takes the runs from 2 001.
        let start = |at, task| (at, Kind::TaskStart { task });
        let end = |at, task| {
            (
                at,
                Kind::TaskEnd {
                    task,
                    next_release_in_us: u32::MAX,
                },
            )
        };
        let bytes = wire(&[
            hello(1_000_000),
            start(900, 4),
            end(950, 4),
            start(1_002, 4),
            end(1_010, 4),
            start(1_100, 4),
            start(1_104, 0),
            end(1_106, 0),
            end(1_110, 4),
            start(1_200, 4),
            event(1_212, magnetometer_taken(1_000)),
            end(1_215, 4),
            start(2_001, 4),
            event(2_005, magnetometer_taken(2_000)),
            end(2_009, 4),
        ]);
        let c = read(&bytes, 1).unwrap();
        let releases = c.release_runs("publisher[magnetometer-x]");
        let spans: Vec<Vec<(u64, u64)>> = releases
            .iter()
            .map(|runs| {
                runs.iter()
                    .map(|r| (r.start_ns / 1_000, r.end_ns / 1_000))
                    .collect()
            })
            .collect();
        assert_eq!(
            spans,
            [
                vec![(1_002, 1_010), (1_100, 1_110), (1_200, 1_215)],
                vec![(2_001, 2_009)]
            ]
        );
        // Another topic's row, or no publisher row: none.
        assert!(c.release_runs("publisher[gyroscope]").is_empty());
        assert!(c.release_runs("can_rx").is_empty());
    }

    #[test]
    fn a_release_due_with_another_topics_of_its_task_owns_only_the_runs_after_that_ones_take() {
        // 1 MHz clock. Task 4 publishes magnetometer-x and magnetometer-y, both due at 1 000: it takes x's release
        // first (scripts: runs 1 002–1 010 and 1 100–1 110, x taken at 1 108), then y's (1 108 run's rest, then
        // 1 200–1 215, y taken at 1 212). y's release owns the run that took x (it went on to start y) and its own,
        // not x's first run; x's owns its two.
        let start = |at, task| (at, Kind::TaskStart { task });
        let end = |at, task| {
            (
                at,
                Kind::TaskEnd {
                    task,
                    next_release_in_us: u32::MAX,
                },
            )
        };
        let taken = |topic, release_us| TraceKind::SampleTaken { topic, release_us };
        let bytes = wire(&[
            hello(1_000_000),
            start(1_002, 4),
            end(1_010, 4),
            start(1_100, 4),
            event(1_108, taken(amiro_can::Topic::MagnetometerX, 1_000)),
            end(1_110, 4),
            start(1_200, 4),
            event(1_212, taken(amiro_can::Topic::MagnetometerY, 1_000)),
            end(1_215, 4),
        ]);
        let c = read(&bytes, 1).unwrap();
        let spans = |row| -> Vec<Vec<(u64, u64)>> {
            c.release_runs(row)
                .iter()
                .map(|runs| {
                    runs.iter()
                        .map(|r| (r.start_ns / 1_000, r.end_ns / 1_000))
                        .collect()
                })
                .collect()
        };
        assert_eq!(
            spans("publisher[magnetometer-x]"),
            [vec![(1_002, 1_010), (1_100, 1_110)]]
        );
        assert_eq!(
            spans("publisher[magnetometer-y]"),
            [vec![(1_100, 1_110), (1_200, 1_215)]]
        );
    }

    #[test]
    fn samples_from_release_to_the_bus() {
        let bytes = wire(&[
            hello(1_000_000),
            event(1_010, magnetometer_taken(1_000)),
            event(1_020, TraceKind::FrameQueued { id: 0x605 }),
            (1_150, Kind::FrameAcked { id: 0x605 }),
        ]);
        let c = read(&bytes, 1).unwrap();
        let s = &c.samples[0];
        assert_eq!(s.release_ns, 1_000_000);
        assert_eq!(s.queued_ns, Some(1_020_000));
        assert_eq!(s.acked_ns, Some(1_150_000));
        assert_eq!(s.level, Some(2));
    }

    #[test]
    fn a_verdict_on_the_topic_is_not_the_samples_frame() {
        // Magnetometer-x has one frame per sample; a second frame on 0x605 later (as an admission verdict on a
        // diagnostics topic is) does not move the sample's queued time.
        let bytes = wire(&[
            hello(1_000_000),
            event(1_010, magnetometer_taken(1_000)),
            event(1_020, TraceKind::FrameQueued { id: 0x605 }),
            event(270_000, TraceKind::FrameQueued { id: 0x605 }),
        ]);
        let c = read(&bytes, 1).unwrap();
        let s = &c.samples[0];
        assert_eq!((s.queued_ns, s.frames_queued), (Some(1_020_000), 1));
    }

    #[test]
    fn qemu_runs_events_from_console_records_and_frames_as_acknowledgements() {
        let bin = wire(&[
            hello(120_000_000),
            (1_200_000, Kind::TaskStart { task: 7 }),
            (
                1_212_000,
                Kind::TaskEnd {
                    task: 7,
                    next_release_in_us: 890,
                },
            ),
        ]);
        let taken = TraceEvent::new(10_000, magnetometer_taken(10_000));
        let queued = TraceEvent::new(10_050, TraceKind::FrameQueued { id: 0x605 });
        let line = |cycles: u64, e: &TraceEvent| {
            let w = Record {
                cycles,
                kind: Kind::Event { record: e.encode() },
            }
            .encode();
            let hex: String = w.as_bytes()[..w.as_bytes().len() - 1]
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            format!("# T {hex}\n")
        };
        let text = format!(
            "{}{}(0.010090) can0 605#204E0000\n# T 7a7a\n# qemu: something else\n",
            line(1_200_000, &taken),
            line(1_206_000, &queued)
        );
        let c = read_qemu(&bin, &text, 120_000_000).unwrap();
        assert_eq!(c.runs.len(), 1);
        assert_eq!(c.runs[0].execution_ns(), 100_000);
        assert_eq!(c.reader.damaged, 1);
        let s = &c.samples[0];
        assert_eq!(
            (s.release_ns, s.queued_ns, s.acked_ns),
            (10_000_000, Some(10_050_000), Some(10_090_000))
        );
    }
}
