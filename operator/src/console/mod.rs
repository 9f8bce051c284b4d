//! `amiro console`: one screen that commands and watches the robot (the thesis's Demo Sender and Demo Receiver
//! together). `state` decides everything; this module only carries events between the bus, the terminal
//! (ratatui + crossterm) or, with `--headless`, standard input and output.

pub mod complete;
pub mod menu;
pub mod state;

use std::io::{self, BufRead, Write};
use std::process::ExitCode;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Borders, List, ListItem, ListState, Paragraph};

use crate::bus::{self, Bus, BusUrl, Direction, Reception};
use crate::cli_session::ConsoleArgs;
use crate::frame::{RawFrame, Timestamp};
use crate::period::parse_duration;
use crate::watch::{Filter, TimeBase, View};
use menu::Question;
use state::{Console, Key, Mode};

/// How long one pass waits for the bus before looking at the keyboard again.
const BUS_SLICE: Duration = Duration::from_millis(15);
/// At most this many frames are taken from the bus per pass, so keys stay responsive under a flood.
const FRAMES_PER_PASS: usize = 500;

/// `amiro console`.
pub fn run(args: &ConsoleArgs) -> Result<ExitCode> {
    let url = BusUrl::parse(&args.bus)?;
    bus::catch_interrupts()?;
    let mut bus = bus::open(&url, Direction::Receive { realtime: true })?;
    let view = View {
        time: TimeBase::Relative {
            origin: Some(Timestamp::now()),
        },
        json: false,
    };
    let filter = Filter {
        sensor_data_only: args.sensor_data,
        ..Filter::default()
    };
    let mut console = Console::new(view, filter);
    // Publish requests are checked against what the console hears (docs/operator.md).
    match crate::admission::Checker::load(args.revision.as_deref()) {
        Ok(checker) => console = console.with_admission(checker),
        Err(error) => console.status = format!("publish requests are not checked: {error:#}"),
    }
    let started = Instant::now();
    let outcome = if args.headless {
        let linger = parse_duration(&args.linger).context("--linger")?;
        headless(bus.as_mut(), &mut console, started, linger)
    } else {
        interactive(bus.as_mut(), &mut console, started, &url)
    };
    // Whatever ended the session, a moving robot is stopped before the bus is closed.
    let stop = console.shutdown(started.elapsed());
    send_all(bus.as_mut(), &mut console, &stop);
    if args.headless {
        print_fresh(&mut console)?;
    }
    let closed = bus.close().with_context(|| format!("closing {url}"));
    for line in console.statistics.summary() {
        eprintln!("{line}");
    }
    outcome.with_context(|| format!("console on {url}"))?;
    closed?;
    Ok(ExitCode::SUCCESS)
}

fn send_all(bus: &mut dyn Bus, console: &mut Console, frames: &[RawFrame]) {
    for frame in frames {
        let result = bus.send(frame).map_err(|error| format!("{error:#}"));
        console.sent(frame, result);
    }
}

/// Takes what the bus has (a bounded number of frames), then keep-alive ticks.
fn pump(
    bus: &mut dyn Bus,
    console: &mut Console,
    started: Instant,
    wait: Duration,
) -> Result<bool> {
    let mut wait = Some(wait);
    for _ in 0..FRAMES_PER_PASS {
        match bus.receive(wait)? {
            Reception::Frame(frame) => console.heard(&frame),
            Reception::TimedOut | Reception::Ended => break,
            Reception::Interrupted => return Ok(false),
        }
        wait = Some(Duration::ZERO);
    }
    let due = console.tick(started.elapsed());
    send_all(bus, console, &due);
    Ok(true)
}

fn print_fresh(console: &mut Console) -> Result<()> {
    let mut out = io::stdout().lock();
    for line in console.take_fresh() {
        writeln!(out, "{line}")?;
    }
    out.flush()?;
    Ok(())
}

/// No screen: command lines from standard input, the bus view on standard output. Ends when the input has
/// ended, a timed drive has finished and `linger` has passed (or on Ctrl-C).
fn headless(
    bus: &mut dyn Bus,
    console: &mut Console,
    started: Instant,
    linger: Duration,
) -> Result<()> {
    let (lines, incoming) = mpsc::channel();
    std::thread::spawn(move || {
        for line in io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let mut input_ended: Option<Instant> = None;
    loop {
        loop {
            match incoming.try_recv() {
                Ok(line) => {
                    let frames = console.submit(&line, started.elapsed());
                    send_all(bus, console, &frames);
                }
                Err(mpsc::TryRecvError::Empty) => break,
                Err(mpsc::TryRecvError::Disconnected) => {
                    input_ended.get_or_insert_with(Instant::now);
                    break;
                }
            }
        }
        if !pump(bus, console, started, BUS_SLICE)? {
            return Ok(());
        }
        print_fresh(console)?;
        if console.quit {
            return Ok(());
        }
        // A timed drive runs to its end even when the input has ended; linger counts from then.
        if console.next_wake().is_some() && console.driving() {
            input_ended = input_ended.map(|_| Instant::now());
        }
        if input_ended.is_some_and(|ended| ended.elapsed() >= linger) {
            return Ok(());
        }
    }
}

/// Restores the terminal however the console ends (also on a panic or an error).
struct TerminalGuard;

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

fn map_key(code: KeyCode, modifiers: KeyModifiers) -> Option<Key> {
    Some(match code {
        KeyCode::Char('c') if modifiers.contains(KeyModifiers::CONTROL) => Key::Interrupt,
        // Ctrl-J is a line feed: some terminals (and pasted text) end lines with it.
        KeyCode::Char('j') if modifiers.contains(KeyModifiers::CONTROL) => Key::Enter,
        KeyCode::Char(_) if modifiers.contains(KeyModifiers::CONTROL) => return None,
        KeyCode::Char(c) => Key::Char(c),
        KeyCode::Enter => Key::Enter,
        KeyCode::Tab => Key::Tab,
        KeyCode::Backspace => Key::Backspace,
        KeyCode::Up => Key::Up,
        KeyCode::Down => Key::Down,
        KeyCode::Left => Key::Left,
        KeyCode::Right => Key::Right,
        KeyCode::PageUp => Key::PageUp,
        KeyCode::PageDown => Key::PageDown,
        KeyCode::End => Key::End,
        KeyCode::Esc => Key::Esc,
        KeyCode::F(2) => Key::Menu,
        KeyCode::F(3) => Key::Drive,
        KeyCode::F(4) => Key::Dashboard,
        _ => return None,
    })
}

fn interactive(
    bus: &mut dyn Bus,
    console: &mut Console,
    started: Instant,
    url: &BusUrl,
) -> Result<()> {
    let mut terminal = ratatui::try_init()
        .context("cannot take over the terminal (is this a terminal? try --headless)")?;
    let _guard = TerminalGuard;
    let title = format!(" amiro console — {url} ");
    // On a live bus the dashboard's clock runs on with the host's (a silent publisher owes samples); a log
    // replayed keeps its own times.
    let live = !matches!(url, BusUrl::File { .. });
    loop {
        if live {
            console.dashboard.tick(Timestamp::now());
        }
        terminal
            .draw(|frame| draw(frame, console, &title))
            .context("cannot draw")?;
        while event::poll(Duration::ZERO).context("cannot read the keyboard")? {
            if let Event::Key(key) = event::read().context("cannot read the keyboard")? {
                if key.kind == KeyEventKind::Release {
                    continue;
                }
                if let Some(key) = map_key(key.code, key.modifiers) {
                    let frames = console.key(key, started.elapsed());
                    send_all(bus, console, &frames);
                }
            }
        }
        if console.quit || !pump(bus, console, started, BUS_SLICE)? {
            return Ok(());
        }
        console.take_fresh();
    }
}

fn draw_log(
    frame: &mut ratatui::Frame<'_>,
    console: &Console,
    title: &str,
    log_area: ratatui::layout::Rect,
) {
    let height = log_area.height.saturating_sub(2) as usize;
    let log = console.log();
    let end = log.len().saturating_sub(console.scroll);
    let start = end.saturating_sub(height);
    let lines: Vec<Line<'_>> = log
        .range(start..end)
        .map(|line| Line::raw(line.as_str()))
        .collect();
    let scrolled = if console.scroll > 0 {
        format!(
            "{title}(scrolled back {} lines, End follows) ",
            console.scroll
        )
    } else {
        title.to_string()
    };
    frame.render_widget(
        Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title(scrolled)),
        log_area,
    );
}

fn draw(frame: &mut ratatui::Frame<'_>, console: &Console, title: &str) {
    let menu_height = match &console.mode {
        Mode::Menu(menu) => match menu.question() {
            Some(Question::Choose { choices, .. }) => choices.len() as u16 + 2,
            _ => 3,
        },
        _ => 0,
    };
    let [log_area, menu_area, status_area, input_area] = Layout::vertical([
        Constraint::Min(3),
        Constraint::Length(menu_height),
        Constraint::Length(1),
        Constraint::Length(3),
    ])
    .areas(frame.area());

    if console.show_dashboard {
        console.dashboard.render(frame, log_area);
    } else {
        draw_log(frame, console, title, log_area);
    }

    if let Mode::Menu(menu) = &console.mode {
        match menu.question() {
            Some(Question::Choose { prompt, choices }) => {
                let items: Vec<ListItem<'_>> = choices
                    .iter()
                    .enumerate()
                    .map(|(index, choice)| ListItem::new(format!("{}. {choice}", index + 1)))
                    .collect();
                let mut state = ListState::default().with_selected(Some(menu.selected));
                let list = List::new(items)
                    .block(
                        Block::default()
                            .borders(Borders::ALL)
                            .title(format!(" {prompt} ")),
                    )
                    .highlight_style(Style::default().add_modifier(Modifier::REVERSED));
                frame.render_stateful_widget(list, menu_area, &mut state);
            }
            Some(Question::Type { prompt, default }) => frame.render_widget(
                Paragraph::new(format!("{}▏", menu.text)).block(
                    Block::default()
                        .borders(Borders::ALL)
                        .title(format!(" {prompt} [Enter: {default}] ")),
                ),
                menu_area,
            ),
            None => {}
        }
    }

    let motor = console.motor();
    let driving = if console.driving() {
        format!(
            "  | driving {} mm/s {:.0}°/s",
            motor.velocity_um_s / 1000,
            crate::drive::degrees_per_second(motor.angular_urad_s)
        )
    } else {
        String::new()
    };
    frame.render_widget(
        Paragraph::new(format!("{}{driving}", console.status)),
        status_area,
    );
    let (label, text) = match console.mode {
        Mode::Drive => (" drive (arrows, Space stops, Esc leaves) ", String::new()),
        _ => (
            " command (Tab completes, F2 menu, F3 drive, F4 dashboard) ",
            format!("{}▏", console.input),
        ),
    };
    frame.render_widget(
        Paragraph::new(text).block(Block::default().borders(Borders::ALL).title(label)),
        input_area,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dashboard::buffer_text;
    use crate::frame::parse_line;
    use crate::watch::Filter;

    fn screen(console: &Console) -> String {
        let mut terminal =
            ratatui::Terminal::new(ratatui::backend::TestBackend::new(80, 24)).expect("terminal");
        terminal
            .draw(|frame| draw(frame, console, " amiro console — test "))
            .expect("draw");
        buffer_text(terminal.backend().buffer())
    }

    #[test]
    fn f4_shows_the_dashboard_in_place_of_the_log_on_an_80_by_24_screen() {
        let mut console = Console::new(
            View {
                time: TimeBase::Relative { origin: None },
                json: false,
            },
            Filter::default(),
        );
        let now = Duration::ZERO;
        for c in "publish gyroscope every 100ms at high".chars() {
            console.key(Key::Char(c), now);
        }
        let frames = console.key(Key::Enter, now);
        console.sent(&frames[0], Ok(()));
        for line in [
            "(1700000000.100000) can0 508#FCFF1E00FBFF",
            "(1700000000.200000) can0 508#FDFF1F00FBFF",
            "(1700000000.300000) can0 508#FEFF2000FBFF",
        ] {
            console.heard(&parse_line(line).unwrap().unwrap());
        }
        let log = screen(&console);
        assert!(log.contains("gyroscope: x -2 dps"), "{log}");
        assert!(!log.contains("period ms"), "{log}");

        console.key(Key::Dashboard, now);
        let dashboard = screen(&console);
        let gyro = dashboard
            .lines()
            .find(|line| line.contains("gyroscope"))
            .unwrap_or_else(|| panic!("{dashboard}"));
        assert!(
            gyro.contains("-2 32 -5 dps") && gyro.contains("100/100"),
            "{gyro}"
        );
        assert!(
            dashboard.contains("F4 dashboard"),
            "the command line stays: {dashboard}"
        );
        assert!(
            dashboard.contains("DiWheelDrive: no diagnostics heard"),
            "{dashboard}"
        );
        assert_eq!(dashboard.lines().count(), 24);

        console.key(Key::Dashboard, now);
        assert!(screen(&console).contains("gyroscope: x -2 dps"));
    }
}
