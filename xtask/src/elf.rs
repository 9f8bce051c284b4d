//! Reads a built firmware ELF: its size (text, data, bss) and the checks a robot needs before flashing
//! (architecture, float ABI, the AMiRo-BLT checksum slot left free).
use anyhow::{bail, Context, Result};
use object::elf::{EF_ARM_ABI_FLOAT_HARD, EM_ARM};
use object::{Object, ObjectSection, ObjectSymbol, SectionFlags, SectionKind};
use serde::Serialize;
use std::path::Path;

use crate::boards::Board;

/// Section sizes of one firmware image.
#[derive(Debug, Clone, Serialize)]
pub struct SizeReport {
    /// Board name.
    pub board: String,
    /// The board revision the image is for (`boards::Revision::name`; set by the build).
    pub revision: String,
    /// The image's ELF (a copy per revision, `target/firmware/<board>-<revision>.elf`; set by the build).
    pub elf: std::path::PathBuf,
    /// The AMiRo-BLT device id the image declares (its `AMIRO_DEVICE_ID` symbol), if it has one.
    pub device_id: Option<u32>,
    /// Code and read-only data in flash (vector table, .text, .rodata).
    pub text: u64,
    /// Initialised data (stored in flash, copied to RAM).
    pub data: u64,
    /// Zero-initialised and uninitialised RAM.
    pub bss: u64,
    /// Flash used: text + data.
    pub flash_used: u64,
    /// Flash available to the application behind the bootloader.
    pub flash_available: u64,
    /// Static RAM used: data + bss (the stack takes the rest of RAM).
    pub ram_used: u64,
    /// RAM of the chip.
    pub ram_available: u64,
    /// Address of the image's vector table.
    pub vector_table: u64,
    /// The project's flash budget for this board (`boards::Board::flash_budget`), for the firmware
    /// without the on-chip admission analysis.
    pub flash_budget: u64,
    /// Flash in named symbols of the on-chip admission analysis (`schedule_analysis::…`,
    /// `amiro_firmware::admission::…`, the admission task's state): a lower bound of its cost, since
    /// inlined code and anonymous constants (the robot table) are not attributed.
    pub analysis_symbols: u64,
    /// The budget that applies: `flash_budget`, plus the board's `admission_allowance` for an image
    /// with the admission analysis in it (≈ 18 KB of analysis code and a ≈ 2.2 KB robot table of
    /// 32-bit rows; its state is zero at reset, in `.bss`).
    pub flash_limit: u64,
}

/// Parses `elf`, checks it against `board` and returns its sizes.
pub fn inspect(board: &Board, elf: &Path, behind_bootloader: bool) -> Result<SizeReport> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file =
        object::File::parse(&*bytes).with_context(|| format!("parsing {}", elf.display()))?;
    let (machine, flags) = match file.flags() {
        object::FileFlags::Elf { e_flags, .. } => (file.architecture(), e_flags),
        _ => bail!("{} is not an ELF file", elf.display()),
    };
    if machine != object::Architecture::Arm {
        bail!(
            "{}: expected an ARM image, found {:?}",
            elf.display(),
            machine
        );
    }
    let _ = EM_ARM;
    let hard = flags & EF_ARM_ABI_FLOAT_HARD != 0;
    if hard != board.hard_float {
        bail!(
            "{}: float ABI is {} but {} needs {}",
            elf.display(),
            if hard { "hard" } else { "soft" },
            board.name,
            if board.hard_float { "hard" } else { "soft" }
        );
    }

    let mut report = SizeReport {
        board: board.name.to_string(),
        revision: String::new(),
        elf: elf.to_path_buf(),
        device_id: declared_device_id(&file),
        text: 0,
        data: 0,
        bss: 0,
        flash_used: 0,
        flash_available: 0,
        ram_used: 0,
        ram_available: board.ram_bytes,
        vector_table: 0,
        flash_budget: board.flash_budget,
        analysis_symbols: 0,
        flash_limit: board.flash_budget,
    };
    for symbol in file.symbols() {
        let name = symbol.name().unwrap_or("");
        if symbol.size() > 0
            && symbol.address() < 0x2000_0000
            && (name.contains("schedule_analysis") || name.contains("admission"))
        {
            report.analysis_symbols += symbol.size();
        }
    }
    if report.analysis_symbols > 0 {
        report.flash_limit += board.admission_allowance;
    }
    let mut vector_end = 0;
    let mut flash_sections = Vec::new();
    for section in file.sections() {
        let name = section.name().unwrap_or("");
        let alloc = match section.flags() {
            SectionFlags::Elf { sh_flags } => sh_flags & u64::from(object::elf::SHF_ALLOC) != 0,
            _ => false,
        };
        if !alloc || section.size() == 0 {
            continue;
        }
        let (start, end) = (section.address(), section.address() + section.size());
        if name == ".vector_table" {
            report.vector_table = start;
            vector_end = end;
        }
        match section.kind() {
            SectionKind::UninitializedData | SectionKind::UninitializedTls => {
                report.bss += section.size()
            }
            SectionKind::Data | SectionKind::Tls => report.data += section.size(),
            _ if name == ".data" => report.data += section.size(),
            _ if name == ".bss" || name == ".uninit" => report.bss += section.size(),
            _ => report.text += section.size(),
        }
        if start < 0x2000_0000 {
            flash_sections.push((name.to_string(), start, end));
        }
    }
    if behind_bootloader {
        check_bootloader_layout(board, (report.vector_table, vector_end), &flash_sections)
            .with_context(|| format!("{}", elf.display()))?;
        report.flash_available = board.flash_bytes - (board.app_base - 0x0800_0000);
    } else {
        report.flash_available = board.flash_bytes;
    }
    report.flash_used = report.text + report.data;
    report.ram_used = report.data + report.bss;
    Ok(report)
}

/// The section that holds the AMiRo-BLT checksum word (see the boards' `memory.x`).
pub const CHECKSUM_SECTION: &str = ".blt_checksum";

/// Checks what AMiRo-BLT needs of an image: the vector table at the application origin and ending
/// before the checksum slot, the slot held by exactly the 4-byte `.blt_checksum` section, and no
/// other section loaded into flash covering it.
pub fn check_bootloader_layout(
    board: &Board,
    vector: (u64, u64),
    flash_sections: &[(String, u64, u64)],
) -> Result<()> {
    let slot = board.app_base + board.checksum_slot;
    if vector.0 != board.app_base {
        bail!(
            "vector table at {:#010x}, but AMiRo-BLT starts the application at {:#010x}",
            vector.0,
            board.app_base
        );
    }
    if vector.1 > slot {
        bail!("vector table runs into the AMiRo-BLT checksum slot {slot:#010x}");
    }
    let mut slot_held = false;
    for (name, start, end) in flash_sections {
        if name == CHECKSUM_SECTION {
            if (*start, *end) != (slot, slot + 4) {
                bail!("{CHECKSUM_SECTION} at {start:#010x}..{end:#010x}, but the slot is {slot:#010x}..{:#010x}", slot + 4);
            }
            slot_held = true;
        } else if *start < slot + 4 && slot < *end {
            bail!("section {name} ({start:#010x}..{end:#010x}) covers the AMiRo-BLT checksum slot {slot:#010x}");
        }
    }
    if !slot_held {
        bail!("no {CHECKSUM_SECTION} section reserves the AMiRo-BLT checksum slot {slot:#010x}");
    }
    Ok(())
}

/// The word AMiRo-BLT expects in the slot: the first seven vector words plus it sum to zero.
pub fn checksum_word(vector_words: &[u32; 7]) -> u32 {
    0u32.wrapping_sub(
        vector_words
            .iter()
            .fold(0u32, |sum, w| sum.wrapping_add(*w)),
    )
}

/// Writes the checksum word into a copy of `elf` at `out`, so an image flashed directly (probe-rs,
/// without the bootloader's own programming) passes AMiRo-BLT's validity check.
pub fn write_checksum(elf: &Path, out: &Path) -> Result<u32> {
    let mut bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let (vector_offset, slot_offset) = {
        let file =
            object::File::parse(&*bytes).with_context(|| format!("parsing {}", elf.display()))?;
        let offset_of = |name: &str| -> Result<u64> {
            let section = file
                .section_by_name(name)
                .with_context(|| format!("{}: no {name} section", elf.display()))?;
            let (offset, size) = section
                .file_range()
                .with_context(|| format!("{}: {name} has no file contents", elf.display()))?;
            if name == CHECKSUM_SECTION && size != 4 {
                bail!("{}: {name} is {size} bytes, expected 4", elf.display());
            }
            Ok(offset)
        };
        (offset_of(".vector_table")?, offset_of(CHECKSUM_SECTION)?)
    };
    let mut words = [0u32; 7];
    for (i, w) in words.iter_mut().enumerate() {
        let at = (vector_offset as usize) + 4 * i;
        let chunk = bytes
            .get(at..at + 4)
            .context("vector table shorter than 7 words")?;
        *w = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
    }
    let checksum = checksum_word(&words);
    let slot = bytes
        .get_mut(slot_offset as usize..slot_offset as usize + 4)
        .context("checksum slot outside the file")?;
    slot.copy_from_slice(&checksum.to_le_bytes());
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(checksum)
}

// What a probe and the revision check read of an image: in the machine-code crate.
pub use machine_code::elf::{
    declared_device_id, device_id_of, load_segments, rtt_control_block, DEVICE_ID_SYMBOL,
};

/// Prints the size table.
pub fn print_table(reports: &[SizeReport]) {
    println!(
        "{:<14} {:<8} {:>8} {:>7} {:>7} {:>22} {:>20} {:>16} {:>12}",
        "board",
        "revision",
        "text",
        "data",
        "bss",
        "flash used",
        "static RAM used",
        "flash budget",
        "admission"
    );
    for r in reports {
        println!(
            "{:<14} {:<8} {:>8} {:>7} {:>7} {:>9} / {:>6} KiB {:>4.1}% {:>7} / {:>4} KiB {:>4.1}% {:>6} KiB {:<4} {:>12}",
            r.board,
            r.revision,
            r.text,
            r.data,
            r.bss,
            r.flash_used,
            r.flash_available / 1024,
            100.0 * r.flash_used as f64 / r.flash_available as f64,
            r.ram_used,
            r.ram_available / 1024,
            100.0 * r.ram_used as f64 / r.ram_available as f64,
            r.flash_limit / 1024,
            if r.flash_used <= r.flash_limit {
                "ok"
            } else {
                "OVER"
            },
            if r.analysis_symbols > 0 {
                format!("≥ {} B", r.analysis_symbols)
            } else {
                "none".to_string()
            },
        );
    }
    if reports.iter().any(|r| r.analysis_symbols > 0) {
        println!(
            "flash budget: the board's own budget, plus its allowance for the on-chip admission analysis where it is \
             built in (DiWheelDrive, LightRing: 28 KiB + 1 520 B; PowerManagement: 6 KiB + 1 520 B) (admission: bytes in its named \
             symbols, a lower bound)"
        );
    }
}

/// The boards whose flash exceeds their budget, as one message each.
pub fn over_budget(reports: &[SizeReport]) -> Vec<String> {
    reports
        .iter()
        .filter(|r| r.flash_used > r.flash_limit)
        .map(|r| {
            format!(
                "{} uses {} bytes of flash, {} over its {} KiB budget",
                r.board,
                r.flash_used,
                r.flash_used - r.flash_limit,
                r.flash_limit / 1024
            )
        })
        .collect()
}

/// The 52-byte header of a little-endian ARM ELF32 executable entered at 0x0800_6000, for tests: the program
/// and section header tables at `phoff` and `shoff`, `[phnum, shnum, shstrndx]`.
#[cfg(test)]
pub(crate) fn elf32_header(phoff: u32, shoff: u32, [phnum, shnum, shstrndx]: [u16; 3]) -> Vec<u8> {
    let mut out = vec![0x7f, b'E', b'L', b'F', 1, 1, 1];
    out.resize(16, 0);
    out.extend_from_slice(&2u16.to_le_bytes()); // e_type EXEC
    out.extend_from_slice(&40u16.to_le_bytes()); // e_machine ARM
    out.extend_from_slice(&1u32.to_le_bytes()); // e_version
    out.extend_from_slice(&0x0800_6000u32.to_le_bytes()); // e_entry
    out.extend_from_slice(&phoff.to_le_bytes());
    out.extend_from_slice(&shoff.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes()); // e_flags
                                                // ehsize, phentsize, phnum, shentsize, shnum, shstrndx
    for v in [52u16, 32, phnum, 40, shnum, shstrndx] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boards::BOARDS;

    fn sections(text_start: u64) -> Vec<(String, u64, u64)> {
        vec![
            (".vector_table".into(), 0x0800_6000, 0x0800_6130),
            (".blt_checksum".into(), 0x0800_6150, 0x0800_6154),
            (".text".into(), text_start, 0x0800_9000),
        ]
    }

    #[test]
    fn the_shipped_layout_leaves_the_slot_free() {
        let f103 = &BOARDS[0];
        assert!(
            check_bootloader_layout(f103, (0x0800_6000, 0x0800_6130), &sections(0x0800_6200))
                .is_ok()
        );
    }

    #[test]
    fn code_over_the_slot_is_refused() {
        let f103 = &BOARDS[0];
        // .text right behind the vector table (cortex-m-rt's default) runs over app + 0x150.
        let err = check_bootloader_layout(f103, (0x0800_6000, 0x0800_6130), &sections(0x0800_6130))
            .unwrap_err();
        assert!(
            err.to_string()
                .contains("covers the AMiRo-BLT checksum slot 0x08006150"),
            "{err}"
        );
    }

    #[test]
    fn a_wrong_origin_a_long_vector_table_or_a_missing_slot_is_refused() {
        let f405 = &BOARDS[1];
        let slot = vec![(".blt_checksum".to_string(), 0x0800_81AC, 0x0800_81B0)];
        assert!(check_bootloader_layout(f405, (0x0800_0000, 0x0800_0188), &slot).is_err());
        assert!(check_bootloader_layout(f405, (0x0800_8000, 0x0800_81B0), &slot).is_err());
        assert!(check_bootloader_layout(f405, (0x0800_8000, 0x0800_8188), &slot).is_ok());
        assert!(check_bootloader_layout(f405, (0x0800_8000, 0x0800_8188), &[]).is_err());
        let misplaced = vec![(".blt_checksum".to_string(), 0x0800_81A8, 0x0800_81AC)];
        assert!(check_bootloader_layout(f405, (0x0800_8000, 0x0800_8188), &misplaced).is_err());
    }

    #[test]
    fn checksum_makes_the_words_sum_to_zero() {
        let words = [
            0x2001_0000,
            0x0800_6201,
            0x0800_6301,
            0x0800_6401,
            0x0800_6301,
            0x0800_6301,
            0x0800_6301,
        ];
        let c = checksum_word(&words);
        assert_eq!(words.iter().fold(c, |s, w| s.wrapping_add(*w)), 0);
    }

    /// A minimal little-endian ELF32 with `segments` (load address, contents, file size); the
    /// symbol table is left out.
    fn elf32(segments: &[(u32, &[u8], bool)]) -> Vec<u8> {
        let phoff = 52u32;
        let data_at = phoff + 32 * segments.len() as u32;
        let mut out = elf32_header(phoff, 0, [segments.len() as u16, 0, 0]);
        let mut offset = data_at;
        for (paddr, contents, load) in segments {
            let len = contents.len() as u32;
            let p_type: u32 = if *load { 1 } else { 4 }; // PT_LOAD or PT_NOTE
                                                         // A RAM address as the virtual one: .data runs in RAM, is stored in flash.
            for v in [p_type, offset, 0x2000_0000, *paddr, len, len + 8, 6, 4] {
                out.extend_from_slice(&v.to_le_bytes());
            }
            offset += len;
        }
        for (_, contents, _) in segments {
            out.extend_from_slice(contents);
        }
        out
    }

    #[test]
    fn loadable_segments_at_their_load_addresses() {
        let image = elf32(&[
            (0x0800_6000, &[1, 2, 3, 4], true),
            (0x0800_9000, &[9, 9], false),
            (0x0800_7000, &[5, 6], true),
        ]);
        let segments = load_segments(&image).unwrap();
        assert_eq!(
            segments,
            vec![(0x0800_6000, vec![1, 2, 3, 4]), (0x0800_7000, vec![5, 6])]
        );
        assert_eq!(rtt_control_block(&image), None);
    }

    #[test]
    fn a_damaged_image_is_an_error_not_a_panic() {
        let image = elf32(&[(0x0800_6000, &[1, 2, 3, 4], true)]);
        for cut in [0, 10, 60, image.len() - 2] {
            assert!(load_segments(&image[..cut]).is_err(), "cut at {cut}");
        }
        assert!(load_segments(&elf32(&[(0x0800_6000, &[1], false)])).is_err());
    }
}
