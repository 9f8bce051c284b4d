//! MCAP recordings, the dashboard and the spoken commands, run as a user runs `amiro`: against a candump log
//! through the `file:` bus (the same `Bus` trait SLCAN and SocketCAN implement).

use std::path::{Path, PathBuf};

use assert_cmd::Command;
use serde_json::Value;

const LOG: &str = "\
(1700000000.000000) can0 108#01640000
(1700000000.100000) can0 508#FCFF1E00FBFF
(1700000000.200000) can0 508#FDFF1F00FBFF
(1700000000.300000) can0 508#FEFF2000FBFF
(1700000000.500000) can0 508#FFFF2100FBFF
(1700000000.510000) can0 71E#003E4701720C
(1700000000.530000) can0 71F#037800
(1700000000.540000) can0 010#A0860100B03CFFFF
(1700000000.600000) can0 508#00002200FBFF
";

fn amiro() -> Command {
    let mut command = Command::cargo_bin("amiro").expect("amiro binary");
    command.env_remove("AMIRO_BUS");
    command
}

fn log(dir: &Path) -> PathBuf {
    let path = dir.join("run.log");
    std::fs::write(&path, LOG).expect("write the log");
    path
}

/// (channel, log time, message) of every message in the file, in file order.
fn messages(path: &Path) -> Vec<(String, u64, Value)> {
    let bytes = std::fs::read(path).expect("the MCAP file");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|message| {
            let message = message.expect("a message");
            (
                message.channel.topic.clone(),
                message.log_time,
                serde_json::from_slice(&message.data).expect("JSON"),
            )
        })
        .collect()
}

fn check_recording(path: &Path) {
    let all = messages(path);
    let gyroscope: Vec<_> = all
        .iter()
        .filter(|(channel, _, _)| channel == "/amiro/gyroscope")
        .collect();
    assert_eq!(gyroscope.len(), 5);
    assert_eq!(gyroscope[0].1, 1_700_000_000_100_000_000);
    assert_eq!(gyroscope[0].2["x_dps"], -4);
    assert_eq!(gyroscope[4].1, 1_700_000_000_600_000_000);
    let frames = all.iter().filter(|(c, _, _)| c == "/amiro/frames").count();
    assert_eq!(frames, 9, "every frame on the raw channel");
    assert!(all
        .iter()
        .any(|(c, _, v)| c == "/amiro/motor/command" && v["velocity_um_s"] == 100_000));
}

#[test]
fn record_monitor_and_decode_write_the_same_recording() {
    let dir = tempfile::tempdir().unwrap();
    let log = log(dir.path());
    let bus = format!("file:{}", log.display());
    let recorded = dir.path().join("record.mcap");
    let output = amiro()
        .args(["record", "--bus", &bus, "--out"])
        .arg(&recorded)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    assert!(String::from_utf8_lossy(&output.stderr).contains("recorded 9 frames"));
    check_recording(&recorded);

    let decoded = dir.path().join("decode.mcap");
    let output = amiro()
        .args(["decode", "--file"])
        .arg(&log)
        .arg("--mcap")
        .arg(&decoded)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    assert!(String::from_utf8_lossy(&output.stdout).contains("gyroscope: x 0 dps"));
    check_recording(&decoded);

    let monitored = dir.path().join("monitor.mcap");
    let output = amiro()
        .args(["monitor", "--bus", &bus, "--topic", "motor", "--record"])
        .arg(&monitored)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(
        stdout.lines().count(),
        1,
        "the filter chooses what is printed: {stdout}"
    );
    check_recording(&monitored);
    assert_eq!(
        std::fs::read(&recorded).unwrap(),
        std::fs::read(&monitored).unwrap()
    );
}

#[test]
fn record_adds_a_virtual_robots_world_and_refuses_a_malformed_one() {
    let dir = tempfile::tempdir().unwrap();
    let log = log(dir.path());
    let bus = format!("file:{}", log.display());
    let world = dir.path().join("world.json");
    std::fs::write(
        &world,
        r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 },
             "walls": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]] }"#,
    )
    .unwrap();
    // Rows in the log's time: two before its frames, one among them, one after.
    let trajectory = dir.path().join("path.csv");
    std::fs::write(
        &trajectory,
        "t_s,x_m,y_m,heading_deg\n1699999999.000000,0.5,0.5,0\n1699999999.500000,0.6,0.5,0\n\
         1700000000.250000,0.7,0.5,10\n1700000001.000000,0.8,0.5,20\n",
    )
    .unwrap();
    let out = dir.path().join("world.mcap");
    let output = amiro()
        .args(["record", "--bus", &bus, "--out"])
        .arg(&out)
        .arg("--world")
        .arg(&world)
        .arg("--trajectory")
        .arg(&trajectory)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    assert!(String::from_utf8_lossy(&output.stderr).contains("recorded 9 frames and 4 poses"));
    let all = messages(&out);
    check_recording(&out);
    let topics: Vec<&str> = all
        .iter()
        .filter(|(c, _, _)| c.starts_with("/world/"))
        .map(|(c, _, _)| c.as_str())
        .collect();
    assert_eq!(
        topics,
        [
            "/world/arena",
            "/world/pose",
            "/world/pose",
            "/world/pose",
            "/world/pose"
        ]
    );
    let times: Vec<u64> = all.iter().map(|(_, t, _)| *t).skip(1).collect();
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");

    std::fs::write(
        &world,
        r#"{ "robot": { "x": 0.5, "y": 0.5, "heading_deg": 0 }, "floor": [ { "polygon": [[0, 0], [1, 0]], "grey": 0 } ] }"#,
    )
    .unwrap();
    let refused = dir.path().join("refused.mcap");
    let output = amiro()
        .args(["record", "--bus", &bus, "--out"])
        .arg(&refused)
        .arg("--world")
        .arg(&world)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("floor[0].polygon: 2 points, at least 3 needed"),
        "{stderr}"
    );
    assert!(!refused.exists(), "nothing written for a malformed world");
}

#[test]
fn the_dashboard_of_a_log_is_printed_when_output_is_not_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let log = log(dir.path());
    let output = amiro()
        .args(["monitor", "--dashboard", "--no-summary", "--bus"])
        .arg(format!("file:{}", log.display()))
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    let text = String::from_utf8(output.stdout).unwrap();
    assert_eq!(text.lines().count(), 24, "{text}");
    let gyro = text.lines().find(|l| l.contains("gyroscope")).expect(&text);
    assert!(
        gyro.contains("0 34 -5 dps") && gyro.contains("125/100") && gyro.contains("1/1"),
        "{gyro}"
    );
    assert!(
        text.contains("DiWheelDrive: no diagnostics heard"),
        "{text}"
    );
}

#[test]
fn scripts_take_the_spoken_forms() {
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("spoken.amiro");
    std::fs::write(
        &script,
        "publish gyroscope every 100ms at high\nonce floor at urgent\nstop gyroscope\nled 3 #FF8020\n\
         drive 100mm/s turn 30deg/s for 3s\n",
    )
    .unwrap();
    let output = amiro()
        .args(["run", "--check"])
        .arg(&script)
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    let stdout = String::from_utf8(output.stdout).unwrap();
    for frame in [
        "108#01640000",
        "004#02",
        "208#00",
        "313#FF8020",
        "drive 100000 µm/s, 523599 µrad/s",
    ] {
        assert!(stdout.contains(frame), "{frame} in {stdout}");
    }
    std::fs::write(&script, "publish magnetomter-x every 1s\n").unwrap();
    let output = amiro()
        .args(["run", "--check"])
        .arg(&script)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8(output.stderr).unwrap();
    assert!(
        stderr.contains("line 1") && stderr.contains("did you mean magnetometer-x?"),
        "{stderr}"
    );
}

#[test]
fn the_dashboard_capture_in_the_user_guide_is_what_amiro_prints() {
    let guide = include_str!("../../docs/operator.md");
    let section = &guide[guide
        .find("## The dashboard")
        .expect("the dashboard section")..];
    let start = section.find("```text\n").expect("the capture") + "```text\n".len();
    let capture = &section[start..start + section[start..].find("```").expect("its end")];
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let output = amiro()
        .args(["monitor", "--dashboard", "--no-summary", "--bus"])
        .arg(format!(
            "file:{}",
            root.join("examples/dashboard-demo.log").display()
        ))
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    assert_eq!(String::from_utf8(output.stdout).unwrap(), capture);
}
