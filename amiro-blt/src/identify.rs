//! Which robot is on the cable, learnt without asking any module: the main board's own device id
//! read out of its bootloader's code.
//!
//! AMiRo-BLT has no command that reports a board's id, and a CONNECT to an id no module owns
//! hangs the main board's CAN gateway until reset, so ids cannot be tried. The board on the
//! serial port always answers CONNECT(0) itself, and UPLOAD reads any address, its own
//! bootloader included. That code compares CONNECT and CAN ids with the board's
//! `BOOT_COM_DEVICE_ID` (`xcp.c`, `can.c`); the 1-1 and 1-2 bootloaders of a board differ in that
//! constant (and their pins) only. How the compiler holds it depends on its bits: DiWheelDrive's
//! 0x0100010x fits no Thumb-2 immediate and is loaded from a literal pool (or built by
//! MOVW/MOVT); PowerManagement's 0x01010101 is a modified immediate and is compared with
//! `CMP.W Rn, #0x01010101`, and 0x01010102 with `CMN.W Rn, #0xFEFEFEFE` (its negation), with no
//! data word anywhere. [`ids_in_code`] finds which of the main boards' known ids occur in any of
//! these forms (the `thumb` module decodes the instructions); exactly one must, else the
//! robot's revision is unknown and nothing may be erased.
use crate::target::IdSet;
use thumb::Insn;

mod thumb;

/// Where the scan reads: the first 24 KiB of flash, bootloader on every board (the F103's whole
/// bootloader, the F405's sectors 0 and 1 in part), never an application.
pub const BOOTLOADER_SCAN: (u32, u32) = (0x0800_0000, 0x0800_6000);

/// A board that can be the main board (on the serial port), with the robot its id names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MainBoardId {
    /// The board's name, as in [`crate::target::robot`].
    pub board: &'static str,
    /// Its 32-bit device id.
    pub id: u32,
    /// The ids the rest of that robot answers to.
    pub robot: IdSet,
}

/// Every main board's id (DiWheelDrive's and PowerManagement's, revisions 1-1 and 1-2).
pub const MAIN_BOARD_IDS: [MainBoardId; 4] = [
    MainBoardId {
        board: "diwheeldrive",
        id: 0x0100_0101,
        robot: IdSet::Rev11,
    },
    MainBoardId {
        board: "diwheeldrive",
        id: 0x0100_0102,
        robot: IdSet::Rev12,
    },
    MainBoardId {
        board: "powermgmt",
        id: 0x0101_0101,
        robot: IdSet::Rev11,
    },
    MainBoardId {
        board: "powermgmt",
        id: 0x0101_0102,
        robot: IdSet::Rev12,
    },
];

/// What reading the main board's bootloader showed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identification {
    /// The known main-board ids found in its code (empty or several: unknown).
    pub found: Vec<MainBoardId>,
}

impl Identification {
    /// The main board, when exactly one known id was found.
    pub fn main_board(&self) -> Option<MainBoardId> {
        match self.found[..] {
            [one] => Some(one),
            _ => None,
        }
    }

    /// For messages: `diwheeldrive 0x01000102`, or what was found instead.
    pub fn describe(&self) -> String {
        match &self.found[..] {
            [] => "none of the known main-board ids".into(),
            found => found
                .iter()
                .map(|m| format!("{} {:#010x}", m.board, m.id))
                .collect::<Vec<_>>()
                .join(" and "),
        }
    }
}

/// The main boards' ids that `code` (read from `BOOTLOADER_SCAN.0`) loads or compares with, in
/// [`MAIN_BOARD_IDS`] order: see `constants_in` for the forms read.
pub fn ids_in_code(code: &[u8]) -> Identification {
    let constants = constants_in(code);
    Identification {
        found: MAIN_BOARD_IDS
            .iter()
            .copied()
            .filter(|m| constants.contains(&m.id))
            .collect(),
    }
}

/// How far (in bytes past the instruction that sets the low half) a MOVT may complete it: an
/// instruction scheduler may put a few instructions between the two.
const MOVT_REACH: usize = 16;

/// How many instructions after a MOV.W/MVN.W may hold the CMP that uses the moved register.
const COMPARE_REACH: usize = 4;

/// Every 32-bit constant `code` loads or compares with, in the forms GCC emits for
/// `x == CONSTANT` on Cortex-M:
///
/// - a literal-pool word, 4-byte aligned (LDR literal reads only aligned words);
/// - the low half into Rd by MOVW, or by MOV.W/MVN.W when it is a modified immediate (GCC's
///   choice for 0x0102: `mov.w r3, #0x102`), then MOVT Rd (within [`MOVT_REACH`] bytes);
/// - CMP.W Rn, #c (the constant `c`) or CMN.W Rn, #c (the constant `-c`), `c` a modified
///   immediate (ThumbExpandImm: an 8-bit value, 0x00XY00XY, 0xXY00XY00, 0xXYXYXYXY or a rotated
///   8-bit value): how a constant of those shapes, or whose negation has one, is compared;
/// - MOV.W Rd, #c (the constant `c`) or MVN.W Rd, #c (`!c`) when one of the next
///   [`COMPARE_REACH`] instructions, read in sequence from it, is a CMP of two registers with Rd
///   one of them (no check that Rd is not written in between: the ids are specific enough).
///
/// Instructions are read at every halfword-aligned offset (Thumb code is halfword-aligned, and
/// `code` starts at the flash base), never at odd ones.
fn constants_in(code: &[u8]) -> Vec<u32> {
    let mut found: Vec<u32> = code
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    for at in (0..code.len()).step_by(2) {
        let Some((insn, len)) = thumb::decode_at(code, at) else {
            continue;
        };
        let low_half = match insn {
            Insn::Movw { rd, imm } => Some((rd, imm)),
            Insn::MoveImmediate { rd, value } => u16::try_from(value).ok().map(|low| (rd, low)),
            _ => None,
        };
        if let Some((rd, low)) = low_half {
            if let Some(high) = movt_after(code, at, rd) {
                found.push(u32::from(high) << 16 | u32::from(low));
            }
        }
        match insn {
            Insn::CompareImmediate { value, .. } => found.push(value),
            Insn::MoveImmediate { rd, value } if compared_soon(code, at + len, rd) => {
                found.push(value)
            }
            _ => {}
        }
    }
    found.sort_unstable();
    found.dedup();
    found
}

/// The immediate of a MOVT into `rd` at a halfword offset within [`MOVT_REACH`] bytes after the
/// 32-bit instruction at `at`.
fn movt_after(code: &[u8], at: usize, rd: u8) -> Option<u16> {
    (at + 4..=at + MOVT_REACH)
        .step_by(2)
        .find_map(|next| match thumb::decode_at(code, next) {
            Some((Insn::Movt { rd: rd2, imm }, _)) if rd2 == rd => Some(imm),
            _ => None,
        })
}

/// Whether one of the [`COMPARE_REACH`] instructions from `at` on is a CMP with register `r`.
fn compared_soon(code: &[u8], mut at: usize, r: u8) -> bool {
    for _ in 0..COMPARE_REACH {
        match thumb::decode_at(code, at) {
            Some((Insn::CompareRegisters { rn, rm }, _)) if rn == r || rm == r => return true,
            Some((_, len)) => at += len,
            None => return false,
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn code_with(bytes: &[(usize, &[u8])]) -> Vec<u8> {
        let mut code = vec![0u8; 0x400];
        for (at, b) in bytes {
            code[*at..*at + b.len()].copy_from_slice(b);
        }
        code
    }

    #[test]
    fn a_literal_pool_word_names_the_main_board() {
        let code = code_with(&[(0x100, &0x0100_0101u32.to_le_bytes())]);
        let id = ids_in_code(&code).main_board().unwrap();
        assert_eq!((id.board, id.robot), ("diwheeldrive", IdSet::Rev11));
        // Unaligned, it is no literal.
        let code = code_with(&[(0x102, &0x0100_0101u32.to_le_bytes())]);
        assert_eq!(ids_in_code(&code).main_board(), None);
    }

    #[test]
    fn a_movw_movt_pair_names_the_main_board() {
        // MOVW r3, #0x0102; (one other instruction); MOVT r3, #0x0100.
        let pair = [
            0x40, 0xF2, 0x02, 0x13, 0x00, 0xBF, 0x00, 0xBF, 0xC0, 0xF2, 0x00, 0x13,
        ];
        let code = code_with(&[(0x202, &pair)]);
        let id = ids_in_code(&code).main_board().unwrap();
        assert_eq!((id.id, id.robot), (0x0100_0102, IdSet::Rev12));
        // The MOVT into another register does not complete it.
        let mut other = pair;
        other[11] = 0x12;
        assert!(ids_in_code(&code_with(&[(0x202, &other)])).found.is_empty());
    }

    /// `insns` (each one instruction's bytes) checked against a reference decoder's text, then
    /// placed one after the other from `at`.
    fn assembled(at: usize, insns: &[(&[u8], &str)]) -> Vec<u8> {
        use yaxpeax_arch::{Decoder, U8Reader};
        let mut code = vec![0u8; 0x3000];
        let mut next = at;
        for (bytes, text) in insns {
            let mut reader = U8Reader::new(bytes);
            let inst = yaxpeax_arm::armv7::InstDecoder::default_thumb()
                .decode(&mut reader)
                .unwrap();
            assert_eq!(inst.to_string().replace('#', ""), *text);
            code[next..next + bytes.len()].copy_from_slice(bytes);
            next += bytes.len();
        }
        code
    }

    #[test]
    fn powermanagements_compares_name_its_revision() {
        // As GCC 12.2 -O1 builds AMiRo-BLT's PowerManagement_1-1 and _1-2 (xcp.c's CONNECT and
        // can.c's receiver; no literal word, no MOVT): the same two sites in each.
        for (site_a, site_b, id, robot) in [
            (
                (&[0xB7, 0xF1, 0x01, 0x3F][..], "cmp.w r7, 0x1010101"),
                (&[0xB1, 0xF1, 0x01, 0x3F][..], "cmp.w r1, 0x1010101"),
                0x0101_0101,
                IdSet::Rev11,
            ),
            (
                (&[0x17, 0xF1, 0xFE, 0x3F][..], "cmn.w r7, 0xfefefefe"),
                (&[0x11, 0xF1, 0xFE, 0x3F][..], "cmn.w r1, 0xfefefefe"),
                0x0101_0102,
                IdSet::Rev12,
            ),
        ] {
            let mut code = assembled(0x232C, &[site_a]);
            code[0x2B84..0x2B88].copy_from_slice(site_b.0);
            let main = ids_in_code(&code).main_board().unwrap();
            assert_eq!((main.board, main.id, main.robot), ("powermgmt", id, robot));
            // Either site alone is enough; at an odd offset neither is an instruction.
            assert_eq!(ids_in_code(&assembled(0x100, &[site_b])).found, [main]);
            let mut odd = vec![0u8; 0x3000];
            odd[0x101..0x105].copy_from_slice(site_a.0);
            assert!(ids_in_code(&odd).found.is_empty());
        }
    }

    #[test]
    fn a_moved_constant_counts_when_a_compare_soon_uses_its_register() {
        let mov = (&[0x4F, 0xF0, 0x01, 0x33][..], "mov.w r3, 0x1010101");
        let mvn = (&[0x6F, 0xF0, 0xFE, 0x33][..], "mvn.w r3, 0xfefefefe");
        let nop = (&[0x00, 0xBF][..], "nop");
        let ldr = (&[0xD0, 0xF8, 0x04, 0x10][..], "ldr.w r1, [r0, 0x4]");
        let cmp_r0_r3 = (&[0x98, 0x42][..], "cmp r0, r3");
        let cmp_w_r3_r9 = (&[0xB3, 0xEB, 0x09, 0x0F][..], "cmp.w r3, sb");
        let cmp_r0_r2 = (&[0x90, 0x42][..], "cmp r0, r2");
        let pm_1_1 = |insns: &[(&[u8], &str)]| {
            ids_in_code(&assembled(0x800, insns))
                .main_board()
                .map(|m| (m.board, m.id))
        };
        let found = Some(("powermgmt", 0x0101_0101));
        assert_eq!(pm_1_1(&[mov, cmp_r0_r3]), found);
        assert_eq!(pm_1_1(&[mvn, ldr, nop, cmp_w_r3_r9]), found);
        // The fourth instruction after it is the last that counts.
        assert_eq!(pm_1_1(&[mov, nop, ldr, nop, cmp_r0_r3]), found);
        assert_eq!(pm_1_1(&[mov, nop, ldr, nop, nop, cmp_r0_r3]), None);
        // A compare of other registers, or none, leaves it a mere move.
        assert_eq!(pm_1_1(&[mov, cmp_r0_r2]), None);
        assert_eq!(pm_1_1(&[mvn, nop]), None);
    }

    #[test]
    fn the_callback_tables_unaligned_version_bytes_are_no_id() {
        // 0x080001C0 in every AMiRo-BLT image: magic `A-BL`, the bootloader's version (release
        // 1.1.5), SSSP's (1.1.0), GCC's (12.2.1). Bytes 0x1C9..0x1CD read 01 01 00 01, which is
        // DiWheelDrive 1-1's id, unaligned.
        let table = [
            0x4C, 0x42, 0x2D, 0x41, 0x05, 0x01, 0x01, 0x05, 0x01, 0x01, 0x01, 0x00, 0x01, 0x0C,
            0x02, 0x01,
        ];
        let code = code_with(&[(0x1C0, &table)]);
        assert_eq!(code[0x1C9..0x1CD], 0x0100_0101u32.to_le_bytes());
        assert!(ids_in_code(&code).found.is_empty());
        // So a PowerManagement 1-2 bootloader is PowerManagement 1-2, not also DiWheelDrive 1-1.
        let mut code = code;
        code[0x300..0x304].copy_from_slice(&[0x11, 0xF1, 0xFE, 0x3F]);
        let main = ids_in_code(&code).main_board().unwrap();
        assert_eq!((main.board, main.id), ("powermgmt", 0x0101_0102));
    }

    #[test]
    fn the_other_sign_or_revision_is_not_taken_for_an_id() {
        for (insns, what) in [
            // CMN with 0x01010101 compares with 0xFEFEFEFF; CMP with 0xFEFEFEFE with itself.
            (
                [(&[0x13, 0xF1, 0x01, 0x3F][..], "cmn.w r3, 0x1010101")],
                "cmn of the 1-1 id",
            ),
            (
                [(&[0xB3, 0xF1, 0xFE, 0x3F][..], "cmp.w r3, 0xfefefefe")],
                "cmp with the 1-2 id negated",
            ),
            // MVN of 0x01010101 is 0xFEFEFEFE.
            (
                [(&[0x6F, 0xF0, 0x01, 0x33][..], "mvn.w r3, 0x1010101")],
                "mvn of the 1-1 id",
            ),
        ] {
            let mut code = assembled(0x400, &insns);
            code[0x404..0x406].copy_from_slice(&[0x98, 0x42]); // cmp r0, r3
            assert!(ids_in_code(&code).found.is_empty(), "{what}");
        }
        // Both PowerManagement revisions' compares in one image: unknown, refused.
        let mut code = vec![0u8; 0x400];
        code[0x100..0x104].copy_from_slice(&[0xB7, 0xF1, 0x01, 0x3F]);
        code[0x200..0x204].copy_from_slice(&[0x17, 0xF1, 0xFE, 0x3F]);
        let seen = ids_in_code(&code);
        assert_eq!(seen.main_board(), None);
        assert_eq!(
            seen.describe(),
            "powermgmt 0x01010101 and powermgmt 0x01010102"
        );
    }

    #[test]
    fn a_low_half_moved_as_a_modified_immediate_completes_a_movt() {
        // DiWheelDrive 1-2 as GCC 12.2 -O1 -mslow-flash-data builds it (no literal pools):
        // 0x0102 is a modified immediate, so the low half is a MOV.W, not a MOVW.
        for (insns, id) in [
            (
                [
                    (&[0x4F, 0xF4, 0x81, 0x73][..], "mov.w r3, 0x102"),
                    (&[0xC0, 0xF2, 0x00, 0x13][..], "movt r3, 0x100"),
                ],
                0x0100_0102,
            ),
            (
                [
                    (&[0x4F, 0xF4, 0x81, 0x7E][..], "mov.w lr, 0x102"),
                    (&[0xC0, 0xF2, 0x00, 0x1E][..], "movt lr, 0x100"),
                ],
                0x0100_0102,
            ),
        ] {
            let main = ids_in_code(&assembled(0x1398, &insns))
                .main_board()
                .unwrap();
            assert_eq!((main.board, main.id), ("diwheeldrive", id));
        }
    }

    #[test]
    fn none_or_two_ids_leave_the_revision_unknown() {
        assert_eq!(ids_in_code(&[0u8; 64]).main_board(), None);
        let code = code_with(&[
            (0x100, &0x0100_0101u32.to_le_bytes()),
            (0x200, &0x0100_0102u32.to_le_bytes()),
        ]);
        let seen = ids_in_code(&code);
        assert_eq!(seen.main_board(), None);
        assert_eq!(
            seen.describe(),
            "diwheeldrive 0x01000101 and diwheeldrive 0x01000102"
        );
    }
}
