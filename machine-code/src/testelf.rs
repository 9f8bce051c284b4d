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
    object.write().expect("a test image writes")
}
