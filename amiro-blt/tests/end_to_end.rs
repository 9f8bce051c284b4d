//! The host library against the simulated robot in virtual time: all three boards, each fault.
mod common;

use std::time::Duration;

use amiro_blt::target::{robot, IdSet};
use amiro_blt::xcp::ErrorCode;
use amiro_blt::{Error, Flasher, Options, RestartOutcome, Transport};
use amiro_blt_sim::{BoardSpec, Faults, IdInCode, Mode, Nak, Robot, SimChip, Timing};
use common::*;

fn opts() -> Options {
    Options {
        window_patience: Duration::from_secs(5),
        ..Options::default()
    }
}

fn images() -> Vec<amiro_blt::Image> {
    let t = targets();
    vec![
        firmware(&t[0], 9000, 1),
        firmware(&t[1], 7000, 2),
        firmware(&t[2], 5000, 3),
    ]
}

#[test]
fn all_three_boards_are_flashed_byte_for_byte_and_the_robot_starts() {
    let targets = targets();
    let images = images();
    let sim = sim_robot(Faults::default());
    let bootloaders: Vec<Vec<u8>> = targets
        .iter()
        .map(|t| {
            let flash = sim.flash(t.device_id);
            flash.bytes(0x0800_0000, flash.chip().app_origin()).to_vec()
        })
        .collect();
    let mut flasher = Flasher::new(SimLink::new(sim, 115_200), opts());
    flasher.enter_flash_mode(&mut ()).unwrap();
    for (t, img) in targets.iter().zip(&images) {
        let report = flasher.flash(t, img, &mut ()).unwrap();
        assert_eq!((report.attempts, report.retries), (1, 0));
    }
    assert_eq!(flasher.restart().unwrap(), RestartOutcome::Started);
    let robot = &flasher.link().robot;
    for ((t, img), bootloader) in targets.iter().zip(&images).zip(&bootloaders) {
        let flash = robot.flash(t.device_id);
        assert!(holds(flash, t, img), "{}", t.name);
        assert!(flash.app_valid(), "{}", t.name);
        assert!(robot.app_started(t.device_id), "{}", t.name);
        let origin = flash.chip().app_origin();
        assert_eq!(flash.bytes(0x0800_0000, origin), &bootloader[..]);
        assert_eq!(flash.protected_hits, 0);
    }
    assert_eq!(*robot.mode(), Mode::Application);
}

/// Identifies the main board of `boards` the way `cargo xtask flash` does, then checks that
/// the robot was neither hung nor erased.
fn identify(boards: Vec<BoardSpec>) -> (amiro_blt::Identification, Flasher<SimLink>) {
    let ids: Vec<u32> = boards.iter().map(|b| b.device_id).collect();
    let sim = Robot::new(boards, Timing::robot(), Faults::default());
    let mut flasher = Flasher::new(SimLink::new(sim, 115_200), opts());
    flasher.enter_flash_mode(&mut ()).unwrap();
    let before = flasher.link().clock();
    let seen = flasher.identify_main_board().unwrap();
    // 24 KiB read back at 115200 baud: about 2 s.
    let took = flasher.link().clock() - before;
    assert!(took < Duration::from_millis(2600), "{took:?}");
    let robot = &flasher.link().robot;
    assert_eq!(*robot.mode(), Mode::Flashing, "{:?}", robot.log);
    for id in ids {
        assert_eq!(robot.flash(id).erases, 0);
    }
    (seen, flasher)
}

#[test]
fn the_main_boards_bootloader_names_the_robots_revision_without_a_module_connect() {
    // 1-1: the id in literal pools; 1-2: built by MOVW/MOVT.
    for (boards, id, ids) in [
        (BoardSpec::robot_1_1(), 0x0100_0101, IdSet::Rev11),
        (BoardSpec::robot_1_2(), 0x0100_0102, IdSet::Rev12),
    ] {
        let (seen, mut flasher) = identify(boards);
        let main = seen.main_board().unwrap();
        assert_eq!((main.board, main.id, main.robot), ("diwheeldrive", id, ids));
        // And the robot it names is then flashed through its ids, every board greeted first.
        let targets = robot(ids);
        for t in &targets {
            flasher.greet(t).unwrap();
        }
        for t in &targets {
            let img = firmware(t, 2000, 7);
            flasher.flash(t, &img, &mut ()).unwrap();
            assert!(holds(flasher.link().robot.flash(t.device_id), t, &img));
        }
    }
    // A bootloader in which no known id can be found leaves the revision unknown.
    let mut boards = BoardSpec::robot_1_2();
    boards[0].id_in_code = IdInCode::Absent;
    let (seen, _) = identify(boards);
    assert_eq!(seen.main_board(), None);
    assert_eq!(seen.describe(), "none of the known main-board ids");
}

#[test]
fn powermanagement_on_the_cable_is_identified_from_its_compares_alone() {
    // Its simulated bootloaders hold the id only as GCC compiles it: CMP.W #0x01010101 (1-1),
    // CMN.W #0xFEFEFEFE (1-2); no literal word, no MOVW/MOVT, and the callback table's
    // unaligned 01 01 00 01 (DiWheelDrive 1-1's id) in both.
    for (boards, id, ids) in [
        (BoardSpec::robot_1_1(), 0x0101_0101, IdSet::Rev11),
        (BoardSpec::robot_1_2(), 0x0101_0102, IdSet::Rev12),
    ] {
        let boards = BoardSpec::with_main(boards, "powermgmt").unwrap();
        let (seen, mut flasher) = identify(boards);
        let main = seen.main_board().unwrap();
        assert_eq!(
            (main.board, main.id, main.robot),
            ("powermgmt", id, ids),
            "{}",
            seen.describe()
        );
        // And the robot it names is flashed through PowerManagement's gateway.
        let targets = robot(ids);
        for t in &targets {
            flasher.greet(t).unwrap();
        }
        for t in &targets {
            let img = firmware(t, 1500, 5);
            flasher.flash(t, &img, &mut ()).unwrap();
            assert!(holds(flasher.link().robot.flash(t.device_id), t, &img));
        }
    }
}

#[test]
fn a_module_of_the_other_revision_hangs_the_greeting_before_anything_is_erased() {
    // A 1-2 main board with a 1-1 PowerManagement: its inferred id 0x01010102 is no one's.
    let mut boards = BoardSpec::robot_1_2();
    boards[1].device_id = 0x0101_0101;
    let (seen, mut flasher) = identify(boards);
    let targets = robot(seen.main_board().unwrap().robot);
    flasher.greet(&targets[0]).unwrap();
    let err = flasher.greet(&targets[1]).unwrap_err();
    assert!(
        matches!(
            err,
            Error::NoAnswerFromBoard {
                id: 0x0101_0102,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("reset the robot"));
    let robot = &flasher.link().robot;
    assert!(matches!(robot.mode(), Mode::Hung(_)));
    for id in [0x0100_0102, 0x0101_0101, 0x017F_0102] {
        assert_eq!(robot.flash(id).erases, 0);
    }
}

#[test]
fn two_byte_legacy_ids_select_boards_of_a_1_1_robot() {
    let mut boards = BoardSpec::robot_1_2();
    for (b, (id, legacy)) in
        boards
            .iter_mut()
            .zip([(0x0100_0101, 1), (0x0101_0101, 2), (0x017F_0100, 3)])
    {
        b.device_id = id;
        b.legacy_id = Some(legacy);
    }
    let sim = Robot::new(boards, Timing::robot(), Faults::default());
    let targets = robot(IdSet::Legacy);
    let mut flasher = Flasher::new(SimLink::new(sim, 115_200), opts());
    flasher.enter_flash_mode(&mut ()).unwrap();
    for t in &targets {
        let img = firmware(t, 3000, 9);
        flasher.flash(t, &img, &mut ()).unwrap();
        let ids = robot(IdSet::Rev11);
        let id = ids.iter().find(|x| x.name == t.name).unwrap().device_id;
        assert!(holds(flasher.link().robot.flash(id), t, &img));
    }
}

/// A robot whose applications run: its window closed long ago.
fn running_robot() -> Robot {
    let mut sim = sim_robot(Faults::default());
    for t in targets() {
        let img = firmware(&t, 100, 4);
        for (a, b) in expected_bytes(&t, &img) {
            sim.flash_mut(t.device_id).install(a, &[b]);
        }
    }
    sim.advance(2_000_000_000);
    assert_eq!(*sim.mode(), Mode::Application);
    sim
}

#[test]
fn a_missed_window_is_no_answer_and_the_reset_line_recovers_it() {
    let mut flasher = Flasher::new(SimLink::new(running_robot(), 115_200), opts());
    let err = flasher.enter_flash_mode(&mut ()).unwrap_err();
    assert!(matches!(err, Error::NoAnswer { .. }), "{err}");
    assert!(err.to_string().contains("reset"));

    let mut sim = running_robot();
    sim.rts_wired = true;
    let reset_line = Options {
        reset_line: true,
        ..opts()
    };
    let mut flasher = Flasher::new(SimLink::new(sim, 115_200), reset_line);
    flasher.enter_flash_mode(&mut ()).unwrap();
    let t = &targets()[2];
    let img = firmware(t, 2000, 5);
    flasher.flash(t, &img, &mut ()).unwrap();
    assert!(holds(flasher.link().robot.flash(t.device_id), t, &img));
}

#[test]
fn flashing_mode_ends_after_30_s_without_traffic() {
    let mut flasher = Flasher::new(
        SimLink::new(running_robot(), 115_200),
        Options {
            reset_line: true,
            ..opts()
        },
    );
    flasher.link().robot.rts_wired = true;
    flasher.enter_flash_mode(&mut ()).unwrap();
    use amiro_blt::Transport;
    flasher.link().pause(Duration::from_secs(29));
    assert_eq!(*flasher.link().robot.mode(), Mode::Flashing);
    flasher.link().pause(Duration::from_secs(2));
    assert_eq!(*flasher.link().robot.mode(), Mode::Application);
}

/// Flashes all three boards with one fault injected; checks the invariant on every board and
/// returns the outcome.
fn with_fault(faults: Faults) -> (Result<(), Error>, Robot) {
    let targets = targets();
    let images = images();
    let mut flasher = Flasher::new(SimLink::new(sim_robot(faults), 115_200), opts());
    let result = (|| {
        flasher.enter_flash_mode(&mut ())?;
        for (t, img) in targets.iter().zip(&images) {
            flasher.flash(t, img, &mut ())?;
        }
        Ok(())
    })();
    let robot = &flasher.link().robot;
    for (t, img) in targets.iter().zip(&images) {
        assert!(
            never_half_written(robot.flash(t.device_id), t, img),
            "{} half written after {result:?}",
            t.name
        );
    }
    if result.is_ok() {
        for (t, img) in targets.iter().zip(&images) {
            assert!(holds(robot.flash(t.device_id), t, img), "{}", t.name);
            assert!(robot.flash(t.device_id).app_valid());
        }
    }
    let SimLink { robot, .. } = std::mem::replace(
        flasher.link(),
        SimLink::new(sim_robot(Faults::default()), 0),
    );
    (result, robot)
}

#[test]
fn a_dropped_byte_anywhere_is_retried_or_named() {
    let mut ok = 0;
    // Total host bytes for the session are about 2 × 21 kB; spread the losses over all of it.
    for index in (0..44_000).step_by(1999) {
        let (result, _) = with_fault(Faults {
            drop_host_byte: Some(index),
            ..Faults::default()
        });
        match result {
            Ok(()) => ok += 1,
            Err(
                e @ (Error::Xcp { .. }
                | Error::LostConnection { .. }
                | Error::NoAnswerFromBoard { .. }
                | Error::VerifyFailed { .. }),
            ) => {
                assert!(!e.to_string().is_empty())
            }
            Err(e) => panic!("byte {index}: unexpected {e}"),
        }
    }
    assert!(ok >= 15, "only {ok} of 23 runs recovered");
}

#[test]
fn a_corrupted_byte_either_way_is_retried_or_named() {
    let mut ok = 0;
    for index in (5..44_000).step_by(2503) {
        for faults in [
            Faults {
                corrupt_host_byte: Some((index, 0x10)),
                ..Faults::default()
            },
            Faults {
                corrupt_reply_byte: Some((index / 4, 0x01)),
                ..Faults::default()
            },
        ] {
            if with_fault(faults).0.is_ok() {
                ok += 1;
            }
        }
    }
    assert!(ok >= 25, "only {ok} of 36 runs recovered");
}

#[test]
fn a_corrupted_data_byte_is_caught_by_the_read_back_and_reprogrammed() {
    // Byte 3000 of the session is inside DiWheelDrive's image data: written wrong, acknowledged.
    let (result, _) = with_fault(Faults {
        corrupt_host_byte: Some((3000, 0x55)),
        ..Faults::default()
    });
    result.unwrap();
}

#[test]
fn a_module_that_stops_acknowledging_is_a_lost_connection_and_the_next_run_recovers() {
    let lr = targets()[2].clone();
    let (result, mut sim) = with_fault(Faults {
        silent_after: Some((lr.device_id, 12)),
        ..Faults::default()
    });
    let err = result.unwrap_err();
    assert!(
        matches!(&err, Error::LostConnection { board, .. } if board == "lightring"),
        "{err}"
    );
    assert!(matches!(sim.mode(), Mode::Hung(_)));
    assert!(!sim.flash(lr.device_id).app_valid());
    // The user resets the robot; the next run finishes it.
    sim.reset();
    let mut flasher = Flasher::new(SimLink::new(sim, 115_200), opts());
    flasher.enter_flash_mode(&mut ()).unwrap();
    let img = &images()[2];
    flasher.flash(&lr, img, &mut ()).unwrap();
    assert!(holds(flasher.link().robot.flash(lr.device_id), &lr, img));
}

#[test]
fn a_single_refusal_of_each_code_is_retried_and_a_persistent_one_is_named() {
    let pm = targets()[1].clone();
    for code in ErrorCode::NAMED {
        for command in [0xC9u8, 0xD1, 0xD0] {
            let nak = Nak {
                device_id: pm.device_id,
                command,
                occurrence: if command == 0xD1 { 1 } else { 2 },
                code: code.byte(),
                persistent: false,
            };
            let (result, _) = with_fault(Faults {
                nak: Some(nak),
                ..Faults::default()
            });
            assert!(result.is_ok(), "{code} on {command:#04x}: {result:?}");
            let (result, _) = with_fault(Faults {
                nak: Some(Nak {
                    persistent: true,
                    ..nak
                }),
                ..Faults::default()
            });
            match result {
                Err(Error::Xcp {
                    board, code: got, ..
                }) => {
                    assert_eq!((board.as_str(), got), ("powermgmt", code));
                }
                other => panic!("{code} on {command:#04x}: {other:?}"),
            }
        }
    }
}

#[test]
fn a_board_with_another_chip_answering_is_refused_before_the_erase() {
    let mut boards = BoardSpec::robot_1_2();
    // PowerManagement hardware answers to LightRing's id.
    boards[1].device_id = 0x017F_0102;
    boards[2].device_id = 0x0101_0102;
    boards[2].chip = SimChip::F103;
    let mut flasher = Flasher::new(
        SimLink::new(
            Robot::new(boards, Timing::robot(), Faults::default()),
            115_200,
        ),
        opts(),
    );
    flasher.enter_flash_mode(&mut ()).unwrap();
    let lr = &targets()[2];
    let err = flasher
        .flash(lr, &firmware(lr, 500, 1), &mut ())
        .unwrap_err();
    assert!(matches!(err, Error::WrongBoard { .. }), "{err}");
    assert!(err.to_string().contains("0x20020000"), "{err}");
    let flash = flasher.link().robot.flash(0x017F_0102);
    assert_eq!(flash.bytes(0x0800_8000, 0x0800_8400), [0xFF; 0x400]);
}

#[test]
fn a_bare_chip_or_oversized_image_is_refused_before_anything_is_sent() {
    let dwd = &targets()[0];
    let bare = {
        let mut t = dwd.clone();
        t.app_origin = 0x0800_0000;
        firmware(&t, 100, 1)
    };
    let mut flasher = Flasher::new(SimLink::new(sim_robot(Faults::default()), 115_200), opts());
    let before = flasher.link().robot.log.len();
    let err = flasher.flash(dwd, &bare, &mut ()).unwrap_err();
    assert!(matches!(err, Error::NotLinkedForBootloader { .. }), "{err}");
    let huge = firmware(dwd, 0x7A000, 1);
    let err = flasher.flash(dwd, &huge, &mut ()).unwrap_err();
    assert!(matches!(err, Error::ImageTooLarge { .. }), "{err}");
    assert_eq!(flasher.link().robot.log.len(), before);
    assert_eq!(*flasher.link().robot.mode(), Mode::Bootloader);
}

#[test]
fn restart_with_an_invalid_main_board_reports_that_it_stayed() {
    let mut flasher = Flasher::new(SimLink::new(sim_robot(Faults::default()), 115_200), opts());
    flasher.enter_flash_mode(&mut ()).unwrap();
    assert_eq!(
        flasher.restart().unwrap(),
        RestartOutcome::StayedInBootloader
    );
}
