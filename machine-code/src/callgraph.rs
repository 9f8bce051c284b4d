//! Which panics a firmware image's on-chip admission check can reach: the direct calls and tail calls of its
//! machine code (Thumb-2 `BL`, `B.W`, and `B` to another function, decoded by [`crate::decode`]), followed from every function of the check to
//! whatever it calls, so a new `unwrap`, slice index or division by a value from the bus shows up as a path from the
//! check to `core::panicking` — the firmware rule "no panic on data from the bus" kept by the build, not by reading.
//!
//! What it cannot see: calls through a function pointer or a trait object (`BLX` to a register), which the check
//! does not use, and code the linker did not name. Literal pools are skipped (the ELF's `$d` mapping symbols mark
//! them), and an edge counts only when it lands on a function's first instruction.
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;

use crate::{Error, Image};

/// Whether a function belongs to the on-chip admission check: the core analysis, the firmware's admission state and
/// task, the verdict frames (what the size table counts as the check).
pub fn is_check(name: &str) -> bool {
    name.contains("schedule_analysis::") || name.to_lowercase().contains("admission")
}

/// Whether reaching this function means a panic can happen: `core::panicking::*`, the slice and `Option`/`Result`
/// failure paths (`slice_index_fail`, `unwrap_failed`, ...).
pub fn is_panic(name: &str) -> bool {
    // The compiler's guard against polling a finished `async fn` again: the RTIC executor never does.
    if name.contains("panic_const_async_fn_resumed") {
        return false;
    }
    name.contains("panic") || name.ends_with("_fail") || name.ends_with("_failed")
}

/// Whether a function is the Rust library's panic machinery: a panic by [`is_panic`]'s names, in `core::`,
/// `alloc::` or `std::` (`core::panicking::panic_fmt`, `core::option::unwrap_failed`, ...), functions the library
/// declares `-> !`. The WCET analysis takes these alone by name as never returning; whether any other function
/// returns it reads from its code (a firmware function named `..._failed` may well return).
pub fn is_library_panic(name: &str) -> bool {
    ["core::", "alloc::", "std::"]
        .iter()
        .any(|crate_| name.starts_with(crate_))
        && is_panic(name)
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
pub fn admission_panics(elf: &Path) -> Result<PanicPaths, Error> {
    admission_panics_in(&Image::read(elf)?).map_err(|e| match e {
        Error::Other(m) => Error::Other(format!("{}: {m}", elf.display())),
        other => other,
    })
}

/// The panic paths of the admission check in `image` (see [`admission_panics`]).
pub fn admission_panics_in(image: &Image) -> Result<PanicPaths, Error> {
    let roots: Vec<u64> = image
        .functions
        .values()
        .filter(|f| is_check(&f.name))
        .map(|f| f.start)
        .collect();
    if roots.is_empty() {
        return Err(Error::Other(
            "no function of the admission check found (was it inlined away or renamed?)".into(),
        ));
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
        for target in image.callees(f)? {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode;
    use crate::thumb;

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
            let insns = decode("f", at, &thumb(halves), &[]).unwrap();
            let targets: Vec<u64> = insns.iter().filter_map(|i| i.direct_target()).collect();
            assert_eq!(targets, vec![target], "at {at:#x}");
        }
        // No branch: mov r0, r1; ldr.w r0, [r1, #4]; a 16-bit then a 32-bit instruction stay in step.
        let none = decode("f", 0x1000, &thumb(&[0x4608, 0xf8d1, 0x0004]), &[]).unwrap();
        assert!(none.iter().all(|i| i.direct_target().is_none()));
        let both = decode("f", 0x1000, &thumb(&[0x4608, 0xf8d1, 0x0004, 0xe7fb]), &[]).unwrap();
        // The b at 0x1006 (behind the 32-bit ldr.w) goes back 10 bytes from 0x100a.
        let targets: Vec<u64> = both.iter().filter_map(|i| i.direct_target()).collect();
        assert_eq!(targets, vec![0x1000]);
        // cbz r0, +4 at 0x1000 goes to 0x1008 (PC + 4).
        let cbz = decode("f", 0x1000, &thumb(&[0xb110]), &[]).unwrap();
        assert_eq!(cbz[0].direct_target(), Some(0x1008));
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

    #[test]
    fn only_the_librarys_panics_are_known_by_name_not_to_return() {
        assert!(is_library_panic("core::panicking::panic_bounds_check"));
        assert!(is_library_panic("core::option::unwrap_failed"));
        assert!(is_library_panic("std::panicking::begin_panic"));
        // The firmware's own `..._failed` functions return (DiWheelDrive's floor and compass steps):
        // a panic for the admission check's names, not known by name to end the path.
        assert!(is_panic("amiro_firmware::sensors::floor_failed"));
        assert!(!is_library_panic("amiro_firmware::sensors::floor_failed"));
        assert!(!is_library_panic(
            "core::panicking::panic_const::panic_const_async_fn_resumed"
        ));
    }
}
