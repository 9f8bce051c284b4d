//! What instructions do to the interrupt masking, and the part of a function's graph a critical
//! section runs through ([`super::critical`] states the patterns): the raise and restore encodings,
//! the constant a raise writes (a forward data-flow pass), and the section's region as a graph of
//! its own, bounded as a function is.
use std::collections::BTreeMap;

use super::cfg::{Block, Cfg, Edge};
use crate::decode::{Insn, Opcode, Operand};
use crate::waits::Conditional;
use crate::Image;

/// The deepest nesting of raises of one kind a section is followed through.
const MAX_NESTING: u32 = 16;

/// The two kinds of masking, nested apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Basepri,
    Primask,
}

/// What an instruction does to the masking.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Effect {
    /// A raise: `MSR BASEPRI_MAX, rN` (the register), `CPSID i`, `MSR PRIMASK` of a set constant.
    Raise(Kind, Option<u8>),
    /// A restore: `MSR BASEPRI, rN`, `MSR PRIMASK, rN`, `CPSIE i`.
    Restore(Kind),
}

/// What [`effect`] reads of the registers before an instruction, followed through a block.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Known {
    /// The constant each holds on every path ([`Conditional::Joined`]: a conditional write, which
    /// may not execute, joined with the value before it).
    constants: [Option<u32>; 16],
    /// The registers that may hold a constant with bit 0 set (one was written, under a condition
    /// or not, and no unconditional write has replaced it since): an `MSR PRIMASK` of one of them
    /// may set PRIMASK.
    may_set: u16,
}

impl Known {
    /// The registers after `insn`.
    pub(super) fn step(&mut self, image: &Image, insn: &Insn) {
        let mut taken = self.constants;
        crate::waits::step_constants(image, insn, &mut taken, Conditional::Taken);
        crate::waits::step_constants(image, insn, &mut self.constants, Conditional::Joined);
        let written = insn.writes();
        for r in 0..16u8 {
            if !written.contains(r) {
                continue;
            }
            let bit = 1u16 << r;
            let sets = taken[usize::from(r)].is_some_and(|v| v & 1 == 1);
            if sets {
                self.may_set |= bit;
            } else if !insn.conditional {
                self.may_set &= !bit;
            }
        }
    }
}

/// The masking effect of `insn` (its encoding: ARMv7-M ARM B5.2.3 `MSR`, B5.2.1 `CPS`); `known`
/// what the registers hold before it. An `MSR PRIMASK` is a raise when its register may hold a
/// constant with bit 0 set on some path, else a restore (the value an `MRS` saved, which the code
/// does not fix). A conditional `MSR` (in an `IT` block) has its effect where it executes: a raise
/// is counted as one ([`region`] declines a section whose restore is conditional).
pub(super) fn effect(insn: &Insn, known: &Known) -> Option<Effect> {
    let [hw1, hw2] = insn.raw;
    if insn.len == 2 && hw1 & 0xffe8 == 0xb660 {
        // CPS: im (bit 4) 1 disables; I (bit 1) is PRIMASK.
        if hw1 & 0b10 == 0 {
            return None;
        }
        return Some(if hw1 & 0x10 != 0 {
            Effect::Raise(Kind::Primask, None)
        } else {
            Effect::Restore(Kind::Primask)
        });
    }
    if insn.len == 4 && hw1 & 0xfff0 == 0xf380 && hw2 & 0xff00 == 0x8800 {
        let rn = (hw1 & 0xf) as u8;
        return match hw2 & 0xff {
            0x10 => Some(if known.may_set & (1 << rn) != 0 {
                Effect::Raise(Kind::Primask, None)
            } else {
                Effect::Restore(Kind::Primask)
            }),
            0x11 => Some(Effect::Restore(Kind::Basepri)),
            0x12 => Some(Effect::Raise(Kind::Basepri, Some(rn))),
            _ => None,
        };
    }
    None
}

/// The part of `graph` a section runs through, as a graph of its own: block 0 from the raise
/// (instruction `k` of block `b`) on, every block a path reaches before its kind's nesting is back
/// where it was (a copy per nesting depth it is reached at), ending at that restore (an exit).
pub(super) fn region(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    b: usize,
    k: usize,
    kind: Kind,
) -> Result<Cfg, String> {
    // (block, first instruction, depth on entry) → sub-block.
    let mut index: BTreeMap<(usize, usize, u32), usize> = BTreeMap::new();
    let mut blocks: Vec<Block> = Vec::new();
    let mut work = vec![(b, k, 0u32)];
    index.insert((b, k, 0), 0);
    blocks.push(placeholder());
    while let Some((ob, first, depth_in)) = work.pop() {
        let me = index[&(ob, first, depth_in)];
        let block = &graph.blocks[ob];
        let mut depth = depth_in;
        let mut known = Known::default();
        let mut end = None;
        for (j, insn) in insns
            .iter()
            .enumerate()
            .take(block.last + 1)
            .skip(block.first)
        {
            if j >= first {
                match effect(insn, &known) {
                    Some(Effect::Raise(kd, _)) if kd == kind => depth += 1,
                    // A restore that may not execute: the section may run on past it, to a
                    // restore this part of the graph does not fix.
                    Some(Effect::Restore(kd)) if kd == kind && insn.conditional => {
                        return Err(format!(
                            "restored under a condition (an IT block) at {:#010x}",
                            insn.addr
                        ));
                    }
                    Some(Effect::Restore(kd)) if kd == kind => {
                        depth = depth.saturating_sub(1);
                        if depth == 0 {
                            end = Some(j);
                            break;
                        }
                    }
                    _ => {}
                }
                if depth > MAX_NESTING {
                    return Err(format!(
                        "raises nest deeper than {MAX_NESTING} on a path from the raise"
                    ));
                }
            }
            known.step(image, insn);
        }
        if let Some(j) = end {
            blocks[me] = Block {
                first,
                last: j,
                succs: Vec::new(),
                call: None,
                exit: true,
                copy: block.copy,
            };
            continue;
        }
        if block.exit {
            return Err(format!(
                "not restored before the function returns (at {:#010x})",
                insns[block.last].addr
            ));
        }
        let mut succs = Vec::new();
        for e in &block.succs {
            let key = (e.to, graph.blocks[e.to].first, depth);
            let to = match index.get(&key) {
                Some(&to) => to,
                None => {
                    let to = blocks.len();
                    blocks.push(placeholder());
                    index.insert(key, to);
                    work.push(key);
                    to
                }
            };
            succs.push(Edge { to, taken: e.taken });
        }
        blocks[me] = Block {
            first,
            last: block.last,
            succs,
            call: block.call,
            exit: false,
            copy: block.copy,
        };
    }
    Ok(Cfg { blocks })
}

fn placeholder() -> Block {
    Block {
        first: 0,
        last: 0,
        succs: Vec::new(),
        call: None,
        exit: false,
        copy: false,
    }
}

/// What a forward pass knows of one register at a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Held {
    /// No path reaches it (yet).
    Unreached,
    Constant(u32),
    Unknown,
}

impl Held {
    fn meet(self, other: Held) -> Held {
        match (self, other) {
            (Held::Unreached, x) | (x, Held::Unreached) => x,
            (Held::Constant(a), Held::Constant(b)) if a == b => Held::Constant(a),
            _ => Held::Unknown,
        }
    }
}

/// `held` after `run`: the constants [`crate::waits::step_constants`] follows on every path (a
/// conditional write joined with the value before it), `r` seeded with what it held before.
fn through(image: &Image, run: &[Insn], r: u8, held: Held) -> Held {
    let mut known = [None; 16];
    if let Held::Constant(v) = held {
        known[usize::from(r)] = Some(v);
    }
    let mut written = false;
    for insn in run {
        // A register copied (`MOV rD, rM`) holds what its source held.
        let copied = match (insn.inst.opcode, &insn.inst.operands[..2]) {
            (Opcode::MOV, [Operand::Reg(d), Operand::Reg(m)]) if !insn.conditional => {
                Some((d.number(), known[usize::from(m.number())]))
            }
            _ => None,
        };
        crate::waits::step_constants(image, insn, &mut known, Conditional::Joined);
        if let Some((d, v)) = copied {
            known[usize::from(d)] = v;
        }
        written |= insn.writes().contains(r);
    }
    match (written, known[usize::from(r)]) {
        (false, _) => held,
        (true, Some(v)) => Held::Constant(v),
        (true, None) => Held::Unknown,
    }
}

/// The constant register `r` holds before instruction `k` of block `b` on every path from the
/// function's entry (a forward data-flow pass to its fixed point: a value set before a loop and
/// not written in it is still known in it), `None` when it is not one constant.
pub(super) fn value_before(
    image: &Image,
    insns: &[Insn],
    graph: &Cfg,
    b: usize,
    k: usize,
    r: u8,
) -> Option<u32> {
    let n = graph.blocks.len();
    let mut entry = vec![Held::Unreached; n];
    entry[0] = Held::Unknown;
    let mut work: Vec<usize> = vec![0];
    let mut queued = vec![false; n];
    queued[0] = true;
    while let Some(x) = work.pop() {
        queued[x] = false;
        let block = &graph.blocks[x];
        let out = through(image, &insns[block.first..=block.last], r, entry[x]);
        for e in &block.succs {
            let met = entry[e.to].meet(out);
            if met != entry[e.to] {
                entry[e.to] = met;
                if !queued[e.to] {
                    queued[e.to] = true;
                    work.push(e.to);
                }
            }
        }
    }
    match through(image, &insns[graph.blocks[b].first..k], r, entry[b]) {
        Held::Constant(v) => Some(v),
        _ => None,
    }
}
