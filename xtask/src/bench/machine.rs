//! Observed execution against the machine-code bounds: per task with a bound in the board's generated bounds
//! file (`schedule-analysis/models/<board>[-<rev>].wcet.json`), the largest execution observed beside the
//! bound, in instructions for a QEMU run (QEMU under `-icount` executes one instruction per 8 ns of virtual time)
//! or in cycles for a robot capture (the DWT cycle counter is the trace clock), and their ratio.
//!
//! The bounds are the release image's; the measured build is the traced one. A run's measured execution holds the
//! task trace's records (its start and end records, docs/bench.md), which the release image does not execute:
//! they are accounted for explicitly (in QEMU at the fewest instructions they run, [`QEMU_RECORDS_FEWEST_INSTRUCTIONS`];
//! on the chip the timing file's `trace.per_job_us`), subtracted from the observation before it is held to the
//! bound. In QEMU, so is what each traced run that pre-empted the job executed inside it outside its own stamps —
//! its interrupt's handler or dispatcher up to its start record's clock read, and from its end record's clock
//! read to the exception return — at the fewest instructions that takes, counted from the traced images
//! ([`QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS`], [`QEMU_PREEMPTION_BY_DISPATCHER_FEWEST_INSTRUCTIONS`];
//! docs/bench.md, "A pre-empting run's unstamped part"), once per direct pre-emption. The QEMU platform clock's
//! busy ticks (a single-board run's SysTick stays periodic; a tick that checks a timer queue stamps itself in
//! `clock.bin`) are such runs ([`QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS`]); its plain ticks, unstamped, are
//! counted where they surely fell inside the job and taken off at their fewest ([`QEMU_TICK_FEWEST_INSTRUCTIONS`];
//! docs/bench.md, "The QEMU tick"). Nothing else is subtracted: what the QEMU build executes beyond the release image otherwise (its
//! platform's console lines, a pre-emption's unstamped part beyond its fewest) makes an observation larger, never
//! smaller, so a run within its bound is within it, and a job above its bound by more than its pre-emptions'
//! measured spread ([`QEMU_PREEMPTION_BY_HANDLER_SPREAD_INSTRUCTIONS`] and the others) fails however often it was
//! pre-empted.
use schedule_analysis::analysis::BoardResult;
use schedule_analysis::bounds::{self, BoundsFile};
use schedule_analysis::scenario::BoardBounds;

/// QEMU's virtual time per instruction (`-icount shift=3`), ns.
pub const QEMU_NS_PER_INSTRUCTION: f64 = 8.0;

/// One task's observed execution against its bound.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MachineRow {
    /// The RTIC task.
    pub task: String,
    /// `instructions` (a QEMU run) or `cycles` (a robot capture).
    pub unit: &'static str,
    /// The execution observed of the job held (the one with the largest own figure once the allowances are
    /// out), in `unit`, the trace records included.
    pub observed: u64,
    /// The trace records' part of it, in `unit` (subtracted before the comparison): QEMU, its own two records and
    /// its handler events at their fewest; a robot capture, the timing file's trace cost per job.
    pub trace_allowance: u64,
    /// Traced runs that pre-empted that job directly.
    pub preemptions: u32,
    /// How many of them were software tasks' runs (their dispatcher's).
    pub dispatched: u32,
    /// How many of them were the QEMU platform clock's interrupt (stamped, `amiro_trace::PLATFORM_CLOCK_TASK`);
    /// the rest (neither dispatched nor the clock's) hardware tasks' runs (their handler).
    pub clocked: u32,
    /// Their tasks (filled in by the caller, which knows the task names).
    pub preempted_by: Vec<String>,
    /// Their tasks, one bit per task number.
    #[serde(skip)]
    pub preempted_by_mask: u32,
    /// Handler events the job stamped itself (in QEMU each is encoded and printed inside the job).
    pub events: u32,
    /// QEMU: the platform's plain (unstamped) ticks that surely ran inside it (their fewest instructions are in
    /// `unstamped`).
    pub ticks: u32,
    /// QEMU: the stretches of it whose last plain tick may have run inside it uncounted (`capture::Run`).
    pub uncounted_ticks: u32,
    /// The largest own figure of the task's jobs that no traced run pre-empted (`None`: every job was): what the
    /// job ran with no pre-emption's unstamped rest in it.
    pub alone: Option<u64>,
    /// What they ran inside it outside their stamps (handler, dispatcher or the clock's interrupt, records,
    /// exception return) at the fewest, in `unit` (subtracted before the comparison; QEMU only: a robot
    /// capture's pre-emptions are not counted, 0).
    pub unstamped: u64,
    /// The bound, in `unit` (`None`: declined).
    pub bound: Option<u64>,
    /// Whether the bound is one the bounds file holds back (the analysis keeps a stated budget): held to it all
    /// the same.
    pub held: bool,
    /// `(observed − trace_allowance − unstamped) / bound`: at most 1 within the bound; below 0.5 the bound is more than twice
    /// what ran.
    pub ratio: Option<f64>,
    /// `ok`, `EXCEEDS BOUND` (with the cause where the QEMU image's own bound of a simulated device's task is
    /// declined), `NOT HELD: …` (above by no more than the measured spread of what is unstamped) or `declined: …`.
    pub verdict: String,
    /// Where the bound is more than twice the largest job's own figure (issue 33's "tight"), why, where the rows
    /// tell (`loose_reason`); `None` within 2×, or where the allowances leave no own figure.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub loose: Option<String>,
    /// Whose bound: `release` (the generated bounds file's, the trace records taken off) or `qemu image` (the
    /// traced QEMU image's own, [`QemuImage`]: its records are in it, nothing is taken off for them).
    pub image: &'static str,
}

/// The traced QEMU image's own bounds of the tasks that run a simulated device in QEMU (the timing file's
/// `trace.qemu.other_code`): computed from the image the scenarios ran (`crate::wcet_qemu`), in instructions
/// (the longest path's), or the reason the machine code declined it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct QemuImage {
    /// The image bounded (for the report).
    pub elf: String,
    /// Per task its bound in instructions, or why it has none.
    pub tasks: std::collections::BTreeMap<String, Result<u64, String>>,
}

/// The bound's source of a row held to the release image's bound.
pub const RELEASE: &str = "release";
/// The bound's source of a row held to the traced QEMU image's own bound.
pub const QEMU_IMAGE: &str = "qemu image";

impl MachineRow {
    /// The job's own figure: observed, its trace records and the pre-empting runs' unstamped parts out.
    pub fn own(&self) -> u64 {
        self.observed
            .saturating_sub(self.trace_allowance)
            .saturating_sub(self.unstamped)
    }
}

/// One line of a task's largest job over the runs (`run`: where it ran) against its bound: own / bound, the ratio,
/// used or held, the verdict and whether the bound is loose.
pub fn summary(m: &MachineRow, run: &str) -> String {
    match m.bound {
        Some(b) => format!(
            "{} / {} {} ({:.2}; {run}; {} bound; observed {}, trace {}, {} pre-emptions ({} dispatched, {} the clock's){} and {} \
             plain ticks −{}, {} events; largest not pre-empted {}): {}{}",
            m.own(),
            b,
            m.unit,
            m.ratio.unwrap_or(0.0),
            match (m.image, m.held) {
                (QEMU_IMAGE, _) => "QEMU image's own",
                (_, true) => "held",
                _ => "used",
            },
            m.observed,
            m.trace_allowance,
            m.preemptions,
            m.dispatched,
            m.clocked,
            if m.preempted_by.is_empty() {
                String::new()
            } else {
                format!(" by {}", m.preempted_by.join("+"))
            },
            m.ticks,
            m.unstamped,
            m.events,
            m.alone.map_or_else(|| "-".to_string(), |a| a.to_string()),
            m.verdict,
            m.loose
                .as_ref()
                .map_or_else(String::new, |why| format!(", loose (bound > {TIGHT}× the job): {why}"))
        ),
        None => format!("{} {} ({run}): {}", m.own(), m.unit, m.verdict),
    }
}

/// A bound is loose above this many times the largest own figure observed (issue 33's "tight": at most 2×).
pub const TIGHT: f64 = 2.0;
/// Why a bound can be far above what a QEMU job runs, from the rows summed for the task: stated bus waits (the
/// bound's longest path polls each wait for its stated latency; QEMU's devices answer at once), a whole job of
/// several activations (the observed jobs served fewer), or nothing known.
fn loose_reason(rows: &[&bounds::TaskBound]) -> String {
    let mut why = Vec::new();
    let waits: f64 = rows
        .iter()
        .map(|r| r.held.as_ref().map_or(r.bus_wait_us, |h| h.bus_wait_us))
        .sum();
    if waits > 0.0 {
        why.push(format!(
            "its path polls {waits:.0} µs of stated bus waits, which QEMU's devices answer at once"
        ));
    }
    if rows
        .iter()
        .any(|r| r.job.is_some() || r.held.as_ref().is_some_and(|h| h.job.is_some()))
    {
        why.push("its job's bound serves the most activations (frames) a job can; the jobs seen served fewer".into());
    }
    if why.is_empty() {
        "not explained".into()
    } else {
        why.join("; ")
    }
}

/// The verdict of a job above its bound (`--check` fails on it).
pub const EXCEEDS: &str = "EXCEEDS BOUND";
/// The start of the verdict of a task whose largest job, in QEMU, is above its bound by no more than its pre-empting
/// runs' unstamped parts and its ticks were seen to run beyond their fewest (their measured spread): printed with
/// the counts, not failed, since the bench cannot tell such an excess from those runs' variation (docs/bench.md,
/// "What the check holds"). A job above by more fails like any other, and so does a simulated device's task whose
/// QEMU image bound is declined, above the release image's bound (`EXCEEDS BOUND` with the cause).
pub const NOT_HELD: &str = "NOT HELD";

/// A task's bound in the file, in `unit`: its own row (its job's bound where the row is a charge per activation),
/// or — for a publisher task, whose run takes one sample of
/// each topic due — the sum of the rows of the topics the analysis has as its jobs (`publish_medium[magnetometer-x]`
/// → `publisher[magnetometer-x]`) and of the topics the capture saw sampled at the task's level besides (`seen`:
/// (task, topic); the analysis has each topic at one level, a run may move a topic between levels). A row the bounds file holds back (`held`: declined for the analysis, which keeps a
/// stated budget) is held to its machine-code bound all the same: a held bound is still a promise that every job
/// runs within it. `Some(Ok((bound, held)))`, `held` when any row summed is a held one; `Some(Err(reason))` when a
/// row has no bound at all (declined by the machine code too); `None` when the file has no row for the task.
fn bound_of(
    file: &BoundsFile,
    task: &str,
    analysed: Option<&BoardResult>,
    seen: &[(String, String)],
    qemu: bool,
) -> Option<Result<(u64, bool, String), String>> {
    // A row charged per activation holds an observed job against its job's bound: a trace's job does not say
    // how many activations (frames) it served, and the job's bound holds every job, however many. A release of a
    // task that suspends on its scripts holds each traced run, one poll (a script's wait ends the run), against
    // one poll's bound, which the release's rests on.
    let value = |row: &bounds::TaskBound| -> Result<(u64, bool), String> {
        if let Some(release) = &row.release {
            let poll = if qemu {
                release.poll_instructions
            } else {
                release.poll_cycles
            };
            return Ok((poll, row.declined.is_some()));
        }
        match (qemu, row.instructions, row.cycles, &row.job, &row.held) {
            (true, _, _, Some(job), _) => Ok((job.instructions, false)),
            (false, _, _, Some(job), _) => Ok((job.cycles, false)),
            (true, Some(i), _, None, _) => Ok((i, false)),
            (false, _, Some(c), None, _) => Ok((c, false)),
            (_, _, _, None, Some(held)) => {
                match (qemu, &held.job, held.instructions, held.cycles) {
                    (true, Some(job), _, _) => Ok((job.instructions, true)),
                    (false, Some(job), _, _) => Ok((job.cycles, true)),
                    (true, None, Some(i), _) => Ok((i, true)),
                    (false, None, _, Some(c)) => Ok((c, true)),
                    _ => Err(row
                        .declined
                        .clone()
                        .unwrap_or_else(|| "no bound".to_string())),
                }
            }
            _ => Err(row
                .declined
                .clone()
                .unwrap_or_else(|| "no bound".to_string())),
        }
    };
    if let Some(row) = file.task(task) {
        return Some(value(row).map(|(b, h)| (b, h, loose_reason(&[row]))));
    }
    let prefix = format!("{task}[");
    let mut topics: Vec<&str> = analysed?
        .tasks
        .iter()
        .filter(|t| t.job_of.as_deref() == Some(task))
        .filter_map(|t| t.name.strip_prefix(&prefix)?.strip_suffix(']'))
        .collect();
    if !topics.is_empty() {
        for (_, topic) in seen.iter().filter(|(t, _)| t == task) {
            if !topics.contains(&topic.as_str()) {
                topics.push(topic);
            }
        }
    }
    let rows: Vec<&bounds::TaskBound> = topics
        .iter()
        .filter_map(|topic| file.task(&bounds::publisher_row(topic)))
        .collect();
    if rows.is_empty() {
        return None;
    }
    if rows.len() < topics.len() {
        return Some(Err("a topic of the task has no row".into()));
    }
    let reason = loose_reason(&rows);
    rows.iter()
        .map(|r| value(r))
        .try_fold((0, false), |(sum, held), v| {
            v.map(|(b, h)| (sum + b, held || h))
        })
        .map(|(b, h)| (b, h, reason))
        .into()
}

/// One observed job of a task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Job {
    /// Its execution, the stamped spans of the runs that pre-empted it taken out, µs.
    pub exec_us: f64,
    /// The traced runs that pre-empted it directly.
    pub preemptions: u32,
    /// How many of them were software tasks' runs (a dispatcher's).
    pub dispatched: u32,
    /// How many of them were the QEMU platform clock's interrupt (`capture::Run::clock_preemptions`); the rest
    /// (neither) were hardware tasks' (a handler's).
    pub clocked: u32,
    /// Their tasks, one bit per task number.
    pub preempted_by: u32,
    /// Handler events it stamped itself (QEMU: each a console line written inside it).
    pub events: u32,
    /// QEMU: the platform's plain ticks that surely ran inside it (`capture::Run::ticks`).
    pub ticks: u32,
    /// QEMU: its stretches whose last plain tick may have run inside it, not counted
    /// (`capture::Run::uncounted_ticks`).
    pub uncounted_ticks: u32,
}

/// The fewest instructions a QEMU job's own two task records run inside its span (its start record after the clock
/// read, its end record up to it; `amiro_firmware::tracing::{start, end, write}`, written through semihosting):
/// single-stepped as [`QEMU_TICK_FEWEST_INSTRUCTIONS`] with `-dfilter` on `tracing::{start, end, event, emit,
/// write}`, `amiro_trace::Encoder::{put, raw}`, `qemu::timer::now_ticks`, `qemu::console_write`, semihosting's
/// `HostStream::write_all`, `__aeabi_memclr8` and the outlined helper `write` calls (other callees not counted: a
/// lower bound), on DiWheelDrive 1-1's traced image over `motor-deadman`: after the clock read (the `ldr` of
/// SysTick's CVR in `write`) to `start`'s return 437 instructions (118 of 207 records; at most 469), from `end`'s entry
/// to the clock read 54 (198 of 206; at most 92): 491 on main. Recounted 2026-12-03 on branch 34speed's image (main
/// merged: `write`'s clock read inlined, its clamp after the read), from a whole single-stepped log with only those
/// functions' instructions counted: after the clock read 431 (114 of 207; at most 436), up to it 58 (152 of 206; at
/// most 66): 489; `hostile`'s 16 645 records and LightRing 1-2 `flood`'s 330 the same (431, 58); PowerManagement's
/// image (Cortex-M4) over `flood`: 431 and 55 (2 719 of 4 626), so 486. docs/bench.md, "The traced QEMU build's own
/// records".
pub const QEMU_RECORDS_FEWEST_INSTRUCTIONS: u64 = 486;

/// The fewest instructions one handler event runs in the traced QEMU build (`amiro_firmware::tracing::event`:
/// encoded, stamped and printed as a `# T` console line; the release image copies it into the ring, which its bound
/// holds), counted as [`QEMU_RECORDS_FEWEST_INSTRUCTIONS`] (only the tracing functions' own instructions: at most
/// the true figure) with tools/bench-count on 2026-12-05's images: 1 618 to 1 629 over DiWheelDrive 1-1
/// `motor-deadman`'s 93 events, 1 617 to 1 667 over PowerManagement `flood`'s 323, 1 618 to 1 669 over LightRing
/// 1-0 `admission`'s 103 (callees included, 1 980 and more). Every count since `tracing::write` read the clock
/// inline (2026-12-03, twice, on the three boards) found 1 617 or more; the 1 311 taken off until 2026-12-05 was
/// main's count of the image before that, and left about 306 instructions of each printed event in the job's own
/// figure (docs/bench.md, "The traced QEMU build's own records").
pub const QEMU_EVENT_FEWEST_INSTRUCTIONS: u64 = 1617;

/// The fewest instructions a traced **hardware task**'s run executes inside the job it pre-empts outside its own
/// stamps: from its exception's entry (its handler, `job`, `tracing::start` and `tracing::write`) to its start
/// record's clock read, and from its end record's clock read (the rest of `tracing::write`: the TaskEnd record
/// encoded and written through semihosting; `tracing::end`, the guard's drop, the handler's epilogue) to its
/// exception return. Counted by single-stepping QEMU over whole scenario runs (`-singlestep -d exec,nochain,int`,
/// no filter: every instruction with the exception entries, returns and tail-chains, QEMU's re-executed I/O
/// instructions counted once), per exception activation its own instructions outside its runs' stamped spans
/// (nested exceptions counted to themselves; the clock read is the `ldr` of SysTick's CVR in `tracing::write`
/// that ends the read loop): DiWheelDrive 1-1 `hostile` (7 237 activations of `USB_LP_CAN_RX0` and
/// `USB_HP_CAN_TX`: 690–699), PowerManagement `flood` (2 077: 692–699) and LightRing 1-2 `flood` (123: 690–693);
/// the fewest, 690 (entry 130, exit 559 or more), less 13 for the end record's data-dependent steps (2
/// instructions per zero byte the encoder meets, at most 5 of them, and the clock's clamp and range checks):
/// 677. Recounted 2026-12-03 on branch 34speed's DiWheelDrive 1-1 image (main merged) over `hostile` (7 217
/// activations: 691–, entry 135 or more, exit 555 or more), `motor-deadman` (47: 691–) and, on LightRing 1-2's
/// image, `flood` (123: 691–), on PowerManagement's (2 077: 693–): not lower, 677 kept.
/// docs/bench.md, "A pre-empting run's unstamped part".
pub const QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS: u64 = 677;

/// The same for a traced **software task**'s run, which its priority's dispatcher polls: the dispatcher's entry
/// and its poll of the task up to the start record's clock read (`tracing::resume` or `enter`), and after the end
/// record's clock read (`tracing::suspend`) the task's return to the dispatcher, the dispatcher's pass over its
/// other tasks and the exception return. One dispatcher activation can run several tasks' runs (each of its
/// runs counts as a pre-emption), so the figure per run is the smaller of the fewest entry plus the fewest exit
/// (one run) and the fewest gap from one run's end stamp to the next one's start stamp in the same activation:
/// per run `(entry + (k − 1) × gap + exit) / k` is at least that for any k. Counted as
/// [`QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS`], over every dispatcher activation with a run: fewest entry
/// 150, exit 633, gap 776 (DiWheelDrive 1-1 `hostile`'s 893 activations of two runs of one dispatcher; 778 on
/// PowerManagement `flood`, 779 on LightRing 1-2 `flood`), so 776, less 13 as above: 763. Recounted 2026-12-03 on
/// branch 34speed's DiWheelDrive 1-1 image (main merged) over `hostile`: fewest gap 777 (888 two-run activations),
/// entry 171 + exit 630; `motor-deadman` no lower; LightRing 1-2 `flood` and PowerManagement `flood` gap 779: not lower,
/// 763 kept.
pub const QEMU_PREEMPTION_BY_DISPATCHER_FEWEST_INSTRUCTIONS: u64 = 763;

/// The fewest instructions a **busy tick** of the QEMU platform clock (SysTick in a single-board run, a queue due or
/// its head changed: `amiro_firmware::qemu::timer`'s `SysTick`) executes inside the job it pre-empts outside its own
/// stamps (the two readings it writes to `clock.bin`, the runs of `amiro_trace::PLATFORM_CLOCK_TASK`): from the
/// exception's entry (the mode checks, `busy_queues`, `tick_cycles` up to its read of the counter) to its start
/// stamp, and from its end stamp (`tick_cycles`' return, the stamps encoded and written through semihosting) to the
/// exception return. Counted as [`QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS`] (tools/bench-count,
/// `unstamped.py`) on branch 33tick's images: DiWheelDrive 1-1 `hostile` (14 344 busy ticks: entry 57–85, exit
/// 37–38, 94–122 a tick) and PowerManagement `flood` (4 067: the same); the fewest, 94 (no data-dependent step below
/// it: a wrap seen in `tick_cycles` only adds a pass). docs/bench.md, "The QEMU tick".
pub const QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS: u64 = 94;

/// How much more than [`QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS`] a hardware task's run was seen to execute
/// outside its stamps: at most 745 (PowerManagement `flood`, 2 077 activations of its two receive interrupts:
/// 693–745; DiWheelDrive 1-1 `hostile`, 7 198: 691–742), counted as that figure on branch 33tick's images. A
/// measured spread, not a proven one: what a pre-empted job may hold beyond the fewest taken off, which no record
/// stamps (docs/bench.md, "What the check holds").
pub const QEMU_PREEMPTION_BY_HANDLER_SPREAD_INSTRUCTIONS: u64 =
    745 - QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS;

/// The same for a dispatched run, per run of its dispatcher's activation ((entry + gaps + exit) / runs): at most
/// 1 127 (PowerManagement `flood`, exception 69's 26 single-run activations: 816–1 127, entry up to 305 and exit up
/// to 822; DiWheelDrive 1-1 `hostile`'s dispatchers at most 1 022), against the 763 taken off.
pub const QEMU_PREEMPTION_BY_DISPATCHER_SPREAD_INSTRUCTIONS: u64 =
    1127 - QEMU_PREEMPTION_BY_DISPATCHER_FEWEST_INSTRUCTIONS;

/// The same for a busy tick ([`QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS`]): at most 122.
pub const QEMU_PREEMPTION_BY_CLOCK_SPREAD_INSTRUCTIONS: u64 =
    122 - QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS;

/// The fewest instructions a **plain tick** executes (SysTick every 10 µs in a single-board run, no queue due and no
/// head changed: it counts the wrap and leaves both queues alone; not stamped), whole (its exception activation's
/// every instruction, single-stepped: tools/bench-count, `unstamped.py`): 63–71 over DiWheelDrive 1-1 `hostile`'s
/// 32 227 plain ticks and PowerManagement `flood`'s 22 888 (70 for most). The bench counts the plain ticks that
/// surely ran inside a job (`capture::Run::ticks`) and takes each off at this. (Until branch 33tick every tick was
/// plain and ran both queues' checks, 98–105 instructions and up to 302 when it woke a task, and the bench took 42
/// off, the part in `SysTick` and `run_queues` alone.) docs/bench.md, "The QEMU tick".
pub const QEMU_TICK_FEWEST_INSTRUCTIONS: u64 = 63;

/// The most a plain tick was seen to run ([`QEMU_TICK_FEWEST_INSTRUCTIONS`]): 71. A stretch of a job's (between two
/// of the trace's task records) may hold one plain tick the bench cannot prove inside it (the last boundary's,
/// whose interrupt may come after the stretch): so much is left in the job unsubtracted, per stretch.
pub const QEMU_TICK_MOST_INSTRUCTIONS: u64 = 71;

/// A counted plain tick's part beyond its fewest: 71 − 63.
pub const QEMU_TICK_SPREAD_INSTRUCTIONS: u64 =
    QEMU_TICK_MOST_INSTRUCTIONS - QEMU_TICK_FEWEST_INSTRUCTIONS;

#[cfg(test)]
impl Job {
    /// A job no traced run pre-empted.
    pub fn alone(exec_us: f64) -> Job {
        Job {
            exec_us,
            preemptions: 0,
            dispatched: 0,
            clocked: 0,
            preempted_by: 0,
            events: 0,
            ticks: 0,
            uncounted_ticks: 0,
        }
    }
}

/// The rows of `tasks` (task name, its observed jobs) against the board's bounds, for a QEMU run (`qemu`)
/// or a robot capture at `clock_hz`: each task's job with the largest own figure, held to its bound.
#[cfg(test)]
pub fn rows(
    bounds: &BoardBounds,
    tasks: &[(String, Vec<Job>)],
    analysed: Option<&BoardResult>,
    qemu: bool,
    clock_hz: u64,
) -> Vec<MachineRow> {
    rows_against(bounds, tasks, analysed, qemu, clock_hz, None)
}

/// The row a suspending release's summed runs are held against: `publisher[gyroscope] release`.
pub fn release_row(row: &str) -> String {
    format!("{row} release")
}

/// The releases of the rows that are a suspending task's release (the bounds file's `release`), each held as one
/// job, its runs (one poll each) summed, against the release's bound (`polls` × one poll's): per row (`publisher[…]`)
/// the runs of each of its releases in the trace. A release's job is its runs' executions summed less every run's
/// trace records but one's at their fewest (the check takes one job's off), with their pre-emptions, events and
/// ticks summed; its row is [`release_row`]. A run that ended one release and took the next is in both, as the
/// count has it (docs/analysis.md, "A suspending release: the sum of its polls"). `releases` names each row's
/// releases' task: where the QEMU build runs a simulated device inside it (`trace.qemu.other_code`), the release
/// image's bound does not cover the runs, and a sum above it fails, as such a task's run does.
pub fn release_rows(
    bounds: &BoardBounds,
    releases: &[(String, String, Vec<Vec<Job>>)],
    qemu: bool,
    clock_hz: u64,
) -> Vec<MachineRow> {
    let Some(file) = &bounds.bounds else {
        return Vec::new();
    };
    // Each release row as a plain row of its release's figures (or held ones), under its own name.
    let mut sums = file.clone();
    sums.tasks = file
        .tasks
        .iter()
        .filter(|r| r.release.is_some())
        .map(|r| bounds::TaskBound {
            task: release_row(&r.task),
            release: None,
            ..r.clone()
        })
        .collect();
    let mut sums = BoardBounds {
        bounds: Some(sums),
        ..bounds.clone()
    };
    if let Some(q) = sums.trace.as_mut().and_then(|t| t.qemu.as_mut()) {
        for (row, task, _) in releases {
            if let Some(what) = q.other_code.get(task).cloned() {
                q.other_code.insert(release_row(row), what);
            }
        }
    }
    // One run's records at their fewest, µs: QEMU's, or the timing file's trace cost per job on the chip.
    let records_us = if qemu {
        QEMU_RECORDS_FEWEST_INSTRUCTIONS as f64 * QEMU_NS_PER_INSTRUCTION / 1_000.0
    } else {
        bounds.trace.as_ref().map_or(0.0, |t| t.per_job_us)
    };
    let jobs: Vec<(String, Vec<Job>)> = releases
        .iter()
        .map(|(row, _, each)| {
            let merged = each
                .iter()
                .filter(|runs| !runs.is_empty())
                .map(|runs| Job {
                    exec_us: (runs.iter().map(|j| j.exec_us).sum::<f64>()
                        - (runs.len() - 1) as f64 * records_us)
                        .max(0.0),
                    preemptions: runs.iter().map(|j| j.preemptions).sum(),
                    dispatched: runs.iter().map(|j| j.dispatched).sum(),
                    clocked: runs.iter().map(|j| j.clocked).sum(),
                    preempted_by: runs.iter().fold(0, |m, j| m | j.preempted_by),
                    events: runs.iter().map(|j| j.events).sum(),
                    ticks: runs.iter().map(|j| j.ticks).sum(),
                    uncounted_ticks: runs.iter().map(|j| j.uncounted_ticks).sum(),
                })
                .collect();
            (release_row(row), merged)
        })
        .collect();
    rows_against(&sums, &jobs, None, qemu, clock_hz, None)
}

/// A job's direct pre-emptions by kind: (hardware tasks' runs, dispatched runs, the clock's runs). The clock's come
/// first, then the dispatched, each at most what is left (a damaged input counts no run twice).
fn kinds(j: &Job) -> (u64, u64, u64) {
    let clocked = j.clocked.min(j.preemptions);
    let dispatched = j.dispatched.min(j.preemptions - clocked);
    (
        u64::from(j.preemptions - clocked - dispatched),
        u64::from(dispatched),
        u64::from(clocked),
    )
}

/// `rows`, with the traced QEMU image's own bounds (`image`) for the tasks that run a simulated device in QEMU
/// (`trace.qemu.other_code`): in a QEMU run such a task is held to its bound in the image that ran, with nothing
/// taken off for the trace records (the image's bound holds them, and its handler events: the tracing code is in
/// it), only the pre-empting runs' unstamped records and the tick interrupts (other tasks' code) at their fewest.
/// A job above it fails (`EXCEEDS BOUND`) unless it is above by no more than the measured spread of what is
/// unstamped; where the image's bound is declined (or, without `image`, not computed) the task is held to the release
/// bound and fails above it, with the machine code's reason: that bound never covered the device's code, and nothing
/// else holds the job. In a robot capture (the release code) such a task is held like any other.
pub fn rows_against(
    bounds: &BoardBounds,
    tasks: &[(String, Vec<Job>)],
    analysed: Option<&BoardResult>,
    qemu: bool,
    clock_hz: u64,
    image: Option<&QemuImage>,
) -> Vec<MachineRow> {
    rows_against_seen(bounds, tasks, analysed, &[], qemu, clock_hz, image)
}

/// [`rows_against`], a publisher task held to the rows of the topics the capture saw sampled at its level as well
/// (`seen`: (task, topic), [`bound_of`]).
pub fn rows_against_seen(
    bounds: &BoardBounds,
    tasks: &[(String, Vec<Job>)],
    analysed: Option<&BoardResult>,
    seen: &[(String, String)],
    qemu: bool,
    clock_hz: u64,
    image: Option<&QemuImage>,
) -> Vec<MachineRow> {
    let Some(file) = &bounds.bounds else {
        return Vec::new();
    };
    let (unit, per_us) = if qemu {
        ("instructions", 1_000.0 / QEMU_NS_PER_INSTRUCTION)
    } else {
        ("cycles", clock_hz as f64 / 1e6)
    };
    // A robot capture: the timing file's trace cost per job. QEMU: what the job's own records and its handler
    // events run inside it at the fewest (the timing file's `trace.qemu.per_job_us`, 8 µs = 1 000 instructions, is
    // the analysis's charge, above what an event-free job's records run: taken off, it would hide up to ~500
    // instructions of the job's own, and below what a job printing events runs).
    let robot_allowance =
        (bounds.trace.as_ref().map_or(0.0, |t| t.per_job_us) * per_us).floor() as u64;
    let allowance = |events: u32| {
        if qemu {
            QEMU_RECORDS_FEWEST_INSTRUCTIONS + u64::from(events) * QEMU_EVENT_FEWEST_INSTRUCTIONS
        } else {
            robot_allowance
        }
    };
    // QEMU: what each traced run that pre-empted the job directly ran inside it outside its stamps, at the fewest
    // (a handler's run, a dispatched one, the clock's interrupt), and how much more than that such runs were seen
    // to run (their spread). A robot capture's records are the ring's and its pre-emptions were never counted
    // there: nothing is taken off for them.
    let pre_empting = |j: &Job| {
        if qemu {
            let (handlers, dispatched, clocked) = kinds(j);
            (
                handlers * QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS
                    + dispatched * QEMU_PREEMPTION_BY_DISPATCHER_FEWEST_INSTRUCTIONS
                    + clocked * QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS,
                handlers * QEMU_PREEMPTION_BY_HANDLER_SPREAD_INSTRUCTIONS
                    + dispatched * QEMU_PREEMPTION_BY_DISPATCHER_SPREAD_INSTRUCTIONS
                    + clocked * QEMU_PREEMPTION_BY_CLOCK_SPREAD_INSTRUCTIONS,
            )
        } else {
            (0, 0)
        }
    };
    let other_code = |task: &str| {
        if !qemu {
            return None;
        }
        let q = bounds.trace.as_ref()?.qemu.as_ref()?;
        q.other_code.get(task).cloned()
    };
    let mut out = Vec::new();
    for (task, jobs) in tasks {
        let Some(release) = bound_of(file, task, analysed, seen, qemu) else {
            continue;
        };
        // A simulated device's task in a QEMU run with the image's own bound: held to it, records in it.
        let own_image = other_code(task)
            .and(image)
            .and_then(|i| i.tasks.get(task).map(|b| (i, b)));
        let (bound, in_image) = match own_image {
            Some((_, Ok(b))) => (
                Ok((
                    *b,
                    false,
                    "the QEMU image's own bound takes every path of the simulated device at its stated worst \
                     (a robot run's register-model and link paths, the queue's searches, every loop at its bound); \
                     the single-board runs took fewer"
                        .to_string(),
                )),
                true,
            ),
            _ => (release, false),
        };
        let allowance = |events: u32| if in_image { 0 } else { allowance(events) };
        // (own, observed, pre-emptions, unstamped, by, events, spread, trace, dispatched, clocked, ticks) of each
        // job; the largest own figure is the one held, pre-empted or not.
        let figures: Vec<_> = jobs
            .iter()
            .map(|j| {
                let observed = (j.exec_us * per_us).round() as u64;
                let (unstamped, spread) = pre_empting(j);
                // QEMU: the plain ticks that ran inside it, at their fewest; what they and the plain ticks not
                // counted (at most one a stretch) may have run beyond that.
                let (unstamped, spread) = if qemu {
                    (
                        unstamped + u64::from(j.ticks) * QEMU_TICK_FEWEST_INSTRUCTIONS,
                        spread
                            + u64::from(j.ticks) * QEMU_TICK_SPREAD_INSTRUCTIONS
                            + u64::from(j.uncounted_ticks) * QEMU_TICK_MOST_INSTRUCTIONS,
                    )
                } else {
                    (unstamped, spread)
                };
                let trace_allowance = allowance(j.events);
                let own = observed
                    .saturating_sub(trace_allowance)
                    .saturating_sub(unstamped);
                (
                    own,
                    observed,
                    j.preemptions,
                    unstamped,
                    j.preempted_by,
                    j.events,
                    spread,
                    trace_allowance,
                    j.dispatched,
                    j.clocked,
                    j.ticks,
                    j.uncounted_ticks,
                )
            })
            .collect();
        let alone = figures.iter().filter(|f| f.2 == 0).map(|f| f.0).max();
        let Some(&(
            own,
            observed,
            preemptions,
            unstamped,
            by,
            events,
            spread,
            trace_allowance,
            dispatched,
            clocked,
            ticks,
            uncounted_ticks,
        )) = figures.iter().max()
        else {
            continue;
        };
        let (bound, held, ratio, verdict, why) = match bound {
            Ok((b, held, why)) => {
                let ratio = (b > 0).then(|| own as f64 / b as f64);
                let verdict = if own <= b {
                    "ok".to_string()
                } else if let (Some(what), Some((i, Err(why)))) =
                    (other_code(task).filter(|_| !in_image), own_image)
                {
                    // The QEMU image's own bound is declined: the release bound never covered the device's code,
                    // and no bound holds the job: above the only one there is, it fails (issue 33: "CI fails on
                    // any job above its bound").
                    format!(
                        "{EXCEEDS}: the QEMU build runs {what} inside it, which the release image's bound does not \
                         cover, and the bound of {} that would hold it is declined: {why}",
                        i.elf
                    )
                } else if let Some(what) = other_code(task).filter(|_| !in_image) {
                    // No QEMU image bounded (a release's summed runs, or no image given): the release bound never
                    // covered the simulated device's code, and no bound holds the job: it fails, as above.
                    format!(
                        "{EXCEEDS}: the QEMU build runs {what} inside it, which the release image's bound does not \
                         cover, and no bound of the QEMU image holds it"
                    )
                } else if qemu && own - b <= spread {
                    // Above by no more than its pre-empting runs' unstamped parts were seen to run beyond their
                    // fewest: not proved above, not held either.
                    format!(
                        "{NOT_HELD}: above by {} after its records, its {preemptions} pre-empting runs' unstamped \
                         parts and its {ticks} plain ticks were taken off at their fewest, within the {spread} those \
                         (and {uncounted_ticks} plain ticks not counted) were seen to run beyond that (their measured \
                         spread), which no record stamps",
                        own - b
                    )
                } else {
                    EXCEEDS.to_string()
                };
                (Some(b), held, ratio, verdict, why)
            }
            Err(reason) => (
                None,
                false,
                None,
                format!("declined: {reason}"),
                String::new(),
            ),
        };
        // Where the allowances swallow the whole observation the job's own figure is not known: not loose.
        let loose = bound
            .filter(|b| own > 0 && *b as f64 > TIGHT * own as f64)
            .map(|_| why);
        out.push(MachineRow {
            task: task.clone(),
            unit,
            observed,
            trace_allowance,
            preemptions,
            dispatched,
            clocked,
            preempted_by: Vec::new(),
            preempted_by_mask: by,
            events,
            ticks,
            uncounted_ticks,
            alone,
            unstamped,
            bound,
            held,
            ratio,
            verdict,
            loose,
            image: if in_image { QEMU_IMAGE } else { RELEASE },
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use schedule_analysis::scenario::{QemuBuild, TraceCost, UnstampedPerPreemption};

    fn file() -> BoundsFile {
        BoundsFile::from_json(
            "t.wcet.json",
            &serde_json::json!({
                "generated": format!("{} for a test", bounds::GENERATED_PREFIX),
                "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
                "clock_hz": 72_000_000, "wait_states": 2,
                "image": { "code_sha256": "0".repeat(64), "code_bytes": 4 },
                "tasks": [
                    { "task": "can_rx", "cycles": 720, "us": 10.0, "instructions": 500, "declined": null },
                    { "task": "publisher[gyroscope]", "cycles": 1440, "us": 20.0, "instructions": 1000, "declined": null },
                    { "task": "admit_requests", "cycles": null, "us": null, "instructions": null,
                      "declined": "a loop without a bound" }
                ]
            })
            .to_string(),
        )
        .unwrap()
    }

    /// `board_bounds` with the traced QEMU build's figures: 8 µs of trace per job, 400 instructions stated
    /// unstamped per pre-emption (which the bench no longer reads: it counts its own), and `other_code`'s tasks
    /// running a simulated device.
    fn traced_bounds(other_code: &[(&str, &str)]) -> BoardBounds {
        let mut bounds = board_bounds();
        bounds.trace = Some(TraceCost {
            feature: "task-trace".into(),
            per_job_us: 12.0,
            note: None,
            qemu: Some(QemuBuild {
                per_job_us: 8.0,
                budget_scale: 1.0,
                transmit: None,
                replay: None,
                unstamped_per_preemption: Some(UnstampedPerPreemption {
                    instructions: 400,
                    note: "a test".into(),
                }),
                other_code: other_code
                    .iter()
                    .map(|(t, w)| (t.to_string(), w.to_string()))
                    .collect(),
                note: None,
            }),
        });
        bounds
    }

    fn board_bounds() -> BoardBounds {
        BoardBounds {
            file: "t.wcet.json".into(),
            bounds: Some(file()),
            trace: Some(TraceCost {
                feature: "task-trace".into(),
                per_job_us: 12.0,
                note: None,
                qemu: None,
            }),
        }
    }

    #[test]
    fn observed_instructions_are_held_to_the_bound_after_the_trace_records() {
        // QEMU: the job's own records at their fewest, 486 instructions (the timing file's 12 µs are the robot's).
        let rows = rows(
            &board_bounds(),
            &[
                ("can_rx".into(), vec![Job::alone(7.888)]), // 986 instructions: 500 once the records are out
                ("admit_requests".into(), vec![Job::alone(100.0)]), // declined
                ("stimulus".into(), vec![Job::alone(5.0)]), // no row: not listed
            ],
            None,
            true,
            120_000_000,
        );
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].observed, 986);
        assert_eq!(rows[0].trace_allowance, QEMU_RECORDS_FEWEST_INSTRUCTIONS);
        assert_eq!(rows[0].bound, Some(500));
        assert_eq!(rows[0].verdict, "ok");
        assert_eq!(rows[0].ratio, Some(1.0));
        assert!(rows[1].verdict.starts_with("declined: a loop"));
        // One instruction more than the bound and the trace: above it.
        let over = super::rows(
            &board_bounds(),
            &[("can_rx".into(), vec![Job::alone(7.896)])],
            None,
            true,
            120_000_000,
        );
        assert_eq!(over[0].observed, 987);
        assert_eq!(over[0].verdict, EXCEEDS);
        // A job that printed two handler events: each taken off at its fewest (1 617), not more.
        let printed = |exec_us: f64| Job {
            events: 2,
            ..Job::alone(exec_us)
        };
        let two = super::rows(
            &board_bounds(),
            &[("can_rx".into(), vec![printed(33.760)])], // 4 220 = 500 + 486 + 2 × 1 617
            None,
            true,
            120_000_000,
        );
        assert_eq!(
            (two[0].trace_allowance, two[0].verdict.as_str()),
            (486 + 2 * 1617, "ok")
        );
        let two_over = super::rows(
            &board_bounds(),
            &[("can_rx".into(), vec![printed(33.768)])],
            None,
            true,
            120_000_000,
        );
        assert_eq!(two_over[0].verdict, EXCEEDS);
    }

    #[test]
    fn a_robot_capture_is_held_to_the_cycles() {
        // 72 MHz: 12 µs of trace = 864 cycles; 20 µs observed = 1440 cycles, 576 once the trace is out.
        let rows = rows(
            &board_bounds(),
            &[("can_rx".into(), vec![Job::alone(20.0)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!((rows[0].unit, rows[0].observed), ("cycles", 1440));
        assert_eq!(rows[0].bound, Some(720));
        assert_eq!(rows[0].verdict, "ok");
        let rows = super::rows(
            &board_bounds(),
            &[("can_rx".into(), vec![Job::alone(22.1)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(rows[0].verdict, EXCEEDS);
    }

    #[test]
    fn a_row_charged_per_activation_holds_a_job_against_the_job_bound() {
        // can_rx charged per frame at 300 instructions (the budget), its job (a FIFO drained) 900.
        let mut file = file();
        let rx = file.tasks.iter_mut().find(|t| t.task == "can_rx").unwrap();
        rx.instructions = Some(300);
        rx.job = Some(bounds::JobBound {
            cycles: 2160,
            us: 30.0,
            instructions: 900,
            per_activation: "RX at src/rx.rs:12 at 2 passes: …".into(),
            parts: None,
        });
        let charged = BoardBounds {
            bounds: Some(file),
            ..board_bounds()
        };
        // 1 386 instructions, 900 once the records are out: a job of three frames, above one frame's 300 but
        // within the job's bound.
        let held = rows(
            &charged,
            &[("can_rx".into(), vec![Job::alone(11.088)])],
            None,
            true,
            1,
        );
        assert_eq!((held[0].bound, held[0].verdict.as_str()), (Some(900), "ok"));
        let over = rows(
            &charged,
            &[("can_rx".into(), vec![Job::alone(11.096)])],
            None,
            true,
            1,
        );
        assert_eq!(over[0].verdict, EXCEEDS);
        let robot = rows(
            &charged,
            &[("can_rx".into(), vec![Job::alone(1.0)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot[0].bound, Some(2160));
    }

    #[test]
    fn a_suspending_release_holds_each_run_to_one_polls_bound() {
        // can_rx as a release of one script: 4 polls of 500 instructions (720 cycles), the row 2 000 (2 880).
        let mut file = file();
        let row = file.tasks.iter_mut().find(|t| t.task == "can_rx").unwrap();
        (row.cycles, row.us, row.instructions) = (Some(2880), Some(40.0), Some(2000));
        row.release = Some(bounds::ReleaseBound {
            polls: 4,
            poll_cycles: 720,
            poll_us: 10.0,
            poll_instructions: 500,
            poll_bus_wait_us: 0.0,
            reason: "1 script stated: …".into(),
        });
        let release = BoardBounds {
            bounds: Some(file),
            ..board_bounds()
        };
        // A run is one poll: 986 instructions, 500 once its records (486) are out, is within one poll's bound;
        // 987 is above it, though far within the release's 2 000.
        let within = rows(
            &release,
            &[("can_rx".into(), vec![Job::alone(7.888)])],
            None,
            true,
            1,
        );
        assert_eq!(
            (within[0].bound, within[0].verdict.as_str()),
            (Some(500), "ok")
        );
        let over = rows(
            &release,
            &[("can_rx".into(), vec![Job::alone(7.896)])],
            None,
            true,
            1,
        );
        assert_eq!(
            (over[0].bound, over[0].verdict.as_str()),
            (Some(500), EXCEEDS)
        );
        let robot = rows(
            &release,
            &[("can_rx".into(), vec![Job::alone(1.0)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot[0].bound, Some(720));
    }

    #[test]
    fn a_suspending_releases_runs_are_held_summed_to_the_release_bound() {
        // publisher[gyroscope] as a release of one script: 4 polls of 500 instructions, the release 2 000.
        let mut file = file();
        let row = file
            .tasks
            .iter_mut()
            .find(|t| t.task == "publisher[gyroscope]")
            .unwrap();
        (row.cycles, row.us, row.instructions) = (Some(2880), Some(40.0), Some(2000));
        row.release = Some(bounds::ReleaseBound {
            polls: 4,
            poll_cycles: 720,
            poll_us: 10.0,
            poll_instructions: 500,
            poll_bus_wait_us: 0.0,
            reason: "1 script stated: …".into(),
        });
        let release = BoardBounds {
            bounds: Some(file),
            ..board_bounds()
        };
        // A run of `n` instructions (8 ns each), its records (486) in it.
        let run = |n: u64| Job::alone(n as f64 * QEMU_NS_PER_INSTRUCTION / 1_000.0);
        let held = |runs: Vec<Job>| {
            release_rows(
                &release,
                &[("publisher[gyroscope]".into(), "publish".into(), vec![runs])],
                true,
                1,
            )
        };
        // Three polls of 500 each after their records: 1 500 of 2 000.
        let three = held(vec![run(986), run(986), run(986)]);
        assert_eq!(three[0].task, "publisher[gyroscope] release");
        assert_eq!(
            (three[0].own(), three[0].bound, three[0].verdict.as_str()),
            (1500, Some(2000), "ok")
        );
        // Five polls of 450: each within one poll's 500, the release above its 2 000 (more polls than counted).
        let five = held(vec![run(936); 5]);
        assert_eq!((five[0].own(), five[0].verdict.as_str()), (2250, EXCEEDS));
        // The largest release is the one held; no release row, no check.
        let two = release_rows(
            &release,
            &[(
                "publisher[gyroscope]".into(),
                "publish".into(),
                vec![vec![run(986)], vec![run(986), run(1486)]],
            )],
            true,
            1,
        );
        assert_eq!(two[0].own(), 1500);
        assert!(release_rows(
            &board_bounds(),
            &[(
                "publisher[gyroscope]".into(),
                "publish".into(),
                vec![vec![run(986)]]
            )],
            true,
            1
        )
        .is_empty());
        // A publisher that runs a simulated device in QEMU: the release image's bound does not cover its runs, no
        // bound of the QEMU image holds their sum, and the sum above the release bound fails.
        let simulated = BoardBounds {
            trace: traced_bounds(&[("publish", "the simulated bus")]).trace,
            ..release.clone()
        };
        let unheld = release_rows(
            &simulated,
            &[(
                "publisher[gyroscope]".into(),
                "publish".into(),
                vec![vec![run(936); 5]],
            )],
            true,
            1,
        );
        assert!(
            unheld[0].verdict.starts_with(EXCEEDS)
                && unheld[0].verdict.contains("the simulated bus"),
            "{}",
            unheld[0].verdict
        );
    }

    #[test]
    fn a_pre_empted_job_is_held_after_what_its_pre_empting_runs_ran_unstamped_inside_it() {
        let mut bounds = traced_bounds(&[]);
        // µs of a QEMU job of `n` instructions (8 ns each).
        let us = |n: u64| n as f64 * QEMU_NS_PER_INSTRUCTION / 1_000.0;
        let (handler, dispatched) = (
            QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS,
            QEMU_PREEMPTION_BY_DISPATCHER_FEWEST_INSTRUCTIONS,
        );
        let pre_empted = |n: u64, preemptions: u32, by_dispatcher: u32| Job {
            exec_us: us(n),
            preemptions,
            dispatched: by_dispatcher,
            clocked: 0,
            preempted_by: 0,
            events: 0,
            ticks: 0,
            uncounted_ticks: 0,
        };
        // can_rx's bound is 500. Pre-empted by a hardware task's run and a dispatched one: its records (486),
        // each run's unstamped part at its fewest, 500 its own: within. Alone, 900 observed: 414 its own.
        let at = 500 + QEMU_RECORDS_FEWEST_INSTRUCTIONS + handler + dispatched;
        let r = rows(
            &bounds,
            &[(
                "can_rx".into(),
                vec![Job::alone(us(900)), pre_empted(at, 2, 1)],
            )],
            None,
            true,
            1,
        );
        assert_eq!(
            (
                r[0].observed,
                r[0].preemptions,
                r[0].dispatched,
                r[0].unstamped
            ),
            (at, 2, 1, handler + dispatched)
        );
        assert_eq!(r[0].alone, Some(414));
        assert_eq!((r[0].verdict.as_str(), r[0].ratio), ("ok", Some(1.0)));
        // What is still unstamped and variable: each pre-empting run's part above its fewest (the job crossed no
        // tick boundary: no plain tick in it).
        let spread = QEMU_PREEMPTION_BY_HANDLER_SPREAD_INSTRUCTIONS
            + QEMU_PREEMPTION_BY_DISPATCHER_SPREAD_INSTRUCTIONS;
        // One instruction more: above its bound, but within that spread: not proved above, printed and not held.
        let within = rows(
            &bounds,
            &[(
                "can_rx".into(),
                vec![Job::alone(us(900)), pre_empted(at + 1, 2, 1)],
            )],
            None,
            true,
            1,
        );
        assert_eq!(within[0].own(), 501);
        assert!(
            within[0].verdict.starts_with(NOT_HELD),
            "{}",
            within[0].verdict
        );
        // At the spread's end still not proved; one more fails like a job that ran alone, however well the jobs
        // that ran alone kept within.
        let edge = rows(
            &bounds,
            &[("can_rx".into(), vec![pre_empted(at + spread, 2, 1)])],
            None,
            true,
            1,
        );
        assert!(edge[0].verdict.starts_with(NOT_HELD), "{}", edge[0].verdict);
        let over = rows(
            &bounds,
            &[(
                "can_rx".into(),
                vec![Job::alone(us(900)), pre_empted(at + spread + 1, 2, 1)],
            )],
            None,
            true,
            1,
        );
        assert_eq!(
            (over[0].own(), over[0].alone, over[0].verdict.as_str()),
            (501 + spread, Some(414), EXCEEDS)
        );
        // The same observation with both runs a hardware task's: only the handler's part comes off twice, and the
        // job is above its bound by the difference, held against the handlers' spread.
        let by_handlers = rows(
            &bounds,
            &[("can_rx".into(), vec![pre_empted(at, 2, 0)])],
            None,
            true,
            1,
        );
        assert_eq!(
            (by_handlers[0].unstamped, by_handlers[0].own()),
            (2 * handler, 500 + dispatched - handler)
        );
        let handlers_spread = 2 * QEMU_PREEMPTION_BY_HANDLER_SPREAD_INSTRUCTIONS;
        assert_eq!(
            by_handlers[0].verdict.starts_with(NOT_HELD),
            dispatched - handler <= handlers_spread,
            "{}",
            by_handlers[0].verdict
        );
        // A dispatched count above the pre-emptions (a damaged input) is not taken off more than once per run.
        let capped = rows(
            &bounds,
            &[("can_rx".into(), vec![pre_empted(at, 2, 7)])],
            None,
            true,
            1,
        );
        assert_eq!(capped[0].unstamped, 2 * dispatched);
        // The timing file's stated figure (`unstamped_per_preemption`, 400 here) is not what is taken off.
        assert_ne!(r[0].unstamped, 800);
        // A task the timing file says runs a simulated device in QEMU, without its image's bound: held to the
        // release bound, which does not cover the device's code, and failed above it with that cause.
        if let Some(q) = bounds.trace.as_mut().and_then(|t| t.qemu.as_mut()) {
            q.other_code
                .insert("can_rx".into(), "the bxCAN register model".into());
        }
        let model = rows(
            &bounds,
            &[("can_rx".into(), vec![Job::alone(us(992))])],
            None,
            true,
            1,
        );
        assert!(
            model[0].verdict.starts_with(EXCEEDS)
                && model[0].verdict.contains("the bxCAN register model")
                && model[0]
                    .verdict
                    .ends_with("no bound of the QEMU image holds it"),
            "{}",
            model[0].verdict
        );
        // ... in QEMU only: a robot capture runs the release code.
        let robot_model = rows(
            &bounds,
            &[("can_rx".into(), vec![Job::alone(25.0)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot_model[0].verdict, EXCEEDS);
        if let Some(q) = bounds.trace.as_mut().and_then(|t| t.qemu.as_mut()) {
            q.other_code.clear();
        }
        // The job held is the one with the largest own figure: here the one that ran alone.
        let alone = rows(
            &bounds,
            &[(
                "can_rx".into(),
                vec![Job::alone(us(992)), pre_empted(at, 2, 1)],
            )],
            None,
            true,
            1,
        );
        assert_eq!(
            (alone[0].preemptions, alone[0].verdict.as_str()),
            (0, EXCEEDS)
        );
        // A robot capture's records are the ring's: nothing per pre-emption.
        let robot = rows(
            &bounds,
            &[("can_rx".into(), vec![pre_empted(72, 3, 1)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot[0].unstamped, 0);
    }

    #[test]
    fn the_clocks_busy_tick_is_a_pre_empting_run_and_its_plain_ticks_come_off_at_their_fewest() {
        let bounds = traced_bounds(&[]);
        let us = |n: u64| n as f64 * QEMU_NS_PER_INSTRUCTION / 1_000.0;
        let clock = QEMU_PREEMPTION_BY_CLOCK_FEWEST_INSTRUCTIONS;
        // Two plain ticks counted; the two stretches (before and after the clock's run) each crossed a boundary
        // whose tick may have run inside uncounted.
        let job = |n: u64, clocked: u32, handlers: u32, ticks: u32| Job {
            exec_us: us(n),
            preemptions: clocked + handlers,
            dispatched: 0,
            clocked,
            preempted_by: 0,
            events: 0,
            ticks,
            uncounted_ticks: ticks,
        };
        let held = |j: Job| rows(&bounds, &[("can_rx".into(), vec![j])], None, true, 1).remove(0);
        // can_rx's bound is 500: its records, one busy tick (a stamped run of the clock: its span is out of the
        // execution already, its unstamped part at its fewest comes off) and two plain ticks at their fewest.
        let at = 500 + QEMU_RECORDS_FEWEST_INSTRUCTIONS + clock + 2 * QEMU_TICK_FEWEST_INSTRUCTIONS;
        let within = held(job(at, 1, 0, 2));
        assert_eq!(
            (
                within.preemptions,
                within.clocked,
                within.dispatched,
                within.ticks,
                within.unstamped,
                within.own()
            ),
            (1, 1, 0, 2, clock + 2 * QEMU_TICK_FEWEST_INSTRUCTIONS, 500)
        );
        assert_eq!(within.verdict, "ok");
        // Above the bound by more than what is left unstamped and variable (the clock run's part beyond its
        // fewest, the two plain ticks' beyond theirs, a plain tick not counted in each of the two stretches):
        // it fails.
        let spread = QEMU_PREEMPTION_BY_CLOCK_SPREAD_INSTRUCTIONS
            + 2 * QEMU_TICK_SPREAD_INSTRUCTIONS
            + 2 * QEMU_TICK_MOST_INSTRUCTIONS;
        let edge = held(job(at + spread, 1, 0, 2));
        assert!(edge.verdict.starts_with(NOT_HELD), "{}", edge.verdict);
        let over = held(job(at + spread + 1, 1, 0, 2));
        assert_eq!((over.own(), over.verdict.as_str()), (501 + spread, EXCEEDS));
        // Taken for a hardware task's run instead, the clock's run would come off at the handler's fewest.
        let as_handler = held(job(at, 0, 1, 2));
        assert_eq!(
            as_handler.unstamped,
            QEMU_PREEMPTION_BY_HANDLER_FEWEST_INSTRUCTIONS + 2 * QEMU_TICK_FEWEST_INSTRUCTIONS
        );
        // A clock count above the pre-emptions (a damaged input) counts no run twice.
        let damaged = held(Job {
            preemptions: 1,
            clocked: 5,
            ..job(at, 0, 0, 0)
        });
        assert_eq!(damaged.unstamped, clock);
        // A robot capture has no clock runs or ticks to take off.
        let robot = rows(
            &bounds,
            &[("can_rx".into(), vec![job(100, 1, 0, 2)])],
            None,
            false,
            72_000_000,
        )
        .remove(0);
        assert_eq!(robot.unstamped, 0);
    }

    #[test]
    fn a_held_row_is_held_to_its_bound_and_a_loose_one_is_flagged() {
        // can_tx held (declined for the analysis, which keeps a stated budget): one frame's job 400, its whole job
        // 900; handle_commands held at 3 000; the accelerometer held, the gyroscope used.
        let held = |instructions: u64, job: Option<u64>| {
            serde_json::json!({ "task": "x", "cycles": null, "us": null, "instructions": null,
                "declined": "held back as its budget: a test",
                "held": { "cycles": instructions * 3, "us": instructions as f64 * 3.0 / 72.0,
                          "instructions": instructions, "reason": "a test",
                          "job": job.map(|j| serde_json::json!({ "cycles": j * 3, "us": j as f64 * 3.0 / 72.0,
                              "instructions": j, "per_activation": "a test" })) } })
        };
        let named = |task: &str, mut row: serde_json::Value| {
            row["task"] = task.into();
            row
        };
        let file = BoundsFile::from_json(
            "t.wcet.json",
            &serde_json::json!({
                "generated": format!("{} for a test", bounds::GENERATED_PREFIX),
                "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
                "clock_hz": 72_000_000, "wait_states": 2,
                "image": { "code_sha256": "0".repeat(64), "code_bytes": 4 },
                "tasks": [
                    named("can_tx", held(400, Some(900))),
                    named("handle_commands", held(3000, None)),
                    { "task": "can_rx", "cycles": 720, "us": 10.0, "instructions": 500, "declined": null },
                    { "task": "watchdog", "cycles": null, "us": null, "instructions": null,
                      "declined": "a loop without a bound" }
                ]
            })
            .to_string(),
        )
        .unwrap();
        let held_bounds = BoardBounds {
            file: "t.wcet.json".into(),
            bounds: Some(file),
            trace: None,
        };
        // 8 ns per instruction, each with its records' 486: can_tx 906 of its own (1 392 instructions, 11.136 µs),
        // handle_commands 1 405 (15.128 µs), can_rx 305 (6.328 µs), the watchdog declined by the machine code too.
        let r = rows(
            &held_bounds,
            &[
                ("can_tx".into(), vec![Job::alone(11.136)]),
                ("handle_commands".into(), vec![Job::alone(15.128)]),
                ("can_rx".into(), vec![Job::alone(6.328)]),
                ("watchdog".into(), vec![Job::alone(1.0)]),
            ],
            None,
            true,
            1,
        );
        // A held row with a whole job is held to the job's bound, not one frame's: 906 > 900.
        assert_eq!(
            (r[0].bound, r[0].held, r[0].verdict.as_str()),
            (Some(900), true, EXCEEDS)
        );
        // Held, within; more than twice what ran: loose, unexplained.
        assert_eq!(
            (r[1].bound, r[1].held, r[1].verdict.as_str()),
            (Some(3000), true, "ok")
        );
        assert_eq!(r[1].loose.as_deref(), Some("not explained"));
        // Used, within, and within 2× of what ran.
        assert_eq!(
            (r[2].bound, r[2].held, r[2].loose.as_deref()),
            (Some(500), false, None)
        );
        assert!(r[3].verdict.starts_with("declined: a loop"));
        // Exactly twice is tight.
        let twice = rows(
            &held_bounds,
            &[("handle_commands".into(), vec![Job::alone(15.928)])],
            None,
            true,
            1,
        );
        assert_eq!(twice[0].loose, None);
        // A robot capture holds the held row's cycles.
        let robot = rows(
            &held_bounds,
            &[("can_tx".into(), vec![Job::alone(1.0)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot[0].bound, Some(2700));
    }

    #[test]
    fn a_simulated_devices_task_is_held_to_the_qemu_images_own_bound_with_its_records_in_it() {
        // can_rx runs the bxCAN model in QEMU (other_code); its release bound is 500, its QEMU image's 2 000.
        let bounds = traced_bounds(&[("can_rx", "the bxCAN model")]);
        let image = |bound: Result<u64, String>| QemuImage {
            elf: "target/qemu/firmware/t".into(),
            tasks: [("can_rx".to_string(), bound)].into(),
        };
        let held = |exec_us: f64, image: Option<&QemuImage>| {
            rows_against(
                &bounds,
                &[(
                    "can_rx".into(),
                    vec![Job {
                        events: 1,
                        ticks: 1,
                        uncounted_ticks: 1,
                        ..Job::alone(exec_us)
                    }],
                )],
                None,
                true,
                1,
                image,
            )
            .remove(0)
        };
        let us = |n: u64| n as f64 * QEMU_NS_PER_INSTRUCTION / 1_000.0;
        // 2 000 instructions and its plain tick at its fewest; nothing off for the records or the event (the
        // image's bound holds them): 2 000, at the bound.
        let n = 2000 + QEMU_TICK_FEWEST_INSTRUCTIONS;
        let at = held(us(n), Some(&image(Ok(2000))));
        assert_eq!(
            (at.observed, at.trace_allowance, at.unstamped, at.own()),
            (n, 0, QEMU_TICK_FEWEST_INSTRUCTIONS, 2000)
        );
        assert_eq!(
            (at.bound, at.image, at.verdict.as_str()),
            (Some(2000), QEMU_IMAGE, "ok")
        );
        // One instruction more is within what its plain tick and one it could not count may run beyond the
        // tick's fewest: not proved above.
        let near = held(us(n + 1), Some(&image(Ok(2000))));
        assert_eq!(near.own(), 2001);
        assert!(near.verdict.starts_with(NOT_HELD), "{}", near.verdict);
        // One more than that fails: no NOT HELD for a simulated device once the image has its own bound.
        let spread = QEMU_TICK_SPREAD_INSTRUCTIONS + QEMU_TICK_MOST_INSTRUCTIONS;
        let over = held(us(n + spread + 1), Some(&image(Ok(2000))));
        assert_eq!(
            (over.own(), over.verdict.as_str()),
            (2001 + spread, EXCEEDS)
        );
        // The same job against the release bound, without the image's bound: the records, the event and the
        // plain tick off (486 + 1 617 + 63), nothing left within 500; 3 750 observed fails, nothing but a bound
        // that does not cover the device's code holding it.
        let release = held(16.336, None);
        assert_eq!(
            (release.image, release.trace_allowance, release.bound),
            (
                RELEASE,
                QEMU_RECORDS_FEWEST_INSTRUCTIONS + QEMU_EVENT_FEWEST_INSTRUCTIONS,
                Some(500)
            )
        );
        let far = held(30.0, None);
        assert!(far.verdict.starts_with(EXCEEDS), "{}", far.verdict);
        // The image's bound declined: failed above the release bound, with the machine code's reason.
        let declined = held(30.0, Some(&image(Err("a loop without a bound".into()))));
        assert_eq!(declined.image, RELEASE);
        assert!(
            declined.verdict.starts_with(EXCEEDS)
                && declined
                    .verdict
                    .ends_with("declined: a loop without a bound"),
            "{}",
            declined.verdict
        );
        // Either way the check fails on it: CI lets no job above its bound through without a bound that holds it.
        let bench = crate::bench::Bench {
            board: "t".into(),
            origin: "t".into(),
            build: "qemu".into(),
            model: "t".into(),
            clock_hz: 1,
            records: 0,
            damaged: 0,
            lost: 0,
            unbalanced: 0,
            span_us: 0.0,
            tasks: Vec::new(),
            topics: Vec::new(),
            machine_bounds: String::new(),
            machine: vec![declined, far, near],
            admitted: true,
        };
        let failed = bench.bound_failures();
        assert_eq!(failed.len(), 2, "{failed:?}");
        assert!(failed.iter().all(|f| f.starts_with("t/can_rx: ")));
        // A task that runs the release code is held to the release file whatever the image says.
        let release_code = rows_against(
            &bounds,
            &[("admit_requests".into(), vec![Job::alone(1.0)])],
            None,
            true,
            1,
            Some(&QemuImage {
                elf: "t".into(),
                tasks: [("admit_requests".to_string(), Ok(1))].into(),
            }),
        )
        .remove(0);
        assert_eq!(release_code.image, RELEASE);
        assert!(release_code.verdict.starts_with("declined: a loop"));
        // A robot capture (the release code) ignores the QEMU image.
        let robot = rows_against(
            &bounds,
            &[("can_rx".into(), vec![Job::alone(20.0)])],
            None,
            false,
            72_000_000,
            Some(&image(Ok(1))),
        )
        .remove(0);
        assert_eq!((robot.image, robot.bound), (RELEASE, Some(720)));
    }

    #[test]
    fn without_a_file_there_is_nothing_to_compare() {
        let none = BoardBounds {
            bounds: None,
            ..board_bounds()
        };
        assert!(rows(
            &none,
            &[("can_rx".into(), vec![Job::alone(1.0)])],
            None,
            true,
            1
        )
        .is_empty());
    }
}
