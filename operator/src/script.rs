//! Scripts: timed sequences of commands (`amiro run demo.amiro`), in the same words as the command line, and
//! the one parser the console's command line uses too.
//!
//! One step per line; `#` starts a comment. A step is a raw frame (`205#01840302`), any `encode` command
//! (`publish gyroscope --every 100ms --priority high`, `stop …`, `once …`, `motor …`, `led …`), `wait 500ms`
//! (watch the bus for that long), or `drive --forward 100mm/s --turn 0deg/s --for 2s` (a kept-alive motor command
//! ending in a stop). The spoken forms of `speech` (`publish gyroscope every 100ms at high`, `led 3 red`,
//! `drive 100mm/s turn 30deg/s for 3s`) are rewritten into these flag forms first. A whole script is parsed before anything is sent, so a typo on line 9 does not leave the
//! robot half-configured.

use std::time::Duration;

use amiro_can::{MotorCommand, Priority};
use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Parser, Subcommand};

use crate::cli::MessageArgs;
use crate::describe::decode_frame;
use crate::drive::{check_every, parse_speed, parse_turn, DrivePlan, DEFAULT_EVERY};
use crate::encode;
use crate::frame::{parse_compact, RawFrame};
use crate::period::parse_duration;

/// One line of a script or of the console, parsed by clap with the same words as the command line.
#[derive(Debug, Parser)]
#[command(
    no_binary_name = true,
    disable_help_flag = true,
    disable_version_flag = true
)]
pub struct StepLine {
    /// The step.
    #[command(subcommand)]
    pub step: StepArgs,
}

/// The words of a step.
#[derive(Debug, Clone, Subcommand)]
pub enum StepArgs {
    /// A command, as `amiro encode` takes it.
    #[command(flatten)]
    Message(MessageArgs),
    /// Watch the bus for a while
    Wait {
        /// How long, e.g. 500ms or 2s
        #[arg(value_name = "DURATION")]
        duration: String,
    },
    /// Drive with the motor command kept alive, then stop
    Drive(DriveWords),
}

/// `drive --forward 100mm/s --turn 30deg/s --for 3s`.
#[derive(Debug, Clone, Args)]
pub struct DriveWords {
    /// Forward speed: 100mm/s, 0.1m/s, -50mm/s (backwards)
    #[arg(
        long,
        value_name = "SPEED",
        default_value = "0mm/s",
        allow_hyphen_values = true
    )]
    pub forward: String,
    /// Turning rate: 30deg/s, 0.5rad/s (positive: counter-clockwise seen from above)
    #[arg(
        long,
        value_name = "RATE",
        default_value = "0deg/s",
        allow_hyphen_values = true
    )]
    pub turn: String,
    /// How long to drive, e.g. 3s (without it: until Ctrl-C)
    #[arg(long = "for", value_name = "DURATION")]
    pub duration: Option<String>,
    /// Priority of the motor frames
    #[arg(long, value_name = "PRIORITY", default_value = "high", value_parser = parse_priority)]
    pub priority: Priority,
    /// How often the motor command is repeated (the board stops after 500 ms without one)
    #[arg(long, value_name = "PERIOD", default_value = "200ms")]
    pub every: String,
}

fn parse_priority(text: &str) -> Result<Priority, String> {
    Priority::from_name(text)
        .ok_or_else(|| format!("unknown priority {text:?}: urgent, high, medium or low"))
}

impl DriveWords {
    /// The plan these words describe.
    pub fn plan(&self) -> Result<DrivePlan> {
        let duration = self
            .duration
            .as_deref()
            .map(|text| parse_duration(text).with_context(|| format!("--for {text}")))
            .transpose()?;
        if duration.is_some_and(|duration| duration.is_zero()) {
            bail!("--for 0 drives for no time at all");
        }
        let every = check_every(
            parse_duration(&self.every).with_context(|| format!("--every {}", self.every))?,
        )?;
        Ok(DrivePlan {
            command: MotorCommand {
                velocity_um_s: parse_speed(&self.forward)?,
                angular_urad_s: parse_turn(&self.turn)?,
            },
            priority: self.priority,
            duration,
            every,
        })
    }
}

/// A step ready to play: everything checked and encoded.
#[derive(Clone, Debug)]
pub enum Step {
    /// Send these frames.
    Send(Vec<RawFrame>),
    /// Watch the bus for this long.
    Wait(Duration),
    /// A kept-alive drive.
    Drive(DrivePlan),
}

/// Splits a line into words as a shell would (quotes allowed, so `led 3 --rgb '#FF8000'` works).
/// A `#` that begins a word is a colour (`led 3 #FF8020`), not a comment, so it is escaped before splitting.
pub fn words(line: &str) -> Result<Vec<String>> {
    let mut escaped = String::with_capacity(line.len() + 4);
    let mut quote = None;
    let mut previous = ' ';
    for c in line.chars() {
        match (quote, c) {
            (None, '\'' | '"') => quote = Some(c),
            (Some(open), _) if c == open => quote = None,
            (None, '#') if previous.is_whitespace() => escaped.push('\\'),
            _ => {}
        }
        escaped.push(c);
        previous = c;
    }
    shlex::split(&escaped).ok_or_else(|| anyhow!("unbalanced quotes"))
}

/// Parses one step; `Ok(None)` for a blank line or a comment. Raw frames are checked by the decoder unless `raw`.
pub fn parse_step(line: &str, raw: bool) -> Result<Option<Step>> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') || line.starts_with("//") {
        return Ok(None);
    }
    let words = words(line)?;
    if words
        .iter()
        .all(|word| word.contains('#') && !word.starts_with('#') && !word.starts_with('-'))
    {
        let mut frames = Vec::new();
        for word in &words {
            let frame = parse_compact(word)?;
            if !raw {
                if let Err(error) = decode_frame(&frame) {
                    bail!(
                        "{frame} is not a valid AMiRo frame: {error} [{}]",
                        error.kind_name()
                    );
                }
            }
            frames.push(frame);
        }
        return Ok(Some(Step::Send(frames)));
    }
    // A spoken line (`publish gyroscope every 100ms at high`) becomes its flag form first.
    let words = match crate::speech::translate(&words) {
        Some(flags) => flags?,
        None => words,
    };
    let parsed = StepLine::try_parse_from(&words).map_err(|error| {
        let mut message = clap_message(&error);
        if let Some(suggestion) = crate::speech::suggestion(&words) {
            message.push_str(&format!(" ({suggestion})"));
        }
        anyhow!("{message}")
    })?;
    Ok(Some(match parsed.step {
        StepArgs::Message(message) => Step::Send(vec![encode::frame(&encode::message(&message)?)?]),
        StepArgs::Wait { duration } => Step::Wait(parse_duration(&duration)?),
        StepArgs::Drive(words) => Step::Drive(words.plan()?),
    }))
}

/// clap's message without its usage block, on one line.
pub fn clap_message(error: &clap::Error) -> String {
    let text = error.to_string();
    let first = text
        .lines()
        .map(str::trim)
        .find(|line| !line.is_empty())
        .unwrap_or("cannot read the step");
    first.trim_start_matches("error: ").to_string()
}

/// A parsed script: its steps with their line numbers and text.
#[derive(Clone, Debug)]
pub struct Script {
    /// (line number, the line as written, the step).
    pub steps: Vec<(usize, String, Step)>,
}

/// Parses a whole script; every bad line is reported (with its number) before any step would run.
pub fn parse_script(text: &str, raw: bool) -> Result<Script> {
    let mut steps = Vec::new();
    let mut errors = Vec::new();
    for (index, line) in text.lines().enumerate() {
        match parse_step(line, raw) {
            Ok(Some(step)) => steps.push((index + 1, line.trim().to_string(), step)),
            Ok(None) => {}
            Err(error) => errors.push(format!("line {}: {error:#}", index + 1)),
        }
    }
    if !errors.is_empty() {
        bail!(
            "the script has errors, nothing was sent:\n  {}",
            errors.join("\n  ")
        );
    }
    Ok(Script { steps })
}

/// How long a script takes, counting waits and timed drives (a drive without `--for` counts as zero).
pub fn planned_duration(script: &Script) -> Duration {
    script
        .steps
        .iter()
        .map(|(_, _, step)| match step {
            Step::Wait(duration) => *duration,
            Step::Drive(plan) => plan.duration.unwrap_or_default(),
            Step::Send(_) => Duration::ZERO,
        })
        .sum()
}

/// The keep-alive period a console uses when none is given.
pub const CONSOLE_EVERY: Duration = DEFAULT_EVERY;

#[cfg(test)]
mod tests {
    use super::*;

    const DEMO: &str = include_str!("../examples/standalone-demo.amiro");

    #[test]
    fn the_shipped_standalone_demo_parses_into_the_thesis_sequence() {
        let script = parse_script(DEMO, false).unwrap();
        let sent: Vec<String> = script
            .steps
            .iter()
            .filter_map(|(_, _, step)| match step {
                Step::Send(frames) => Some(
                    frames
                        .iter()
                        .map(ToString::to_string)
                        .collect::<Vec<_>>()
                        .join(" "),
                ),
                Step::Drive(_) => Some("drive".into()),
                Step::Wait(_) => None,
            })
            .collect();
        // Gyroscope, proximity ring, motor, odometry, stop gyroscope, LED 3 — the thesis's order.
        assert_eq!(sent.len(), 8, "{sent:?}");
        assert!(
            sent[0].starts_with("108#01"),
            "gyroscope publish at high: {sent:?}"
        );
        assert!(
            sent[1].starts_with("21F#01"),
            "proximity ring at medium: {sent:?}"
        );
        assert_eq!(sent[2], "drive");
        assert!(sent[3].starts_with("301#01"), "odometry at low: {sent:?}");
        assert_eq!(sent[4], "108#00");
        assert!(sent[5].starts_with("313#"), "LED 3: {sent:?}");
        assert_eq!(sent[6..], ["21F#00", "301#00"], "a quiet bus at the end");
        assert!(planned_duration(&script) >= Duration::from_secs(5));
    }

    #[test]
    fn every_step_form_parses() {
        assert!(parse_step("  # comment", false).unwrap().is_none());
        let Some(Step::Send(frames)) = parse_step("205#01840302 204#02", false).unwrap() else {
            panic!()
        };
        assert_eq!(frames.len(), 2);
        let Some(Step::Send(frames)) = parse_step("led 3 --rgb '#FF8000'", false).unwrap() else {
            panic!()
        };
        assert_eq!(frames[0].to_string(), "313#FF8000");
        let Some(Step::Wait(wait)) = parse_step("wait 1.5s", false).unwrap() else {
            panic!()
        };
        assert_eq!(wait, Duration::from_millis(1500));
        let Some(Step::Drive(plan)) =
            parse_step("drive --forward -100mm/s --turn 30deg/s --for 3s", false).unwrap()
        else {
            panic!()
        };
        assert_eq!(plan.command.velocity_um_s, -100_000);
        assert_eq!(plan.command.angular_urad_s, 523_599);
        assert_eq!(plan.duration, Some(Duration::from_secs(3)));
        assert_eq!(plan.priority, Priority::High);
    }

    #[test]
    fn bad_lines_are_all_reported_with_their_numbers() {
        let error = parse_script(
            "publish gyroscope --every 10ms --priority high\nwait soon\n205#03\nfly away\ndrive --forward 1mm/s --every 600ms\n",
            false,
        )
        .unwrap_err();
        let message = format!("{error:#}");
        for expected in [
            "line 2:",
            "line 3: 205#03",
            "[bad-mode]",
            "line 4:",
            "line 5:",
            "dead-man",
        ] {
            assert!(message.contains(expected), "{expected} in {message}");
        }
        assert!(!message.contains("line 1:"), "{message}");
        assert!(
            parse_script("205#03\n", true).is_ok(),
            "--raw sends what it is told"
        );
    }
}
