//! Loops that run once per byte of a length argument: the memory functions of `compiler-builtins`
//! (`memcpy`, `memset`, `__aeabi_memclr8`, …) and core's `ptr::swap_nonoverlapping_bytes`. Such a loop has no bound of its own; a call of one
//! with a length the machine code fixes (a constant, or the smaller of a value and a constant) bounds
//! each of its loops by that length: every pass moves or compares at least one byte, so a loop of a
//! call with at most `n` bytes passes its header at most `n + 1` times. The bound is worked out per
//! call: the callee is bounded again with the lengths its caller passes ([`Args`]), and a call whose
//! length the machine code does not fix declines with [`LENGTH_UNKNOWN`] in its reason.
use crate::decode::{Insn, Opcode, Operand};
use crate::wcet::cfg::Cfg;

/// Upper bounds of the argument registers r0–r3 at a call (unsigned), where the machine code fixes them.
pub type Args = [Option<u32>; 4];

/// No argument known.
pub const NO_ARGS: Args = [None; 4];

/// In a declined reason: a memory function's loop whose length the call does not fix (a caller may).
pub const LENGTH_UNKNOWN: &str = "runs once per byte of a length the call does not fix";

/// The register that holds the length of a memory function of `compiler-builtins` (by its name as the
/// analysis names functions), if `name` is one.
pub fn length_register(name: &str) -> Option<u8> {
    let name = name
        .strip_prefix("compiler_builtins::mem::")
        .unwrap_or(name);
    match name {
        // (dest, src, n), (dest, c, n), (a, b, n)
        "memcpy" | "memmove" | "memset" | "memcmp" | "bcmp" | "__aeabi_memcpy"
        | "__aeabi_memcpy4" | "__aeabi_memcpy8" | "__aeabi_memmove" | "__aeabi_memmove4"
        | "__aeabi_memmove8" => Some(2),
        // core's byte-wise swap (x, y, bytes), behind `slice::swap` of types without a word layout.
        "core::ptr::swap_nonoverlapping_bytes" => Some(2),
        // (dest, n, c), (dest, n)
        "__aeabi_memset" | "__aeabi_memset4" | "__aeabi_memset8" | "__aeabi_memclr"
        | "__aeabi_memclr4" | "__aeabi_memclr8" => Some(1),
        _ => None,
    }
}

/// What a memory function's loops move, to count their passes by: the bytes it stores or loads
/// through a register other than `SP` (its buffers), or plain passes (one element each).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Moved {
    Stores,
    Loads,
    Passes,
}

/// What the loops of function `name` move, and how many units all of them together move at most
/// per byte of its length argument: `memcpy`, `memmove` and `memset` store each byte of the
/// destination once, the byte-wise swap each byte of both buffers, `memcmp` and `bcmp` load each
/// byte of both; any other function (a `per_element` one) counts passes, one per element.
pub fn moved_by(name: &str) -> (Moved, u64) {
    let name = name
        .strip_prefix("compiler_builtins::mem::")
        .unwrap_or(name);
    match name {
        "memcmp" | "bcmp" => (Moved::Loads, 2),
        "core::ptr::swap_nonoverlapping_bytes" => (Moved::Stores, 2),
        _ if length_register(name).is_some() => (Moved::Stores, 1),
        _ => (Moved::Passes, 1),
    }
}

/// The fewest units `moved` any pass of loop `l` moves: the least, over the ways from its header back
/// to it, of the bytes its unconditional loads or stores (as `moved` says) move through a base other
/// than `SP`; at least 1 (each pass moves at least one byte, or is one element).
pub fn per_pass(insns: &[Insn], graph: &Cfg, l: &crate::wcet::cfg::Loop, moved: Moved) -> u64 {
    let weight = |b: usize| -> u64 {
        let blk = &graph.blocks[b];
        insns[blk.first..=blk.last]
            .iter()
            .filter(|i| !i.conditional)
            .filter(|i| match moved {
                Moved::Stores => i.is_store(),
                Moved::Loads => i.is_load(),
                Moved::Passes => false,
            })
            .filter(|i| {
                !matches!(i.inst.opcode, Opcode::PUSH | Opcode::POP)
                    && i.memory_base().or_else(|| i.memory_base_wback()) != Some(crate::decode::SP)
            })
            .map(|i| i.bytes_moved())
            .sum()
    };
    // Least bytes from the header to each block of the body (Dijkstra: the weights are not negative).
    let mut best: std::collections::BTreeMap<usize, u64> = std::collections::BTreeMap::new();
    let mut open = std::collections::BTreeSet::from([(weight(l.header), l.header)]);
    let mut fewest: Option<u64> = None;
    while let Some((d, b)) = open.pop_first() {
        if best.contains_key(&b) {
            continue;
        }
        best.insert(b, d);
        for e in &graph.blocks[b].succs {
            if e.to == l.header {
                fewest = Some(fewest.map_or(d, |f| f.min(d)));
            } else if l.body.contains(&e.to) && !best.contains_key(&e.to) {
                open.insert((d + weight(e.to), e.to));
            }
        }
    }
    fewest.unwrap_or(1).max(1)
}

/// The argument registers' bounds at the call that ends block `block` of `graph`: from the last write of
/// each on every way into the call (the function's `entry` arguments where a way starts at its entry
/// without one).
pub fn call_args(insns: &[Insn], graph: &Cfg, block: usize, entry: &Args) -> Args {
    let b = &graph.blocks[block];
    let run = &insns[b.first..b.last];
    // A call made under an `IT` block whose every instruction has the same condition: the
    // conditional moves of that block ran whenever the call is made.
    let call = &insns[b.last];
    let call_it = if call.conditional {
        run.iter()
            .rposition(|i| i.inst.opcode == Opcode::IT)
            .filter(|&it| all_then(&run[it]) && it_slots(&run[it]) >= run.len() - it)
            .map(|it| b.first + it)
    } else {
        None
    };
    let ways = Ways {
        insns,
        graph,
        entry,
        call_block: block,
        call_it,
    };
    let mut args = NO_ARGS;
    for (r, arg) in args.iter_mut().enumerate() {
        *arg = ways.bound(
            block,
            b.last,
            r as u8,
            &mut std::collections::BTreeSet::new(),
        );
    }
    args
}

/// The ways into a call, for [`call_args`].
struct Ways<'a> {
    insns: &'a [Insn],
    graph: &'a Cfg,
    entry: &'a Args,
    call_block: usize,
    /// The `IT` (its index in `insns`) the call is in, when its conditional moves ran with it.
    call_it: Option<usize>,
}

impl Ways<'_> {
    /// The bound of register `r` before `insns[upto]` in block `block`: its last write there, else the
    /// largest at the end of every predecessor (`None` through a loop, or from an unknown entry).
    fn bound(
        &self,
        block: usize,
        upto: usize,
        r: u8,
        visiting: &mut std::collections::BTreeSet<usize>,
    ) -> Option<u32> {
        let first = self.graph.blocks[block].first;
        let run = &self.insns[first..upto];
        let Some(at) = run.iter().rposition(|i| i.writes().contains(r)) else {
            if block == 0 {
                return self.entry.get(usize::from(r)).copied().flatten();
            }
            let preds: Vec<usize> = self
                .graph
                .blocks
                .iter()
                .enumerate()
                .filter(|(_, blk)| blk.succs.iter().any(|e| e.to == block))
                .map(|(p, _)| p)
                .collect();
            if preds.is_empty() {
                return None;
            }
            let mut most = 0;
            for p in preds {
                if !visiting.insert(p) {
                    return None;
                }
                let end = self.graph.blocks[p].last + 1;
                let v = self.bound(p, end, r, visiting);
                visiting.remove(&p);
                most = most.max(v?);
            }
            return Some(most);
        };
        let insn = &run[at];
        if insn.inst.opcode != Opcode::MOV {
            return None;
        }
        let regs = insn.registers();
        let ran = !insn.conditional
            || (block == self.call_block
                && self.call_it.is_some_and(|it| {
                    run[..at].iter().rposition(|i| i.inst.opcode == Opcode::IT) == Some(it - first)
                }));
        match (ran, &regs[..]) {
            // mov rN, #c
            (true, [d]) if *d == r => insn.immediate(),
            // mov rN, rM
            (true, [d, m]) if *d == r => self.bound(block, first + at, *m, visiting),
            // cmp rM, #c; mov rN, rM; it cs|hi; movcs|movhi rN, #c: the smaller of rM and c.
            (false, [d]) if *d == r && insn.immediate() != Some(0) => smaller_of(run, at, r),
            // subs rN, rA, X; it cc; movcc rN, #0: `rA.saturating_sub(X)`, at most rA.
            (false, [d]) if *d == r => {
                let a = saturated_from(run, at, r)?;
                self.bound(block, first + at - 2, a, visiting)
            }
            _ => None,
        }
    }
}

/// `cmp rM, #c; mov rN, rM; it cs|hi; movcs|movhi rN, #c` ending at `run[at]`: rN is at most c.
fn smaller_of(run: &[Insn], at: usize, r: u8) -> Option<u32> {
    let c = run[at].immediate()?;
    let it = run[..at]
        .iter()
        .rposition(|i| i.inst.opcode == Opcode::IT)?;
    let first_condition = (run[it].raw[0] >> 4) & 0xF;
    // The move runs under the `IT`'s own condition (no else slot) and the flags the compare set.
    let in_block = at - it <= it_slots(&run[it]) && all_then(&run[it]);
    if !matches!(first_condition, 2 | 8) || !in_block || run[it + 1..at].iter().any(|i| i.inst.s) {
        return None;
    }
    let cmp = run[..it].iter().rposition(|i| {
        matches!(i.inst.opcode, Opcode::CMP | Opcode::CMN | Opcode::TST) || i.inst.s
    })?;
    // cmp rN, #c; it cs|hi; movcs|movhi rN, #c: rN itself made the smaller of it and c.
    if run[cmp].inst.opcode == Opcode::CMP
        && matches!(run[cmp].inst.operands[0], Operand::Reg(x) if x.number() == r)
        && run[cmp].immediate() == Some(c)
        && run[cmp + 1..at].iter().all(|i| !i.writes().contains(r))
    {
        return Some(c);
    }
    let before = run[..it].iter().rposition(|i| i.writes().contains(r))?;
    let [d2, m] = run[before].registers()[..] else {
        return None;
    };
    if run[before].inst.opcode != Opcode::MOV || run[before].conditional || d2 != r {
        return None;
    }
    let compared = &run[cmp];
    let same = compared.inst.opcode == Opcode::CMP
        && matches!(compared.inst.operands[0], Operand::Reg(x) if x.number() == m)
        && compared.immediate() == Some(c);
    // Nothing between the compare and the conditional move writes rM.
    let untouched = run[cmp + 1..at].iter().all(|i| !i.writes().contains(m));
    (same && untouched).then_some(c)
}

/// `subs rN, rA, X; it cc; movcc rN, #0` ending at `run[at]` (`rA.saturating_sub(X)`): `rA`, whose bound
/// is rN's (the subtraction without a borrow is at most rA, with one the result is 0).
fn saturated_from(run: &[Insn], at: usize, r: u8) -> Option<u8> {
    if at < 2 || run[at].immediate() != Some(0) {
        return None;
    }
    let (it, sub) = (&run[at - 1], &run[at - 2]);
    // `IT CC` (condition 3) covering the move alone.
    if it.inst.opcode != Opcode::IT || (it.raw[0] >> 4) & 0xF != 3 || it_slots(it) != 1 {
        return None;
    }
    if sub.inst.opcode != Opcode::SUB || !sub.inst.s || sub.conditional {
        return None;
    }
    match sub.registers()[..] {
        [d, a, ..] if d == r => Some(a),
        _ => None,
    }
}

/// How many instructions an `IT` instruction covers (1–4), from its mask.
fn it_slots(it: &Insn) -> usize {
    let mask = it.raw[0] & 0xF;
    4 - mask.trailing_zeros().min(3) as usize
}

/// Whether every instruction an `IT` covers runs under its first condition (`IT`, `ITT`, `ITTT`, `ITTTT`).
fn all_then(it: &Insn) -> bool {
    let (first, mask) = ((it.raw[0] >> 4) & 1, it.raw[0] & 0xF);
    let slots = it_slots(it);
    (1..slots).all(|k| (mask >> (4 - k)) & 1 == first)
}

/// The function a call through a register at the end of block `block` reaches when the register holds a
/// constant address: its last write on every way into the call is a literal load (`LDR rX, [PC, #k]`)
/// or a `MOVW`/`MOVT` pair of the same address, or a plain copy (`MOV rX, rY`) of a register that
/// holds it so (the compiler keeps a function's address in one register for several calls and may
/// move it to another between them). The address with its Thumb bit cleared.
pub fn constant_target(
    image: &crate::Image,
    insns: &[Insn],
    graph: &Cfg,
    block: usize,
) -> Option<u64> {
    let b = &graph.blocks[block];
    let call = &insns[b.last];
    let [r] = call.registers()[..] else {
        return None;
    };
    // The last write of the register on every way into the call: each must load the same address.
    let preds = |x: usize| {
        graph
            .blocks
            .iter()
            .enumerate()
            .filter(move |(_, blk)| blk.succs.iter().any(|e| e.to == x))
            .map(|(p, _)| p)
    };
    let mut value = None;
    // (block, register) pairs whose predecessors are queued; a copy goes back within its block, so
    // the search ends.
    let mut seen = std::collections::BTreeSet::new();
    let mut work = vec![(block, b.last, r)];
    while let Some((x, end, r)) = work.pop() {
        let blk = &graph.blocks[x];
        let run = &insns[blk.first..end];
        match run.iter().rposition(|i| i.writes().contains(r)) {
            Some(at) => {
                if let Some(source) = register_copy(&run[at], r) {
                    work.push((x, blk.first + at, source));
                    continue;
                }
                let v = loaded_address(image, run, at, r)?;
                if value.is_some_and(|known| known != v) {
                    return None;
                }
                value = Some(v);
            }
            // The register as the function was entered: not known.
            None if x == 0 => return None,
            None => {
                for p in preds(x) {
                    if seen.insert((p, r)) {
                        work.push((p, graph.blocks[p].last + 1, r));
                    }
                }
            }
        }
    }
    value.map(|v| u64::from(v & !1))
}

/// The register `w` copies into `r` when it is a plain, unconditional `MOV r, rY` (no shift, no
/// immediate).
fn register_copy(w: &Insn, r: u8) -> Option<u8> {
    if w.inst.opcode != Opcode::MOV || w.conditional {
        return None;
    }
    let [d, source] = w.registers()[..] else {
        return None;
    };
    let operands = w
        .inst
        .operands
        .iter()
        .filter(|o| !matches!(o, Operand::Nothing))
        .count();
    (d == r && operands == 2).then_some(source)
}

/// The address the write of `r` at `run[at]` puts there: a literal load, or the high half of a `MOVW`/`MOVT`
/// pair.
fn loaded_address(image: &crate::Image, run: &[Insn], at: usize, r: u8) -> Option<u32> {
    let w = &run[at];
    if w.conditional {
        return None;
    }
    match w.inst.opcode {
        Opcode::LDR => image.word(w.literal_address()?),
        Opcode::MOVT => {
            let low = run[..at].iter().rposition(|i| i.writes().contains(r))?;
            let low = &run[low];
            if low.inst.opcode != Opcode::MOV || low.conditional || low.registers() != [r] {
                return None;
            }
            Some((low.immediate()? & 0xFFFF) | (w.immediate()? << 16))
        }
        _ => None,
    }
}
