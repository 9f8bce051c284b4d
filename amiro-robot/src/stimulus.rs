//! What a robot run's stimulus may say: `candump -l` frames the operator's adapter sends, and the
//! world's events — SYS_PD_N pulled from outside, a SYS_WARMRST_N pulse or a board reset, a board
//! unplugged and plugged back, a bit error on the bus, a board's CAN controller babbling.
use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::log as qemu;

/// The three boards of the robot, in node order on the bus (the operator's adapter is the fourth).
pub const BOARDS: [&str; 3] = ["diwheeldrive", "powermgmt", "lightring"];

/// One thing the stimulus makes happen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// The operator's adapter sends a frame.
    Frame {
        /// Identifier (11-bit).
        id: u16,
        /// Payload.
        data: Vec<u8>,
    },
    /// SYS_PD_N pulled low from outside the boards (it stays low).
    PowerDown,
    /// A board is reset (its QEMU restarts; it rejoins after its boot).
    Reset(usize),
    /// A board's CAN connector is pulled.
    Unplug(usize),
    /// … and put back.
    Plug(usize),
    /// The next transmission (of this identifier, or any) starting from here reads a bit wrong.
    BitError(Option<u16>),
    /// A board's CAN controller starts babbling this frame back to back (a "babbling idiot").
    Babble {
        /// The board.
        board: usize,
        /// Identifier (11-bit).
        id: u16,
        /// Payload.
        data: Vec<u8>,
    },
    /// … and stops.
    Quiet(usize),
}

/// An action and when (µs from the start of the run).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Timed {
    /// When.
    pub at_us: u64,
    /// What.
    pub action: Action,
}

fn board_index(name: &str, line: &str) -> Result<usize> {
    BOARDS.iter().position(|b| *b == name).with_context(|| {
        format!("`{line}`: no board `{name}` (diwheeldrive, powermgmt, lightring)")
    })
}

/// Parses one stimulus line; blank lines and `#` comments give `None`.
pub fn parse_line(line: &str) -> Result<Option<Timed>> {
    let trimmed = line.trim();
    if trimmed.is_empty() || trimmed.starts_with('#') {
        return Ok(None);
    }
    let mut fields = trimmed.split_whitespace();
    let stamp = fields.next().unwrap_or_default();
    let verb = fields.next().unwrap_or_default();
    let object = fields.next();
    let at = |s: &str| -> Result<u64> {
        let stamp =
            amiro_can::candump::parse_timestamp(s).map_err(|e| anyhow::anyhow!("`{line}`: {e}"))?;
        qemu::micros_of(stamp, line)
    };
    let action = match (verb, object) {
        ("signal", Some("SYS_PD_N")) => Action::PowerDown,
        // A warm-reset pulse: LightRing is held in reset by SYS_WARMRST_N (DiWheelDrive only reads
        // the line at its start-up, PowerManagement drives it), so the pulse restarts LightRing.
        ("signal", Some("SYS_WARMRST_N")) => Action::Reset(2),
        ("signal", _) => bail!("`{line}`: a stimulus pulls SYS_PD_N or pulses SYS_WARMRST_N"),
        ("reset", Some(board)) => Action::Reset(board_index(board, line)?),
        ("unplug", Some(board)) => Action::Unplug(board_index(board, line)?),
        ("plug", Some(board)) => Action::Plug(board_index(board, line)?),
        ("babble", Some(board)) => {
            let board = board_index(board, line)?;
            match fields.next() {
                Some("off") => Action::Quiet(board),
                Some(frame) => {
                    let frame = amiro_can::candump::parse_compact(frame)
                        .map_err(|e| anyhow::anyhow!("`{line}`: {e}"))?;
                    let amiro_can::candump::FrameId::Standard(id) = frame.id() else {
                        bail!("`{line}`: the robot's bus carries 11-bit identifiers only");
                    };
                    if frame.is_remote() {
                        bail!("`{line}`: the robot's bus carries no remote frames");
                    }
                    Action::Babble {
                        board,
                        id,
                        data: frame.data().to_vec(),
                    }
                }
                None => bail!("`{line}`: babble BOARD ID#DATA or babble BOARD off"),
            }
        }
        ("bit-error", Some("any")) => Action::BitError(None),
        ("bit-error", Some(id)) => Action::BitError(Some(
            u16::from_str_radix(id, 16)
                .ok()
                .filter(|&id| id <= 0x7FF)
                .with_context(|| format!("`{line}`: `{id}` is no 11-bit identifier"))?,
        )),
        _ => {
            let Some(frame) = qemu::parse_log_line(trimmed)? else {
                return Ok(None);
            };
            if frame.id > 0x7FF {
                bail!("`{line}`: the robot's bus carries 11-bit identifiers only");
            }
            return Ok(Some(Timed {
                at_us: frame.at_us,
                action: Action::Frame {
                    id: frame.id as u16,
                    data: frame.data,
                },
            }));
        }
    };
    Ok(Some(Timed {
        at_us: at(stamp)?,
        action,
    }))
}

/// Reads a robot stimulus: its actions in time order, and its `# duration:` header if it has one.
pub fn read(path: &Path) -> Result<(Vec<Timed>, Option<u64>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut actions = Vec::new();
    let mut duration = None;
    for (n, line) in text.lines().enumerate() {
        if let Some(d) = line.trim().strip_prefix("# duration:") {
            duration = Some(qemu::parse_duration(d.trim())?);
        }
        if let Some(a) =
            parse_line(line).with_context(|| format!("{}:{}", path.display(), n + 1))?
        {
            actions.push(a);
        }
    }
    // Stable: actions at the same time keep the file's order.
    actions.sort_by_key(|a| a.at_us);
    Ok((actions, duration))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines() {
        assert_eq!(
            parse_line("(0.010000) can0 205#01840302").unwrap(),
            Some(Timed {
                at_us: 10_000,
                action: Action::Frame {
                    id: 0x205,
                    data: vec![1, 0x84, 3, 2]
                }
            })
        );
        assert_eq!(
            parse_line("(0.500000) reset lightring")
                .unwrap()
                .unwrap()
                .action,
            Action::Reset(2)
        );
        // A fraction is a decimal fraction of a second.
        assert_eq!(
            parse_line("(0.5) unplug diwheeldrive")
                .unwrap()
                .unwrap()
                .at_us,
            500_000
        );
        assert!(parse_line("(0.5x) unplug diwheeldrive").is_err());
        assert_eq!(
            parse_line("(0.100000) bit-error 605")
                .unwrap()
                .unwrap()
                .action,
            Action::BitError(Some(0x605))
        );
        assert_eq!(
            parse_line("(0.100000) signal SYS_PD_N").unwrap().unwrap(),
            Timed {
                at_us: 100_000,
                action: Action::PowerDown
            }
        );
        assert_eq!(
            parse_line("(0.200000) signal SYS_WARMRST_N")
                .unwrap()
                .unwrap()
                .action,
            Action::Reset(2)
        );
        assert_eq!(
            parse_line("(0.020000) babble lightring 610#A5A5")
                .unwrap()
                .unwrap(),
            Timed {
                at_us: 20_000,
                action: Action::Babble {
                    board: 2,
                    id: 0x610,
                    data: vec![0xA5, 0xA5]
                }
            }
        );
        assert_eq!(
            parse_line("(0.050000) babble lightring off")
                .unwrap()
                .unwrap()
                .action,
            Action::Quiet(2)
        );
        assert!(parse_line("(0.050000) babble lightring").is_err());
        assert!(parse_line("(0.050000) babble operator 610#00").is_err());
        assert!(parse_line("(0.200000) signal SYS_SYNC_N").is_err());
        assert!(parse_line("(0.100000) reset operator").is_err());
        assert!(parse_line("(0.100000) bit-error 800").is_err());
        assert!(parse_line("(0.100000) can0 12345#00").is_err());
        assert_eq!(parse_line("# a comment").unwrap(), None);
    }
}
