//! The live dashboard: frames from a bus into the state, redrawn on the terminal until q, Esc or Ctrl-C; printed
//! once where the output is not a terminal.

use std::io::{self, IsTerminal, Write};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use ratatui::layout::{Constraint, Layout};
use ratatui::widgets::Paragraph;

use super::Dashboard;
use crate::bus::{Bus, Reception};
use crate::cli::MonitorArgs;
use crate::frame::Timestamp;
use crate::session::Taps;
use crate::watch::{Filter, Statistics};

/// How often the live dashboard is redrawn.
const REDRAW: Duration = Duration::from_millis(100);

/// `amiro monitor --dashboard`: on a terminal, the live dashboard until q, Esc or Ctrl-C; otherwise the frames are
/// taken until the count, the timeout or the end of the log, and the dashboard is printed once (80×24).
pub fn monitor(
    bus: &mut dyn Bus,
    args: &MonitorArgs,
    filter: &Filter,
    statistics: &mut Statistics,
    taps: &mut Taps,
) -> Result<()> {
    let mut dashboard = Dashboard::default();
    let live = io::stdout().is_terminal();
    let give_up = args.timeout.map(|timeout| Instant::now() + timeout);
    let mut terminal = if live {
        Some(ratatui::try_init().context("cannot take over the terminal")?)
    } else {
        None
    };
    // Built only when the terminal was taken: dropping it restores the terminal.
    let _guard = if live { Some(RestoreTerminal) } else { None };
    let mut ended = false;
    let mut last_draw: Option<Instant> = None;
    loop {
        let counted = args.count.is_some_and(|count| statistics.frames() >= count);
        let timed_out = give_up.is_some_and(|give_up| Instant::now() >= give_up);
        if !live && (ended || counted || timed_out) {
            break;
        }
        if !ended && !counted && !timed_out {
            let wait = if live {
                Duration::from_millis(20)
            } else {
                Duration::from_millis(200)
            };
            match bus.receive(Some(wait))? {
                Reception::Frame(mut logged) => {
                    taps.frame(&logged)?;
                    if filter.admits(&logged.frame) {
                        statistics.record(&logged);
                        logged.timestamp.get_or_insert_with(Timestamp::now);
                        dashboard.heard(&logged);
                    }
                }
                Reception::TimedOut => {}
                Reception::Ended => ended = true,
                Reception::Interrupted => break,
            }
        }
        if let Some(terminal) = terminal.as_mut() {
            if last_draw.is_none_or(|at| at.elapsed() >= REDRAW) {
                if !matches!(args.bus.split_once(':'), Some(("file", _))) {
                    dashboard.tick(Timestamp::now());
                }
                terminal
                    .draw(|frame| {
                        let [main, status] =
                            Layout::vertical([Constraint::Min(3), Constraint::Length(1)])
                                .areas(frame.area());
                        dashboard.render(frame, main);
                        let note = if ended { "end of the log — " } else { "" };
                        frame.render_widget(
                            Paragraph::new(format!(" {} — {note}q leaves", args.bus)),
                            status,
                        );
                    })
                    .context("cannot draw")?;
                last_draw = Some(Instant::now());
            }
            use crossterm::event::{self, Event, KeyCode, KeyModifiers};
            while event::poll(Duration::ZERO).context("cannot read the keyboard")? {
                if let Event::Key(key) = event::read().context("cannot read the keyboard")? {
                    let ctrl_c = key.code == KeyCode::Char('c')
                        && key.modifiers.contains(KeyModifiers::CONTROL);
                    if ctrl_c || matches!(key.code, KeyCode::Char('q') | KeyCode::Esc) {
                        return Ok(());
                    }
                }
            }
            if ended || crate::bus::interrupted() {
                std::thread::sleep(Duration::from_millis(20));
            }
            if crate::bus::interrupted() {
                return Ok(());
            }
        }
    }
    let mut out = io::stdout().lock();
    out.write_all(dashboard.text(80, 24).as_bytes())?;
    out.flush()?;
    Ok(())
}

/// Gives the terminal back however the dashboard ends.
struct RestoreTerminal;

impl Drop for RestoreTerminal {
    fn drop(&mut self) {
        ratatui::restore();
    }
}
