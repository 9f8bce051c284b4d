//! The console's state machine, free of any terminal: keys, heard frames and clock ticks go in, frames to send
//! and lines to show come out. The terminal front end (`ui`) and the headless mode only carry events to it, so
//! everything the console decides is tested here.

use std::collections::VecDeque;
use std::time::Duration;

use amiro_can::{MotorCommand, Priority};

use crate::admission::Checker;
use crate::dashboard::Dashboard;
use crate::describe::decode_frame;
use crate::drive::{motor_frame, KeepAlive};
use crate::frame::{LoggedFrame, RawFrame, Timestamp};
use crate::script::{parse_step, Step, CONSOLE_EVERY};
use crate::watch::{Filter, Statistics, View};

use super::complete;
use super::menu::{Menu, Question};

/// Lines kept for scrolling back.
const LOG_LINES: usize = 5000;
/// Teleoperation steps: 50 mm/s forward, 30 °/s turning.
const SPEED_STEP: i32 = 50_000;
const TURN_STEP: i32 = 523_599;
/// The DiWheelDrive's wheel speed limit (0.5 m/s): asking for more only saturates.
const MAX_SPEED: i32 = 500_000;
/// About 4 turns per second: more than the robot can do.
const MAX_TURN: i32 = 25_132_741;

/// A key, as the console understands it (the terminal front end maps crossterm's events to these).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// A printable character.
    Char(char),
    /// Enter.
    Enter,
    /// Tab.
    Tab,
    /// Backspace.
    Backspace,
    /// Arrow up.
    Up,
    /// Arrow down.
    Down,
    /// Arrow left.
    Left,
    /// Arrow right.
    Right,
    /// Page up.
    PageUp,
    /// Page down.
    PageDown,
    /// End.
    End,
    /// Escape.
    Esc,
    /// F2: the menu.
    Menu,
    /// F3: drive mode.
    Drive,
    /// F4: the dashboard instead of the scrolling log, and back.
    Dashboard,
    /// Ctrl-C.
    Interrupt,
}

/// What the console is doing with keys.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Typing a command line.
    Command,
    /// Building a command from menus.
    Menu(Menu),
    /// Arrows drive the robot.
    Drive,
}

/// The console.
pub struct Console {
    log: VecDeque<String>,
    /// Lines appended since the headless mode last took them.
    fresh: Vec<String>,
    /// How many lines the view is scrolled up from the newest (0: follows the bus).
    pub scroll: usize,
    /// The command line being typed.
    pub input: String,
    history: Vec<String>,
    history_at: Option<usize>,
    /// What keys do now.
    pub mode: Mode,
    keep_alive: KeepAlive,
    drive_end: Option<Duration>,
    drive_priority: Priority,
    /// One line of feedback under the bus view.
    pub status: String,
    view: View,
    filter: Filter,
    /// Frames heard, per topic.
    pub statistics: Statistics,
    /// Set when the console should end.
    pub quit: bool,
    /// The robot's admission check fed with what the console hears (`None`: requests are not checked).
    admission: Option<Checker>,
    /// The robot's state at a glance, from everything heard and sent.
    pub dashboard: Dashboard,
    /// Whether the dashboard is shown instead of the log (F4).
    pub show_dashboard: bool,
}

impl Console {
    /// A console that shows frames through `view`, those `filter` admits.
    pub fn new(view: View, filter: Filter) -> Self {
        Self {
            log: VecDeque::new(),
            fresh: Vec::new(),
            scroll: 0,
            input: String::new(),
            history: Vec::new(),
            history_at: None,
            mode: Mode::Command,
            keep_alive: KeepAlive::new(CONSOLE_EVERY),
            drive_end: None,
            drive_priority: Priority::High,
            status: "Type a command (Tab completes), F2 menu, F3 drive, Ctrl-C quits".into(),
            view,
            filter,
            statistics: Statistics::default(),
            quit: false,
            admission: None,
            dashboard: Dashboard::default(),
            show_dashboard: false,
        }
    }

    /// Checks publish requests before they are sent, with what the console hears on the bus, and explains
    /// the admission verdicts heard.
    pub fn with_admission(mut self, checker: Checker) -> Self {
        self.admission = Some(checker);
        self
    }

    /// Every line kept, oldest first.
    pub fn log(&self) -> &VecDeque<String> {
        &self.log
    }

    /// Lines added since the last call (the headless mode prints them).
    pub fn take_fresh(&mut self) -> Vec<String> {
        std::mem::take(&mut self.fresh)
    }

    fn say(&mut self, line: String) {
        if self.log.len() == LOG_LINES {
            self.log.pop_front();
        }
        if self.scroll > 0 {
            self.scroll += 1;
        }
        self.fresh.push(line.clone());
        self.log.push_back(line);
    }

    /// The motor command being kept alive.
    pub fn motor(&self) -> MotorCommand {
        self.keep_alive.command()
    }

    /// Whether the robot is being driven.
    pub fn driving(&self) -> bool {
        self.keep_alive.driving()
    }

    /// When the console next needs a tick (a keep-alive or the end of a timed drive).
    pub fn next_wake(&self) -> Option<Duration> {
        [self.keep_alive.next_due(), self.drive_end]
            .into_iter()
            .flatten()
            .min()
    }

    /// A frame heard on the bus.
    pub fn heard(&mut self, logged: &LoggedFrame) {
        // Every frame teaches the admission check what runs; a verdict's second page explains it.
        let verdict = self.admission.as_mut().and_then(|checker| {
            let mut stamped = logged.clone();
            stamped.timestamp.get_or_insert_with(Timestamp::now);
            checker.heard(&stamped)
        });
        let mut stamped = logged.clone();
        stamped.timestamp.get_or_insert_with(Timestamp::now);
        self.dashboard.heard(&stamped);
        if self.filter.admits(&logged.frame) {
            self.statistics.record(logged);
            let line = self.view.line(logged);
            self.say(line);
        }
        if let Some(verdict) = verdict {
            self.status = verdict.clone();
            self.say(format!("! {verdict}"));
        }
    }

    /// The outcome of sending a frame the console asked for.
    pub fn sent(&mut self, frame: &RawFrame, result: Result<(), String>) {
        match result {
            Ok(()) => {
                let stamped = LoggedFrame {
                    timestamp: Some(Timestamp::now()),
                    interface: None,
                    frame: *frame,
                };
                // A publish request sent sets the period the dashboard measures against (its clock is the
                // bus's: a log replayed has its own times, so the host's time is not given).
                self.dashboard.heard(&LoggedFrame::bare(*frame));
                let line = format!("sent {}", self.view.line(&stamped));
                self.say(line);
            }
            Err(error) => {
                self.status = format!("could not send {frame}: {error}");
                self.say(format!("! could not send {frame}: {error}"));
            }
        }
    }

    /// Time passes: keep-alive repeats and the end of a timed drive.
    pub fn tick(&mut self, now: Duration) -> Vec<RawFrame> {
        if self.drive_end.is_some_and(|end| now >= end) {
            self.drive_end = None;
            self.keep_alive.stop(now);
            self.status = "timed drive done: stopped".into();
        }
        self.due_frames(now)
    }

    fn due_frames(&mut self, now: Duration) -> Vec<RawFrame> {
        match self.keep_alive.due(now) {
            Some(command) => match motor_frame(command, self.drive_priority) {
                Ok(frame) => vec![frame],
                Err(error) => {
                    self.status = format!("cannot build the motor command: {error:#}");
                    Vec::new()
                }
            },
            None => Vec::new(),
        }
    }

    /// The frames to send before the console ends: a stop if the robot moves.
    pub fn shutdown(&mut self, now: Duration) -> Vec<RawFrame> {
        self.drive_end = None;
        if self.driving() {
            self.keep_alive.stop(now);
        }
        self.due_frames(now)
    }

    /// A key was pressed; returns the frames to send now.
    pub fn key(&mut self, key: Key, now: Duration) -> Vec<RawFrame> {
        if key == Key::Interrupt {
            self.quit = true;
            return self.shutdown(now);
        }
        match key {
            Key::PageUp => {
                self.scroll = (self.scroll + 10).min(self.log.len().saturating_sub(1));
                return Vec::new();
            }
            Key::PageDown => {
                self.scroll = self.scroll.saturating_sub(10);
                return Vec::new();
            }
            Key::End => {
                self.scroll = 0;
                return Vec::new();
            }
            Key::Dashboard => {
                self.toggle_dashboard();
                return Vec::new();
            }
            _ => {}
        }
        match std::mem::replace(&mut self.mode, Mode::Command) {
            Mode::Command => self.command_key(key, now),
            Mode::Menu(menu) => {
                self.menu_key(menu, key);
                Vec::new()
            }
            Mode::Drive => {
                self.mode = Mode::Drive;
                self.drive_key(key, now)
            }
        }
    }

    fn command_key(&mut self, key: Key, now: Duration) -> Vec<RawFrame> {
        match key {
            Key::Char(c) => self.input.push(c),
            Key::Backspace => {
                self.input.pop();
            }
            Key::Tab => self.complete(),
            Key::Up => self.recall(true),
            Key::Down => self.recall(false),
            Key::Enter => {
                let line = std::mem::take(&mut self.input);
                return self.submit(&line, now);
            }
            Key::Esc => self.input.clear(),
            Key::Menu => self.open_menu(),
            Key::Drive => self.enter_drive_mode(),
            _ => {}
        }
        Vec::new()
    }

    fn recall(&mut self, older: bool) {
        if self.history.is_empty() {
            return;
        }
        let last = self.history.len() - 1;
        let at = match (self.history_at, older) {
            (None, true) => Some(last),
            (None, false) => None,
            (Some(at), true) => Some(at.saturating_sub(1)),
            (Some(at), false) if at < last => Some(at + 1),
            (Some(_), false) => None,
        };
        self.history_at = at;
        self.input = at.map(|at| self.history[at].clone()).unwrap_or_default();
    }

    fn toggle_dashboard(&mut self) {
        self.show_dashboard = !self.show_dashboard;
        self.status = if self.show_dashboard {
            "Dashboard: one row per topic heard; F4 shows the bus log again".into()
        } else {
            "Bus log; F4 shows the dashboard".into()
        };
    }

    fn open_menu(&mut self) {
        self.mode = Mode::Menu(Menu::default());
        self.status = "Menu: Up/Down and Enter (or a number), Esc cancels".into();
    }

    fn enter_drive_mode(&mut self) {
        self.mode = Mode::Drive;
        self.status =
            "Drive: Up/Down speed, Left/Right turn, Space stops, Esc leaves (and stops)".into();
    }

    /// Runs a command line; returns the frames to send.
    pub fn submit(&mut self, line: &str, now: Duration) -> Vec<RawFrame> {
        let line = line.trim();
        if line.is_empty() {
            return Vec::new();
        }
        if self.history.last().map(String::as_str) != Some(line) {
            self.history.push(line.to_string());
        }
        self.history_at = None;
        self.say(format!("> {line}"));
        match line {
            "quit" | "exit" => {
                self.quit = true;
                return self.shutdown(now);
            }
            "clear" => {
                self.log.clear();
                self.scroll = 0;
                return Vec::new();
            }
            "help" => {
                for help in HELP {
                    self.say((*help).to_string());
                }
                return Vec::new();
            }
            "menu" => {
                self.open_menu();
                return Vec::new();
            }
            "dashboard" => {
                self.toggle_dashboard();
                return Vec::new();
            }
            "stop-driving" => {
                self.drive_end = None;
                self.keep_alive.stop(now);
                return self.due_frames(now);
            }
            _ => {}
        }
        match parse_step(line, false) {
            Ok(Some(Step::Send(frames))) => {
                self.check_requests(&frames);
                frames
            }
            Ok(Some(Step::Drive(plan))) => {
                self.drive_priority = plan.priority;
                self.keep_alive = KeepAlive::new(plan.every);
                self.keep_alive.set(plan.command, now);
                self.drive_end = plan.duration.map(|duration| now + duration);
                self.status = format!("driving {}", plan.describe(" until stop-driving"));
                self.due_frames(now)
            }
            Ok(Some(Step::Wait(_))) => {
                self.status =
                    "`wait` is for scripts (amiro run); the console always watches".into();
                Vec::new()
            }
            Ok(None) => Vec::new(),
            Err(error) => {
                self.status = format!("{error:#}");
                self.say(format!("! {error:#}"));
                Vec::new()
            }
        }
    }

    /// Warns (and still sends: the board decides) when a board would refuse a request.
    fn check_requests(&mut self, frames: &[RawFrame]) {
        let Some(checker) = self.admission.as_mut() else {
            return;
        };
        let warnings: Vec<String> = frames
            .iter()
            .filter_map(|frame| decode_frame(frame).ok())
            .filter_map(|message| checker.check(&message))
            .collect();
        for warning in warnings {
            self.status = format!("warning: {warning}");
            self.say(format!("! warning: {warning}"));
        }
    }

    fn drive_key(&mut self, key: Key, now: Duration) -> Vec<RawFrame> {
        let mut command = self.keep_alive.command();
        match key {
            Key::Up => command.velocity_um_s = (command.velocity_um_s + SPEED_STEP).min(MAX_SPEED),
            Key::Down => {
                command.velocity_um_s = (command.velocity_um_s - SPEED_STEP).max(-MAX_SPEED)
            }
            Key::Left => {
                command.angular_urad_s = (command.angular_urad_s + TURN_STEP).min(MAX_TURN)
            }
            Key::Right => {
                command.angular_urad_s = (command.angular_urad_s - TURN_STEP).max(-MAX_TURN)
            }
            Key::Char(' ') => {
                command = MotorCommand {
                    velocity_um_s: 0,
                    angular_urad_s: 0,
                }
            }
            Key::Esc | Key::Drive => {
                self.mode = Mode::Command;
                self.status = "left drive mode".into();
                return self.shutdown(now);
            }
            _ => return Vec::new(),
        }
        self.drive_end = None;
        self.drive_priority = Priority::High;
        if command != self.keep_alive.command() || !self.driving() {
            self.keep_alive = KeepAlive::new(CONSOLE_EVERY);
            self.keep_alive.set(command, now);
        }
        self.status = format!(
            "Drive: {} mm/s, {:.0} °/s (Space stops, Esc leaves)",
            command.velocity_um_s / 1000,
            crate::drive::degrees_per_second(command.angular_urad_s)
        );
        self.due_frames(now)
    }

    fn menu_key(&mut self, mut menu: Menu, key: Key) {
        let Some(question) = menu.question() else {
            return;
        };
        match (key, &question) {
            (Key::Esc, _) => {
                self.status = "menu cancelled".into();
                return;
            }
            (Key::Up, Question::Choose { .. }) => menu.selected = menu.selected.saturating_sub(1),
            (Key::Down, Question::Choose { choices, .. }) => {
                menu.selected = (menu.selected + 1).min(choices.len() - 1)
            }
            (Key::Char(c), Question::Choose { choices, .. }) if c.is_ascii_digit() => {
                let index = c.to_digit(10).unwrap_or(0) as usize;
                if (1..=choices.len()).contains(&index) {
                    menu.selected = index - 1;
                    menu.answer(choices[index - 1].clone());
                }
            }
            (Key::Enter, Question::Choose { choices, .. }) => {
                menu.answer(choices[menu.selected].clone())
            }
            (Key::Char(c), Question::Type { .. }) => menu.text.push(c),
            (Key::Backspace, Question::Type { .. }) => {
                menu.text.pop();
            }
            (Key::Enter, Question::Type { default, .. }) => {
                let text = if menu.text.trim().is_empty() {
                    default.clone()
                } else {
                    menu.text.trim().to_string()
                };
                menu.answer(text);
            }
            _ => {}
        }
        if menu.question().is_none() {
            self.input = menu.command();
            self.status = format!("Enter sends: {}", self.input);
        } else {
            self.mode = Mode::Menu(menu);
        }
    }

    /// Tab: completes the word at the end of the command line, or lists the choices.
    pub fn complete(&mut self) {
        let completion = complete::complete(&self.input);
        self.input = completion.input;
        if let Some(status) = completion.status {
            self.status = status;
        }
    }
}

const HELP: &[&str] = &[
    "commands (Tab completes), said as you would say them or with flags:",
    "  publish gyroscope every 100ms at high       start a sensor (publish TOPIC --every PERIOD --priority P)",
    "  once floor at urgent                        one sample now (once TOPIC --priority P)",
    "  stop gyroscope [at high]                    stop a sensor (stop TOPIC --priority P; said: medium)",
    "  led 3 red, led 3 #FF8020                    colour of LED 1-8 (led N --rgb R,G,B [--priority P])",
    "  motor --velocity UM_S --angular URAD_S      one motor frame (the board stops after 500 ms without one)",
    "  drive 100mm/s turn 30deg/s for 3s           kept alive every 200 ms, then stopped (drive --forward ...)",
    "  stop-driving, ID#DATA (a raw frame), dashboard (or F4), clear, help, quit",
    "keys: F2 menu, F3 drive with the arrows, F4 dashboard, PageUp/PageDown scroll, End follows, Ctrl-C quits",
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::console::complete::candidates;
    use crate::watch::TimeBase;

    fn console() -> Console {
        Console::new(
            View {
                time: TimeBase::Relative { origin: None },
                json: false,
            },
            Filter::default(),
        )
    }

    fn type_line(console: &mut Console, text: &str, now: Duration) -> Vec<RawFrame> {
        for c in text.chars() {
            console.key(Key::Char(c), now);
        }
        console.key(Key::Enter, now)
    }

    fn texts(frames: &[RawFrame]) -> Vec<String> {
        frames.iter().map(ToString::to_string).collect()
    }

    #[test]
    fn a_typed_command_is_sent_and_shown_and_bad_ones_are_explained() {
        let mut console = console();
        let frames = type_line(
            &mut console,
            "publish magnetometer-x --every 900us --priority medium",
            Duration::ZERO,
        );
        assert_eq!(texts(&frames), ["205#01840302"]);
        console.sent(&frames[0], Ok(()));
        assert!(
            console.log().back().unwrap().contains("sent"),
            "{:?}",
            console.log()
        );
        assert!(type_line(
            &mut console,
            "publish gyroscope --every 0ms --priority high",
            Duration::ZERO
        )
        .is_empty());
        assert!(console.status.contains("zero"), "{}", console.status);
        assert!(type_line(&mut console, "205#03", Duration::ZERO).is_empty());
        assert!(console.status.contains("bad-mode"), "{}", console.status);
        // Up recalls the last line.
        console.key(Key::Up, Duration::ZERO);
        assert_eq!(console.input, "205#03");
        console.key(Key::Up, Duration::ZERO);
        assert_eq!(
            console.input,
            "publish gyroscope --every 0ms --priority high"
        );
        console.key(Key::Down, Duration::ZERO);
        console.key(Key::Down, Duration::ZERO);
        assert_eq!(console.input, "");
    }

    #[test]
    fn a_request_the_robot_would_refuse_is_warned_about_from_what_was_heard() {
        let mut console =
            console().with_admission(Checker::load(None).expect("the repository's timing files"));
        // On an idle robot a gyroscope every 2 ms passes without a word (every 1 ms passes by 3.4 µs only on a 1-1 robot since
        // DiWheelDrive 1-1's publisher rows are the machine code's, 2026-12-06).
        let frames = type_line(
            &mut console,
            "publish gyroscope --every 2000us --priority medium",
            Duration::ZERO,
        );
        assert_eq!(texts(&frames), ["208#01D00702"]);
        assert!(!console.status.contains("warning"), "{}", console.status);
        type_line(
            &mut console,
            "stop gyroscope --priority medium",
            Duration::ZERO,
        );
        // Somebody else starts magnetometer-x every 7 ms: the console hears the command.
        console.heard(&LoggedFrame {
            timestamp: None,
            interface: None,
            frame: crate::frame::parse_compact("205#01581B02").expect("frame"),
        });
        let frames = type_line(
            &mut console,
            "publish gyroscope --every 2000us --priority medium",
            Duration::ZERO,
        );
        assert_eq!(texts(&frames), ["208#01D00702"], "sent all the same");
        assert!(
            console
                .status
                .contains("DiWheelDrive on a 1-1 robot would refuse"),
            "{}",
            console.status
        );
        assert!(
            console.log().iter().any(|l| l.starts_with("! warning:")),
            "{:?}",
            console.log()
        );
    }

    #[test]
    fn tab_completes_commands_topics_options_and_values() {
        let mut console = console();
        for c in "pub".chars() {
            console.key(Key::Char(c), Duration::ZERO);
        }
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(console.input, "publish ");
        for c in "gy".chars() {
            console.key(Key::Char(c), Duration::ZERO);
        }
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(console.input, "publish gyroscope ");
        console.key(Key::Char('-'), Duration::ZERO);
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(
            console.input, "publish gyroscope --",
            "two options: the common prefix"
        );
        assert!(console.status.contains("--every") && console.status.contains("--priority"));
        for c in "p".chars() {
            console.key(Key::Char(c), Duration::ZERO);
        }
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(console.input, "publish gyroscope --priority ");
        console.key(Key::Char('h'), Duration::ZERO);
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(console.input, "publish gyroscope --priority high ");
        assert!(candidates(
            &["publish", "gyroscope", "--priority", "high", "--every"],
            ""
        )
        .contains(&"10ms".to_string()));
        assert!(candidates(&["led"], "").contains(&"8".to_string()));
        assert!(candidates(&[], "").contains(&"drive".to_string()));
    }

    #[test]
    fn spoken_commands_are_sent_completed_and_corrected() {
        let mut console = console();
        let frames = type_line(
            &mut console,
            "publish gyroscope every 100ms at high",
            Duration::ZERO,
        );
        assert_eq!(texts(&frames), ["108#01640000"]);
        assert_eq!(
            texts(&type_line(&mut console, "led 3 #FF8020", Duration::ZERO)),
            ["313#FF8020"]
        );
        // Tab offers the spoken words beside the flags, and their values.
        assert!(candidates(&["publish", "gyroscope"], "").contains(&"every".to_string()));
        assert!(candidates(&["publish", "gyroscope"], "").contains(&"--every".to_string()));
        assert_eq!(
            candidates(&["publish", "gyroscope", "every", "100ms", "at"], ""),
            ["urgent", "high", "medium", "low"]
        );
        assert!(candidates(&["once"], "").contains(&"floor".to_string()));
        assert!(candidates(&["led", "3"], "").contains(&"red".to_string()));
        assert!(candidates(&["drive", "100mm/s"], "").contains(&"turn".to_string()));
        for c in "publish gyroscope ev".chars() {
            console.key(Key::Char(c), Duration::ZERO);
        }
        console.key(Key::Tab, Duration::ZERO);
        assert_eq!(console.input, "publish gyroscope every ");
        console.input = "stop magnetomter-x".into();
        console.key(Key::Tab, Duration::ZERO);
        assert!(
            console.status.contains("did you mean magnetometer-x?"),
            "{}",
            console.status
        );
        console.input.clear();
        assert!(type_line(&mut console, "stop magnetomter-x", Duration::ZERO).is_empty());
        assert!(
            console.status.contains("did you mean magnetometer-x?"),
            "{}",
            console.status
        );
    }

    #[test]
    fn the_menu_builds_the_thesis_sender_commands() {
        let mut console = console();
        console.key(Key::Menu, Duration::ZERO);
        // sensor → publish → proximity-ring (by arrows) → default period → medium
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Char('1'), Duration::ZERO);
        let Mode::Menu(menu) = &console.mode else {
            panic!("{:?}", console.mode)
        };
        let Some(Question::Choose { choices, .. }) = menu.question() else {
            panic!()
        };
        let ring = choices
            .iter()
            .position(|choice| choice == "proximity-ring")
            .unwrap();
        for _ in 0..ring {
            console.key(Key::Down, Duration::ZERO);
        }
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Char('3'), Duration::ZERO);
        assert_eq!(console.mode, Mode::Command);
        assert_eq!(
            console.input,
            "publish proximity-ring --every 62.5ms --priority medium"
        );
        let frames = console.key(Key::Enter, Duration::ZERO);
        assert_eq!(texts(&frames), ["21F#0124F402"]);

        console.key(Key::Menu, Duration::ZERO);
        console.key(Key::Char('3'), Duration::ZERO);
        console.key(Key::Char('5'), Duration::ZERO);
        for c in "10,50,120".chars() {
            console.key(Key::Char(c), Duration::ZERO);
        }
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Char('4'), Duration::ZERO);
        assert_eq!(console.input, "led 5 --rgb '10,50,120' --priority low");
        assert_eq!(
            texts(&console.key(Key::Enter, Duration::ZERO)),
            ["315#0A3278"]
        );

        console.key(Key::Menu, Duration::ZERO);
        console.key(Key::Char('2'), Duration::ZERO);
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Enter, Duration::ZERO);
        console.key(Key::Enter, Duration::ZERO);
        assert_eq!(
            console.input,
            "drive --forward 100mm/s --turn 0deg/s --for 2s"
        );
        console.key(Key::Menu, Duration::ZERO);
        console.key(Key::Esc, Duration::ZERO);
        assert_eq!(console.mode, Mode::Command);
    }

    #[test]
    fn teleoperation_keeps_the_command_alive_and_stops_on_leaving_or_quitting() {
        let ms = Duration::from_millis;
        let mut console = console();
        console.key(Key::Drive, ms(0));
        let first = console.key(Key::Up, ms(0));
        assert_eq!(texts(&first), ["110#50C3000000000000"], "50 mm/s at once");
        let turn = console.key(Key::Left, ms(50));
        assert_eq!(turn.len(), 1);
        // Repeated every 200 ms from the last change: the gaps never reach the dead-man.
        let mut sent_at = vec![ms(50)];
        let mut now = ms(50);
        while now < ms(2000) {
            now += ms(7);
            if !console.tick(now).is_empty() {
                sent_at.push(now);
            }
        }
        for gap in sent_at.windows(2).map(|pair| pair[1] - pair[0]) {
            assert!(gap <= ms(207) && gap < crate::drive::DEADMAN, "{gap:?}");
        }
        assert!(sent_at.len() >= 9, "{sent_at:?}");
        let stop = console.key(Key::Esc, now);
        assert_eq!(texts(&stop), ["110#0000000000000000"]);
        assert!(
            console.tick(now + ms(1000)).is_empty(),
            "stopped: nothing more is sent"
        );
        assert_eq!(console.mode, Mode::Command);

        console.key(Key::Drive, now);
        console.key(Key::Down, now);
        let quit = console.key(Key::Interrupt, now);
        assert_eq!(texts(&quit), ["110#0000000000000000"]);
        assert!(console.quit);
    }

    #[test]
    fn a_timed_drive_from_the_command_line_ends_with_a_stop() {
        let ms = Duration::from_millis;
        let mut console = console();
        let first = type_line(&mut console, "drive --forward 100mm/s --for 1s", ms(0));
        assert_eq!(texts(&first), ["110#A086010000000000"]);
        let mut sent = Vec::new();
        let mut now = ms(0);
        while now < ms(1500) {
            now += ms(10);
            sent.extend(
                console
                    .tick(now)
                    .into_iter()
                    .map(|frame| (now, frame.to_string())),
            );
        }
        assert_eq!(sent.len(), 5, "{sent:?}");
        assert_eq!(
            sent.last().unwrap(),
            &(ms(1000), "110#0000000000000000".to_string())
        );
    }

    #[test]
    fn heard_frames_scroll_and_obey_the_filter() {
        let mut console = Console::new(
            View {
                time: TimeBase::Absolute,
                json: false,
            },
            Filter {
                sensor_data_only: true,
                ..Filter::default()
            },
        );
        let frame = |text: &str| LoggedFrame::bare(crate::frame::parse_compact(text).unwrap());
        console.heard(&frame("608#FCFF1E00FBFF"));
        console.heard(&frame("108#010A0000"));
        assert_eq!(console.log().len(), 1);
        assert!(console.log()[0].contains("gyroscope: x -4 dps"));
        console.key(Key::PageUp, Duration::ZERO);
        console.heard(&frame("71F#037800"));
        assert_eq!(console.take_fresh().len(), 2);
        assert!(console.log().back().unwrap().contains("front-left"));
    }
}
