//! The few Thumb-2 (ARMv7-M) instructions through which compiled code holds a 32-bit constant,
//! decoded from the halfwords at one position: MOVW/MOVT with a 16-bit half, CMP/CMN/MOV/MVN
//! with a modified immediate, and the register compares that use a moved constant. Everything
//! else is only measured (16 or 32 bits), so a scan can step from one instruction to the next.
//!
//! Encodings from the ARMv7-M Architecture Reference Manual (DDI 0403E), §A5.3 and §A7.7:
//! MOVW T3, MOVT T1, CMP (immediate) T2, CMN (immediate) T1, MOV (immediate) T2, MVN (immediate)
//! T1, CMP (register) T1/T2/T3; ThumbExpandImm is §A5.3.2. Encodings the manual calls
//! UNPREDICTABLE (PC or SP where they are not allowed, a zero byte in a replicated pattern) are
//! no instruction a compiler emits and decode as [`Insn::Other`].

/// What one instruction does with a constant, as far as the id scan cares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Insn {
    /// `MOVW Rd, #imm16`: the low half of a constant.
    Movw {
        /// Destination register.
        rd: u8,
        /// The 16-bit immediate.
        imm: u16,
    },
    /// `MOVT Rd, #imm16`: the high half of a constant, low half kept.
    Movt {
        /// Destination register.
        rd: u8,
        /// The 16-bit immediate.
        imm: u16,
    },
    /// `CMP.W Rn, #c` or `CMN.W Rn, #c`: flags as for `Rn - value`, so `value` is the constant
    /// compared with (CMN adds its immediate: `value` is then the immediate negated).
    CompareImmediate {
        /// The register compared.
        rn: u8,
        /// The constant `Rn` is compared with.
        value: u32,
    },
    /// `MOV.W Rd, #c` or `MVN.W Rd, #c`: `Rd = value` (MVN's immediate inverted).
    MoveImmediate {
        /// Destination register.
        rd: u8,
        /// The value `Rd` receives.
        value: u32,
    },
    /// `CMP Rn, Rm` (16-bit T1/T2, or unshifted CMP.W T3).
    CompareRegisters {
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
    },
    /// Any other instruction (or halfwords that are none).
    Other,
}

/// The instruction at byte offset `at` of `code` (which must be halfword-aligned for the result
/// to mean anything) and its length in bytes (2 or 4); `None` when `code` ends inside it.
pub(super) fn decode_at(code: &[u8], at: usize) -> Option<(Insn, usize)> {
    let half = |at: usize| -> Option<u16> {
        code.get(at..at.checked_add(2)?)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    };
    let first = half(at)?;
    if is_32_bit(first) {
        Some((decode_32(first, half(at + 2)?), 4))
    } else {
        Some((decode_16(first), 2))
    }
}

/// Whether a halfword starts a 32-bit instruction (its top five bits 0b11101, 0b11110 or 0b11111).
fn is_32_bit(first: u16) -> bool {
    first >> 11 >= 0b11101
}

fn decode_16(hw: u16) -> Insn {
    let low3 = |shift: u16| ((hw >> shift) & 7) as u8;
    if hw & 0xFFC0 == 0x4280 {
        // CMP (register) T1: 0100 0010 10 Rm Rn, low registers.
        return Insn::CompareRegisters {
            rn: low3(0),
            rm: low3(3),
        };
    }
    if hw & 0xFF00 == 0x4500 {
        // CMP (register) T2: 0100 0101 N Rm:4 Rn:3, at least one high register, no PC.
        let rn = ((hw >> 4) & 8) as u8 | low3(0);
        let rm = ((hw >> 3) & 0xF) as u8;
        if (rn < 8 && rm < 8) || rn == 15 || rm == 15 {
            return Insn::Other;
        }
        return Insn::CompareRegisters { rn, rm };
    }
    Insn::Other
}

fn decode_32(first: u16, second: u16) -> Insn {
    let rn = (first & 0xF) as u8;
    let rd = ((second >> 8) & 0xF) as u8;
    // Data processing (modified immediate): 11110 i 0 op:4 S Rn | 0 imm3 Rd imm8.
    if first & 0xFA00 == 0xF000 && second & 0x8000 == 0 {
        let op = (first >> 5) & 0xF;
        let s = first & 0x10 != 0;
        let Some(imm) = expand_imm((first >> 10) & 1, (second >> 12) & 7, second & 0xFF) else {
            return Insn::Other;
        };
        return match (op, s, rn, rd) {
            // CMP.W T2 (SUBS with Rd = PC) and CMN.W T1 (ADDS with Rd = PC).
            (0b1101, true, 0..=14, 15) => Insn::CompareImmediate { rn, value: imm },
            (0b1000, true, 0..=14, 15) => Insn::CompareImmediate {
                rn,
                value: imm.wrapping_neg(),
            },
            // MOV.W T2 (ORR with Rn = PC) and MVN.W T1 (ORN with Rn = PC); Rd neither SP nor PC.
            (0b0010, _, 15, rd) if rd != 13 && rd != 15 => Insn::MoveImmediate { rd, value: imm },
            (0b0011, _, 15, rd) if rd != 13 && rd != 15 => Insn::MoveImmediate { rd, value: !imm },
            _ => Insn::Other,
        };
    }
    // Plain binary immediate, MOVW T3 / MOVT T1: 11110 i 10 o 1 0 0 imm4 | 0 imm3 Rd imm8.
    if first & 0xFB70 == 0xF240 && second & 0x8000 == 0 && rd != 13 && rd != 15 {
        let imm = (first & 0xF) << 12 | ((first >> 10) & 1) << 11 | ((second >> 12) & 7) << 8;
        let imm = imm | (second & 0xFF);
        return if first & 0x0080 == 0 {
            Insn::Movw { rd, imm }
        } else {
            Insn::Movt { rd, imm }
        };
    }
    // CMP.W (register) T3 without a shift: 1110 1011 1011 Rn | 0 000 1111 00 00 Rm.
    if first & 0xFFF0 == 0xEBB0 && second & 0xFFF0 == 0x0F00 {
        let rm = (second & 0xF) as u8;
        if rn == 15 || rm == 13 || rm == 15 {
            return Insn::Other;
        }
        return Insn::CompareRegisters { rn, rm };
    }
    Insn::Other
}

/// ThumbExpandImm of `i:imm3:imm8`: an 8-bit value, one of the byte patterns 0x00XY00XY,
/// 0xXY00XY00, 0xXYXYXYXY, or `1bcdefgh` rotated right by 8 to 31. `None` where the manual calls
/// the encoding UNPREDICTABLE (a pattern of a zero byte).
pub(super) fn expand_imm(i: u16, imm3: u16, imm8: u16) -> Option<u32> {
    let imm8 = u32::from(imm8 & 0xFF);
    let top = (i & 1) << 3 | (imm3 & 7);
    if top & 0b1100 == 0 {
        let pattern = match top & 0b11 {
            0 => return Some(imm8),
            1 => imm8 << 16 | imm8,
            2 => imm8 << 24 | imm8 << 8,
            _ => imm8 * 0x0101_0101,
        };
        return (imm8 != 0).then_some(pattern);
    }
    let rotation = u32::from(top) << 1 | imm8 >> 7;
    Some((0x80 | (imm8 & 0x7F)).rotate_right(rotation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use yaxpeax_arch::{Decoder, U8Reader};
    use yaxpeax_arm::armv7::{
        InstDecoder, Instruction, Opcode, Operand, RegShiftStyle, ShiftStyle,
    };

    /// An independent decoding (yaxpeax-arm), for the encodings this module claims to read.
    fn reference(bytes: &[u8]) -> Option<Instruction> {
        let mut reader = U8Reader::new(bytes);
        InstDecoder::default_thumb().decode(&mut reader).ok()
    }

    /// A register operand, or a register shifted by nothing (how CMP.W T3 operands come).
    fn reg(operand: &Operand) -> Option<u8> {
        match operand {
            Operand::Reg(r) => Some(r.number()),
            Operand::RegShift(shift) => match shift.into_shift() {
                RegShiftStyle::RegImm(s) if s.stype() == ShiftStyle::LSL && s.imm() == 0 => {
                    Some(s.shiftee().number())
                }
                _ => None,
            },
            _ => None,
        }
    }

    fn imm(operand: &Operand) -> Option<u32> {
        match operand {
            Operand::Imm32(v) => Some(*v),
            _ => None,
        }
    }

    fn bytes(first: u16, second: u16) -> [u8; 4] {
        let [a, b] = first.to_le_bytes();
        let [c, d] = second.to_le_bytes();
        [a, b, c, d]
    }

    #[test]
    fn every_modified_immediate_compare_and_move_agrees_with_a_reference_decoder() {
        // All 4096 immediates of CMP.W/CMN.W/MOV.W/MVN.W, in a low and a high register.
        let mut checked = 0;
        for imm12 in 0u16..4096 {
            let (i, imm3, imm8) = (imm12 >> 11, (imm12 >> 8) & 7, imm12 & 0xFF);
            for r in [3u16, 11] {
                let imm_bits = i << 10;
                let second_cmp = imm3 << 12 | 0x0F00 | imm8;
                let second_mov = imm3 << 12 | r << 8 | imm8;
                for (first, second) in [
                    (0xF1B0 | imm_bits | r, second_cmp),
                    (0xF110 | imm_bits | r, second_cmp),
                    (0xF04F | imm_bits, second_mov),
                    (0xF06F | imm_bits, second_mov),
                ] {
                    let code = bytes(first, second);
                    let (ours, len) = decode_at(&code, 0).unwrap();
                    assert_eq!(len, 4);
                    if expand_imm(i, imm3, imm8).is_none() {
                        assert_eq!(ours, Insn::Other, "{code:02x?}");
                        continue;
                    }
                    let r = r as u8;
                    let inst = reference(&code).unwrap_or_else(|| panic!("{code:02x?}"));
                    let ops = inst.operands;
                    let expected = match inst.opcode {
                        Opcode::CMP => Insn::CompareImmediate {
                            rn: reg(&ops[0]).unwrap(),
                            value: imm(&ops[1]).unwrap(),
                        },
                        Opcode::CMN => Insn::CompareImmediate {
                            rn: reg(&ops[0]).unwrap(),
                            value: imm(&ops[1]).unwrap().wrapping_neg(),
                        },
                        Opcode::MOV => Insn::MoveImmediate {
                            rd: reg(&ops[0]).unwrap(),
                            value: imm(&ops[1]).unwrap(),
                        },
                        Opcode::MVN => Insn::MoveImmediate {
                            rd: reg(&ops[0]).unwrap(),
                            value: !imm(&ops[1]).unwrap(),
                        },
                        other => panic!("{code:02x?} decodes as {other:?}"),
                    };
                    assert_eq!(ours, expected, "{code:02x?}: {inst}");
                    assert!(matches!(
                        ours,
                        Insn::CompareImmediate { rn, .. } | Insn::MoveImmediate { rd: rn, .. }
                            if rn == r
                    ));
                    checked += 1;
                }
            }
        }
        // 4096 immediates less the three zero-byte patterns (UNPREDICTABLE), 8 forms each.
        assert_eq!(checked, 4093 * 8);
    }

    #[test]
    fn the_compares_powermanagement_is_built_with_decode_as_its_ids() {
        // cmp.w r3, #0x01010101 (PowerManagement 1-1) and cmn.w r2, #0xfefefefe (1-2:
        // -0x01010102), as GCC emits them.
        for (code, text, rn, value) in [
            (
                [0xB3, 0xF1, 0x01, 0x3F],
                "cmp.w r3, 0x1010101",
                3,
                0x0101_0101,
            ),
            (
                [0x12, 0xF1, 0xFE, 0x3F],
                "cmn.w r2, 0xfefefefe",
                2,
                0x0101_0102,
            ),
        ] {
            let inst = reference(&code).unwrap();
            assert_eq!(inst.to_string().replace('#', ""), text);
            assert_eq!(
                decode_at(&code, 0),
                Some((Insn::CompareImmediate { rn, value }, 4))
            );
        }
    }

    #[test]
    fn register_compares_and_movw_movt_agree_with_a_reference_decoder() {
        for (code, ours) in [
            // cmp r0, r3 (T1); cmp r8, r3 (T2); cmp.w r1, r12 (T3).
            (vec![0x98, 0x42], Insn::CompareRegisters { rn: 0, rm: 3 }),
            (vec![0x98, 0x45], Insn::CompareRegisters { rn: 8, rm: 3 }),
            (
                vec![0xB1, 0xEB, 0x0C, 0x0F],
                Insn::CompareRegisters { rn: 1, rm: 12 },
            ),
            // movw r3, #0x0102; movt r3, #0x0100; movw r0, #0xffff.
            (
                vec![0x40, 0xF2, 0x02, 0x13],
                Insn::Movw { rd: 3, imm: 0x0102 },
            ),
            (
                vec![0xC0, 0xF2, 0x00, 0x13],
                Insn::Movt { rd: 3, imm: 0x0100 },
            ),
            (
                vec![0x4F, 0xF6, 0xFF, 0x70],
                Insn::Movw { rd: 0, imm: 0xFFFF },
            ),
        ] {
            let inst = reference(&code).unwrap();
            let ops = inst.operands;
            let theirs = match inst.opcode {
                Opcode::CMP => Insn::CompareRegisters {
                    rn: reg(&ops[0]).unwrap(),
                    rm: reg(&ops[1]).unwrap(),
                },
                // yaxpeax-arm names MOVW `mov` (with its 16-bit immediate).
                Opcode::MOV | Opcode::MOVT => {
                    let rd = reg(&ops[0]).unwrap();
                    let Operand::Imm32(imm) = ops[1] else {
                        panic!("{inst}")
                    };
                    if inst.opcode == Opcode::MOV {
                        Insn::Movw {
                            rd,
                            imm: imm as u16,
                        }
                    } else {
                        Insn::Movt {
                            rd,
                            imm: imm as u16,
                        }
                    }
                }
                other => panic!("{code:02x?} decodes as {other:?}"),
            };
            assert_eq!(theirs, ours, "{inst}");
            assert_eq!(decode_at(&code, 0), Some((ours, code.len())), "{inst}");
        }
        // A shifted CMP.W (cmp.w r1, r2, lsl #1) compares another value.
        let shifted = [0xB1, 0xEB, 0x42, 0x0F];
        assert!(reference(&shifted).is_some());
        assert_eq!(decode_at(&shifted, 0), Some((Insn::Other, 4)));
    }

    #[test]
    fn an_instruction_cut_off_by_the_end_of_the_code_is_none() {
        assert_eq!(decode_at(&[0xB3, 0xF1, 0x01], 0), None);
        assert_eq!(decode_at(&[0xB3], 0), None);
        assert_eq!(decode_at(&[0x00, 0xBF], 0), Some((Insn::Other, 2)));
    }
}
