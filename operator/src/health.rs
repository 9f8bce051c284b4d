//! `amiro health`: asks every board for one diagnostics sample (a `once` command on its diagnostics topic), prints
//! the pages as they come, and ends with one verdict per board — answered or silent, and every counter that
//! points at a problem (rejected commands, lost frames, bus errors, missed deadlines, faults, a watchdog reset).

use std::collections::BTreeSet;
use std::io::{self, Write};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use amiro_can::{
    reason_name, Board, Command, Diagnostics, DiagnosticsPage, Message, Priority, ResetCause,
    SensorCommand, SensorData, SensorMode, COUNTED_REASONS, PAGES_PER_SAMPLE, REJECT_REASONS,
};
use anyhow::{Context, Result};
use clap::Args;

use crate::bus::{self, BusUrl, Direction, Reception};
use crate::describe::decode_frame;
use crate::encode;
use crate::frame::Timestamp;
use crate::watch::{TimeBase, View};

pub const HEALTH_ABOUT: &str = "\
Ask each board for its health (one diagnostics sample: six frames on its diagnostics topic) and print it: \
uptime and reset cause, commands accepted and rejected, admission refusals, received frames dropped, transmit \
drops, CAN error-passive and bus-off episodes, deadline misses per priority, sensor faults. Ends with one line \
per board: what looks wrong, or that nothing does.

Exit status: 0 if every board asked answered completely; 1 if one was silent or answered in part.";

pub const HEALTH_HELP: &str = "\
Examples:
  amiro health --bus slcan:/dev/ttyUSB0
  amiro health --board diwheeldrive --timeout 2s --bus socketcan:can0
  amiro monitor --topic diwheeldrive-diagnostics --bus socketcan:can0     (after `amiro send publish ...`)";

/// `amiro health`.
#[derive(Debug, Args)]
pub struct HealthArgs {
    /// The bus: socketcan:IFACE, slcan:DEVICE or slcan:DEVICE@BAUD or file:PATH
    #[arg(long, env = "AMIRO_BUS", value_name = "BUS")]
    pub bus: String,

    /// Only this board (repeatable): diwheeldrive, powermanagement, lightring
    #[arg(long, value_name = "BOARD", value_parser = parse_board)]
    pub board: Vec<Board>,

    /// Priority of the request and of the answer
    #[arg(long, value_name = "PRIORITY", default_value = "low", value_parser = parse_priority)]
    pub priority: Priority,

    /// How long to wait for the answers
    #[arg(long, value_name = "DURATION", default_value = "1s", value_parser = parse_timeout)]
    pub timeout: Duration,

    /// Print the pages as JSON Lines (the verdicts stay on standard error)
    #[arg(long)]
    pub json: bool,
}

fn parse_board(text: &str) -> Result<Board, String> {
    Board::ALL
        .into_iter()
        .find(|board| board.name().eq_ignore_ascii_case(text))
        .ok_or_else(|| {
            format!("unknown board {text:?}: diwheeldrive, powermanagement or lightring")
        })
}

fn parse_priority(text: &str) -> Result<Priority, String> {
    Priority::from_name(text)
        .ok_or_else(|| format!("unknown priority {text:?}: urgent, high, medium or low"))
}

fn parse_timeout(text: &str) -> Result<Duration, String> {
    crate::period::parse_duration(text).map_err(|error| error.to_string())
}

/// What one board said.
#[derive(Clone, Debug, Default)]
pub struct BoardHealth {
    /// The counters of the pages heard.
    pub diagnostics: Diagnostics,
    /// Which of the pages 0..5 arrived.
    pub pages: BTreeSet<u8>,
}

/// The page number of a health page; `None` for admission verdicts.
fn page_number(page: &DiagnosticsPage) -> Option<u8> {
    match page {
        DiagnosticsPage::VerdictRequest(_) | DiagnosticsPage::VerdictBound(_) => None,
        _ => Some(page.page()),
    }
}

impl BoardHealth {
    /// Takes one page.
    pub fn absorb(&mut self, page: &DiagnosticsPage) {
        if let Some(number) = page_number(page) {
            self.pages.insert(number);
            self.diagnostics.absorb(page);
        }
    }

    /// One line: silent, partial, or the problems the counters show (or that there are none).
    pub fn verdict(&self, board: Board) -> String {
        if self.pages.is_empty() {
            return format!("{board}: no answer");
        }
        let d = &self.diagnostics;
        let mut findings = Vec::new();
        let mut count = |value: u32, what: &str| {
            if value > 0 {
                findings.push(format!("{value} {what}"));
            }
        };
        count(d.rejected_total(), "rejected commands");
        count(
            d.admission_refused,
            "requests refused by the admission check",
        );
        count(d.rx_dropped, "received frames dropped (at least)");
        count(d.rx_overruns, "receive overruns");
        count(d.tx_dropped, "transmit drops");
        count(d.error_passive, "error-passive episodes");
        count(d.bus_off, "bus-off episodes");
        count(d.sensor_faults, "sensor faults");
        for priority in Priority::ALL {
            count(
                d.deadline_misses[priority as usize],
                &format!("{} deadline misses", priority.name()),
            );
        }
        let alarming = [
            ResetCause::INDEPENDENT_WATCHDOG,
            ResetCause::WINDOW_WATCHDOG,
            ResetCause::FAULT,
            ResetCause::BROWN_OUT,
        ];
        if alarming.iter().any(|cause| d.reset_cause.contains(*cause)) {
            findings.push(format!("last reset: {}", d.reset_cause));
        }
        let by_reason = |range: std::ops::Range<usize>| -> Vec<String> {
            range
                .filter_map(|index| {
                    let count = d.reason_count(index).filter(|c| *c > 0)?;
                    Some(format!("{} {count}", reason_name(index).unwrap_or("?")))
                })
                .collect()
        };
        let rejected = by_reason(0..REJECT_REASONS);
        if !rejected.is_empty() {
            findings.push(format!(
                "rejected by reason (the windows heard): {}",
                rejected.join(", ")
            ));
        }
        let refused = by_reason(REJECT_REASONS..COUNTED_REASONS);
        if !refused.is_empty() {
            findings.push(format!(
                "admission verdicts by reason (the windows heard): {}",
                refused.join(", ")
            ));
        }
        let partial = if self.pages.len() < usize::from(PAGES_PER_SAMPLE) {
            format!(
                " [only {} of {PAGES_PER_SAMPLE} pages arrived]",
                self.pages.len()
            )
        } else {
            String::new()
        };
        if findings.is_empty() {
            format!("{board}: healthy, up {} s{partial}", d.uptime_s)
        } else {
            format!(
                "{board}: up {} s; {}{partial}",
                d.uptime_s,
                findings.join("; ")
            )
        }
    }
}

/// `amiro health`.
pub fn health(args: &HealthArgs) -> Result<ExitCode> {
    let boards: Vec<Board> = if args.board.is_empty() {
        Board::ALL.to_vec()
    } else {
        args.board.clone()
    };
    let url = BusUrl::parse(&args.bus)?;
    bus::catch_interrupts()?;
    let mut bus = bus::open(&url, Direction::Send)?;
    let outcome = ask(bus.as_mut(), args, &boards);
    let closed = bus.close().with_context(|| format!("closing {url}"));
    let heard = outcome.with_context(|| format!("asking for health on {url}"))?;
    closed?;
    let mut complete = true;
    for (board, health) in boards.iter().zip(&heard) {
        complete &= health.pages.len() == usize::from(PAGES_PER_SAMPLE);
        eprintln!("{}", health.verdict(*board));
    }
    Ok(if complete {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn ask(bus: &mut dyn bus::Bus, args: &HealthArgs, boards: &[Board]) -> Result<Vec<BoardHealth>> {
    let mut view = View {
        time: TimeBase::Relative {
            origin: Some(Timestamp::now()),
        },
        json: args.json,
    };
    for board in boards {
        let request = Message::Command(Command::Sensor(SensorCommand {
            topic: board.diagnostics_topic(),
            priority: args.priority,
            mode: SensorMode::Once,
        }));
        bus.send(&encode::frame(&request)?)
            .with_context(|| format!("asking {board} for its health"))?;
    }
    let mut heard = vec![BoardHealth::default(); boards.len()];
    let mut out = io::stdout().lock();
    let give_up = Instant::now() + args.timeout;
    loop {
        let left = give_up.saturating_duration_since(Instant::now());
        if left.is_zero()
            || heard
                .iter()
                .all(|health| health.pages.len() == usize::from(PAGES_PER_SAMPLE))
        {
            break;
        }
        let logged = match bus.receive(Some(left))? {
            Reception::Frame(logged) => logged,
            Reception::TimedOut | Reception::Ended | Reception::Interrupted => break,
        };
        if let Ok(Message::Sample {
            data: SensorData::Diagnostics { board, page },
            ..
        }) = decode_frame(&logged.frame)
        {
            if let Some(index) = boards.iter().position(|asked| *asked == board) {
                heard[index].absorb(&page);
                writeln!(out, "{}", view.line(&logged))?;
                out.flush()?;
            }
        }
    }
    Ok(heard)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `amiro health` hears from one sample per reason window (every reason once).
    fn heard(diagnostics: &Diagnostics, board: Board) -> BoardHealth {
        let mut health = BoardHealth::default();
        let mut window = 0;
        loop {
            for frame in diagnostics.frames(board, Priority::Low, window) {
                let Ok(Message::Sample {
                    data: SensorData::Diagnostics { page, .. },
                    ..
                }) = amiro_can::decode(frame.id().raw(), frame.data())
                else {
                    panic!("a diagnostics frame")
                };
                health.absorb(&page);
            }
            window = Diagnostics::next_window(window);
            if window == 0 {
                return health;
            }
        }
    }

    #[test]
    fn a_quiet_board_is_healthy_and_a_troubled_one_names_its_troubles() {
        let mut diagnostics = Diagnostics::ZERO;
        diagnostics.uptime_s = 42;
        diagnostics.accepted = 10;
        let verdict = heard(&diagnostics, Board::DiWheelDrive).verdict(Board::DiWheelDrive);
        assert_eq!(verdict, "DiWheelDrive: healthy, up 42 s");

        diagnostics.rejected[1] = 3;
        diagnostics.rx_dropped = 7;
        diagnostics.deadline_misses[Priority::High as usize] = 2;
        diagnostics.bus_off = 1;
        diagnostics.admission_refused = 4;
        diagnostics.refusals[amiro_can::RefusalReason::MessageDeadline as usize] = 4;
        let verdict = heard(&diagnostics, Board::LightRing).verdict(Board::LightRing);
        for expected in [
            "3 rejected commands",
            "7 received frames dropped",
            "2 high deadline misses",
            "1 bus-off episodes",
            &format!("{} 3", amiro_can::DecodeError::KINDS[1]),
            "4 requests refused by the admission check",
            "admission verdicts by reason (the windows heard): admission-message-deadline 4",
        ] {
            assert!(verdict.contains(expected), "{expected} in {verdict}");
        }
        assert!(!verdict.contains("healthy"), "{verdict}");
    }

    #[test]
    fn silence_and_missing_pages_are_reported() {
        assert_eq!(
            BoardHealth::default().verdict(Board::PowerManagement),
            "PowerManagement: no answer"
        );
        let mut health = heard(&Diagnostics::ZERO, Board::PowerManagement);
        health.pages.remove(&5);
        assert!(health
            .verdict(Board::PowerManagement)
            .contains("only 5 of 6 pages"));
    }
}
