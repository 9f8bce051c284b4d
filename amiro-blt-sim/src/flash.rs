//! One board's flash as AMiRo-BLT programs it: protected bootloader sectors, 512-byte write
//! blocks buffered in RAM, the first block held back until programming ends and then written
//! with the checksum word.

/// Start of flash on both chips.
pub const FLASH_BASE: u32 = 0x0800_0000;
/// The bootloader's write-block size.
pub const BLOCK: u32 = 512;
/// Where the bootloader keeps its callback table, and its magic.
pub const CALLBACK_TABLE: u32 = 0x0800_01C0;
const MAGIC: u32 = 0x412D_424C;
/// The version fields after the magic (`amiroblt.h`, `Boot/main.c`): the bootloader's (release
/// 1.1.5), the shutdown protocol's (1.1.0) and the compiler's (GCC 12.2.1), four bytes each
/// (identifier, major, minor, patch). Bytes 9..13 of the table, 01 01 00 01, read as a word are
/// DiWheelDrive 1-1's device id, unaligned, in every board's bootloader.
const VERSIONS: [u8; 12] = [5, 1, 1, 5, 1, 1, 1, 0, 1, 12, 2, 1];

/// The two chips of the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimChip {
    /// STM32F103xE: 512 KiB in 2 KiB pages, bootloader 24 KiB, 64 KiB RAM.
    F103,
    /// STM32F405xG: 1 MiB in 16/64/128 KiB sectors, bootloader 32 KiB, 128 KiB RAM.
    F405,
}

impl SimChip {
    /// Where the application starts.
    pub fn app_origin(self) -> u32 {
        match self {
            SimChip::F103 => 0x0800_6000,
            SimChip::F405 => 0x0800_8000,
        }
    }
    /// Offset of the checksum word from the application origin.
    pub fn checksum_offset(self) -> u32 {
        match self {
            SimChip::F103 => 0x150,
            SimChip::F405 => 0x1AC,
        }
    }
    /// Flash size in bytes.
    pub fn flash_size(self) -> u32 {
        match self {
            SimChip::F103 => 512 * 1024,
            SimChip::F405 => 1024 * 1024,
        }
    }
    /// The bootloader's initial stack pointer (top of the chip's RAM).
    pub fn bootloader_stack(self) -> u32 {
        match self {
            SimChip::F103 => 0x2001_0000,
            SimChip::F405 => 0x2002_0000,
        }
    }
    /// The erase units as (start, length).
    pub fn sectors(self) -> Vec<(u32, u32)> {
        match self {
            SimChip::F103 => (0..256).map(|i| (FLASH_BASE + i * 2048, 2048)).collect(),
            SimChip::F405 => {
                let mut sizes = vec![16 * 1024; 4];
                sizes.push(64 * 1024);
                sizes.extend([128 * 1024; 7]);
                let mut at = FLASH_BASE;
                sizes
                    .into_iter()
                    .map(|len| {
                        let s = (at, len);
                        at += len;
                        s
                    })
                    .collect()
            }
        }
    }
    /// Typical erase time of one unit of `len` bytes (datasheet figures), in ns.
    pub fn erase_ns(self, len: u32) -> u64 {
        match (self, len) {
            (SimChip::F103, _) => 20_000_000,
            (SimChip::F405, 16384) => 250_000_000,
            (SimChip::F405, 65536) => 550_000_000,
            (SimChip::F405, _) => 1_000_000_000,
        }
    }
    /// Typical time to program one 512-byte block, in ns (F1: 256 half-words at 52 µs; F4:
    /// 128 words at 16 µs).
    pub fn block_program_ns(self) -> u64 {
        match self {
            SimChip::F103 => 256 * 52_000,
            SimChip::F405 => 128 * 16_000,
        }
    }
}

/// Why a flash operation failed (the bootloader answers all of them with ERR_GENERIC).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FlashError {
    /// Below the application origin: the bootloader's own sectors.
    Protected(u32),
    /// Beyond the end of flash.
    OutOfFlash(u32),
    /// A write onto flash that is not erased (and differs).
    NotErased(u32),
}

/// A board's flash memory with the bootloader's write buffers.
#[derive(Debug, Clone)]
pub struct Flash {
    chip: SimChip,
    mem: Vec<u8>,
    boot_block: Option<Vec<u8>>,
    block: Option<(u32, Vec<u8>)>,
    /// Time the last operation took, in ns (when costs are simulated).
    pub last_cost_ns: u64,
    /// Erase operations that touched the bootloader region (must stay 0).
    pub protected_hits: u32,
    /// Erase operations asked for (PROGRAM_CLEAR), refused ones included.
    pub erases: u32,
}

impl Flash {
    /// Flash with a bootloader installed (vector table, callback table, code) and the
    /// application region erased.
    pub fn new(chip: SimChip) -> Self {
        let size = chip.flash_size() as usize;
        let mut mem = vec![0xFF; size];
        let blt_len = (chip.app_origin() - FLASH_BASE) as usize;
        let mut x: u32 = 0x1234_5678;
        for b in mem[..blt_len].iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *b = x as u8;
        }
        mem[0..4].copy_from_slice(&chip.bootloader_stack().to_le_bytes());
        mem[4..8].copy_from_slice(&(FLASH_BASE + 0x1E1).to_le_bytes());
        let t = (CALLBACK_TABLE - FLASH_BASE) as usize;
        mem[t..t + 4].copy_from_slice(&MAGIC.to_le_bytes());
        mem[t + 4..t + 16].copy_from_slice(&VERSIONS);
        Flash {
            chip,
            mem,
            boot_block: None,
            block: None,
            last_cost_ns: 0,
            protected_hits: 0,
            erases: 0,
        }
    }

    /// The chip.
    pub fn chip(&self) -> SimChip {
        self.chip
    }

    /// Flash contents from `start` to `end` (no write buffers).
    pub fn bytes(&self, start: u32, end: u32) -> &[u8] {
        &self.mem[(start - FLASH_BASE) as usize..(end - FLASH_BASE) as usize]
    }

    /// What a CPU read of `len` bytes at `address` returns (zeros outside flash).
    pub fn read(&self, address: u32, len: usize) -> Vec<u8> {
        (0..len as u32)
            .map(|i| {
                let a = address.wrapping_add(i);
                a.checked_sub(FLASH_BASE)
                    .and_then(|o| self.mem.get(o as usize).copied())
                    .unwrap_or(0)
            })
            .collect()
    }

    fn end(&self) -> u32 {
        FLASH_BASE + self.chip.flash_size()
    }

    /// Forgets the RAM write buffers (a reset).
    pub fn reset_buffers(&mut self) {
        self.boot_block = None;
        self.block = None;
    }

    /// Erases every unit overlapping `[address, address + len)`; refuses the bootloader's.
    pub fn erase(&mut self, address: u32, len: u32) -> Result<(), FlashError> {
        self.last_cost_ns = 0;
        self.erases += 1;
        if len == 0 {
            return Ok(());
        }
        let end = address.saturating_add(len);
        if address < self.chip.app_origin() {
            self.protected_hits += 1;
            return Err(FlashError::Protected(address));
        }
        if end > self.end() {
            return Err(FlashError::OutOfFlash(end));
        }
        for (start, size) in self.chip.sectors() {
            if start < end && address < start + size {
                if start < self.chip.app_origin() {
                    self.protected_hits += 1;
                    return Err(FlashError::Protected(start));
                }
                let o = (start - FLASH_BASE) as usize;
                self.mem[o..o + size as usize].fill(0xFF);
                self.last_cost_ns += self.chip.erase_ns(size);
            }
        }
        Ok(())
    }

    /// Adds bytes to the write buffers; a block is programmed when a write moves to another.
    pub fn write(&mut self, address: u32, data: &[u8]) -> Result<(), FlashError> {
        self.last_cost_ns = 0;
        let end = address.saturating_add(data.len() as u32);
        if address < self.chip.app_origin() {
            return Err(FlashError::Protected(address));
        }
        if end > self.end() {
            return Err(FlashError::OutOfFlash(end));
        }
        let origin = self.chip.app_origin();
        for (i, &byte) in data.iter().enumerate() {
            let at = address + i as u32;
            let base = at & !(BLOCK - 1);
            let offset = (at - base) as usize;
            if base == origin {
                let init = self.bytes(base, base + BLOCK).to_vec();
                self.boot_block.get_or_insert(init)[offset] = byte;
                continue;
            }
            if self.block.as_ref().is_some_and(|(b, _)| *b != base) {
                self.flush_block()?;
            }
            if self.block.is_none() {
                self.block = Some((base, self.bytes(base, base + BLOCK).to_vec()));
            }
            if let Some((_, buf)) = self.block.as_mut() {
                buf[offset] = byte;
            }
        }
        Ok(())
    }

    fn flush_block(&mut self) -> Result<(), FlashError> {
        if let Some((base, data)) = self.block.take() {
            self.program(base, &data)?;
        }
        Ok(())
    }

    fn program(&mut self, base: u32, data: &[u8]) -> Result<(), FlashError> {
        self.last_cost_ns += self.chip.block_program_ns();
        let o = (base - FLASH_BASE) as usize;
        for (i, &b) in data.iter().enumerate() {
            let cell = &mut self.mem[o + i];
            // The bootloader verifies each written word: equal data passes, other data on
            // unerased flash does not.
            if *cell != b && *cell != 0xFF {
                return Err(FlashError::NotErased(base + i as u32));
            }
            *cell = b;
        }
        Ok(())
    }

    /// Ends programming: writes the checksum into the held first block and programs it, then
    /// the last open block.
    pub fn done(&mut self) -> Result<(), FlashError> {
        self.last_cost_ns = 0;
        if let Some(mut boot) = self.boot_block.take() {
            let word =
                |i: usize| u32::from_le_bytes([boot[i], boot[i + 1], boot[i + 2], boot[i + 3]]);
            let sum = (0..7).fold(0u32, |s, i| s.wrapping_add(word(4 * i)));
            let slot = self.chip.checksum_offset() as usize;
            boot[slot..slot + 4].copy_from_slice(&0u32.wrapping_sub(sum).to_le_bytes());
            let origin = self.chip.app_origin();
            let cost = self.last_cost_ns;
            self.program(origin, &boot)?;
            self.last_cost_ns += cost;
        }
        let cost = self.last_cost_ns;
        self.flush_block()?;
        self.last_cost_ns += cost;
        Ok(())
    }

    /// Whether the application's checksum verifies (what the bootloader checks before starting it).
    pub fn app_valid(&self) -> bool {
        let origin = self.chip.app_origin();
        let v = self.read(origin, 28);
        let slot = self.read(origin + self.chip.checksum_offset(), 4);
        let word = |b: &[u8], i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let sum = (0..7).fold(word(&slot, 0), |s, i| s.wrapping_add(word(&v, 4 * i)));
        sum == 0 && word(&v, 0) != 0xFFFF_FFFF
    }

    /// Puts the bootloader's own device id into its code the way a compiler does for the id
    /// comparisons in `xcp.c` (CONNECT) and `can.c` (the CAN receiver, twice): three sites, each
    /// a literal-pool word, a MOVW/MOVT pair or a CMP.W/CMN.W, or none at all
    /// ([`IdInCode::Absent`], a bootloader in which a host cannot find its id).
    pub fn compile_device_id(&mut self, id: u32, encoding: IdInCode) {
        // Three call sites in the code, past the vector and callback tables, each comparing
        // another register.
        for (site, rn) in [(0x0B14usize, 7u16), (0x1F3C, 1), (0x2A80, 3)] {
            match encoding {
                IdInCode::LiteralPool => {
                    self.mem[site..site + 4].copy_from_slice(&id.to_le_bytes())
                }
                IdInCode::MovwMovt => {
                    // r3 = id: MOVW r3, #low; MOVT r3, #high (Thumb-2, encoding T3/T1).
                    let movw = thumb_mov_imm16(0xF240, 3, id as u16);
                    let movt = thumb_mov_imm16(0xF2C0, 3, (id >> 16) as u16);
                    self.mem[site..site + 4].copy_from_slice(&movw);
                    self.mem[site + 4..site + 8].copy_from_slice(&movt);
                }
                IdInCode::CompareImmediate => {
                    if let Some(compare) = thumb_compare_imm(rn, id) {
                        self.mem[site..site + 4].copy_from_slice(&compare);
                    }
                }
                IdInCode::Absent => {}
            }
        }
    }

    /// Writes bytes straight into flash, as a probe would (for setting up a robot with an app).
    pub fn install(&mut self, address: u32, data: &[u8]) {
        let o = (address - FLASH_BASE) as usize;
        self.mem[o..o + data.len()].copy_from_slice(data);
    }
}

/// How a bootloader's compiled code holds its device id. AMiRo-BLT built with GCC 12.2 `-O1`
/// loads DiWheelDrive's and LightRing's from literal pools (MOVW/MOVT where literal pools are
/// avoided) and compares PowerManagement's as an immediate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdInCode {
    /// A 32-bit word in a literal pool, loaded PC-relative.
    LiteralPool,
    /// A MOVW (low half) and MOVT (high half) into one register.
    MovwMovt,
    /// No data at all: `CMP.W Rn, #id` when the id is a Thumb-2 modified immediate
    /// (PowerManagement 1-1's 0x01010101), else `CMN.W Rn, #-id` when its negation is one
    /// (1-2's 0x01010102, compared as CMN #0xFEFEFEFE), as GCC builds PowerManagement's
    /// bootloaders. An id that is neither cannot be compiled so and is left out (as
    /// [`IdInCode::Absent`]); a compiler would load it (`LiteralPool`, `MovwMovt`).
    CompareImmediate,
    /// Not findable (e.g. a bootloader built otherwise, or computing its id).
    Absent,
}

/// A 32-bit Thumb-2 MOVW/MOVT (`base` 0xF240 or 0xF2C0) of `imm` into register `rd`, as the
/// four bytes in flash (two little-endian halfwords).
fn thumb_mov_imm16(base: u16, rd: u16, imm: u16) -> [u8; 4] {
    let first = base | ((imm >> 11) & 1) << 10 | (imm >> 12);
    let second = ((imm >> 8) & 7) << 12 | rd << 8 | (imm & 0xFF);
    let [a, b] = first.to_le_bytes();
    let [c, d] = second.to_le_bytes();
    [a, b, c, d]
}

/// A 32-bit Thumb-2 compare of register `rn` with `value` as the four bytes in flash:
/// `CMP.W Rn, #value` (encoding T2) if `value` is a modified immediate, else `CMN.W Rn, #-value`
/// (T1) if its negation is one, else `None`.
fn thumb_compare_imm(rn: u16, value: u32) -> Option<[u8; 4]> {
    let (base, imm12) = match modified_immediate(value) {
        Some(imm12) => (0xF1B0, imm12),
        None => (0xF110, modified_immediate(value.wrapping_neg())?),
    };
    let first = base | (imm12 >> 11) << 10 | (rn & 0xF);
    let second = ((imm12 >> 8) & 7) << 12 | 0x0F00 | (imm12 & 0xFF);
    let [a, b] = first.to_le_bytes();
    let [c, d] = second.to_le_bytes();
    Some([a, b, c, d])
}

/// The 12-bit `i:imm3:imm8` whose Thumb-2 expansion (ThumbExpandImm, ARMv7-M manual §A5.3.2) is
/// `value`: a byte, the byte patterns 0x00XY00XY, 0xXY00XY00, 0xXYXYXYXY, or `1bcdefgh` rotated
/// right by 8 to 31 bits.
fn modified_immediate(value: u32) -> Option<u16> {
    let byte = value & 0xFF;
    if value == byte {
        return Some(byte as u16);
    }
    for (kind, pattern) in [(1u16, 0x0001_0001), (2, 0x0100_0100), (3, 0x0101_0101)] {
        let b = if kind == 2 { value >> 8 & 0xFF } else { byte };
        if b != 0 && value == b * pattern {
            return Some(kind << 8 | b as u16);
        }
    }
    (8..32u32).find_map(|rotation| {
        let unrotated = value.rotate_left(rotation);
        (unrotated & !0xFF == 0 && unrotated & 0x80 != 0)
            .then_some((rotation as u16) << 7 | (unrotated & 0x7F) as u16)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bootloader_is_protected_and_the_first_block_waits_for_the_end() {
        let mut f = Flash::new(SimChip::F103);
        let blt = f.bytes(FLASH_BASE, 0x0800_6000).to_vec();
        assert!(f.erase(0x0800_5800, 0x1000).is_err());
        assert_eq!(f.protected_hits, 1);
        f.erase(0x0800_6000, 0x1000).unwrap();
        let mut vectors = vec![0u8; 0x200];
        vectors[0..4].copy_from_slice(&0x2001_0000u32.to_le_bytes());
        f.write(0x0800_6000, &vectors).unwrap();
        f.write(0x0800_6200, &[1, 2, 3]).unwrap();
        assert_eq!(f.bytes(0x0800_6000, 0x0800_6004), [0xFF; 4]);
        assert!(!f.app_valid());
        f.done().unwrap();
        assert!(f.app_valid());
        assert_eq!(f.bytes(0x0800_6200, 0x0800_6203), [1, 2, 3]);
        assert_eq!(f.bytes(FLASH_BASE, 0x0800_6000), &blt[..]);
    }

    #[test]
    fn movw_and_movt_are_encoded_as_the_architecture_manual_says() {
        // MOVW r3, #0x0102 = F240 1302; MOVT r3, #0x0100 = F2C0 1300.
        assert_eq!(thumb_mov_imm16(0xF240, 3, 0x0102), [0x40, 0xF2, 0x02, 0x13]);
        assert_eq!(thumb_mov_imm16(0xF2C0, 3, 0x0100), [0xC0, 0xF2, 0x00, 0x13]);
        // imm4:i:imm3:imm8 all used: MOVW r0, #0xFFFF = F64F 70FF.
        assert_eq!(thumb_mov_imm16(0xF240, 0, 0xFFFF), [0x4F, 0xF6, 0xFF, 0x70]);
    }

    #[test]
    fn compares_are_encoded_as_the_architecture_manual_says() {
        // As arm-none-eabi-as 2.40 assembles them (and GCC 12.2 emits the first two for
        // PowerManagement 1-1 and 1-2).
        for (rn, value, bytes) in [
            (7, 0x0101_0101, [0xB7, 0xF1, 0x01, 0x3F]), // cmp.w r7, #0x01010101
            (1, 0x0101_0102, [0x11, 0xF1, 0xFE, 0x3F]), // cmn.w r1, #0xfefefefe
            (0, 0x3F80_0000, [0xB0, 0xF1, 0x7E, 0x5F]), // cmp.w r0, #0x3f800000
            (2, 0x00AB_00AB, [0xB2, 0xF1, 0xAB, 0x1F]), // cmp.w r2, #0x00ab00ab
            (12, 0x54FF_5500, [0x1C, 0xF1, 0xAB, 0x2F]), // cmn.w ip, #0xab00ab00
            (4, 0xFF, [0xB4, 0xF1, 0xFF, 0x0F]),        // cmp.w r4, #0xff
        ] {
            assert_eq!(thumb_compare_imm(rn, value), Some(bytes), "{value:#x}");
        }
        // DiWheelDrive's and LightRing's ids are no modified immediates, nor their negations.
        for id in [0x0100_0101, 0x0100_0102, 0x017F_0100, 0x017F_0102] {
            assert_eq!(thumb_compare_imm(3, id), None, "{id:#x}");
        }
        // So their bootloaders compiled so hold no id at all; PowerManagement's hold three compares.
        let mut f = Flash::new(SimChip::F103);
        let before = f.bytes(FLASH_BASE, 0x0800_6000).to_vec();
        f.compile_device_id(0x0100_0102, IdInCode::CompareImmediate);
        assert_eq!(f.bytes(FLASH_BASE, 0x0800_6000), &before[..]);
        let mut f = Flash::new(SimChip::F405);
        f.compile_device_id(0x0101_0102, IdInCode::CompareImmediate);
        assert_eq!(f.read(0x0800_1F3C, 4), [0x11, 0xF1, 0xFE, 0x3F]);
    }

    #[test]
    fn the_callback_table_holds_the_magic_and_the_versions() {
        let f = Flash::new(SimChip::F405);
        let table = f.read(CALLBACK_TABLE, 16);
        assert_eq!(table[..4], *b"LB-A");
        // The unaligned bytes a scan must not take for DiWheelDrive 1-1's id.
        assert_eq!(table[9..13], 0x0100_0101u32.to_le_bytes());
    }

    #[test]
    fn a_different_write_onto_unerased_flash_fails_when_its_block_is_flushed() {
        let mut f = Flash::new(SimChip::F405);
        f.erase(0x0800_8000, 0x4000).unwrap();
        f.write(0x0800_8400, &[7]).unwrap();
        f.done().unwrap();
        f.write(0x0800_8400, &[7]).unwrap();
        f.done().unwrap();
        f.write(0x0800_8400, &[8]).unwrap();
        assert_eq!(f.done(), Err(FlashError::NotErased(0x0800_8400)));
    }
}
