//! Thumb-2 decoding with `yaxpeax-arm` (ARMv7-M: Cortex-M3 and M4), and what the analyses ask of an
//! instruction: where control goes, which registers it writes, what memory it touches.
//!
//! `yaxpeax-arm` decodes an instruction alone; the `IT` state (which following instructions are
//! conditional) is kept here. Data inside a function (literal pools and jump tables, marked by the
//! ELF's `$d` mapping symbols) is skipped, never decoded.
use yaxpeax_arch::{Decoder, LengthedInstruction, U8Reader};
use yaxpeax_arm::armv7::{ConditionCode, InstDecoder, Instruction, Reg};
pub use yaxpeax_arm::armv7::{Opcode, Operand};

use crate::Error;

/// One decoded instruction.
#[derive(Debug, Clone)]
pub struct Insn {
    /// Its address.
    pub addr: u64,
    /// Its length in bytes (2 or 4).
    pub len: u8,
    /// Its first (and for a 32-bit instruction second) halfword.
    pub raw: [u16; 2],
    /// The instruction as `yaxpeax-arm` decoded it.
    pub inst: Instruction,
    /// Whether it executes only under a condition: its own (`B<c>`, `CBZ`) or an `IT` block's.
    pub conditional: bool,
    /// A call of an `OUTLINED_FUNCTION_n` (LLVM's machine outliner, which follows no calling
    /// convention): the registers the callee writes, and the constants it leaves in them (its last
    /// write of the register an unconditional `MOV #c`). Filled in by [`crate::Image`].
    pub outlined: Option<Outlined>,
}

/// What a call of an outlined function does to the registers ([`Insn::outlined`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Outlined {
    pub writes: u16,
    pub constants: Vec<(u8, u32)>,
}

/// Where control goes after an instruction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// To the next instruction.
    Next,
    /// A direct branch (`B`, `B<c>`, `CBZ`, `CBNZ`; conditional when [`Insn::conditional`]).
    Branch(u64),
    /// A direct call (`BL`): the callee, then the next instruction.
    Call(u64),
    /// A call through a register (`BLX Rm`).
    IndirectCall(u8),
    /// A return: `BX LR`, `POP {…, PC}`, `LDM SP!, {…, PC}`, `LDR PC, [SP], #4`.
    Return,
    /// A jump through a register that is not a return (`BX Rm`, `MOV PC, Rm`, a load of PC).
    IndirectJump,
    /// A table branch (`TBB`/`TBH [PC, Rm]`): the table follows the instruction.
    Table { halfwords: bool, index: u8 },
    /// A trap that ends the path (`UDF`, `BKPT` other than a semihosting call's).
    Stop,
}

/// Register numbers the analyses name.
pub const SP: u8 = 13;
pub const LR: u8 = 14;
pub const PC: u8 = 15;

/// Decodes `code` (loaded at `start`) as Thumb-2, skipping the `data` ranges.
pub fn decode(
    function: &str,
    start: u64,
    code: &[u8],
    data: &[(u64, u64)],
) -> Result<Vec<Insn>, Error> {
    let decoder = InstDecoder::default_thumb();
    let mut out = Vec::with_capacity(code.len() / 3);
    let mut offset = 0usize;
    // The IT block's remaining instructions.
    let mut it_left = 0u8;
    while offset + 1 < code.len() {
        let addr = start + offset as u64;
        if let Some(&(_, end)) = data.iter().find(|(from, to)| (*from..*to).contains(&addr)) {
            offset = usize::try_from(end - start).unwrap_or(code.len());
            it_left = 0;
            continue;
        }
        let mut reader = U8Reader::new(&code[offset..]);
        let half_at = |at: usize| -> Option<u16> {
            code.get(at..at + 2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
        };
        let inst = match decoder.decode(&mut reader) {
            Ok(inst) => inst,
            Err(_) => half_at(offset)
                .zip(half_at(offset + 2))
                .and_then(|(hw1, hw2)| floating_point(hw1, hw2))
                .ok_or_else(|| Error::Undecodable {
                    function: function.to_string(),
                    address: addr,
                })?,
        };
        let len: u32 = inst.len().to_const();
        let len = len as u8;
        let half = |at: usize| -> u16 {
            code.get(at..at + 2)
                .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
        };
        let raw = [half(offset), if len == 4 { half(offset + 2) } else { 0 }];
        // `CBZ`/`CBNZ` carry no condition code but branch only on their register's value.
        let conditional = it_left > 0
            || inst.condition != ConditionCode::AL
            || matches!(inst.opcode, Opcode::CBZ | Opcode::CBNZ);
        it_left = it_left.saturating_sub(1);
        if inst.opcode == Opcode::IT {
            // The mask's lowest set bit ends the block: 1 to 4 instructions.
            let mask = raw[0] & 0xf;
            it_left = 4 - mask.trailing_zeros().min(3) as u8;
        }
        out.push(Insn {
            addr,
            len,
            raw,
            inst,
            conditional,
            outlined: None,
        });
        offset += usize::from(len);
    }
    Ok(out)
}

/// The ARMv7-M floating-point instructions (coprocessors 10 and 11: the Cortex-M4F's FPU), which
/// `yaxpeax-arm` 0.5 does not decode in Thumb mode (`DecodeError::Incomplete`): classified by their
/// encoding class (ARMv7-M ARM, A6.3 "Floating-point instruction encoding") into the coprocessor
/// opcodes the rest of the analysis reads: loads and stores (`VLDR`, `VSTR`, `VLDM`, `VSTM`,
/// `VPUSH`, `VPOP`) as `LDC`/`STC` with their base register, register transfers (`VMOV`, `VMRS`,
/// `VMSR`) as `MRC`/`MCR`/`MRRC`/`MCRR` with the core registers they write, data processing as
/// `CDP`.
fn floating_point(hw1: u16, hw2: u16) -> Option<Instruction> {
    if hw2 & 0x0e00 != 0x0a00 || hw1 & 0xf000 != 0xe000 {
        return None;
    }
    let cp = ((hw2 >> 8) & 0xf) as u8;
    let rn = Reg::from_u8((hw1 & 0xf) as u8);
    let rt = ((hw2 >> 12) & 0xf) as u8;
    let mut operands = [Operand::Nothing; 4];
    let opcode = match hw1 & 0x0f00 {
        0x0c00 | 0x0d00 => {
            let load = hw1 & 0x10 != 0;
            if hw1 & 0x01e0 == 0x0040 {
                // 64-bit transfers between core and FP registers (VMOV two registers).
                if load {
                    let rt2 = (hw1 & 0xf) as u8;
                    operands[0] = Operand::Reg(Reg::from_u8(rt));
                    operands[1] = Operand::Reg(Reg::from_u8(rt2));
                    Opcode::MRRC(cp, 0, false)
                } else {
                    Opcode::MCRR(cp, 0, false)
                }
            } else {
                let (p, u, w) = (hw1 & 0x100 != 0, hw1 & 0x80 != 0, hw1 & 0x20 != 0);
                operands[0] = if p && !w {
                    Operand::RegDerefPreindexOffset(rn, (hw2 & 0xff) * 4, u, false)
                } else {
                    Operand::RegWBack(rn, w)
                };
                if load {
                    Opcode::LDC(cp, false)
                } else {
                    Opcode::STC(cp, false)
                }
            }
        }
        0x0e00 if hw2 & 0x10 != 0 => {
            if hw1 & 0x10 != 0 {
                // To a core register; Rt = 15 is `VMRS APSR_nzcv, FPSCR` (the flags).
                if rt != 15 {
                    operands[0] = Operand::Reg(Reg::from_u8(rt));
                }
                Opcode::MRC(cp, 0, 0, false)
            } else {
                Opcode::MCR(cp, 0, 0, false)
            }
        }
        0x0e00 => Opcode::CDP(cp, 0, 0, false),
        _ => return None,
    };
    Some(Instruction {
        condition: ConditionCode::AL,
        opcode,
        operands,
        s: false,
        wide: true,
        thumb_w: false,
        thumb: true,
    })
}

fn reg(r: &Reg) -> u8 {
    r.number()
}

impl Insn {
    /// The address of the next instruction.
    pub fn next(&self) -> u64 {
        self.addr + u64::from(self.len)
    }

    /// The target of a direct branch or call.
    pub fn direct_target(&self) -> Option<u64> {
        match self.inst.opcode {
            Opcode::B | Opcode::BL | Opcode::CBZ | Opcode::CBNZ => {}
            _ => return None,
        }
        // `yaxpeax-arm` gives the offset in halfwords from PC (the address + 4), but for the 16-bit
        // `CBZ`, `CBNZ` and `B<c>` (T1) from the address + 2 (it adds one halfword to their
        // offsets).
        let short = self.len == 2
            && (matches!(self.inst.opcode, Opcode::CBZ | Opcode::CBNZ)
                || self.inst.condition != ConditionCode::AL);
        let from = if short { 2 } else { 4 };
        self.inst.operands.iter().find_map(|o| match o {
            Operand::BranchThumbOffset(halfwords) => Some(
                self.addr
                    .wrapping_add(from)
                    .wrapping_add_signed(i64::from(*halfwords) * 2),
            ),
            _ => None,
        })
    }

    /// Whether it is a semihosting call: `BKPT #0xAB` (Thumb encoding `0xBEAB`).
    pub fn is_semihosting(&self) -> bool {
        self.inst.opcode == Opcode::BKPT && self.len == 2 && self.raw[0] == 0xbeab
    }

    /// Where control goes after it.
    pub fn flow(&self) -> Flow {
        let ops = &self.inst.operands;
        match self.inst.opcode {
            Opcode::B | Opcode::CBZ | Opcode::CBNZ => self
                .direct_target()
                .map_or(Flow::IndirectJump, Flow::Branch),
            Opcode::BL => self.direct_target().map_or(Flow::IndirectJump, Flow::Call),
            Opcode::BLX => match ops[0] {
                Operand::Reg(r) => Flow::IndirectCall(reg(&r)),
                // BLX to an immediate switches to ARM state, which a Cortex-M cannot execute.
                _ => Flow::Stop,
            },
            Opcode::BX => match ops[0] {
                Operand::Reg(r) if reg(&r) == LR => Flow::Return,
                _ => Flow::IndirectJump,
            },
            Opcode::TBB | Opcode::TBH => Flow::Table {
                halfwords: self.raw[1] & 0x10 != 0,
                index: (self.raw[1] & 0xf) as u8,
            },
            // A semihosting call (`BKPT #0xAB`, the ARMv7-M semihosting specification): the
            // debugger or QEMU performs it and the program goes on after it, its result in r0
            // (the QEMU builds' console and trace writes). Any other breakpoint stops the core.
            Opcode::BKPT if self.is_semihosting() => Flow::Next,
            Opcode::UDF | Opcode::BKPT => Flow::Stop,
            Opcode::POP => match ops[0] {
                Operand::RegList(list) if list & (1 << PC) != 0 => Flow::Return,
                Operand::Reg(r) if reg(&r) == PC => Flow::Return,
                _ => Flow::Next,
            },
            Opcode::LDM(..) => {
                let base_sp =
                    matches!(ops[0], Operand::RegWBack(r, _) | Operand::Reg(r) if reg(&r) == SP);
                match ops[1] {
                    Operand::RegList(list) if list & (1 << PC) != 0 => {
                        if base_sp {
                            Flow::Return
                        } else {
                            Flow::IndirectJump
                        }
                    }
                    _ => Flow::Next,
                }
            }
            _ => {
                if self.writes().contains(PC) {
                    let from_stack =
                        matches!(self.inst.opcode, Opcode::LDR) && self.memory_base() == Some(SP);
                    if from_stack {
                        Flow::Return
                    } else {
                        Flow::IndirectJump
                    }
                } else {
                    Flow::Next
                }
            }
        }
    }

    /// The base register of its memory operand, if it has one.
    pub fn memory_base(&self) -> Option<u8> {
        self.inst.operands.iter().find_map(|o| match o {
            Operand::RegDeref(r)
            | Operand::RegDerefPostindexRegShift(r, ..)
            | Operand::RegDerefPreindexRegShift(r, ..)
            | Operand::RegDerefPostindexOffset(r, ..)
            | Operand::RegDerefPreindexOffset(r, ..)
            | Operand::RegDerefPostindexReg(r, ..)
            | Operand::RegDerefPreindexReg(r, ..) => Some(reg(r)),
            _ => None,
        })
    }

    /// The base register of a load or store multiple that writes its base back (`STMDB SP!`).
    pub fn memory_base_wback(&self) -> Option<u8> {
        self.inst.operands.iter().find_map(|o| match o {
            Operand::RegWBack(r, true) => Some(reg(r)),
            _ => None,
        })
    }

    /// The words a `VPUSH` (a `VSTMDB SP!`) stores, when it is one.
    pub fn vpush_words(&self) -> Option<u32> {
        // VSTMDB SP!, {list}: 1110 1101 0D10 1101 | Vd 101x imm8.
        (self.len == 4 && self.raw[0] & 0xffbf == 0xed2d && self.raw[1] & 0x0e00 == 0x0a00)
            .then_some(u32::from(self.raw[1] & 0xff))
    }

    /// The immediate offset of its memory operand (signed), if it has one and it is pre-indexed.
    pub fn memory_offset(&self) -> Option<i64> {
        self.inst.operands.iter().find_map(|o| match o {
            Operand::RegDeref(_) => Some(0),
            Operand::RegDerefPreindexOffset(_, offset, add, _) => Some(if *add {
                i64::from(*offset)
            } else {
                -i64::from(*offset)
            }),
            _ => None,
        })
    }

    /// The address a PC-relative load reads (`LDR Rt, [PC, #imm]`: from the word-aligned PC).
    pub fn literal_address(&self) -> Option<u64> {
        if self.memory_base() != Some(PC) {
            return None;
        }
        let offset = self.memory_offset()?;
        Some(((self.addr + 4) & !3).wrapping_add_signed(offset))
    }

    /// The immediate of a data-processing instruction, if its last operand is one.
    pub fn immediate(&self) -> Option<u32> {
        self.inst.operands.iter().rev().find_map(|o| match o {
            Operand::Imm12(v) => Some(u32::from(*v)),
            Operand::Imm32(v) => Some(*v),
            _ => None,
        })
    }

    /// The registers among its operands that are plain registers, in order.
    pub fn registers(&self) -> Vec<u8> {
        self.inst
            .operands
            .iter()
            .filter_map(|o| match o {
                Operand::Reg(r) => Some(reg(r)),
                _ => None,
            })
            .collect()
    }

    /// Whether it reads memory.
    pub fn is_load(&self) -> bool {
        use Opcode::*;
        matches!(
            self.inst.opcode,
            LDR | LDRB
                | LDRH
                | LDRSB
                | LDRSH
                | LDRD
                | LDREX
                | LDREXB
                | LDREXH
                | LDRT
                | LDRBT
                | LDRHT
                | LDRSBT
                | LDRSHT
                | LDM(..)
                | POP
                | TBB
                | TBH
        ) || self.is_coprocessor_load()
    }

    /// Whether it writes memory.
    pub fn is_store(&self) -> bool {
        use Opcode::*;
        matches!(
            self.inst.opcode,
            STR | STRB
                | STRH
                | STRD
                | STREX
                | STREXB
                | STREXH
                | STRT
                | STRBT
                | STRHT
                | STM(..)
                | PUSH
        ) || self.is_coprocessor_store()
    }

    /// How many bytes it moves to or from memory as a load or store of the core's registers
    /// (`STRB` 1, `STRH` 2, `STR` 4, `STRD` 8, `STM`/`PUSH`/`LDM`/`POP` 4 per register; 0 for
    /// anything else, a floating-point transfer included).
    pub fn bytes_moved(&self) -> u64 {
        use Opcode::*;
        match self.inst.opcode {
            STRB | STRBT | STREXB | LDRB | LDRSB | LDRBT | LDRSBT | LDREXB => 1,
            STRH | STRHT | STREXH | LDRH | LDRSH | LDRHT | LDRSHT | LDREXH => 2,
            STR | STRT | STREX | LDR | LDRT | LDREX => 4,
            STRD | LDRD => 8,
            STM(..) | PUSH | LDM(..) | POP => {
                4 * u64::from(self.register_list().unwrap_or(0).count_ones())
            }
            _ => 0,
        }
    }

    /// A floating-point load (`VLDR`, `VLDM`, `VPOP`): an `LDC` to coprocessor 10 or 11.
    pub fn is_coprocessor_load(&self) -> bool {
        matches!(self.inst.opcode, Opcode::LDC(c, _) | Opcode::LDCL(c, _) if c == 10 || c == 11)
    }

    /// A floating-point store (`VSTR`, `VSTM`, `VPUSH`): an `STC` to coprocessor 10 or 11.
    pub fn is_coprocessor_store(&self) -> bool {
        matches!(self.inst.opcode, Opcode::STC(c, _) | Opcode::STCL(c, _) if c == 10 || c == 11)
    }

    /// The registers it transfers in a list (`PUSH`, `POP`, `LDM`, `STM`).
    pub fn register_list(&self) -> Option<u16> {
        self.inst.operands.iter().find_map(|o| match o {
            Operand::RegList(list) => Some(*list),
            _ => None,
        })
    }

    /// The registers it writes (a conservative set: the destination of anything that has one,
    /// loaded lists, written-back bases, `LR` for a call).
    pub fn writes(&self) -> Regs {
        use Opcode::*;
        let ops = &self.inst.operands;
        let mut out = Regs::default();
        for o in ops {
            match o {
                Operand::RegWBack(r, true)
                | Operand::RegDerefPostindexRegShift(r, _, _, true)
                | Operand::RegDerefPreindexRegShift(r, _, _, true)
                | Operand::RegDerefPostindexOffset(r, _, _, true)
                | Operand::RegDerefPreindexOffset(r, _, _, true)
                | Operand::RegDerefPostindexReg(r, _, _, true)
                | Operand::RegDerefPreindexReg(r, _, _, true) => out.insert(reg(r)),
                Operand::RegDerefPostindexOffset(r, ..)
                | Operand::RegDerefPostindexReg(r, ..)
                | Operand::RegDerefPostindexRegShift(r, ..) => out.insert(reg(r)),
                _ => {}
            }
        }
        match self.inst.opcode {
            MCR(..) | MCRR(..) | CDP(..) | STC(..) | STCL(..) => {}
            CMP | CMN | TST | TEQ | IT | B | CBZ | CBNZ | NOP | DMB | DSB | ISB | WFI | WFE
            | SEV | YIELD | CPS(_) | CPS_modeonly | UDF | SVC | MSR | TBB | TBH | PLD | PLI
            | CLREX | HINT | DBG => {}
            // A semihosting call's result is in r0.
            BKPT => {
                if self.is_semihosting() {
                    out.insert(0);
                }
            }
            STR | STRB | STRH | STRD | STRT | STRBT | STRHT | STM(..) => {}
            PUSH => out.insert(SP),
            STREX | STREXB | STREXH => {
                if let Some(Operand::Reg(r)) = ops.first() {
                    out.insert(reg(r));
                }
            }
            POP => {
                out.insert(SP);
                match ops[0] {
                    Operand::RegList(list) => out.0 |= list,
                    Operand::Reg(r) => out.insert(reg(&r)),
                    _ => {}
                }
            }
            LDM(..) => {
                if let Some(list) = self.register_list() {
                    out.0 |= list;
                }
            }
            BL | BLX => {
                out.insert(LR);
                // The callee may clobber r0-r3 and r12 (AAPCS); an outlined one whatever it writes.
                out.0 |= 0b1_0000_0000_1111;
                if let Some(outlined) = &self.outlined {
                    out.0 |= outlined.writes;
                }
            }
            BX => {}
            // Two destinations: RdLo and RdHi (the long multiplies and accumulates).
            LDRD | UMULL | SMULL | UMLAL | SMLAL | SMLAL_halfword(..) | SMLALD(_) | SMLSLD(_)
            | UMAAL | MRRC(..) => {
                for r in self.registers().into_iter().take(2) {
                    out.insert(r);
                }
            }
            _ => {
                if let Some(Operand::Reg(r)) = ops.first() {
                    out.insert(reg(r));
                }
            }
        }
        out
    }
}

/// A set of core registers r0-r15.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Regs(pub u16);

impl Regs {
    /// Adds a register.
    pub fn insert(&mut self, r: u8) {
        if r < 16 {
            self.0 |= 1 << r;
        }
    }
    /// Whether the set holds `r`.
    pub fn contains(self, r: u8) -> bool {
        r < 16 && self.0 & (1 << r) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thumb;

    #[test]
    fn a_long_accumulate_writes_both_halves() {
        // ARMv7-M ARM A7.7.139-142: RdLo (hw2 15:12) and RdHi (11:8) are both written.
        let code = thumb(&[
            0xfbc2, 0x0183, // smlalbb r0, r1, r2, r3
            0xfbc2, 0x45c3, // smlald r4, r5, r2, r3
            0xfbd2, 0x67c3, // smlsld r6, r7, r2, r3
            0xfbc2, 0x8903, // smlal r8, r9, r2, r3
        ]);
        let insns = decode("f", 0, &code, &[]).expect("decodes");
        let written: Vec<u16> = insns.iter().map(|i| i.writes().0).collect();
        assert_eq!(written, [0b11, 0b11 << 4, 0b11 << 6, 0b11 << 8]);
    }
}
