//! The `amiro` binary run as a user runs it: arguments in, text and exit status out.

use std::path::Path;

use assert_cmd::Command;
use serde_json::Value;

mod common;
use common::{assert_mentions, thesis};

fn amiro() -> Command {
    let mut command = Command::cargo_bin("amiro").expect("amiro binary");
    command.env_remove("AMIRO_BUS");
    command
}

/// Runs `amiro` and returns (success, stdout, stderr).
fn run(args: &[&str]) -> (bool, String, String) {
    let output = amiro().args(args).output().expect("run amiro");
    (
        output.status.success(),
        String::from_utf8(output.stdout).expect("UTF-8 stdout"),
        String::from_utf8(output.stderr).expect("UTF-8 stderr"),
    )
}

fn stdout_of(args: &[&str]) -> String {
    let (ok, stdout, stderr) = run(args);
    assert!(ok, "amiro {args:?} failed: {stderr}");
    stdout
}

#[test]
fn thesis_example_decodes_as_magnetometer_x_publish_every_900_us_at_medium() {
    let stdout = stdout_of(&["decode", "205#01840302"]);
    assert_eq!(
        stdout,
        "205#01840302          medium command magnetometer-x: publish every 900 µs (samples arrive on 605)\n"
    );
}

#[test]
fn thesis_example_encodes_exactly() {
    assert_eq!(stdout_of(&thesis("encode")), "205#01840302\n");
}

#[test]
fn negative_gyroscope_values_print_with_a_minus_sign() {
    // x = 0xFFFC = -4, y = 30, z = 0xFFFB = -5: the thesis's receiver printed 65532 for -4.
    let stdout = stdout_of(&["decode", "608#FCFF1E00FBFF"]);
    assert!(
        stdout.contains("gyroscope: x -4 dps, y 30 dps, z -5 dps"),
        "{stdout}"
    );
    assert!(!stdout.contains("65532"), "{stdout}");
    let json: Value =
        serde_json::from_str(&stdout_of(&["decode", "--json", "608#FCFF1E00FBFF"])).unwrap();
    assert_eq!(json["values"]["x_dps"], -4);
    assert_eq!(json["values"]["z_dps"], -5);
}

/// A log as it comes from the robot: candump -l lines, a bare frame, candump screen lines, comments, blank
/// lines, garbage, and frames the protocol rejects.
const MIXED_LOG: &str = "\
# recorded on the robot with candump -l can0
(1700000000.000000) can0 205#01840302
(1700000000.000900) can0 605#D8ADFFFF
(1700000000.001000) can0 608#FCFF1E00FBFF

this line is not a frame
(1700000000.002000) can0 205#0184
(1700000000.003000) can0 203#00
(1700000000.004000) can0 71E#003E4701720C
204#02
  can0  71F   [3]  03 78 00
(1700000000.005000) can0 12345678#00
(1700000000.006000) can0 205#03
(1700000000.007000) can0 609#1A00FEFF0E04 R
(garbage) can0 205#00
// end of the excerpt
";

/// The frames of MIXED_LOG in order, and a piece of what each line must say.
const MIXED_LOG_EXPECTED: [(&str, &str); 14] = [
    ("205#01840302", "magnetometer-x: publish every 900 µs"),
    ("605#D8ADFFFF", "magnetometer-x: x -21032 nT"),
    (
        "608#FCFF1E00FBFF",
        "gyroscope: x -4 dps, y 30 dps, z -5 dps",
    ),
    ("line 6", "not a CAN frame"),
    ("205#0184", "[dlc-too-short]"),
    ("203#00", "[unknown-topic]"),
    (
        "71E#003E4701720C",
        "power-status: discharging, 62 % charged, 327 min to empty, drawing 3186 mW",
    ),
    ("204#02", "floor-proximity: send one sample now"),
    ("71F#037800", "proximity-ring: sensor 3 sees 120 mm"),
    ("12345678#00", "[extended-id]"),
    ("205#03", "[bad-mode]"),
    (
        "609#1A00FEFF0E04",
        "accelerometer: x 26 milli-g, y -2 milli-g, z 1038 milli-g",
    ),
    ("line 15", "bad timestamp"),
    ("", ""),
];

fn write_log(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("candump-mixed.log");
    std::fs::write(&path, MIXED_LOG).unwrap();
    path
}

fn check_mixed_log_text(stdout: &str) {
    let lines: Vec<&str> = stdout.lines().collect();
    let expected: Vec<_> = MIXED_LOG_EXPECTED
        .iter()
        .filter(|(frame, _)| !frame.is_empty())
        .collect();
    assert_eq!(
        lines.len(),
        expected.len(),
        "one line per frame or unreadable line:\n{stdout}"
    );
    for (line, (frame, meaning)) in lines.iter().zip(expected) {
        assert!(
            line.contains(frame) && line.contains(meaning),
            "expected {frame} / {meaning} in {line:?}"
        );
    }
}

#[test]
fn a_mixed_candump_log_decodes_every_frame_from_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let log = write_log(dir.path());
    let output = amiro()
        .args(["decode", "--file"])
        .arg(&log)
        .output()
        .unwrap();
    // Some lines were bad, so the exit status says so, but every line was reported.
    assert_eq!(output.status.code(), Some(1));
    let stdout = String::from_utf8(output.stdout).unwrap();
    check_mixed_log_text(&stdout);
    // Timestamps and interface of candump -l lines are kept in front of the frame.
    assert!(
        stdout.starts_with("(1700000000.000000) can0 205#01840302"),
        "{stdout}"
    );
}

#[test]
fn a_mixed_candump_log_decodes_every_frame_from_standard_input() {
    let output = amiro()
        .arg("decode")
        .write_stdin(MIXED_LOG)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    check_mixed_log_text(&String::from_utf8(output.stdout).unwrap());
}

#[test]
fn json_output_parses_line_by_line() {
    let output = amiro()
        .args(["decode", "--json", "--file", "-"])
        .write_stdin(MIXED_LOG)
        .output()
        .unwrap();
    let stdout = String::from_utf8(output.stdout).unwrap();
    let records: Vec<Value> = stdout
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}")))
        .collect();
    assert_eq!(records.len(), 13);
    for record in &records {
        assert!(record["ok"].is_boolean(), "{record}");
        assert!(record["line"].is_u64(), "{record}");
        if record["ok"] == true {
            assert!(
                record["kind"].is_string()
                    && record["priority"].is_string()
                    && record["topic"].is_string()
            );
            assert!(
                record["command"].is_object() != record["values"].is_object(),
                "{record}"
            );
        } else {
            assert!(
                record["error"].is_string() && record["message"].is_string(),
                "{record}"
            );
        }
    }
    assert_eq!(records[0]["timestamp"], "1700000000.000000");
    assert_eq!(records[0]["command"]["action"], "publish");
    assert_eq!(records[0]["command"]["period_us"], 900);
    assert_eq!(records[1]["values"]["nanotesla"], -21032);
    assert_eq!(records[3]["error"], "not-a-frame");
    assert_eq!(records[3]["input"], "this line is not a frame");
    assert_eq!(records[4]["error"], "dlc-too-short");
    assert_eq!(records[6]["values"]["state_of_charge_percent"], 62);
    assert_eq!(records[8]["interface"], "can0");
    assert_eq!(records[8]["values"]["mm"], 120);
}

#[test]
fn frames_that_all_decode_exit_zero() {
    let (ok, stdout, _) = run(&["decode", "204#02", "(1.5) vcan0 308#00"]);
    assert!(ok);
    assert_eq!(stdout.lines().count(), 2);
    let (ok, stdout, _) = run(&["decode", "205#0184", "308#00"]);
    assert!(!ok, "a bad frame is reported and the status says so");
    assert!(
        stdout.contains("[dlc-too-short]") && stdout.contains("gyroscope: stop publishing"),
        "{stdout}"
    );
}

#[test]
fn every_sensor_command_round_trips_through_encode_and_decode() {
    let sensors = [
        "gyroscope",
        "accelerometer",
        "magnetometer-x",
        "magnetometer-y",
        "magnetometer-z",
        "floor-proximity",
        "odometry",
        "velocity",
        "power-status",
        "proximity-ring",
    ];
    for topic in sensors {
        for priority in ["urgent", "high", "medium", "low"] {
            for (action, extra) in [
                ("publish", &["--every", "62.5ms"][..]),
                ("stop", &[][..]),
                ("once", &[][..]),
            ] {
                let mut args = vec!["encode", action, topic, "--priority", priority];
                args.extend_from_slice(extra);
                let frame = stdout_of(&args);
                let record: Value =
                    serde_json::from_str(&stdout_of(&["decode", "--json", frame.trim()])).unwrap();
                assert_eq!(record["topic"], topic, "{frame}");
                assert_eq!(record["priority"], priority, "{frame}");
                assert_eq!(record["command"]["action"], action, "{frame}");
                if action == "publish" {
                    assert_eq!(record["command"]["period_us"], 62_500, "{frame}");
                }
            }
        }
    }
}

#[test]
fn actuator_commands_round_trip() {
    let frame = stdout_of(&[
        "encode",
        "motor",
        "--velocity",
        "-100000",
        "--angular",
        "2000000",
    ]);
    assert_eq!(frame, "110#6079FEFF80841E00\n");
    let record: Value =
        serde_json::from_str(&stdout_of(&["decode", "--json", frame.trim()])).unwrap();
    assert_eq!(record["command"]["velocity_um_s"], -100_000);
    assert_eq!(record["command"]["angular_urad_s"], 2_000_000);
    assert_eq!(record["priority"], "high");

    for led in 1..=8u8 {
        let frame = stdout_of(&[
            "encode",
            "led",
            &led.to_string(),
            "--rgb",
            "1,2,255",
            "--priority",
            "urgent",
        ]);
        assert_eq!(frame, format!("0{:02X}#0102FF\n", 0x10 + led));
        let record: Value =
            serde_json::from_str(&stdout_of(&["decode", "--json", frame.trim()])).unwrap();
        assert_eq!(record["command"]["led"], led);
        assert_eq!(record["topic"], format!("led-{led}"));
    }
}

#[test]
fn periods_choose_an_exact_unit_or_fail_clearly() {
    let publish = |every: &str| {
        run(&[
            "encode",
            "publish",
            "gyroscope",
            "--every",
            every,
            "--priority",
            "low",
        ])
    };
    assert_eq!(
        publish("70000us").1,
        "308#01460000\n",
        "70000 µs is sent as 70 ms"
    );
    assert_eq!(publish("2s").1, "308#01020001\n");
    assert_eq!(publish("1.5s").1, "308#01DC0500\n");
    for (bad, reason) in [
        ("65536001us", "cannot be encoded exactly"),
        ("0ms", "zero"),
        ("5000s", "longer than the longest period"),
        ("0.5us", "finer than the 1 µs resolution"),
        ("10", "has no unit"),
        ("10 minutes", "unknown unit"),
    ] {
        let (ok, stdout, stderr) = publish(bad);
        assert!(!ok && stdout.is_empty(), "{bad} must be refused");
        assert!(stderr.contains(reason), "{bad}: {stderr}");
    }
}

#[test]
fn wrong_words_are_refused_before_anything_is_built() {
    let (ok, _, stderr) = run(&[
        "encode",
        "publish",
        "motor",
        "--every",
        "1s",
        "--priority",
        "low",
    ]);
    assert!(
        !ok && stderr.contains("possible values") && stderr.contains("gyroscope"),
        "{stderr}"
    );
    let (ok, _, stderr) = run(&["encode", "stop", "gyroscope", "--priority", "fast"]);
    assert!(!ok && stderr.contains("urgent"), "{stderr}");
    let (ok, _, stderr) = run(&["encode", "led", "9", "--rgb", "1,2,3"]);
    assert!(!ok && stderr.contains("1..=8"), "{stderr}");
    let (ok, _, stderr) = run(&["encode", "led", "2", "--rgb", "300,0,0"]);
    assert!(!ok && stderr.contains("0 to 255"), "{stderr}");
}

#[test]
fn every_subcommand_has_help_with_examples() {
    let subcommands: [&[&str]; 11] = [
        &[],
        &["decode"],
        &["encode"],
        &["encode", "publish"],
        &["encode", "stop"],
        &["encode", "once"],
        &["encode", "motor"],
        &["encode", "led"],
        &["send"],
        &["monitor"],
        &["topics"],
    ];
    for path in subcommands {
        let mut args = path.to_vec();
        args.push("--help");
        let help = stdout_of(&args);
        assert!(
            help.contains("Example"),
            "amiro {path:?} --help has no examples:\n{help}"
        );
    }
}

/// The examples in `encode`'s help that show their output are run, so the help cannot drift from the code.
#[test]
fn encode_help_examples_print_what_they_claim() {
    let mut checked = 0;
    for path in [
        ["encode", "--help"],
        ["encode", "publish"],
        ["encode", "stop"],
        ["encode", "once"],
        ["encode", "led"],
    ] {
        let mut args = path.to_vec();
        if args[1] != "--help" {
            args.push("--help");
        }
        for line in stdout_of(&args).lines() {
            let Some(command) = line.trim().strip_prefix("amiro ") else {
                continue;
            };
            let words: Vec<String> = command
                .split_whitespace()
                .map(|w| w.trim_matches('\'').to_string())
                .collect();
            let Some((claimed, args)) = words.split_last() else {
                continue;
            };
            if !(claimed.len() > 4 && claimed.as_bytes()[3] == b'#') {
                continue;
            }
            let args: Vec<&str> = args
                .iter()
                .map(String::as_str)
                .filter(|w| *w != "prints")
                .collect();
            assert_eq!(stdout_of(&args).trim(), claimed, "help example: {line}");
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} examples found");
}

#[test]
fn topics_lists_the_table() {
    assert_mentions(
        &stdout_of(&["topics"]),
        &[
            "0x05  magnetometer-x",
            "0x1F  proximity-ring",
            "0x10  motor",
            "0x18  led-8",
        ],
    );
}

#[test]
fn send_to_a_log_file_and_monitor_it_back() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("sent.log");
    let bus = format!("file:{}", log.display());
    let stdout = stdout_of(&[
        "send",
        "publish",
        "gyroscope",
        "--every",
        "10ms",
        "--priority",
        "high",
        "--bus",
        &bus,
    ]);
    assert!(stdout.starts_with("sent 108#010A0000"), "{stdout}");
    // The bus can also come from the environment.
    let output = amiro()
        .args(["send", "308#00", "608#FCFF1E00FBFF"])
        .env("AMIRO_BUS", &bus)
        .output()
        .unwrap();
    assert!(output.status.success());

    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3);
    assert!(
        lines[0].starts_with('(') && lines[0].ends_with(") can0 108#010A0000"),
        "{text}"
    );

    let stdout = stdout_of(&["monitor", "--bus", &bus, "--json"]);
    let frames: Vec<String> = stdout
        .lines()
        .map(|line| {
            serde_json::from_str::<Value>(line).unwrap()["frame"]
                .as_str()
                .unwrap()
                .to_string()
        })
        .collect();
    assert_eq!(frames, ["108#010A0000", "308#00", "608#FCFF1E00FBFF"]);

    let stdout = stdout_of(&["monitor", "--bus", &bus, "--count", "2"]);
    assert_eq!(stdout.lines().count(), 2);
    let (ok, _, stderr) = run(&["monitor", "--bus", &bus, "--count", "5"]);
    assert!(!ok && stderr.contains("only 3 of 5 frames"), "{stderr}");
}

#[test]
fn monitor_replays_a_log_in_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("paced.log");
    std::fs::write(
        &log,
        "(100.000000) can0 608#FCFF1E00FBFF\n(100.300000) can0 608#FBFF1E00FBFF\n",
    )
    .unwrap();
    let bus = format!("file:{}", log.display());
    let start = std::time::Instant::now();
    let stdout = stdout_of(&["monitor", "--bus", &bus, "--realtime"]);
    assert!(start.elapsed() >= std::time::Duration::from_millis(300));
    assert_eq!(stdout.lines().count(), 2);
    // A timeout shorter than the gap stops the replay after the first frame.
    let stdout = stdout_of(&["monitor", "--bus", &bus, "--realtime", "--timeout", "100ms"]);
    assert_eq!(stdout.lines().count(), 1);
}

#[test]
fn send_refuses_frames_the_robot_would_reject_unless_raw() {
    let dir = tempfile::tempdir().unwrap();
    let bus = format!("file:{}", dir.path().join("raw.log").display());
    let (ok, _, stderr) = run(&["send", "205#0184", "--bus", &bus]);
    assert!(
        !ok && stderr.contains("[dlc-too-short]") && stderr.contains("--raw"),
        "{stderr}"
    );
    let (ok, stdout, stderr) = run(&["send", "205#0184", "--raw", "--bus", &bus]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("sent 205#0184"), "{stdout}");
    let (ok, _, stderr) = run(&["send", "205#01840302"]);
    assert!(!ok && stderr.contains("no bus given"), "{stderr}");
    let (ok, _, stderr) = run(&["send", "205#01840302", "--bus", "can0"]);
    assert!(!ok && stderr.contains("socketcan:can0"), "{stderr}");
}

/// The `encode` examples in docs/operator.md (`amiro encode ... # FRAME`) print the frame they claim.
#[test]
fn user_guide_encode_examples_are_true() {
    let guide =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/operator.md"))
            .expect("docs/operator.md");
    let mut checked = 0;
    for line in guide.lines() {
        if !line.starts_with("amiro encode") {
            continue;
        }
        // The comment marker follows the command after spaces; a '#' inside a quoted colour is not one.
        let Some((command, comment)) = line.rsplit_once("  # ") else {
            continue;
        };
        let claimed = comment.split_whitespace().next().unwrap_or_default();
        if !(claimed.len() > 4 && claimed.as_bytes()[3] == b'#') {
            continue;
        }
        let words: Vec<String> = command
            .split_whitespace()
            .skip(1)
            .map(|word| word.trim_matches('\'').to_string())
            .collect();
        let words: Vec<&str> = words.iter().map(String::as_str).collect();
        assert_eq!(
            stdout_of(&words).trim(),
            claimed,
            "docs/operator.md: {line}"
        );
        checked += 1;
    }
    assert!(checked >= 7, "only {checked} examples found in the guide");
}

#[test]
fn a_line_that_is_not_utf8_is_reported_with_its_number_and_decoding_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.log");
    let mut log = b"(1700000000.000000) can0 205#01840302\n".to_vec();
    log.extend_from_slice(b"(1700000000.000100) can0 \xff\xfe#00\n");
    log.extend_from_slice(b"(1700000000.000900) can0 605#D8ADFFFF\r\n");
    std::fs::write(&path, log).unwrap();
    let output = amiro()
        .args(["decode", "--file", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stdout = String::from_utf8(output.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(lines[0].contains("205#01840302"), "{stdout}");
    assert!(
        lines[1].starts_with("line 2: cannot read: not UTF-8 text"),
        "{stdout}"
    );
    assert!(lines[2].contains("magnetometer-x: x -21032 nT"), "{stdout}");

    let output = amiro()
        .args(["decode", "--json", "--file", path.to_str().unwrap()])
        .output()
        .unwrap();
    let second: Value = serde_json::from_str(
        String::from_utf8(output.stdout)
            .unwrap()
            .lines()
            .nth(1)
            .unwrap(),
    )
    .unwrap();
    assert_eq!(second["line"], 2);
    assert_eq!(second["error"], "not-text");
}

#[test]
fn a_period_too_long_to_count_names_the_firmware_limit() {
    let (ok, _, stderr) = run(&[
        "encode",
        "publish",
        "gyroscope",
        "--every",
        "99999999999999999999s",
        "--priority",
        "high",
    ]);
    assert!(!ok);
    assert!(stderr.contains("4294.967295 s"), "{stderr}");
    assert!(!stderr.contains("18446744073709"), "{stderr}");
}

#[test]
fn the_motor_help_states_the_deadman() {
    let stdout = stdout_of(&["encode", "motor", "--help"]);
    assert!(
        stdout.contains("500 ms") && stdout.contains("Dead-man"),
        "{stdout}"
    );
}

#[test]
fn the_shipped_demo_script_checks_without_a_bus() {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/standalone-demo.amiro"
    );
    let stdout = stdout_of(&["run", script, "--check"]);
    assert!(stdout.contains("108#01640000"), "{stdout}");
    assert!(stdout.contains("313#003278"), "{stdout}");
}

#[test]
fn send_reads_frames_from_a_file_and_refuses_a_bad_one_before_sending_any() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames.txt");
    let log = dir.path().join("out.log");
    std::fs::write(
        &frames,
        "# two frames\n205#01840302\n(1700000000.000000) can0 204#02\n",
    )
    .unwrap();
    let bus = format!("file:{}", log.display());
    let stdout = stdout_of(&["send", "--file", frames.to_str().unwrap(), "--bus", &bus]);
    assert_eq!(stdout.lines().count(), 2, "{stdout}");
    assert_eq!(std::fs::read_to_string(&log).unwrap().lines().count(), 2);
    std::fs::write(&frames, "205#01840302\n205#03\nnonsense\n").unwrap();
    let (ok, _, stderr) = run(&["send", "--file", frames.to_str().unwrap(), "--bus", &bus]);
    assert!(!ok);
    assert!(
        stderr.contains("line 2")
            && stderr.contains("line 3")
            && stderr.contains("nothing was sent"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(&log).unwrap().lines().count(),
        2,
        "nothing more was sent"
    );
    let output = amiro()
        .args(["send", "--bus", &bus])
        .write_stdin("313#FF8000\n")
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(std::fs::read_to_string(&log).unwrap().lines().count(), 3);
}

#[test]
fn monitor_filters_names_positions_and_summarises_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ring.log");
    std::fs::write(
        &path,
        "(10.000000) can0 21F#0124F402\n(10.001000) can0 71F#037800\n(10.002000) can0 608#FCFF1E00FBFF\n\
         (10.063500) can0 71F#037A00\n",
    )
    .unwrap();
    let bus = format!("file:{}", path.display());
    let (ok, stdout, stderr) = run(&[
        "monitor",
        "--bus",
        &bus,
        "--board",
        "powermanagement",
        "--sensor-data",
    ]);
    assert!(ok, "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(
        lines[0].starts_with("(   0.000000) can0 71F#037800"),
        "{stdout}"
    );
    assert!(
        lines[1].starts_with("(   0.062500)")
            && lines[1].contains("sensor 3 front-left sees 122 mm"),
        "{stdout}"
    );
    assert!(
        stderr.contains("summary: 2 frames") && stderr.contains("62.5 ms"),
        "{stderr}"
    );
}

#[test]
fn send_warns_from_what_a_log_of_the_bus_shows_runs() {
    let dir = tempfile::tempdir().unwrap();
    let bus = format!("file:{}", dir.path().join("sent.log").display());
    // On an idle robot a gyroscope every 2 ms at medium passes without a warning (every 1 ms passes by 3.4 µs only on a 1-1
    // robot since DiWheelDrive 1-1's publisher rows are the machine code's, 2026-12-06).
    let (ok, _, stderr) = run(&["send", "208#01D00702", "--bus", &bus]);
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
    // A candump -l log in which magnetometer-x data arrive at medium every 7 ms (its command was
    // never heard): the same request is refused, and the measured period is named.
    let heard = dir.path().join("heard.log");
    let lines: String = (0..12)
        .map(|k| format!("(1700000000.{:06}) can0 605#00000000\n", 1000 + k * 7000))
        .collect();
    std::fs::write(&heard, lines).unwrap();
    let (ok, _, stderr) = run(&[
        "send",
        "208#01D00702",
        "--bus",
        &bus,
        "--heard",
        heard.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("warning: 208#01D00702: DiWheelDrive on a 1-1 robot would refuse"),
        "{stderr}"
    );
    assert!(
        stderr.contains("magnetometer-x at medium every ~7000 µs"),
        "{stderr}"
    );
}

#[test]
fn send_names_the_robot_whose_tables_it_checks_and_refuses_an_unknown_one() {
    let dir = tempfile::tempdir().unwrap();
    let bus = format!("file:{}", dir.path().join("sent.log").display());
    // Accelerometer every 1 µs at urgent: refused on either robot, and the warning says which robot it checked.
    let (ok, _, stderr) = run(&["send", "009#01010002", "--bus", &bus, "--revision", "1-2"]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("warning: 009#01010002: DiWheelDrive on a 1-2 robot would refuse"),
        "{stderr}"
    );
    // A revision the check does not know: nothing is sent.
    let (ok, _, stderr) = run(&["send", "009#01010002", "--bus", &bus, "--revision", "1-3"]);
    assert!(!ok);
    assert!(stderr.contains("1-3") && stderr.contains("1-2"), "{stderr}");
    let sent = std::fs::read_to_string(dir.path().join("sent.log")).unwrap_or_default();
    assert_eq!(sent.lines().count(), 1, "{sent}");
}

#[test]
fn monitor_explains_an_admission_verdict_in_one_sentence() {
    use amiro_can::{
        AdmissionVerdict, Board, Count, Priority, SampleTime, Topic, Verdict, Violation,
    };
    let verdict = AdmissionVerdict {
        board: Board::DiWheelDrive,
        topic: Topic::Accelerometer,
        requested: SampleTime::from_micros(1).unwrap(),
        priority: Priority::Urgent,
        verdict: Verdict::Refused,
        violation: Violation::Task { index: 0 },
        wcrt_us: Count::saturating(u32::MAX),
        deadline_us: Count::saturating(1000),
        shortest_period: None,
        priority_needed: None,
        searched: false,
        one_shot: false,
    };
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("verdict.log");
    let lines: String = verdict
        .frames(Priority::Urgent)
        .iter()
        .enumerate()
        .map(|(k, frame)| {
            let data: String = frame.data().iter().map(|b| format!("{b:02X}")).collect();
            format!(
                "(1700000000.00000{k}) can0 {:03X}#{data}\n",
                frame.id().raw()
            )
        })
        .collect();
    std::fs::write(&log, lines).unwrap();
    let stdout = stdout_of(&["monitor", "--bus", &format!("file:{}", log.display())]);
    let sentence = stdout
        .lines()
        .find(|l| l.starts_with("  → "))
        .unwrap_or_else(|| panic!("no verdict sentence in {stdout}"));
    assert!(
        sentence.contains(
            "DiWheelDrive refused \"publish accelerometer every 1 µs at urgent\": its task"
        ),
        "{sentence}"
    );
    assert!(sentence.contains("deadline 1000 µs"), "{sentence}");
    assert!(
        sentence.contains("At urgent it would accept every"),
        "{sentence}"
    );
}
