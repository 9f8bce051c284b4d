//! The longest path through a function's graph, exact on the graph left after each loop is
//! collapsed into one node, innermost loop first: a loop of bound N costs (N − 1) × its longest
//! iteration (header to a branch back) plus its longest way out (header to an exit edge). Every
//! path through the loop runs its header at most N times, each of the first N − 1 passes is an
//! iteration at most as long as the longest, and the last pass leaves by some exit at most as long
//! as the longest: so the collapsed node bounds every path through the loop, and the longest path
//! on the acyclic graph that remains bounds every path through the function.
//!
//! Where it is known too that at most B passes go on past the header (a loop whose header's test
//! ends it on its last run, as `for x in ..` compiles: B = N − 1), a way out from inside the body
//! ends one of those B passes: such a path makes at most B − 1 passes past the header back to it
//! before its last ([`LoopCount::Body`]).
//!
//! A way out counts only where the function can still return after it: an exit edge into a block
//! from which no path reaches a return (a trap, a call that never returns, a loop with no exit, or
//! a block whose ways on were left out, as one topic's job leaves out another's sample) ends no
//! path that completes, so it is no last pass to charge, and the collapsed node does not lead there
//! (`completing`). The bound is of the paths that complete (a job's execution); one that never
//! returns is a halt, not a longer job.
use std::collections::BTreeSet;

use serde::Serialize;

/// What a path costs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Cost {
    /// Core and memory cycles.
    pub cycles: u64,
    /// Instructions executed.
    pub instructions: u64,
    /// Stated waits on peripherals, in nanoseconds (apart from the cycles).
    pub wait_ns: u64,
}

impl Cost {
    /// Both added.
    pub fn plus(self, other: Cost) -> Cost {
        Cost {
            cycles: self.cycles + other.cycles,
            instructions: self.instructions + other.instructions,
            wait_ns: self.wait_ns + other.wait_ns,
        }
    }
    /// This divided by `n`, each figure rounded up.
    pub fn div_ceil(self, n: u64) -> Cost {
        Cost {
            cycles: self.cycles.div_ceil(n),
            instructions: self.instructions.div_ceil(n),
            wait_ns: self.wait_ns.div_ceil(n),
        }
    }
    /// `n` times this.
    pub fn times(self, n: u64) -> Cost {
        Cost {
            cycles: self.cycles * n,
            instructions: self.instructions * n,
            wait_ns: self.wait_ns * n,
        }
    }
}

/// How a loop is bounded for the collapse.
#[derive(Debug, Clone, Copy)]
pub enum LoopCount {
    /// The header runs at most this many times per entry.
    Passes(u64),
    /// The header runs at most `header` times per entry, and at most `body` of those passes go on
    /// past it (into any other block of the loop): a loop whose header's test ends it on its last
    /// run has `body` = `header` − 1. Charged the longer of: a way out from the header after
    /// `header` − 1 passes back, at most `body` of them through the body; a way out from the body
    /// after `header` − 1 passes back, at most `body` − 1 of them through the body (the last pass
    /// is one of the `body`). A pass back that stays in the header (a header with an edge to
    /// itself) is charged its own longest such pass.
    Body { header: u64, body: u64 },
    /// A wait: the loop spins for at most this long (ns, and as cycles at the clock); it costs its
    /// way out plus the wait, and at most one instruction per cycle of the wait.
    Wait { ns: u64, cycles: u64 },
    /// An exclusive-access retry loop (`LDREX` … `STREX`, back while the store fails): one pass
    /// per job; each preemption inside it costs one more iteration, returned apart
    /// ([`Longest::retry`]).
    Retry,
    /// One of several loops that share one count between them (a memory function's loops: each
    /// pass moves at least `per_pass` of the `n` bytes all of them move together): collapsed to its
    /// way out, its longest iteration per unit moved returned apart ([`Longest::shared`]) for the
    /// caller to charge `n` times. Whatever passes the loops make, `Σ passes·per_pass ≤ n`, so
    /// `Σ passes·iteration ≤ n · max(iteration / per_pass)`.
    Shared { per_pass: u64 },
    /// A loop whose passes back to its header are stated in total for the whole job, however often
    /// it is entered (the bounds file's `totals`): collapsed to its way out, its longest iteration
    /// returned apart ([`Longest::totals`], under `key`) for the job's bound to charge the stated
    /// number of times. Loops under one key share the count (their passes back together). Every
    /// pass back is one iteration at most as long as the longest of them, so the passes of all
    /// their entries together cost at most that many longest iterations.
    Total { key: usize },
    /// No exit: no path through it completes.
    Endless,
}

/// The longest path, and the longest iteration of an exclusive-access retry loop on any path (what
/// one preemption can add).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Longest {
    pub path: Cost,
    pub retry: Cost,
    /// The longest iteration per unit moved of a [`LoopCount::Shared`] loop (rounded up).
    pub shared: Cost,
    /// The longest iteration of each [`LoopCount::Total`] loop, by its key.
    pub totals: Vec<(usize, Cost)>,
}

/// One node: a block, or a loop collapsed.
#[derive(Debug, Clone)]
pub struct Node {
    pub cost: Cost,
    /// Successors and what the edge adds (a taken branch's refill).
    pub succs: Vec<(usize, Cost)>,
    /// The function may return from here.
    pub exit: bool,
    /// What returning from here adds (a tail call's callee), not paid by the ways on.
    pub exit_cost: Cost,
}

/// A loop to collapse: its header and body (node indices of the original graph).
#[derive(Debug, Clone)]
pub struct LoopNodes {
    pub header: usize,
    pub body: BTreeSet<usize>,
    pub count: LoopCount,
}

/// Why no longest path could be found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PathError {
    /// A cycle left after collapsing the natural loops (irreducible flow), at this node.
    Irreducible(usize),
    /// No path from the entry reaches a return.
    NoExit,
}

/// Longest distances from `start` over `members` (edges into `skip` left out), in topological
/// order; `None` for a node not reached.
fn longest_from(
    nodes: &[Node],
    start: usize,
    members: &dyn Fn(usize) -> bool,
    skip: usize,
    key: &dyn Fn(Cost) -> u64,
) -> Result<Vec<Option<Cost>>, PathError> {
    // Topological order by depth-first search, a cycle is an error.
    let n = nodes.len();
    let mut state = vec![0u8; n]; // 0 new, 1 open, 2 done
    let mut order = Vec::new();
    let mut stack = vec![(start, 0usize)];
    state[start] = 1;
    while let Some(&mut (v, ref mut next)) = stack.last_mut() {
        let succ = nodes[v].succs.get(*next).map(|&(to, _)| to);
        match succ {
            Some(to) => {
                *next += 1;
                if to == skip || !members(to) {
                    continue;
                }
                match state[to] {
                    0 => {
                        state[to] = 1;
                        stack.push((to, 0));
                    }
                    1 => return Err(PathError::Irreducible(to)),
                    _ => {}
                }
            }
            None => {
                state[v] = 2;
                order.push(v);
                stack.pop();
            }
        }
    }
    order.reverse();
    let mut dist: Vec<Option<Cost>> = vec![None; n];
    dist[start] = Some(nodes[start].cost);
    for &v in &order {
        let Some(here) = dist[v] else { continue };
        for &(to, edge) in &nodes[v].succs {
            if to == skip || !members(to) {
                continue;
            }
            let via = here.plus(edge).plus(nodes[to].cost);
            if dist[to].is_none_or(|d| key(via) > key(d)) {
                dist[to] = Some(via);
            }
        }
    }
    Ok(dist)
}

/// Per node, whether some path from it reaches a return, along the edges as they stand (the loops
/// collapsed so far: an endless one has no edge on). The graph holds every way a run can go, so a
/// node marked `false` starts no run that returns.
fn completing(nodes: &[Node]) -> Vec<bool> {
    let mut preds = vec![Vec::new(); nodes.len()];
    for (v, node) in nodes.iter().enumerate() {
        for &(to, _) in &node.succs {
            preds[to].push(v);
        }
    }
    let mut returns: Vec<bool> = nodes.iter().map(|node| node.exit).collect();
    let mut work: Vec<usize> = (0..nodes.len()).filter(|&v| returns[v]).collect();
    while let Some(v) = work.pop() {
        for &p in &preds[v] {
            if !returns[p] {
                returns[p] = true;
                work.push(p);
            }
        }
    }
    returns
}

fn better(a: Option<Cost>, b: Cost, key: &dyn Fn(Cost) -> u64) -> Option<Cost> {
    match a {
        Some(a) if key(a) >= key(b) => Some(a),
        _ => Some(b),
    }
}

/// The longest path from node 0 to a return, by `key`, after collapsing `loops` (innermost
/// first). Returns the path's cost.
pub fn longest(
    mut nodes: Vec<Node>,
    loops: &[LoopNodes],
    key: &dyn Fn(Cost) -> u64,
) -> Result<Longest, PathError> {
    let n = nodes.len();
    let mut retry: Option<Cost> = None;
    let mut shared: Option<Cost> = None;
    let mut totals: Vec<(usize, Cost)> = Vec::new();
    // Each original node's representative (itself, or the header of the loop it was collapsed into).
    let mut rep: Vec<usize> = (0..n).collect();
    for l in loops {
        let members: BTreeSet<usize> = l.body.iter().map(|&b| rep[b]).collect();
        let h = rep[l.header];
        let is_member = |x: usize| members.contains(&x);
        let dist = longest_from(&nodes, h, &is_member, h, key)?;
        let returns = completing(&nodes);
        // Iterations and ways out, [0] those that stay in the header, [1] those through the body.
        let mut iterations: [Option<Cost>; 2] = [None, None];
        let mut ways_out: [Option<Cost>; 2] = [None, None];
        let mut exits: Vec<usize> = Vec::new();
        let mut exit_here = false;
        for &m in &members {
            let Some(d) = dist[m] else { continue };
            let part = usize::from(m != h);
            if nodes[m].exit {
                ways_out[part] = better(ways_out[part], d.plus(nodes[m].exit_cost), key);
                exit_here = true;
            }
            for &(to, edge) in &nodes[m].succs {
                if to == h {
                    iterations[part] = better(iterations[part], d.plus(edge), key);
                } else if !members.contains(&to) && returns[to] {
                    ways_out[part] = better(ways_out[part], d.plus(edge), key);
                    exits.push(to);
                }
            }
        }
        let iteration = iterations[1]
            .map_or(iterations[0], |i| better(iterations[0], i, key))
            .unwrap_or_default();
        let way_out = ways_out[1].map_or(ways_out[0], |o| better(ways_out[0], o, key));
        let collapsed = match (l.count, way_out) {
            (_, None) | (LoopCount::Endless, _) => None,
            (LoopCount::Passes(passes), Some(out)) => {
                Some(iteration.times(passes.max(1) - 1).plus(out))
            }
            (LoopCount::Body { header, body }, Some(out)) => {
                let back = header.max(1) - 1;
                let in_header = iterations[0].unwrap_or_default();
                // `back` passes back, at most `through` of them through the body.
                let passes = |through: u64| {
                    let through = through.min(back);
                    iteration
                        .times(through)
                        .plus(in_header.times(back - through))
                };
                let from_header = ways_out[0].map(|o| passes(body).plus(o));
                let from_body = ways_out[1]
                    .filter(|_| body >= 1)
                    .map(|o| passes(body - 1).plus(o));
                match (from_header, from_body) {
                    (Some(a), Some(b)) => better(Some(a), b, key),
                    (a, b) => a.or(b),
                }
                // No way out the counts allow (a statement the graph contradicts): the header's
                // count alone.
                .or(Some(iteration.times(back).plus(out)))
            }
            (LoopCount::Retry, Some(out)) => {
                retry = better(retry, iteration, key);
                Some(out)
            }
            (LoopCount::Shared { per_pass }, Some(out)) => {
                shared = better(shared, iteration.div_ceil(per_pass.max(1)), key);
                Some(out)
            }
            (LoopCount::Total { key }, Some(out)) => {
                totals.push((key, iteration));
                Some(out)
            }
            (LoopCount::Wait { ns, cycles }, Some(out)) => Some(out.plus(Cost {
                cycles: 0,
                instructions: cycles,
                wait_ns: ns,
            })),
        };
        exits.sort_unstable();
        exits.dedup();
        for &m in &members {
            if m != h {
                nodes[m].succs.clear();
                nodes[m].exit = false;
            }
            nodes[m].exit_cost = Cost::default();
        }
        match collapsed {
            Some(cost) => {
                nodes[h].cost = cost;
                nodes[h].succs = exits.into_iter().map(|to| (to, Cost::default())).collect();
                nodes[h].exit = exit_here;
            }
            None => {
                // No way out: nothing after it is reached through it.
                nodes[h].succs.clear();
                nodes[h].exit = false;
            }
        }
        for b in &l.body {
            rep[*b] = h;
        }
        // Nodes outside that pointed into the loop point at its header already (a natural loop
        // is entered only there).
    }
    let all = |_: usize| true;
    let dist = longest_from(&nodes, 0, &all, usize::MAX, key)?;
    let mut best: Option<Cost> = None;
    for (v, node) in nodes.iter().enumerate() {
        if node.exit {
            if let Some(d) = dist[v] {
                best = better(best, d.plus(node.exit_cost), key);
            }
        }
    }
    Ok(Longest {
        path: best.ok_or(PathError::NoExit)?,
        retry: retry.unwrap_or_default(),
        shared: shared.unwrap_or_default(),
        totals,
    })
}
