//! What the machine code fixes of each register's value where a block starts: a forward data-flow
//! analysis over a function's control-flow graph, so that a load or store whose base register was
//! set in another block (a peripheral's address loaded before a loop, a static's address kept in a
//! callee-saved register across calls) is charged the latency of the memory it goes to rather than
//! the worst ([`super::chip::Chip::memory_cycles`]; docs/analysis.md, "The cycle model").
//!
//! Per register the lattice is: a range of values `lo..=hi` (a constant where `lo == hi`), an
//! address in the stack, or unknown. At a merge two ranges join to the smallest range holding both
//! (two addresses of one region stay in it; a RAM address and an APB1 one span both, and the access
//! is charged the worse), anything else to unknown. The analysis runs to its fixed point; a block
//! whose entry keeps changing (a register stepped on every pass of a loop) has each changing register
//! widened to unknown after [`WIDEN_AFTER`] changes, so it ends. What the code writes through memory
//! changes no register the analysis follows (a load's destination is unknown), a call leaves r0-r3,
//! r12 and LR unknown (AAPCS: r4-r11 and SP are the callee's to restore; a machine-outlined helper,
//! which follows no convention, whatever it writes), and a conditional instruction (in an `IT` block)
//! joins its result with the value before it.
use super::cfg::Cfg;
use crate::decode::{Flow, Insn, Opcode, Operand, PC, SP};
use crate::Image;

/// What is known of one register's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Value {
    /// Nothing.
    Unknown,
    /// An address in the stack: SP, or SP moved by an immediate (the stack is in RAM).
    Stack,
    /// One of the values `lo..=hi`.
    Range(u32, u32),
}

/// Every register's [`Value`], r0 to r15.
pub type State = [Value; 16];

/// Changes of a block's entry after which a register that changes again is widened to unknown.
pub const WIDEN_AFTER: u32 = 4;

/// What a call leaves in r0-r12 for its callee ([`context`]).
pub type Context = [Value; 13];

/// A function entered with nothing known of r0-r12.
pub const NO_CONTEXT: Context = [Value::Unknown; 13];

/// Where a function starts: `context` in r0-r12, SP an address in the stack, nothing known of LR.
fn entry_state(context: &Context) -> State {
    let mut state = [Value::Unknown; 16];
    state[..13].copy_from_slice(context);
    state[usize::from(SP)] = Value::Stack;
    state
}

/// The context a call passes its callee, from the registers before it (`state`): r0-r3, the
/// arguments (a callee reads nothing else of its caller's registers but to save and restore them),
/// or, for a machine-outlined helper, which keeps no convention, r0-r12. Each range is widened to
/// the 64 KiB-aligned span that holds it: the callee's analysis then starts from values that hold
/// the caller's (sound), and a callee is worked out once per few contexts rather than once per
/// address a call passes (a static's, a peripheral's: an offset into the object stays in the span's
/// region, as the memory map's regions start at multiples of 64 KiB but APB2's end on the F103,
/// where AHB follows it and costs less).
pub fn context(state: &State, outlined: bool) -> Context {
    let passed = if outlined { 13 } else { 4 };
    std::array::from_fn(|r| {
        if r >= passed {
            return Value::Unknown;
        }
        match state[r] {
            Value::Range(lo, hi) => Value::Range(lo & !0xffff, hi | 0xffff),
            other => other,
        }
    })
}

/// The smallest and largest address of SRAM's region (0x2000_0000..0x4000_0000), which holds the stack.
const RAM_REGION: (u32, u32) = (0x2000_0000, 0x3fff_ffff);

impl Value {
    /// The value `c`.
    pub fn constant(c: u32) -> Value {
        Value::Range(c, c)
    }

    /// The least value that holds both.
    pub fn join(self, other: Value) -> Value {
        match (self, other) {
            (a, b) if a == b => a,
            (Value::Range(a, b), Value::Range(c, d)) => Value::Range(a.min(c), b.max(d)),
            // A stack address is one of SRAM's.
            (Value::Stack, Value::Range(lo, hi)) | (Value::Range(lo, hi), Value::Stack) => {
                Value::Range(lo.min(RAM_REGION.0), hi.max(RAM_REGION.1))
            }
            _ => Value::Unknown,
        }
    }

    /// The value plus `by`: exact for a constant (the core's arithmetic wraps), a range moved where
    /// no value of it wraps (else unknown), a stack address still one.
    pub fn plus(self, by: i64) -> Value {
        match self {
            Value::Range(c, d) if c == d => Value::constant((i64::from(c) + by) as u32),
            Value::Range(lo, hi) => {
                let moved = |v: u32| u32::try_from(i64::from(v) + by).ok();
                match (moved(lo), moved(hi)) {
                    (Some(lo), Some(hi)) => Value::Range(lo, hi),
                    _ => Value::Unknown,
                }
            }
            other => other,
        }
    }
}

/// The join of two states, register by register.
fn join(a: &State, b: &State) -> State {
    std::array::from_fn(|r| a[r].join(b[r]))
}

/// The word-aligned PC an instruction at `addr` reads (`ADR`, a literal load).
fn aligned_pc(addr: u64) -> i64 {
    ((addr + 4) & !3) as i64
}

/// The register `insn` adds to or subtracts an immediate from (`ADD Rd, Rn, #k`, `ADDS Rd, #k`,
/// `SUB`, `ADDW`, `SUBW`), with the signed immediate.
fn immediate_step(insn: &Insn) -> Option<(u8, i64)> {
    let sign = match insn.inst.opcode {
        Opcode::ADD => 1,
        Opcode::SUB => -1,
        _ => return None,
    };
    let ops = &insn.inst.operands;
    match (ops[0], ops[1], ops[2]) {
        (Operand::Reg(_), Operand::Reg(rn), Operand::Imm32(k)) => {
            Some((rn.number(), sign * i64::from(k)))
        }
        (Operand::Reg(rd), Operand::Imm32(k), Operand::Nothing) => {
            Some((rd.number(), sign * i64::from(k)))
        }
        _ => None,
    }
}

/// The value `insn` leaves in its destination `rd`, from what is known before it (`state`); unknown
/// where the analysis does not follow the instruction.
fn result(image: &Image, insn: &Insn, state: &State, rd: u8) -> Value {
    let ops = &insn.inst.operands;
    let regs = insn.registers();
    if regs.first() != Some(&rd) {
        return Value::Unknown;
    }
    let read = |r: u8| match r {
        PC => Value::constant((insn.addr + 4) as u32),
        SP => Value::Stack,
        r => state[usize::from(r)],
    };
    match insn.inst.opcode {
        // A literal: flash does not change while the code runs.
        Opcode::LDR if insn.memory_base() == Some(PC) => insn
            .literal_address()
            .and_then(|at| image.word(at))
            .map_or(Value::Unknown, Value::constant),
        Opcode::ADR => match ops[1] {
            Operand::Imm32(k) => Value::constant((aligned_pc(insn.addr) + i64::from(k)) as u32),
            _ => Value::Unknown,
        },
        Opcode::MOV | Opcode::MVN if regs.len() == 1 && ops[2] == Operand::Nothing => {
            match (insn.inst.opcode, ops[1]) {
                (Opcode::MOV, Operand::Imm32(c)) => Value::constant(c),
                (Opcode::MOV, Operand::Imm12(c)) => Value::constant(u32::from(c)),
                (Opcode::MVN, Operand::Imm32(c)) => Value::constant(!c),
                (Opcode::MVN, Operand::Imm12(c)) => Value::constant(!u32::from(c)),
                _ => Value::Unknown,
            }
        }
        Opcode::MOVT => match (state[usize::from(rd)], insn.immediate()) {
            (Value::Range(low, l2), Some(high)) if low == l2 => {
                Value::constant((low & 0xffff) | (high << 16))
            }
            _ => Value::Unknown,
        },
        // A copy (`MOV Rd, Rm`; `MOVS Rd, Rm` decodes as `LSLS Rd, Rm, #0`).
        Opcode::MOV if regs.len() == 2 && ops[2] == Operand::Nothing => read(regs[1]),
        Opcode::LSL if regs.len() == 2 && matches!(ops[2], Operand::Imm12(0)) => read(regs[1]),
        Opcode::ADD | Opcode::SUB => match immediate_step(insn) {
            Some((PC, k)) => Value::constant((aligned_pc(insn.addr) + k) as u32),
            Some((rn, k)) => read(rn).plus(k),
            None => Value::Unknown,
        },
        _ => Value::Unknown,
    }
}

/// The registers after `insn`, from `state` before it.
pub fn step(image: &Image, insn: &Insn, state: &mut State) {
    let before = *state;
    let mut written = insn.writes();
    // A supervisor call's handler may change the stacked r0-r3 and r12 (none in the shipped images).
    if insn.inst.opcode == Opcode::SVC {
        written.0 |= 0b1_0000_0000_1111;
    }
    let call = matches!(insn.flow(), Flow::Call(_) | Flow::IndirectCall(_));
    for r in 0..16u8 {
        if !written.contains(r) {
            continue;
        }
        let destination = insn.registers().first() == Some(&r);
        let mut value = if call {
            // What an outlined helper's straight-line code leaves (its last write a `MOV #c`).
            insn.outlined
                .as_ref()
                .and_then(|o| o.constants.iter().find(|&&(x, _)| x == r))
                .map_or(Value::Unknown, |&(_, c)| Value::constant(c))
        } else if destination {
            result(image, insn, &before, r)
        } else {
            // A base register written back by a load or store: moved by its immediate.
            written_back(insn, &before, r)
        };
        if insn.conditional {
            value = before[usize::from(r)].join(value);
        }
        state[usize::from(r)] = value;
    }
    state[usize::from(SP)] = Value::Stack;
}

/// The value a load or store writes back to its base `r` (`LDR Rt, [Rn], #k`, `STR Rt, [Rn, #k]!`);
/// unknown for any other write of `r` (a list's base, a loaded register).
fn written_back(insn: &Insn, state: &State, r: u8) -> Value {
    insn.inst
        .operands
        .iter()
        .find_map(|o| match *o {
            Operand::RegDerefPostindexOffset(rn, k, add, _)
            | Operand::RegDerefPreindexOffset(rn, k, add, true)
                if rn.number() == r =>
            {
                let k = i64::from(k);
                Some(state[usize::from(r)].plus(if add { k } else { -k }))
            }
            _ => None,
        })
        .unwrap_or(Value::Unknown)
}

/// The registers at the start of each block of a function's graph, at the analysis' fixed point.
#[derive(Debug, Clone)]
pub struct Values {
    /// Per block: its instructions and its entry state (`None`: not reached from the entry).
    blocks: Vec<(usize, usize, Option<State>)>,
}

impl Values {
    /// The analysis of `graph` (the function's whole graph, entered at block 0 with `context`).
    pub fn of(image: &Image, insns: &[Insn], graph: &Cfg, context: &Context) -> Values {
        let entry = entry_state(context);
        let n = graph.blocks.len();
        let mut entries: Vec<Option<State>> = vec![None; n];
        let mut changes = vec![0u32; n];
        if n == 0 {
            return Values { blocks: Vec::new() };
        }
        entries[0] = Some(entry);
        // Blocks in reverse postorder, each worked when its entry changed.
        let order = graph.reverse_postorder();
        let mut rank = vec![usize::MAX; n];
        for (k, &b) in order.iter().enumerate() {
            rank[b] = k;
        }
        let mut work = std::collections::BTreeSet::from([(rank[0], 0usize)]);
        while let Some((_, b)) = work.pop_first() {
            let Some(mut state) = entries[b] else {
                continue;
            };
            let block = &graph.blocks[b];
            for insn in &insns[block.first..=block.last] {
                step(image, insn, &mut state);
            }
            for e in &block.succs {
                let merged = match &entries[e.to] {
                    None => state,
                    Some(old) => {
                        let mut merged = join(old, &state);
                        if merged == *old {
                            continue;
                        }
                        changes[e.to] += 1;
                        if changes[e.to] > WIDEN_AFTER {
                            for r in 0..16 {
                                if merged[r] != old[r] {
                                    merged[r] = Value::Unknown;
                                }
                            }
                        }
                        merged
                    }
                };
                entries[e.to] = Some(merged);
                work.insert((rank[e.to], e.to));
            }
        }
        Values {
            blocks: graph
                .blocks
                .iter()
                .zip(entries)
                .map(|(b, s)| (b.first, b.last, s))
                .collect(),
        }
    }

    /// The registers before instruction `k`: from the entry of the block that holds it, through the
    /// instructions before it in that block; all unknown but SP where no block reached from the entry
    /// holds it.
    pub fn before(&self, image: &Image, insns: &[Insn], k: usize) -> State {
        let found = self
            .blocks
            .iter()
            .find(|&&(first, last, _)| first <= k && k <= last);
        match found {
            Some(&(first, _, Some(mut state))) => {
                for insn in &insns[first..k] {
                    step(image, insn, &mut state);
                }
                state
            }
            _ => entry_state(&NO_CONTEXT),
        }
    }
}
