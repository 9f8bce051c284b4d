//! The boards AMiRo-BLT flashes: device ids, chips and the application region of each.
use std::fmt;

/// The microcontroller of a board, as far as flashing cares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Chip {
    /// STM32F103xE (DiWheelDrive, LightRing): 512 KiB flash, 64 KiB RAM.
    Stm32F103xE,
    /// STM32F405xG (PowerManagement): 1 MiB flash, 128 KiB SRAM and 64 KiB CCM.
    Stm32F405xG,
}

impl Chip {
    /// Whether `sp` can be an initial stack pointer on this chip (the top of a RAM region at
    /// most). A bootloader's first vector word that fails this was linked for another chip.
    pub fn accepts_stack_pointer(self, sp: u32) -> bool {
        match self {
            Chip::Stm32F103xE => (0x2000_0004..=0x2001_0000).contains(&sp),
            Chip::Stm32F405xG => {
                (0x2000_0004..=0x2002_0000).contains(&sp)
                    || (0x1000_0004..=0x1001_0000).contains(&sp)
            }
        }
    }
}

impl fmt::Display for Chip {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Chip::Stm32F103xE => "STM32F103xE",
            Chip::Stm32F405xG => "STM32F405xG",
        })
    }
}

/// One board as the flashing session addresses it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    /// Board name (the firmware crate's name).
    pub name: String,
    /// The id CONNECT selects it with.
    pub device_id: u32,
    /// Its chip.
    pub chip: Chip,
    /// Where AMiRo-BLT starts the application; nothing below is ever erased or written.
    pub app_origin: u32,
    /// End of flash (exclusive).
    pub flash_end: u32,
    /// Offset from `app_origin` of the word the bootloader writes its checksum into.
    pub checksum_offset: u32,
}

/// Which device ids the robot's bootloaders answer to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdSet {
    /// Revision 1-2 boards (the default; their bootloaders know no legacy ids).
    Rev12,
    /// Revision 1-1 DiWheelDrive and PowerManagement with a 1-0 LightRing.
    Rev11,
    /// The one-byte legacy ids (1, 2, 3) that 1-0 and 1-1 bootloaders also accept.
    Legacy,
}

impl IdSet {
    /// Parses `1-2`, `1-1` or `legacy`.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "1-2" => Some(IdSet::Rev12),
            "1-1" => Some(IdSet::Rev11),
            "legacy" => Some(IdSet::Legacy),
            _ => None,
        }
    }
}

/// The three base boards with the ids of `ids`.
pub fn robot(ids: IdSet) -> [Target; 3] {
    let (dwd, pm, lr) = match ids {
        IdSet::Rev12 => (0x0100_0102, 0x0101_0102, 0x017F_0102),
        IdSet::Rev11 => (0x0100_0101, 0x0101_0101, 0x017F_0100),
        IdSet::Legacy => (1, 2, 3),
    };
    [
        Target {
            name: "diwheeldrive".into(),
            device_id: dwd,
            chip: Chip::Stm32F103xE,
            app_origin: 0x0800_6000,
            flash_end: 0x0808_0000,
            checksum_offset: 0x150,
        },
        Target {
            name: "powermgmt".into(),
            device_id: pm,
            chip: Chip::Stm32F405xG,
            app_origin: 0x0800_8000,
            flash_end: 0x0810_0000,
            checksum_offset: 0x1AC,
        },
        Target {
            name: "lightring".into(),
            device_id: lr,
            chip: Chip::Stm32F103xE,
            app_origin: 0x0800_6000,
            flash_end: 0x0808_0000,
            checksum_offset: 0x150,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ids_match_the_bootloaders_module_table() {
        let r = robot(IdSet::Rev12);
        assert_eq!(
            r.iter().map(|t| t.device_id).collect::<Vec<_>>(),
            [0x0100_0102, 0x0101_0102, 0x017F_0102]
        );
        assert_eq!(robot(IdSet::Legacy)[2].device_id, 3);
        assert_eq!(IdSet::parse("1-1"), Some(IdSet::Rev11));
        assert_eq!(IdSet::parse("2"), None);
    }

    #[test]
    fn a_stack_pointer_beyond_64_kib_proves_the_f405() {
        assert!(Chip::Stm32F103xE.accepts_stack_pointer(0x2001_0000));
        assert!(!Chip::Stm32F103xE.accepts_stack_pointer(0x2002_0000));
        assert!(Chip::Stm32F405xG.accepts_stack_pointer(0x2002_0000));
        assert!(!Chip::Stm32F405xG.accepts_stack_pointer(0xFFFF_FFFF));
    }
}
