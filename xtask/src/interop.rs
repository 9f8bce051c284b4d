//! Interop with other CAN tools: cantools loads `amiro dbc` and decodes sample frames to the values `amiro decode`
//! prints; python-can's `CanutilsLogReader` and can-utils' `log2long` / `log2asc` read the candump logs `amiro`
//! writes (`canplayer` needs a CAN interface, and CI kernels have no vcan, so it is not run here); Foxglove's
//! Python `mcap` reader opens the MCAP recordings of `amiro record` and `amiro decode --mcap` and finds every
//! topic's channel and JSON schema, the values of `decode --json` and each frame's time as the log time.
//!
//! Foxglove's own WebSocket client (`@foxglove/ws-protocol`, run with node) subscribes to `amiro monitor --foxglove`.
//!
//! The example behaviours in `examples/` close the loop against amiro-world's `world-loop` (`test_world_examples.py`).
//!
//! The checks are `tools/interop/test_interop.py`, `test_mcap.py`, `test_foxglove.py` and the others there, run with pytest in a
//! venv under the target directory that holds exactly `tools/requirements-ci.txt`; the venv is rebuilt only when
//! that file changes.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::workspace;

/// pytest's exit code when it collected no tests: a renamed file must not pass silently.
const PYTEST_NO_TESTS: i32 = 5;

/// Sets up the pinned tools (and can-utils), builds `amiro`, and runs the interop checks.
pub fn check(root: &Path) -> Result<()> {
    let work = crate::workspace::target_dir(root).join("interop");
    let python = venv(root, &work)?;
    ensure_can_utils()?;
    ensure_node()?;
    // With the live Foxglove server, which Foxglove's own WebSocket client checks (tools/interop/test_foxglove.py).
    crate::workspace::cargo(
        root,
        &[
            "build",
            "--quiet",
            "-p",
            "operator",
            "--bin",
            "amiro",
            "--features",
            "foxglove",
        ],
    )
    .context("building amiro for the interop checks")?;
    // amiro-world's kinematic loop, for the example behaviours (tools/interop/test_world_examples.py).
    crate::workspace::cargo(
        root,
        &[
            "build",
            "--quiet",
            "-p",
            "amiro-world",
            "--bin",
            "world-loop",
        ],
    )
    .context("building world-loop for the interop checks")?;
    let amiro = crate::workspace::target_dir(root)
        .join("debug")
        .join("amiro");
    let world_loop = crate::workspace::target_dir(root)
        .join("debug")
        .join("world-loop");
    println!("interop: cantools, python-can, can-utils, the mcap reader and the Foxglove client against amiro");
    let status = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("tools").join("interop"))
        .env("AMIRO", &amiro)
        .env("AMIRO_WORLD_LOOP", &world_loop)
        .env("AMIRO_INTEROP_DIR", &work)
        // `cargo xtask robot --slcan` for tools/interop/test_robot_slcan.py.
        .env("AMIRO_XTASK", std::env::current_exe()?)
        // The bus logs of the QEMU scenarios (`bus.log` per run): other tools must read them too.
        .env(
            "AMIRO_QEMU_SCENARIOS",
            crate::qemu::target_dir(root).join("scenarios"),
        )
        .current_dir(root)
        .status()
        .with_context(|| format!("running pytest with {}", python.display()))?;
    match status.code() {
        Some(0) => Ok(()),
        Some(PYTEST_NO_TESTS) => bail!("interop: pytest found no tests in tools/interop"),
        Some(code) => bail!("interop checks failed (pytest exit code {code})"),
        None => bail!("interop checks were killed by a signal"),
    }
}

/// The venv's python, with `tools/requirements-ci.txt` installed; reuses the venv while the file is unchanged.
pub(crate) fn venv(root: &Path, work: &Path) -> Result<PathBuf> {
    let requirements = root.join("tools").join("requirements-ci.txt");
    let pinned = std::fs::read_to_string(&requirements)
        .with_context(|| format!("reading {}", requirements.display()))?;
    let venv = work.join("venv");
    let python = venv.join("bin").join("python");
    let stamp = venv.join("requirements-ci.txt");
    if python.exists() && std::fs::read_to_string(&stamp).ok().as_deref() == Some(&pinned) {
        return Ok(python);
    }
    if venv.exists() {
        std::fs::remove_dir_all(&venv).with_context(|| format!("removing {}", venv.display()))?;
    }
    std::fs::create_dir_all(work).with_context(|| format!("creating {}", work.display()))?;
    let venv_text = venv.to_string_lossy();
    crate::workspace::run_tool(root, "python3", &["-m", "venv", venv_text.as_ref()]).context(
        "creating the interop venv (needs python3 with venv; Debian: apt-get install python3-venv)",
    )?;
    let requirements_text = requirements.to_string_lossy();
    let python_text = python.to_string_lossy();
    crate::workspace::run_tool(
        root,
        python_text.as_ref(),
        &[
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--require-virtualenv",
            "-r",
            requirements_text.as_ref(),
        ],
    )
    .context("installing tools/requirements-ci.txt")?;
    std::fs::write(&stamp, pinned).with_context(|| format!("writing {}", stamp.display()))?;
    Ok(python)
}

/// Node and npm for Foxglove's WebSocket client (`@foxglove/ws-protocol`, pinned in
/// tools/interop/foxglove-client/package-lock.json); installed with apt when running as root, like can-utils.
fn ensure_node() -> Result<()> {
    if workspace::runs("node", &["--version"]) && workspace::runs("npm", &["--version"]) {
        return Ok(());
    }
    workspace::apt_install(&["nodejs", "npm"], "node and npm are missing")
}

/// can-utils' log converters; installed with apt when running as root (as CI does), like QEMU.
fn ensure_can_utils() -> Result<()> {
    if workspace::runs("log2long", &[]) {
        return Ok(());
    }
    workspace::apt_install(&["can-utils"], "can-utils is missing")
}
