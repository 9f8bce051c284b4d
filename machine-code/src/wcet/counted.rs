//! Counted loops: a register set to a constant before the loop, stepped by a constant once per
//! iteration on the way back, and compared with a constant (or stepped with flags) to decide the
//! branch back. The bound is found by running that register's values through the branch's
//! condition, exactly as the core evaluates it.
use crate::decode::{Flow, Insn, Opcode, Operand};
use crate::wcet::cfg::{Cfg, Loop};

/// The most iterations the count is run for: a loop counted higher than this is not taken as
/// counted (a stated bound is needed).
const MAX_COUNT: u64 = 1 << 20;

/// The flags `a - b` sets (`CMP`, `SUBS`): N, Z, C, V.
fn sub_flags(a: u32, b: u32) -> [bool; 4] {
    let r = a.wrapping_sub(b);
    [r >> 31 == 1, r == 0, a >= b, ((a ^ b) & (a ^ r)) >> 31 == 1]
}

/// The flags `a + b` sets (`ADDS`, `CMN`).
fn add_flags(a: u32, b: u32) -> [bool; 4] {
    let (r, carry) = a.overflowing_add(b);
    [r >> 31 == 1, r == 0, carry, (!(a ^ b) & (a ^ r)) >> 31 == 1]
}

/// Whether condition `code` (the ARM encoding, 0 = EQ … 13 = LE) holds under `flags`.
fn holds(code: u8, [n, z, c, v]: [bool; 4]) -> bool {
    match code {
        0 => z,
        1 => !z,
        2 => c,
        3 => !c,
        4 => n,
        5 => !n,
        6 => v,
        7 => !v,
        8 => c && !z,
        9 => !c || z,
        10 => n == v,
        11 => n != v,
        12 => !z && n == v,
        13 => z || n != v,
        _ => true,
    }
}

/// The condition code of a conditional branch (`B<c>`; for `CBZ`/`CBNZ` none: not counted here).
fn branch_condition(insn: &Insn) -> Option<u8> {
    if insn.inst.opcode != Opcode::B || !insn.conditional {
        return None;
    }
    // B<c> T1: 1101 cond imm8; B<c>.W T3: 11110 S cond imm6 | 10 J1 0 J2 imm11.
    if insn.len == 2 {
        Some(((insn.raw[0] >> 8) & 0xf) as u8)
    } else {
        Some(((insn.raw[0] >> 6) & 0xf) as u8)
    }
}

/// How the counter steps: by `+k` or `-k`, and whether the step sets the flags the branch reads.
struct Step {
    add: bool,
    k: u32,
    flags: bool,
}

fn as_step(insn: &Insn, r: u8) -> Option<Step> {
    let add = match insn.inst.opcode {
        Opcode::ADD => true,
        Opcode::SUB => false,
        _ => return None,
    };
    let regs = insn.registers();
    // `adds rX, #k` or `adds rX, rX, #k`.
    if regs.first() != Some(&r) || regs.iter().any(|&x| x != r) {
        return None;
    }
    let k = insn.immediate().filter(|&k| k > 0)?;
    Some(Step {
        add,
        k,
        flags: insn.inst.s,
    })
}

/// Whether an instruction sets the condition flags.
fn sets_flags(insn: &Insn) -> bool {
    matches!(
        insn.inst.opcode,
        Opcode::CMP | Opcode::CMN | Opcode::TST | Opcode::TEQ | Opcode::MSR
    ) || insn.inst.s
}

/// A counted loop's bound.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Counted {
    /// The most times its header runs per entry.
    pub header: u64,
    /// The most passes per entry that go on past the header, where the count says (tested at the
    /// top: the header's test ends the loop on its last run, so at most `header` − 1).
    pub body: Option<u64>,
    /// How it was found.
    pub how: String,
}

/// The bound of a counted loop: tested at the bottom (the branch back decides) or at the top (the
/// header's branch out decides, as `for i in 0..n` compiles).
pub fn counted(insns: &[Insn], cfg: &Cfg, l: &Loop) -> Option<Counted> {
    if let Some((header, how)) = counted_at_bottom(insns, cfg, l) {
        return Some(Counted {
            header,
            body: None,
            how,
        });
    }
    // The header's one way into the body is its test's, which leaves on the run the count gives:
    // every run before it goes on, that one does not.
    counted_at_top(insns, cfg, l, None).map(|(header, how)| Counted {
        header,
        body: Some(header.saturating_sub(1)),
        how,
    })
}

/// The most entry values of an argument's counter that are run through the header's test (one run
/// per value the argument may hold): above it, the loop is left to its per-call count.
const MAX_ARGUMENT: u32 = 1 << 12;

/// A loop of a function called with its argument registers bounded by `args` (a `per_element` or
/// memory function's length, fixed at the call), tested at its top as [`counted`]'s are, whose
/// counter comes on every way in from an argument register not written since the function's entry
/// (directly or through register moves) or from a constant: its header runs at most the most any
/// entry value from 0 to the argument's bound gives, and as with [`counted`]'s loops tested at the
/// top, at most one pass fewer go on past it.
pub fn counted_from_arguments(
    insns: &[Insn],
    cfg: &Cfg,
    l: &Loop,
    args: &super::length::Args,
) -> Option<Counted> {
    counted_at_top(insns, cfg, l, Some(args)).map(|(header, how)| Counted {
        header,
        body: Some(header.saturating_sub(1)),
        how,
    })
}

/// A loop whose header ends in a conditional branch out of the loop on a `CMP rX, #c`, with rX stepped
/// by a constant exactly once on every way around (in one block every way back passes) and set to a
/// constant on every way in. Other exits only end it sooner.
fn counted_at_top(
    insns: &[Insn],
    cfg: &Cfg,
    l: &Loop,
    args: Option<&super::length::Args>,
) -> Option<(u64, String)> {
    let header = &cfg.blocks[l.header];
    let branch = &insns[header.last];
    // One edge out of the loop, one in: whether taking the branch leaves.
    let [a, b] = header.succs[..] else {
        return None;
    };
    let taken_leaves = match (l.body.contains(&a.to), l.body.contains(&b.to)) {
        (true, false) => b.taken,
        (false, true) => a.taken,
        _ => return None,
    };
    // The counter, the constant it is compared with, the condition (EQ/NE for `CBZ`/`CBNZ`, whose
    // test is a compare with 0), and where in the header the compare is.
    let (counter, limit, code, at) = match branch.inst.opcode {
        Opcode::CBZ | Opcode::CBNZ
            if !insns[header.first..header.last]
                .iter()
                .any(|i| i.conditional) =>
        {
            let Operand::Reg(r) = branch.inst.operands[0] else {
                return None;
            };
            let code = if branch.inst.opcode == Opcode::CBZ {
                0
            } else {
                1
            };
            (r.number(), 0, code, header.last - header.first)
        }
        _ => {
            let code = branch_condition(branch)?;
            let head = &insns[header.first..header.last];
            let (at, setter) = head.iter().enumerate().rev().find(|(_, i)| sets_flags(i))?;
            if setter.inst.opcode != Opcode::CMP
                || setter.conditional
                || setter.registers().len() != 1
            {
                return None;
            }
            let Operand::Reg(r) = setter.inst.operands[0] else {
                return None;
            };
            (r.number(), setter.immediate()?, code, at)
        }
    };
    // Exactly one write of the counter in the loop: the step.
    let (step_block, step_at) = only_write(insns, cfg, l, counter)?;
    if insns[step_at].conditional {
        return None;
    }
    let step = as_step(&insns[step_at], counter)?;
    // Before the compare in the header: each pass compares the stepped value.
    let stepped_first = step_block == l.header && step_at < header.first + at;
    // Elsewhere, every way from the header back to it passes the step's block.
    if step_block != l.header && reaches_latch_avoiding(cfg, l, step_block) {
        return None;
    }
    let mut most = 0;
    let mut found_entry = false;
    for (blk, block) in cfg.blocks.iter().enumerate() {
        if l.body.contains(&blk) || !block.succs.iter().any(|e| e.to == l.header) {
            continue;
        }
        let (low, high) = match args {
            None => {
                let start = initial(insns, cfg, blk, counter, &mut Vec::new())?;
                (start, start)
            }
            Some(args) => {
                let end = cfg.blocks[blk].last + 1;
                entry_range(insns, cfg, blk, end, counter, args, &mut Vec::new())?
            }
        };
        if high - low >= MAX_ARGUMENT {
            return None;
        }
        for start in low..=high {
            most = most.max(run_top(
                start,
                &step,
                limit,
                code,
                taken_leaves,
                stepped_first,
            )?);
        }
        found_entry = true;
    }
    if !found_entry {
        return None;
    }
    Some((
        most,
        format!(
            "counted: r{counter} from its entry value{} by {}{}, compared with #{limit} at the loop's top",
            if args.is_some() {
                " (an argument's bound at the call, or a constant)"
            } else {
                ""
            },
            if step.add { '+' } else { '-' },
            step.k
        ),
    ))
}

/// The loop's one write of register `r` (its block and index), if it has exactly one.
fn only_write(insns: &[Insn], cfg: &Cfg, l: &Loop, r: u8) -> Option<(usize, usize)> {
    let mut writes = l.body.iter().flat_map(|&b| {
        let block = &cfg.blocks[b];
        (block.first..=block.last)
            .filter(move |&at| insns[at].writes().contains(r))
            .map(move |at| (b, at))
    });
    let first = writes.next()?;
    writes.next().is_none().then_some(first)
}

/// Whether a block with an edge back to the header is reached from the header without `avoid`.
fn reaches_latch_avoiding(cfg: &Cfg, l: &Loop, avoid: usize) -> bool {
    let mut seen = std::collections::BTreeSet::new();
    let mut stack = vec![l.header];
    while let Some(b) = stack.pop() {
        if b == avoid || !seen.insert(b) {
            continue;
        }
        for e in &cfg.blocks[b].succs {
            if e.to == l.header {
                return true;
            }
            if l.body.contains(&e.to) {
                stack.push(e.to);
            }
        }
    }
    false
}

/// The header's executions of a loop tested at its top: each pass compares the counter (stepped
/// first when `stepped_first`) and leaves when the branch says so.
fn run_top(
    start: u32,
    step: &Step,
    limit: u32,
    code: u8,
    taken_leaves: bool,
    stepped_first: bool,
) -> Option<u64> {
    let next = |v: u32| {
        if step.add {
            v.wrapping_add(step.k)
        } else {
            v.wrapping_sub(step.k)
        }
    };
    let mut v = start;
    for n in 1..=MAX_COUNT {
        if stepped_first {
            v = next(v);
        }
        if holds(code, sub_flags(v, limit)) == taken_leaves {
            return Some(n);
        }
        if !stepped_first {
            v = next(v);
        }
    }
    None
}

/// A loop tested at its bottom: the latch's conditional branch back on the counter.
fn counted_at_bottom(insns: &[Insn], cfg: &Cfg, l: &Loop) -> Option<(u64, String)> {
    let [latch] = l.latches[..] else { return None };
    let block = &cfg.blocks[latch];
    let branch = &insns[block.last];
    let Flow::Branch(_) = branch.flow() else {
        return None;
    };
    // The branch back is the taken edge to the header.
    if !block.succs.iter().any(|e| e.to == l.header && e.taken) {
        return None;
    }
    let code = branch_condition(branch)?;
    // The last instruction before the branch that sets the flags.
    let latch_insns = &insns[block.first..block.last];
    let (at, setter) = latch_insns
        .iter()
        .enumerate()
        .rev()
        .find(|(_, i)| sets_flags(i))?;
    let (counter, compare) = match setter.inst.opcode {
        Opcode::CMP => {
            let Operand::Reg(r) = setter.inst.operands[0] else {
                return None;
            };
            if setter.registers().len() != 1 {
                return None;
            }
            (r.number(), Some(setter.immediate()?))
        }
        Opcode::ADD | Opcode::SUB => (*setter.registers().first()?, None),
        _ => return None,
    };
    // Exactly one write of the counter in the whole loop: the step, in the latch before the flags
    // are set (or the flag-setting step itself).
    let (step_block, step_at) = only_write(insns, cfg, l, counter)?;
    if step_block != latch || step_at > block.first + at {
        return None;
    }
    // An `IT` block's step or compare may not run: not a count.
    if insns[step_at].conditional || setter.conditional {
        return None;
    }
    let step = as_step(&insns[step_at], counter)?;
    if compare.is_none() && !(step.flags && step_at == block.first + at) {
        return None;
    }
    // The counter's value on entry, from every predecessor of the header outside the loop.
    let mut most = 0;
    let mut found_entry = false;
    for (b, blk) in cfg.blocks.iter().enumerate() {
        if l.body.contains(&b) || !blk.succs.iter().any(|e| e.to == l.header) {
            continue;
        }
        let start = initial(insns, cfg, b, counter, &mut Vec::new())?;
        most = most.max(run(start, &step, compare, code)?);
        found_entry = true;
    }
    if !found_entry {
        return None;
    }
    let how = match compare {
        Some(limit) => format!(
            "counted: r{counter} from its entry value by {}{} to the compare with #{limit}",
            if step.add { '+' } else { '-' },
            step.k
        ),
        None => format!(
            "counted: r{counter} from its entry value by {}{} until the flags end it",
            if step.add { '+' } else { '-' },
            step.k
        ),
    };
    Some((most, how))
}

/// Whether the loop is an exclusive-access retry: it holds one `STREX` (any width) and an `LDREX`,
/// and its one branch back is taken only when that `STREX` failed (`CBNZ` on its status register,
/// or `CMP` of it with 0 and `BNE`). On a single Cortex-M3/M4 (no global monitor on the STM32) a
/// `STREX` fails only when the local monitor was cleared since the `LDREX`, which exception entry
/// and return do: each retry needs a preemption inside the sequence.
///
/// The machine outliner may move parts of the sequence into helpers (`OUTLINED_FUNCTION_*`:
/// `LDREXB; CMP; BX LR`, `STREXB; CMP; BX LR`): `leaf` gives the body of a called function that is
/// straight-line code ending in `BX LR` (without it), and such a call is read as its body, so the
/// `STREX`, its status and the flags the branch back tests may be in one.
pub fn exclusive_retry(
    insns: &[Insn],
    cfg: &Cfg,
    l: &Loop,
    leaf: &dyn Fn(u64) -> Option<Vec<Insn>>,
) -> bool {
    let [latch] = l.latches[..] else { return false };
    // A block's instructions with every call of a leaf helper replaced by the helper's body.
    let expanded = |b: usize| -> Vec<Insn> {
        let mut out = Vec::new();
        for i in &insns[cfg.blocks[b].first..=cfg.blocks[b].last] {
            match i.flow() {
                Flow::Call(target) => match leaf(target) {
                    Some(body) => out.extend(body),
                    None => out.push(i.clone()),
                },
                _ => out.push(i.clone()),
            }
        }
        out
    };
    let all: Vec<Insn> = l.body.iter().flat_map(|&b| expanded(b)).collect();
    let is_strex = |i: &Insn| {
        matches!(
            i.inst.opcode,
            Opcode::STREX | Opcode::STREXB | Opcode::STREXH | Opcode::STREXD
        )
    };
    let is_ldrex = |i: &Insn| {
        matches!(
            i.inst.opcode,
            Opcode::LDREX | Opcode::LDREXB | Opcode::LDREXH | Opcode::LDREXD
        )
    };
    let stores: Vec<&Insn> = all.iter().filter(|i| is_strex(i)).collect();
    let [strex] = stores[..] else { return false };
    if !all.iter().any(is_ldrex) {
        return false;
    }
    let Some(Operand::Reg(status)) = strex.inst.operands.first() else {
        return false;
    };
    let status = status.number();
    let block = &cfg.blocks[latch];
    if !block.succs.iter().any(|e| e.to == l.header && e.taken) {
        return false;
    }
    // The latch block, preceded by the blocks that only fall into it from a call (a call ends a
    // block): the straight run of code that ends in the branch back.
    let mut run = vec![latch];
    loop {
        let first = run[0];
        let into: Vec<usize> = l
            .body
            .iter()
            .copied()
            .filter(|&b| cfg.blocks[b].succs.iter().any(|e| e.to == first))
            .collect();
        let [before] = into[..] else { break };
        let blk = &cfg.blocks[before];
        if first == l.header || blk.call.is_none() || blk.succs.len() != 1 || run.contains(&before)
        {
            break;
        }
        run.insert(0, before);
    }
    let latch_insns: Vec<Insn> = run.iter().flat_map(|&b| expanded(b)).collect();
    let Some((branch, before)) = latch_insns.split_last() else {
        return false;
    };
    // The STREX is in that run (or a helper it calls), and its status does not change between it
    // and the branch.
    let Some(strex_at) = before.iter().position(|i| i.addr == strex.addr) else {
        return false;
    };
    let after = &before[strex_at + 1..];
    if after.iter().any(|i| i.writes().contains(status)) {
        return false;
    }
    match branch.inst.opcode {
        Opcode::CBNZ => matches!(branch.inst.operands[0], Operand::Reg(r) if r.number() == status),
        Opcode::B => {
            let Some(1) = branch_condition(branch) else {
                return false;
            };
            after
                .iter()
                .rev()
                .find(|i| sets_flags(i))
                .is_some_and(|cmp| {
                    cmp.inst.opcode == Opcode::CMP
                        && cmp.registers() == [status]
                        && cmp.immediate() == Some(0)
                })
        }
        _ => false,
    }
}

/// The counter's constant value at the end of block `b`: its last write there must be `MOV rX, #c`;
/// a block that does not write it has the value every way into it has (the same on all, and never
/// through a cycle).
fn initial(insns: &[Insn], cfg: &Cfg, b: usize, r: u8, on_the_way: &mut Vec<usize>) -> Option<u32> {
    let block = &insns[cfg.blocks[b].first..=cfg.blocks[b].last];
    if let Some(last) = block.iter().rev().find(|i| i.writes().contains(r)) {
        // A call of an outlined helper that sets it (the machine outliner moved the `MOV` there).
        if let Some(outlined) = &last.outlined {
            return outlined
                .constants
                .iter()
                .find(|&&(x, _)| x == r)
                .map(|&(_, c)| c)
                .filter(|_| !last.conditional);
        }
        let regs = last.registers();
        return (last.inst.opcode == Opcode::MOV && regs == [r] && !last.conditional)
            .then(|| last.immediate())
            .flatten();
    }
    if b == 0 || on_the_way.contains(&b) {
        return None;
    }
    on_the_way.push(b);
    let mut value = None;
    for (p, pred) in cfg.blocks.iter().enumerate() {
        if pred.succs.iter().any(|e| e.to == b) {
            let v = initial(insns, cfg, p, r, on_the_way)?;
            if value.is_some_and(|known| known != v) {
                return None;
            }
            value = Some(v);
        }
    }
    on_the_way.pop();
    value
}

/// The values register `r` may hold before instruction `end` of block `b` (an index into `insns`),
/// as a range: a constant `MOV` gives one value; a register `MOV` the values of its source before
/// it; no write back to the function's entry the argument's bound in `args` (from 0). `None` where
/// any way in writes it otherwise, or an argument is not bounded.
fn entry_range(
    insns: &[Insn],
    cfg: &Cfg,
    b: usize,
    end: usize,
    r: u8,
    args: &super::length::Args,
    on_the_way: &mut Vec<(usize, u8)>,
) -> Option<(u32, u32)> {
    let first = cfg.blocks[b].first;
    if let Some(at) = (first..end)
        .rev()
        .find(|&at| insns[at].writes().contains(r))
    {
        let last = &insns[at];
        if last.conditional || last.inst.opcode != Opcode::MOV || last.outlined.is_some() {
            return None;
        }
        if let Some(c) = last.immediate() {
            return (last.registers() == [r]).then_some((c, c));
        }
        // `mov r, rX`: rX's values before it.
        let (Operand::Reg(to), Operand::Reg(from)) = (last.inst.operands[0], last.inst.operands[1])
        else {
            return None;
        };
        if to.number() != r || !matches!(last.inst.operands[2], Operand::Nothing) {
            return None;
        }
        return entry_range(insns, cfg, b, at, from.number(), args, on_the_way);
    }
    if b == 0 {
        // The entry's arguments, where nothing branches back to the entry.
        let entered_again = cfg.blocks.iter().any(|p| p.succs.iter().any(|e| e.to == 0));
        return (!entered_again)
            .then(|| args.get(usize::from(r)).copied().flatten())
            .flatten()
            .map(|n| (0, n));
    }
    if on_the_way.contains(&(b, r)) {
        return None;
    }
    on_the_way.push((b, r));
    let mut range: Option<(u32, u32)> = None;
    for (p, pred) in cfg.blocks.iter().enumerate() {
        if pred.succs.iter().any(|e| e.to == b) {
            let (low, high) =
                entry_range(insns, cfg, p, cfg.blocks[p].last + 1, r, args, on_the_way)?;
            range = Some(range.map_or((low, high), |(l, h)| (l.min(low), h.max(high))));
        }
    }
    on_the_way.pop();
    range
}

/// The header's executions: each pass steps the counter and branches back while the condition
/// holds.
fn run(start: u32, step: &Step, compare: Option<u32>, code: u8) -> Option<u64> {
    let mut v = start;
    for n in 1..=MAX_COUNT {
        let before = v;
        v = if step.add {
            v.wrapping_add(step.k)
        } else {
            v.wrapping_sub(step.k)
        };
        let flags = match compare {
            Some(limit) => sub_flags(v, limit),
            None if step.add => add_flags(before, step.k),
            None => sub_flags(before, step.k),
        };
        if !holds(code, flags) {
            return Some(n);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions_as_the_core_evaluates_them() {
        let step_up = Step {
            add: true,
            k: 1,
            flags: false,
        };
        // for i in 0..8: cmp r, #8; bne → 8 passes.
        assert_eq!(run(0, &step_up, Some(8), 1), Some(8));
        // cmp r, #8; blo: 8 passes; bls: the pass that reaches 8 branches back too, 9.
        assert_eq!(run(0, &step_up, Some(8), 3), Some(8));
        assert_eq!(run(0, &step_up, Some(8), 9), Some(9));
        // Down from 5 by subs #1, bne: 5 passes.
        let step_down = Step {
            add: false,
            k: 1,
            flags: true,
        };
        assert_eq!(run(5, &step_down, None, 1), Some(5));
        // Tested at the top: `for i in 0..3` as `cmp r, #3; beq out` … `adds r, #1; b top`: three
        // passes and the one that leaves, 4; from -1 stepped after `cmp r, #2; beq out`: 4.
        assert_eq!(run_top(0, &step_up, 3, 0, true, false), Some(4));
        assert_eq!(run_top(u32::MAX, &step_up, 2, 0, true, false), Some(4));
        // By 8 to 24 (`bit::rqcp(i)` shifts): 4 passes; `cmp r, #24; bne body` (the fall-through
        // leaves): the same.
        let by_eight = Step {
            add: true,
            k: 8,
            flags: false,
        };
        assert_eq!(run_top(0, &by_eight, 24, 0, true, false), Some(4));
        assert_eq!(run_top(0, &by_eight, 24, 1, false, false), Some(4));
        // A step that misses the limit with bne never ends within the count.
        let by_three = Step {
            add: true,
            k: 3,
            flags: false,
        };
        assert_eq!(run(0, &by_three, Some(8), 1), None);
    }
}
