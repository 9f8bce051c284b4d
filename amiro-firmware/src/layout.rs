//! Where a firmware image lives: the AMiRo-BLT layout of each chip family, and the linker memory
//! map every board's build script writes from it (one scheme for all boards).
//!
//! Facts from `shared/reference/amiro-boards.md` §1–§2: AMiRo-BLT owns the first 24 KiB (F103) or
//! 32 KiB (F405) of flash, starts the application right after it, and keeps its validity checksum
//! in the word at app + 0x150 (F103) / app + 0x1AC (F405), an unused vector slot.
use core::fmt::{self, Write};

/// The chip family of a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// STM32F103xE (DiWheelDrive, LightRing): 512 KiB flash, 64 KiB RAM.
    F1,
    /// STM32F405xG (PowerManagement): 1 MiB flash, 128 KiB SRAM1+SRAM2.
    F4,
}

/// How an image is linked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// Behind AMiRo-BLT (the default: what runs on a robot).
    Bootloader,
    /// At the start of flash of a development chip without the bootloader.
    BareChip,
    /// For QEMU's STM32 machines (netduino2 / netduinoplus2: 1 MiB flash at 0x0800_0000).
    Qemu,
}

/// Start of flash on both families.
pub const FLASH_BASE: u32 = 0x0800_0000;
/// Start of SRAM on both families.
pub const RAM_BASE: u32 = 0x2000_0000;
/// Where cortex-m-rt places code behind the vector table (`_stext`), past the checksum slot.
pub const TEXT_OFFSET: u32 = 0x200;

impl Family {
    /// The bytes AMiRo-BLT owns at the start of flash.
    pub const fn bootloader_bytes(self) -> u32 {
        match self {
            Family::F1 => 24 * 1024,
            Family::F4 => 32 * 1024,
        }
    }

    /// Where AMiRo-BLT starts the application.
    pub const fn app_base(self) -> u32 {
        FLASH_BASE + self.bootloader_bytes()
    }

    /// Offset from [`Family::app_base`] of the word AMiRo-BLT writes its checksum into.
    pub const fn checksum_slot(self) -> u32 {
        match self {
            Family::F1 => 0x150,
            Family::F4 => 0x1AC,
        }
    }

    /// Flash of the chip.
    pub const fn flash_bytes(self) -> u32 {
        match self {
            Family::F1 => 512 * 1024,
            Family::F4 => 1024 * 1024,
        }
    }

    /// RAM the firmware links into (SRAM1+SRAM2 on the F405; its CCM is not used).
    pub const fn ram_bytes(self) -> u32 {
        match self {
            Family::F1 => 64 * 1024,
            Family::F4 => 128 * 1024,
        }
    }

    /// The family of a Rust target triple (`thumbv7m…` → F1, `thumbv7em…` → F4).
    pub fn of_target(triple: &str) -> Option<Family> {
        if triple.starts_with("thumbv7em") {
            Some(Family::F4)
        } else if triple.starts_with("thumbv7m") {
            Some(Family::F1)
        } else {
            None
        }
    }
}

/// A memory map to link against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryMap {
    /// Start of the image (its vector table).
    pub flash_origin: u32,
    /// Bytes of flash the image may use.
    pub flash_bytes: u32,
    /// Bytes of RAM.
    pub ram_bytes: u32,
    /// Offset of the AMiRo-BLT checksum slot from the origin, when linked behind the bootloader.
    pub checksum_slot: Option<u32>,
}

impl MemoryMap {
    /// The map of `family` linked as `link`.
    pub const fn new(family: Family, link: Link) -> Self {
        match link {
            Link::Bootloader => Self {
                flash_origin: family.app_base(),
                flash_bytes: family.flash_bytes() - family.bootloader_bytes(),
                ram_bytes: family.ram_bytes(),
                checksum_slot: Some(family.checksum_slot()),
            },
            Link::BareChip => Self {
                flash_origin: FLASH_BASE,
                flash_bytes: family.flash_bytes(),
                ram_bytes: family.ram_bytes(),
                checksum_slot: None,
            },
            // Both QEMU machines have 1 MiB of flash; RAM stays the real board's.
            Link::Qemu => Self {
                flash_origin: FLASH_BASE,
                flash_bytes: 1024 * 1024,
                ram_bytes: family.ram_bytes(),
                checksum_slot: None,
            },
        }
    }

    /// Writes the `memory.x` cortex-m-rt links with.
    pub fn write_memory_x(&self, out: &mut impl Write) -> fmt::Result {
        writeln!(
            out,
            "/* Written by amiro-firmware's board build script (layout.rs). */"
        )?;
        writeln!(out, "MEMORY")?;
        writeln!(out, "{{")?;
        writeln!(
            out,
            "  FLASH : ORIGIN = {:#010x}, LENGTH = {}K",
            self.flash_origin,
            self.flash_bytes / 1024
        )?;
        writeln!(
            out,
            "  RAM   : ORIGIN = {:#010x}, LENGTH = {}K",
            RAM_BASE,
            self.ram_bytes / 1024
        )?;
        writeln!(out, "}}")?;
        if let Some(slot) = self.checksum_slot {
            // Code starts past the slot, and the slot holds only the reserved checksum word.
            writeln!(out, "_stext = ORIGIN(FLASH) + {TEXT_OFFSET:#x};")?;
            writeln!(out, "SECTIONS")?;
            writeln!(out, "{{")?;
            writeln!(out, "  .blt_checksum ORIGIN(FLASH) + {slot:#x} :")?;
            writeln!(out, "  {{")?;
            writeln!(out, "    KEEP(*(.blt_checksum));")?;
            writeln!(out, "  }} > FLASH")?;
            writeln!(out, "}} INSERT AFTER .vector_table;")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bootloader_layouts_match_the_reference() {
        let f1 = MemoryMap::new(Family::F1, Link::Bootloader);
        assert_eq!((f1.flash_origin, f1.flash_bytes), (0x0800_6000, 488 * 1024));
        assert_eq!(f1.checksum_slot, Some(0x150));
        let f4 = MemoryMap::new(Family::F4, Link::Bootloader);
        assert_eq!((f4.flash_origin, f4.flash_bytes), (0x0800_8000, 992 * 1024));
        assert_eq!(f4.checksum_slot, Some(0x1AC));
        assert_eq!(
            MemoryMap::new(Family::F4, Link::BareChip).flash_origin,
            0x0800_0000
        );
    }

    #[test]
    fn memory_x_reserves_the_checksum_slot_only_behind_the_bootloader() {
        let mut text = String::new();
        MemoryMap::new(Family::F1, Link::Bootloader)
            .write_memory_x(&mut text)
            .unwrap();
        assert!(text.contains("ORIGIN = 0x08006000, LENGTH = 488K"));
        assert!(text.contains(".blt_checksum ORIGIN(FLASH) + 0x150"));
        assert!(text.contains("_stext = ORIGIN(FLASH) + 0x200;"));
        let mut bare = String::new();
        MemoryMap::new(Family::F1, Link::BareChip)
            .write_memory_x(&mut bare)
            .unwrap();
        assert!(!bare.contains("blt_checksum"));
        assert!(bare.contains("ORIGIN = 0x08000000, LENGTH = 512K"));
    }

    #[test]
    fn families_from_targets() {
        assert_eq!(Family::of_target("thumbv7m-none-eabi"), Some(Family::F1));
        assert_eq!(Family::of_target("thumbv7em-none-eabihf"), Some(Family::F4));
        assert_eq!(Family::of_target("x86_64-unknown-linux-gnu"), None);
    }
}
