//! What the trials' analysis tests share: a script's counts on the wire and a scratch copy of the workspace's
//! timing files.

use std::path::{Path, PathBuf};

use amiro_sensors::script::{Script, Symbol};
use schedule_analysis::analysis::{analyse, Analysis, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;

/// Bytes (address bytes included) and STARTs (operation starts and repeated STARTs) on the wire.
pub fn wire_counts(script: &Script) -> (u32, u32) {
    script
        .wire()
        .fold((0, 0), |(bytes, starts), symbol| match symbol {
            Symbol::Start | Symbol::RepeatedStart => (bytes, starts + 1),
            Symbol::Stop => (bytes, starts),
            _ => (bytes + 1, starts),
        })
}

/// The workspace's root.
pub fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .to_path_buf()
}

/// Copies the directory `from` to `to`, recursively.
pub fn copy_dir(from: &Path, to: &Path) {
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

/// The thesis demo's report on the timing files under `root` (exact frame costs).
#[allow(dead_code)]
pub fn thesis_demo(root: &Path) -> Analysis {
    let file = root
        .join(scenario::MODELS_DIR)
        .join("thesis-demo.scenario.json");
    let built = scenario::build(root, &file, &scenario::timing_files(root))
        .unwrap_or_else(|e| panic!("{e}"));
    analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    )
}
