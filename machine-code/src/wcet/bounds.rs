//! The bounds file: what the machine code cannot tell, stated with a reason. Keyed by the function
//! (demangled name without hash, as the analysis names it) and the source file and line the DWARF
//! line table gives for the loop or call — never an address, which changes with every build.
//!
//! ```json
//! {
//!   "loops": [{ "function": "…", "file": "src/tasks.rs", "line": 42, "bound": 9, "body": 8,
//!               "reason": "the heapless::Vec holds at most 8 frames: 8 passes and the one that ends" }],
//!   "waits": [{ "function": "…", "file": "src/i2c.rs", "line": 120, "wait_us": 25.0,
//!               "source": "one I2C byte at 400 kHz: 9 bit times (UM10204 §3.1)" }],
//!   "indirect": [{ "function": "…", "file": "src/waker.rs", "line": 7,
//!                  "targets": ["…::wake"], "reason": "the only waker vtable in the image" },
//!                { "function": "…", "file": "src/waker.rs", "line": 9,
//!                  "vtable_entry": { "objects": ["…::WAKER_VTABLE"], "entry": 0 },
//!                  "reason": "a clone of a waker of one of these vtables" }],
//!   "lengths": [{ "function": "…", "file": "heapless/src/vec/mod.rs", "line": 728, "register": 2,
//!                 "bytes": 180, "reason": "shifts at most 15 frames of 12 bytes" }],
//!   "per_element": [{ "function": "…::Encoder::put", "register": 2,
//!                     "reason": "one pass per byte of its slice argument" }],
//!   "tasks": [{ "name": "monotonic", "symbol": "TIM5", "handler": true,
//!               "reason": "the TIM5 monotonic's compare interrupt (board.rs)" }],
//!   "jobs": [{ "function": "UART4", "file": "src/tasks.rs", "line": 150,
//!              "reason": "the watchdog's period: a delay ready at once is the next release" }],
//!   "totals": [{ "function": "…", "file": "src/busy_window.rs", "line": 829, "passes": 500,
//!                "reason": "every pass back is one of the job's at most 500 fixed-point iterations" }],
//!   "per_activation": [{ "task": "can_rx", "function": "…", "file": "src/bxcan.rs", "line": 125,
//!                        "passes": 2, "reason": "a job that drains k frames costs at most k times one frame's" }],
//!   "transactions": [{ "function": "…::Master::read_register", "register": 3, "fixed_us": 126.0,
//!                      "per_byte_us": 25.2, "waits": [{ "function": "…::Master::wait", "file": "src/i2c.rs",
//!                      "line": 109 }], "reason": "the flags of one transfer wait in sum at most its wire time" }],
//!   "per_frame": [{ "task": "can_tx", "function": "…", "file": "src/tx_queue.rs", "line": 372,
//!                   "completion": "…::collect_completions::{{closure}}", "completions": 3,
//!                   "requeue": "…::TxQueue<_>::place", "reason": "a job costs at most F + q·P + s·S + a·(S + R)" }]
//! }
//! ```
//!
//! `file` matches the end of the line table's path (`src/tasks.rs` matches
//! `/work/amiro-firmware/src/tasks.rs`). A target of an indirect call stands for every function of
//! that name.
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::Error;

/// A loop's stated bound: the most times its header runs per entry (`bound`), and, where stated,
/// the most of those passes that go on past the header into the rest of the loop (`body`: a loop
/// whose header's test ends it on its last run, `for x in ..` over at most k elements, makes k + 1
/// header runs and k passes on). Without `body` a way out from inside the body is charged after
/// `bound` − 1 whole passes; with it, after `body` − 1 ([`super::path::LoopCount::Body`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopBound {
    pub function: String,
    pub file: String,
    pub line: u32,
    pub bound: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body: Option<u64>,
    pub reason: String,
}

/// A wait on a peripheral: the loop polls for at most `wait_us`, the peripheral's stated
/// worst-case latency (not the timeout: that is the fault path).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaitBound {
    pub function: String,
    pub file: String,
    pub line: u32,
    pub wait_us: f64,
    pub source: String,
}

/// A function a job calls at most `calls` times in all, wherever it calls it (the bus clear, which only a
/// failed transfer runs, after which the job makes no transfer): the job's bound charges it that many times
/// its longest call, in place of each call on the longest path (as [`TotalBound`] charges a loop). The
/// reason says why no job calls it more often.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CallTotal {
    pub function: String,
    pub calls: u64,
    pub reason: String,
}

/// A stated wait's place (`function`, `file`, `line`, as [`WaitBound`] keys it), named by a
/// [`TransactionCap`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaitPlace {
    pub function: String,
    pub file: String,
    pub line: u32,
}

impl WaitPlace {
    /// Whether this names the wait `w`.
    pub fn names(&self, w: &WaitBound) -> bool {
        self.function == w.function && self.line == w.line && same_file(&w.file, &self.file)
    }
}

/// A cap on the sum of the stated waits of one call of a bus transaction's function: the waits at
/// `waits` (the polled flags of the transfer) that the call and its callees make wait at most
/// `fixed_us` + `per_byte_us` × the call's length in argument `register` in sum (without
/// `register`, `fixed_us`), because each such wait ends when the bus reaches a state of this
/// transfer, the waits are disjoint spans of the CPU's time, and the bus moves on from one state to
/// the next only within the transfer's wire time (plus what its devices stretch it by, stated in
/// the figures). The function's bound is then its machine-code cycles plus the smaller of the sum
/// of those waits on its longest path and the cap (the other waits charged as ever): the smaller of
/// its bound with the waits at their stated figures, and its bound with them at nothing plus the
/// cap (docs/analysis.md, "The bus transaction's cap"). The reason says why the waits are within
/// the cap: which bus events it counts, at which bit time, and which devices may stretch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransactionCap {
    pub function: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub register: Option<u8>,
    pub fixed_us: f64,
    #[serde(default)]
    pub per_byte_us: f64,
    pub waits: Vec<WaitPlace>,
    pub reason: String,
}

impl CallTotal {
    /// Checks it has a count of at least 1 and a reason.
    fn check(&self) -> Result<(), Error> {
        if self.calls == 0 || self.reason.trim().is_empty() {
            return Err(Error::Bounds(format!(
                "the calls in total of {} need a count of at least 1 and a reason",
                self.function
            )));
        }
        Ok(())
    }
}

impl TransactionCap {
    /// The cap in nanoseconds for a call whose argument registers are bounded by `args`: `None`
    /// where it names a length register the call does not bound.
    pub fn cap_ns(&self, args: &[Option<u32>; 4]) -> Option<u64> {
        let bytes = match self.register {
            Some(r) => f64::from(args[usize::from(r)]?),
            None => 0.0,
        };
        Some(((self.fixed_us + self.per_byte_us * bytes) * 1000.0).ceil() as u64)
    }

    /// Checks the figures are finite and not negative, the register an argument's (0-3), and that
    /// it names waits and has a reason.
    fn check(&self, whose: &str) -> Result<(), Error> {
        let figure = |x: f64| x.is_finite() && x >= 0.0;
        if !figure(self.fixed_us)
            || !figure(self.per_byte_us)
            || self.register.is_some_and(|r| r > 3)
            || (self.per_byte_us > 0.0 && self.register.is_none())
            || self.waits.is_empty()
            || self.reason.trim().is_empty()
        {
            return Err(Error::Bounds(format!(
                "the transaction cap of {} ({whose}) needs figures ≥ 0 (a per-byte one with its length \
                 register, 0-3), the waits it holds and a reason",
                self.function
            )));
        }
        Ok(())
    }
}

/// The functions a call through a register at a place may reach: named (`targets`), or found in
/// the image (`stored_with`: the functions whose addresses the code that takes the named data
/// object's address uses as data, [`super::stored`]; `vtable_entry`: the function each named
/// vtable holds at one entry). One of the three.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IndirectTargets {
    pub function: String,
    pub file: String,
    pub line: u32,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub targets: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stored_with: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vtable_entry: Option<VtableEntry>,
    pub reason: String,
}

/// The functions at one entry of named vtables (data objects of function addresses): a call through
/// a function pointer loaded from word `entry` of a vtable the value may be (a `Waker`'s clone is
/// entry 0 of its `RawWakerVTable`, wake 1, wake_by_ref 2, drop 3). The image gives each function:
/// named by its object, not by its own name, which a closure or a shim (`FnOnce::call_once`) shares
/// with others.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VtableEntry {
    /// The vtables (data objects, demangled names without hash).
    pub objects: Vec<String>,
    /// The word of each.
    pub entry: u32,
}

/// The most bytes a call of a memory function (`memcpy`, `memset`, …) at a place moves, where its
/// machine code does not fix the length: the argument `register` is at most `bytes`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LengthBound {
    pub function: String,
    pub file: String,
    pub line: u32,
    pub register: u8,
    pub bytes: u32,
    pub reason: String,
}

/// A function whose every loop passes at most once per element of a slice argument, whose length is in
/// `register` (0-3): bounded per call by the length its caller passes (as the memory functions are).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerElement {
    pub function: String,
    pub register: u8,
    pub reason: String,
}

/// A task the image's RTIC app does not declare as one (the monotonic's timer interrupt): its name,
/// the function it runs, and whether that is an exception handler.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskSpec {
    pub name: String,
    pub symbol: String,
    #[serde(default)]
    pub handler: bool,
    pub reason: String,
}

/// A task whose bound the generated file does not give the analysis as its budget yet, with why: the
/// bound is sound but known to be loose (named), and used as the budget it would break the boards'
/// sets. The generated row says it is held, with the figures, and the analysis keeps the stated
/// budget (docs/analysis.md, "Held bounds"). `task` is a row's name, or `publisher[*]` for every
/// topic's row. `revisions`, where given, names the board's revisions whose images hold it back (the
/// others use the bound); without it every image of the board holds it back.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeldBound {
    pub task: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub revisions: Option<Vec<String>>,
    pub reason: String,
}

/// A held bound's `revisions` names a revision the board has no image for ([`HeldBound::holds_on`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownRevision {
    /// The held row (`task` of the statement).
    pub task: String,
    /// The revision it names.
    pub revision: String,
    /// The board's revisions.
    pub known: Vec<String>,
}

impl std::fmt::Display for UnknownRevision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the held bound of {} names revision `{}`, which the board has no image for (its revisions: {})",
            self.task,
            self.revision,
            self.known.join(", ")
        )
    }
}

impl std::error::Error for UnknownRevision {}

impl HeldBound {
    /// Whether this statement names the generated row `task`.
    pub fn names(&self, task: &str) -> bool {
        self.task == task || (self.task == "publisher[*]" && task.starts_with("publisher["))
    }

    /// Whether the image of the board's revision `revision` holds this bound back: every image when
    /// the statement lists no `revisions`, else the ones it lists. Each listed revision must be one of
    /// `known` (the board's revisions), else [`UnknownRevision`] names it.
    pub fn holds_on(&self, revision: &str, known: &[&str]) -> Result<bool, UnknownRevision> {
        let Some(listed) = &self.revisions else {
            return Ok(true);
        };
        if let Some(r) = listed.iter().find(|r| !known.contains(&r.as_str())) {
            return Err(UnknownRevision {
                task: self.task.clone(),
                revision: r.clone(),
                known: known.iter().map(|k| k.to_string()).collect(),
            });
        }
        Ok(listed.iter().any(|r| r == revision))
    }
}

/// An async task's loop, named at the `.await` its jobs end at: one job (one poll of the task, from
/// its resume to the next `await` that is pending) makes at most one pass of the loop, because that
/// `await` ready at once is the task's next release, which the response-time analysis counts as a
/// job of its own. The analysis counts the loop, entered at that `await`, as two runs of its header
/// (the resume and the `await` the job parks at) — [`JOB_PASSES`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobLoop {
    pub function: String,
    pub file: String,
    pub line: u32,
    pub reason: String,
}

/// The runs of an async task's loop header in one job ([`JobLoop`]): the `await` it resumes at,
/// and the one it parks at after its pass.
pub const JOB_PASSES: u64 = 2;

/// A loop whose passes back to its header are capped for the whole job, however often the job enters
/// it (a budget of iterations the code counts across calls): at most `passes` in total per job. Several
/// loops the analysis names at one place (a loop the compiler split in two, or one whose header has no
/// line of its own) share the statement: `passes` counts their passes back together.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TotalBound {
    pub function: String,
    pub file: String,
    pub line: u32,
    pub passes: u64,
    pub reason: String,
}

/// A task whose activations are not its jobs: one job serves every activation that arrived by then (a
/// receive interrupt drains every frame its FIFO holds), so the analysis charges it per activation, and
/// that charge is the task's bound with the stated loop at `file:line` in `function` (its header runs,
/// as [`LoopBound::bound`]) at `passes` — one activation's pass and the one that ends — in place of its
/// bound per job. The reason says why a job that serves k activations costs at most k such charges.
/// The loop must be one the file states under `loops`, at a bound of at least `passes`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerActivation {
    pub task: String,
    pub function: String,
    pub file: String,
    pub line: u32,
    pub passes: u64,
    pub reason: String,
}

/// A transmit interrupt charged by its parts ([`super::FrameBound`]): a fixed part once per job, a pass
/// of its transmit loop (`function` at `file:line`, stated under `loops`: one pass fills one mailbox) per
/// frame it puts in a mailbox, a completion per completion it collects (the scan calls `completion`
/// once per pass of a loop of `completions` passes, one per mailbox), and the requeue per aborted frame
/// (`requeue`: a function only an aborted frame's completion calls). Each part comes from the machine
/// code: the task bounded with the transmit loop at 1 and 2 passes and with `completion` or `requeue`
/// left out. The reason says why a job costs at most the fixed part plus its passes, completions and
/// requeues.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerFrame {
    pub task: String,
    pub function: String,
    pub file: String,
    pub line: u32,
    pub completion: String,
    pub completions: u64,
    pub requeue: String,
    pub reason: String,
}

/// The stated bounds of one image (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundsFile {
    #[serde(default)]
    pub loops: Vec<LoopBound>,
    #[serde(default)]
    pub waits: Vec<WaitBound>,
    #[serde(default)]
    pub indirect: Vec<IndirectTargets>,
    #[serde(default)]
    pub lengths: Vec<LengthBound>,
    #[serde(default)]
    pub per_element: Vec<PerElement>,
    /// Tasks besides the app's own (for `cargo xtask wcet BOARD`).
    #[serde(default)]
    pub tasks: Vec<TaskSpec>,
    /// Async tasks' loops: one pass per job.
    #[serde(default)]
    pub jobs: Vec<JobLoop>,
    /// Loops capped in total per job ([`TotalBound`]).
    #[serde(default)]
    pub totals: Vec<TotalBound>,
    /// Tasks whose bound is not the analysis' budget yet ([`HeldBound`]).
    #[serde(default)]
    pub held: Vec<HeldBound>,
    /// Tasks charged per activation, not per job ([`PerActivation`]).
    #[serde(default)]
    pub per_activation: Vec<PerActivation>,
    /// Transmit interrupts charged by their parts, per job, frame and abort ([`PerFrame`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub per_frame: Vec<PerFrame>,
    /// Caps on the sum of a bus transaction's flag waits per call ([`TransactionCap`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transactions: Vec<TransactionCap>,
    /// Functions called at most a stated number of times per job ([`CallTotal`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub calls: Vec<CallTotal>,
    /// The publisher's release loop and its topic groups: a bound per topic's job
    /// ([`PerTopic`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topics: Option<PerTopic>,
}

/// The bounds file's `topics`: the publisher's release loop and its topic groups, for a bound per
/// topic's job ([`super::topics`] says how it is used).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerTopic {
    /// The release loop (`for release in releases`), as the analysis names it.
    pub function: String,
    pub file: String,
    pub line: u32,
    /// Why one job's releases each cost at most one topic's bound.
    pub reason: String,
    pub groups: Vec<TopicGroup>,
}

/// Topics whose job calls the same sample functions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicGroup {
    /// The name the report gives the group (`compass`, `diagnostics`).
    pub name: String,
    /// Its topics (`magnetometer-x`, as the timing file names them).
    pub topics: Vec<String>,
    /// The functions (demangled, without hash) only a job of these topics calls.
    pub functions: Vec<String>,
    /// The waits of this group's jobs, in place of the file's at the same places (`function`, `file`,
    /// `line`): the stated latency of the devices its sample addresses.
    #[serde(default)]
    pub waits: Vec<WaitBound>,
    /// Loop bounds of this group's jobs, in place of the file's at the same places (how many frames
    /// this group's sample holds, where the file states the most of any sample).
    #[serde(default)]
    pub loops: Vec<LoopBound>,
    /// Transaction caps of this group's jobs, in place of the file's for the same function (the
    /// wire time and the stretch of the devices its sample addresses).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transactions: Vec<TransactionCap>,
    /// Calls in total per job of this group's jobs, in place of the file's for the same function.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub calls: Vec<CallTotal>,
    /// Why only a job of these topics calls `functions` (the sampler's dispatch), and the waits'.
    pub reason: String,
}

impl PerTopic {
    /// Checks every group has topics, functions and a reason, and each wait has a positive figure
    /// and a source.
    fn check(&self) -> Result<(), Error> {
        if self.reason.trim().is_empty() || self.groups.is_empty() {
            return Err(Error::Bounds(format!(
                "the per-topic statement at {}:{} in {} needs its groups and a reason",
                self.file, self.line, self.function
            )));
        }
        for g in &self.groups {
            if g.topics.is_empty() || g.functions.is_empty() || g.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the topic group {} needs its topics, the functions only its jobs call and a reason",
                    g.name
                )));
            }
            for l in &g.loops {
                if l.bound == 0 || l.reason.trim().is_empty() {
                    return Err(Error::Bounds(format!(
                        "the loop of topic group {} at {}:{} in {} needs a bound of at least 1 and a reason",
                        g.name, l.file, l.line, l.function
                    )));
                }
            }
            for c in &g.transactions {
                c.check(&format!("topic group {}", g.name))?;
            }
            for c in &g.calls {
                c.check()?;
            }
            for w in &g.waits {
                if !(w.wait_us.is_finite() && w.wait_us > 0.0) || w.source.trim().is_empty() {
                    return Err(Error::Bounds(format!(
                        "the wait of topic group {} at {}:{} in {} needs a positive wait_us and its source",
                        g.name, w.file, w.line, w.function
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Whether a line-table path is the stated `file`.
pub(crate) fn same_file(path: &str, file: &str) -> bool {
    let file = file.trim_start_matches("./");
    path == file || path.ends_with(&format!("/{file}"))
}

impl BoundsFile {
    /// Parses the JSON of a bounds file and checks every entry has a reason and a usable figure.
    pub fn parse(json: &str) -> Result<BoundsFile, Error> {
        let file: BoundsFile =
            serde_json::from_str(json).map_err(|e| Error::Bounds(e.to_string()))?;
        for l in &file.loops {
            if l.bound == 0 || l.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the loop at {}:{} in {} needs a bound of at least 1 and a reason",
                    l.file, l.line, l.function
                )));
            }
        }
        for w in &file.waits {
            if !(w.wait_us.is_finite() && w.wait_us > 0.0) || w.source.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the wait at {}:{} in {} needs a positive wait_us and its source",
                    w.file, w.line, w.function
                )));
            }
        }
        for i in &file.indirect {
            let ways = usize::from(!i.targets.is_empty())
                + usize::from(i.stored_with.is_some())
                + usize::from(
                    i.vtable_entry
                        .as_ref()
                        .is_some_and(|v| !v.objects.is_empty()),
                );
            let empty_vtables = i
                .vtable_entry
                .as_ref()
                .is_some_and(|v| v.objects.is_empty());
            if ways != 1 || empty_vtables || i.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the indirect call at {}:{} in {} needs its targets, the object they are \
                     stored with or the vtables whose entry they are (one of the three) and a reason",
                    i.file, i.line, i.function
                )));
            }
        }
        for l in &file.lengths {
            if l.register > 3 || l.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the length at {}:{} in {} needs an argument register (0-3) and a reason",
                    l.file, l.line, l.function
                )));
            }
        }
        for j in &file.jobs {
            if j.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the task's loop at {}:{} in {} needs a reason (what its `await` waits for)",
                    j.file, j.line, j.function
                )));
            }
        }
        for h in &file.held {
            if h.revisions.as_ref().is_some_and(|r| r.is_empty()) {
                return Err(Error::Bounds(format!(
                    "the held bound of {} lists no revisions (leave `revisions` out to hold it on every image)",
                    h.task
                )));
            }
            if h.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the held bound of {} needs a reason (what makes it loose)",
                    h.task
                )));
            }
        }
        for t in &file.totals {
            if t.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the total at {}:{} in {} needs a reason",
                    t.file, t.line, t.function
                )));
            }
        }
        for a in &file.per_activation {
            let stated = file.loop_bound(&a.function, &a.file, a.line);
            if a.passes == 0 || a.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the per-activation charge of {} needs passes of at least 1 and a reason",
                    a.task
                )));
            }
            match stated {
                Some(l) if l.bound >= a.passes => {}
                Some(l) => {
                    return Err(Error::Bounds(format!(
                    "the per-activation charge of {} takes the loop at {}:{} in {} at {} passes, \
                         more than its stated bound of {}",
                    a.task, a.file, a.line, a.function, a.passes, l.bound
                )))
                }
                None => {
                    return Err(Error::Bounds(format!(
                        "the per-activation charge of {} names the loop at {}:{} in {}, which the \
                         file does not state under `loops`",
                        a.task, a.file, a.line, a.function
                    )))
                }
            }
        }
        for f in &file.per_frame {
            if f.completions == 0
                || f.reason.trim().is_empty()
                || f.completion.trim().is_empty()
                || f.requeue.trim().is_empty()
            {
                return Err(Error::Bounds(format!(
                    "the per-frame charge of {} needs its completion and requeue functions, \
                     completions of at least 1 and a reason",
                    f.task
                )));
            }
            match file.loop_bound(&f.function, &f.file, f.line) {
                Some(l) if l.bound >= 2 => {}
                _ => {
                    return Err(Error::Bounds(format!(
                        "the per-frame charge of {} names the loop at {}:{} in {}, which the file \
                         does not state under `loops` at a bound of at least 2",
                        f.task, f.file, f.line, f.function
                    )))
                }
            }
        }
        for c in &file.transactions {
            c.check("the file's")?;
        }
        for c in &file.calls {
            c.check()?;
        }
        if let Some(t) = &file.topics {
            t.check()?;
        }
        for p in &file.per_element {
            if p.register > 3 || p.reason.trim().is_empty() {
                return Err(Error::Bounds(format!(
                    "the per-element function {} needs its length register (0-3) and a reason",
                    p.function
                )));
            }
        }
        Ok(file)
    }

    /// Reads and parses a bounds file.
    pub fn read(path: &Path) -> Result<BoundsFile, Error> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        BoundsFile::parse(&text).map_err(|e| Error::Bounds(format!("{}: {e}", path.display())))
    }

    /// The stated bound of the loop at `file:line` in `function`.
    pub fn loop_bound(&self, function: &str, file: &str, line: u32) -> Option<&LoopBound> {
        self.loops
            .iter()
            .find(|l| l.function == function && l.line == line && same_file(file, &l.file))
    }

    /// The stated wait of the loop at `file:line` in `function`.
    pub fn wait(&self, function: &str, file: &str, line: u32) -> Option<&WaitBound> {
        self.waits
            .iter()
            .find(|w| w.function == function && w.line == line && same_file(file, &w.file))
    }

    /// The stated calls in total per job of `function`, if any.
    pub fn call_total(&self, function: &str) -> Option<&CallTotal> {
        self.calls.iter().find(|c| c.function == function)
    }

    /// The transaction cap of `function`, if it has one.
    pub fn transaction(&self, function: &str) -> Option<&TransactionCap> {
        self.transactions.iter().find(|c| c.function == function)
    }

    /// This file with the waits `cap` holds at nothing, and no transaction cap: the bound of a capped
    /// call's function without the waits the cap stands for.
    pub fn without_capped_waits(&self, cap: &TransactionCap) -> BoundsFile {
        let mut file = self.clone();
        for w in &mut file.waits {
            if cap.waits.iter().any(|p| p.names(w)) {
                w.wait_us = 0.0;
            }
        }
        file.transactions.clear();
        file
    }

    /// The async task's loop at `file:line` in `function`, when stated as one pass per job.
    pub fn job(&self, function: &str, file: &str, line: u32) -> Option<&JobLoop> {
        self.jobs
            .iter()
            .find(|j| j.function == function && j.line == line && same_file(file, &j.file))
    }

    /// The stated slice-length register of `function`, if its loops pass once per element.
    pub fn per_element(&self, function: &str) -> Option<&PerElement> {
        self.per_element.iter().find(|p| p.function == function)
    }

    /// The stated length of the memory-function call at `file:line` in `function`.
    pub fn length(&self, function: &str, file: &str, line: u32) -> Option<&LengthBound> {
        self.lengths
            .iter()
            .find(|l| l.function == function && l.line == line && same_file(file, &l.file))
    }

    /// The stated total of the loop at `file:line` in `function`, for the whole job.
    pub fn total(&self, function: &str, file: &str, line: u32) -> Option<&TotalBound> {
        self.totals
            .iter()
            .find(|t| t.function == function && t.line == line && same_file(file, &t.file))
    }

    /// The per-activation charge of the task named `task`, if it has one.
    pub fn per_activation(&self, task: &str) -> Option<&PerActivation> {
        self.per_activation.iter().find(|a| a.task == task)
    }

    /// The per-frame charge of the task named `task`, if it has one.
    pub fn per_frame(&self, task: &str) -> Option<&PerFrame> {
        self.per_frame.iter().find(|f| f.task == task)
    }

    /// This file with the transmit loop of `charge` at `passes`.
    pub fn at_passes(&self, charge: &PerFrame, passes: u64) -> BoundsFile {
        let mut file = self.clone();
        for l in &mut file.loops {
            if l.function == charge.function
                && l.line == charge.line
                && same_file(&charge.file, &l.file)
            {
                l.bound = passes;
            }
        }
        file
    }

    /// This file with the loop of `charge` at its passes per activation in place of its bound per
    /// job (the file's other statements unchanged).
    pub fn at_activation(&self, charge: &PerActivation) -> BoundsFile {
        let mut file = self.clone();
        for l in &mut file.loops {
            if l.function == charge.function
                && l.line == charge.line
                && same_file(&charge.file, &l.file)
            {
                l.bound = charge.passes;
            }
        }
        file
    }

    /// This file with the statements of `extra` added: the bounds of another build of the same source (the traced
    /// QEMU build's simulated devices, `<board>.qemu.bounds.json`) beside the release image's. `extra` states
    /// loops, waits, indirect calls, lengths, per-element functions, job loops and totals only: what the release
    /// file says of the tasks (their charges, holds and topic groups) stays the release file's. A place stated in
    /// both is an error (two reasons for one loop).
    pub fn with(&self, extra: &BoundsFile) -> Result<BoundsFile, Error> {
        if !(extra.tasks.is_empty()
            && extra.held.is_empty()
            && extra.per_activation.is_empty()
            && extra.per_frame.is_empty()
            && extra.topics.is_none())
        {
            return Err(Error::Bounds(
                "a file added to another states loops, waits, indirect calls, lengths, per-element functions, \
                 jobs and totals only (tasks, held, per_activation, per_frame and topics are the first file's)"
                    .into(),
            ));
        }
        let twice = extra
            .loops
            .iter()
            .find(|l| self.loop_bound(&l.function, &l.file, l.line).is_some())
            .map(|l| (&l.function, &l.file, l.line))
            .or_else(|| {
                extra
                    .indirect
                    .iter()
                    .find(|i| self.indirect(&i.function, &i.file, i.line).is_some())
                    .map(|i| (&i.function, &i.file, i.line))
            })
            .or_else(|| {
                extra
                    .jobs
                    .iter()
                    .find(|j| self.job(&j.function, &j.file, j.line).is_some())
                    .map(|j| (&j.function, &j.file, j.line))
            });
        if let Some((function, file, line)) = twice {
            return Err(Error::Bounds(format!(
                "{file}:{line} in {function} is stated in both files"
            )));
        }
        let mut out = self.clone();
        out.loops.extend(extra.loops.iter().cloned());
        out.waits.extend(extra.waits.iter().cloned());
        out.indirect.extend(extra.indirect.iter().cloned());
        out.lengths.extend(extra.lengths.iter().cloned());
        out.per_element.extend(extra.per_element.iter().cloned());
        out.jobs.extend(extra.jobs.iter().cloned());
        out.totals.extend(extra.totals.iter().cloned());
        out.transactions.extend(extra.transactions.iter().cloned());
        out.calls.extend(extra.calls.iter().cloned());
        Ok(out)
    }

    /// The stated targets of the call through a register at `file:line` in `function`.
    pub fn indirect(&self, function: &str, file: &str, line: u32) -> Option<&IndirectTargets> {
        self.indirect
            .iter()
            .find(|i| i.function == function && i.line == line && same_file(file, &i.file))
    }
}

impl BoundsFile {
    /// The entries whose place is not in `image`: no function of their name, or no instruction of it
    /// at their file and line (a key the source moved away from; keys are lines, so an edit above a
    /// stated loop leaves its entry behind). Each as `kind function file:line`.
    pub fn missing_places(&self, image: &crate::Image) -> Vec<String> {
        let functions = |name: &str| -> Vec<&crate::image::Function> {
            image
                .functions
                .values()
                .filter(|f| f.name == name || f.symbol == name)
                .collect()
        };
        let has_line = |function: &str, file: &str, line: u32| {
            functions(function).iter().any(|f| {
                f.instructions().is_ok_and(|insns| {
                    insns.iter().any(|i| {
                        image
                            .line(i.addr)
                            .is_some_and(|(path, l)| l == line && same_file(&path, file))
                    })
                })
            })
        };
        let mut missing = Vec::new();
        let keyed = self
            .loops
            .iter()
            .map(|l| ("loop", &l.function, &l.file, l.line))
            .chain(
                self.waits
                    .iter()
                    .map(|w| ("wait", &w.function, &w.file, w.line)),
            )
            .chain(
                self.indirect
                    .iter()
                    .map(|i| ("indirect call", &i.function, &i.file, i.line)),
            )
            .chain(
                self.lengths
                    .iter()
                    .map(|l| ("length", &l.function, &l.file, l.line)),
            )
            .chain(
                self.jobs
                    .iter()
                    .map(|j| ("job", &j.function, &j.file, j.line)),
            )
            .chain(
                self.totals
                    .iter()
                    .map(|t| ("total", &t.function, &t.file, t.line)),
            )
            .chain(
                self.per_activation
                    .iter()
                    .map(|a| ("per-activation loop", &a.function, &a.file, a.line)),
            )
            .chain(
                self.per_frame
                    .iter()
                    .map(|f| ("per-frame transmit loop", &f.function, &f.file, f.line)),
            )
            .chain(
                self.topics
                    .iter()
                    .map(|t| ("per-topic release loop", &t.function, &t.file, t.line)),
            )
            .chain(self.topics.iter().flat_map(|t| {
                t.groups.iter().flat_map(|g| {
                    g.waits
                        .iter()
                        .map(|w| ("topic group wait", &w.function, &w.file, w.line))
                        .chain(
                            g.loops
                                .iter()
                                .map(|l| ("topic group loop", &l.function, &l.file, l.line)),
                        )
                })
            }));
        for (kind, function, file, line) in keyed {
            if !has_line(function, file, line) {
                missing.push(format!("{kind} {function} {file}:{line}"));
            }
        }
        for p in &self.per_element {
            if functions(&p.function).is_empty() {
                missing.push(format!("per-element function {}", p.function));
            }
        }
        for f in &self.per_frame {
            for (kind, name) in [("completion", &f.completion), ("requeue", &f.requeue)] {
                if functions(name).is_empty() {
                    missing.push(format!("per-frame {kind} function {name}"));
                }
            }
        }
        let caps = self
            .transactions
            .iter()
            .map(|c| ("transaction cap", c))
            .chain(self.topics.iter().flat_map(|t| &t.groups).flat_map(|g| {
                g.transactions
                    .iter()
                    .map(|c| ("topic group transaction cap", c))
            }));
        let calls = self.calls.iter().map(|c| ("calls in total", c)).chain(
            self.topics
                .iter()
                .flat_map(|t| &t.groups)
                .flat_map(|g| g.calls.iter().map(|c| ("topic group calls in total", c))),
        );
        for (kind, c) in calls {
            if functions(&c.function).is_empty() {
                missing.push(format!("{kind} function {}", c.function));
            }
        }
        for (kind, c) in caps {
            if functions(&c.function).is_empty() {
                missing.push(format!("{kind} function {}", c.function));
            }
            for w in &c.waits {
                if !has_line(&w.function, &w.file, w.line) {
                    missing.push(format!("{kind} wait {} {}:{}", w.function, w.file, w.line));
                }
            }
        }
        for g in self.topics.iter().flat_map(|t| &t.groups) {
            for f in &g.functions {
                if functions(f).is_empty() {
                    missing.push(format!("topic group {} function {f}", g.name));
                }
            }
        }
        for t in &self.tasks {
            if functions(&t.symbol).is_empty() {
                missing.push(format!("task {} ({})", t.name, t.symbol));
            }
        }
        missing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_bound_holds_on_the_revisions_it_lists_and_names_an_unknown_one() {
        let file = BoundsFile::parse(
            r#"{"held":[{"task":"publisher[*]","revisions":["1-2"],"reason":"polled on 1-2"},
                        {"task":"can_tx","reason":"on every image"}]}"#,
        )
        .unwrap();
        let known = ["1-2", "1-1"];
        let (publishers, tx) = (&file.held[0], &file.held[1]);
        assert_eq!(publishers.holds_on("1-2", &known), Ok(true));
        assert_eq!(publishers.holds_on("1-1", &known), Ok(false));
        // Without `revisions`, every image holds it back.
        assert_eq!(tx.holds_on("1-1", &known), Ok(true));
        assert_eq!(tx.holds_on("1-2", &known), Ok(true));
        // A revision the board has no image for is an error naming it, not a bound silently used.
        let wrong = BoundsFile::parse(
            r#"{"held":[{"task":"publisher[*]","revisions":["1-3"],"reason":"polled"}]}"#,
        )
        .unwrap();
        let e = wrong.held[0].holds_on("1-2", &known).unwrap_err();
        assert_eq!(
            e,
            UnknownRevision {
                task: "publisher[*]".into(),
                revision: "1-3".into(),
                known: vec!["1-2".into(), "1-1".into()],
            }
        );
        assert!(e.to_string().contains("`1-3`"), "{e}");
        // An empty list holds nothing and says nothing: refused.
        assert!(matches!(
            BoundsFile::parse(r#"{"held":[{"task":"can_tx","revisions":[],"reason":"loose"}]}"#),
            Err(Error::Bounds(_))
        ));
    }

    #[test]
    fn a_qemu_file_adds_its_places_and_states_none_twice_nor_any_task() {
        let release = BoundsFile::parse(
            r#"{"loops":[{"function":"f","file":"src/a.rs","line":3,"bound":8,"reason":"capacity 8"}],
                "held":[{"task":"t","reason":"loose"}]}"#,
        )
        .unwrap();
        let qemu = BoundsFile::parse(
            r#"{"loops":[{"function":"f","file":"src/sim.rs","line":9,"bound":4,"reason":"three mailboxes"}],
                "indirect":[{"function":"g","file":"src/w.rs","line":2,"targets":["h"],"reason":"the only one"}]}"#,
        )
        .unwrap();
        let both = release.with(&qemu).unwrap();
        assert_eq!(
            both.loop_bound("f", "src/a.rs", 3).map(|l| l.bound),
            Some(8)
        );
        assert_eq!(
            both.loop_bound("f", "src/sim.rs", 9).map(|l| l.bound),
            Some(4)
        );
        assert!(both.indirect("g", "src/w.rs", 2).is_some());
        assert_eq!(both.held, release.held);
        // The release file alone does not know the QEMU places.
        assert!(release.loop_bound("f", "src/sim.rs", 9).is_none());
        // A place stated in both files has two reasons: refused.
        let twice = BoundsFile::parse(
            r#"{"loops":[{"function":"f","file":"src/a.rs","line":3,"bound":9,"reason":"other"}]}"#,
        )
        .unwrap();
        assert!(matches!(release.with(&twice), Err(Error::Bounds(_))));
        // What the release file says of the tasks is its own.
        let task = BoundsFile::parse(r#"{"held":[{"task":"u","reason":"loose"}]}"#).unwrap();
        assert!(matches!(release.with(&task), Err(Error::Bounds(_))));
    }

    #[test]
    fn entries_need_a_reason_and_a_figure() {
        let ok = r#"{"loops":[{"function":"f","file":"src/a.rs","line":3,"bound":8,"reason":"capacity 8"}]}"#;
        let file = BoundsFile::parse(ok).unwrap();
        assert_eq!(
            file.loop_bound("f", "/work/x/src/a.rs", 3).map(|l| l.bound),
            Some(8)
        );
        assert!(file.loop_bound("f", "/work/x/src/ba.rs", 3).is_none());
        assert!(file.loop_bound("g", "/work/x/src/a.rs", 3).is_none());
        let no_reason =
            r#"{"loops":[{"function":"f","file":"a.rs","line":3,"bound":8,"reason":" "}]}"#;
        assert!(matches!(
            BoundsFile::parse(no_reason),
            Err(Error::Bounds(_))
        ));
        let zero =
            r#"{"waits":[{"function":"f","file":"a.rs","line":3,"wait_us":0,"source":"x"}]}"#;
        assert!(matches!(BoundsFile::parse(zero), Err(Error::Bounds(_))));
        let address = r#"{"loops":[{"address":134242304,"bound":8}]}"#;
        assert!(matches!(BoundsFile::parse(address), Err(Error::Bounds(_))));
        // An indirect call's targets one way of three: named, stored with an object, or a vtable
        // entry (with at least one vtable).
        let call = |targets: &str| {
            BoundsFile::parse(&format!(
                r#"{{"indirect":[{{"function":"f","file":"a.rs","line":3,{targets},"reason":"r"}}]}}"#
            ))
        };
        let vtable = r#""vtable_entry":{"objects":["V"],"entry":0}"#;
        assert!(call(vtable).is_ok());
        assert!(call(r#""targets":["g"]"#).is_ok());
        for bad in [
            format!(r#""targets":["g"],{vtable}"#),
            format!(r#""stored_with":"V",{vtable}"#),
            r#""vtable_entry":{"objects":[],"entry":0}"#.to_string(),
            r#""targets":[]"#.to_string(),
        ] {
            assert!(matches!(call(&bad), Err(Error::Bounds(_))), "{bad}");
        }
        assert!(matches!(
            BoundsFile::parse("not json"),
            Err(Error::Bounds(_))
        ));
    }
}
