//! A firmware image read once: its named functions with their decoded code, the vector table, the
//! functions whose address is stored, the flash contents and the DWARF line table.
use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::rc::Rc;

use object::{Object, ObjectSection, ObjectSymbol, SymbolKind};

use crate::decode::{self, Insn, Outlined};
use crate::Error;

/// The DWARF reader the line table is read through.
type Reader = gimli::EndianRcSlice<gimli::RunTimeEndian>;

/// One named function of the image.
#[derive(Debug, Clone)]
pub struct Function {
    /// Its address (the Thumb bit cleared) and size in bytes.
    pub start: u64,
    pub size: u64,
    /// Its demangled name without the hash (`{:#}` of `rustc_demangle`).
    pub name: String,
    /// Its symbol as the linker wrote it.
    pub symbol: String,
    /// Its machine code, data inside it (literal pools, jump tables) zeroed.
    pub code: Vec<u8>,
    /// The stretches of data inside it (from the `$d` mapping symbols), as address ranges.
    pub data: Vec<(u64, u64)>,
    /// Its instructions, or why they could not be decoded.
    pub insns: Result<Vec<Insn>, Error>,
}

impl Function {
    /// Its decoded instructions, or the decoder's error.
    pub fn instructions(&self) -> Result<&[Insn], Error> {
        self.insns.as_deref().map_err(Clone::clone)
    }

    /// Whether `address` lies inside it.
    pub fn contains(&self, address: u64) -> bool {
        (self.start..self.start + self.size).contains(&address)
    }
}

/// A firmware image's functions, and what the analyses need to know about them.
pub struct Image {
    /// Every named function, by start address.
    pub functions: BTreeMap<u64, Function>,
    /// The vector table's entries (index, handler address, Thumb bit cleared), the initial stack
    /// pointer left out.
    pub vectors: Vec<(usize, u64)>,
    /// Functions whose address is stored anywhere outside the vector table (literal pools, vtables,
    /// tables): what a call through a register may reach.
    pub address_taken: BTreeSet<u64>,
    /// The named data objects (`static`s, vtables): their address and size by demangled name
    /// without the hash and by symbol.
    objects: BTreeMap<String, (u64, u64)>,
    /// Every function symbol's start, by demangled name without the hash and by symbol: the names
    /// of functions the linker folded into one (identical code, one address) too, of which
    /// [`Function::name`] keeps the first.
    aliases: BTreeMap<String, BTreeSet<u64>>,
    /// The contents of the allocated sections with file data (address, bytes): flash, and the
    /// initial values of RAM.
    sections: Vec<(u64, Vec<u8>)>,
    /// The DWARF line table, when the image has one.
    lines: Option<addr2line::Context<Reader>>,
}

/// Whether a section is loaded on the chip (the debug sections are not).
fn allocated(section: &object::Section<'_, '_>) -> bool {
    match section.flags() {
        object::SectionFlags::Elf { sh_flags } => sh_flags & u64::from(object::elf::SHF_ALLOC) != 0,
        _ => false,
    }
}

impl Image {
    /// Reads and parses the ELF at `path`.
    pub fn read(path: &Path) -> Result<Image, Error> {
        let bytes = std::fs::read(path).map_err(|e| Error::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Image::parse(&bytes)
    }

    /// Parses an ELF image held in memory.
    pub fn parse(bytes: &[u8]) -> Result<Image, Error> {
        let file = object::File::parse(bytes).map_err(|e| Error::Malformed(e.to_string()))?;
        if file.architecture() != object::Architecture::Arm {
            return Err(Error::NotArm(format!("{:?}", file.architecture())));
        }
        let sections: Vec<(u64, Vec<u8>)> = file
            .sections()
            .filter(|s| allocated(s))
            .filter_map(|s| Some((s.address(), s.data().ok()?.to_vec())))
            .filter(|(_, d)| !d.is_empty())
            .collect();
        // Literal pools and tables inside functions (the ARM ELF mapping symbols: `$d` starts data,
        // `$t` code again).
        let mut marks: Vec<(u64, bool)> = file
            .symbols()
            .filter_map(|symbol| {
                let name = symbol.name().ok()?;
                let data = name == "$d" || name.starts_with("$d.");
                let code = name == "$t" || name.starts_with("$t.");
                (data || code).then_some((symbol.address(), data))
            })
            .collect();
        marks.sort_unstable();
        let data_ranges: Vec<(u64, u64)> = marks
            .iter()
            .enumerate()
            .filter(|(_, (_, data))| *data)
            .map(|(k, &(at, _))| (at, marks.get(k + 1).map_or(u64::MAX, |&(next, _)| next)))
            .collect();
        let mut functions = BTreeMap::new();
        let mut aliases: BTreeMap<String, BTreeSet<u64>> = BTreeMap::new();
        for symbol in file.symbols() {
            if symbol.kind() != SymbolKind::Text || symbol.size() == 0 {
                continue;
            }
            let Ok(raw) = symbol.name() else { continue };
            let start = symbol.address() & !1;
            let demangled = format!("{:#}", rustc_demangle::demangle(raw));
            aliases.entry(demangled).or_default().insert(start);
            aliases.entry(raw.to_string()).or_default().insert(start);
            if functions.contains_key(&start) {
                continue;
            }
            let size = symbol.size();
            let mut code = read_from(&sections, start, size).unwrap_or_default();
            let data: Vec<(u64, u64)> = data_ranges
                .iter()
                .map(|&(from, to)| (from.max(start), to.min(start + size)))
                .filter(|(from, to)| from < to)
                .collect();
            for &(from, to) in &data {
                let (a, b) = ((from - start) as usize, (to - start) as usize);
                if let Some(bytes) = code.get_mut(a..b) {
                    bytes.fill(0);
                }
            }
            let name = format!("{:#}", rustc_demangle::demangle(raw));
            let insns = if code.len() as u64 == size {
                decode::decode(&name, start, &code, &data)
            } else {
                Err(Error::Other(format!(
                    "{name}: its code at {start:#010x} is not in the image's sections"
                )))
            };
            functions.insert(
                start,
                Function {
                    start,
                    size,
                    name,
                    symbol: raw.to_string(),
                    code,
                    data,
                    insns,
                },
            );
        }
        mark_outlined_calls(&mut functions);
        let mut objects = BTreeMap::new();
        for symbol in file.symbols() {
            if symbol.kind() != SymbolKind::Data || symbol.size() == 0 {
                continue;
            }
            let Ok(raw) = symbol.name() else { continue };
            let name = format!("{:#}", rustc_demangle::demangle(raw));
            let at = (symbol.address(), symbol.size());
            objects.entry(name).or_insert(at);
            objects.entry(raw.to_string()).or_insert(at);
        }
        let mut vectors = Vec::new();
        let mut address_taken = BTreeSet::new();
        for section in file.sections().filter(|s| allocated(s)) {
            let Ok(data) = section.data() else { continue };
            let is_vectors = section.name().is_ok_and(|n| n == ".vector_table");
            for (i, word) in data.chunks_exact(4).enumerate() {
                let value = u64::from(u32::from_le_bytes([word[0], word[1], word[2], word[3]]));
                if value & 1 == 0 || !functions.contains_key(&(value & !1)) {
                    continue;
                }
                if is_vectors {
                    if i > 0 {
                        vectors.push((i, value & !1));
                    }
                } else {
                    address_taken.insert(value & !1);
                }
            }
        }
        Ok(Image {
            functions,
            vectors,
            address_taken,
            objects,
            aliases,
            sections,
            lines: line_table(&file),
        })
    }

    /// The function named `name`: its demangled name without hash, or its symbol. The first of
    /// several of the same name (monomorphs differing in their hash).
    pub fn function_named(&self, name: &str) -> Result<&Function, Error> {
        self.functions
            .values()
            .find(|f| f.name == name || f.symbol == name)
            .ok_or_else(|| Error::MissingSymbol(name.to_string()))
    }

    /// The starts of every function a symbol named `name` (demangled without hash, or the symbol)
    /// names: the functions of that name and those the linker folded one of that name into.
    pub fn starts_named(&self, name: &str) -> BTreeSet<u64> {
        self.aliases
            .get(name)
            .into_iter()
            .flatten()
            .copied()
            .filter(|at| self.functions.contains_key(at))
            .collect()
    }

    /// The address and size of the data object named `name` (demangled without hash, or its
    /// symbol).
    pub fn object_named(&self, name: &str) -> Option<(u64, u64)> {
        self.objects.get(name).copied()
    }

    /// The addresses of the aligned words of the loaded sections (code, its literal pools, data)
    /// that hold `value`.
    pub fn words_holding(&self, value: u32) -> Vec<u64> {
        let bytes = value.to_le_bytes();
        self.sections
            .iter()
            .flat_map(|(start, data)| {
                let start = *start;
                let skip = ((4 - start % 4) % 4) as usize;
                data.get(skip..)
                    .unwrap_or_default()
                    .chunks_exact(4)
                    .enumerate()
                    .filter(move |(_, w)| **w == bytes)
                    .map(move |(k, _)| start + skip as u64 + 4 * k as u64)
            })
            .collect()
    }

    /// The function starting at `address`.
    pub fn function_at(&self, address: u64) -> Option<&Function> {
        self.functions.get(&address)
    }

    /// A function's name, or its address when it has none.
    pub fn name(&self, at: u64) -> String {
        self.functions
            .get(&at)
            .map_or_else(|| format!("{at:#x}"), |f| f.name.clone())
    }

    /// The functions `f` calls or tail-calls directly (the first instruction of another function).
    pub fn callees(&self, f: &Function) -> Result<BTreeSet<u64>, Error> {
        Ok(f.instructions()?
            .iter()
            .filter_map(|i| i.direct_target())
            .filter(|t| !f.contains(*t) && self.functions.contains_key(t))
            .collect())
    }

    /// A 32-bit word of the image's contents at `address`, if a loaded section holds it.
    pub fn word(&self, address: u64) -> Option<u32> {
        let bytes = read_from(&self.sections, address, 4)?;
        Some(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
    }

    /// `len` bytes of the image's contents at `address`, if one loaded section holds them.
    pub fn bytes(&self, address: u64, len: u64) -> Option<Vec<u8>> {
        read_from(&self.sections, address, len)
    }

    /// The source file and line of `address` (the line table's row: inlined code is named where it
    /// was written), when the image has DWARF line information for it.
    pub fn line(&self, address: u64) -> Option<(String, u32)> {
        let location = self.lines.as_ref()?.find_location(address).ok()??;
        Some((location.file?.to_string(), location.line?))
    }

    /// The functions whose code is at `address`, innermost first: each DWARF inlined subroutine
    /// the address lies in, then the function it was inlined into, each demangled without its
    /// hash. Empty without DWARF debug information for it.
    pub fn inlined_at(&self, address: u64) -> Vec<String> {
        self.inlined_raw_at(address)
            .iter()
            .map(|raw| format!("{:#}", rustc_demangle::demangle(raw)))
            .collect()
    }

    /// [`Image::inlined_at`]'s functions as DWARF names them (the linkage name, mangled with its
    /// hash where rustc wrote one): a generic function's instances differ by it.
    pub fn inlined_raw_at(&self, address: u64) -> Vec<String> {
        let Some(context) = self.lines.as_ref() else {
            return Vec::new();
        };
        let Ok(mut frames) = context.find_frames(address).skip_all_loads() else {
            return Vec::new();
        };
        let mut names = Vec::new();
        while let Ok(Some(frame)) = frames.next() {
            if let Some(raw) = frame.function.as_ref().and_then(|f| f.raw_name().ok()) {
                names.push(raw.into_owned());
            }
        }
        names
    }
}

/// What an `OUTLINED_FUNCTION_n` does to the registers: the machine outliner's helpers follow no calling
/// convention, so a call of one may write any register (a loop counter in `r4`). Straight-line code ending
/// in a return, or in a tail call of a function that is not outlined (which keeps to the calling
/// convention: it may write r0-r3 and r12), is read whole: every register it writes, and the constants its
/// last writes leave; anything else (a branch, a call) is taken to write every core register and leave
/// nothing known.
fn outlined_effect(f: &Function, outlined: &BTreeSet<u64>) -> Outlined {
    let everything = Outlined {
        writes: 0x1FFF,
        constants: Vec::new(),
    };
    let Ok(insns) = f.instructions() else {
        return everything;
    };
    let Some((last, body)) = insns.split_last() else {
        return everything;
    };
    const CALLER_SAVED: u16 = 0b1_0000_0000_1111;
    let clobbered = match last.flow() {
        decode::Flow::Return => 0,
        decode::Flow::Branch(t)
            if !last.conditional && !f.contains(t) && !outlined.contains(&t) =>
        {
            CALLER_SAVED
        }
        _ => return everything,
    };
    if !body.iter().all(|i| i.flow() == decode::Flow::Next) {
        return everything;
    }
    let mut writes = 0u16;
    let mut constants: Vec<(u8, u32)> = Vec::new();
    for insn in insns {
        let w = insn.writes().0 & 0x1FFF;
        for r in 0..13u8 {
            if w & 1 << r != 0 {
                constants.retain(|&(x, _)| x != r);
                let regs = insn.registers();
                if insn.inst.opcode == decode::Opcode::MOV && regs == [r] && !insn.conditional {
                    if let Some(c) = insn.immediate() {
                        constants.push((r, c));
                    }
                }
            }
        }
        writes |= w;
    }
    constants.retain(|&(r, _)| clobbered & 1 << r == 0);
    Outlined {
        writes: writes | clobbered,
        constants,
    }
}

/// Marks every call of an outlined function with what it does to the registers ([`Insn::outlined`]).
fn mark_outlined_calls(functions: &mut BTreeMap<u64, Function>) {
    let outlined: BTreeSet<u64> = functions
        .values()
        .filter(|f| f.name.starts_with("OUTLINED_FUNCTION"))
        .map(|f| f.start)
        .collect();
    let effects: BTreeMap<u64, Outlined> = outlined
        .iter()
        .filter_map(|at| functions.get(at))
        .map(|f| (f.start, outlined_effect(f, &outlined)))
        .collect();
    if effects.is_empty() {
        return;
    }
    for f in functions.values_mut() {
        if let Ok(insns) = f.insns.as_mut() {
            for insn in insns.iter_mut() {
                let call = matches!(insn.flow(), decode::Flow::Call(_));
                if let Some(effect) = insn.direct_target().and_then(|t| effects.get(&t)) {
                    if call {
                        insn.outlined = Some(effect.clone());
                    }
                }
            }
        }
    }
}

fn read_from(sections: &[(u64, Vec<u8>)], address: u64, len: u64) -> Option<Vec<u8>> {
    sections.iter().find_map(|(start, data)| {
        let from = usize::try_from(address.checked_sub(*start)?).ok()?;
        let to = from.checked_add(usize::try_from(len).ok()?)?;
        data.get(from..to).map(<[u8]>::to_vec)
    })
}

fn line_table(file: &object::File<'_>) -> Option<addr2line::Context<Reader>> {
    file.section_by_name(".debug_line")?;
    let endian = if file.is_little_endian() {
        gimli::RunTimeEndian::Little
    } else {
        gimli::RunTimeEndian::Big
    };
    let load = |id: gimli::SectionId| -> Result<Reader, gimli::Error> {
        let data = file
            .section_by_name(id.name())
            .and_then(|s| s.uncompressed_data().ok())
            .unwrap_or(Cow::Borrowed(&[]));
        Ok(gimli::EndianRcSlice::new(Rc::from(&*data), endian))
    };
    let dwarf = gimli::Dwarf::load(load).ok()?;
    addr2line::Context::from_dwarf(dwarf).ok()
}
