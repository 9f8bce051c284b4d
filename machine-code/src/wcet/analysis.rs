//! The analysis of one image: each function's graph, loops, costs and longest paths, worked out
//! once and composed bottom up ([`super`] states the method).
use std::collections::{BTreeMap, BTreeSet};
use std::rc::Rc;

use super::bounds::{BoundsFile, TransactionCap, JOB_PASSES};
use super::cfg::{self, Call, Cfg};
use super::chip::Chip;
use super::counted;
use super::length::{self, Args, LENGTH_UNKNOWN, NO_ARGS};
use super::path::{self, Cost, LoopCount, LoopNodes, Node, PathError};
use super::polled;
use super::stored;
use super::values::{self, Context, State, Values, NO_CONTEXT};
use super::LoopInfo;
use crate::callgraph::is_library_panic;
use crate::decode::{Flow, Insn, Opcode, PC, SP};
use crate::image::Function;
use crate::{Error, Image};

/// A function's longest paths: by time and by instruction count, with the loops on the way.
#[derive(Debug, Clone)]
pub(super) struct Summary {
    pub(super) time: Cost,
    pub(super) count: Cost,
    /// The longest iteration of an exclusive-access retry loop this function or a callee may be
    /// in (by time, and by instruction count): what one preemption can add.
    pub(super) retry_time: Cost,
    pub(super) retry_count: Cost,
    pub(super) loops: Vec<LoopInfo>,
    /// The loops stated in total per job ([`LoopCount::Total`]) in this function and its callees:
    /// charged once, by the job's bound, not at each call.
    pub(super) totals: Totals,
}

/// A loop stated in total per job: the most passes back to its header, and its longest iteration by
/// time and by instruction count.
#[derive(Debug, Clone, Copy)]
pub(super) struct Total {
    pub(super) passes: u64,
    pub(super) time: Cost,
    pub(super) count: Cost,
}

/// A loop's function, file and line.
pub(super) type LoopKey = (String, Option<String>, Option<u32>);

/// Such loops by their [`LoopKey`].
pub(super) type Totals = BTreeMap<LoopKey, Total>;

/// `from`'s totals into `into`: a loop reached on several ways is charged once, at its longest
/// iteration.
fn merge_totals(into: &mut Totals, from: &Totals, chip: Chip) {
    for (key, t) in from {
        let entry = into.entry(key.clone()).or_insert(*t);
        if time_key(chip)(t.time) > time_key(chip)(entry.time) {
            entry.time = t.time;
        }
        if t.count.instructions > entry.count.instructions {
            entry.count = t.count;
        }
        entry.passes = entry.passes.max(t.passes);
    }
}

/// A function's summary is worked out once per start, argument bounds ([`length`]), outlined helper's
/// call site ([`Site`]) and register context ([`values::context`]).
type SummaryKey = (u64, Args, Option<Site>, Context);

/// The analysis of one image: function summaries worked out once each.
pub(super) struct Analysis<'a> {
    image: &'a Image,
    chip: Chip,
    bounds: &'a BoundsFile,
    known: BTreeMap<SummaryKey, Result<Summary, String>>,
    returns: BTreeMap<u64, bool>,
    open: Vec<u64>,
    /// Functions no path of the job calls (by name, [`super::topics`]): a call of one, and the
    /// blocks only it leads to, are left out of every graph.
    excluded: BTreeSet<String>,
    /// Whether a function has a way to its return with the excluded calls left out.
    feasible: BTreeMap<u64, bool>,
    /// Each function's register values where its blocks start ([`values`]), on its whole graph.
    values: BTreeMap<(u64, Context), Rc<Values>>,
    /// Whether a callee is worked out with what its call leaves in its registers ([`values::context`]);
    /// off, every callee is entered knowing nothing ([`Self::without_call_contexts`]).
    contexts: bool,
}

/// Where a machine-outlined helper (`OUTLINED_FUNCTION_n`) is called from: the calling function's
/// name and the call's file and line. The helper's code has no line of its own (the outliner moved
/// it out of its callers and the line table keeps none for it), so a call through a register in it
/// is keyed at this place in the bounds file's `indirect` section ([`Analysis::bound_graph`]); each
/// call site of a helper is its own key, as its register holds what that caller loaded.
pub(super) type Site = (String, String, u32);

/// Whether `f` is a helper of LLVM's machine outliner: code the compiler moved out of its callers,
/// without a line of its own and following no calling convention.
fn is_outlined(f: &Function) -> bool {
    f.name.starts_with("OUTLINED_FUNCTION_")
}

/// How a declined length names the call that passes it.
const CALL_NAMED: &str = "the length comes from the call in";

/// Where an address is in the source, for messages and keys.
fn place(image: &Image, at: u64) -> (Option<String>, Option<u32>, String) {
    match image.line(at) {
        Some((file, line)) => {
            let text = format!("{file}:{line}");
            (Some(file), Some(line), text)
        }
        None => (None, None, format!("{at:#010x} (no line information)")),
    }
}

impl<'a> Analysis<'a> {
    pub(super) fn new(image: &'a Image, chip: Chip, bounds: &'a BoundsFile) -> Analysis<'a> {
        Analysis {
            image,
            chip,
            bounds,
            known: BTreeMap::new(),
            returns: BTreeMap::new(),
            open: Vec::new(),
            excluded: BTreeSet::new(),
            feasible: BTreeMap::new(),
            values: BTreeMap::new(),
            contexts: true,
        }
    }

    /// An analysis of jobs that call none of the functions named `excluded` ([`super::topics`]).
    pub(super) fn excluding(
        image: &'a Image,
        chip: Chip,
        bounds: &'a BoundsFile,
        excluded: &[String],
    ) -> Analysis<'a> {
        let mut analysis = Analysis::new(image, chip, bounds);
        analysis.excluded = excluded.iter().cloned().collect();
        analysis
    }

    /// The same analysis with every callee entered knowing nothing of its registers: a function's
    /// bound is then the same at every call, as the transmit interrupt's parts need (a part is the
    /// difference of two bounds, checked against a function's bound of its own: [`super::FrameBound`]).
    pub(super) fn without_call_contexts(mut self) -> Analysis<'a> {
        self.contexts = false;
        self
    }

    /// Whether this analysis leaves calls out of the job ([`Self::excluding`]).
    pub(super) fn leaves_calls_out(&self) -> bool {
        !self.excluded.is_empty()
    }

    /// Whether the function at `at` is one the job does not call: named as excluded, or left with no
    /// way to its return once its excluded calls are left out.
    fn left_out(&mut self, at: u64) -> Result<bool, Error> {
        if self.excluded.is_empty() {
            return Ok(false);
        }
        let Some(f) = self.image.function_at(at).filter(|f| f.start == at) else {
            return Ok(false);
        };
        if self.excluded.contains(&f.name) || self.excluded.contains(&f.symbol) {
            return Ok(true);
        }
        if let Some(&known) = self.feasible.get(&at) {
            return Ok(!known);
        }
        // Taken as feasible while being worked out (a recursive call keeps its caller's paths).
        self.feasible.insert(at, true);
        let feasible = match self.pruned(f)? {
            Some(graph) => graph.blocks.iter().any(|b| b.exit),
            None => false,
        };
        self.feasible.insert(at, feasible);
        Ok(!feasible)
    }

    /// `f`'s graph as built, every block that calls a function the job does not call
    /// ([`Self::left_out`]) left out with the blocks only it leads to; `None` when its entry is such
    /// a block.
    fn pruned(&mut self, f: &'a Function) -> Result<Option<Cfg>, Error> {
        let graph = self.built(f)?;
        self.without_left_out(f, graph)
    }

    /// `graph` (of `f`, or a part of it) without the blocks that call a function the job does not
    /// call and those only they lead to; `None` when its entry is such a block.
    fn without_left_out(&mut self, f: &Function, graph: Cfg) -> Result<Option<Cfg>, Error> {
        if self.excluded.is_empty() {
            return Ok(Some(graph));
        }
        let mut dropped = BTreeSet::new();
        for (b, block) in graph.blocks.iter().enumerate() {
            if let Some(Call::Direct { target, .. }) = block.call {
                if target != f.start && self.left_out(target)? {
                    dropped.insert(b);
                }
            }
        }
        if dropped.is_empty() {
            return Ok(Some(graph));
        }
        Ok(graph.without(&dropped))
    }

    /// Whether the function at `at` can return: a return or a tail call of a function that can
    /// is reachable in its graph. The library's panics cannot ([`is_library_panic`], declared
    /// `-> !`); any other function is read from its code, whatever its name says; a function being
    /// worked out is taken to.
    pub(super) fn can_return(&mut self, at: u64) -> bool {
        if let Some(&known) = self.returns.get(&at) {
            return known;
        }
        let Some(f) = self.image.function_at(at) else {
            return true;
        };
        if is_library_panic(&f.name) {
            self.returns.insert(at, false);
            return false;
        }
        self.returns.insert(at, true);
        let image = self.image;
        let read = |address: u64, size: u64| read_entry(image, address, size);
        // A call of a function that cannot return ends the way through it (`panic_const_async_fn_resumed`
        // is no panic for the panic check, and returns only if `panic_fmt` did).
        let mut returning = BTreeMap::new();
        if let Ok(insns) = f.instructions() {
            for i in insns {
                if let Flow::Call(t) = i.flow() {
                    if t != at && !returning.contains_key(&t) {
                        let r = self.can_return(t);
                        returning.insert(t, r);
                    }
                }
            }
        }
        let Ok(graph) = Cfg::build(f, &read, &|t| returning.get(&t).copied().unwrap_or(true))
        else {
            return true;
        };
        let mut seen = BTreeSet::from([0usize]);
        let mut work = vec![0usize];
        let mut returns = false;
        while let Some(b) = work.pop() {
            let block = &graph.blocks[b];
            if block.exit {
                let tail_ok = match block.call {
                    Some(Call::Direct { target, tail: true }) if target != at => {
                        self.can_return(target)
                    }
                    _ => true,
                };
                if tail_ok {
                    returns = true;
                    break;
                }
            }
            for e in &block.succs {
                if seen.insert(e.to) {
                    work.push(e.to);
                }
            }
        }
        self.returns.insert(at, returns);
        returns
    }

    /// The summary of the function at `at`: `Err(Error)` for an image that cannot be analysed,
    /// `Ok(Err(reason))` for a declined bound.
    pub(super) fn summary(&mut self, at: u64) -> Result<Result<Summary, String>, Error> {
        self.summary_with(at, NO_ARGS, None, &NO_CONTEXT)
    }

    /// [`Self::summary`] of a call whose argument registers are bounded by `args` ([`length`]);
    /// for an outlined helper, called from `site` ([`Site`]).
    fn summary_with(
        &mut self,
        at: u64,
        args: Args,
        site: Option<Site>,
        context: &Context,
    ) -> Result<Result<Summary, String>, Error> {
        if let Some(known) = self.known.get(&(at, args, site.clone(), *context)) {
            return Ok(known.clone());
        }
        if self.open.contains(&at) {
            let chain: Vec<String> = self.open.iter().map(|&a| self.image.name(a)).collect();
            return Ok(Err(format!(
                "recursion through {} → {}",
                chain.join(" → "),
                self.image.name(at)
            )));
        }
        let image = self.image;
        let f = image.function_at(at).ok_or_else(|| {
            Error::Other(format!("a call to {at:#010x}, where no function starts"))
        })?;
        self.open.push(at);
        let outcome = self.work_out(f, args, site.as_ref(), context);
        self.open.pop();
        let outcome = match (outcome?, self.bounds.transaction(&f.name)) {
            (Ok(s), Some(cap)) => self.capped(f, args, site.as_ref(), context, s, cap)?,
            (outcome, _) => outcome,
        };
        self.known
            .insert((at, args, site, *context), outcome.clone());
        Ok(outcome)
    }

    /// `summary` of a call of `f`, a bus transaction's function with a transaction cap ([`TransactionCap`]):
    /// its time the smaller of `summary`'s and the bound with the waits the cap holds at nothing plus
    /// the cap. Sound on every path p: the time of p is its cycles and other waits, `z(p)`, plus
    /// its capped waits, at most their stated sum `w(p)` and at most the cap `c`, so at most
    /// min(z(p) + w(p), z(p) + c) ≤ min(summary, max z + c). The instruction count keeps `summary`'s
    /// (the QEMU runs are held to it, and a simulated bus's flags need not keep to the wire's time).
    /// A call whose length the cap needs and does not know keeps `summary`.
    fn capped(
        &mut self,
        f: &'a Function,
        args: Args,
        site: Option<&Site>,
        context: &Context,
        mut summary: Summary,
        cap: &TransactionCap,
    ) -> Result<Result<Summary, String>, Error> {
        let Some(cap_ns) = cap.cap_ns(&args) else {
            return Ok(Ok(summary));
        };
        let bounds = self.bounds.without_capped_waits(cap);
        let mut without = Analysis::new(self.image, self.chip, &bounds);
        without.excluded = self.excluded.clone();
        without.contexts = self.contexts;
        without.open = self.open.clone();
        let zero = match without.summary_with(f.start, args, site.cloned(), context)? {
            Ok(z) => z,
            // Declined without the waits, as it was not with them: keep the bound it has.
            Err(_) => return Ok(Ok(summary)),
        };
        let chip = self.chip;
        let capped = Cost {
            cycles: zero.time.cycles,
            instructions: zero.time.instructions + chip.ns_to_cycles(cap_ns),
            wait_ns: zero.time.wait_ns + cap_ns,
        };
        let applies = time_key(chip)(capped) < time_key(chip)(summary.time);
        let bytes = cap
            .register
            .and_then(|r| args[usize::from(r)])
            .map(|n| format!(", {n} bytes at the call (r{})", cap.register.unwrap_or(0)))
            .unwrap_or_default();
        summary.loops.push(LoopInfo {
            function: f.name.clone(),
            file: None,
            line: None,
            bound: 1,
            source: format!(
                "transaction cap: its flag waits at most {} µs in sum{bytes}; {} ({})",
                cap_ns as f64 / 1000.0,
                if applies {
                    format!(
                        "charged in place of their {} µs on the longest path",
                        (summary.time.wait_ns.saturating_sub(zero.time.wait_ns)) as f64 / 1000.0
                    )
                } else {
                    "their sum on the longest path is within it".to_string()
                },
                cap.reason
            ),
        });
        if applies {
            summary.time = capped;
        }
        Ok(Ok(summary))
    }

    fn work_out(
        &mut self,
        f: &'a Function,
        args: Args,
        site: Option<&Site>,
        context: &Context,
    ) -> Result<Result<Summary, String>, Error> {
        let graph = match self.graph(f)? {
            Ok(graph) => graph,
            Err(reason) => return Ok(Err(reason)),
        };
        self.bound_graph(f, graph, args, site, context)
    }

    /// The control-flow graph of `f` as the bound reads it: the blocks after a call of a function
    /// that cannot return left out, irreducible cycles split into natural loops. `Ok(Err(reason))`
    /// when splitting would grow it too much.
    pub(super) fn graph(&mut self, f: &'a Function) -> Result<Result<Cfg, String>, Error> {
        match self.pruned(f)? {
            Some(graph) if graph.blocks.iter().any(|b| b.exit) => Ok(self.split(f, graph)),
            _ => Ok(Err(format!(
                "every path of {} calls a function this job does not call",
                f.name
            ))),
        }
    }

    /// The control-flow graph of `f` as built, the blocks after a call of a function that cannot
    /// return left out (before any splitting).
    fn built(&mut self, f: &'a Function) -> Result<Cfg, Error> {
        let insns = f.instructions()?;
        let image = self.image;
        let read = |address: u64, size: u64| read_entry(image, address, size);
        // Which callees return (worked out before the graph, which leaves out what follows a call
        // that does not).
        let callees: Vec<u64> = insns
            .iter()
            .filter_map(|i| match i.flow() {
                crate::decode::Flow::Call(t) => Some(t),
                _ => None,
            })
            .collect();
        let mut returning = BTreeMap::new();
        for t in callees {
            let r = self.can_return(t);
            returning.insert(t, r);
        }
        Cfg::build(f, &read, &|t| returning.get(&t).copied().unwrap_or(true))
    }

    /// `f`'s register values ([`values`]), worked out once on its whole graph as built: every path
    /// of any part of it (a task's part of its dispatcher, a job with calls left out, a section, a
    /// split copy) is a path of that graph, so what holds there holds on the part; a part's block is
    /// read from the instruction it starts at ([`Values::before`]).
    fn values(&mut self, f: &'a Function, context: &Context) -> Result<Rc<Values>, Error> {
        if let Some(v) = self.values.get(&(f.start, *context)) {
            return Ok(Rc::clone(v));
        }
        let graph = self.built(f)?;
        let v = Rc::new(Values::of(self.image, f.instructions()?, &graph, context));
        self.values.insert((f.start, *context), Rc::clone(&v));
        Ok(v)
    }

    /// `graph` (of `f`) with each cycle of more than one entry (an async task's loop) made a
    /// natural loop; `Err(reason)` when splitting would grow it too much.
    fn split(&self, f: &Function, graph: Cfg) -> Result<Cfg, String> {
        let image = self.image;
        let Ok(insns) = f.instructions() else {
            return Ok(graph);
        };
        match graph.split_irreducible() {
            Ok(split) => Ok(split.unwrap_or(graph)),
            Err(first) => {
                let (_, _, text) = place(image, insns[first].addr);
                Err(format!(
                    "irreducible control flow in {} at {text}: splitting it into natural loops \
                     would grow the graph more than {}-fold",
                    f.name,
                    cfg::MAX_SPLIT_GROWTH
                ))
            }
        }
    }

    /// The graph of one software task's part of the dispatcher at `at`: the dispatcher's own code
    /// and `task`'s poll, the polls of `others` (the other tasks of its priority) left out
    /// ([`polled`]), split as [`Self::graph`] splits; `None` where the image does not tell `task`'s
    /// part (then the whole dispatcher is its part).
    pub(super) fn polled_graph(
        &mut self,
        at: u64,
        task: &str,
        others: &[String],
    ) -> Result<Option<Result<Cfg, String>>, Error> {
        let image = self.image;
        let f = image.function_at(at).ok_or_else(|| {
            Error::Other(format!(
                "a dispatcher at {at:#010x}, where no function starts"
            ))
        })?;
        let insns = f.instructions()?;
        let graph = self.built(f)?;
        let part = polled::others_blocks(image, insns, &graph, task, others)
            .and_then(|dropped| graph.without(&dropped));
        let Some(part) = part else {
            return Ok(None);
        };
        // The calls the job does not make, left out of the part as of any function.
        Ok(Some(match self.without_left_out(f, part)? {
            Some(part) if part.blocks.iter().any(|b| b.exit) => self.split(f, part),
            _ => Err(format!(
                "every path of {}'s part for {task} calls a function this job does not call",
                f.name
            )),
        }))
    }

    /// The summary of `task`'s part of the dispatcher at `at` ([`Self::polled_graph`]).
    pub(super) fn polled_summary(
        &mut self,
        at: u64,
        task: &str,
        others: &[String],
    ) -> Result<Result<Summary, String>, Error> {
        let f = self.image.function_at(at).ok_or_else(|| {
            Error::Other(format!(
                "a dispatcher at {at:#010x}, where no function starts"
            ))
        })?;
        match self.polled_graph(at, task, others)? {
            None => self.summary(at),
            Some(Ok(graph)) => self.bound_graph(f, graph, NO_ARGS, None, &NO_CONTEXT),
            Some(Err(reason)) => Ok(Err(reason)),
        }
    }

    /// The longest paths through `graph` (of `f`, or a part of it: block 0 is where the paths start,
    /// the blocks marked `exit` where they end), its loops bounded and its calls composed. `site`:
    /// where `f`, an outlined helper, is called from ([`Site`]); a call through a register in `f`
    /// that has no line of its own is keyed there.
    pub(super) fn bound_graph(
        &mut self,
        f: &'a Function,
        graph: Cfg,
        args: Args,
        site: Option<&Site>,
        context: &Context,
    ) -> Result<Result<Summary, String>, Error> {
        let insns = f.instructions()?;
        let image = self.image;
        let chip = self.chip;
        let mut loops_info = Vec::new();
        // Loops and their counts.
        let natural = match graph.loops() {
            Ok(l) => l,
            Err(b) => {
                let (_, _, text) = place(image, insns[graph.blocks[b].first].addr);
                return Ok(Err(format!(
                    "irreducible control flow in {} at {text}: no natural loop to bound",
                    f.name
                )));
            }
        };
        let mut loop_nodes = Vec::new();
        // The count the function's `Shared` loops iterate at most, all together.
        let mut shared_count: Option<u64> = None;
        let (mut retry_time, mut retry_count) = (Cost::default(), Cost::default());
        // The function's loops stated in total per job, by their [`LoopCount::Total`] key.
        let mut total_keys: Vec<(LoopKey, u64)> = Vec::new();
        let mut totals = Totals::new();
        for l in &natural {
            let leaves = l.body.iter().any(|&b| {
                let blk = &graph.blocks[b];
                blk.exit || blk.succs.iter().any(|e| !l.body.contains(&e.to))
            });
            let (file, line, text) = loop_place(image, insns, &graph, l);
            let count = if !leaves {
                LoopCount::Endless
            } else if counted::exclusive_retry(insns, &graph, l, &|at| leaf_body(image, at)) {
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: 1,
                    source: "exclusive retry: one pass, one more per preemption inside it \
                             (exception entry and return clear the local monitor)"
                        .to_string(),
                });
                LoopCount::Retry
            // A stated wait before a count: a poll loop's count is its timeout, the fault path.
            } else if let Some(wait) = file
                .as_deref()
                .zip(line)
                .and_then(|(file, line)| self.bounds.wait(&f.name, file, line))
            {
                let ns = (wait.wait_us * 1000.0).ceil() as u64;
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: 1,
                    source: format!("wait: {} µs ({})", wait.wait_us, wait.source),
                });
                LoopCount::Wait {
                    ns,
                    cycles: chip.ns_to_cycles(ns),
                }
            } else if let Some(stated) = file
                .as_deref()
                .zip(line)
                .and_then(|(file, line)| self.bounds.total(&f.name, file, line))
            {
                // Loops named at one place (a loop the compiler split, or one whose header has no
                // line of its own) share the statement: their passes back together.
                let key = (f.name.clone(), file.clone(), line);
                let index = match total_keys.iter().position(|(k, _)| *k == key) {
                    Some(index) => index,
                    None => {
                        loops_info.push(LoopInfo {
                            function: f.name.clone(),
                            file: file.clone(),
                            line,
                            bound: stated.passes,
                            source: format!(
                                "bounds file, passes in total per job: {}",
                                stated.reason
                            ),
                        });
                        total_keys.push((key, stated.passes));
                        total_keys.len() - 1
                    }
                };
                LoopCount::Total { key: index }
            } else if let Some(c) = counted::counted(insns, &graph, l) {
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: c.header,
                    source: match c.body {
                        Some(b) => format!("{}; at most {b} passes on past it", c.how),
                        None => c.how,
                    },
                });
                match c.body {
                    Some(body) => LoopCount::Body {
                        header: c.header,
                        body,
                    },
                    None => LoopCount::Passes(c.header),
                }
            } else if let Some(stated) = file
                .as_deref()
                .zip(line)
                .and_then(|(file, line)| self.bounds.loop_bound(&f.name, file, line))
            {
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: stated.bound,
                    source: match stated.body {
                        Some(b) => format!(
                            "bounds file, at most {b} passes on past the header: {}",
                            stated.reason
                        ),
                        None => format!("bounds file: {}", stated.reason),
                    },
                });
                match stated.body {
                    Some(body) => LoopCount::Body {
                        header: stated.bound,
                        body,
                    },
                    None => LoopCount::Passes(stated.bound),
                }
            } else if let Some(job) = file
                .as_deref()
                .zip(line)
                .and_then(|(file, line)| self.bounds.job(&f.name, file, line))
            {
                // A job runs the header twice where it can resume there (the header is entered
                // from outside the loop by a block of the function's own, not a copy: the await
                // it polls when resumed, or the loop's top on the first poll), else once: every
                // way in is a copy of an entry's blocks — a resumed poll lands where its await's
                // poll starts, an entry of the loop, so the copied way in holds that poll ahead of
                // the header — and the next await the job meets parks it or, ready at once, is
                // the next release (docs/analysis.md, "Async tasks: one job").
                let resumed_here = l.header == 0
                    || graph.blocks.iter().enumerate().any(|(p, blk)| {
                        !l.body.contains(&p)
                            && !blk.copy
                            && blk.succs.iter().any(|e| e.to == l.header)
                    });
                let passes = if resumed_here { JOB_PASSES } else { 1 };
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: passes,
                    source: format!(
                        "job: one pass of the task's loop per job, its header run {} (bounds file: {})",
                        if resumed_here {
                            "where the job resumes and where it parks"
                        } else {
                            "once, behind the await the job resumes at"
                        },
                        job.reason
                    ),
                });
                LoopCount::Passes(passes)
            } else if let Some(r) = length::length_register(&f.name)
                .or_else(|| self.bounds.per_element(&f.name).map(|p| p.register))
            {
                let Some(n) = args[usize::from(r)] else {
                    return Ok(Err(format!(
                        "the loop in {} at {text} {LENGTH_UNKNOWN}",
                        f.name
                    )));
                };
                // A loop whose header's test ends it on the count its entry value (the length, or a
                // constant) gives: counted per entry as [`counted::counted`]'s loops tested at the
                // top are, a way out from its body charged after one pass fewer.
                if let Some(c) = counted::counted_from_arguments(insns, &graph, l, &args) {
                    loops_info.push(LoopInfo {
                        function: f.name.clone(),
                        file: file.clone(),
                        line,
                        bound: c.header,
                        source: format!(
                            "length: at most {n} at the call (r{r}); {}; at most {} passes on past it",
                            c.how,
                            c.body.unwrap_or(c.header)
                        ),
                    });
                    loop_nodes.push(LoopNodes {
                        header: l.header,
                        body: l.body.clone(),
                        count: LoopCount::Body {
                            header: c.header,
                            body: c.body.unwrap_or(c.header),
                        },
                    });
                    continue;
                }
                let (moved, factor) = length::moved_by(&f.name);
                let units = u64::from(n) * factor;
                shared_count = Some(units);
                let per_pass = length::per_pass(insns, &graph, l, moved);
                let what = match moved {
                    length::Moved::Stores => "bytes stored",
                    length::Moved::Loads => "bytes loaded",
                    length::Moved::Passes => "elements",
                };
                loops_info.push(LoopInfo {
                    function: f.name.clone(),
                    file: file.clone(),
                    line,
                    bound: units / per_pass + 1,
                    source: format!(
                        "length: at most {n} at the call (r{r}), {units} {what} by all of the \
                         function's loops together; each pass of this one moves at least {per_pass}"
                    ),
                });
                LoopCount::Shared { per_pass }
            } else {
                return Ok(Err(format!(
                    "the loop in {} at {text} has no bound (not a counted loop, not in the bounds file)",
                    f.name
                )));
            };
            loop_nodes.push(LoopNodes {
                header: l.header,
                body: l.body.clone(),
                count,
            });
        }
        // Node costs: the block's instructions, and what it calls.
        let values = self.values(f, context)?;
        let mut time_nodes = Vec::with_capacity(graph.blocks.len());
        let mut count_nodes = Vec::with_capacity(graph.blocks.len());
        for (index, block) in graph.blocks.iter().enumerate() {
            let own = self.block_cost(
                &insns[block.first..=block.last],
                values.before(image, insns, block.first),
            );
            let (mut time, mut count) = (own, own);
            // What a tail call adds is paid only on the way out through it; a conditional one
            // (`B<c>` out of the function) also pays its refill there.
            let tail = matches!(
                block.call,
                Some(Call::Direct { tail: true, .. } | Call::Indirect { tail: true, .. })
            );
            let (mut exit_time, mut exit_count) = (Cost::default(), Cost::default());
            if tail && insns[block.last].conditional {
                exit_time.cycles += chip.taken_cycles();
                exit_count.cycles += chip.taken_cycles();
            }
            let (time_ref, count_ref) = if tail {
                (&mut exit_time, &mut exit_count)
            } else {
                (&mut time, &mut count)
            };
            let mut exit = block.exit;
            match block.call {
                // A call of a function that cannot return ends the path (the graph has no edge on
                // from it); a tail call of one is no return either.
                Some(Call::Direct { target, tail }) if !self.can_return(target) => exit &= !tail,
                Some(Call::Direct { target, .. }) => match self
                    .call_summary(target, &f.name, insns, &graph, index, &args, site, &values)?
                {
                    Ok(s) => {
                        let callee = image
                            .function_at(target)
                            .filter(|c| c.start == target)
                            .map(|c| c.name.clone());
                        match callee
                            .as_deref()
                            .and_then(|name| self.bounds.call_total(name))
                        {
                            // A function called at most `calls` times per job: charged by the job's
                            // bound, that many times its longest call, not at each call.
                            Some(stated) => {
                                let name = stated.function.clone();
                                loops_info.push(LoopInfo {
                                    function: name.clone(),
                                    file: None,
                                    line: None,
                                    bound: stated.calls,
                                    source: format!(
                                        "bounds file, calls in total per job: {}",
                                        stated.reason
                                    ),
                                });
                                let mine = Totals::from([(
                                    (name, None, None),
                                    Total {
                                        passes: stated.calls,
                                        time: s.time,
                                        count: s.count,
                                    },
                                )]);
                                merge_totals(&mut totals, &mine, chip);
                            }
                            None => {
                                *time_ref = time_ref.plus(s.time);
                                *count_ref = count_ref.plus(s.count);
                            }
                        }
                        loops_info.extend(s.loops);
                        merge_totals(&mut totals, &s.totals, chip);
                    }
                    Err(reason) => return Ok(Err(format!("via {}: {reason}", image.name(target)))),
                },
                Some(Call::Indirect { .. })
                    if length::constant_target(image, insns, &graph, index)
                        .is_some_and(|t| image.function_at(t).is_some()) =>
                {
                    // A register that holds one function's address: a direct call in effect.
                    let target = length::constant_target(image, insns, &graph, index).unwrap_or(0);
                    match self
                        .call_summary(target, &f.name, insns, &graph, index, &args, site, &values)?
                    {
                        Ok(s) => {
                            *time_ref = time_ref.plus(s.time);
                            *count_ref = count_ref.plus(s.count);
                            if time_key(chip)(s.retry_time) > time_key(chip)(retry_time) {
                                retry_time = s.retry_time;
                            }
                            if s.retry_count.instructions > retry_count.instructions {
                                retry_count = s.retry_count;
                            }
                            loops_info.extend(s.loops);
                            merge_totals(&mut totals, &s.totals, chip);
                        }
                        Err(reason) => {
                            return Ok(Err(format!("via {}: {reason}", image.name(target))))
                        }
                    }
                }
                Some(Call::Indirect { at, .. }) => {
                    let (file, line, mut text) = place(image, at);
                    let stated = match (file.as_deref().zip(line), site) {
                        (Some((file, line)), _) => self.bounds.indirect(&f.name, file, line),
                        // No line of its own, in an outlined helper: keyed where it is called.
                        (None, Some((caller, file, line))) => {
                            text = format!(
                                "{text}, an outlined helper's, keyed at its call in {caller} at \
                                 {file}:{line}"
                            );
                            self.bounds.indirect(caller, file, *line)
                        }
                        (None, None) => None,
                    };
                    let Some(stated) = stated else {
                        return Ok(Err(format!(
                            "the call through a register in {} at {text} has no stated targets",
                            f.name
                        )));
                    };
                    let (mut worst_time, mut worst_count) = (Cost::default(), Cost::default());
                    let targets = match stored::targets(image, stated, &text)? {
                        Ok(targets) => targets,
                        Err(reason) => {
                            return Ok(Err(format!(
                                "the call through a register in {} at {text}: {reason}",
                                f.name
                            )))
                        }
                    };
                    for (name, start) in targets {
                        match self.summary(start)? {
                            Ok(s) => {
                                if time_key(chip)(s.time) > time_key(chip)(worst_time) {
                                    worst_time = s.time;
                                }
                                if time_key(chip)(s.retry_time) > time_key(chip)(retry_time) {
                                    retry_time = s.retry_time;
                                }
                                if s.retry_count.instructions > retry_count.instructions {
                                    retry_count = s.retry_count;
                                }
                                if s.count.instructions > worst_count.instructions {
                                    worst_count = s.count;
                                }
                                loops_info.extend(s.loops);
                                merge_totals(&mut totals, &s.totals, chip);
                            }
                            Err(reason) => return Ok(Err(format!("via {name}: {reason}"))),
                        }
                    }
                    *time_ref = time_ref.plus(worst_time);
                    *count_ref = count_ref.plus(worst_count);
                }
                None => {}
            }
            let taken = Cost {
                cycles: chip.taken_cycles(),
                ..Cost::default()
            };
            let succs: Vec<(usize, Cost)> = block
                .succs
                .iter()
                .map(|e| {
                    (
                        e.to,
                        if e.taken && insns[block.last].conditional {
                            taken
                        } else {
                            Cost::default()
                        },
                    )
                })
                .collect();
            time_nodes.push(Node {
                cost: time,
                succs: succs.clone(),
                exit,
                exit_cost: exit_time,
            });
            count_nodes.push(Node {
                cost: count,
                succs,
                exit,
                exit_cost: exit_count,
            });
        }
        let by_time = path::longest(time_nodes, &loop_nodes, &time_key(chip));
        let by_count = path::longest(count_nodes, &loop_nodes, &|c: Cost| c.instructions);
        let (time, count) = match (by_time, by_count) {
            (Ok(t), Ok(c)) => {
                if time_key(chip)(t.retry) > time_key(chip)(retry_time) {
                    retry_time = t.retry;
                }
                if c.retry.instructions > retry_count.instructions {
                    retry_count = c.retry;
                }
                let n = shared_count.unwrap_or(0);
                let own = |key: usize, longest: &path::Longest, by: &dyn Fn(Cost) -> u64| {
                    longest
                        .totals
                        .iter()
                        .filter(|&&(k, _)| k == key)
                        .map(|&(_, c)| c)
                        .max_by_key(|&c| by(c))
                        .unwrap_or_default()
                };
                let mut mine = Totals::new();
                for (key, (name, passes)) in total_keys.iter().enumerate() {
                    let time = own(key, &t, &time_key(chip));
                    let count = own(key, &c, &|c: Cost| c.instructions);
                    mine.insert(
                        name.clone(),
                        Total {
                            passes: *passes,
                            time,
                            count,
                        },
                    );
                }
                merge_totals(&mut totals, &mine, chip);
                (
                    t.path.plus(t.shared.times(n)),
                    c.path.plus(c.shared.times(n)),
                )
            }
            (Err(PathError::NoExit), _) | (_, Err(PathError::NoExit)) => {
                return Ok(Err(format!("{} never returns", f.name)))
            }
            (Err(PathError::Irreducible(b)), _) | (_, Err(PathError::Irreducible(b))) => {
                let (_, _, text) = place(image, insns[graph.blocks[b].first].addr);
                return Ok(Err(format!(
                    "irreducible control flow in {} at {text}: no natural loop to bound",
                    f.name
                )));
            }
        };
        let mut seen = BTreeSet::new();
        loops_info.retain(|l| {
            seen.insert((l.function.clone(), l.file.clone(), l.line, l.source.clone()))
        });
        Ok(Ok(Summary {
            time,
            count,
            retry_time,
            retry_count,
            loops: loops_info,
            totals,
        }))
    }

    /// The summary of the call ending block `index`: without its arguments, or, where a memory function's
    /// length is what it lacks, with the bounds the call's machine code gives them ([`length`]).
    ///
    /// A call of an outlined helper passes it its place ([`Site`]): the call's line in `caller`
    /// ([`call_line`]), or, where `caller` has none (a helper calling a helper), `site`, the place
    /// `caller` was called from.
    #[allow(clippy::too_many_arguments)]
    fn call_summary(
        &mut self,
        target: u64,
        caller: &str,
        insns: &[Insn],
        graph: &Cfg,
        index: usize,
        entry: &Args,
        site: Option<&Site>,
        values: &Values,
    ) -> Result<Result<Summary, String>, Error> {
        let call = insns[graph.blocks[index].last].addr;
        // What the call leaves in the callee's registers.
        let outlined = self
            .image
            .function_at(target)
            .is_some_and(|callee| callee.start == target && is_outlined(callee));
        let before = values.before(self.image, insns, graph.blocks[index].last);
        let context = if self.contexts {
            values::context(&before, outlined)
        } else {
            NO_CONTEXT
        };
        let site = match self.image.function_at(target) {
            Some(callee) if callee.start == target && is_outlined(callee) => {
                match call_line(self.image, insns, graph.blocks[index].last) {
                    Some((file, line)) => Some((caller.to_string(), file, line)),
                    None => site.cloned(),
                }
            }
            _ => None,
        };
        let plain = self.summary_with(target, NO_ARGS, site.clone(), &context)?;
        if !matches!(&plain, Err(reason) if reason.contains(LENGTH_UNKNOWN)) {
            return Ok(plain);
        }
        let mut args = length::call_args(insns, graph, index, entry);
        // A length the bounds file states for this call (its machine code does not fix it).
        let mut stated_info = None;
        if let Some((file, line)) = self.image.line(call) {
            if let Some(stated) = self.bounds.length(caller, &file, line) {
                let r = usize::from(stated.register);
                let most = stated.bytes;
                args[r] = Some(args[r].map_or(most, |n| n.min(most)));
                stated_info = Some(LoopInfo {
                    function: caller.to_string(),
                    file: Some(file),
                    line: Some(line),
                    bound: u64::from(most),
                    source: format!(
                        "bounds file: a length of at most {most} bytes in r{r}: {}",
                        stated.reason
                    ),
                });
            }
        }
        let mut outcome = if args == NO_ARGS {
            plain
        } else {
            self.summary_with(target, args, site, &context)?
        };
        if let (Ok(s), Some(info)) = (&mut outcome, stated_info) {
            s.loops.push(info);
        }
        // Still no length: name the call that passes it (where a `lengths` entry would go), unless the
        // caller is a memory function called without a length of its own (it passes its argument on;
        // the call that passes it is named).
        let passes_on = length::length_register(caller)
            .or_else(|| self.bounds.per_element(caller).map(|p| p.register))
            .is_some_and(|r| entry[usize::from(r)].is_none());
        if let Err(reason) = &mut outcome {
            if !passes_on && !reason.contains(CALL_NAMED) {
                let (_, _, text) = place(self.image, call);
                reason.push_str(&format!(" ({CALL_NAMED} {caller} at {text})"));
            }
        }
        Ok(outcome)
    }

    /// A straight run of instructions entered with the registers `state`: each one's core and memory
    /// cycles, at least the cycles fetching the flash lines it spans takes.
    fn block_cost(&self, insns: &[Insn], mut state: State) -> Cost {
        let chip = self.chip;
        let mut cycles = 0;
        for insn in insns {
            cycles += chip.core_cycles(insn) + chip.memory_cycles(insn, &state);
            values::step(self.image, insn, &mut state);
        }
        let fetch = match (insns.first(), insns.last()) {
            (Some(first), Some(last)) => chip.fetch_cycles(first.addr, last.next()),
            _ => 0,
        };
        Cost {
            cycles: cycles.max(fetch),
            instructions: insns.len() as u64,
            wait_ns: 0,
        }
    }
}

/// Where a loop is named: the first line of the project's own code (not the core library's) in it,
/// from its header on; else the header's line; else its address.
fn loop_place(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    l: &cfg::Loop,
) -> (Option<String>, Option<u32>, String) {
    let header = &graph.blocks[l.header];
    let in_order = || {
        std::iter::once(header)
            .chain(
                l.body
                    .iter()
                    .filter(|&&b| b != l.header)
                    .map(|&b| &graph.blocks[b]),
            )
            .flat_map(|b| insns[b.first..=b.last].iter())
    };
    let lines: Vec<(u64, String)> = in_order()
        .filter_map(|i| image.line(i.addr).map(|(file, _)| (i.addr, file)))
        .collect();
    match lines
        .iter()
        .find(|(_, file)| !is_library(file))
        .or(lines.first())
    {
        Some((at, _)) => place(image, *at),
        None => place(image, insns[header.first].addr),
    }
}

/// The line of the call `insns[call]` as a key: its own, or, where the line table gives it none (LLVM
/// marks a call of an outlined helper line 0), the line of the closest instruction before it in the
/// function that has one — the line the code was at when it called (as a disassembly listing with
/// lines shows the call). `None` when no instruction up to the call has a line.
fn call_line(image: &Image, insns: &[Insn], call: usize) -> Option<(String, u32)> {
    insns[..=call].iter().rev().find_map(|i| image.line(i.addr))
}

/// Whether a source path is the Rust toolchain's own library (core, alloc, compiler-builtins).
fn is_library(file: &str) -> bool {
    file.contains("/rustlib/src/rust/library/") || file.starts_with("/rustc/")
}

/// The key the time path is longest by: cycles plus the stated waits as cycles.
fn time_key(chip: Chip) -> impl Fn(Cost) -> u64 {
    move |c: Cost| c.cycles + chip.ns_to_cycles(c.wait_ns)
}

/// A jump-table entry (1 or 2 bytes) of the image.
pub(super) fn read_entry(image: &Image, address: u64, size: u64) -> Option<u64> {
    let bytes = image.bytes(address, size)?;
    Some(match bytes[..] {
        [b] => u64::from(b),
        [lo, hi] => u64::from(u16::from_le_bytes([lo, hi])),
        _ => return None,
    })
}

/// The body of the function at `at` when it is a leaf helper: straight-line code (no branch, call
/// or write of SP or PC) ending in `BX LR`; the body without the `BX LR`.
pub(super) fn leaf_body(image: &Image, at: u64) -> Option<Vec<Insn>> {
    let f = image.function_at(at).filter(|f| f.start == at)?;
    let insns = f.instructions().ok()?;
    let (last, body) = insns.split_last()?;
    let straight = body
        .iter()
        .all(|i| i.flow() == Flow::Next && !i.writes().contains(SP) && !i.writes().contains(PC));
    (straight && last.flow() == Flow::Return && last.inst.opcode == Opcode::BX)
        .then(|| body.to_vec())
}
