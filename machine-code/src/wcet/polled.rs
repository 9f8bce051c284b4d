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
//! the task is bounded by the whole dispatcher, as before.
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
    let owners: Vec<Owners> = graph
        .blocks
        .iter()
        .map(|block| {
            let mut owners = Owners::default();
            for insn in &insns[block.first..=block.last] {
                for name in image.inlined_at(insn.addr) {
                    classify(&name, &mut owners);
                }
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
    let on_from_own = graph.reached_from_avoiding(&own, &dropped);
    let returned = graph.returning_avoiding(&BTreeSet::new());
    let returns = graph.returning_avoiding(&dropped);
    let still_returning = on_from_own
        .iter()
        .all(|b| !returned.contains(b) || returns.contains(b));
    (own_reached && still_returning).then_some(dropped)
}
