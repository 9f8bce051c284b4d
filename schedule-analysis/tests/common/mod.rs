//! Helpers shared by the integration tests that build a workspace of their own.

use std::path::{Path, PathBuf};

use schedule_analysis::scenario;

/// The workspace's root (this crate's parent).
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// A workspace of its own under the temporary folder, named by `tag`: the boards' apps linked, a copy of the
/// models folder (which a test may then change), and, when given, `dwd_bounds` as DiWheelDrive 1-1's generated
/// bounds file.
#[allow(dead_code)]
pub fn scratch_workspace(tag: &str, dwd_bounds: Option<&serde_json::Value>) -> PathBuf {
    let root = std::env::temp_dir().join(format!("{tag}-{}", std::process::id()));
    scratch_workspace_at(root, dwd_bounds)
}

/// [`scratch_workspace`] at `root` (emptied first): a test binary that keeps one workspace for all its tests puts it
/// under its `CARGO_TARGET_TMPDIR`, so that each run replaces the last one's.
#[allow(dead_code)]
pub fn scratch_workspace_at(root: PathBuf, dwd_bounds: Option<&serde_json::Value>) -> PathBuf {
    let real = workspace();
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    for board in ["diwheeldrive", "powermgmt", "lightring"] {
        std::os::unix::fs::symlink(real.join(board), root.join(board)).unwrap();
    }
    let models = root.join(scenario::MODELS_DIR);
    copy_dir(&real.join(scenario::MODELS_DIR), &models);
    if let Some(bounds) = dwd_bounds {
        std::fs::write(
            models.join("diwheeldrive-1-1.wcet.json"),
            bounds.to_string(),
        )
        .unwrap();
    }
    root
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// Rewrites `root`'s 900 µs magnetometer set with its frames' deadline at 1 500 µs and no expected failures: the
/// shipped set (deadline = period) is a checked refusal on the sound transmit path (1 116.0 µs on 1-1, 2026-12-05),
/// and the tests that break a passing set by a bound need one that passes on its stated budgets. The publisher's
/// period, and with it every job's deadline on the CPU, stays 900 µs.
#[allow(dead_code)]
pub fn passing_magnetometer_set(root: &Path) {
    let path = root
        .join(scenario::MODELS_DIR)
        .join("thesis-magnetometer-900us.scenario.json");
    let mut sc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    sc["publishers"][0]["deadline_us"] = 1500.into();
    sc.as_object_mut().unwrap().remove("expected_failures");
    std::fs::write(&path, sc.to_string()).unwrap();
}
