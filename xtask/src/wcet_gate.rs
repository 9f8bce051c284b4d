//! The bounds files' staleness gate: each board's generated `schedule-analysis/models/<board>[-<rev>].wcet.json`
//! must have been computed from the release image CI has just built, as a lock file must match its manifest.
//!
//! An image's identity is the SHA-256 of its executable section bytes (`SHF_EXECINSTR`, in address order):
//! what the bounds are computed from. Read-only data is left out on purpose: the admission table the bounds
//! feed into is read-only data, so writing new bounds does not by itself make them stale (docs/analysis.md,
//! "Budgets from the machine code").
use std::path::Path;

use anyhow::{bail, Context, Result};
use object::{Object, ObjectSection, SectionFlags};
use schedule_analysis::bounds::{self, BoundsFile, ImageIdentity};
use sha2::{Digest, Sha256};

use crate::boards::BOARDS;
use crate::revision::{self, Build, Choice};

/// `SHF_EXECINSTR`: the section holds machine code.
const SHF_EXECINSTR: u64 = 0x4;

/// The identity of an ELF image: the SHA-256 of its executable sections' bytes, in address order, and how many
/// bytes that is. An ELF without executable bytes, or one `object` cannot read, is an error.
pub fn image_identity(elf: &[u8]) -> Result<ImageIdentity> {
    let file = object::File::parse(elf).context("not an ELF image `object` can read")?;
    let mut sections: Vec<_> = file
        .sections()
        .filter(|s| match s.flags() {
            SectionFlags::Elf { sh_flags } => sh_flags & SHF_EXECINSTR != 0,
            _ => false,
        })
        .collect();
    sections.sort_by_key(|s| s.address());
    let mut hash = Sha256::new();
    let mut bytes = 0u64;
    for s in &sections {
        let data = s
            .data()
            .with_context(|| format!("reading section {}", s.name().unwrap_or("?")))?;
        hash.update(data);
        bytes += data.len() as u64;
    }
    if bytes == 0 {
        bail!("the image has no executable bytes");
    }
    let code_sha256 = hash.finalize().iter().map(|b| format!("{b:02x}")).collect();
    Ok(ImageIdentity {
        code_sha256,
        code_bytes: bytes,
    })
}

/// The bounds file of a build, relative to the workspace root.
pub fn bounds_path(root: &Path, build: &Build) -> std::path::PathBuf {
    let revision = build.revision.feature.and_then(|f| f.strip_prefix("rev-"));
    bounds::path_for(
        &root.join(schedule_analysis::scenario::MODELS_DIR),
        build.board.name,
        revision,
    )
}

/// `path` as the gate names it: from the workspace root.
fn shown(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

/// What the gate found for one image.
#[derive(Debug, PartialEq)]
pub enum Gate {
    /// The file matches the image.
    Current,
    /// No bounds file (the CI gate fails on it).
    NoFile,
}

/// Checks one build's bounds file against its release ELF `elf`.
pub fn check_one(root: &Path, build: &Build, elf: &Path) -> Result<Gate> {
    let path = bounds_path(root, build);
    let name = shown(root, &path);
    let Some(file) = BoundsFile::read(&path, &name)? else {
        return Ok(Gate::NoFile);
    };
    let revision = build.revision.feature.and_then(|f| f.strip_prefix("rev-"));
    file.check_image(&name, build.board.name, revision)?;
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let built = image_identity(&bytes).with_context(|| elf.display().to_string())?;
    if built != file.image {
        bail!(
            "{name} is out of date with the image {} (its code: {} bytes, SHA-256 {}; the file's: {} bytes, {}): \
             run `cargo xtask wcet --write` and commit the file",
            elf.display(),
            built.code_bytes,
            built.code_sha256,
            file.image.code_bytes,
            file.image.code_sha256
        );
    }
    Ok(Gate::Current)
}

/// The CI gate: every board revision's bounds file must exist and match its release image as built
/// (`target/firmware/<stem>.elf`, after `cargo xtask test` built them).
pub fn check_bounds_current(root: &Path) -> Result<()> {
    let every = revision::plan(&BOARDS.iter().collect::<Vec<_>>(), &Choice::All)?;
    let mut missing = Vec::new();
    for build in &every {
        let elf = crate::workspace::kept_elf(root, build, false);
        let name = shown(root, &bounds_path(root, build));
        match check_one(root, build, &elf)? {
            Gate::Current => println!("bounds gate: {name} matches {}", build.stem()),
            Gate::NoFile => missing.push(name),
        }
    }
    if !missing.is_empty() {
        bail!(
            "no generated bounds file {}: run `cargo xtask wcet --write` and commit them",
            missing.join(", ")
        );
    }
    check_stated_places(root, &every)
}

/// Every entry of each board's stated bounds file (`schedule-analysis/models/<board>.bounds.json`) must name a
/// place in at least one of the board's images, its `scripted-i2c` trial's among them (an entry for the trial's
/// own code: the trial is built by CI's check step in `target/scripted-i2c`, so the build here finds it
/// current): an entry keyed to a line the source no longer has there would silently stop bounding its loop.
fn check_stated_places(root: &Path, every: &[Build]) -> Result<()> {
    let trials = crate::revision::scripted_i2c_builds(every);
    let mut stale = Vec::new();
    for board in BOARDS.iter() {
        let path = root
            .join("schedule-analysis")
            .join("models")
            .join(format!("{}.bounds.json", board.name));
        if !path.exists() {
            continue;
        }
        let stated = machine_code::wcet::bounds::BoundsFile::read(&path)?;
        let mut left: Option<Vec<String>> = None;
        let shipped = every
            .iter()
            .filter(|b| b.board.name == board.name)
            .map(|b| Ok(crate::workspace::kept_elf(root, b, false)));
        let trial = trials
            .iter()
            .filter(|b| b.board.name == board.name)
            .map(|b| crate::workspace::build_trial(root, b, &["scripted-i2c"]));
        for elf in shipped.chain(trial) {
            let elf = elf?;
            let image =
                machine_code::Image::read(&elf).with_context(|| elf.display().to_string())?;
            let here = stated.missing_places(&image);
            left = Some(match left {
                None => here,
                Some(before) => before.into_iter().filter(|m| here.contains(m)).collect(),
            });
        }
        for entry in left.unwrap_or_default() {
            stale.push(format!(
                "{}: {entry}",
                path.strip_prefix(root).unwrap_or(&path).display()
            ));
        }
    }
    if !stale.is_empty() {
        bail!(
            "stated bounds whose place is in none of the board's images (the source moved: correct the line, \
             or remove the entry):\n  {}",
            stale.join("\n  ")
        );
    }
    println!("bounds gate: every stated bound names a place in its board's images");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal little-endian ELF32 with a code section (`.text`, alloc + exec) at 0x0800_6000 and a read-only
    /// data section (`.rodata`, alloc) after it; no segments, no symbols.
    fn elf(code: &[u8], rodata: &[u8]) -> Vec<u8> {
        let names = b"\0.text\0.rodata\0.shstrtab\0";
        let text_at = 52u32;
        let rodata_at = text_at + code.len() as u32;
        let names_at = rodata_at + rodata.len() as u32;
        let shoff = (names_at + names.len() as u32 + 3) & !3;
        let mut out = crate::elf::elf32_header(0, shoff, [0, 4, 3]);
        out.extend_from_slice(code);
        out.extend_from_slice(rodata);
        out.extend_from_slice(names);
        out.resize(shoff as usize, 0);
        let rodata_addr = 0x0800_6000 + code.len() as u32;
        // name, type, flags, addr, offset, size, link, info, addralign, entsize
        let headers: [[u32; 10]; 4] = [
            [0; 10],
            [
                1,
                1,
                0x6,
                0x0800_6000,
                text_at,
                code.len() as u32,
                0,
                0,
                2,
                0,
            ],
            [
                7,
                1,
                0x2,
                rodata_addr,
                rodata_at,
                rodata.len() as u32,
                0,
                0,
                1,
                0,
            ],
            [15, 3, 0, 0, names_at, names.len() as u32, 0, 0, 1, 0],
        ];
        for h in headers {
            for v in h {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    #[test]
    fn the_identity_is_the_code_and_only_the_code() {
        let a = image_identity(&elf(&[0x70, 0x47, 0x00, 0xbf], b"table")).unwrap();
        assert_eq!(a.code_bytes, 4);
        assert_eq!(a.code_sha256.len(), 64);
        // SHA-256 of 70 47 00 bf, as `sha256sum` gives it.
        assert_eq!(
            a.code_sha256,
            "0c302d771ae76f031fe8c4a87c6f54f6b1e93bbf4552d26a8ea553f2a89c0530"
        );
        // Other read-only data: the same identity; one code byte changed: another.
        assert_eq!(
            image_identity(&elf(&[0x70, 0x47, 0x00, 0xbf], b"other")).unwrap(),
            a
        );
        assert_ne!(
            image_identity(&elf(&[0x70, 0x47, 0x01, 0xbf], b"table")).unwrap(),
            a
        );
    }

    #[test]
    fn not_an_image_is_an_error() {
        assert!(image_identity(b"not an elf").is_err());
        assert!(image_identity(&elf(&[], b"data only")).is_err());
    }

    fn bounds_for(identity: &ImageIdentity) -> String {
        serde_json::json!({
            "generated": format!("{} from a test image", bounds::GENERATED_PREFIX),
            "board": "powermgmt", "revision": "1-2", "chip": "stm32f405",
            "clock_hz": 168_000_000, "wait_states": 5,
            "image": identity,
            "tasks": [ { "task": "can_rx", "cycles": 168, "us": 1.0, "instructions": 100, "declined": null } ]
        })
        .to_string()
    }

    #[test]
    fn the_gate_passes_a_current_file_fails_a_stale_one_and_skips_a_missing_one() {
        let root = std::env::temp_dir().join(format!("wcet-gate-{}", std::process::id()));
        let models = root.join(schedule_analysis::scenario::MODELS_DIR);
        std::fs::create_dir_all(&models).unwrap();
        let build = revision::plan(
            &[crate::boards::by_name("powermgmt").unwrap()],
            &Choice::Newest,
        )
        .unwrap()
        .remove(0);
        let image = root.join("powermgmt.elf");
        std::fs::write(&image, elf(&[0x70, 0x47, 0x00, 0xbf], b"")).unwrap();
        assert_eq!(check_one(&root, &build, &image).unwrap(), Gate::NoFile);
        let current = image_identity(&std::fs::read(&image).unwrap()).unwrap();
        std::fs::write(bounds_path(&root, &build), bounds_for(&current)).unwrap();
        assert_eq!(check_one(&root, &build, &image).unwrap(), Gate::Current);
        // The image is rebuilt with other code: the file is stale.
        std::fs::write(&image, elf(&[0x70, 0x47, 0x00, 0x00], b"")).unwrap();
        let e = check_one(&root, &build, &image).unwrap_err().to_string();
        assert!(
            e.contains("out of date") && e.contains("powermgmt-1-2.wcet.json"),
            "{e}"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// The committed files: one per image, each for its image, and each refuses an image with other code.
    #[test]
    fn every_image_has_its_committed_bounds_file_and_another_image_fails_it() {
        let root = crate::workspace::workspace_root();
        let dir = std::env::temp_dir().join(format!("wcet-gate-real-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let other = dir.join("other.elf");
        std::fs::write(&other, elf(&[0x70, 0x47, 0x00, 0xbf], b"")).unwrap();
        let every = revision::plan(&BOARDS.iter().collect::<Vec<_>>(), &Choice::All).unwrap();
        assert_eq!(every.len(), 6);
        for build in &every {
            let path = bounds_path(&root, build);
            let file = BoundsFile::read(&path, "f")
                .unwrap()
                .unwrap_or_else(|| panic!("{} is not committed", path.display()));
            assert_eq!(file.board, build.board.name);
            let e = check_one(&root, build, &other).unwrap_err().to_string();
            assert!(
                e.contains("out of date") && e.contains(&file.image.code_sha256),
                "{e}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
