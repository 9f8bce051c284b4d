//! End-to-end SLCAN: the test plays a USB-serial CAN adapter on the master side of a pseudo-terminal while the
//! real `amiro` binary talks to the slave side, and both directions are checked byte for byte.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Output, Stdio};
use std::time::{Duration, Instant};

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use serde_json::Value;

mod common;
use common::{assert_mentions, thesis};

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

    /// Starts `amiro` with `args` on this adapter (`--bus` added) and accepts its channel set-up.
    fn start(&mut self, args: &[&str]) -> Child {
        let child = self.spawn(args);
        self.accept_open();
        child
    }

    /// Starts `amiro` with `args` on this adapter (`--bus` added).
    fn spawn(&self, args: &[&str]) -> Child {
        let bus = self.bus();
        let mut args = args.to_vec();
        args.extend(["--bus", &bus]);
        amiro(&args)
    }

    /// Answers `amiro`'s close of the channel, then waits for it to exit.
    fn close(&mut self, child: Child) -> Output {
        self.expect("C\r", b"\r");
        finish(child)
    }
}

/// A rendezvous directory of its own per test binary run, so no other `amiro` on this machine is found.
fn runtime_dir() -> &'static Path {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("tempdir"))
        .path()
}

/// `amiro` with `args`: no bus from the environment, this test run's rendezvous directory, output piped.
fn amiro_command(args: &[&str]) -> Command {
    let mut command = Command::new(assert_cmd::cargo::cargo_bin("amiro"));
    command
        .args(args)
        .env_remove("AMIRO_BUS")
        .env("AMIRO_RUNTIME_DIR", runtime_dir())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    command
}

/// `amiro` with `args` started, without input.
fn amiro(args: &[&str]) -> Child {
    amiro_command(args)
        .stdin(Stdio::null())
        .spawn()
        .expect("start amiro")
}

/// `amiro`'s standard output, read as it is written: a test waits for what `amiro` must have printed before it
/// acts (an interrupt, say) instead of sleeping and hoping a loaded machine kept up.
struct Watched {
    stdout: ChildStdout,
    seen: Vec<u8>,
}

impl Watched {
    /// Takes over `child`'s piped standard output ([`finish`]'s output then has none).
    fn of(child: &mut Child) -> Self {
        Self {
            stdout: child.stdout.take().expect("amiro's stdout is piped"),
            seen: Vec::new(),
        }
    }

    /// Reads until `needle` has been printed, failing the test after [`PATIENCE`].
    fn wait_for(&mut self, needle: &str) {
        assert!(
            self.within(needle, PATIENCE),
            "amiro never printed {needle:?}; it printed: {}",
            String::from_utf8_lossy(&self.seen)
        );
    }

    /// Reads until `needle` has been printed (`true`) or `patience` has passed (`false`).
    fn within(&mut self, needle: &str, patience: Duration) -> bool {
        let deadline = Instant::now() + patience;
        while !String::from_utf8_lossy(&self.seen).contains(needle) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            let mut fds = [PollFd::new(self.stdout.as_fd(), PollFlags::POLLIN)];
            if poll(&mut fds, PollTimeout::try_from(left).unwrap()).expect("poll") == 0 {
                continue;
            }
            let mut chunk = [0u8; 512];
            let count = self.stdout.read(&mut chunk).expect("read amiro's stdout");
            assert!(
                count > 0,
                "amiro closed its stdout before printing {needle:?}: {}",
                String::from_utf8_lossy(&self.seen)
            );
            self.seen.extend_from_slice(&chunk[..count]);
        }
        true
    }

    /// Everything `amiro` printed, once it has exited.
    fn all(mut self) -> String {
        self.stdout
            .read_to_end(&mut self.seen)
            .expect("read amiro's stdout");
        String::from_utf8(self.seen).expect("UTF-8 output")
    }
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

/// Fails unless `amiro` succeeded, with what it said on standard error.
fn assert_succeeded(output: &Output) {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

#[test]
fn send_opens_the_channel_transmits_the_thesis_frame_and_closes() {
    let mut adapter = FakeAdapter::new();
    let child = adapter.start(&thesis("send"));
    // A frame from the bus arriving before the transmit acknowledgement must not confuse the sender.
    adapter.expect("t205401840302\r", b"t6054D8ADFFFF\rz\r");
    let output = adapter.close(child);
    assert_succeeded(&output);
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
    let child = adapter.start(&["send", "204#02", "110#A0860100B03CFFFF"]);
    adapter.expect("t204102\r", b"z\r");
    adapter.expect("t1108A0860100B03CFFFF\r", b"\r");
    assert_succeeded(&adapter.close(child));
    assert_eq!(
        adapter.heard,
        b"C\rS8\rO\rt204102\rt1108A0860100B03CFFFF\rC\r"
    );
}

#[test]
fn monitor_reads_frames_split_across_writes_and_closes_the_channel() {
    let mut adapter = FakeAdapter::new();
    let child = adapter.start(&["monitor", "--count", "3", "--json"]);
    // Gyroscope with negative values, split in the middle; a version string and a BEL in between are not frames;
    // then a magnetometer frame with the adapter's own timestamp, and a command that is too short.
    adapter.say(b"t6086FCFF1E");
    std::thread::sleep(Duration::from_millis(50));
    adapter.say(b"00FBFF\rV1013\r\x07t6054D8ADFFFF12AB\rt20520184\r");
    let output = adapter.close(child);
    assert_succeeded(&output);
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
    let mut child = adapter.start(&["monitor"]);
    let mut printed = Watched::of(&mut child);
    adapter.say(b"t71F3037800\r");
    // Once amiro has printed the frame, interrupt it as a user would.
    printed.wait_for("front-left sees 120 mm");
    interrupt(&child);
    assert_succeeded(&adapter.close(child));
    let stdout = printed.all();
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
    let child = adapter.spawn(&["send", "205#00"]);
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
    let child = adapter.start(&["send", "308#00"]);
    adapter.expect("t308100\r", b"\x07");
    let output = adapter.close(child);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("refused to transmit 308#00"), "{stderr}");
}

#[test]
fn a_silent_device_is_not_mistaken_for_an_adapter() {
    let mut adapter = FakeAdapter::new();
    let child = adapter.spawn(&["send", "205#00"]);
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
    let mut monitor = adapter.start(&["monitor", "--absolute"]);
    let mut printed = Watched::of(&mut monitor);
    // The thesis's workflow: one terminal watches, another sends.
    let sender = adapter.spawn(&["send", "205#01840302"]);
    adapter.expect("t205401840302\r", b"z\rt6054D8ADFFFF\r");
    let sent = finish(sender);
    assert_succeeded(&sent);
    assert!(String::from_utf8_lossy(&sent.stdout).starts_with("sent 205#01840302"));
    printed.wait_for("605#D8ADFFFF");
    interrupt(&monitor);
    assert_succeeded(&adapter.close(monitor));
    // Only the owner opened and closed the channel; the sender's frame went through it.
    assert_eq!(adapter.heard, b"C\rS8\rO\rt205401840302\rC\r");
    let stdout = printed.all();
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
    let owner = adapter.start(&["monitor"]);
    let mut user = adapter.spawn(&["monitor"]);
    let mut printed = Watched::of(&mut user);
    // Frames keep coming while the second monitor connects; once connected it prints them.
    let deadline = Instant::now() + PATIENCE;
    loop {
        adapter.say(b"t71F3037800\r");
        if printed.within("71F#037800", Duration::from_millis(100)) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the second monitor never printed a frame"
        );
    }
    assert!(
        user.try_wait().unwrap().is_none(),
        "the second monitor runs"
    );
    interrupt(&owner);
    assert!(adapter.close(owner).status.success());
    let output = finish(user);
    assert!(!output.status.success(), "a lost bus is a failure");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("lost the bus") && stderr.contains("amiro monitor"),
        "{stderr}"
    );
    let stdout = printed.all();
    assert!(
        stdout.contains("71F#037800"),
        "it saw frames while connected: {stdout}"
    );
}

/// Answers every command with `z` and notes when each motor frame arrived, until the stop and the close.
fn record_motor_frames(adapter: &mut FakeAdapter) -> Vec<(Instant, String)> {
    let mut motor = Vec::new();
    loop {
        let heard = adapter.hear();
        if heard == "C\r" {
            adapter.say(b"\r");
            return motor;
        }
        assert!(
            heard.starts_with("t110"),
            "only motor frames while driving: {heard:?}"
        );
        motor.push((Instant::now(), heard));
        adapter.say(b"z\r");
    }
}

const FORWARD_100: &str = "t1108A086010000000000\r";
const STOP: &str = "t11080000000000000000\r";

#[test]
fn drive_repeats_the_motor_command_within_the_deadman_and_ends_with_a_stop() {
    let mut adapter = FakeAdapter::new();
    let child = adapter.start(&["drive", "--forward", "100mm/s", "--for", "1s"]);
    let motor = record_motor_frames(&mut adapter);
    let output = finish(child);
    assert_succeeded(&output);
    let (last_at, last) = motor.last().unwrap();
    assert_eq!(last, STOP);
    assert!(
        motor[..motor.len() - 1]
            .iter()
            .all(|(_, frame)| frame == FORWARD_100),
        "{motor:?}"
    );
    // Every 200 ms for 1 s: 5 commands and the stop. A loaded machine may be late (never bursting to catch
    // up), so one repeat fewer is tolerated; the gap bound below is what protects the robot.
    assert!((5..=6).contains(&motor.len()), "{motor:?}");
    for pair in motor.windows(2) {
        let gap = pair[1].0 - pair[0].0;
        assert!(
            gap < Duration::from_millis(450),
            "a gap of {gap:?} lets the dead-man stop the robot"
        );
    }
    let total = *last_at - motor[0].0;
    assert!(total >= Duration::from_millis(950), "drove {total:?}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("sent") && stdout.contains("motor: drive at 100000 µm/s"),
        "{stdout}"
    );
}

#[test]
fn ctrl_c_while_driving_stops_the_robot_before_closing() {
    let mut adapter = FakeAdapter::new();
    let child = adapter.start(&["drive", "--forward", "100mm/s", "--turn", "30deg/s"]);
    for _ in 0..3 {
        assert!(adapter.hear().starts_with("t1108A08601004FFD0700"));
        adapter.say(b"z\r");
    }
    interrupt(&child);
    let mut rest = record_motor_frames(&mut adapter);
    let (_, last) = rest.pop().expect("a stop");
    assert_eq!(last, STOP);
    let output = finish(child);
    assert_eq!(output.status.code(), Some(130));
}

#[test]
fn a_script_plays_its_steps_in_order_and_prints_what_comes_back() {
    let mut adapter = FakeAdapter::new();
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("short.amiro");
    std::fs::write(
        &script,
        "# a short demo\npublish gyroscope --every 100ms --priority high\nwait 300ms\nled 3 --rgb 0,50,120\n\
         drive --forward 100mm/s --for 500ms\n",
    )
    .unwrap();
    let child = adapter.start(&["run", script.to_str().unwrap()]);
    let gyroscope_published = Instant::now();
    adapter.expect("t108401640000\r", b"z\rt5086FCFF1E00FBFF\r");
    adapter.expect("t3133003278\r", b"z\r");
    assert!(
        gyroscope_published.elapsed() >= Duration::from_millis(300),
        "the wait was kept"
    );
    let motor = record_motor_frames(&mut adapter);
    assert_eq!(motor.first().unwrap().1, FORWARD_100);
    assert_eq!(motor.last().unwrap().1, STOP);
    let output = finish(child);
    assert_succeeded(&output);
    assert_mentions(
        &String::from_utf8_lossy(&output.stdout),
        &[
            "# line 2: publish gyroscope",
            "sent (",
            "gyroscope: x -4 dps, y 30 dps, z -5 dps",
            "led-3: set colour red 0, green 50, blue 120",
        ],
    );
}

#[test]
fn a_headless_console_sends_drives_and_shares_its_adapter() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let mut console = amiro_command(&["console", "--headless", "--linger", "100ms", "--bus", &bus])
        .stdin(Stdio::piped())
        .spawn()
        .expect("start amiro console");
    adapter.accept_open();
    let mut input = console.stdin.take().unwrap();
    writeln!(input, "publish gyroscope --every 10ms --priority high").unwrap();
    adapter.expect("t1084010A0000\r", b"z\rt5086FCFF1E00FBFF\r");
    // Another amiro on the same adapter goes through the console.
    let led = adapter.spawn(&["send", "led", "3", "--rgb", "255,128,0"]);
    adapter.expect("t3133FF8000\r", b"z\r");
    assert!(finish(led).status.success());
    writeln!(input, "drive --forward 100mm/s --for 600ms").unwrap();
    drop(input);
    let motor = record_motor_frames(&mut adapter);
    assert_eq!(motor.first().unwrap().1, FORWARD_100);
    assert_eq!(motor.last().unwrap().1, STOP);
    assert!((3..=5).contains(&motor.len()), "{motor:?}");
    let output = finish(console);
    assert_succeeded(&output);
    assert_mentions(
        &String::from_utf8_lossy(&output.stdout),
        &[
            "> publish gyroscope",
            "sent (",
            "gyroscope: x -4 dps",
            "313#FF8000",
        ],
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("summary:"), "{stderr}");
}

#[test]
fn the_console_screen_runs_on_a_terminal_and_ctrl_c_closes_the_channel() {
    let mut adapter = FakeAdapter::new();
    let bus = adapter.bus();
    let size = nix::pty::Winsize {
        ws_row: 30,
        ws_col: 120,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let terminal = openpty(Some(&size), None).expect("openpty");
    let slave = File::from(terminal.slave);
    let mut keyboard = File::from(terminal.master);
    // The screen must be read, or the console blocks writing it.
    let mut screen_reader = keyboard.try_clone().unwrap();
    let screen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let screen_sink = std::sync::Arc::clone(&screen);
    std::thread::spawn(move || {
        let mut buffer = [0u8; 4096];
        while let Ok(count) = screen_reader.read(&mut buffer) {
            if count == 0 {
                break;
            }
            screen_sink
                .lock()
                .unwrap()
                .extend_from_slice(&buffer[..count]);
        }
    });
    let child = amiro_command(&["console", "--bus", &bus])
        .env("TERM", "xterm")
        .stdin(slave.try_clone().unwrap())
        .stdout(slave.try_clone().unwrap())
        .spawn()
        .expect("start amiro console");
    drop(slave);
    adapter.accept_open();
    // Type only once the screen is up (the terminal is in raw mode then).
    let deadline = Instant::now() + PATIENCE;
    // Cells are drawn with cursor moves in between words, so look for single words of the title.
    let drawn = |screen: &[u8]| {
        let text = String::from_utf8_lossy(screen);
        text.contains("console") && text.contains("F3")
    };
    while !drawn(&screen.lock().unwrap()) {
        assert!(
            Instant::now() < deadline,
            "the console never drew its screen"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    keyboard
        .write_all(b"publish gyroscope --every 10ms --priority high\r")
        .unwrap();
    adapter.expect("t1084010A0000\r", b"z\r");
    while !String::from_utf8_lossy(&screen.lock().unwrap()).contains("108#010A0000") {
        assert!(
            Instant::now() < deadline,
            "the sent frame never appeared on the screen"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    keyboard.write_all(b"\x03").unwrap();
    assert_succeeded(&adapter.close(child));
    let screen = String::from_utf8_lossy(&screen.lock().unwrap()).into_owned();
    assert!(screen.contains("\u{1b}[?1049l"), "the terminal is restored");
}

#[test]
fn health_asks_each_board_once_and_reports_the_silent_one() {
    use amiro_can::{Board, Diagnostics, Priority};
    let mut adapter = FakeAdapter::new();
    let child = adapter.start(&[
        "health",
        "--board",
        "diwheeldrive",
        "--board",
        "lightring",
        "--timeout",
        "1s",
    ]);
    // One-shot requests (mode 2) on each board's diagnostics topic, at low priority.
    adapter.expect("t31A102\r", b"z\r");
    adapter.expect("t31C102\r", b"z\r");
    let mut diagnostics = Diagnostics::ZERO;
    diagnostics.uptime_s = 42;
    let mut answer = Vec::new();
    for frame in diagnostics.frames(Board::DiWheelDrive, Priority::Low, 0) {
        answer.extend_from_slice(
            format!("t{:03X}{}", frame.id().raw(), frame.data().len()).as_bytes(),
        );
        for byte in frame.data() {
            answer.extend_from_slice(format!("{byte:02X}").as_bytes());
        }
        answer.push(b'\r');
    }
    adapter.say(&answer);
    let output = adapter.close(child);
    assert_eq!(output.status.code(), Some(1), "LightRing never answered");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("DiWheelDrive: healthy, up 42 s"),
        "{stderr}"
    );
    assert!(stderr.contains("LightRing: no answer"), "{stderr}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(
        stdout.lines().count(),
        6,
        "the six pages are printed: {stdout}"
    );
}

/// (channel, log time) of every message of an MCAP file.
fn mcap_messages(path: &Path) -> Vec<(String, u64)> {
    let bytes = std::fs::read(path).expect("the MCAP file");
    mcap::MessageStream::new(&bytes)
        .expect("a complete MCAP file")
        .map(|message| {
            let message = message.expect("a message");
            (message.channel.topic.clone(), message.log_time)
        })
        .collect()
}

#[test]
fn record_writes_what_the_adapter_hears_stamped_on_arrival_and_stops_after_its_duration() {
    let mut adapter = FakeAdapter::new();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("live.mcap");
    let out_text = out.display().to_string();
    let before = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let started = Instant::now();
    let child = adapter.start(&["record", "--out", &out_text, "--duration", "700ms"]);
    adapter.say(b"t6086FCFF1E00FBFF\r");
    std::thread::sleep(Duration::from_millis(200));
    adapter.say(b"t6086FDFF1E00FBFF\r");
    assert_succeeded(&adapter.close(child));
    assert!(started.elapsed() < Duration::from_secs(5));
    assert_eq!(adapter.heard, b"C\rS8\rO\rC\r");
    let messages = mcap_messages(&out);
    let gyroscope: Vec<u64> = messages
        .iter()
        .filter(|(channel, _)| channel == "/amiro/gyroscope")
        .map(|(_, time)| *time)
        .collect();
    assert_eq!(gyroscope.len(), 2, "{messages:?}");
    // Host reception times: after the start, about 200 ms apart.
    assert!(gyroscope[0] >= before, "{gyroscope:?} before {before}");
    let apart = gyroscope[1] - gyroscope[0];
    assert!((150_000_000..1_000_000_000).contains(&apart), "{apart}");
}

#[test]
fn ctrl_c_ends_a_recording_with_a_complete_file() {
    let mut adapter = FakeAdapter::new();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("interrupted.mcap");
    let out_text = out.display().to_string();
    let mut child = adapter.start(&["monitor", "--record", &out_text]);
    let mut printed = Watched::of(&mut child);
    adapter.say(b"t71F3037800\r");
    // Interrupted once the frame is in (printed, so it has been recorded).
    printed.wait_for("71F#037800");
    interrupt(&child);
    assert_succeeded(&adapter.close(child));
    let messages = mcap_messages(&out);
    assert!(
        messages
            .iter()
            .any(|(channel, _)| channel == "/amiro/proximity-ring"),
        "{messages:?}"
    );
}
