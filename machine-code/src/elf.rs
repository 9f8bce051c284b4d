//! What a flasher and a trace reader need of an image besides its code: the loadable segments at
//! their load addresses, and named symbols (the RTT control block, the declared device id).
use std::path::Path;

use object::{Object, ObjectSection, ObjectSymbol};

use crate::Error;

/// The bytes a probe writes for an image: every loadable segment's file contents at its load
/// (physical) address, so initialised data goes to flash where the startup code copies it from.
pub fn load_segments(bytes: &[u8]) -> Result<Vec<(u64, Vec<u8>)>, Error> {
    use object::read::elf::{ElfFile32, FileHeader, ProgramHeader};
    let file = ElfFile32::<object::Endianness>::parse(bytes).map_err(|e| {
        Error::Malformed(format!(
            "not a 32-bit ELF image (a firmware build for the board's chip?): {e}"
        ))
    })?;
    let endian = file.endian();
    let header = file.elf_header();
    let mut out = Vec::new();
    for segment in header
        .program_headers(endian, bytes)
        .map_err(|e| Error::Malformed(format!("reading the ELF program headers: {e}")))?
    {
        if segment.p_type(endian) != object::elf::PT_LOAD || segment.p_filesz(endian) == 0 {
            continue;
        }
        let data = segment
            .data(endian, bytes)
            .map_err(|()| Error::Malformed("a loadable segment lies outside the file".into()))?;
        out.push((u64::from(segment.p_paddr(endian)), data.to_vec()));
    }
    if out.is_empty() {
        return Err(Error::Malformed(
            "the ELF image has no loadable contents".into(),
        ));
    }
    Ok(out)
}

/// The address of the RTT control block (`_SEGGER_RTT`) in an image, if it has one.
pub fn rtt_control_block(bytes: &[u8]) -> Option<u64> {
    let file = object::File::parse(bytes).ok()?;
    file.symbols()
        .find(|s| s.name() == Ok("_SEGGER_RTT") && !s.is_undefined())
        .map(|s| s.address())
}

/// The symbol an image declares its board revision with (its AMiRo-BLT device id, a `u32`).
pub const DEVICE_ID_SYMBOL: &str = "AMIRO_DEVICE_ID";

/// The device id an image declares in [`DEVICE_ID_SYMBOL`], read from its section data.
pub fn declared_device_id(file: &object::File<'_>) -> Option<u32> {
    let symbol = file
        .symbols()
        .find(|s| s.name() == Ok(DEVICE_ID_SYMBOL) && !s.is_undefined())?;
    let section = file.section_by_index(symbol.section_index()?).ok()?;
    let data = section.data().ok()?;
    let offset = usize::try_from(symbol.address().checked_sub(section.address())?).ok()?;
    let bytes: [u8; 4] = data.get(offset..offset + 4)?.try_into().ok()?;
    Some(u32::from_le_bytes(bytes))
}

/// The device id the ELF at `path` declares (see [`declared_device_id`]).
pub fn device_id_of(path: &Path) -> Result<Option<u32>, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    let file = object::File::parse(&*bytes).map_err(|e| Error::Malformed(e.to_string()))?;
    Ok(declared_device_id(&file))
}
