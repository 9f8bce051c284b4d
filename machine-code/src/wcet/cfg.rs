//! A function's control-flow graph from its decoded instructions: basic blocks, their edges (taken
//! or fallen through), calls and exits; dominators and natural loops.
use std::collections::{BTreeMap, BTreeSet};

use crate::decode::{Flow, Insn, Opcode, Operand};
use crate::image::Function;
use crate::Error;

/// An edge to another block of the function.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    pub to: usize,
    /// A taken branch (pays the pipeline refill), not a fall-through.
    pub taken: bool,
}

/// What a block's last instruction calls.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Call {
    /// `BL`, or a `B` out of the function (a tail call; `tail`).
    Direct { target: u64, tail: bool },
    /// `BLX Rm`, or `BX Rm` not a return (`tail`), at the instruction's address.
    Indirect { at: u64, tail: bool },
}

/// A basic block: instructions `first..=last` (indices into the function's instructions).
#[derive(Debug, Clone)]
pub struct Block {
    pub first: usize,
    pub last: usize,
    pub succs: Vec<Edge>,
    pub call: Option<Call>,
    /// Control may leave the function here (a return, a tail call, the end of its code).
    pub exit: bool,
    /// A copy node splitting made of a block ([`Cfg::split_irreducible`]).
    pub copy: bool,
}

/// A function's control-flow graph.
#[derive(Debug, Clone)]
pub struct Cfg {
    pub blocks: Vec<Block>,
}

/// The entries of a table branch, where its data ends, and whether a bound check limits them: the table follows the
/// instruction up to the next code, its entries limited by a `CMP Rm, #n` on the index before it (n + 1 entries).
/// Without the check (the compiler knew the index's range, e.g. an enum's discriminant loaded as a byte) the data
/// up to the next code may hold more than the table (its padding, a literal pool): [`Cfg::build`] ends such a
/// table at its first entry that is no instruction of the function.
fn table_targets(
    f: &Function,
    insns: &[Insn],
    at: usize,
    halfwords: bool,
    index: u8,
) -> Result<(Vec<u64>, u64, bool), Error> {
    let insn = &insns[at];
    let table = insn.next();
    let unfollowable = |what: &str| Error::Unfollowable {
        function: f.name.clone(),
        address: insn.addr,
        what: what.to_string(),
    };
    let &(_, end) = f
        .data
        .iter()
        .find(|(from, _)| *from == table)
        .ok_or_else(|| unfollowable("a table branch without its table"))?;
    let size = if halfwords { 2 } else { 1 };
    let mut entries = (end - table) / size;
    // The bound check on the index: `cmp Rm, #n` (then `bhi` to the default) shortly before.
    let limit = insns[at.saturating_sub(6)..at].iter().rev().find_map(|i| {
        (i.inst.opcode == Opcode::CMP
            && matches!(i.inst.operands[0], Operand::Reg(r) if r.number() == index))
        .then(|| i.immediate())
        .flatten()
    });
    if let Some(limit) = limit {
        entries = entries.min(u64::from(limit) + 1);
    }
    // The entries' addresses (their bytes are data, zeroed in `code`: read from the image).
    Ok((
        (0..entries).map(|k| table + k * size).collect(),
        end,
        limit.is_some(),
    ))
}

impl Cfg {
    /// Builds the graph of `f`; `read` reads a jump table's entry from the image (address, entry
    /// size in bytes) and `returns` says whether a called function can return.
    pub fn build(
        f: &Function,
        read: &dyn Fn(u64, u64) -> Option<u64>,
        returns: &dyn Fn(u64) -> bool,
    ) -> Result<Cfg, Error> {
        let insns = f.instructions()?;
        if insns.is_empty() {
            return Err(Error::Other(format!("{}: no instructions", f.name)));
        }
        let index: BTreeMap<u64, usize> =
            insns.iter().enumerate().map(|(k, i)| (i.addr, k)).collect();
        let inside = |t: u64| index.get(&t).copied();
        let unfollowable = |i: &Insn, what: &str| Error::Unfollowable {
            function: f.name.clone(),
            address: i.addr,
            what: what.to_string(),
        };
        // Successor instructions of each instruction: (index, taken), plus calls and exits.
        let mut tables: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        let mut leaders = BTreeSet::from([0usize]);
        for (k, insn) in insns.iter().enumerate() {
            let flow = insn.flow();
            if flow != Flow::Next {
                leaders.insert(k + 1);
            }
            match flow {
                Flow::Branch(t) if f.contains(t) => {
                    let to = inside(t).ok_or_else(|| {
                        unfollowable(insn, "a branch into the middle of an instruction")
                    })?;
                    leaders.insert(to);
                }
                Flow::Table {
                    halfwords,
                    index: rm,
                } => {
                    let mut targets = Vec::new();
                    let (entries, table_end, checked) = table_targets(f, insns, k, halfwords, rm)?;
                    for (n, entry) in entries.into_iter().enumerate() {
                        let size = if halfwords { 2 } else { 1 };
                        let offset = read(entry, size)
                            .ok_or_else(|| unfollowable(insn, "a jump table outside the image"))?;
                        let target = insn.next() + 2 * offset;
                        // An entry into the table itself is its padding byte (a table of an odd
                        // number of bytes is padded to the next halfword): never a target.
                        if target < table_end {
                            continue;
                        }
                        let Some(to) = inside(target) else {
                            // Without a bound check, the table's entries are the halfwords (bytes) before
                            // the first that leads to no instruction of the function: every entry of the
                            // table leads to one, so the table ends before it, and the data after it (the
                            // padding, a literal pool) is not the table. Entries of that data that happen to
                            // lead to an instruction are taken as targets: more paths, never fewer.
                            if !checked && n > 0 {
                                break;
                            }
                            return Err(unfollowable(
                                insn,
                                "a jump table entry that is not an instruction",
                            ));
                        };
                        leaders.insert(to);
                        targets.push(to);
                    }
                    targets.sort_unstable();
                    targets.dedup();
                    tables.insert(k, targets);
                }
                _ => {}
            }
        }
        let starts: Vec<usize> = leaders.into_iter().filter(|&k| k < insns.len()).collect();
        let block_of: BTreeMap<usize, usize> =
            starts.iter().enumerate().map(|(b, &k)| (k, b)).collect();
        let mut blocks = Vec::with_capacity(starts.len());
        for (b, &first) in starts.iter().enumerate() {
            let last = starts.get(b + 1).map_or(insns.len() - 1, |&next| next - 1);
            let insn = &insns[last];
            let mut block = Block {
                first,
                last,
                succs: Vec::new(),
                call: None,
                exit: false,
                copy: false,
            };
            // The next instruction, when it follows directly (not behind a literal pool).
            let fall = (last + 1 < insns.len() && insns[last + 1].addr == insn.next())
                .then(|| block_of[&(last + 1)]);
            let fall_through = |block: &mut Block| match fall {
                Some(to) => block.succs.push(Edge { to, taken: false }),
                None => block.exit = true,
            };
            match insn.flow() {
                Flow::Next => fall_through(&mut block),
                Flow::Branch(t) => {
                    if f.contains(t) {
                        block.succs.push(Edge {
                            to: block_of[&inside(t).unwrap_or(0)],
                            taken: true,
                        });
                    } else {
                        block.call = Some(Call::Direct {
                            target: t,
                            tail: true,
                        });
                        block.exit = true;
                    }
                    if insn.conditional {
                        fall_through(&mut block);
                    }
                }
                Flow::Call(t) => {
                    block.call = Some(Call::Direct {
                        target: t,
                        tail: false,
                    });
                    // A conditional call (`BL<c>` in an IT block) may be skipped: it goes on
                    // whether or not its callee returns.
                    if insn.conditional || returns(t) {
                        fall_through(&mut block);
                    }
                }
                Flow::IndirectCall(_) => {
                    block.call = Some(Call::Indirect {
                        at: insn.addr,
                        tail: false,
                    });
                    fall_through(&mut block);
                }
                Flow::Return => {
                    block.exit = true;
                    if insn.conditional {
                        fall_through(&mut block);
                    }
                }
                Flow::IndirectJump => {
                    block.call = Some(Call::Indirect {
                        at: insn.addr,
                        tail: true,
                    });
                    block.exit = true;
                    if insn.conditional {
                        fall_through(&mut block);
                    }
                }
                Flow::Table { .. } => {
                    for &to in tables.get(&last).map(Vec::as_slice).unwrap_or(&[]) {
                        block.succs.push(Edge {
                            to: block_of[&to],
                            taken: true,
                        });
                    }
                }
                Flow::Stop => {
                    if insn.conditional {
                        fall_through(&mut block);
                    }
                }
            }
            blocks.push(block);
        }
        Ok(Cfg { blocks })
    }

    /// The blocks reachable from the entry, in reverse postorder.
    pub fn reverse_postorder(&self) -> Vec<usize> {
        let n = self.blocks.len();
        let mut seen = vec![false; n];
        let mut order = Vec::with_capacity(n);
        // Iterative depth-first search: (block, next successor to visit).
        let mut stack = vec![(0usize, 0usize)];
        seen[0] = true;
        while let Some(&mut (b, ref mut next)) = stack.last_mut() {
            if let Some(edge) = self.blocks[b].succs.get(*next) {
                *next += 1;
                if !seen[edge.to] {
                    seen[edge.to] = true;
                    stack.push((edge.to, 0));
                }
            } else {
                order.push(b);
                stack.pop();
            }
        }
        order.reverse();
        order
    }

    /// The immediate dominator of each reachable block (the entry's is itself; unreachable: None).
    pub fn dominators(&self) -> Vec<Option<usize>> {
        let order = self.reverse_postorder();
        let n = self.blocks.len();
        let mut rank = vec![usize::MAX; n];
        for (r, &b) in order.iter().enumerate() {
            rank[b] = r;
        }
        let mut preds = vec![Vec::new(); n];
        for (b, block) in self.blocks.iter().enumerate() {
            for e in &block.succs {
                preds[e.to].push(b);
            }
        }
        let mut idom: Vec<Option<usize>> = vec![None; n];
        idom[0] = Some(0);
        let intersect = |idom: &[Option<usize>], mut a: usize, mut b: usize| {
            while a != b {
                while rank[a] > rank[b] {
                    a = idom[a].unwrap_or(0);
                }
                while rank[b] > rank[a] {
                    b = idom[b].unwrap_or(0);
                }
            }
            a
        };
        let mut changed = true;
        while changed {
            changed = false;
            for &b in order.iter().skip(1) {
                let mut new: Option<usize> = None;
                for &p in &preds[b] {
                    if idom[p].is_none() {
                        continue;
                    }
                    new = Some(match new {
                        None => p,
                        Some(n) => intersect(&idom, p, n),
                    });
                }
                if new.is_some() && idom[b] != new {
                    idom[b] = new;
                    changed = true;
                }
            }
        }
        idom
    }

    /// Whether `a` dominates `b`.
    pub fn dominates(idom: &[Option<usize>], a: usize, mut b: usize) -> bool {
        loop {
            if a == b {
                return true;
            }
            match idom[b] {
                Some(d) if d != b => b = d,
                _ => return false,
            }
        }
    }

    /// The natural loops: (header, body blocks, latches), one per header, innermost (smallest)
    /// first. `Err(block)` names a block entered by a retreating edge its target does not dominate
    /// (irreducible flow, which has no natural loop to bound).
    pub fn loops(&self) -> Result<Vec<Loop>, usize> {
        let idom = self.dominators();
        let mut preds = vec![Vec::new(); self.blocks.len()];
        for (b, block) in self.blocks.iter().enumerate() {
            for e in &block.succs {
                preds[e.to].push(b);
            }
        }
        let mut by_header: BTreeMap<usize, Loop> = BTreeMap::new();
        for (b, block) in self.blocks.iter().enumerate() {
            if idom[b].is_none() {
                continue;
            }
            for e in &block.succs {
                if Cfg::dominates(&idom, e.to, b) {
                    let l = by_header.entry(e.to).or_insert_with(|| Loop {
                        header: e.to,
                        body: BTreeSet::from([e.to]),
                        latches: Vec::new(),
                    });
                    l.latches.push(b);
                    let mut work = vec![b];
                    while let Some(x) = work.pop() {
                        if l.body.insert(x) {
                            work.extend(preds[x].iter().copied().filter(|p| idom[*p].is_some()));
                        }
                    }
                }
            }
        }
        // A cycle left that is no natural loop: irreducible.
        let order = self.reverse_postorder();
        let mut rank = vec![usize::MAX; self.blocks.len()];
        for (r, &b) in order.iter().enumerate() {
            rank[b] = r;
        }
        for &b in &order {
            for e in &self.blocks[b].succs {
                if rank[e.to] <= rank[b] && !Cfg::dominates(&idom, e.to, b) {
                    return Err(e.to);
                }
            }
        }
        let mut loops: Vec<Loop> = by_header.into_values().collect();
        loops.sort_by_key(|l| l.body.len());
        Ok(loops)
    }
}

/// A natural loop.
#[derive(Debug, Clone)]
pub struct Loop {
    pub header: usize,
    pub body: BTreeSet<usize>,
    /// The blocks with an edge back to the header.
    pub latches: Vec<usize>,
}

/// The most blocks [`Cfg::split_irreducible`] may make of a graph, as a multiple of its own: node
/// splitting can grow a graph exponentially, and a graph that needs more is declined instead.
pub const MAX_SPLIT_GROWTH: usize = 4;

impl Cfg {
    /// The graph made reducible by node splitting, where it is not: a cycle entered at more than one
    /// block (an async task's loop, entered at its top on the first poll and at an `await` on every
    /// later one) keeps one block as its header — the one whose split copies the fewest blocks, of
    /// those the one leaving the fewest loops — and the blocks a path from each entry runs through
    /// before it reaches the header are copied for the way in from outside (marked
    /// [`Block::copy`]). Every path of the
    /// graph is a path of the result (its blocks are copies with the same instructions and edges),
    /// so a bound of the result bounds the graph; its new natural loop has the header's place, where
    /// a bounds file can state its bound (docs/analysis.md, "Async tasks"). `Ok(None)` when the graph
    /// is reducible; `Err(first)` when splitting would grow it beyond [`MAX_SPLIT_GROWTH`] times:
    /// `first`, the instruction the header it came to starts at (an index into the function's
    /// instructions, as [`Block::first`]: the header may be a copy, a block the graph as given
    /// does not have).
    pub fn split_irreducible(&self) -> Result<Option<Cfg>, usize> {
        let mut graph = self.clone();
        let limit = self.blocks.len() * MAX_SPLIT_GROWTH;
        let mut split = false;
        loop {
            let header = match graph.loops() {
                Ok(_) => return Ok(split.then_some(graph)),
                Err(b) => b,
            };
            if graph.blocks.len() > limit {
                return Err(graph.blocks[header].first);
            }
            graph = graph.split_region(header);
            split = true;
        }
    }

    /// The graph without the blocks in `dropped`: the blocks block 0 reaches through the others,
    /// renumbered in their order, each edge into a dropped block left out (a block left with no
    /// successor and no exit ends no path). `None` when block 0 itself is dropped. Every path of
    /// the graph that avoids the dropped blocks is a path of the result.
    pub fn without(&self, dropped: &BTreeSet<usize>) -> Option<Cfg> {
        if dropped.contains(&0) {
            return None;
        }
        let seen = self.reached_avoiding(dropped);
        let number: BTreeMap<usize, usize> =
            seen.iter().enumerate().map(|(k, &b)| (b, k)).collect();
        let blocks = seen
            .iter()
            .map(|&b| {
                let mut block = self.blocks[b].clone();
                block.succs = block
                    .succs
                    .iter()
                    .filter_map(|e| number.get(&e.to).map(|&to| Edge { to, taken: e.taken }))
                    .collect();
                block
            })
            .collect();
        Some(Cfg { blocks })
    }

    /// The graph without the blocks from which no exit is reached (after [`Self::without`], a block
    /// whose every way on was left out ends no path): the blocks of the paths from block 0 to an
    /// exit, renumbered as [`Self::without`] does. `None` when block 0 reaches no exit.
    pub fn on_paths_to_exits(&self) -> Option<Cfg> {
        let mut live = BTreeSet::new();
        for (b, block) in self.blocks.iter().enumerate() {
            if block.exit && !live.contains(&b) {
                live.extend(self.reach(b, true));
            }
        }
        let dead: BTreeSet<usize> = (0..self.blocks.len())
            .filter(|b| !live.contains(b))
            .collect();
        if dead.is_empty() {
            return Some(self.clone());
        }
        self.without(&dead)
    }

    /// The blocks block 0 reaches without entering any block of `dropped`.
    pub fn reached_avoiding(&self, dropped: &BTreeSet<usize>) -> BTreeSet<usize> {
        self.reached_from_avoiding(&BTreeSet::from([0usize]), dropped)
    }

    /// The blocks of `from` and those they reach without entering any block of `dropped`.
    pub fn reached_from_avoiding(
        &self,
        from: &BTreeSet<usize>,
        dropped: &BTreeSet<usize>,
    ) -> BTreeSet<usize> {
        let mut seen = from.clone();
        let mut work: Vec<usize> = from.iter().copied().collect();
        while let Some(b) = work.pop() {
            for e in &self.blocks[b].succs {
                if !dropped.contains(&e.to) && seen.insert(e.to) {
                    work.push(e.to);
                }
            }
        }
        seen
    }

    /// The blocks outside `dropped` from which a path that enters none of `dropped` reaches a block
    /// where the function may return ([`Block::exit`]).
    pub fn returning_avoiding(&self, dropped: &BTreeSet<usize>) -> BTreeSet<usize> {
        let mut preds = vec![Vec::new(); self.blocks.len()];
        for (b, block) in self.blocks.iter().enumerate() {
            for e in &block.succs {
                preds[e.to].push(b);
            }
        }
        let mut seen: BTreeSet<usize> = (0..self.blocks.len())
            .filter(|b| self.blocks[*b].exit && !dropped.contains(b))
            .collect();
        let mut work: Vec<usize> = seen.iter().copied().collect();
        while let Some(x) = work.pop() {
            for &p in &preds[x] {
                if !dropped.contains(&p) && seen.insert(p) {
                    work.push(p);
                }
            }
        }
        seen
    }

    /// The blocks reachable from `from` along the edges (or, `backwards`, that reach it).
    fn reach(&self, from: usize, backwards: bool) -> BTreeSet<usize> {
        let mut preds = vec![Vec::new(); self.blocks.len()];
        for (b, block) in self.blocks.iter().enumerate() {
            for e in &block.succs {
                preds[e.to].push(b);
            }
        }
        let mut seen = BTreeSet::from([from]);
        let mut work = vec![from];
        while let Some(x) = work.pop() {
            let next: Vec<usize> = if backwards {
                preds[x].clone()
            } else {
                self.blocks[x].succs.iter().map(|e| e.to).collect()
            };
            for y in next {
                if seen.insert(y) {
                    work.push(y);
                }
            }
        }
        seen
    }

    /// The strongly connected region around `block`, and its entries (the blocks of it with an edge
    /// from outside).
    fn region(&self, block: usize) -> (BTreeSet<usize>, BTreeSet<usize>) {
        let ahead = self.reach(block, false);
        let behind = self.reach(block, true);
        let region: BTreeSet<usize> = ahead.intersection(&behind).copied().collect();
        let entries = region
            .iter()
            .copied()
            .filter(|&x| {
                self.blocks
                    .iter()
                    .enumerate()
                    .any(|(p, blk)| !region.contains(&p) && blk.succs.iter().any(|e| e.to == x))
            })
            .collect();
        (region, entries)
    }

    /// The region around `block` split at the block that copies the fewest blocks (the function's
    /// entry, where the region holds it, always stays); of those that copy as few, the one that
    /// leaves the fewest loops (none of them irreducible), so that the cycles of an async task's
    /// loop, entered at its top and at each `await`, share one header.
    fn split_region(&self, block: usize) -> Cfg {
        let (region, entries) = self.region(block);
        if region.contains(&0) {
            let mut graph = self.clone();
            graph.split_at(0, &region, &entries);
            return graph;
        }
        let mut fewest: Vec<Cfg> = Vec::new();
        for &header in &region {
            let mut graph = self.clone();
            graph.split_at(header, &region, &entries);
            // A split that copies nothing changes nothing (a region entered at one block, with
            // an irreducible region inside: `block` is in that one).
            if graph.blocks.len() == self.blocks.len() && header != block {
                continue;
            }
            match fewest.first().map(|g| g.blocks.len()) {
                Some(n) if n < graph.blocks.len() => {}
                Some(n) if n == graph.blocks.len() => fewest.push(graph),
                _ => fewest = vec![graph],
            }
        }
        let loops = |g: &Cfg| g.loops().map_or(usize::MAX, |l| l.len());
        fewest
            .into_iter()
            .min_by_key(loops)
            .unwrap_or_else(|| self.clone())
    }

    /// Splits `region` at `header` (one of its `entries`): every other entry's blocks up to the
    /// header are copied for the edges from outside the region.
    fn split_at(&mut self, header: usize, region: &BTreeSet<usize>, entries: &BTreeSet<usize>) {
        let entries: Vec<usize> = entries.iter().copied().filter(|&x| x != header).collect();
        for entry in entries {
            // The region's blocks reachable from this entry without passing the header.
            let mut part = BTreeSet::from([entry]);
            let mut work = vec![entry];
            while let Some(x) = work.pop() {
                for e in &self.blocks[x].succs {
                    if e.to != header && region.contains(&e.to) && part.insert(e.to) {
                        work.push(e.to);
                    }
                }
            }
            let copy: BTreeMap<usize, usize> = part
                .iter()
                .enumerate()
                .map(|(k, &x)| (x, self.blocks.len() + k))
                .collect();
            for &x in &part {
                let mut block = self.blocks[x].clone();
                block.copy = true;
                for e in &mut block.succs {
                    if let Some(&c) = copy.get(&e.to) {
                        e.to = c;
                    }
                }
                self.blocks.push(block);
            }
            // The ways in from outside the region now enter the copy.
            let entry_copy = copy[&entry];
            let copies: BTreeSet<usize> = copy.values().copied().collect();
            for p in 0..self.blocks.len() {
                if region.contains(&p) || copies.contains(&p) {
                    continue;
                }
                for e in &mut self.blocks[p].succs {
                    if e.to == entry {
                        e.to = entry_copy;
                    }
                }
            }
        }
    }
}
