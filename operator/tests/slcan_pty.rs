//! End-to-end SLCAN: the test plays a USB-serial CAN adapter on the master side of a pseudo-terminal while the
//! real `amiro` binary talks to the slave side, and both directions are checked byte for byte.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use serde_json::Value;

/// How long the fake adapter waits for the next byte from `amiro` before failing the test.
const PATIENCE: Duration = Duration::from_secs(10);

/// The adapter end of a pseudo-terminal, and the device path `amiro` opens.
struct FakeAdapter {
    master: File,
    /// Kept open so the master never sees a hang-up between `amiro` runs.
    _slave: OwnedFd,
    path: PathBuf,
    /// Every byte `amiro` wrote, in order.
    heard: Vec<u8>,
}

impl FakeAdapter {
    fn new() -> Self {
        let pty = openpty(None, None).expect("openpty");
        let path = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd()))
            .expect("slave path");
        Self {
            master: File::from(pty.master),
            _slave: pty.slave,
            path,
            heard: Vec::new(),
        }
    }

    fn bus(&self) -> String {
        format!("slcan:{}", self.path.display())
    }

    /// Reads one `\r`-terminated command from `amiro` and returns it (with the `\r`).
    fn hear(&mut self) -> String {
        let deadline = Instant::now() + PATIENCE;
        let mut command = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            assert!(
                !left.is_zero(),
                "amiro went quiet; heard so far: {:?}",
                String::from_utf8_lossy(&self.heard)
            );
            let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
            let ready = poll(&mut fds, PollTimeout::try_from(left).unwrap()).expect("poll");
            if ready == 0 {
                continue;
            }
            let mut byte = [0u8; 1];
            let count = self.master.read(&mut byte).expect("read from amiro");
            assert_eq!(count, 1, "pty closed");
            self.heard.push(byte[0]);
            command.push(byte[0]);
            if byte[0] == b'\r' {
                return String::from_utf8(command).expect("ASCII command");
            }
        }
    }

    /// Expects exactly `expected` from `amiro`, then answers `reply`.
    fn expect(&mut self, expected: &str, reply: &[u8]) {
        let heard = self.hear();
        assert_eq!(heard, expected, "amiro sent the wrong command");
        self.say(reply);
    }

    fn say(&mut self, bytes: &[u8]) {
        self.master.write_all(bytes).expect("write to amiro");
        self.master.flush().expect("flush");
    }

    /// The channel set-up every `amiro` run starts with: close, 1 Mbit/s, open.
    fn accept_open(&mut self) {
        self.expect("C\r", b"\r");
        self.expect("S8\r", b"\r");
        self.expect("O\r", b"\r");
    }
}

/// A rendezvous directory of its own per test binary run, so no other `amiro` on this machine is found.
fn runtime_dir() -> &'static Path {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("tempdir"))
        .path()
}

fn amiro(args: &[&str]) -> Child {
    Command::new(assert_cmd::cargo::cargo_bin("amiro"))
        .args(args)
        .env_remove("AMIRO_BUS")
        .env("AMIRO_RUNTIME_DIR", runtime_dir())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start amiro")
}

/// Waits for `amiro` to exit, failing the test instead of hanging if it does not.
fn finish(mut child: Child) -> Output {
    let deadline = Instant::now() + PATIENCE;
    while child.try_wait().expect("wait").is_none() {
        if Instant::now() > deadline {
            child.kill().ok();
            panic!("amiro did not exit: {:?}", child.wait_with_output().ok());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().expect("output")
}

#[test]
fn send_opens_the_channel_transmits_the_thesis_frame_and_closes() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&[
        "send",
        "publish",
        "magnetometer-x",
        "--every",
        "900us",
        "--priority",
        "medium",
        "--bus",
        &bus,
    ]);
    adapter.accept_open();
    // A frame from the bus arriving before the transmit acknowledgement must not confuse the sender.
    adapter.expect("t205401840302\r", b"t6054D8ADFFFF\rz\r");
    adapter.expect("C\r", b"\r");
    let output = finish(child);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(adapter.heard, b"C\rS8\rO\rt205401840302\rC\r");
    let stdout = String::from_utf8(output.stdout).unwrap();
    assert!(stdout.starts_with("sent 205#01840302"), "{stdout}");
    assert!(
        stdout.contains("magnetometer-x: publish every 900 µs"),
        "{stdout}"
    );
}

#[test]
fn send_passes_several_raw_frames_in_order() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["send", "204#02", "110#A0860100B03CFFFF", "--bus", &bus]);
    adapter.accept_open();
    adapter.expect("t204102\r", b"z\r");
    adapter.expect("t1108A0860100B03CFFFF\r", b"\r");
    adapter.expect("C\r", b"\r");
    let output = finish(child);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(
        adapter.heard,
        b"C\rS8\rO\rt204102\rt1108A0860100B03CFFFF\rC\r"
    );
}

#[test]
fn monitor_reads_frames_split_across_writes_and_closes_the_channel() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["monitor", "--bus", &bus, "--count", "3", "--json"]);
    adapter.accept_open();
    // Gyroscope with negative values, split in the middle; a version string and a BEL in between are not frames;
    // then a magnetometer frame with the adapter's own timestamp, and a command that is too short.
    adapter.say(b"t6086FCFF1E");
    std::thread::sleep(Duration::from_millis(50));
    adapter.say(b"00FBFF\rV1013\r\x07t6054D8ADFFFF12AB\rt20520184\r");
    adapter.expect("C\r", b"\r");
    let output = finish(child);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(adapter.heard, b"C\rS8\rO\rC\r");

    let records: Vec<Value> = String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).expect("each line is JSON"))
        .collect();
    assert_eq!(records.len(), 3);
    assert_eq!(records[0]["frame"], "608#FCFF1E00FBFF");
    assert_eq!(records[0]["values"]["x_dps"], -4);
    assert_eq!(records[0]["values"]["z_dps"], -5);
    assert_eq!(records[0]["interface"], "slcan");
    assert!(records[0]["timestamp"].is_string());
    assert_eq!(records[1]["topic"], "magnetometer-x");
    assert_eq!(records[1]["values"]["nanotesla"], -21032);
    assert_eq!(records[2]["ok"], false);
    assert_eq!(records[2]["error"], "dlc-too-short");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("V1013"),
        "the unknown message is reported: {stderr}"
    );
}

#[test]
fn ctrl_c_closes_the_channel_before_exit() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["monitor", "--bus", &bus]);
    adapter.accept_open();
    adapter.say(b"t71F3037800\r");
    // Give amiro time to print the frame, then interrupt it as a user would.
    std::thread::sleep(Duration::from_millis(200));
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).expect("SIGINT");
    adapter.expect("C\r", b"\r");
    let output = finish(child);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8(output.stdout).unwrap();
    assert!(
        stdout.contains("71F#037800")
            && stdout.contains("proximity-ring: sensor 3 front-left sees 120 mm"),
        "{stdout}"
    );
    assert_eq!(adapter.heard, b"C\rS8\rO\rC\r");
}

#[test]
fn an_adapter_refusing_to_open_is_a_clear_error() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["send", "205#00", "--bus", &bus]);
    adapter.expect("C\r", b"\x07");
    adapter.expect("S8\r", b"\r");
    adapter.expect("O\r", b"\x07");
    let output = finish(child);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("refused \"O\" (open the CAN channel)"),
        "{stderr}"
    );
    // Nothing was sent, and a channel that never opened is not closed.
    assert_eq!(adapter.heard, b"C\rS8\rO\r");
}

#[test]
fn a_refused_frame_is_an_error_and_the_channel_is_still_closed() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["send", "308#00", "--bus", &bus]);
    adapter.accept_open();
    adapter.expect("t308100\r", b"\x07");
    adapter.expect("C\r", b"\r");
    let output = finish(child);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("refused to transmit 308#00"), "{stderr}");
}

#[test]
fn a_silent_device_is_not_mistaken_for_an_adapter() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let child = amiro(&["send", "205#00", "--bus", &bus]);
    assert_eq!(adapter.hear(), "C\r");
    let output = finish(child);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("no answer to \"C\"") && stderr.contains("SLCAN adapter"),
        "{stderr}"
    );
}

fn interrupt(child: &Child) {
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).expect("SIGINT");
}

#[test]
fn a_second_amiro_sends_through_the_first_without_closing_its_channel() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let monitor = amiro(&["monitor", "--bus", &bus, "--absolute"]);
    adapter.accept_open();
    // The thesis's workflow: one terminal watches, another sends.
    let sender = amiro(&["send", "205#01840302", "--bus", &bus]);
    adapter.expect("t205401840302\r", b"z\rt6054D8ADFFFF\r");
    let sent = finish(sender);
    assert!(
        sent.status.success(),
        "{}",
        String::from_utf8_lossy(&sent.stderr)
    );
    assert!(String::from_utf8_lossy(&sent.stdout).starts_with("sent 205#01840302"));
    std::thread::sleep(Duration::from_millis(200));
    interrupt(&monitor);
    adapter.expect("C\r", b"\r");
    let watched = finish(monitor);
    assert!(
        watched.status.success(),
        "{}",
        String::from_utf8_lossy(&watched.stderr)
    );
    // Only the owner opened and closed the channel; the sender's frame went through it.
    assert_eq!(adapter.heard, b"C\rS8\rO\rt205401840302\rC\r");
    let stdout = String::from_utf8(watched.stdout).unwrap();
    let sent_at = stdout.find("205#01840302").expect(&stdout);
    let answer_at = stdout.find("605#D8ADFFFF").expect(&stdout);
    assert!(
        sent_at < answer_at,
        "the monitor shows the command, then the answer:\n{stdout}"
    );
}

#[test]
fn a_monitor_whose_bus_owner_ends_reports_the_lost_bus_and_fails() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let owner = amiro(&["monitor", "--bus", &bus]);
    adapter.accept_open();
    let mut user = amiro(&["monitor", "--bus", &bus]);
    // Frames keep coming while the second monitor connects; once connected it prints them.
    for _ in 0..6 {
        adapter.say(b"t71F3037800\r");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        user.try_wait().unwrap().is_none(),
        "the second monitor runs"
    );
    interrupt(&owner);
    adapter.expect("C\r", b"\r");
    let owner_output = finish(owner);
    assert!(owner_output.status.success());
    let output = finish(user);
    assert!(!output.status.success(), "a lost bus is a failure");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("lost the bus") && stderr.contains("amiro monitor"),
        "{stderr}"
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("71F#037800"),
        "it saw frames while connected: {stdout}"
    );
}
