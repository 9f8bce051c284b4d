//! The wait scan: finds, in a release ELF's disassembly, every loop that polls memory without a
//! bound — the shape of `while !flag {}` on a peripheral register, whatever source it came from
//! (our code, a HAL, a PAC, an inlined dependency).
//!
//! Why the machine code and not the source: the waits issue 21 found were in the HALs (inlined
//! `Rcc::freeze`, `BlockingI2c`), which a lint of this repository never sees, and a source lint
//! cannot tell a bounded `(0..N).any(..)` from `loop { if .. }` after inlining either. The ELF is
//! what runs. A loop is reported when it is *tight* (a backward branch over at most
//! [`MAX_BODY`] instructions, no call), *polls a peripheral* (it stores nothing and loads from a
//! register the function set to a constant in the peripheral ranges, `0x4000_0000..0x6000_0000`
//! and the core's `0xE000_0000..0xE010_0000`, from a literal or `movw`/`movt`), and has *no counter*
//! (no register stepped by an immediate that was not loaded in the loop: a poll bounded by a count
//! steps one, `(0..N).any(..)` compiles to `subs rX, #1`). A loop that compares a loaded value
//! (such as the DWT cycle counter) against a limit has no counter and is reported too: it is
//! bounded only while that counter runs.
//!
//! What the scan cannot prove bounded is either fixed or listed in [`KNOWN`] with the reason it
//! ends; anything else fails `cargo xtask smoke`. Heuristic limits (docs/faults.md): a wait whose
//! loop calls a function, or stores, or is longer than [`MAX_BODY`], or reads through an address
//! the function did not build from a constant (a driver holding its base in a field, as the
//! runtime's own `Mmio` drivers do — they are bounded by review and host tests), is not seen.
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result};

/// The longest loop body (instructions) taken for a poll.
pub const MAX_BODY: usize = 16;

/// Waits that the scan finds but that end for a stated reason: (source path fragment, reason). A
/// loop is excused when every source line in it outside the core library is under one fragment.
pub const KNOWN: &[(&str, &str)] = &[];

/// One unbounded-looking loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Wait {
    /// The function it is in.
    pub function: String,
    /// Address of its backward branch.
    pub branch: u64,
    /// Source lines in the loop (outside the core library), innermost as the line table gives.
    pub lines: Vec<String>,
}

impl Wait {
    /// Why it is excused, if it is ([`KNOWN`]).
    pub fn known(&self) -> Option<&'static str> {
        self.known_in(KNOWN)
    }

    fn known_in(&self, list: &[(&str, &'static str)]) -> Option<&'static str> {
        list.iter()
            .find(|(fragment, _)| {
                !self.lines.is_empty() && self.lines.iter().all(|l| l.contains(fragment))
            })
            .map(|(_, reason)| *reason)
    }
}

struct Insn {
    addr: u64,
    mnemonic: String,
    operands: String,
    line: Option<String>,
}

/// The waits in `llvm-objdump -d -l --no-show-raw-insn` output.
pub fn scan(disassembly: &str) -> Vec<Wait> {
    // The literal pools: `addr: bytes .word 0x…`.
    let words: HashMap<u64, u32> = disassembly
        .lines()
        .filter_map(|l| {
            let (addr, rest) = l.trim_start().split_once(':')?;
            let (_, value) = rest.split_once(".word")?;
            Some((
                u64::from_str_radix(addr.trim(), 16).ok()?,
                u32::from_str_radix(value.trim().strip_prefix("0x")?, 16).ok()?,
            ))
        })
        .collect();
    let mut waits = Vec::new();
    let mut function = String::new();
    let mut insns: Vec<Insn> = Vec::new();
    let mut line: Option<String> = None;
    let mut flush = |function: &str, insns: &mut Vec<Insn>| {
        waits.extend(loops_in(function, insns, &words));
        insns.clear();
    };
    for text in disassembly.lines() {
        if let Some(name) = text
            .strip_suffix(">:")
            .and_then(|t| t.split_once(" <"))
            .map(|(_, n)| n)
        {
            flush(&function, &mut insns);
            function = name.to_string();
            line = None;
        } else if let Some(location) = text.strip_prefix("; ") {
            if location.contains(".rs:") {
                line = Some(location.trim().to_string());
            }
        } else if let Some((addr, rest)) = text.trim_start().split_once(':') {
            let Ok(addr) = u64::from_str_radix(addr.trim(), 16) else {
                continue;
            };
            if rest.contains(".word") {
                continue;
            }
            let mut fields = rest.split_whitespace();
            let Some(mnemonic) = fields.next() else {
                continue;
            };
            insns.push(Insn {
                addr,
                mnemonic: mnemonic.to_string(),
                operands: fields.collect::<Vec<_>>().join(" "),
                line: line.clone(),
            });
        }
    }
    flush(&function, &mut insns);
    waits
}

fn is_branch(mnemonic: &str) -> bool {
    let m = mnemonic.trim_end_matches(".w").trim_end_matches(".n");
    matches!(m, "b" | "cbz" | "cbnz")
        || (m.len() == 3
            && m.starts_with('b')
            && [
                "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt",
                "gt", "le",
            ]
            .contains(&&m[1..]))
}

fn target(operands: &str) -> Option<u64> {
    operands
        .split([' ', ','])
        .find_map(|f| f.strip_prefix("0x"))
        .and_then(|hex| u64::from_str_radix(hex, 16).ok())
}

/// The destination register of an instruction (its first operand).
fn destination(operands: &str) -> Option<&str> {
    operands
        .split(',')
        .next()
        .map(str::trim)
        .filter(|r| !r.starts_with('{') && !r.starts_with('['))
}

fn is_peripheral(address: u32) -> bool {
    (0x4000_0000..0x6000_0000).contains(&address) || (0xE000_0000..0xE010_0000).contains(&address)
}

fn immediate(operands: &str) -> Option<u32> {
    let text = operands.split('#').nth(1)?.split_whitespace().next()?;
    match text.strip_prefix("0x") {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => text.parse().ok(),
    }
}

/// The registers holding a known constant after `insns` (straight-line view: the last definition
/// wins, anything else that writes a register forgets it).
fn constants(insns: &[Insn], words: &HashMap<u64, u32>) -> HashMap<String, u32> {
    let mut known: HashMap<String, u32> = HashMap::new();
    for insn in insns {
        let Some(rd) = destination(&insn.operands).map(str::to_string) else {
            continue;
        };
        let m = insn.mnemonic.trim_end_matches(".w");
        if m == "ldr" && insn.operands.contains("[pc") {
            let literal = insn
                .operands
                .split('@')
                .nth(1)
                .and_then(target)
                .and_then(|at| words.get(&at).copied());
            match literal {
                Some(value) => known.insert(rd, value),
                None => known.remove(&rd),
            };
        } else if matches!(m, "movw" | "mov" | "movs") && insn.operands.contains('#') {
            match immediate(&insn.operands) {
                Some(value) => known.insert(rd, value),
                None => known.remove(&rd),
            };
        } else if m == "movt" {
            match (known.get(&rd), immediate(&insn.operands)) {
                (Some(low), Some(high)) => {
                    let value = (low & 0xFFFF) | high << 16;
                    known.insert(rd, value)
                }
                _ => known.remove(&rd),
            };
        } else if !m.starts_with("st")
            && !m.starts_with("cmp")
            && !m.starts_with("tst")
            && !m.starts_with('b')
        {
            known.remove(&rd);
        }
    }
    known
}

/// The base register of a load (`ldr r1, [r4, #0x14]` → `r4`).
fn base(operands: &str) -> Option<&str> {
    let inside = operands.split_once('[')?.1;
    Some(inside.split([',', ']']).next()?.trim())
}

fn loops_in(function: &str, insns: &[Insn], words: &HashMap<u64, u32>) -> Vec<Wait> {
    let mut found = Vec::new();
    for (end, branch) in insns.iter().enumerate() {
        if !is_branch(&branch.mnemonic) {
            continue;
        }
        let Some(to) = target(&branch.operands) else {
            continue;
        };
        if to > branch.addr {
            continue;
        }
        let Some(start) = insns.iter().position(|i| i.addr == to) else {
            continue;
        };
        let body = &insns[start..=end];
        if body.len() > MAX_BODY {
            continue;
        }
        let loads: Vec<&str> = body
            .iter()
            .filter(|i| i.mnemonic.starts_with("ldr") || i.mnemonic.starts_with("ldm"))
            .filter_map(|i| destination(&i.operands))
            .collect();
        let calls_or_stores = body.iter().any(|i| {
            matches!(i.mnemonic.as_str(), "bl" | "blx")
                || i.mnemonic.starts_with("str")
                || i.mnemonic.starts_with("stm")
                || i.mnemonic.starts_with("push")
                || i.mnemonic == "wfi"
                || i.mnemonic == "wfe"
        });
        if loads.is_empty() || calls_or_stores {
            continue;
        }
        let known = constants(&insns[..start], words);
        let polls_peripheral = body
            .iter()
            .filter(|i| i.mnemonic.starts_with("ldr") && !i.operands.contains("[pc"))
            .filter_map(|i| base(&i.operands))
            .any(|b| known.get(b).is_some_and(|&a| is_peripheral(a)));
        if !polls_peripheral {
            continue;
        }
        // A counter: a register stepped by an immediate, not one the loop loads.
        let counted = body.iter().any(|i| {
            let m = i.mnemonic.trim_end_matches(".w");
            let stepping = matches!(m, "adds" | "subs" | "add" | "sub" | "addw" | "subw");
            stepping
                && i.operands.contains('#')
                && destination(&i.operands).is_some_and(|d| !loads.contains(&d) && d != "sp")
        });
        if counted {
            continue;
        }
        let mut lines: Vec<String> = body
            .iter()
            .filter_map(|i| i.line.clone())
            .filter(|l| !l.contains("/rustlib/src/rust/library/"))
            .collect();
        lines.dedup();
        found.push(Wait {
            function: function.to_string(),
            branch: branch.addr,
            lines,
        });
    }
    found
}

/// `llvm-objdump` from the toolchain's llvm-tools component.
fn objdump() -> Result<std::path::PathBuf> {
    let sysroot = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .context("running rustc --print sysroot")?;
    let sysroot = String::from_utf8_lossy(&sysroot.stdout).trim().to_string();
    let lib = Path::new(&sysroot).join("lib").join("rustlib");
    std::fs::read_dir(&lib)
        .with_context(|| format!("listing {}", lib.display()))?
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("bin").join("llvm-objdump"))
        .find(|p| p.exists())
        .context("llvm-objdump not found: rustup component add llvm-tools")
}

/// Disassembles `elf` and scans it.
pub fn scan_elf(elf: &Path) -> Result<Vec<Wait>> {
    let out = Command::new(objdump()?)
        .args(["-d", "-l", "--no-show-raw-insn"])
        .arg(elf)
        .output()
        .with_context(|| format!("disassembling {}", elf.display()))?;
    anyhow::ensure!(
        out.status.success(),
        "llvm-objdump failed on {}: {}",
        elf.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(scan(&String::from_utf8_lossy(&out.stdout)))
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIS: &str = "\
080000f0 <poll_forever>:
 80000f0:      \tldr\tr0, [pc, #0x4]         @ 0x80000f8 <poll_forever+0x8>
 80000f2:      \tb\t0x8000100 <poll_forever+0x10>
 80000f8: 00 10 02 40  \t.word\t0x40021000
; /work/amiro-firmware/src/chip.rs:10
 8000100:      \tldr\tr1, [r0]
 8000102:      \tlsls\tr1, r1, #0xe
 8000104:      \tbpl\t0x8000100 <poll_forever> @ imm = #-0x8
 8000106:      \tbx\tlr

08000108 <poll_counted>:
; /work/amiro-firmware/src/clock_tree.rs:60
 8000106:      \tmovw\tr0, #0x1000
 8000107:      \tmovt\tr0, #0x4002
 8000108:      \tldr\tr2, [r0]
 800010a:      \tlsls\tr2, r2, #0xe
 800010c:      \tbmi\t0x8000114 <poll_counted+0xc>
 800010e:      \tsubs\tr1, #0x1
 8000110:      \tbne\t0x8000108 <poll_counted> @ imm = #-0xc
 8000112:      \tbx\tlr

08000114 <poll_on_cycle_counter>:
 8000110:      \tldr\tr4, [pc, #0x4]         @ 0x80000f8 <poll_forever+0x8>
 8000111:      \tmovw\tr4, #0x1004
 8000112:      \tmovt\tr4, #0xe000
; /x/stm32f1xx-hal-0.11.0/src/i2c/blocking.rs:127
 8000114:      \tldr\tr1, [r4]
 8000116:      \tsubs\tr1, r1, r0
 8000118:      \tcmp\tr1, r6
 800011a:      \tblo\t0x8000114 <poll_on_cycle_counter>
 800011c:      \tbx\tlr

08000120 <copy>:
; /x/copy.rs:1
 8000120:      \tldrb\tr3, [r1], #1
 8000124:      \tstrb\tr3, [r0], #1
 8000128:      \tbne\t0x8000120 <copy>
 800012a:      \tbx\tlr

08000140 <walk_list_in_ram>:
 8000140:      \tldr\tr0, [pc, #0x4]         @ 0x8000148 <walk_list_in_ram+0x8>
 8000142:      \tldr\tr0, [r0]
 8000144:      \tcmp\tr0, #0x0
 8000146:      \tbne\t0x8000142 <walk_list_in_ram+0x2>
 8000148: 00 00 00 20  \t.word\t0x20000000

08000130 <idle>:
 8000130:      \twfi
 8000132:      \tb\t0x8000130 <idle>
";

    #[test]
    fn polls_without_a_counter_are_found_and_counted_ones_are_not() {
        let waits = scan(DIS);
        let names: Vec<&str> = waits.iter().map(|w| w.function.as_str()).collect();
        assert_eq!(names, ["poll_forever", "poll_on_cycle_counter"]);
        assert_eq!(waits[0].lines, ["/work/amiro-firmware/src/chip.rs:10"]);
        assert_eq!(waits[0].branch, 0x8000104);
        assert_eq!(waits[0].known(), None);
    }

    #[test]
    fn a_listed_wait_is_excused_only_when_all_of_it_is_listed_code() {
        let list = [("stm32f1xx-hal-0.11.0/src/rcc.rs", "its flags are set first")];
        let hal = Wait {
            function: "freeze".into(),
            branch: 0,
            lines: vec!["/r/stm32f1xx-hal-0.11.0/src/rcc.rs:239".into()],
        };
        assert_eq!(hal.known_in(&list), Some("its flags are set first"));
        let mixed = Wait {
            lines: vec![
                "/r/stm32f1xx-hal-0.11.0/src/rcc.rs:239".into(),
                "/work/board.rs:3".into(),
            ],
            ..hal.clone()
        };
        assert!(mixed.known_in(&list).is_none());
        let unknown_place = Wait {
            lines: vec![],
            ..hal
        };
        assert!(unknown_place.known_in(&list).is_none());
    }
}
