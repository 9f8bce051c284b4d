//! Which robot is on the cable, learnt without asking any module: the main board's own device id
//! read out of its bootloader's code.
//!
//! AMiRo-BLT has no command that reports a board's id, and a CONNECT to an id no module owns
//! hangs the main board's CAN gateway until reset, so ids cannot be tried. The board on the
//! serial port always answers CONNECT(0) itself, and UPLOAD reads any address, its own
//! bootloader included. That code compares CONNECT and CAN ids with the board's
//! `BOOT_COM_DEVICE_ID` (`xcp.c`, `can.c`), a 32-bit constant no Thumb-2 immediate can hold, so
//! the compiler puts it in a literal pool or builds it with a MOVW/MOVT pair; the 1-1 and 1-2
//! bootloaders of a board differ in that constant (and their pins) only. [`ids_in_code`] finds
//! which of the main boards' known ids occur in either form; exactly one must, else the robot's
//! revision is unknown and nothing may be erased.
use crate::target::IdSet;

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

/// The main boards' ids that `code` (read from `BOOTLOADER_SCAN.0`) holds as a 4-byte aligned
/// literal word or as a MOVW/MOVT pair into one register, in [`MAIN_BOARD_IDS`] order.
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

/// Every 32-bit constant `code` can load: aligned words and MOVW/MOVT pairs (the MOVT within
/// the next 16 bytes, as an instruction scheduler may move it).
fn constants_in(code: &[u8]) -> Vec<u32> {
    let half = |at: usize| -> Option<u16> {
        code.get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    };
    let mut found: Vec<u32> = code
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    let mut at = 0;
    while at + 4 <= code.len() {
        if let Some((rd, low)) = mov_imm16(half(at), half(at + 2), 0xF240) {
            for next in (at + 4..=at + 16).step_by(2) {
                if let Some((rd2, high)) = mov_imm16(half(next), half(next + 2), 0xF2C0) {
                    if rd2 == rd {
                        found.push(u32::from(high) << 16 | u32::from(low));
                        break;
                    }
                }
            }
        }
        at += 2;
    }
    found.sort_unstable();
    found.dedup();
    found
}

/// Decodes a Thumb-2 MOVW (`op` 0xF240) or MOVT (0xF2C0) with a 16-bit immediate (ARMv7-M
/// encoding T3/T1: imm16 = imm4:i:imm3:imm8): its register and immediate.
fn mov_imm16(first: Option<u16>, second: Option<u16>, op: u16) -> Option<(u16, u16)> {
    let (first, second) = (first?, second?);
    if first & 0xFBF0 != op || second & 0x8000 != 0 {
        return None;
    }
    let imm4 = first & 0xF;
    let i = (first >> 10) & 1;
    let imm3 = (second >> 12) & 7;
    let imm8 = second & 0xFF;
    Some(((second >> 8) & 0xF, imm4 << 12 | i << 11 | imm3 << 8 | imm8))
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
