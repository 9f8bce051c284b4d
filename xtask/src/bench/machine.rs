//! Observed execution against the machine-code bounds: per task with a bound in the board's generated bounds
//! file (`schedule-analysis/models/<board>[-<rev>].wcet.json`), the largest execution observed beside the
//! bound, in instructions for a QEMU run (QEMU under `-icount` executes one instruction per 8 ns of virtual time)
//! or in cycles for a robot capture (the DWT cycle counter is the trace clock), and their ratio.
//!
//! The bounds are the release image's; the measured build is the traced one. A run's measured execution holds the
//! task trace's records (its start and end records, docs/bench.md), which the release image does not execute:
//! they are accounted for explicitly, as the timing file's `trace` cost per job (`trace.qemu.per_job_us` in QEMU,
//! `trace.per_job_us` on the chip), subtracted from the observation before it is held to the bound. In QEMU, so is
//! what each traced run that pre-empted the job executed of its own records outside its stamps (its start record
//! before the clock read, its end record after it), at the fewest instructions that can take (the timing file's
//! `trace.qemu.unstamped_per_preemption`, counted from the traced image: docs/bench.md, "A pre-empting run's
//! unstamped part"), once per direct pre-emption. Nothing else is subtracted: what the QEMU build executes beyond
//! the release image otherwise (its platform's console lines, the untraced timer interrupts counted to the task
//! they interrupt, a pre-emption's entry, dispatch and return beyond its records) makes an observation larger,
//! never smaller, so a run within its bound is within it.
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
    /// The trace records' part of it, per job, in `unit` (subtracted before the comparison).
    pub trace_allowance: u64,
    /// Traced runs that pre-empted that job directly.
    pub preemptions: u32,
    /// What they ran of their records inside it, at the fewest, in `unit` (subtracted before the comparison;
    /// QEMU only, 0 without the timing file's `trace.qemu.unstamped_per_preemption`).
    pub unstamped: u64,
    /// The bound, in `unit` (`None`: declined).
    pub bound: Option<u64>,
    /// `(observed − trace_allowance − unstamped) / bound`: at most 1 within the bound; below 0.5 the bound is more than twice
    /// what ran.
    pub ratio: Option<f64>,
    /// `ok`, `EXCEEDS BOUND`, or `declined: …`.
    pub verdict: String,
}

/// The verdict of a job above its bound (`--check` fails on it).
pub const EXCEEDS: &str = "EXCEEDS BOUND";

/// A task's bound in the file, in `unit`: its own row (its job's bound where the row is a charge per activation),
/// or — for a publisher task, whose run takes one sample of
/// each topic due — the sum of the rows of the topics the analysis has as its jobs (`publish_medium[magnetometer-x]`
/// → `publisher[magnetometer-x]`). `Some(Err(reason))` when a row is declined; `None` when the file has none.
fn bound_of(
    file: &BoundsFile,
    task: &str,
    analysed: Option<&BoardResult>,
    qemu: bool,
) -> Option<Result<u64, String>> {
    // A row charged per activation holds an observed job against its job's bound: a trace's job does not say
    // how many activations (frames) it served, and the job's bound holds every job, however many.
    let value = |row: &bounds::TaskBound| match (qemu, row.instructions, row.cycles, &row.job) {
        (true, _, _, Some(job)) => Ok(job.instructions),
        (false, _, _, Some(job)) => Ok(job.cycles),
        (true, Some(i), _, None) => Ok(i),
        (false, _, Some(c), None) => Ok(c),
        _ => Err(row
            .declined
            .clone()
            .unwrap_or_else(|| "no bound".to_string())),
    };
    if let Some(row) = file.task(task) {
        return Some(value(row));
    }
    let prefix = format!("{task}[");
    let topics: Vec<&str> = analysed?
        .tasks
        .iter()
        .filter(|t| t.job_of.as_deref() == Some(task))
        .filter_map(|t| t.name.strip_prefix(&prefix)?.strip_suffix(']'))
        .collect();
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
    Some(rows.iter().map(|r| value(r)).sum())
}

/// One observed job of a task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Job {
    /// Its execution, the stamped spans of the runs that pre-empted it taken out, µs.
    pub exec_us: f64,
    /// The traced runs that pre-empted it directly.
    pub preemptions: u32,
}

#[cfg(test)]
impl Job {
    /// A job no traced run pre-empted.
    pub fn alone(exec_us: f64) -> Job {
        Job {
            exec_us,
            preemptions: 0,
        }
    }
}

/// The rows of `tasks` (task name, its observed jobs) against the board's bounds, for a QEMU run (`qemu`)
/// or a robot capture at `clock_hz`: each task's job with the largest own figure, held to its bound.
pub fn rows(
    bounds: &BoardBounds,
    tasks: &[(String, Vec<Job>)],
    analysed: Option<&BoardResult>,
    qemu: bool,
    clock_hz: u64,
) -> Vec<MachineRow> {
    let Some(file) = &bounds.bounds else {
        return Vec::new();
    };
    let (unit, per_us) = if qemu {
        ("instructions", 1_000.0 / QEMU_NS_PER_INSTRUCTION)
    } else {
        ("cycles", clock_hz as f64 / 1e6)
    };
    let trace_us = bounds.trace.as_ref().map_or(0.0, |t| {
        if qemu {
            t.qemu.as_ref().map_or(t.per_job_us, |q| q.per_job_us)
        } else {
            t.per_job_us
        }
    });
    let trace_allowance = (trace_us * per_us).floor() as u64;
    // A robot capture's records are the ring's (no write-through): nothing is known of them per pre-emption.
    let per_preemption = match (qemu, &bounds.trace) {
        (true, Some(t)) => t
            .qemu
            .as_ref()
            .and_then(|q| q.unstamped_per_preemption.as_ref())
            .map_or(0, |u| u.instructions),
        _ => 0,
    };
    let mut out = Vec::new();
    for (task, jobs) in tasks {
        let Some(bound) = bound_of(file, task, analysed, qemu) else {
            continue;
        };
        // (own, observed, pre-emptions, unstamped) of each job; the largest own figure is the one held.
        let Some((own, observed, preemptions, unstamped)) = jobs
            .iter()
            .map(|j| {
                let observed = (j.exec_us * per_us).round() as u64;
                let unstamped = u64::from(j.preemptions) * per_preemption;
                let own = observed
                    .saturating_sub(trace_allowance)
                    .saturating_sub(unstamped);
                (own, observed, j.preemptions, unstamped)
            })
            .max()
        else {
            continue;
        };
        let (bound, ratio, verdict) = match bound {
            Ok(b) => {
                let ratio = (b > 0).then(|| own as f64 / b as f64);
                let verdict = if own > b {
                    EXCEEDS.to_string()
                } else {
                    "ok".to_string()
                };
                (Some(b), ratio, verdict)
            }
            Err(reason) => (None, None, format!("declined: {reason}")),
        };
        out.push(MachineRow {
            task: task.clone(),
            unit,
            observed,
            trace_allowance,
            preemptions,
            unstamped,
            bound,
            ratio,
            verdict,
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
        // 12 µs of trace per job = 1500 instructions at 8 ns.
        let rows = rows(
            &board_bounds(),
            &[
                ("can_rx".into(), vec![Job::alone(16.0)]), // 2000 instructions: 500 once the trace is out
                ("admit_requests".into(), vec![Job::alone(100.0)]), // declined
                ("stimulus".into(), vec![Job::alone(5.0)]), // no row: not listed
            ],
            None,
            true,
            120_000_000,
        );
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].observed, 2000);
        assert_eq!(rows[0].trace_allowance, 1500);
        assert_eq!(rows[0].bound, Some(500));
        assert_eq!(rows[0].verdict, "ok");
        assert_eq!(rows[0].ratio, Some(1.0));
        assert!(rows[1].verdict.starts_with("declined: a loop"));
        // One instruction more than the bound and the trace: above it.
        let over = super::rows(
            &board_bounds(),
            &[("can_rx".into(), vec![Job::alone(16.008)])],
            None,
            true,
            120_000_000,
        );
        assert_eq!(over[0].observed, 2001);
        assert_eq!(over[0].verdict, EXCEEDS);
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
        // 2 400 instructions, 900 once the trace is out: a job of three frames, above one frame's 300 but within
        // the job's bound.
        let held = rows(
            &charged,
            &[("can_rx".into(), vec![Job::alone(19.2)])],
            None,
            true,
            1,
        );
        assert_eq!((held[0].bound, held[0].verdict.as_str()), (Some(900), "ok"));
        let over = rows(
            &charged,
            &[("can_rx".into(), vec![Job::alone(19.208)])],
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
    fn a_pre_empted_job_is_held_after_the_unstamped_records_of_what_pre_empted_it() {
        // QEMU: 8 µs of trace per job = 1000 instructions; 400 instructions unstamped per pre-emption.
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
                note: None,
            }),
        });
        let pre_empted = |exec_us: f64, preemptions: u32| Job {
            exec_us,
            preemptions,
        };
        // can_rx's bound is 500. Pre-empted twice, 2 300 observed: 1 000 its records, 800 the pre-empting
        // runs', 500 its own, within; alone, 1 400 observed: 400 its own. The held job is the pre-empted one.
        let r = rows(
            &bounds,
            &[("can_rx".into(), vec![Job::alone(11.2), pre_empted(18.4, 2)])],
            None,
            true,
            1,
        );
        assert_eq!(
            (r[0].observed, r[0].preemptions, r[0].unstamped),
            (2300, 2, 800)
        );
        assert_eq!((r[0].verdict.as_str(), r[0].ratio), ("ok", Some(1.0)));
        // One instruction more: above.
        let over = rows(
            &bounds,
            &[("can_rx".into(), vec![pre_empted(18.408, 2)])],
            None,
            true,
            1,
        );
        assert_eq!(over[0].verdict, EXCEEDS);
        // Nothing is taken off a job no run pre-empted: one above its bound stays above.
        let alone = rows(
            &bounds,
            &[(
                "can_rx".into(),
                vec![Job::alone(12.008), pre_empted(18.4, 2)],
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
            &[("can_rx".into(), vec![pre_empted(1.0, 3)])],
            None,
            false,
            72_000_000,
        );
        assert_eq!(robot[0].unstamped, 0);
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
