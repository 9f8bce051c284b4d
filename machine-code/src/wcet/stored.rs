//! The targets of a call through a register, found in the image: the bounds file names them
//! (`targets`), or names the data object they are stored with (`stored_with`).
//!
//! A waker is a pair (data, vtable). RTIC 2's executor builds its wakers in two places only
//! (rtic `export/executor.rs`): `AsyncTaskExecutor::waker(wake)`, inlined into each dispatcher's
//! poll of a task with the task's pend closure as `wake` (a `fn()`, a constant of the dispatcher),
//! and `waker_clone(p)`, which keeps the data of the waker it clones. So every waker of
//! `WAKER_VTABLE` carries, as its data, the address of a function that the code taking the
//! vtable's address (or a caller of it, where the construction is not inlined) holds as a constant
//! and stores or passes on — and the vtable's wake calls that data. The targets are found so:
//!
//! * the functions that take the object's address: a literal of their pools, or a `MOVW`/`MOVT`
//!   pair that builds it; the object's address stored anywhere else (a value built before run
//!   time, whose neighbouring words the analysis does not read) declines;
//! * those functions and, transitively, every function that calls one of them directly;
//! * in each, every constant that is a function's address and is **used as data**: followed from
//!   the instruction that puts it in a register along every path of the function's graph, any use
//!   other than as the target of a call through that register (`BLX`/`BX`) — a store, a copy, an
//!   argument register at a call, a return value, an operand of anything — makes it data; a
//!   function address left in a pool no load reads is data too. A constant only ever called (a
//!   `fn` pointer the compiler kept in a register, the drive controller's closure) is not a waker.
//!
//! No such function, or a function that takes the address (other than one the object itself holds:
//! `waker_clone`) while neither it nor a caller holds a function's address as data, declines the call.
//! Known answers in this module's tests.
use std::collections::{BTreeMap, BTreeSet};

use super::bounds::IndirectTargets;
use super::cfg::Cfg;
use crate::decode::{Flow, Insn, Opcode, Operand};
use crate::image::Function;
use crate::waits::Conditional;
use crate::{Error, Image};

/// The argument and result registers r0-r3.
const ARGS: u16 = 0b1111;

/// The functions a stated call through a register reaches (name and address): `Err(Error)` for a
/// named target the image lacks, `Ok(Err(reason))` when the targets stored with an object cannot
/// be found (the bound is declined).
pub(super) fn targets(
    image: &Image,
    stated: &IndirectTargets,
    at: &str,
) -> Result<Result<Vec<(String, u64)>, String>, Error> {
    if let Some(object) = &stated.stored_with {
        return Ok(stored_with(image, object)
            .map(|found| found.into_iter().map(|t| (image.name(t), t)).collect()));
    }
    if let Some(v) = &stated.vtable_entry {
        return vtable_entries(image, v, at).map(Ok);
    }
    let mut targets = Vec::new();
    // A name stands for every function of that name (monomorphs and closures share theirs once
    // the hash is gone), and for the function the linker folded one of that name into.
    for name in &stated.targets {
        let before = targets.len();
        targets.extend(
            image
                .starts_named(name)
                .into_iter()
                .map(|start| (name.clone(), start)),
        );
        if targets.len() == before {
            return Err(Error::Bounds(format!(
                "the indirect call at {at} names `{name}`, which is not in the image"
            )));
        }
    }
    Ok(Ok(targets))
}

/// The function at word `entry` of each vtable `v` names (its name and address): `Err(Error)` for a
/// vtable the image lacks, one too short for the entry, or an entry that is no function's address
/// (a Thumb function's, with bit 0 set).
fn vtable_entries(
    image: &Image,
    v: &super::bounds::VtableEntry,
    at: &str,
) -> Result<Vec<(String, u64)>, Error> {
    let mut found = Vec::new();
    for object in &v.objects {
        let (address, size) = image.object_named(object).ok_or_else(|| {
            Error::Bounds(format!(
                "the indirect call at {at} names the vtable `{object}`, which is not in the image"
            ))
        })?;
        let offset = 4 * u64::from(v.entry);
        let function = (offset + 4 <= size)
            .then(|| image.word(address + offset))
            .flatten()
            .filter(|w| w & 1 == 1)
            .map(|w| u64::from(w & !1))
            .filter(|&t| image.function_at(t).is_some_and(|f| f.start == t));
        let Some(t) = function else {
            return Err(Error::Bounds(format!(
                "the indirect call at {at}: entry {} of the vtable `{object}` ({size} bytes) \
                 holds no function's address",
                v.entry
            )));
        };
        if !found.iter().any(|&(_, s)| s == t) {
            found.push((format!("{} ({object}[{}])", image.name(t), v.entry), t));
        }
    }
    Ok(found)
}

/// The functions whose addresses the code taking `object`'s address (and its callers) uses as data
/// (the module's method), or why they cannot be found.
pub fn stored_with(image: &Image, object: &str) -> Result<BTreeSet<u64>, String> {
    let (address, size) = image
        .object_named(object)
        .ok_or_else(|| format!("no data object `{object}` in the image"))?;
    let value = u32::try_from(address).map_err(|_| format!("`{object}` lies above 4 GiB"))?;
    let mut takers = BTreeSet::new();
    for word in image.words_holding(value) {
        let holder = image.functions.values().find(|f| f.contains(word));
        match holder {
            // A literal of its pool.
            Some(f) if f.data.iter().any(|&(from, to)| (from..to).contains(&word)) => {
                takers.insert(f.start);
            }
            // Instructions that happen to read as the value.
            Some(_) => {}
            None => {
                return Err(format!(
                    "the address of `{object}` is stored in data at {word:#010x} (a value built \
                     before run time, whose neighbouring words the analysis does not read)"
                ))
            }
        }
    }
    for f in image.functions.values() {
        let Ok(insns) = f.instructions() else {
            continue;
        };
        let mut known = [None; 16];
        // A conditional write taken as done: an address the code may build takes the object's.
        for insn in insns {
            crate::waits::step_constants(image, insn, &mut known, Conditional::Taken);
            if known.contains(&Some(value)) {
                takers.insert(f.start);
                break;
            }
        }
    }
    if takers.is_empty() {
        return Err(format!("no function takes the address of `{object}`"));
    }
    // Their callers, transitively: a construction not inlined gets its data from a caller.
    let mut callers: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
    for f in image.functions.values() {
        if let Ok(callees) = image.callees(f) {
            for c in callees {
                callers.entry(c).or_default().push(f.start);
            }
        }
    }
    let upward = |from: u64| {
        let mut seen = BTreeSet::from([from]);
        let mut work = vec![from];
        while let Some(f) = work.pop() {
            for &c in callers.get(&f).map(Vec::as_slice).unwrap_or_default() {
                if seen.insert(c) {
                    work.push(c);
                }
            }
        }
        seen
    };
    // The functions the object itself holds (a vtable's entries: `waker_clone` takes the vtable's
    // address to pass on the data of the waker it clones, no new data).
    let entries: BTreeSet<u64> = (0..size / 4)
        .filter_map(|k| image.word(address + 4 * k))
        .filter(|v| v & 1 == 1)
        .map(|v| u64::from(v & !1))
        .collect();
    let mut of_builder: BTreeMap<u64, BTreeSet<u64>> = BTreeMap::new();
    let mut found = BTreeSet::new();
    for &taker in &takers {
        let mut here = BTreeSet::new();
        for at in upward(taker) {
            if let std::collections::btree_map::Entry::Vacant(slot) = of_builder.entry(at) {
                slot.insert(match image.function_at(at) {
                    Some(f) => data_constants(image, f)?,
                    None => BTreeSet::new(),
                });
            }
            here.extend(of_builder[&at].iter().copied());
        }
        // A builder whose data no constant of its own or its callers' gives: it comes from memory
        // or from elsewhere the method does not follow.
        if here.is_empty() && !entries.contains(&taker) {
            return Err(format!(
                "{} takes the address of `{object}`, but neither it nor a caller holds a function's \
                 address as data: where its wakers' data comes from is not followed",
                image.name(taker)
            ));
        }
        found.extend(here);
    }
    if found.is_empty() {
        return Err(format!(
            "no function's address is used as data where `{object}`'s address is taken"
        ));
    }
    Ok(found)
}

/// The functions whose addresses `f` holds as constants and uses as data.
fn data_constants(image: &Image, f: &Function) -> Result<BTreeSet<u64>, String> {
    let insns = f.instructions().map_err(|e| format!("{}: {e}", f.name))?;
    let function_at = |v: u32| {
        let t = u64::from(v & !1);
        (v & 1 == 1 && image.function_at(t).is_some()).then_some(t)
    };
    let read = |address: u64, size: u64| {
        let bytes = image.bytes(address, size)?;
        Some(match bytes[..] {
            [b] => u64::from(b),
            [lo, hi] => u64::from(u16::from_le_bytes([lo, hi])),
            _ => return None,
        })
    };
    let graph = Cfg::build(f, &read, &|_| true).map_err(|e| format!("{}: {e}", f.name))?;
    let mut found = BTreeSet::new();
    // Pool words that hold a function's address and that no literal load reads.
    let loaded: BTreeSet<u64> = insns.iter().filter_map(Insn::literal_address).collect();
    for &(from, to) in &f.data {
        let mut word = from.next_multiple_of(4);
        while word + 4 <= to {
            if let Some(t) = image.word(word).and_then(function_at) {
                if !loaded.contains(&word) {
                    found.insert(t);
                }
            }
            word += 4;
        }
    }
    // Each constant a register is given, followed from there (a conditional write taken as done,
    // seen where it is written; `used_as_data` keeps a register through a conditional write).
    for (b, block) in graph.blocks.iter().enumerate() {
        let mut known = [None; 16];
        for k in block.first..=block.last {
            let before = known;
            crate::waits::step_constants(image, &insns[k], &mut known, Conditional::Taken);
            for r in 0..13u8 {
                let now = known[usize::from(r)];
                if now == before[usize::from(r)] && !insns[k].writes().contains(r) {
                    continue;
                }
                if let Some(t) = now.and_then(function_at) {
                    if used_as_data(insns, &graph, b, k, r, image) {
                        found.insert(t);
                    }
                }
            }
        }
    }
    Ok(found)
}

/// Whether the value register `r` holds after instruction `k` (of block `b`) is used other than
/// as the target of a call through it, on any path.
fn used_as_data(insns: &[Insn], graph: &Cfg, b: usize, k: usize, r: u8, image: &Image) -> bool {
    let mut seen = BTreeSet::new();
    let mut work = vec![(b, k + 1, 1u16 << r)];
    while let Some((b, from, mut regs)) = work.pop() {
        let block = &graph.blocks[b];
        let mut ended = false;
        for insn in insns.iter().take(block.last + 1).skip(from) {
            if regs == 0 {
                ended = true;
                break;
            }
            match insn.flow() {
                Flow::IndirectCall(_) => {
                    if regs & ARGS != 0 {
                        return true;
                    }
                }
                Flow::IndirectJump => {
                    let through = match insn.registers()[..] {
                        [t] if insn.inst.opcode == Opcode::BX => Some(t),
                        _ => None,
                    };
                    // A tail call through a register of the set, its arguments not of it.
                    if through.is_some_and(|t| regs & (1 << t) != 0 && regs & ARGS == 0) {
                        ended = true;
                        break;
                    }
                    return true;
                }
                Flow::Call(t) => {
                    let reads = match &insn.outlined {
                        Some(_) => helper_reads(image, t),
                        None => ARGS,
                    };
                    if regs & reads != 0 {
                        return true;
                    }
                }
                Flow::Return => {
                    if regs & ARGS != 0 {
                        return true;
                    }
                    ended = true;
                    break;
                }
                Flow::Branch(t) if !graph_holds(insns, t) => {
                    // A tail call: its arguments.
                    if regs & ARGS != 0 {
                        return true;
                    }
                    if !insn.conditional {
                        ended = true;
                        break;
                    }
                }
                _ => {
                    if reads(insn) & regs != 0 {
                        return true;
                    }
                }
            }
            // A conditional write may not happen: the register keeps the value.
            if !insn.conditional {
                regs &= !insn.writes().0;
            }
        }
        if ended || regs == 0 {
            continue;
        }
        for e in &block.succs {
            if seen.insert((e.to, regs)) {
                work.push((e.to, graph.blocks[e.to].first, regs));
            }
        }
    }
    false
}

/// Whether `t` is an instruction of the function (`insns`).
fn graph_holds(insns: &[Insn], t: u64) -> bool {
    insns.first().is_some_and(|f| f.addr <= t) && insns.last().is_some_and(|l| t < l.next())
}

/// The registers an outlined helper may read: every register any of its instructions names, and
/// the arguments of a call it makes; every register when it branches.
fn helper_reads(image: &Image, at: u64) -> u16 {
    let Some(insns) = image.function_at(at).and_then(|f| f.instructions().ok()) else {
        return 0xFFFF;
    };
    let mut out = 0;
    for insn in insns {
        match insn.flow() {
            Flow::Next | Flow::Return => out |= reads(insn),
            Flow::Call(_) | Flow::Branch(_) if !insn.conditional => out |= reads(insn) | ARGS,
            _ => return 0xFFFF,
        }
    }
    out
}

/// The registers an instruction reads: every register it names, except its destinations where
/// they are only written (a load's, a load multiple's list, the first operand of a move or of a
/// data-processing instruction of three operands or more). Conservative: a destination the
/// instruction also reads, or one it is not known to only write, counts as read.
pub(super) fn reads(insn: &Insn) -> u16 {
    let ops = &insn.inst.operands;
    let count = ops
        .iter()
        .filter(|o| !matches!(o, Operand::Nothing))
        .count();
    let load = insn.is_load() && !insn.is_store();
    let store = insn.is_store();
    let written_only = |position: usize| {
        (load && position < 2 && matches!(ops[position], Operand::Reg(_)))
            || (position == 0
                && !store
                && (matches!(insn.inst.opcode, Opcode::MOV | Opcode::MVN)
                    || (count >= 3
                        && !matches!(
                            insn.inst.opcode,
                            Opcode::BFI
                                | Opcode::BFC
                                | Opcode::MOVT
                                | Opcode::UMLAL
                                | Opcode::SMLAL
                                | Opcode::UMAAL
                        ))))
    };
    let mut out = 0u16;
    let bit = |r: &yaxpeax_arm::armv7::Reg| 1u16 << r.number();
    for (position, o) in ops.iter().enumerate() {
        match o {
            Operand::Reg(r) if !written_only(position) => out |= bit(r),
            Operand::RegWBack(r, _) | Operand::RegDeref(r) => out |= bit(r),
            Operand::RegList(list) if !load => out |= list,
            Operand::RegShift(s) => shift_reads(s, &mut out),
            Operand::RegDerefPostindexRegShift(r, s, ..)
            | Operand::RegDerefPreindexRegShift(r, s, ..) => {
                out |= bit(r);
                shift_reads(s, &mut out);
            }
            Operand::RegDerefPostindexOffset(r, ..) | Operand::RegDerefPreindexOffset(r, ..) => {
                out |= bit(r)
            }
            Operand::RegDerefPostindexReg(r, i, ..) | Operand::RegDerefPreindexReg(r, i, ..) => {
                out |= bit(r) | bit(i);
            }
            Operand::BankedReg(_, r) => out |= bit(r),
            _ => {}
        }
    }
    out
}

/// The registers a shifted operand reads.
fn shift_reads(s: &yaxpeax_arm::armv7::RegShift, out: &mut u16) {
    use yaxpeax_arm::armv7::RegShiftStyle;
    match s.into_shift() {
        RegShiftStyle::RegImm(shift) => *out |= 1 << shift.shiftee().number(),
        RegShiftStyle::RegReg(shift) => {
            *out |= 1 << shift.shiftee().number() | 1 << shift.shifter().number()
        }
    }
}

#[cfg(test)]
mod tests {
    //! Known answers on a hand-assembled image (GNU as for Cortex-M3, its words copied), cycles
    //! from the Cortex-M3 TRM (table 18-1) at 0 wait states: data processing 1, a return or a
    //! branch through a register 1 + P (P = 3).
    use super::*;
    use crate::testelf::{elf_with_lines, Sym};
    use crate::thumb;
    use crate::wcet::bound_function;
    use crate::wcet::bounds::BoundsFile;
    use crate::wcet::chip::Chip;

    const F103_0WS: Chip = Chip::Stm32f103 { wait_states: 0 };

    /// `wake` calls its argument (`bx r0`, as RTIC's `waker_wake`) at src/exec.rs:22. `dispatch`
    /// builds a waker on its stack from `VTABLE`'s address and `pend`'s, and calls `costly`
    /// through a register it only calls; `outer` passes `pend2` to `dispatch`; `elsewhere` returns
    /// `other`'s address but takes no vtable's. [`Extra`] adds more after the vtable.
    fn waker_image(extra: Extra) -> Image {
        let mut halves = vec![
            0x4700, // 0x00 wake: bx r0
            0xbf00, // 0x02 nop
            0xb510, // 0x04 dispatch: push {r4, lr}
            0xb082, // 0x06 sub sp, #8
            0x4804, // 0x08 ldr r0, [pc, #16]: pend (0x1c)
            0x4905, // 0x0a ldr r1, [pc, #20]: VTABLE (0x20)
            0x9100, // 0x0c str r1, [sp, #0]: the waker's vtable
            0x9001, // 0x0e str r0, [sp, #4]: its data
            0x4c04, // 0x10 ldr r4, [pc, #16]: costly (0x24)
            0x47a0, // 0x12 blx r4
            0x47a0, // 0x14 blx r4
            0xb002, // 0x16 add sp, #8
            0xbd10, // 0x18 pop {r4, pc}
            0xbf00, // 0x1a nop
            0x0041, 0x0000, // 0x1c .word pend + 1
            0x0068, 0x0000, // 0x20 .word VTABLE
            0x004b, 0x0000, // 0x24 .word costly + 1
            0x4800, // 0x28 elsewhere: ldr r0, [pc, #0]: other (0x2c)
            0x4770, // 0x2a bx lr
            0x0059, 0x0000, // 0x2c .word other + 1
            0xb580, // 0x30 outer: push {r7, lr}
            0x4802, // 0x32 ldr r0, [pc, #8]: pend2 (0x3c)
            0xf7ff, 0xffe6, // 0x34 bl dispatch
            0xbd80, // 0x38 pop {r7, pc}
            0xbf00, // 0x3a nop
            0x0045, 0x0000, // 0x3c .word pend2 + 1
            0x2001, // 0x40 pend: movs r0, #1
            0x4770, // 0x42 bx lr
            0x2001, // 0x44 pend2: movs r0, #1
            0x3001, // 0x46 adds r0, #1
            0x4770, // 0x48 bx lr
            0x2000, // 0x4a costly: movs r0, #0 (a counted loop of 8 passes)
            0x2300, // 0x4c movs r3, #0
            0x18c0, // 0x4e adds r0, r0, r3
            0x3301, // 0x50 adds r3, #1
            0x2b08, // 0x52 cmp r3, #8
            0xd1fb, // 0x54 bne 0x4e
            0x4770, // 0x56 bx lr
            0x2000, // 0x58 other: the same loop
            0x2300, // 0x5a movs r3, #0
            0x18c0, // 0x5c adds r0, r0, r3
            0x3301, // 0x5e adds r3, #1
            0x2b08, // 0x60 cmp r3, #8
            0xd1fb, // 0x62 bne 0x5c
            0x4770, // 0x64 bx lr
            0xbf00, // 0x66 nop
            0x0000, 0x0000, // 0x68 VTABLE: clone (none here)
            0x0001, 0x0000, // 0x6c wake
            0x0001, 0x0000, // 0x70 wake by reference
            0x0000, 0x0000, // 0x74 drop
        ];
        let mut symbols = vec![];
        match extra {
            Extra::Nothing => {}
            Extra::Stray => halves.extend([0x0068, 0x0000]), // 0x78 .word VTABLE, in no function
            Extra::Reload => {
                halves.extend([
                    0x6810, // 0x78 reload: ldr r0, [r2]: the data from memory
                    0x4902, // 0x7a ldr r1, [pc, #8]: VTABLE (0x84)
                    0x6019, // 0x7c str r1, [r3]
                    0x6058, // 0x7e str r0, [r3, #4]
                    0x4770, // 0x80 bx lr
                    0xbf00, // 0x82 nop
                    0x0068, 0x0000, // 0x84 .word VTABLE
                ]);
                symbols.extend([
                    Sym::code(0x78),
                    Sym::function("reload", 0x78, 0x10),
                    Sym::data(0x84),
                ]);
            }
        }
        symbols.extend([
            Sym::function("wake", 0, 4),
            Sym::function("dispatch", 0x04, 0x24),
            Sym::data(0x1c),
            Sym::code(0x28),
            Sym::function("elsewhere", 0x28, 8),
            Sym::data(0x2c),
            Sym::code(0x30),
            Sym::function("outer", 0x30, 0x10),
            Sym::data(0x3c),
            Sym::code(0x40),
            Sym::function("pend", 0x40, 4),
            Sym::function("pend2", 0x44, 6),
            Sym::function("costly", 0x4a, 0x0e),
            Sym::function("other", 0x58, 0x10),
            Sym::object("VTABLE", 0x68, 16),
            Sym::data(0x68),
        ]);
        let bytes = elf_with_lines(
            &thumb(&halves),
            &symbols,
            "firmware/src/exec.rs",
            &[(0, 22), (4, 30)],
        );
        Image::parse(&bytes).expect("the test image parses")
    }

    /// What the test image holds after its vtable.
    #[derive(Clone, Copy)]
    enum Extra {
        Nothing,
        /// A word holding the vtable's address outside any function.
        Stray,
        /// `reload`, which builds a waker of the vtable from data it loads from memory.
        Reload,
    }

    fn bounds(targets: &str) -> BoundsFile {
        BoundsFile::parse(&format!(
            r#"{{"indirect":[{{"function":"wake","file":"src/exec.rs","line":22,{targets},"reason":"the waker's data"}}]}}"#
        ))
        .expect("the bounds file parses")
    }

    #[test]
    fn the_functions_stored_with_a_vtable_are_those_its_builders_use_as_data() {
        let img = waker_image(Extra::Nothing);
        let found = stored_with(&img, "VTABLE").unwrap();
        // pend (stored beside the vtable's address) and pend2 (passed to the builder by its
        // caller); not costly (only called through r4), not other (no builder holds it).
        assert_eq!(found, BTreeSet::from([0x40, 0x44]));
    }

    #[test]
    fn a_waker_call_is_bounded_by_the_functions_stored_with_its_vtable() {
        let img = waker_image(Extra::Nothing);
        let b =
            bound_function(&img, "wake", F103_0WS, &bounds(r#""stored_with":"VTABLE""#)).unwrap();
        // bx r0: 1 + P = 4, then the costlier target, pend2: movs 1 + adds 1 + bx lr 4 = 6.
        // 10 cycles; 1 + 3 instructions.
        assert_eq!((b.cycles, b.instructions, b.declined), (10, 4, None));
        // Named instead: costly, 8 passes (2 + 8 × 4 + 7 × 3 + 4 = 59): 63 cycles, 1 + 35.
        let b = bound_function(&img, "wake", F103_0WS, &bounds(r#""targets":["costly"]"#)).unwrap();
        assert_eq!((b.cycles, b.instructions, b.declined), (63, 36, None));
    }

    #[test]
    fn a_vtable_that_cannot_be_followed_declines_the_call() {
        // Its address stored outside any function's code.
        let img = waker_image(Extra::Stray);
        let reason = stored_with(&img, "VTABLE").unwrap_err();
        assert!(reason.contains("stored in data at 0x00000078"), "{reason}");
        let b =
            bound_function(&img, "wake", F103_0WS, &bounds(r#""stored_with":"VTABLE""#)).unwrap();
        let declined = b.declined.expect("declined");
        assert!(declined.contains("exec.rs:22"), "{declined}");
        // A builder whose data comes from memory.
        let reason = stored_with(&waker_image(Extra::Reload), "VTABLE").unwrap_err();
        assert!(
            reason.starts_with("reload takes the address of `VTABLE`"),
            "{reason}"
        );
        // No such object.
        let img = waker_image(Extra::Nothing);
        let b = bound_function(&img, "wake", F103_0WS, &bounds(r#""stored_with":"NONE""#)).unwrap();
        assert!(b
            .declined
            .is_some_and(|d| d.contains("no data object `NONE`")));
        // Both ways, or neither, is no entry.
        for both in [
            r#""stored_with":"VTABLE","targets":["pend"]"#,
            r#""targets":[]"#,
        ] {
            let json = format!(
                r#"{{"indirect":[{{"function":"wake","file":"src/exec.rs","line":22,{both},"reason":"x"}}]}}"#
            );
            assert!(matches!(BoundsFile::parse(&json), Err(Error::Bounds(_))));
        }
    }
}
