//! The controller protocol against small shell programs: frames in, frames out, and each way a
//! program can fail.

use std::process::Command;
use std::time::Duration;

use amiro_world::controller::{Controller, ControllerError, Frame, LineProblem};

fn sh(script: &str, timeout: Duration) -> Controller {
    let mut command = Command::new("sh");
    command.arg("-c").arg(script);
    Controller::spawn_command("sh test", command, timeout).unwrap()
}

const SECOND: Duration = Duration::from_secs(5);

/// Answers every tick with one frame whose byte counts the frame lines since the last tick, and
/// with the last frame line's timestamp and identifier as a second frame (`7FF#` + the text's
/// bytes would be too long; so the digits of the time's micro-seconds as hex).
const COUNTER: &str = r#"
n=0
while IFS= read -r line; do
  case "$line" in
    *" tick") printf '110#%02X\n\nok\n' "$n"; n=0 ;;
    "(0.001000) can0 61F#0102") n=$((n+1)) ;;
    "(0.002000) can0 008#") n=$((n+1)) ;;
    *) n=$((n+100)) ;;
  esac
done
"#;

#[test]
fn frames_go_in_as_candump_lines_and_come_back_at_the_tick() {
    let mut c = sh(COUNTER, SECOND);
    c.frame(1_000, &Frame::new(0x61F, &[1, 2]).unwrap())
        .unwrap();
    c.frame(2_000, &Frame::new(0x008, &[]).unwrap()).unwrap();
    let frames = c.tick(10_000).unwrap();
    assert_eq!(frames, vec![Frame::new(0x110, &[2]).unwrap()]);
    let frames = c.tick(20_000).unwrap();
    assert_eq!(frames, vec![Frame::new(0x110, &[0]).unwrap()]);
    let status = c.finish().unwrap();
    assert!(status.success());
}

#[test]
fn a_program_that_dies_is_an_error_with_its_status() {
    let mut c = sh("read line; exit 3", SECOND);
    let e = c.tick(10_000).unwrap_err();
    match &e {
        ControllerError::Exited {
            at_us: 10_000,
            status: Some(s),
            ..
        } => assert_eq!(s.code(), Some(3)),
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().contains("ended at 0.010000 s"), "{e}");
    // Writing to it afterwards is the same error, not a panic.
    assert!(matches!(
        c.frame(20_000, &Frame::new(1, &[]).unwrap()),
        Err(ControllerError::Exited { .. })
    ));
}

#[test]
fn a_program_that_stops_answering_times_out() {
    let mut c = sh("while read line; do :; done", Duration::from_millis(200));
    let e = c.tick(30_000).unwrap_err();
    assert!(
        matches!(e, ControllerError::Timeout { at_us: 30_000, .. }),
        "{e:?}"
    );
    assert!(
        e.to_string()
            .contains("did not answer the tick at 0.030000 s"),
        "{e}"
    );
}

#[test]
fn a_malformed_line_names_the_line() {
    let mut c = sh("read line; echo '110#ABC'; echo ok", SECOND);
    match c.tick(40_000).unwrap_err() {
        ControllerError::Malformed { line, problem, .. } => {
            assert_eq!(line, "110#ABC");
            assert_eq!(problem, LineProblem::BadData);
        }
        other => panic!("{other:?}"),
    }
    let mut c = sh("read line; echo hello", SECOND);
    assert!(matches!(
        c.tick(0),
        Err(ControllerError::Malformed {
            problem: LineProblem::NotAFrame,
            ..
        })
    ));
}

#[test]
fn a_program_that_does_not_exist_is_a_spawn_error() {
    let e = Controller::spawn("/nonexistent/behaviour --fast", SECOND)
        .err()
        .unwrap();
    assert!(matches!(e, ControllerError::Spawn { .. }), "{e:?}");
    assert!(Controller::spawn("   ", SECOND).is_err());
}
