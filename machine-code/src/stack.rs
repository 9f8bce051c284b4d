//! A static bound on a firmware image's stack, from its machine code: what QEMU's painted stack can only sample.
//!
//! Per function, its frame is every instruction that moves the stack pointer down (`PUSH`, `SUB SP`, `VPUSH`, a
//! pre-indexed store to `SP`), summed over the whole body, so a frame set up on several paths is counted on each: an
//! upper bound. A function's depth is its frame plus the deepest of its callees (direct calls and tail calls, from
//! [`Image::callees`]); a call through a register may reach any function whose address the image stores
//! outside its vector table (waker vtables, function pointers), so it counts the deepest of those. Recursion has no
//! bound and is an error.
//!
//! The image's stack is then thread mode (the reset handler: `main`, `init`, `idle` and the priority-0 tasks polled
//! there, the admission check among them) plus the interrupts nested on it. An exception handler cannot preempt
//! itself and the NVIC nests at most one handler per priority level, so at most `levels` distinct handlers are on the
//! stack at once: the bound adds the `levels` deepest handlers of the vector table, each with its exception frame
//! (the basic frame, or the extended one with the FPU's registers). That is sound without knowing which handler has
//! which priority, and loose by as much as the deepest handlers share a level.
use std::collections::BTreeMap;
use std::path::Path;

use crate::decode::{Insn, Opcode, Operand, SP};
use crate::{Error, Image};

/// Bytes the Cortex-M pushes on exception entry: the basic frame (r0-r3, r12, lr, pc, xPSR) and, with the FPU
/// active, the extended frame (s0-s15, FPSCR and a reserved word besides), plus the alignment word the core may add.
const BASIC_FRAME: u64 = 32 + 4;
const EXTENDED_FRAME: u64 = 104 + 4;

/// What one function's code does to the stack: the bytes its instructions move the stack pointer down (summed over
/// the body), and how many calls or tail calls go through a register.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct FrameFacts {
    /// Bytes pushed or reserved.
    pub frame: u64,
    /// `BLX Rm`, and `BX Rm` other than a return through `LR`.
    pub indirect: usize,
}

/// What `insns` do to the stack and how many of them call or jump through a register.
pub fn frame_facts(insns: &[Insn]) -> FrameFacts {
    let mut facts = FrameFacts::default();
    for insn in insns {
        let ops = &insn.inst.operands;
        match insn.inst.opcode {
            // PUSH {registers} (16- and 32-bit; STMDB SP! decodes as PUSH).
            Opcode::PUSH => {
                let words = match ops[0] {
                    Operand::RegList(list) => list.count_ones(),
                    _ => 1,
                };
                facts.frame += 4 * u64::from(words);
            }
            Opcode::STM(false, true, _, _) if insn.memory_base_wback() == Some(SP) => {
                facts.frame += 4 * u64::from(insn.register_list().unwrap_or(0).count_ones());
            }
            // SUB SP, SP, #imm (SUB, SUB.W, SUBW).
            Opcode::SUB if insn.registers().first() == Some(&SP) => {
                if let Some(imm) = insn.immediate() {
                    facts.frame += u64::from(imm);
                }
            }
            // STR Rt, [SP, #-imm]! (a single register's PUSH).
            Opcode::STR | Opcode::STRB | Opcode::STRH | Opcode::STRD => {
                if let Some(Operand::RegDerefPreindexOffset(base, offset, false, true)) = ops
                    .iter()
                    .find(|o| matches!(o, Operand::RegDerefPreindexOffset(..)))
                {
                    if base.number() == SP {
                        facts.frame += u64::from(*offset);
                    }
                }
            }
            _ => {}
        }
        // VPUSH {s or d registers}: a store to coprocessor 10 or 11 through SP with writeback, its
        // immediate the words pushed.
        if let Some(words) = insn.vpush_words() {
            facts.frame += 4 * u64::from(words);
        }
        match insn.flow() {
            crate::decode::Flow::IndirectCall(_) | crate::decode::Flow::IndirectJump => {
                facts.indirect += 1
            }
            _ => {}
        }
    }
    facts
}

/// A function's deepest stack, and the chain of calls that reaches it.
#[derive(Debug, Clone)]
pub struct Depth {
    /// Bytes.
    pub bytes: u64,
    /// The functions on the deepest chain, from the one asked about.
    pub chain: Vec<u64>,
}

/// Depths of an image's functions, worked out once each.
struct Depths<'a> {
    image: &'a Image,
    known: BTreeMap<u64, Depth>,
    /// The deepest function whose address is taken: what a call through a register may reach.
    indirect: Option<Depth>,
    /// The functions being worked out (a call back to one of them is recursion).
    open: Vec<u64>,
    /// Targets of calls through a register left out so far because they were on the chain: a depth worked out
    /// while one was left out depends on its chain and is not kept.
    skipped: usize,
}

impl Depths<'_> {
    fn of(&mut self, at: u64) -> Result<Depth, Error> {
        if let Some(known) = self.known.get(&at) {
            return Ok(known.clone());
        }
        if self.open.contains(&at) {
            let cycle: Vec<String> = self.open.iter().map(|&a| self.image.name(a)).collect();
            return Err(Error::Other(format!(
                "recursion through {} → {}: the stack has no static bound",
                cycle.join(" → "),
                self.image.name(at)
            )));
        }
        let Some(f) = self.image.functions.get(&at) else {
            return Ok(Depth {
                bytes: 0,
                chain: vec![at],
            });
        };
        self.open.push(at);
        let skipped_before = self.skipped;
        let facts = frame_facts(f.instructions()?);
        let mut deepest = Depth {
            bytes: 0,
            chain: Vec::new(),
        };
        for callee in self.image.callees(f)? {
            let d = self.of(callee)?;
            if d.bytes > deepest.bytes || deepest.chain.is_empty() {
                deepest = d;
            }
        }
        if facts.indirect > 0 {
            let d = self.through_register()?;
            if d.bytes > deepest.bytes || deepest.chain.is_empty() {
                deepest = d;
            }
        }
        self.open.pop();
        let mut chain = vec![at];
        chain.extend(deepest.chain);
        let depth = Depth {
            bytes: facts.frame + deepest.bytes,
            chain,
        };
        if self.skipped == skipped_before {
            self.known.insert(at, depth.clone());
        }
        Ok(depth)
    }

    /// The deepest function a call through a register may reach, but the ones already on the chain: a call through
    /// a register is taken not to re-enter the chain (the firmware has no recursion; a waker's `wake`, itself in a
    /// vtable, calls the task's pend function through a register, which the conservative target set would
    /// otherwise turn into a cycle). Worked out once, from the first chain that needs it, so it is not cached when a
    /// target was left out.
    fn through_register(&mut self) -> Result<Depth, Error> {
        if let Some(d) = &self.indirect {
            return Ok(d.clone());
        }
        let mut deepest = Depth {
            bytes: 0,
            chain: Vec::new(),
        };
        let mut skipped = false;
        for &target in &self.image.address_taken {
            if self.open.contains(&target) {
                skipped = true;
                self.skipped += 1;
                continue;
            }
            let d = self.of(target)?;
            if d.bytes > deepest.bytes || deepest.chain.is_empty() {
                deepest = d;
            }
        }
        if !skipped {
            self.indirect = Some(deepest.clone());
        }
        Ok(deepest)
    }
}

/// The stack bound of one image.
#[derive(Debug)]
pub struct StackBound {
    /// Thread mode's deepest chain (from the reset handler).
    pub thread: Depth,
    /// The handlers counted as nested on it, deepest first: (vector index, depth).
    pub handlers: Vec<(usize, Depth)>,
    /// Bytes of one exception frame.
    pub exception_frame: u64,
    /// The bound: thread mode, plus each counted handler and its exception frame.
    pub bytes: u64,
}

/// The stack bound of `elf` with at most `levels` handlers nested (the number of distinct exception priorities the
/// image can use, the fault handlers' included), `fpu` for the extended exception frame.
pub fn bound(elf: &Path, levels: usize, fpu: bool) -> Result<StackBound, Error> {
    bound_in(&Image::read(elf)?, levels, fpu)
}

/// [`bound`] of an image already read.
pub fn bound_in(image: &Image, levels: usize, fpu: bool) -> Result<StackBound, Error> {
    let Some(&(_, reset)) = image.vectors.iter().find(|(i, _)| *i == 1) else {
        return Err(Error::Other("no reset vector".into()));
    };
    let mut depths = Depths {
        image,
        known: BTreeMap::new(),
        indirect: None,
        open: Vec::new(),
        skipped: 0,
    };
    let thread = depths.of(reset)?;
    // Every distinct handler once (a handler shared by several vectors cannot nest on itself either).
    let mut handlers: BTreeMap<u64, usize> = BTreeMap::new();
    for &(index, handler) in image.vectors.iter().filter(|(i, _)| *i > 1) {
        handlers.entry(handler).or_insert(index);
    }
    let mut nested = Vec::new();
    for (handler, index) in handlers {
        nested.push((index, depths.of(handler)?));
    }
    nested.sort_by_key(|n| std::cmp::Reverse(n.1.bytes));
    nested.truncate(levels);
    let exception_frame = if fpu { EXTENDED_FRAME } else { BASIC_FRAME };
    let bytes = thread.bytes
        + nested
            .iter()
            .map(|(_, d)| d.bytes + exception_frame)
            .sum::<u64>();
    Ok(StackBound {
        thread,
        handlers: nested,
        exception_frame,
        bytes,
    })
}

/// Names of a chain's functions, for a report.
pub fn chain_names(image: &Image, chain: &[u64]) -> Vec<String> {
    chain.iter().map(|&a| image.name(a)).collect()
}

/// A demangled name without its hash and generic arguments, for a one-line chain.
pub fn short(name: &str) -> String {
    let mut out = String::new();
    let mut depth = 0;
    for c in name.chars() {
        match c {
            '<' => depth += 1,
            '>' => depth -= 1,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode;
    use crate::thumb;

    #[test]
    fn counts_what_moves_the_stack_pointer_down() {
        // Encodings as llvm-objdump shows them in the boards' images.
        let code = thumb(&[
            0xb5f0, // push {r4, r5, r6, r7, lr}: 20
            0xe92d, 0x0f00, // push.w {r8, r9, r10, r11}: 16
            0xb085, // sub sp, #20: 20
            0xf5ad, 0x6d80, // sub.w sp, sp, #1024: 1024
            0xf2ad, 0x4d0c, // subw sp, sp, #1036: 1036
            0xf84d, 0x4d04, // str r4, [sp, #-4]!: 4
            0xed2d, 0x8b10, // vpush {d8-d15}: 64
            0xb005, // add sp, #20: nothing
            0x4780, // blx r0
            0x4770, // bx lr: a return
            0x4718, // bx r3
        ]);
        let insns = decode("f", 0x1000, &code, &[]).unwrap();
        assert_eq!(
            frame_facts(&insns),
            FrameFacts {
                frame: 20 + 16 + 20 + 1024 + 1036 + 4 + 64,
                indirect: 2
            }
        );
    }
}
