//! One software task's part of its dispatcher. RTIC 2 polls every async task of one priority from
//! one interrupt handler (the dispatcher): for each task in turn, if it is pending, its executor
//! polls its future. With fat LTO the futures' polls are inlined into the dispatcher, so the
//! dispatcher's graph holds every task of the level, and its longest path polls each of them with
//! each loop at its worst. One task's job is the dispatcher's own code and that task's poll: the
//! other tasks' polls are jobs of their own (the response-time analysis counts them as such).
//!
//! The task's poll is its async body, `<crate>::app::<task>::{{closure}}` as rustc names it: where
//! it is inlined, the DWARF inlined subroutines say which instructions are its (and what it inlines
//! in turn); where it is a function of its own, the dispatcher calls it. A block that runs another
//! task's poll — an instruction inside that task's inlined body, or a call of its body — and none
//! of this task's is left out of the graph ([`Cfg::without`]), and so is everything only it
//! reaches; the pending checks and the executor's code around the polls stay. A block that this
//! task's own code flows into directly is kept whatever its attribution (code LLVM merged between
//! two tasks' tails is named after one of them). Without any block of its own in the dispatcher
//! (no debug information, a poll reached some other way), or with one that only another task's
//! code leads to (an attribution that does not tell the polls apart), or where a block the part
//! keeps on the way on from this task's own code could return only through another task's poll,
//! the task is bounded by the whole dispatcher, as before. That way on stops at another task's
//! executor code: a block named no task's body whose DWARF frames are only instances of RTIC's
//! `AsyncTaskExecutor<F>::poll` (told apart by their mangled names) that inline other tasks'
//! bodies — that task's pending check and the code ahead of its poll, which a job of this task
//! whose poll ends in that check runs only on its way to the other task's poll — unless this
//! task's own code flows into it directly.
use std::collections::BTreeSet;

use super::cfg::{Call, Cfg};
use crate::decode::Insn;
use crate::Image;

/// Whether `name` (demangled, without hash) is the async body of RTIC task `task`:
/// `<crate>::app::<task>::{{closure}}`.
pub fn is_task_body(name: &str, task: &str) -> bool {
    name.strip_suffix("::{{closure}}")
        .and_then(|p| p.strip_suffix(task))
        .is_some_and(|p| p.ends_with("::app::"))
}

/// Whether `name` (demangled, without hash) is RTIC 2's executor's poll of one task's future,
/// `rtic::export::executor::AsyncTaskExecutor<F>::poll` (its instances differ by their hash).
fn is_executor_poll(name: &str) -> bool {
    name == "rtic::export::executor::AsyncTaskExecutor<F>::poll"
}

/// Whose polls a block runs: this task's, another task's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Owners {
    own: bool,
    other: bool,
}

/// The blocks of `graph` (of the dispatcher whose instructions are `insns`) that run another of
/// `others`' polls and none of `task`'s: what to leave out for `task`'s part. `None` when no block
/// runs `task`'s poll (nothing to tell its part by), or when leaving them out would leave a block of
/// `task`'s own unreached, or a block that `task`'s own code leads to and that had a way to a return
/// without one.
pub fn others_blocks(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    task: &str,
    others: &[String],
) -> Option<BTreeSet<usize>> {
    let classify = |name: &str, into: &mut Owners| {
        if is_task_body(name, task) {
            into.own = true;
        } else if others.iter().any(|o| is_task_body(name, o)) {
            into.other = true;
        }
    };
    // Each block's executor instances (`AsyncTaskExecutor<F>::poll` as DWARF names it, by its
    // mangled name: one instance per task's future), and which tasks' bodies each instance inlines.
    let mut instances: Vec<BTreeSet<String>> = vec![BTreeSet::new(); graph.blocks.len()];
    let mut polls_of: std::collections::BTreeMap<String, BTreeSet<bool>> = Default::default();
    let owners: Vec<Owners> = graph
        .blocks
        .iter()
        .enumerate()
        .map(|(b, block)| {
            let mut owners = Owners::default();
            for insn in &insns[block.first..=block.last] {
                let raw = image.inlined_raw_at(insn.addr);
                let names: Vec<String> = raw
                    .iter()
                    .map(|r| format!("{:#}", rustc_demangle::demangle(r)))
                    .collect();
                let executors = raw
                    .iter()
                    .zip(&names)
                    .filter(|(_, n)| is_executor_poll(n))
                    .map(|(r, _)| r.clone());
                let mut here = Owners::default();
                for name in &names {
                    classify(name, &mut here);
                }
                for e in executors {
                    if here.own {
                        polls_of.entry(e.clone()).or_default().insert(true);
                    }
                    if here.other {
                        polls_of.entry(e.clone()).or_default().insert(false);
                    }
                    instances[b].insert(e);
                }
                owners.own |= here.own;
                owners.other |= here.other;
            }
            if let Some(Call::Direct { target, .. }) = block.call {
                classify(&image.name(target), &mut owners);
            }
            owners
        })
        .collect();
    if !owners.iter().any(|o| o.own) {
        return None;
    }
    let mut dropped: BTreeSet<usize> = owners
        .iter()
        .enumerate()
        .filter(|(_, o)| o.other && !o.own)
        .map(|(b, _)| b)
        .collect();
    // What this task's own code flows into directly stays.
    for (b, block) in graph.blocks.iter().enumerate() {
        if owners[b].own {
            for e in &block.succs {
                dropped.remove(&e.to);
            }
        }
    }
    // Every block of this task's own that the dispatcher reaches must stay reachable: one that only
    // another task's code leads to says the attribution does not tell the polls apart, and the whole
    // dispatcher is the bound.
    let before = graph.reached_avoiding(&BTreeSet::new());
    let after = graph.reached_avoiding(&dropped);
    let own_reached = owners
        .iter()
        .enumerate()
        .all(|(b, o)| !o.own || !before.contains(&b) || after.contains(&b));
    // And every block the part keeps on the way on from this task's own code that had a way to a
    // return must keep one: the bound charges no way into blocks that cannot return
    // ([`super::path`]), so a way of this task's job that returned only through code named another
    // task's (code LLVM shares between two polls) would be left out of the part rather than cut off
    // at it. A kept block that this task's code does not lead to and that returned only through
    // another task's poll (the executor's code between that task's pending check and its poll) is
    // on that task's way, charged in its part: a job of this task that runs it runs that task's
    // poll before its own, and this task's part takes the pending check's other way past them.
    let own: BTreeSet<usize> = after.iter().copied().filter(|&b| owners[b].own).collect();
    // Another task's executor code — a block named no task's body, inlined only from executor
    // instances that poll other tasks' bodies (its pending check's pending way, the code ahead of
    // its poll) — is that task's way, not this task's: a run of this task's job that goes on
    // through it is dispatching the other task, whose part holds it. So the way on from this
    // task's code is followed up to such code, but for a block this task's own code flows into
    // directly (code merged with this task's tail stays this task's).
    let others_executor: BTreeSet<usize> = (0..graph.blocks.len())
        .filter(|&b| {
            let o = owners[b];
            !o.own
                && !o.other
                && !instances[b].is_empty()
                && instances[b].iter().all(|e| {
                    polls_of
                        .get(e)
                        .is_some_and(|t| t == &BTreeSet::from([false]))
                })
        })
        .filter(|b| {
            !graph
                .blocks
                .iter()
                .enumerate()
                .any(|(p, block)| owners[p].own && block.succs.iter().any(|e| e.to == *b))
        })
        .collect();
    let past: BTreeSet<usize> = dropped.union(&others_executor).copied().collect();
    let on_from_own = graph.reached_from_avoiding(&own, &past);
    let returned = graph.returning_avoiding(&BTreeSet::new());
    let returns = graph.returning_avoiding(&dropped);
    let still_returning = on_from_own
        .iter()
        .all(|b| !returned.contains(b) || returns.contains(b));
    (own_reached && still_returning).then_some(dropped)
}
