//! The bytes a board receives: the loadable segments of its ELF, checked against its layout.
use object::elf::PT_LOAD;
use object::read::elf::{ElfFile32, ProgramHeader};
use object::Endianness;

use crate::error::Error;
use crate::target::Target;

/// A run of bytes at a flash address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Segment {
    /// Load (physical) address.
    pub address: u32,
    /// The bytes.
    pub data: Vec<u8>,
}

impl Segment {
    /// One past the last byte.
    pub fn end(&self) -> u32 {
        self.address + self.data.len() as u32
    }
}

/// A firmware image: sorted, non-overlapping segments (adjacent ones merged).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    segments: Vec<Segment>,
}

impl Image {
    /// Builds an image from segments in any order; refuses overlaps, wrap-around and emptiness.
    pub fn new(mut segments: Vec<Segment>) -> Result<Self, Error> {
        segments.retain(|s| !s.data.is_empty());
        segments.sort_by_key(|s| s.address);
        let mut merged: Vec<Segment> = Vec::new();
        for s in segments {
            if u64::from(s.address) + s.data.len() as u64 > 1 << 32 {
                return Err(Error::BadImage(format!(
                    "segment at {:#010x} runs past the end of the address space",
                    s.address
                )));
            }
            match merged.last_mut() {
                Some(last) if s.address < last.end() => {
                    return Err(Error::BadImage(format!(
                        "segments overlap at {:#010x}",
                        s.address
                    )))
                }
                Some(last) if s.address == last.end() => last.data.extend_from_slice(&s.data),
                _ => merged.push(s),
            }
        }
        if merged.is_empty() {
            return Err(Error::BadImage("no loadable bytes".into()));
        }
        Ok(Image { segments: merged })
    }

    /// The loadable segments of a 32-bit ARM ELF at their load addresses (`.data` travels at its
    /// flash address, as an S-record from `objcopy` carries it).
    pub fn from_elf(bytes: &[u8]) -> Result<Self, Error> {
        let file = ElfFile32::<Endianness>::parse(bytes)
            .map_err(|e| Error::BadImage(format!("not a 32-bit ELF: {e}")))?;
        let endian = file.endian();
        let mut segments = Vec::new();
        for header in file.elf_program_headers() {
            if header.p_type(endian) != PT_LOAD || header.p_filesz(endian) == 0 {
                continue;
            }
            let data = header
                .data(endian, bytes)
                .map_err(|_| Error::BadImage("a segment lies outside the file".into()))?;
            segments.push(Segment {
                address: header.p_paddr(endian),
                data: data.to_vec(),
            });
        }
        Image::new(segments)
    }

    /// The segments in address order.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Lowest address.
    pub fn start(&self) -> u32 {
        self.segments[0].address
    }

    /// One past the highest address.
    pub fn end(&self) -> u32 {
        self.segments[self.segments.len() - 1].end()
    }

    /// Bytes to program.
    pub fn len(&self) -> usize {
        self.segments.iter().map(|s| s.data.len()).sum()
    }

    /// Never true: an image has at least one byte.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The byte at `address`, if the image has one there.
    pub fn byte_at(&self, address: u32) -> Option<u8> {
        self.segments
            .iter()
            .find(|s| (s.address..s.end()).contains(&address))
            .map(|s| s.data[(address - s.address) as usize])
    }

    /// Checks the image against the board before anything is sent: linked at the application
    /// origin (a bare-chip image starts at 0x08000000 and would overwrite the bootloader), a
    /// vector table long enough for the checksum, and room in flash.
    pub fn check_for(&self, target: &Target) -> Result<(), Error> {
        if self.start() != target.app_origin {
            return Err(Error::NotLinkedForBootloader {
                board: target.name.clone(),
                start: self.start(),
                origin: target.app_origin,
            });
        }
        if self.vector_words().is_none() {
            return Err(Error::BadImage(format!(
                "{}: the image does not start with a vector table of seven words",
                target.name
            )));
        }
        if self.end() > target.flash_end {
            return Err(Error::ImageTooLarge {
                board: target.name.clone(),
                size: u64::from(self.end() - self.start()),
                available: u64::from(target.flash_end - target.app_origin),
            });
        }
        Ok(())
    }

    fn vector_words(&self) -> Option<[u32; 7]> {
        let first = &self.segments[0];
        let mut words = [0u32; 7];
        for (i, w) in words.iter_mut().enumerate() {
            let b = first.data.get(4 * i..4 * i + 4)?;
            *w = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        Some(words)
    }

    /// The word AMiRo-BLT writes into the checksum slot: the first seven vector words plus it
    /// sum to zero.
    pub fn checksum(&self) -> Option<u32> {
        self.vector_words()
            .map(|w| 0u32.wrapping_sub(w.iter().fold(0u32, |s, x| s.wrapping_add(*x))))
    }

    /// What the board's flash must hold after programming: the image with the checksum in its
    /// slot (the slot word is added as a segment of its own if the image leaves it out).
    pub fn expected_flash(&self, target: &Target) -> Vec<Segment> {
        let slot = target.app_origin + target.checksum_offset;
        let word = self.checksum().unwrap_or(0).to_le_bytes();
        let mut segments = self.segments.clone();
        let mut placed = 0;
        for s in &mut segments {
            for (i, b) in word.iter().enumerate() {
                let at = slot + i as u32;
                if (s.address..s.end()).contains(&at) {
                    s.data[(at - s.address) as usize] = *b;
                    placed += 1;
                }
            }
        }
        if placed < 4 {
            // Only possible if the slot falls into a gap; then the whole word is read back.
            segments.push(Segment {
                address: slot,
                data: word.to_vec(),
            });
            segments.sort_by_key(|s| s.address);
        }
        segments
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::target::{robot, IdSet};

    fn vectors(base: u32) -> Vec<u8> {
        let mut v = Vec::new();
        v.extend_from_slice(&0x2001_0000u32.to_le_bytes());
        for i in 0..6u32 {
            v.extend_from_slice(&(base + 0x201 + 2 * i).to_le_bytes());
        }
        v
    }

    #[test]
    fn segments_are_sorted_merged_and_overlaps_refused() {
        let img = Image::new(vec![
            Segment {
                address: 0x0800_6100,
                data: vec![2; 4],
            },
            Segment {
                address: 0x0800_6000,
                data: vectors(0x0800_6000),
            },
            Segment {
                address: 0x0800_601C,
                data: vec![1; 4],
            },
        ])
        .unwrap();
        assert_eq!(img.segments().len(), 2);
        assert_eq!(img.len(), 36);
        assert_eq!(img.byte_at(0x0800_601C), Some(1));
        assert!(Image::new(vec![
            Segment {
                address: 0,
                data: vec![0; 8]
            },
            Segment {
                address: 4,
                data: vec![0; 8]
            }
        ])
        .is_err());
    }

    #[test]
    fn a_bare_chip_image_and_an_oversized_one_are_refused() {
        let dwd = &robot(IdSet::Rev12)[0];
        let bare = Image::new(vec![Segment {
            address: 0x0800_0000,
            data: vectors(0x0800_0000),
        }])
        .unwrap();
        assert!(matches!(
            bare.check_for(dwd),
            Err(Error::NotLinkedForBootloader { .. })
        ));
        let mut big = vectors(0x0800_6000);
        big.resize(0x0808_0000 - 0x0800_6000 + 1, 0);
        let big = Image::new(vec![Segment {
            address: 0x0800_6000,
            data: big,
        }])
        .unwrap();
        assert!(matches!(
            big.check_for(dwd),
            Err(Error::ImageTooLarge { .. })
        ));
    }

    #[test]
    fn the_expected_flash_carries_a_checksum_that_zeroes_the_sum() {
        let dwd = &robot(IdSet::Rev12)[0];
        let mut data = vectors(0x0800_6000);
        data.resize(0x200, 0xAA);
        let img = Image::new(vec![Segment {
            address: 0x0800_6000,
            data,
        }])
        .unwrap();
        img.check_for(dwd).unwrap();
        let flash = img.expected_flash(dwd);
        let bytes = &flash[0].data;
        let word = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
        let sum = (0..7).fold(word(0x150), |s, i| s.wrapping_add(word(4 * i)));
        assert_eq!(sum, 0);
        assert_eq!(bytes[0x154], 0xAA);
    }
}
