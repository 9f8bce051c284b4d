//! The files a model is built from: a board's timing file ([`Timing`]) and a scenario ([`Scenario`]), as serde
//! reads them (unknown fields refused).

use std::collections::BTreeMap;

use amiro_can::Priority;
use serde::Deserialize;

use super::bounded::{BoardBudgets, BudgetFrom};
use crate::bounds;
use crate::can;
use crate::model::{FrameCostSpec, Overheads};

/// A board's timing file.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    /// Board name (the firmware folder: `diwheeldrive`, `powermgmt`, `lightring`).
    pub board: String,
    /// Free text.
    #[serde(default)]
    pub note: Option<String>,
    /// The RTIC app to read; `null` while the board has none (tasks are then declared here).
    #[serde(default)]
    pub app: Option<AppSource>,
    /// Interrupt and dispatcher overheads.
    #[serde(default)]
    pub overheads: Overheads,
    /// What the firmware's task trace costs per job (a start and an end record), when the analysed
    /// build has it: added to every `hardware` and `software` job as interrupt entry and exit are.
    #[serde(default)]
    pub trace: Option<TraceCost>,
    /// The monotonic's timer interrupt, which wakes every timer-released task.
    #[serde(default)]
    pub monotonic: Option<Monotonic>,
    /// Publisher task per CAN priority (`urgent` … `low`); defaults to `publish_<level>`.
    #[serde(default = "default_publishers")]
    pub publishers: BTreeMap<String, String>,
    /// The task that acts on received commands (the end of a command's path).
    #[serde(default)]
    pub command_handler: Option<String>,
    /// The task that moves queued frames into the CAN controller.
    #[serde(default)]
    pub can_tx_task: Option<String>,
    /// Critical sections of `idle`, µs.
    #[serde(default)]
    pub idle_critical_sections_us: BTreeMap<String, f64>,
    /// Budgets per task (not the publisher tasks: their jobs are the topics).
    #[serde(default)]
    pub tasks: BTreeMap<String, TimingTask>,
    /// Budgets per published topic (one job of the publisher task per sample).
    #[serde(default)]
    pub topics: BTreeMap<String, TopicTiming>,
    /// The board's sensor buses (I2C) where a topic's `script` runs ([`crate::sensor_bus`]).
    #[serde(default)]
    pub sensor_buses: Vec<crate::sensor_bus::SensorBusModel>,
}

fn default_publishers() -> BTreeMap<String, String> {
    Priority::ALL
        .iter()
        .map(|p| (p.name().to_string(), format!("publish_{}", p.name())))
        .collect()
}

/// The cost of the firmware's task trace (`amiro_firmware::tracing`, cargo feature `feature`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TraceCost {
    /// The cargo feature that compiles the trace in (the analysed build has it).
    pub feature: String,
    /// One job's start and end records, µs.
    pub per_job_us: f64,
    /// Where the figure comes from.
    #[serde(default)]
    pub note: Option<String>,
    /// The traced QEMU build.
    #[serde(default)]
    pub qemu: Option<QemuBuild>,
}

/// How the traced QEMU build differs from the chip's (`Firmware::Qemu`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QemuBuild {
    /// The trace's cost per job in QEMU, µs (measured: deterministic under `-icount`).
    pub per_job_us: f64,
    /// Every budget of the board times this (≥ 1: QEMU is never assumed faster than the chip).
    #[serde(default = "one")]
    pub budget_scale: f64,
    /// What pends the transmit task in QEMU (absent: the robot's arrival, one job per frame).
    #[serde(default)]
    pub transmit: Option<QemuTransmit>,
    /// The QEMU build's stand-in for the bus: the task that replays the stimulus (absent: none).
    #[serde(default)]
    pub replay: Option<QemuReplay>,
    /// Instructions every run that pre-empts a traced job executes outside its own stamps, inside the
    /// pre-empted job's: at least its start record before that record's clock read and its end record
    /// after it (counted from the traced image, docs/bench.md "A pre-empting run's unstamped part").
    /// The bench takes this many per direct pre-emption off a job before holding it to its
    /// machine-code bound: a lower bound, so a job is never made smaller than what it ran itself.
    /// Absent: 0 (nothing taken off).
    #[serde(default)]
    pub unstamped_per_preemption: Option<UnstampedPerPreemption>,
    /// Tasks whose QEMU build runs code the release image has not (a device simulated in software inside the
    /// task: the bxCAN register model, the candump printer, the motor plant, the TLC5947 chain), each with what
    /// it runs. The release image's machine-code bound does not cover that code, so the bench prints such a
    /// task's jobs against it but does not hold them (docs/bench.md, "What the check holds").
    #[serde(default)]
    pub other_code: BTreeMap<String, String>,
    /// Where the figures come from.
    #[serde(default)]
    pub note: Option<String>,
}

/// What every pre-empting run executes unstamped inside the job it pre-empts, in the traced QEMU image.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct UnstampedPerPreemption {
    /// Instructions (at most the fewest any pre-emption executes outside its stamps).
    pub instructions: u64,
    /// How they were counted.
    pub note: String,
}

/// The task of the traced QEMU build that replays a run's stimulus: woken by the monotonic at each
/// received frame's time, it puts the frame into the virtual receive FIFO and pends the receive
/// interrupt. It exists only in QEMU (feature `qemu`), where it preempts the board's tasks once per
/// received frame, so the QEMU model has it as a job per received frame at its priority (read from the
/// app with the `qemu` feature), with the trace's and the dispatcher's cost per job like every task.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QemuReplay {
    /// The replay task's name in the app.
    pub task: String,
    /// One job (one frame delivered), µs in QEMU; not scaled by `budget_scale` (a QEMU figure).
    pub per_frame_us: f64,
    /// Where the figure comes from.
    #[serde(default)]
    pub note: Option<String>,
}

/// The transmit task of a QEMU build whose only frames are its publisher's samples.
///
/// QEMU's virtual mailboxes put a frame on the bus the moment it is offered: no transmit-complete
/// interrupt paces the transmit task. It runs when a publisher pends it after queueing a sample's
/// frames, and again at once while frames remain after three (`amiro_firmware::qemu::CanTxPort`):
/// ⌈frames / 3⌉ jobs per sample. So the task becomes one job per publisher job of the scenario
/// (`can_tx[topic]`, released by it) and one for the samples commands request (the task itself):
/// the command handler (`requests_from`) handles at most one command per its period, a request
/// wakes the publisher, and requests not yet served for one topic are one release — so in any
/// window at most one more per requestable topic than the handler's rate allows (the extra release
/// jitter of one period per topic).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QemuTransmit {
    /// The command handler whose commands request one-shot samples.
    pub requests_from: String,
    /// What the virtual mailbox costs per frame in QEMU, µs (it prints the frame's candump line),
    /// added to the transmit task's budget for each frame a job sends.
    #[serde(default)]
    pub frame_us: f64,
    /// Why this holds for the board.
    #[serde(default)]
    pub note: Option<String>,
}

/// The `frame-acked` records one job of the transmit task writes at most on the chip: one per
/// mailbox whose transmission completed (bxCAN has three).
pub const ACKS_PER_TRANSMIT_JOB: u64 = 3;

/// The frames one transmit job takes from the queue in QEMU (three virtual mailboxes).
pub const QEMU_FRAMES_PER_TRANSMIT_JOB: u64 = 3;

fn one() -> f64 {
    1.0
}

impl Timing {
    /// The timing with every execution budget, critical section and overhead times `factor`, except the stated
    /// peripheral waits of a budget bounded from the machine code (`budgets`' [`BudgetFrom::Bound`]
    /// `bus_wait_us`): a wait is the bus's time, not the CPU's, so a slower CPU does not lengthen it, and the
    /// budget becomes (budget − waits) × `factor` + waits ([`scaled_cpu`]). The traced QEMU build's simulated
    /// devices answer at once (its waits are about 0), so the unscaled stated waits still cover them. A best case
    /// is scaled the same way, with at most its whole self taken as waits. Critical sections and the sensor buses'
    /// engine rows are scaled whole (their waits too: only wider).
    pub(super) fn scaled(&self, factor: f64, budgets: &BoardBudgets) -> Timing {
        let mut t = self.clone();
        let f = factor.max(1.0);
        let waits = |row: &str| match budgets.rows.get(row) {
            Some(BudgetFrom::Bound { bus_wait_us, .. }) => *bus_wait_us,
            _ => 0.0,
        };
        t.overheads.isr_entry_us *= f;
        t.overheads.isr_exit_us *= f;
        t.overheads.dispatcher_us *= f;
        if let Some(m) = &mut t.monotonic {
            m.timer_isr_us *= f;
        }
        for v in t.idle_critical_sections_us.values_mut() {
            *v *= f;
        }
        for (name, task) in t.tasks.iter_mut() {
            let wait = waits(name);
            task.wcet_us = task.wcet_us.map(|w| scaled_cpu(w, wait, f));
            task.bcet_us = task.bcet_us.map(|w| scaled_cpu(w, wait, f));
            for v in task.critical_sections_us.values_mut() {
                *v *= f;
            }
            if let Some(m) = &mut task.measured {
                m.wcet_us *= f;
            }
        }
        for bus in &mut t.sensor_buses {
            bus.engine.per_event_us *= f;
            // The condition wait is the block's time, not the CPU's, but scaling it only widens the charge.
            for part in [&mut bus.engine.per_script, &mut bus.engine.condition_wait]
                .into_iter()
                .flatten()
            {
                part.us *= f;
            }
        }
        for (name, topic) in t.topics.iter_mut() {
            let wait = waits(&bounds::publisher_row(name));
            topic.wcet_us = scaled_cpu(topic.wcet_us, wait, f);
            topic.bcet_us = topic.bcet_us.map(|w| scaled_cpu(w, wait, f));
            for v in topic.critical_sections_us.values_mut() {
                *v *= f;
            }
            if let Some(m) = &mut topic.measured {
                m.wcet_us *= f;
            }
        }
        t
    }
}

/// A budget of `us` µs, of which `wait_us` are stated peripheral waits, on a CPU `factor` times slower: its CPU
/// part times `factor`, its waits as they are (`wait_us` taken as at most `us`, at least 0).
pub fn scaled_cpu(us: f64, wait_us: f64, factor: f64) -> f64 {
    let wait = wait_us.clamp(0.0, us.max(0.0));
    (us - wait) * factor + wait
}

/// A budget measured on a bench (`cargo xtask bench --calibrate`), kept beside the estimate.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Measured {
    /// The budget the analysis uses: the largest execution time seen times `margin`, µs.
    pub wcet_us: f64,
    /// The largest execution time seen, µs.
    pub max_us: f64,
    /// The margin `wcet_us` adds to `max_us`.
    pub margin: f64,
    /// Jobs measured.
    pub jobs: u64,
    /// The capture it came from.
    pub origin: String,
    /// `robot` (the real chip) or `qemu` (the emulator: not the chip's times).
    pub build: String,
}

/// The admission task's costliest step as measured in QEMU (`admit_requests`' budget rests on it): what
/// `cargo xtask analyze` prints beside the reservation, and what scenario `admission-search` holds its replay to (the
/// replay may not cost more than this record says).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WorstStep {
    /// Instructions the step executes of its own (pre-emptions taken out).
    pub instructions: u64,
    /// Its fixed-point iterations.
    pub iterations: u64,
    /// Where it was measured: the scenario and the image.
    pub measured_in: String,
    /// The chip's core clock the budget is for, MHz.
    pub clock_mhz: f64,
    /// The cycles per instruction assumed on that chip (an estimate until a robot measures it).
    pub cycles_per_instruction: f64,
}

impl WorstStep {
    /// The step's time on the chip, µs.
    pub fn on_chip_us(&self) -> f64 {
        self.us_for(self.instructions)
    }

    /// The time `instructions` take on this chip (its clock and cycles per instruction), µs.
    pub fn us_for(&self, instructions: u64) -> f64 {
        instructions as f64 * self.cycles_per_instruction / self.clock_mhz
    }
}

/// Where a board's app is.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AppSource {
    /// The file with `#[rtic::app]`, relative to the workspace root.
    pub source: String,
    /// A stand-in app description used while `source` is still a skeleton without any budgeted task.
    #[serde(default)]
    pub fallback: Option<String>,
    /// Cargo features the analysed build has (for `#[cfg(feature = ..)]` on tasks); none = the real board.
    #[serde(default)]
    pub features: Vec<String>,
}

/// The monotonic's timer interrupt.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Monotonic {
    /// Its RTIC/NVIC logical priority.
    pub priority: u32,
    /// Execution time of one timer interrupt (timer queue, waking one task), µs, entry/exit overheads excluded.
    pub timer_isr_us: f64,
    /// Tick length, µs: a wake-up comes up to one tick late.
    #[serde(default)]
    pub tick_us: f64,
}

/// How often a task is activated.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Arrival {
    /// At most once per frame on the bus: the shortest frame (47 bit times) apart.
    BusFrame,
    /// At most once per frame this board sends: the shortest of its frames apart (its transmit-complete
    /// interrupt); the shortest frame on the bus when it sends nothing.
    OwnFrame,
    /// Periodically, µs.
    PeriodicUs(f64),
    /// At most once per this many µs.
    SporadicUs(f64),
}

/// Budgets of one task.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct TimingTask {
    /// Priority — only for a board without an app (an app's priorities come from its source).
    #[serde(default)]
    pub priority: Option<u32>,
    /// Interrupt the task is bound to — only without an app; a task without one is a software task.
    #[serde(default)]
    pub binds: Option<String>,
    /// Shared resources — only without an app; defaults to the keys of `critical_sections_us`.
    #[serde(default)]
    pub shared: Option<Vec<String>>,
    /// Worst-case execution time, µs.
    #[serde(default)]
    pub wcet_us: Option<f64>,
    /// Best-case execution time, µs.
    #[serde(default)]
    pub bcet_us: Option<f64>,
    /// Activation pattern.
    #[serde(default)]
    pub arrival: Option<Arrival>,
    /// `"timer"` (woken by the monotonic) or the task that releases it.
    #[serde(default)]
    pub released_by: Option<String>,
    /// Release jitter of its own, µs.
    #[serde(default)]
    pub jitter_us: f64,
    /// Deadline, µs (default: the period). Not for the transmit task (`can_tx_task`), which has none of its own:
    /// its response is every message's queuing jitter (docs/analysis.md, "The transmit interrupt keeps no
    /// deadline").
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Longest critical section per resource, µs.
    #[serde(default)]
    pub critical_sections_us: BTreeMap<String, f64>,
    /// Free text: where the budget comes from.
    #[serde(default)]
    pub note: Option<String>,
    /// A measured budget; when present the analysis uses it instead of `wcet_us` (the estimate).
    #[serde(default)]
    pub measured: Option<Measured>,
    /// The admission task only: the costliest step measured in QEMU, which its estimate rests on.
    #[serde(default)]
    pub worst_step: Option<WorstStep>,
    /// The transmit task only (`can_tx_task`): every other task that puts frames in the transmit queue (its
    /// `tx_queue`) but is no publisher, with the most frames one job of it queues (each job pends the transmit
    /// interrupt once after them). Used where the machine code charges the transmit interrupt by its parts
    /// (docs/analysis.md, "The transmit interrupt's parts"): a publisher's frames per sample come from its topic.
    #[serde(default)]
    pub queued_by: Option<BTreeMap<String, QueuedBy>>,
    /// The script each job runs on one of the board's `sensor_buses` (PowerManagement's `power_monitor`), as a
    /// topic's; `wcet_us` is then the job's CPU alone.
    #[serde(default)]
    pub script: Option<crate::sensor_bus::ScriptModel>,
    /// A job of several scripts, in the order it runs them; instead of `script`.
    #[serde(default)]
    pub scripts: Option<Vec<crate::sensor_bus::ScriptModel>>,
}

/// What one task's jobs put in the transmit queue ([`TimingTask::queued_by`]).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QueuedBy {
    /// The most frames one job queues (0: none, and no pend).
    pub frames: u32,
    /// The shortest time between two of its jobs that queue frames, where it is not the task's period: the
    /// admission task's busy verdicts go out up to once per one-shot interval, counted from the send
    /// (`amiro_firmware::admission::BusyWindow`), more often than its stated 240 ms, µs.
    #[serde(default)]
    pub at_least_us: Option<f64>,
}

/// Budgets of one published topic: one job of the publisher task per sample.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct TopicTiming {
    /// Worst-case execution time of one sample (read, encode, queue every frame), µs.
    pub wcet_us: f64,
    /// Best-case execution time, µs (the earliest the frame can be queued).
    #[serde(default)]
    pub bcet_us: Option<f64>,
    /// Longest critical section per resource, µs.
    #[serde(default)]
    pub critical_sections_us: BTreeMap<String, f64>,
    /// Free text.
    #[serde(default)]
    pub note: Option<String>,
    /// A measured budget; when present the analysis uses it instead of `wcet_us` (the estimate).
    #[serde(default)]
    pub measured: Option<Measured>,
    /// The script the sample runs on one of the board's `sensor_buses`, suspending the publisher until it ends
    /// ([`crate::sensor_bus`]); `wcet_us` is then the sample's CPU alone.
    #[serde(default)]
    pub script: Option<crate::sensor_bus::ScriptModel>,
    /// A sample of several scripts, in the order the sample runs them (each submitted when the one before it
    /// ends and its `settle_us` has passed); instead of `script`.
    #[serde(default)]
    pub scripts: Option<Vec<crate::sensor_bus::ScriptModel>>,
}

/// A scenario: what runs on the robot.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: Option<String>,
    /// Bus bit rate (default 1 Mbit/s).
    #[serde(default = "default_bitrate")]
    pub bitrate: u32,
    /// Frame-cost model that decides the verdict (default exact).
    #[serde(default)]
    pub frame_cost: FrameCostSpec,
    /// Running sensor publishers.
    #[serde(default)]
    pub publishers: Vec<ScenarioPublisher>,
    /// Commands the operator sends.
    #[serde(default)]
    pub commands: Vec<ScenarioCommand>,
    /// One-shot requests (`once`) the operator sends: each analysed as a sample of its topic at its priority every
    /// [`amiro_can::ONE_SHOT_INTERVAL_MS`] (how often a board takes one at most), in place of the topic's publisher —
    /// what the boards' admission check decides a one-shot as.
    #[serde(default)]
    pub one_shots: Vec<ScenarioOneShot>,
    /// The failures the set is known to have, each named as the VERDICT names it (`bus/magnetometer-x`,
    /// `topic/magnetometer-x (end-to-end deadline)`): `cargo xtask analyze --check` passes only when exactly these
    /// fail (a set kept as a checked refusal; its description says why). Empty: everything must pass. A list holds
    /// on every revision; an object keyed by revision (`{"1-1": [...], "1-2": [...]}`) per revision
    /// ([`ExpectedFailures::on`]).
    #[serde(default)]
    pub expected_failures: ExpectedFailures,
}

/// A scenario's `expected_failures`: one list for every revision, or one per revision.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum ExpectedFailures {
    /// The same failures whatever the revision.
    All(Vec<String>),
    /// Per revision (a key is a revision as the boards' bounds files name theirs: `1-1`, `1-2`).
    PerRevision(BTreeMap<String, Vec<String>>),
}

impl Default for ExpectedFailures {
    fn default() -> Self {
        ExpectedFailures::All(Vec::new())
    }
}

impl ExpectedFailures {
    /// The failures expected of a build whose boards' images are of `revisions` (their bounds files' revisions): the
    /// list, or the list of the first key among `revisions`; none (everything must pass) when no key is.
    pub fn on(&self, revisions: &[&str]) -> Vec<String> {
        match self {
            ExpectedFailures::All(list) => list.clone(),
            ExpectedFailures::PerRevision(map) => map
                .iter()
                .find(|(k, _)| revisions.contains(&k.as_str()))
                .map(|(_, v)| v.clone())
                .unwrap_or_default(),
        }
    }
}

/// A one-shot request: a sensor topic's sample at a priority, asked for again and again.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioOneShot {
    /// Topic name as `amiro_can` spells it.
    pub topic: String,
    /// CAN priority.
    pub priority: String,
}

fn default_bitrate() -> u32 {
    can::DEFAULT_BITRATE
}

/// A sensor topic being published.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioPublisher {
    /// Topic name as `amiro_can` spells it (`gyroscope`, `proximity-ring`).
    pub topic: String,
    /// CAN priority: `urgent`, `high`, `medium` (or `normal`), `low`.
    pub priority: String,
    /// Sample period, µs.
    pub period_us: f64,
    /// Deadline from the sample's due time to its last frame on the bus, µs (default: the period).
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Budget for the delivery jitter, µs.
    #[serde(default)]
    pub jitter_budget_us: Option<f64>,
}

/// A command stream from the operator.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioCommand {
    /// Actuator topic (`motor`, `led-3`).
    pub topic: String,
    /// CAN priority.
    pub priority: String,
    /// Shortest time between two commands, µs.
    pub period_us: f64,
    /// The operator's queuing jitter, µs.
    #[serde(default)]
    pub jitter_us: f64,
    /// Deadline from sending to the board having acted, µs (default: the period).
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Budget for the jitter, µs.
    #[serde(default)]
    pub jitter_budget_us: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expected_failures_are_one_list_or_one_per_revision() {
        let all: ExpectedFailures = serde_json::from_str(r#"["bus/a"]"#).unwrap();
        assert_eq!(all.on(&["1-1"]), ["bus/a"]);
        assert_eq!(all.on(&[]), ["bus/a"]);
        let per: ExpectedFailures = serde_json::from_str(
            r#"{"1-1": ["bus/a", "topic/a (jitter budget)"], "1-2": ["bus/a"]}"#,
        )
        .unwrap();
        // A robot of 1-1: DiWheelDrive's file names 1-1, LightRing's 1-0.
        assert_eq!(
            per.on(&["1-1", "1-0"]),
            ["bus/a", "topic/a (jitter budget)"]
        );
        assert_eq!(per.on(&["1-2", "1-2"]), ["bus/a"]);
        // No board of a listed revision: nothing is expected to fail.
        assert!(per.on(&["1-0"]).is_empty());
        assert_eq!(
            ExpectedFailures::default().on(&["1-1"]),
            Vec::<String>::new()
        );
    }
}
