//! Small ARM ELF images built in the tests (`object::write`): one `.text` section at address 0
//! holding the code, function symbols with the Thumb bit, and the `$d`/`$t` mapping symbols.
use object::write::{Object, Symbol, SymbolSection};
use object::{
    Architecture, BinaryFormat, Endianness, SectionKind, SymbolFlags, SymbolKind, SymbolScope,
};

/// One symbol of a test image.
pub struct Sym {
    name: String,
    offset: u64,
    size: u64,
    kind: SymbolKind,
}

impl Sym {
    /// A Thumb function of `size` bytes at `offset`.
    pub fn function(name: &str, offset: u64, size: u64) -> Sym {
        Sym {
            name: name.to_string(),
            offset,
            size,
            kind: SymbolKind::Text,
        }
    }
    /// A named data object (a `static`, a vtable) of `size` bytes at `offset`.
    pub fn object(name: &str, offset: u64, size: u64) -> Sym {
        Sym {
            name: name.to_string(),
            offset,
            size,
            kind: SymbolKind::Data,
        }
    }
    /// Data (a literal pool, a table) starts at `offset`.
    pub fn data(offset: u64) -> Sym {
        Sym {
            name: "$d".into(),
            offset,
            size: 0,
            kind: SymbolKind::Label,
        }
    }
    /// Code starts again at `offset`.
    pub fn code(offset: u64) -> Sym {
        Sym {
            name: "$t".into(),
            offset,
            size: 0,
            kind: SymbolKind::Label,
        }
    }
}

/// An ELF image of `code` with `symbols`.
pub fn elf(code: &[u8], symbols: &[Sym]) -> Vec<u8> {
    elf_with_lines(code, symbols, "", &[])
}

/// An ELF image of `code` with `symbols` and a DWARF line table: each `(address, line)` row of
/// `file` (`/work/<file>`) holds from its address to the next row's.
pub fn elf_with_lines(code: &[u8], symbols: &[Sym], file: &str, rows: &[(u64, u64)]) -> Vec<u8> {
    elf_with_inlines(code, symbols, file, rows, &[])
}

/// A function's code as DWARF describes it: `function` (its name, start and end) with the
/// subroutines inlined into it (each its name and the address range its code occupies).
pub struct Inlines<'a> {
    pub function: (&'a str, u64, u64),
    pub inlined: &'a [(&'a str, u64, u64)],
}

/// [`elf_with_lines`] with DWARF subprograms: each of `functions` a subprogram, its inlined
/// subroutines children of it naming an abstract subprogram of their name (as rustc writes an
/// inlined function); one whose range lies within an earlier one's is that one's child.
pub fn elf_with_inlines(
    code: &[u8],
    symbols: &[Sym],
    file: &str,
    rows: &[(u64, u64)],
    functions: &[Inlines<'_>],
) -> Vec<u8> {
    let mut object = Object::new(BinaryFormat::Elf, Architecture::Arm, Endianness::Little);
    let text = object.add_section(Vec::new(), b".text".to_vec(), SectionKind::Text);
    object.append_section_data(text, code, 4);
    for s in symbols {
        let function = s.kind == SymbolKind::Text;
        object.add_symbol(Symbol {
            name: s.name.as_bytes().to_vec(),
            value: if function { s.offset | 1 } else { s.offset },
            size: s.size,
            kind: s.kind,
            scope: if function {
                SymbolScope::Linkage
            } else {
                SymbolScope::Compilation
            },
            weak: false,
            section: SymbolSection::Section(text),
            flags: SymbolFlags::None,
        });
    }
    if !rows.is_empty() {
        for (name, data) in line_table(code.len() as u64, file, rows, functions) {
            let id = object.add_section(Vec::new(), name.into_bytes(), SectionKind::Debug);
            object.append_section_data(id, &data, 1);
        }
    }
    object.write().expect("a test image writes")
}

/// The DWARF sections of one compilation unit covering `0..len` with the given line rows and
/// subprograms.
fn line_table(
    len: u64,
    file: &str,
    rows: &[(u64, u64)],
    functions: &[Inlines<'_>],
) -> Vec<(String, Vec<u8>)> {
    use gimli::write::{
        Address, AttributeValue, DwarfUnit, EndianVec, LineProgram, LineString, Sections,
    };
    let encoding = gimli::Encoding {
        format: gimli::Format::Dwarf32,
        version: 4,
        address_size: 4,
    };
    let mut dwarf = DwarfUnit::new(encoding);
    // The file by its absolute path, as rustc writes them.
    let path = format!("/work/{file}");
    let mut program = LineProgram::new(
        encoding,
        gimli::LineEncoding::default(),
        LineString::String(b"/work".to_vec()),
        LineString::String(path.clone().into_bytes()),
        None,
    );
    let directory = program.default_directory();
    let file_id = program.add_file(LineString::String(path.into_bytes()), directory, None);
    program.begin_sequence(Some(Address::Constant(0)));
    for &(address, line) in rows {
        program.row().address_offset = address;
        program.row().file = file_id;
        program.row().line = line;
        program.generate_row();
    }
    program.end_sequence(len);
    dwarf.unit.line_program = program;
    let root = dwarf.unit.root();
    let entry = dwarf.unit.get_mut(root);
    entry.set(
        gimli::DW_AT_low_pc,
        AttributeValue::Address(Address::Constant(0)),
    );
    entry.set(gimli::DW_AT_high_pc, AttributeValue::Udata(len));
    let range = |unit: &mut gimli::write::Unit, id, from: u64, to: u64| {
        let entry = unit.get_mut(id);
        entry.set(
            gimli::DW_AT_low_pc,
            AttributeValue::Address(Address::Constant(from)),
        );
        entry.set(gimli::DW_AT_high_pc, AttributeValue::Udata(to - from));
    };
    for f in functions {
        let (name, from, to) = f.function;
        let outer = dwarf.unit.add(root, gimli::DW_TAG_subprogram);
        dwarf.unit.get_mut(outer).set(
            gimli::DW_AT_name,
            AttributeValue::String(name.as_bytes().to_vec()),
        );
        range(&mut dwarf.unit, outer, from, to);
        // An inlined subroutine whose range lies within an earlier one's is its child (inlined into it).
        let mut placed: Vec<(gimli::write::UnitEntryId, u64, u64)> = Vec::new();
        for &(name, from, to) in f.inlined {
            let origin = dwarf.unit.add(root, gimli::DW_TAG_subprogram);
            let abstract_entry = dwarf.unit.get_mut(origin);
            abstract_entry.set(
                gimli::DW_AT_linkage_name,
                AttributeValue::String(name.as_bytes().to_vec()),
            );
            abstract_entry.set(
                gimli::DW_AT_inline,
                AttributeValue::Inline(gimli::DW_INL_inlined),
            );
            let parent = placed
                .iter()
                .rev()
                .find(|&&(_, f, t)| f <= from && to <= t && (f, t) != (from, to))
                .map_or(outer, |&(id, _, _)| id);
            let inlined = dwarf.unit.add(parent, gimli::DW_TAG_inlined_subroutine);
            placed.push((inlined, from, to));
            dwarf.unit.get_mut(inlined).set(
                gimli::DW_AT_abstract_origin,
                AttributeValue::UnitRef(origin),
            );
            range(&mut dwarf.unit, inlined, from, to);
        }
    }
    let mut sections = Sections::new(EndianVec::new(gimli::LittleEndian));
    dwarf.write(&mut sections).expect("the line table writes");
    let mut out = Vec::new();
    sections
        .for_each(|id, data| {
            if !data.slice().is_empty() {
                out.push((id.name().to_string(), data.slice().to_vec()));
            }
            Ok::<(), gimli::write::Error>(())
        })
        .expect("the sections are read");
    out
}
