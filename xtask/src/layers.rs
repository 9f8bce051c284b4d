//! The firmware runtime's layers (ARCHITECTURE.md, *Layers of the runtime*): which of
//! `amiro-firmware`'s platform, output and timing modules may name which. `cargo xtask check`
//! fails when a module names one in its own layer or above, so the QEMU platform stays below the
//! tracing and the two output paths never call each other in a circle again.
use std::path::Path;

use anyhow::{bail, Context, Result};

/// The layers, lowest first: a module may name (`crate::NAME`) only modules before it.
pub const LAYERS: [&str; 7] = [
    // Counters every task bumps: names nothing.
    "health",
    // The QEMU platform: SysTick and its timer queues, the stimulus, the robot's exchange.
    "qemu",
    // Where bytes go: RTT, or QEMU's console and trace file.
    "channels",
    // The task-level trace records.
    "tracing",
    // The tasks' clock (its waits write trace records) and the QEMU build's start.
    "mono",
    // Trace events and the human log.
    "telemetry",
    // The task bodies every board shares.
    "tasks",
];

/// The modules of [`LAYERS`] that `source` names as `crate::NAME` (or `$crate::NAME`) outside
/// comments; `crate::log!` names `telemetry`, whose macro it is.
pub fn named_modules(source: &str) -> Vec<&'static str> {
    let mut named = Vec::new();
    for line in source.lines() {
        let code = line.split("//").next().unwrap_or_default();
        for (at, _) in code.match_indices("crate::") {
            let rest = &code[at + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            let name = if name == "log" && rest[3..].starts_with('!') {
                "telemetry".to_string()
            } else {
                name
            };
            if let Some(&m) = LAYERS.iter().find(|&&m| m == name) {
                if !named.contains(&m) {
                    named.push(m);
                }
            }
        }
    }
    named
}

/// Every edge from a module to one in its own layer or above, as `from → to`.
pub fn violations(sources: &[(&str, String)]) -> Vec<String> {
    let rank = |m: &str| LAYERS.iter().position(|&l| l == m);
    let mut wrong = Vec::new();
    for (module, source) in sources {
        let Some(from) = rank(module) else { continue };
        for to in named_modules(source) {
            if to != *module && rank(to).is_some_and(|r| r >= from) {
                wrong.push(format!("{module} → {to}"));
            }
        }
    }
    wrong
}

/// Reads each layer's sources (`src/NAME.rs` and everything under `src/NAME/`) and fails on an
/// edge that does not point down.
pub fn check(root: &Path) -> Result<()> {
    let src = root.join("amiro-firmware/src");
    let mut sources = Vec::new();
    for module in LAYERS {
        let mut text = std::fs::read_to_string(src.join(format!("{module}.rs")))
            .with_context(|| format!("amiro-firmware/src/{module}.rs"))?;
        if let Ok(dir) = std::fs::read_dir(src.join(module)) {
            let mut files: Vec<_> = dir.flatten().map(|e| e.path()).collect();
            files.sort();
            for file in files
                .iter()
                .filter(|f| f.extension().is_some_and(|e| e == "rs"))
            {
                text.push_str(&std::fs::read_to_string(file)?);
            }
        }
        sources.push((module, text));
    }
    let wrong = violations(&sources);
    if !wrong.is_empty() {
        bail!(
            "amiro-firmware's runtime layers ({}, lowest first) point up or sideways: {}",
            LAYERS.join(" < "),
            wrong.join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_outside_comments_only() {
        let source = "//! [`crate::tracing`] writes here\nuse crate::qemu::TICK_US;\n\
                      let x = crate::health::rx_dropped(); // crate::tasks\n\
                      $crate::telemetry::log_parts(&[]);\nuse crate::can::Frame;";
        assert_eq!(named_modules(source), vec!["qemu", "health", "telemetry"]);
        assert_eq!(named_modules("crate::log!(\"up\");"), vec!["telemetry"]);
        assert!(named_modules("crate::logger::x").is_empty());
    }

    #[test]
    fn an_edge_up_is_refused_and_a_circle_always_has_one() {
        let sources = [
            ("qemu", "use crate::health::x;".to_string()),
            ("tracing", "crate::telemetry::write_trace".to_string()),
            ("telemetry", "crate::tracing::event()".to_string()),
        ];
        assert_eq!(violations(&sources), vec!["tracing → telemetry"]);
        assert!(violations(&sources[..1]).is_empty());
    }

    #[test]
    fn the_firmware_runtime_is_layered() {
        check(&Path::new(env!("CARGO_MANIFEST_DIR")).join("..")).unwrap();
    }
}
