//! The search for the on-chip admission check's costliest step (issue 20), on the host: random command sequences
//! (publish requests of every topic of the robot at every level and a spread of periods, stops, one-shots, and
//! optionally policy changes), each replayed through DiWheelDrive's [`Admission`] step by step as the admission
//! task runs them ([`Admission::replay`]: the preparation steps, the decision, the refresh steps after a stop; each
//! analyses at most one board and the bus), hill-climbed by mutating single commands of the best sequence.
//!
//! The objective is a step's fixed-point iterations (what the host counts the same as the chip); the instructions
//! the chip spends on a winner are measured by replaying its `candump -l` log in QEMU (scenario `admission-search`).
//! [`search`] runs the search, [`worst_step`] replays one sequence, [`StoredLog`] reads and writes the scenario's log,
//! and [`keep`] is the rule that picks between a stored sequence and a new winner. The example
//! `admission_search` and `cargo xtask admission-search` call these.
use std::boxed::Box;
use std::fmt;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec;

use schedule_analysis::admission::RobotTable;
use schedule_analysis::rng::Rng;

use crate::admission::{Admission, State, StepKind};

/// Every sensor topic of the robot: DiWheelDrive's nine, PowerManagement's three, LightRing's one.
const TOPICS: [u8; 13] = [
    0x01, 0x02, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x1A, 0x1B, 0x1E, 0x1F, 0x1C,
];
/// The boards' diagnostics topics (where a policy command goes).
const DIAGNOSTICS: [u8; 3] = [0x1A, 0x1B, 0x1C];
/// Periods tried: (value, unit byte: 0 ms, 1 s, 2 µs).
const PERIODS: [(u16, u8); 14] = [
    (1, 2),
    (100, 2),
    (400, 2),
    (700, 2),
    (900, 2),
    (1, 0),
    (2, 0),
    (5, 0),
    (10, 0),
    (20, 0),
    (50, 0),
    (100, 0),
    (500, 0),
    (1, 1),
];
/// Commands per searched sequence (the protocol's 13 publishers fit several times over).
pub const LENGTH: usize = 40;
/// When a log's first command is sent, in µs.
pub const FIRST_US: u64 = 5_000;
/// The pace of a log's commands, in µs: the admission task's sustained pace, so none waits for the pacing or finds
/// the queue full.
pub const PACE_US: u64 = 45_000;
/// How long a log runs after its first command's slot ends, in ms (its `# duration:` is `commands × 45 + 60`).
pub const TAIL_MS: u64 = 60;

/// One command frame of a sequence: a standard identifier and up to four data bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Command {
    /// The frame's identifier.
    pub id: u16,
    data: [u8; 4],
    len: u8,
}

impl Command {
    /// A command with `data` (at most four bytes; `None` for more).
    pub fn new(id: u16, data: &[u8]) -> Option<Self> {
        let mut bytes = [0; 4];
        bytes.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id,
            data: bytes,
            len: data.len() as u8,
        })
    }

    /// The frame's data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }

    fn random(rng: &mut Rng, policies: bool) -> Self {
        let level = rng.below(4) as u16;
        let topic = rng.pick(&TOPICS) as u16;
        let id = level << 8 | topic;
        match rng.below(if policies { 10 } else { 9 }) {
            // Mostly publish requests: they are what the check analyses.
            0..=5 => {
                let (value, unit) = rng.pick(&PERIODS);
                let [lo, hi] = value.to_le_bytes();
                Self {
                    id,
                    data: [1, lo, hi, unit],
                    len: 4,
                }
            }
            6 | 7 => Self {
                id,
                data: [0; 4],
                len: 1,
            },
            8 => Self {
                id,
                data: [2, 0, 0, 0],
                len: 1,
            },
            _ => Self {
                id: rng.pick(&DIAGNOSTICS) as u16,
                data: [3, rng.below(2) as u8, 0, 0],
                len: 2,
            },
        }
    }
}

/// A sequence's costliest step; ordered by iterations, then by the later command, then a refresh after a decision.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct Cost {
    /// The step's fixed-point iterations.
    pub iterations: u64,
    /// The index of the command whose step it was (0 for the first).
    pub command: usize,
    /// Whether it was a step of the command other than its decision (a refresh after a stop, or a step preparing
    /// the decision).
    pub refresh: bool,
}

impl fmt::Display for Cost {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} iterations at command {}{}",
            self.iterations,
            self.command + 1,
            if self.refresh {
                ", its refresh step"
            } else {
                ""
            }
        )
    }
}

/// The costliest step of `commands` replayed from a fresh state through DiWheelDrive's admission on `table`.
pub fn worst_step(table: &RobotTable<'_>, commands: &[Command]) -> Cost {
    let mut state = Box::new(State::<48, 32>::new());
    let mut admission = Admission::new(table, amiro_can::Board::DiWheelDrive, &mut state);
    admission.prepare();
    let mut worst = Cost::default();
    for (i, c) in commands.iter().enumerate() {
        let _ = admission.replay(c.id, c.data(), |kind, iterations| {
            worst = worst.max(Cost {
                iterations,
                command: i,
                refresh: kind != StepKind::Decision,
            });
        });
    }
    worst
}

/// What a search found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Found {
    /// The winner, cut after its costliest step.
    pub commands: Vec<Command>,
    /// Its costliest step.
    pub cost: Cost,
    /// The seed.
    pub seed: u64,
    /// Rounds run (fewer than asked when a step reached the most a step can take).
    pub run: usize,
    /// Rounds asked for.
    pub rounds: usize,
    /// Whether policy changes were among the commands.
    pub policies: bool,
}

impl Found {
    /// The winner as a stimulus log, one command every [`PACE_US`], with the header the scenario's logs carry;
    /// `how` names how it was run (its first header line).
    pub fn to_log(&self, how: &str) -> StoredLog {
        let mut header = Vec::new();
        header.push(format!(
            "Found by {how} (seed {}, {} of {} rounds{}{}): the command sequence whose",
            self.seed,
            self.run,
            self.rounds,
            if self.policies {
                ", policy changes"
            } else {
                ""
            },
            if self.run < self.rounds {
                ", stopped at the most a step can take"
            } else {
                ""
            }
        ));
        header.push(format!(
            "costliest admission step took the most fixed-point iterations on the host ({}).",
            self.cost
        ));
        header.push(
            "Replayed in QEMU by scenario admission-search: every step within the admission task's budget per step."
                .to_string(),
        );
        StoredLog::paced(header, self.commands.clone())
    }
}

/// Hill-climbs `rounds` rounds from `seed` (half the rounds a fresh random sequence, half a mutation of the best)
/// for the most fixed-point iterations in one step; `progress` hears each new best (round, cost). Stops early once
/// a step reaches both caps (a board's and the bus's `DECISION_ITERATIONS`), which nothing can beat.
pub fn search(
    table: &RobotTable<'_>,
    seed: u64,
    rounds: usize,
    policies: bool,
    mut progress: impl FnMut(usize, Cost),
) -> Found {
    let mut rng = Rng::new(seed.max(1));
    let mut best: Vec<Command> = (0..LENGTH)
        .map(|_| Command::random(&mut rng, policies))
        .collect();
    let mut best_cost = worst_step(table, &best);
    let most = 2 * schedule_analysis::admission::DECISION_ITERATIONS;
    let mut run = 0;
    for round in 0..rounds {
        if best_cost.iterations >= most {
            break;
        }
        run = round + 1;
        let candidate: Vec<Command> = if round % 2 == 0 {
            (0..LENGTH)
                .map(|_| Command::random(&mut rng, policies))
                .collect()
        } else {
            let mut c = best.clone();
            for _ in 0..1 + rng.below(3) {
                let at = rng.index(LENGTH);
                c[at] = Command::random(&mut rng, policies);
            }
            c
        };
        let cost = worst_step(table, &candidate);
        if cost.iterations > best_cost.iterations {
            best = candidate;
            best_cost = cost;
            progress(round, cost);
        }
    }
    best.truncate(best_cost.command + 1);
    Found {
        commands: best,
        cost: best_cost,
        seed,
        run,
        rounds,
        policies,
    }
}

/// Which sequence to keep: the new winner only if its costliest step takes strictly more iterations than the
/// stored sequence's, both replayed on the same tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keep {
    /// The stored sequence costs as much or more.
    Stored,
    /// The new winner costs more.
    Found,
}

/// [`Keep`]'s rule.
pub fn keep(stored: Cost, found: Cost) -> Keep {
    if found.iterations > stored.iterations {
        Keep::Found
    } else {
        Keep::Stored
    }
}

/// A scenario's stimulus log as stored: `#` header lines, a `# duration: <n>ms` line, then one `candump -l` line
/// per command.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredLog {
    /// The header's comment lines without their `# ` and without the duration line.
    pub header: Vec<String>,
    /// The `# duration:` in ms.
    pub duration_ms: u64,
    /// The commands with their times in µs.
    pub commands: Vec<(u64, Command)>,
}

/// Why a stored log does not parse; `line` counts from 1.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LogError {
    /// A frame line that is not `(seconds.micros) can0 ID#DATA`.
    BadFrame {
        /// The line's number.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// An extended identifier or a remote frame: no admission command is one.
    NotACommand {
        /// The line's number.
        line: usize,
    },
    /// More than four data bytes: no admission command has them.
    TooLong {
        /// The line's number.
        line: usize,
    },
    /// A `# duration:` that is not `<n>ms`.
    BadDuration {
        /// The line's number.
        line: usize,
    },
    /// No `# duration:` line.
    NoDuration,
    /// No command.
    NoCommands,
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadFrame { line, reason } => write!(f, "line {line}: {reason}"),
            Self::NotACommand { line } => write!(
                f,
                "line {line}: an extended identifier or a remote frame is no admission command"
            ),
            Self::TooLong { line } => write!(
                f,
                "line {line}: more than four data bytes, no admission command"
            ),
            Self::BadDuration { line } => {
                write!(f, "line {line}: expected `# duration: <n>ms`")
            }
            Self::NoDuration => f.write_str("no `# duration: <n>ms` line"),
            Self::NoCommands => f.write_str("no command"),
        }
    }
}

impl std::error::Error for LogError {}

impl StoredLog {
    /// `commands` one every [`PACE_US`] from [`FIRST_US`], the duration covering them.
    pub fn paced(header: Vec<String>, commands: Vec<Command>) -> Self {
        let n = commands.len() as u64;
        Self {
            header,
            duration_ms: n * PACE_US / 1000 + TAIL_MS,
            commands: commands
                .into_iter()
                .enumerate()
                .map(|(i, c)| (FIRST_US + i as u64 * PACE_US, c))
                .collect(),
        }
    }

    /// Reads a stored log.
    pub fn parse(text: &str) -> Result<Self, LogError> {
        let mut header = Vec::new();
        let mut duration_ms = None;
        let mut commands = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let number = i + 1;
            if let Some(comment) = line.trim().strip_prefix('#') {
                let comment = comment.strip_prefix(' ').unwrap_or(comment);
                if let Some(value) = comment.strip_prefix("duration:") {
                    let ms = value
                        .trim()
                        .strip_suffix("ms")
                        .and_then(|v| v.parse().ok())
                        .ok_or(LogError::BadDuration { line: number })?;
                    duration_ms = Some(ms);
                } else {
                    header.push(comment.to_string());
                }
                continue;
            }
            let parsed =
                amiro_can::candump::parse_log_line(line).map_err(|e| LogError::BadFrame {
                    line: number,
                    reason: e.to_string(),
                })?;
            let Some(parsed) = parsed else { continue };
            let id = match parsed.frame.id() {
                amiro_can::candump::FrameId::Standard(id) if !parsed.frame.is_remote() => id,
                _ => return Err(LogError::NotACommand { line: number }),
            };
            let command =
                Command::new(id, parsed.frame.data()).ok_or(LogError::TooLong { line: number })?;
            commands.push((parsed.timestamp.as_micros(), command));
        }
        if commands.is_empty() {
            return Err(LogError::NoCommands);
        }
        Ok(Self {
            header,
            duration_ms: duration_ms.ok_or(LogError::NoDuration)?,
            commands,
        })
    }

    /// The commands alone.
    pub fn sequence(&self) -> Vec<Command> {
        self.commands.iter().map(|(_, c)| *c).collect()
    }

    /// The log's text: the header, the duration, the frames.
    pub fn render(&self) -> String {
        let mut out = String::new();
        for line in &self.header {
            out.push_str("# ");
            out.push_str(line);
            out.push('\n');
        }
        out.push_str(&format!("# duration: {}ms\n", self.duration_ms));
        for (at, c) in &self.commands {
            let data: String = c.data().iter().map(|b| format!("{b:02X}")).collect();
            let at = amiro_can::candump::Timestamp::from_micros(*at);
            out.push_str(&format!("({at}) can0 {:03X}#{data}\n", c.id));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_path(revision: &str) -> std::path::PathBuf {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        match revision {
            "1-2" => root.join("diwheeldrive/qemu/rev-1-2/admission-search.log"),
            _ => root.join("diwheeldrive/qemu/admission-search.log"),
        }
    }

    #[test]
    fn the_stored_logs_round_trip() {
        for revision in ["1-1", "1-2"] {
            let text = std::fs::read_to_string(log_path(revision)).unwrap();
            let log = StoredLog::parse(&text).unwrap();
            assert_eq!(log.render(), text, "{revision}");
            assert_eq!(StoredLog::parse(&log.render()).unwrap(), log);
            // The stored logs are paced as the search writes them.
            let paced = StoredLog::paced(log.header.clone(), log.sequence());
            assert_eq!(paced, log, "{revision}");
        }
    }

    #[test]
    fn malformed_logs_are_typed_errors() {
        assert_eq!(StoredLog::parse("# hi\n"), Err(LogError::NoCommands));
        assert_eq!(
            StoredLog::parse("(0.005000) can0 006#00\n"),
            Err(LogError::NoDuration)
        );
        assert_eq!(
            StoredLog::parse("# duration: 5s\n(0.005000) can0 006#00\n"),
            Err(LogError::BadDuration { line: 1 })
        );
        assert!(matches!(
            StoredLog::parse("# duration: 50ms\n(0.005000) can0 00G#00\n"),
            Err(LogError::BadFrame { line: 2, .. })
        ));
        assert_eq!(
            StoredLog::parse("# duration: 50ms\n(0.005000) can0 006#0011223344\n"),
            Err(LogError::TooLong { line: 2 })
        );
        assert_eq!(
            StoredLog::parse("# duration: 50ms\n(0.005000) can0 00000006#00\n"),
            Err(LogError::NotACommand { line: 2 })
        );
    }

    #[test]
    fn the_stored_sequence_is_kept_unless_the_new_one_costs_more() {
        let at = |iterations, command| Cost {
            iterations,
            command,
            refresh: false,
        };
        assert_eq!(keep(at(1975, 35), at(1971, 35)), Keep::Stored);
        // A tie keeps the stored one, even at a later command.
        assert_eq!(keep(at(1975, 10), at(1975, 30)), Keep::Stored);
        assert_eq!(keep(at(1975, 35), at(1976, 3)), Keep::Found);
    }

    #[test]
    fn a_small_search_writes_a_log_that_replays_to_its_cost() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let robot = schedule_analysis::admission_host::lower_robot_for(&root, Some("1-2")).unwrap();
        robot.with_table(|table| {
            let found = search(table, 38, 6, true, |_, _| {});
            assert_eq!(found.run, 6);
            assert_eq!(found.commands.len(), found.cost.command + 1);
            let log = found.to_log("a test");
            let back = StoredLog::parse(&log.render()).unwrap();
            assert_eq!(back, log);
            assert_eq!(worst_step(table, &back.sequence()), found.cost);
            assert_eq!(
                log.duration_ms,
                found.commands.len() as u64 * 45 + 60,
                "the scenario's duration rule"
            );
            // The stored 1-2 sequence replays on the same tables; the rule picks one of them.
            let stored =
                StoredLog::parse(&std::fs::read_to_string(log_path("1-2")).unwrap()).unwrap();
            let stored_cost = worst_step(table, &stored.sequence());
            assert!(stored_cost.iterations > 0);
        });
    }
}
