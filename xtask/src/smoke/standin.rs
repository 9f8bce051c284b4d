//! The stand-in for AMiRo-BLT the production image boots behind, and the flash image it hands over
//! to.
use anyhow::{ensure, Context, Result};

use super::{RAM_BASE, STANDIN_BASE};

/// Where the stand-in's callbacks start (one `b .` each), right behind its vector table.
const CALLBACK_CODE: u32 = STANDIN_BASE + 8;
/// Where its start-up code starts.
pub const STARTUP_CODE: u32 = STANDIN_BASE + 0x14;
/// AMiRo-BLT's callback table (`amiro_firmware::bootloader::CALLBACK_TABLE`).
const CALLBACK_TABLE: u32 = STANDIN_BASE + 0x1C0;
/// The callbacks in table order (`amiro_firmware::bootloader::Callback`, offsets 16..32).
pub const CALLBACKS: [&str; 5] = [
    "hibernate",
    "deep sleep",
    "transportation",
    "restart",
    "handle a shutdown request",
];

/// The stand-in for AMiRo-BLT: a two-word vector table (stack in low RAM, reset vector to the
/// start-up code); one `b .` per callback; the start-up code — for each `(address, value)` of
/// `environment` `ldr r2, =address; ldr r3, =value; str r3, [r2]`, then AMiRo-BLT's hand-over
/// `ldr r0, =app; ldr r1, =VTOR; str r0, [r1]; ldr r1, [r0]; msr msp, r1; ldr r1, [r0, #4];
/// bx r1` — and its literals; and at [`CALLBACK_TABLE`] the table the application looks for
/// (magic "A-BL", three version words, the five callbacks, seven reserved words), so a hand-over
/// parks the CPU where the run sees which callback the board chose.
pub fn standin(app_base: u32, environment: &[(u32, u32)]) -> Vec<u8> {
    const VTOR: u32 = 0xE000_ED08;
    // Instructions: a plain halfword, or `ldr rt, [pc, #…]` of a literal.
    enum Op {
        Half(u16),
        Literal(u16, u32),
    }
    let mut ops = Vec::new();
    for &(address, value) in environment {
        ops.extend([
            Op::Literal(2, address),
            Op::Literal(3, value),
            Op::Half(0x6013),
        ]); // str r3, [r2]
    }
    ops.extend([
        Op::Literal(0, app_base),
        Op::Literal(1, VTOR),
        Op::Half(0x6008), // str r0, [r1]
        Op::Half(0x6801), // ldr r1, [r0]: the application's initial stack pointer
        Op::Half(0xF381), // msr msp, r1
        Op::Half(0x8808),
        Op::Half(0x6841), // ldr r1, [r0, #4]: its reset vector
        Op::Half(0x4708), // bx r1
    ]);
    let start = (STARTUP_CODE - STANDIN_BASE) as usize;
    let pool = (start + 2 * ops.len()).next_multiple_of(4);
    let mut out = Vec::with_capacity(0x200);
    out.extend_from_slice(&(RAM_BASE + 0x1000).to_le_bytes());
    out.extend_from_slice(&(STARTUP_CODE + 1).to_le_bytes());
    for _ in CALLBACKS {
        out.extend_from_slice(&0xE7FEu16.to_le_bytes()); // b .
    }
    out.resize(start, 0xFF);
    let mut literals = Vec::new();
    for (i, op) in ops.iter().enumerate() {
        let half = match *op {
            Op::Half(half) => half,
            Op::Literal(rt, value) => {
                let at = pool + 4 * literals.len();
                literals.push(value);
                let pc = (start + 2 * i + 4) & !3;
                0x4800 | rt << 8 | ((at - pc) / 4) as u16
            }
        };
        out.extend_from_slice(&half.to_le_bytes());
    }
    out.resize(pool, 0xFF);
    for value in literals {
        out.extend_from_slice(&value.to_le_bytes());
    }
    assert!(
        out.len() <= (CALLBACK_TABLE - STANDIN_BASE) as usize,
        "stand-in too long"
    );
    out.resize((CALLBACK_TABLE - STANDIN_BASE) as usize, 0xFF);
    out.extend_from_slice(&0x412D_424Cu32.to_le_bytes());
    out.extend_from_slice(&[0; 12]);
    for i in 0..CALLBACKS.len() as u32 {
        out.extend_from_slice(&(CALLBACK_CODE + 2 * i + 1).to_le_bytes());
    }
    out.extend_from_slice(&[0; 28]);
    out
}

/// Which callback of the stand-in the CPU sits in, if any.
pub fn callback_at(pc: u32) -> Option<&'static str> {
    let offset = (pc & !1).checked_sub(CALLBACK_CODE)?;
    CALLBACKS.get((offset / 2) as usize).copied()
}

/// The flash contents from `base` on: every load segment at its address, gaps erased (0xFF).
pub fn flash_image(segments: &[(u64, Vec<u8>)], base: u64) -> Result<Vec<u8>> {
    let end = segments
        .iter()
        .map(|(at, bytes)| at + bytes.len() as u64)
        .max()
        .context("no load segments")?;
    ensure!(end > base, "the image ends before its base {base:#x}");
    let mut image = vec![0xFF; (end - base) as usize];
    for (at, bytes) in segments {
        ensure!(
            *at >= base,
            "a load segment at {at:#x} lies below the application base {base:#x}"
        );
        let from = (at - base) as usize;
        image[from..from + bytes.len()].copy_from_slice(bytes);
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_standin_loads_vtor_stack_and_reset_vector_of_the_application() {
        let code = standin(0x0800_6000, &[(0x4001_1008, 0x4100)]);
        let word = |i: usize| u32::from_le_bytes(code[i..i + 4].try_into().unwrap());
        let half = |i: usize| u16::from_le_bytes(code[i..i + 2].try_into().unwrap());
        assert_eq!(word(0), 0x2000_1000);
        assert_eq!(
            word(4),
            STARTUP_CODE + 1,
            "reset vector: the start-up code, Thumb"
        );
        // Decode the start-up code: each `ldr rt, [pc, #…]` loads its literal into a register.
        let mut regs = [0u32; 4];
        let mut stores = Vec::new();
        let mut at = (STARTUP_CODE - STANDIN_BASE) as usize;
        loop {
            let insn = half(at);
            match insn {
                0x4800..=0x4BFF => {
                    let pc = (at + 4) & !3;
                    regs[usize::from(insn >> 8 & 7)] = word(pc + 4 * usize::from(insn & 0xFF));
                }
                0x6013 => stores.push((regs[2], regs[3])),
                0x6008 => stores.push((regs[1], regs[0])),
                0x4708 => break,
                _ => {}
            }
            at += 2;
        }
        assert_eq!(stores, [(0x4001_1008, 0x4100), (0xE000_ED08, 0x0800_6000)]);
        assert_eq!(
            regs[0], 0x0800_6000,
            "MSP and the reset vector come from the application"
        );
        assert_eq!(
            word(0x1C0),
            0x412D_424C,
            "the callback table's magic at 0x080001C0"
        );
        for (i, name) in CALLBACKS.iter().enumerate() {
            let pointer = word(0x1C0 + 16 + 4 * i);
            assert_eq!(pointer & 1, 1, "Thumb");
            assert_eq!(callback_at(pointer), Some(*name));
            let at = (pointer & !1) as usize - 0x0800_0000;
            assert_eq!(&code[at..at + 2], &[0xFE, 0xE7], "b .");
        }
        assert_eq!(callback_at(STARTUP_CODE), None);
    }

    #[test]
    fn the_flash_image_places_segments_and_erases_gaps() {
        let image = flash_image(&[(0x100, vec![1, 2]), (0x104, vec![3])], 0x100).unwrap();
        assert_eq!(image, vec![1, 2, 0xFF, 0xFF, 3]);
        assert!(flash_image(&[(0xF0, vec![1])], 0x100).is_err());
    }
}
