//! Board revisions in the build (`--revision`): which image of each board a command builds, how
//! cargo is told (a `rev-*` feature), where each revision's ELF is kept, and which timing files the
//! analysis reads for it (`AMIRO_REVISION`, schedule_analysis::scenario::REVISION_ENV).
use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::boards::{Board, Revision, ROBOT_REVISIONS};

/// What `--revision` asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Choice {
    /// Each board's newest image (no `--revision`).
    Newest,
    /// The images for a robot of this revision (`1-1`, `1-2`).
    Robot(&'static str),
    /// Every revision of every board (`all`: CI).
    All,
}

impl Choice {
    /// Parses `--revision`: absent, `1-1`, `1-2` or `all`.
    pub fn parse(text: Option<&str>) -> Result<Self> {
        match text {
            None => Ok(Choice::Newest),
            Some("all") => Ok(Choice::All),
            Some(r) => ROBOT_REVISIONS
                .iter()
                .find(|known| **known == r)
                .map(|known| Choice::Robot(known))
                .with_context(|| {
                    format!("--revision {r}: expected one of {ROBOT_REVISIONS:?} or all")
                }),
        }
    }
}

/// One image to build: a board at one of its revisions.
#[derive(Debug, Clone, Copy)]
pub struct Build {
    /// The board.
    pub board: &'static Board,
    /// Its revision.
    pub revision: &'static Revision,
}

impl Build {
    /// The robot revision whose timing files the analysis and the admission table use.
    pub fn robot(&self) -> &'static str {
        self.revision.robot()
    }

    /// cargo arguments after `build --release` (or `clippy --release`): the revision's feature
    /// (without the default one) and `extra` features.
    pub fn feature_args(&self, extra: &[&str]) -> Vec<String> {
        let mut features: Vec<&str> = Vec::new();
        let mut args = Vec::new();
        if let Some(feature) = self.revision.feature {
            args.push("--no-default-features".to_string());
            features.push(feature);
        }
        features.extend_from_slice(extra);
        if !features.is_empty() {
            args.push("--features".to_string());
            args.push(features.join(","));
        }
        args
    }

    /// A name for files of this image: `diwheeldrive-1-2`, `lightring-1-0`.
    pub fn stem(&self) -> String {
        format!(
            "{}-{}",
            self.board.name,
            self.revision.name.replace('/', "+")
        )
    }

    /// Sets `AMIRO_REVISION` for this process and the cargo runs it starts: the analysis and the
    /// boards' admission tables read this revision's timing files.
    pub fn select_models(&self) {
        select_models(self.robot());
    }
}

/// Sets `AMIRO_REVISION` (the robot revision whose timing files are read) for this process and
/// its children.
pub fn select_models(robot: &str) {
    std::env::set_var(schedule_analysis::scenario::REVISION_ENV, robot);
}

/// The images `choice` asks for of `boards`, in board order (newest revision first).
pub fn plan(boards: &[&'static Board], choice: &Choice) -> Result<Vec<Build>> {
    let mut builds = Vec::new();
    for &board in boards {
        match choice {
            Choice::Newest => builds.push(Build {
                board,
                revision: board.newest(),
            }),
            Choice::Robot(robot) => {
                let Some(revision) = board.revision_for(robot) else {
                    bail!(
                        "{} has no image for a revision-{robot} robot (its revisions: {})",
                        board.name,
                        names(board)
                    );
                };
                builds.push(Build { board, revision });
            }
            Choice::All => builds.extend(
                board
                    .revisions
                    .iter()
                    .map(|revision| Build { board, revision }),
            ),
        }
    }
    Ok(builds)
}

/// The board images with the `scripted-i2c` trial: DiWheelDrive 1-1 and PowerManagement 1-2 (its
/// two images differ only in their admission table; the robot scenarios run its trial on the 1-1
/// image).
pub fn scripted_i2c_builds(every: &[Build]) -> Vec<Build> {
    every
        .iter()
        .filter(|b| {
            (b.board.name == "diwheeldrive" && b.revision.name == "1-1")
                || (b.board.name == "powermgmt" && b.revision.name == "1-2")
        })
        .cloned()
        .collect()
}

/// The board's revisions, for messages: `1-2, 1-1`.
pub fn names(board: &Board) -> String {
    board
        .revisions
        .iter()
        .map(|r| r.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The revision a board's `cargo build` builds without features (the crate's default), for the
/// boards' `cargo run` runner: the one whose device id the ELF declares, else the newest.
pub fn of_elf(board: &Board, elf: &Path) -> Result<&'static Revision> {
    match crate::elf::device_id_of(elf)? {
        Some(id) => board.revision_of_id(id).with_context(|| {
            format!(
                "{} declares device id {id:#010x}, which is no {} revision ({})",
                elf.display(),
                board.name,
                names(board)
            )
        }),
        None if board.revisions.len() == 1 => Ok(board.newest()),
        None => bail!(
            "{} declares no device id ({}): cannot tell which {} revision it is for",
            elf.display(),
            crate::elf::DEVICE_ID_SYMBOL,
            board.name
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boards::{by_name, BOARDS};

    fn all() -> Vec<&'static Board> {
        BOARDS.iter().collect()
    }

    #[test]
    fn the_default_is_each_boards_newest() {
        let plan = plan(&all(), &Choice::parse(None).unwrap()).unwrap();
        let names: Vec<String> = plan.iter().map(Build::stem).collect();
        assert_eq!(
            names,
            ["diwheeldrive-1-2", "powermgmt-1-2", "lightring-1-2"]
        );
    }

    #[test]
    fn a_robot_revision_picks_each_boards_image_or_says_which_is_missing() {
        let dwd = by_name("diwheeldrive").unwrap();
        let pm = by_name("powermgmt").unwrap();
        let one = plan(&[dwd, pm], &Choice::parse(Some("1-1")).unwrap()).unwrap();
        assert_eq!(one[0].revision.feature, Some("rev-1-1"));
        assert_eq!(
            one[0].feature_args(&["qemu"]),
            ["--no-default-features", "--features", "rev-1-1,qemu"]
        );
        // PowerManagement: an image per robot revision, for its admission table (the code is the same).
        assert_eq!(one[1].stem(), "powermgmt-1-1");
        assert_eq!(one[1].robot(), "1-1");
        assert_eq!(
            one[1].feature_args(&["bare-chip"]),
            ["--no-default-features", "--features", "rev-1-1,bare-chip"]
        );
        let new = plan(&[pm], &Choice::parse(Some("1-2")).unwrap()).unwrap();
        assert_eq!(new[0].stem(), "powermgmt-1-2");
        assert_eq!(new[0].robot(), "1-2");
        // LightRing: 1-0 on a 1-1 robot, 1-2 on a 1-2 robot.
        let lr = by_name("lightring").unwrap();
        let old = plan(&[lr], &Choice::parse(Some("1-1")).unwrap()).unwrap();
        assert_eq!(old[0].stem(), "lightring-1-0");
        assert_eq!(old[0].robot(), "1-1");
        assert_eq!(
            old[0].feature_args(&["qemu"]),
            ["--no-default-features", "--features", "rev-1-0,qemu"]
        );
        let new = plan(&[lr], &Choice::parse(Some("1-2")).unwrap()).unwrap();
        assert_eq!(new[0].stem(), "lightring-1-2");
        assert_eq!(new[0].robot(), "1-2");
        assert!(Choice::parse(Some("1-3")).is_err());
    }

    #[test]
    fn all_builds_every_revision() {
        let plan = plan(&all(), &Choice::All).unwrap();
        let names: Vec<String> = plan.iter().map(Build::stem).collect();
        assert_eq!(
            names,
            [
                "diwheeldrive-1-2",
                "diwheeldrive-1-1",
                "powermgmt-1-2",
                "powermgmt-1-1",
                "lightring-1-2",
                "lightring-1-0"
            ]
        );
        assert_eq!(plan[0].robot(), "1-2");
        assert_eq!(plan[1].robot(), "1-1");
    }

    /// The robot revision whose timing files an image's admission table is built from, as the boards'
    /// build script picks it (`amiro-firmware/board-build.rs`): the `rev-*` feature (LightRing's
    /// `rev-1-0` sits on 1-1 robots), else `AMIRO_REVISION`, which `cargo xtask` sets to
    /// [`Build::robot`].
    fn table_revision(build: &Build) -> &'static str {
        match build.revision.feature.and_then(|f| f.strip_prefix("rev-")) {
            Some("1-0") => "1-1",
            Some(revision) => revision,
            None => build.robot(),
        }
    }

    /// A board's view: per running stream its sender's board index and topic byte, and its period in ns.
    type View = Vec<(u8, u8, u64)>;

    /// Each board's view of the robot's streams after `commands` (`id`, `data`), every board
    /// deciding on the table of the robot revision `tables` names for it (the running set: sender
    /// and period of each stream).
    fn views(
        commands: &[(u16, &[u8])],
        tables: &[(amiro_can::Board, &'static str)],
    ) -> Vec<(amiro_can::Board, View)> {
        use amiro_firmware::admission::{Admission, State};
        use schedule_analysis::{admission_host, model::FrameCostSpec, scenario};
        let root = crate::workspace::workspace_root();
        let mut out = Vec::new();
        for &(board, revision) in tables {
            let robot = admission_host::lower(
                &root,
                &scenario::timing_files_for(&root, Some(revision)),
                schedule_analysis::can::DEFAULT_BITRATE,
                FrameCostSpec::Exact,
            )
            .unwrap_or_else(|e| panic!("the {revision} robot's table: {e}"));
            assert!(robot.max_tasks() <= 64 && robot.max_publishers() <= 32);
            let view = robot.with_table(|table| {
                let mut state = Box::new(State::<64, 32>::new());
                let mut admission = Admission::new(table, board, &mut state);
                admission.prepare();
                for (id, data) in commands {
                    let _ = admission.on_command(*id, data);
                }
                let mut view: View = admission
                    .running()
                    .iter()
                    .filter_map(|s| s.sender.map(|t| (t.board, t.topic, s.period.as_ns())))
                    .collect();
                view.sort_unstable();
                view
            });
            out.push((board, view));
        }
        out
    }

    /// The gap found on 2026-12-05 (docs/boards.md, "Revisions"): a board keeps another board's
    /// stream in its view only when its own table admits it, so on a robot every board must judge on
    /// that robot's table. Replayed on the host (the example re-derived on 2026-12-06, when DiWheelDrive
    /// 1-1's publisher rows came from the machine code and the 2026-12-05 one, magnetometer-x every
    /// 1 150 µs, was refused on both robots): the gyroscope every 1 ms at urgent (DiWheelDrive 1-1's table
    /// admits it, a 1-2 robot's refuses it), then the proximity ring every 10 ms at low (DiWheelDrive 1-1's
    /// check refuses it beside the gyroscope). With PowerManagement's one image of before (the 1-2 robot's
    /// table on both robots) its view missed the gyroscope on a 1-1 robot and it started the ring; every
    /// board's image for a robot now carries that robot's table, and the views agree on both revisions.
    /// Re-derived again when DiWheelDrive's `can_tx` was used (2026-12-06): the gyroscope at urgent needs
    /// 1 519 µs on a 1-1 robot and 2 026 µs on a 1-2 robot, so it is asked every 1.6 ms (1 ms before).
    /// And when PowerManagement's ring row was used (2026-12-06: the ring needs about 53 ms, and beside the
    /// gyroscope every period it admits is admitted on either table): PowerManagement's power status every
    /// 4 200 µs at low in the ring's place, admitted alone on either robot and refused beside the gyroscope on a
    /// 1-1 robot (0x71E at 4 298 of 4 200 µs; host's check, `amiro send … --revision`).
    #[test]
    fn every_boards_image_for_a_robot_judges_on_that_robots_table_so_the_views_agree() {
        let commands: [(u16, &[u8]); 2] =
            [(0x008, &[1, 0x40, 0x06, 2]), (0x31E, &[1, 0x68, 0x10, 2])];
        let gyroscope = |view: &[(u8, u8, u64)]| view.iter().any(|s| s.1 == 0x08);
        for robot in ROBOT_REVISIONS {
            let builds = plan(&all(), &Choice::Robot(robot)).unwrap();
            let tables: Vec<(amiro_can::Board, &'static str)> = builds
                .iter()
                .map(|b| {
                    let board = amiro_can::Board::ALL
                        .into_iter()
                        .find(|x| schedule_analysis::scenario::board_folder(*x) == b.board.name)
                        .unwrap();
                    (board, table_revision(b))
                })
                .collect();
            let views = views(&commands, &tables);
            for (board, view) in &views {
                assert_eq!(
                    view, &views[0].1,
                    "a {robot} robot: {board:?}'s view differs from {:?}'s",
                    views[0].0
                );
            }
            for b in &builds {
                assert_eq!(table_revision(b), robot, "{}", b.stem());
            }
            // The example still tells the tables apart: DiWheelDrive 1-1 runs the gyroscope, a 1-2 robot
            // refuses it.
            assert_eq!(gyroscope(&views[0].1), robot == "1-1", "{robot}");
        }
        // And what the test guards against: PowerManagement on the 1-2 robot's table on a 1-1 robot.
        let mixed = views(
            &commands,
            &[
                (amiro_can::Board::DiWheelDrive, "1-1"),
                (amiro_can::Board::PowerManagement, "1-2"),
            ],
        );
        // DiWheelDrive runs the gyroscope, PowerManagement's view misses it, so PowerManagement starts the
        // power status, which DiWheelDrive's check refuses beside the gyroscope.
        let status = |view: &[(u8, u8, u64)]| view.iter().any(|s| s.1 == 0x1E);
        assert!(gyroscope(&mixed[0].1) && !gyroscope(&mixed[1].1));
        assert!(status(&mixed[1].1) && !status(&mixed[0].1));
    }

    #[test]
    fn device_ids_name_the_revision() {
        let dwd = by_name("diwheeldrive").unwrap();
        assert_eq!(dwd.revision_of_id(0x0100_0102).unwrap().name, "1-2");
        assert_eq!(dwd.revision_of_id(0x0100_0101).unwrap().name, "1-1");
        assert!(dwd.revision_of_id(0x017F_0102).is_none());
        let lr = by_name("lightring").unwrap();
        assert_eq!(lr.revision_of_id(0x017F_0102).unwrap().name, "1-2");
        assert_eq!(lr.revision_of_id(0x017F_0100).unwrap().name, "1-0");
        assert_eq!(lr.revision_of_id(3).unwrap().name, "1-0");
        // PowerManagement's legacy id is the 1-1 robot's: 1-2 bootloaders define no legacy ids.
        let pm = by_name("powermgmt").unwrap();
        assert_eq!(pm.revision_of_id(0x0101_0102).unwrap().name, "1-2");
        assert_eq!(pm.revision_of_id(0x0101_0101).unwrap().name, "1-1");
        assert_eq!(pm.revision_of_id(2).unwrap().name, "1-1");
        assert!(pm.revision_of_id(1).is_none());
    }
}
