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
//! venv that holds exactly `tools/requirements-ci.txt` (`target/interop/venv`, a link to the one kept in the user's
//! cache per pinned file and python version, so a fresh checkout does not install the same pins again).

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
    // `amiro` with the live Foxglove server, which Foxglove's own WebSocket client checks
    // (tools/interop/test_foxglove.py), and amiro-world's kinematic loop for the example behaviours
    // (tools/interop/test_world_examples.py). One invocation over the default members with their examples, as the
    // host tests build them: the feature `foxglove` adds its own crates and features, but syn, serde, clap and the
    // rest keep the features of that build and are not built again (`-p operator` alone resolved them apart).
    crate::workspace::cargo(
        root,
        &[
            "build",
            "--quiet",
            "--bin",
            "amiro",
            "--bin",
            "world-loop",
            "--examples",
            "--features",
            "operator/foxglove",
        ],
    )
    .context("building amiro (with foxglove) and world-loop for the interop checks")?;
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
            crate::workspace::qemu_target_dir(root).join("scenarios"),
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

/// The venv's python, with `tools/requirements-ci.txt` installed: `work/venv`, a link to the venv kept in the
/// user's cache (`~/.cache/amiro/interop-venv-<hash>`, the hash of the pinned file and of `python3 --version`), so
/// a fresh checkout on a machine that has run CI before reuses it instead of installing the same pins again (the
/// cargo registry and the toolchain are reused alike); without a cache folder the venv itself is `work/venv`. The
/// stamp (the pinned file's text) is written last, so a venv half made by an interrupted run is made again.
pub(crate) fn venv(root: &Path, work: &Path) -> Result<PathBuf> {
    let requirements = root.join("tools").join("requirements-ci.txt");
    let pinned = std::fs::read_to_string(&requirements)
        .with_context(|| format!("reading {}", requirements.display()))?;
    std::fs::create_dir_all(work).with_context(|| format!("creating {}", work.display()))?;
    let link = work.join("venv");
    let Some(cache) = cache_dir() else {
        let python = link.join("bin").join("python");
        if !is_current(&link, &pinned) {
            if link.symlink_metadata().is_ok() {
                remove_any(&link)?;
            }
            make_venv(root, &requirements, &pinned, &link)?;
        }
        return Ok(python);
    };
    let python_version = workspace::output(root, "python3", &["--version"]).unwrap_or_default();
    let key = {
        use sha2::{Digest, Sha256};
        let mut hash = Sha256::new();
        hash.update(pinned.as_bytes());
        hash.update(python_version.trim().as_bytes());
        hash.finalize()
            .iter()
            .take(8)
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    let kept = cache.join(format!("interop-venv-{key}"));
    if !is_current(&kept, &pinned) {
        std::fs::create_dir_all(&cache).with_context(|| format!("creating {}", cache.display()))?;
        // One run makes it, a concurrent one waits for it (the lock goes with the file's closing).
        let lock_path = cache.join(format!("interop-venv-{key}.lock"));
        let lock = std::fs::File::create(&lock_path)
            .with_context(|| format!("creating {}", lock_path.display()))?;
        {
            use std::os::fd::AsRawFd;
            // SAFETY: flock on a file descriptor this function owns for the call.
            if unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX) } != 0 {
                bail!("locking {}", lock_path.display());
            }
        }
        if !is_current(&kept, &pinned) {
            if kept.symlink_metadata().is_ok() {
                // Half made (no stamp) or damaged: made again.
                remove_any(&kept)?;
            }
            make_venv(root, &requirements, &pinned, &kept)?;
        }
        drop(lock);
    }
    if std::fs::read_link(&link).ok().as_deref() != Some(kept.as_path()) {
        if link.symlink_metadata().is_ok() {
            remove_any(&link)?;
        }
        std::os::unix::fs::symlink(&kept, &link)
            .with_context(|| format!("linking {} to {}", link.display(), kept.display()))?;
    }
    Ok(link.join("bin").join("python"))
}

/// Where the interop venv is kept between checkouts: `$XDG_CACHE_HOME/amiro` or `~/.cache/amiro`.
fn cache_dir() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|d| !d.is_empty())
                .map(|home| PathBuf::from(home).join(".cache"))
        })?;
    Some(base.join("amiro"))
}

/// Whether the venv at `venv` has a python and was made from exactly `pinned`.
fn is_current(venv: &Path, pinned: &str) -> bool {
    venv.join("bin").join("python").exists()
        && std::fs::read_to_string(venv.join("requirements-ci.txt"))
            .ok()
            .as_deref()
            == Some(pinned)
}

fn remove_any(path: &Path) -> Result<()> {
    let meta = path.symlink_metadata()?;
    if meta.is_dir() {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    }
    .with_context(|| format!("removing {}", path.display()))
}

/// Makes a venv at `venv` with `requirements` installed, stamped with their text `pinned`.
fn make_venv(root: &Path, requirements: &Path, pinned: &str, venv: &Path) -> Result<()> {
    let venv_text = venv.to_string_lossy();
    crate::workspace::run_tool(root, "python3", &["-m", "venv", venv_text.as_ref()]).context(
        "creating the interop venv (needs python3 with venv; Debian: apt-get install python3-venv)",
    )?;
    let requirements_text = requirements.to_string_lossy();
    let python = venv.join("bin").join("python");
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
    let stamp = venv.join("requirements-ci.txt");
    std::fs::write(&stamp, pinned).with_context(|| format!("writing {}", stamp.display()))
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
