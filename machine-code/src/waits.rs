//! The wait scan: finds, in a release ELF's machine code, every loop that polls memory without a
//! bound — the shape of `while !flag {}` on a peripheral register, whatever source it came from
//! (our code, a HAL, a PAC, an inlined dependency).
//!
//! Why the machine code and not the source: the waits issue 21 found were in the HALs (inlined
//! `Rcc::freeze`, `BlockingI2c`), which a lint of this repository never sees, and a source lint
//! cannot tell a bounded `(0..N).any(..)` from `loop { if .. }` after inlining either. The ELF is
//! what runs (decoded by [`crate::decode`], source lines from the DWARF line table). A loop is reported when it is *tight* (a backward branch over at most
//! [`MAX_BODY`] instructions, no call), *polls a peripheral* (it stores nothing and loads from a
//! register the function set to a constant in the peripheral ranges, `0x4000_0000..0x6000_0000`
//! and the core's `0xE000_0000..0xE010_0000`, from a literal or `movw`/`movt`), and has *no counter*
//! (no register stepped by an immediate that was not loaded in the loop: a poll bounded by a count
//! steps one, `(0..N).any(..)` compiles to `subs rX, #1`). A loop that compares a loaded value
//! (such as the DWT cycle counter) against a limit has no counter and is reported too: it is
//! bounded only while that counter runs.
//!
//! What the scan cannot prove bounded is either fixed or listed in [`KNOWN`] with the reason it
//! ends; anything else fails `cargo xtask smoke`. Heuristic limits (docs/faults.md): a wait whose
//! loop calls a function, or stores, or is longer than [`MAX_BODY`], or reads through an address
//! the function did not build from a constant (a driver holding its base in a field, as the
//! runtime's own `Mmio` drivers do — they are bounded by review and host tests), is not seen.
use std::path::Path;

use crate::decode::{Flow, Insn, Opcode, Operand, PC, SP};
use crate::{Error, Image};

/// The longest loop body (instructions) taken for a poll.
pub const MAX_BODY: usize = 16;

/// Waits that the scan finds but that end for a stated reason: (source path fragment, reason). A
/// loop is excused when every source line in it outside the core library is under one fragment.
pub const KNOWN: &[(&str, &str)] = &[];

/// One unbounded-looking loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Wait {
    /// The function it is in.
    pub function: String,
    /// Address of its backward branch.
    pub branch: u64,
    /// Source lines in the loop (outside the core library), innermost as the line table gives.
    pub lines: Vec<String>,
}

impl Wait {
    /// Why it is excused, if it is ([`KNOWN`]).
    pub fn known(&self) -> Option<&'static str> {
        self.known_in(KNOWN)
    }

    fn known_in(&self, list: &[(&str, &'static str)]) -> Option<&'static str> {
        list.iter()
            .find(|(fragment, _)| {
                !self.lines.is_empty() && self.lines.iter().all(|l| l.contains(fragment))
            })
            .map(|(_, reason)| *reason)
    }
}

/// The waits in the image at `elf`.
pub fn scan_elf(elf: &Path) -> Result<Vec<Wait>, Error> {
    scan(&Image::read(elf)?)
}

/// The waits in `image`: every function's tight loops that poll a peripheral without a counter.
pub fn scan(image: &Image) -> Result<Vec<Wait>, Error> {
    let mut waits = Vec::new();
    for f in image.functions.values() {
        waits.extend(loops_in(image, &f.name, f.instructions()?));
    }
    Ok(waits)
}

/// Whether an address is a peripheral's (the STM32 peripherals, the core's private bus).
pub fn is_peripheral(address: u32) -> bool {
    (0x4000_0000..0x6000_0000).contains(&address) || (0xE000_0000..0xE010_0000).contains(&address)
}

/// How [`step_constants`] takes a conditional instruction (one in an `IT` block), which may not
/// execute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conditional {
    /// Joined with the value before it: a register keeps a constant only where both agree, so a
    /// known constant is the register's value on every path (what a raise of the masking writes).
    Joined,
    /// As executed: each value the code may build is seen where it is written, and replaces the
    /// one before (a scan for what the code may hold looks at each value at its write: a polled
    /// peripheral's address, an object's or a function's address taken).
    Taken,
}

/// The registers holding a known constant after `insns` (straight-line view: the last definition
/// wins, anything else that writes a register forgets it): literal loads, `MOV`/`MOVW` of an
/// immediate, `MOVT` over a known low half; a conditional write as executed (the wait scan looks
/// for every peripheral address a loop may poll).
pub fn constants(image: &Image, insns: &[Insn]) -> [Option<u32>; 16] {
    let mut known = [None; 16];
    for insn in insns {
        step_constants(image, insn, &mut known, Conditional::Taken);
    }
    known
}

/// One instruction's effect on [`constants`], a conditional one taken as `conditional` says.
pub fn step_constants(
    image: &Image,
    insn: &Insn,
    known: &mut [Option<u32>; 16],
    conditional: Conditional,
) {
    let before = *known;
    let regs = insn.registers();
    let value = match insn.inst.opcode {
        Opcode::LDR if insn.memory_base() == Some(PC) => {
            insn.literal_address().and_then(|at| image.word(at))
        }
        Opcode::MOV if regs.len() == 1 => insn.immediate(),
        Opcode::MOVT if regs.len() == 1 => {
            let low = known[usize::from(regs[0])];
            low.zip(insn.immediate())
                .map(|(low, high)| (low & 0xffff) | (high << 16))
        }
        _ => None,
    };
    let written = insn.writes();
    for r in 0..16u8 {
        if written.contains(r) {
            known[usize::from(r)] = None;
        }
    }
    if let (Some(v), Some(&rd)) = (value, regs.first()) {
        known[usize::from(rd)] = Some(v);
    }
    if insn.conditional && conditional == Conditional::Joined {
        for r in 0..16 {
            if known[r] != before[r] {
                known[r] = None;
            }
        }
    }
}

fn loops_in(image: &Image, function: &str, insns: &[Insn]) -> Vec<Wait> {
    let mut found = Vec::new();
    for (end, branch) in insns.iter().enumerate() {
        let Flow::Branch(to) = branch.flow() else {
            continue;
        };
        if to > branch.addr {
            continue;
        }
        let Some(start) = insns.iter().position(|i| i.addr == to) else {
            continue;
        };
        let body = &insns[start..=end];
        if body.len() > MAX_BODY {
            continue;
        }
        let mut loaded = crate::decode::Regs::default();
        for i in body.iter().filter(|i| i.is_load()) {
            loaded.0 |= i.writes().0;
        }
        let calls_or_stores = body.iter().any(|i| {
            matches!(i.flow(), Flow::Call(_) | Flow::IndirectCall(_))
                || i.is_store()
                || matches!(i.inst.opcode, Opcode::WFI | Opcode::WFE)
        });
        if loaded.0 == 0 || calls_or_stores {
            continue;
        }
        let known = constants(image, &insns[..start]);
        let polls_peripheral = body
            .iter()
            .filter(|i| i.is_load() && i.memory_base() != Some(PC))
            .filter_map(Insn::memory_base)
            .any(|b| known[usize::from(b)].is_some_and(is_peripheral));
        if !polls_peripheral {
            continue;
        }
        // A counter: a register stepped by an immediate, not one the loop loads.
        let counted = body.iter().any(|i| {
            matches!(i.inst.opcode, Opcode::ADD | Opcode::SUB)
                && i.immediate().is_some()
                && matches!(i.inst.operands[0], Operand::Reg(r)
                    if !loaded.contains(r.number()) && r.number() != SP)
        });
        if counted {
            continue;
        }
        let mut lines: Vec<String> = body
            .iter()
            .filter_map(|i| image.line(i.addr))
            .map(|(file, line)| format!("{file}:{line}"))
            .filter(|l| !l.contains("/rustlib/src/rust/library/"))
            .collect();
        lines.dedup();
        found.push(Wait {
            function: function.to_string(),
            branch: branch.addr,
            lines,
        });
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testelf::{elf, Sym};
    use crate::thumb;

    /// A poll of RCC (0x4002_1000) without a counter, the same poll with one, and a copy loop.
    fn image() -> Image {
        let mut code = thumb(&[
            // poll_forever at 0x00:
            0x4801, // 0x00 ldr r0, [pc, #4]  (the literal at 0x08)
            0xe003, // 0x02 b 0x0c
            0x0000, 0x0000, // 0x04 padding (data)
            0x1000, 0x4002, // 0x08 .word 0x40021000
            0x6801, // 0x0c ldr r1, [r0]
            0x0389, // 0x0e lsls r1, r1, #14
            0xd5fc, // 0x10 bpl 0x0c
            0x4770, // 0x12 bx lr
            // poll_counted at 0x14:
            0xf241, 0x0000, // 0x14 movw r0, #0x1000
            0xf2c4, 0x0002, // 0x18 movt r0, #0x4002
            0x6802, // 0x1c ldr r2, [r0]
            0x0392, // 0x1e lsls r2, r2, #14
            0xd401, // 0x20 bmi 0x26
            0x3901, // 0x22 subs r1, #1
            0xd1fa, // 0x24 bne 0x1c
            0x4770, // 0x26 bx lr
            // copy at 0x28:
            0xf811, 0x3b01, // 0x28 ldrb r3, [r1], #1
            0xf800, 0x3b01, // 0x2c strb r3, [r0], #1
            0xd1fa, // 0x30 bne 0x28
            0x4770, // 0x32 bx lr
        ]);
        code.extend_from_slice(&[0; 4]);
        let bytes = elf(
            &code,
            &[
                Sym::function("poll_forever", 0x00, 0x14),
                Sym::function("poll_counted", 0x14, 0x14),
                Sym::function("copy", 0x28, 0x0c),
                Sym::data(0x04),
                Sym::code(0x0c),
            ],
        );
        Image::parse(&bytes).unwrap()
    }

    #[test]
    fn polls_without_a_counter_are_found_and_counted_ones_are_not() {
        let waits = scan(&image()).unwrap();
        let names: Vec<&str> = waits.iter().map(|w| w.function.as_str()).collect();
        assert_eq!(names, ["poll_forever"]);
        assert_eq!(waits[0].branch, 0x10);
        assert_eq!(waits[0].known(), None);
    }

    #[test]
    fn a_listed_wait_is_excused_only_when_all_of_it_is_listed_code() {
        let list = [("stm32f1xx-hal-0.11.0/src/rcc.rs", "its flags are set first")];
        let hal = Wait {
            function: "freeze".into(),
            branch: 0,
            lines: vec!["/r/stm32f1xx-hal-0.11.0/src/rcc.rs:239".into()],
        };
        assert_eq!(hal.known_in(&list), Some("its flags are set first"));
        let mixed = Wait {
            lines: vec![
                "/r/stm32f1xx-hal-0.11.0/src/rcc.rs:239".into(),
                "/work/board.rs:3".into(),
            ],
            ..hal.clone()
        };
        assert!(mixed.known_in(&list).is_none());
        let unknown_place = Wait {
            lines: vec![],
            ..hal
        };
        assert!(unknown_place.known_in(&list).is_none());
    }
}
