//! Which panics a firmware image's on-chip admission check can reach: the direct calls and tail calls of its
//! machine code (Thumb-2 `BL`, `B.W`, and `B` to another function), followed from every function of the check to
//! whatever it calls, so a new `unwrap`, slice index or division by a value from the bus shows up as a path from the
//! check to `core::panicking` — the firmware rule "no panic on data from the bus" kept by the build, not by reading.
//!
//! What it cannot see: calls through a function pointer or a trait object (`BLX` to a register), which the check
//! does not use, and code the linker did not name. Literal pools are skipped (the ELF's `$d` mapping symbols mark
//! them); a word of data read as an instruction could only add an edge that is not there (a false alarm), never
//! hide one, and an edge counts only when it lands on a function's first instruction.
use anyhow::{bail, ensure, Context, Result};
use object::{Object, ObjectSection, ObjectSymbol, SymbolKind};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;

/// One function of the image.
#[derive(Debug, Clone)]
pub struct Function {
    /// Its address (the Thumb bit cleared) and size.
    pub start: u64,
    pub size: u64,
    /// Its demangled name.
    pub name: String,
    /// Its machine code.
    pub code: Vec<u8>,
}

/// A firmware image's functions, and what its call graph needs to know about them.
pub struct Image {
    /// Every named function, by start address.
    pub functions: BTreeMap<u64, Function>,
    /// The vector table's entries (index, handler address, Thumb bit cleared), the initial stack pointer left out.
    pub vectors: Vec<(usize, u64)>,
    /// Functions whose address is stored anywhere outside the vector table (literal pools, vtables, tables): what a
    /// call through a register may reach.
    pub address_taken: BTreeSet<u64>,
}

impl Image {
    /// Reads `elf`'s symbols, code, vector table and stored function addresses.
    pub fn read(elf: &Path) -> Result<Image> {
        let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
        let file =
            object::File::parse(&*bytes).with_context(|| format!("parsing {}", elf.display()))?;
        let mut functions = BTreeMap::new();
        for symbol in file.symbols() {
            if symbol.kind() != SymbolKind::Text || symbol.size() == 0 {
                continue;
            }
            let Ok(raw) = symbol.name() else { continue };
            let start = symbol.address() & !1;
            if functions.contains_key(&start) {
                continue;
            }
            let code = file
                .sections()
                .find(|s| s.address() <= start && start + symbol.size() <= s.address() + s.size())
                .and_then(|s| {
                    let data = s.data().ok()?;
                    let from = usize::try_from(start - s.address()).ok()?;
                    data.get(from..from + usize::try_from(symbol.size()).ok()?)
                        .map(<[u8]>::to_vec)
                })
                .unwrap_or_default();
            functions.insert(
                start,
                Function {
                    start,
                    size: symbol.size(),
                    name: format!("{:#}", rustc_demangle::demangle(raw)),
                    code,
                },
            );
        }
        // Literal pools and tables inside functions (the ARM ELF mapping symbols: `$d` starts data, `$t` code
        // again) are blanked, so that a word of data is not read as a branch.
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
        for (k, &(at, data)) in marks.iter().enumerate() {
            if !data {
                continue;
            }
            let end = marks.get(k + 1).map_or(u64::MAX, |&(next, _)| next);
            for f in functions.values_mut() {
                let (from, to) = (at.max(f.start), end.min(f.start + f.size));
                if from < to {
                    let (a, b) = ((from - f.start) as usize, (to - f.start) as usize);
                    if let Some(bytes) = f.code.get_mut(a..b) {
                        bytes.fill(0);
                    }
                }
            }
        }
        let mut vectors = Vec::new();
        let mut address_taken = BTreeSet::new();
        for section in file.sections() {
            // Only what the chip holds (the debug sections name every function).
            let alloc = match section.flags() {
                object::SectionFlags::Elf { sh_flags } => {
                    sh_flags & u64::from(object::elf::SHF_ALLOC) != 0
                }
                _ => false,
            };
            let Ok(data) = section.data() else { continue };
            if !alloc {
                continue;
            }
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
        })
    }

    /// The functions `f` calls or tail-calls directly (the first instruction of another function).
    pub fn callees(&self, f: &Function) -> BTreeSet<u64> {
        branch_targets(&f.code, f.start)
            .into_iter()
            .filter(|t| !(f.start..f.start + f.size).contains(t) && self.functions.contains_key(t))
            .collect()
    }

    /// A function's name, or its address when it has none.
    pub fn name(&self, at: u64) -> String {
        self.functions
            .get(&at)
            .map_or_else(|| format!("{at:#x}"), |f| f.name.clone())
    }
}

/// Whether a function belongs to the on-chip admission check: the core analysis, the firmware's admission state and
/// task, the verdict frames (what the size table counts as the check).
fn is_check(name: &str) -> bool {
    name.contains("schedule_analysis::") || name.to_lowercase().contains("admission")
}

/// Whether reaching this function means a panic can happen: `core::panicking::*`, the slice and `Option`/`Result`
/// failure paths (`slice_index_fail`, `unwrap_failed`, ...).
fn is_panic(name: &str) -> bool {
    // The compiler's guard against polling a finished `async fn` again: the RTIC executor never does.
    if name.contains("panic_const_async_fn_resumed") {
        return false;
    }
    name.contains("panic") || name.ends_with("_fail") || name.ends_with("_failed")
}

/// The targets of the direct branches in `code` (Thumb-2, loaded at `base`): `BL` (T1), `B.W` (T3, T4) and the 16-bit
/// `B` (T1, T2).
fn branch_targets(code: &[u8], base: u64) -> Vec<u64> {
    let half = |i: usize| -> Option<u32> {
        Some(u32::from(u16::from_le_bytes([
            *code.get(i)?,
            *code.get(i + 1)?,
        ])))
    };
    let mut targets = Vec::new();
    let mut i = 0;
    while let Some(hw1) = half(i) {
        let pc = base + i as u64 + 4;
        let wide = matches!(hw1 >> 11, 0b11101..=0b11111);
        if !wide {
            if hw1 >> 11 == 0b11100 {
                // B (T2): imm11.
                let offset = sign_extend((hw1 & 0x7ff) << 1, 12);
                targets.push(pc.wrapping_add_signed(offset));
            } else if hw1 >> 12 == 0b1101 && !matches!((hw1 >> 8) & 0xf, 0b1110 | 0b1111) {
                // B<cond> (T1): imm8.
                let offset = sign_extend((hw1 & 0xff) << 1, 9);
                targets.push(pc.wrapping_add_signed(offset));
            }
            i += 2;
            continue;
        }
        let Some(hw2) = half(i + 2) else { break };
        if hw1 >> 11 == 0b11110 && hw2 >> 15 == 1 {
            let s = (hw1 >> 10) & 1;
            let (j1, j2) = ((hw2 >> 13) & 1, (hw2 >> 11) & 1);
            let imm11 = hw2 & 0x7ff;
            let link_or_t4 = (hw2 >> 12) & 1 == 1;
            // Bit 15 of the second half is set: BL and B.W (T4) have bit 12 set too, B<cond>.W (T3) has 14 and 12 clear.
            if link_or_t4 {
                // BL (T1) and B.W (T4): S:I1:I2:imm10:imm11:0.
                let (i1, i2) = (!(j1 ^ s) & 1, !(j2 ^ s) & 1);
                let imm10 = hw1 & 0x3ff;
                let raw = (s << 24) | (i1 << 23) | (i2 << 22) | (imm10 << 12) | (imm11 << 1);
                targets.push(pc.wrapping_add_signed(sign_extend(raw, 25)));
            } else if hw2 >> 14 == 0b10 && !link_or_t4 && (hw1 >> 7) & 0b111 != 0b111 {
                // B<cond>.W (T3): S:J2:J1:imm6:imm11:0.
                let imm6 = hw1 & 0x3f;
                let raw = (s << 20) | (j2 << 19) | (j1 << 18) | (imm6 << 12) | (imm11 << 1);
                targets.push(pc.wrapping_add_signed(sign_extend(raw, 21)));
            }
        }
        i += 4;
    }
    targets
}

fn sign_extend(value: u32, bits: u32) -> i64 {
    let shift = 32 - bits;
    i64::from(((value << shift) as i32) >> shift)
}

/// What [`admission_panics`] found in one image.
#[derive(Debug)]
pub struct PanicPaths {
    /// Functions of the check (named, not inlined).
    pub check_functions: usize,
    /// Functions reachable from them, themselves included.
    pub reachable: usize,
    /// For each panic function the check can reach, one call chain from a function of the check to it (names
    /// demangled).
    pub paths: Vec<Vec<String>>,
}

/// The panic paths of the admission check in `elf`. An error when the image has no function of the check at all
/// (nothing to inspect would pass silently).
pub fn admission_panics(elf: &Path) -> Result<PanicPaths> {
    let image = Image::read(elf)?;
    let roots: Vec<u64> = image
        .functions
        .values()
        .filter(|f| is_check(&f.name))
        .map(|f| f.start)
        .collect();
    if roots.is_empty() {
        bail!(
            "{}: no function of the admission check found (was it inlined away or renamed?)",
            elf.display()
        );
    }
    // Breadth first from every function of the check, keeping each function's caller for the path.
    let mut caller: BTreeMap<u64, Option<u64>> = roots.iter().map(|&r| (r, None)).collect();
    let check_functions = roots.len();
    let mut queue: VecDeque<u64> = roots.into_iter().collect();
    let mut reached_panics = BTreeSet::new();
    while let Some(at) = queue.pop_front() {
        let Some(f) = image.functions.get(&at) else {
            continue;
        };
        if is_panic(&f.name) {
            reached_panics.insert(at);
            continue;
        }
        for target in image.callees(f) {
            if caller.contains_key(&target) {
                continue;
            }
            caller.insert(target, Some(at));
            queue.push_back(target);
        }
    }
    let mut paths = Vec::new();
    for panic in reached_panics {
        let mut path = Vec::new();
        let mut at = Some(panic);
        while let Some(a) = at {
            path.push(image.name(a));
            at = caller.get(&a).copied().flatten();
        }
        path.reverse();
        paths.push(path);
    }
    Ok(PanicPaths {
        check_functions,
        reachable: caller.len(),
        paths,
    })
}

/// Thumb halfwords as the bytes of an image (for tests of the decoders).
/// No image's admission check can reach a panic: it decides on data from the bus. Prints each image's figures.
pub fn check_images(reports: &[crate::elf::SizeReport]) -> Result<()> {
    let mut failures = Vec::new();
    for r in reports.iter().filter(|r| r.analysis_symbols > 0) {
        let found = admission_panics(&r.elf)?;
        println!(
            "{} {}: the admission check ({} functions, {} reachable from them) reaches {} panic path(s)",
            r.board,
            r.revision,
            found.check_functions,
            found.reachable,
            found.paths.len()
        );
        for path in found.paths {
            failures.push(format!("{} {}: {}", r.board, r.revision, path.join(" → ")));
        }
    }
    ensure!(
        failures.is_empty(),
        "the admission check can panic:\n{}",
        failures.join("\n")
    );
    Ok(())
}

#[cfg(test)]
pub(crate) fn thumb(halves: &[u16]) -> Vec<u8> {
    halves.iter().flat_map(|h| h.to_le_bytes()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_calls_and_branches_both_ways() {
        // Instructions of a DiWheelDrive image as llvm-objdump shows them: (address, halfwords, target).
        let cases: [(u64, &[u16], u64); 8] = [
            (0x0801_2fb0, &[0xf7fc, 0xff7c], 0x0800_feac), // bl, backwards
            (0x0800_6222, &[0xf009, 0xfb09], 0x0800_f838), // bl, forwards
            (0x0800_7be0, &[0xf7ff, 0xff0c], 0x0800_79fc), // bl, just behind
            (0x0800_6f78, &[0xf00b, 0xba80], 0x0801_247c), // b.w (a tail call)
            (0x0800_632e, &[0xf000, 0x8162], 0x0800_65f6), // beq.w
            (0x0800_660e, &[0xf040, 0x80b1], 0x0800_6774), // bne.w
            (0x0800_6210, &[0xe7fb], 0x0800_620a),         // b
            (0x0800_62ac, &[0xd1f9], 0x0800_62a2),         // bne
        ];
        for (at, halves, target) in cases {
            assert_eq!(
                branch_targets(&thumb(halves), at),
                vec![target],
                "at {at:#x}"
            );
        }
        // No branch: mov r0, r1; ldr.w r0, [r1, #4]; a 16-bit then a 32-bit instruction stay in step.
        assert!(branch_targets(&thumb(&[0x4608, 0xf8d1, 0x0004]), 0x1000).is_empty());
        let both = thumb(&[0x4608, 0xf8d1, 0x0004, 0xe7fb]);
        // The b at 0x1006 (behind the 32-bit ldr.w) goes back 10 bytes from 0x100a.
        assert_eq!(branch_targets(&both, 0x1000), vec![0x1000]);
    }

    #[test]
    fn knows_a_panic_from_the_check() {
        assert!(is_panic("core::panicking::panic_bounds_check"));
        assert!(is_panic("core::slice::index::slice_index_fail"));
        assert!(is_panic("core::option::unwrap_failed"));
        assert!(!is_panic(
            "core::panicking::panic_const::panic_const_async_fn_resumed"
        ));
        assert!(!is_panic("schedule_analysis::admission::analyse_board"));
        assert!(is_check("schedule_analysis::admission::analyse_board"));
        assert!(is_check(
            "amiro_firmware::admission::Admission<_,_>::on_command"
        ));
        assert!(is_check("amiro_can::diagnostics::AdmissionVerdict::frames"));
        assert!(!is_check("amiro_firmware::tasks::handle_commands"));
    }
}
