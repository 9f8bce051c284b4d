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

    /// A name for files of this image: `diwheeldrive-1-2`, `powermgmt-1-1+1-2`.
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
            ["diwheeldrive-1-2", "powermgmt-1-1+1-2", "lightring-1-2"]
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
        // PowerManagement: one image for both revisions, no feature.
        assert_eq!(one[1].revision.name, "1-1/1-2");
        assert_eq!(
            one[1].feature_args(&["bare-chip"]),
            ["--features", "bare-chip"]
        );
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
                "powermgmt-1-1+1-2",
                "lightring-1-2",
                "lightring-1-0"
            ]
        );
        assert_eq!(plan[0].robot(), "1-2");
        assert_eq!(plan[1].robot(), "1-1");
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
    }
}
