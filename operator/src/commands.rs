//! What each subcommand does: read frames, decode or encode them, talk to a bus, print the results.

use std::fs::File;
use std::io::{self, BufRead, BufReader, IsTerminal, Write};
use std::path::Path;
use std::process::ExitCode;

use amiro_can::{Command, Message, SensorCommand, SensorMode, TOPICS};
use anyhow::{bail, Context, Result};

use crate::bus::{self, BusUrl, Direction};
use crate::cli::{DbcArgs, DecodeArgs, EncodeArgs, MessageArgs, MonitorArgs, SendArgs};
use crate::describe::{decode_frame, json_record, json_unreadable, text_line, text_unreadable};
use crate::encode;
use crate::frame::{parse_compact, parse_line, text_lines, FrameTextError, LoggedFrame, RawFrame};
use crate::period::human_micros;

/// Writes decoded frames in the chosen format and remembers whether anything was wrong.
struct Report<W: Write> {
    out: W,
    json: bool,
    all_decoded: bool,
    /// `decode --mcap`: every frame also goes into this recording.
    recording: Option<crate::record::Recording<io::BufWriter<File>>>,
}

impl<W: Write> Report<W> {
    fn new(out: W, json: bool) -> Self {
        Self {
            out,
            json,
            all_decoded: true,
            recording: None,
        }
    }

    fn frame(&mut self, logged: &LoggedFrame, line: Option<usize>) -> io::Result<()> {
        if let Some(recording) = self.recording.as_mut() {
            recording.record(logged).map_err(io::Error::other)?;
        }
        let decoded = decode_frame(&logged.frame);
        self.all_decoded &= decoded.is_ok();
        if self.json {
            writeln!(self.out, "{}", json_record(logged, line, &decoded))
        } else {
            writeln!(self.out, "{}", text_line(logged, &decoded))
        }
    }

    fn unreadable(
        &mut self,
        line: Option<usize>,
        input: &str,
        error: &FrameTextError,
    ) -> io::Result<()> {
        self.all_decoded = false;
        if self.json {
            writeln!(self.out, "{}", json_unreadable(line, input, error))
        } else {
            writeln!(self.out, "{}", text_unreadable(line, error))
        }
    }

    /// Completes the MCAP file, if one is written.
    fn finish(&mut self, path: Option<&Path>) -> Result<()> {
        if let (Some(recording), Some(path)) = (self.recording.take(), path) {
            let untimed = recording.untimed;
            let (frames, _) = recording.finish()?;
            eprintln!("recorded {frames} frames into {}", path.display());
            if untimed > 0 {
                eprintln!("note: {untimed} frames had no time; each took the previous frame's (0 at the start)");
            }
        }
        Ok(())
    }

    fn exit_code(&self) -> ExitCode {
        if self.all_decoded {
            ExitCode::SUCCESS
        } else {
            ExitCode::FAILURE
        }
    }
}

/// `amiro decode`.
pub fn decode(args: &DecodeArgs) -> Result<ExitCode> {
    let mut report = Report::new(io::stdout().lock(), args.json);
    if let Some(path) = &args.mcap {
        report.recording = Some(crate::record::Recording::create(path)?);
    }
    let outcome = decode_into(args, &mut report);
    report.finish(args.mcap.as_deref())?;
    outcome
}

fn decode_into<W: Write>(args: &DecodeArgs, report: &mut Report<W>) -> Result<ExitCode> {
    if !args.frames.is_empty() {
        for text in &args.frames {
            match parse_line(text) {
                Ok(Some(logged)) => report.frame(&logged, None)?,
                Ok(None) => {}
                Err(error) => report.unreadable(None, text, &error)?,
            }
        }
        return Ok(report.exit_code());
    }
    let input: Box<dyn BufRead> = match args.file.as_deref() {
        Some(path) if path != Path::new("-") => Box::new(BufReader::new(
            File::open(path).with_context(|| format!("cannot open {}", path.display()))?,
        )),
        _ => {
            if io::stdin().is_terminal() {
                eprintln!("Reading frames from the terminal, one per line; end with Ctrl-D.");
            }
            Box::new(io::stdin().lock())
        }
    };
    for line in text_lines(input) {
        let (number, line) = line.context("cannot read the input")?;
        let number = Some(number);
        match line {
            Ok(line) => match parse_line(&line) {
                Ok(Some(logged)) => report.frame(&logged, number)?,
                Ok(None) => {}
                Err(error) => report.unreadable(number, &line, &error)?,
            },
            Err(error) => {
                let input = match &error {
                    FrameTextError::NotText { lossy } => lossy.clone(),
                    _ => String::new(),
                };
                report.unreadable(number, &input, &error)?
            }
        }
    }
    Ok(report.exit_code())
}

/// `amiro encode`.
pub fn encode(args: &EncodeArgs) -> Result<ExitCode> {
    let frame = encode::frame(&encode::message(&args.message)?)?;
    writeln!(io::stdout(), "{frame}")?;
    Ok(ExitCode::SUCCESS)
}

/// `amiro send`.
pub fn send(args: &SendArgs) -> Result<ExitCode> {
    let frames = match &args.file {
        Some(path) => crate::session::frames_from_file(path, args.raw)?,
        // `amiro send < frames.txt` or `amiro encode ... | amiro send`: frames from standard input.
        None if args.message.is_none() && args.frames.is_empty() && !io::stdin().is_terminal() => {
            crate::session::frames_from_file(Path::new("-"), args.raw)?
        }
        None => frames_to_send(args.message.as_ref(), &args.frames, args.raw)?,
    };
    let url = bus_url(args.bus.as_deref())?;
    let mut bus = bus::open(&url, Direction::Send)?;
    // Before anything leaves: would the board that owns the topic refuse a publish request, with
    // what the robot runs as far as the bus (or a log of it) tells?
    let requests = frames.iter().any(|frame| {
        matches!(
            decode_frame(frame),
            Ok(Message::Command(Command::Sensor(SensorCommand {
                mode: SensorMode::Publish(_) | SensorMode::Once,
                ..
            })))
        )
    });
    let mut checker = None;
    if requests {
        match crate::admission::Checker::load(args.revision.as_deref()) {
            Ok(mut loaded) => {
                if let Some(path) = &args.heard {
                    learn_from_log(&mut loaded, path)?;
                }
                let live = !matches!(url, BusUrl::File { .. });
                match args.listen {
                    Some(listen) if !live && !listen.is_zero() => {
                        eprintln!(
                            "note: {url} is a log file: nothing to listen to (use --heard FILE)"
                        )
                    }
                    _ if live => {
                        let listen = args.listen.unwrap_or(DEFAULT_LISTEN);
                        listen_first(bus.as_mut(), &mut loaded, listen)
                            .with_context(|| format!("listening on {url}"))?;
                    }
                    _ => {}
                }
                checker = Some(loaded);
            }
            Err(error) => eprintln!("note: publish requests are not checked: {error:#}"),
        }
    }
    for frame in &frames {
        let (Some(checker), Ok(message)) = (checker.as_mut(), decode_frame(frame)) else {
            continue;
        };
        if let Some(warning) = checker.check(&message) {
            eprintln!("warning: {frame}: {warning}");
        }
    }
    let mut report = Report::new(io::stdout().lock(), false);
    let mut outcome = Ok(());
    for frame in &frames {
        if let Err(error) = bus.send(frame) {
            outcome = Err(error);
            break;
        }
        write!(report.out, "sent ")?;
        report.frame(&LoggedFrame::bare(*frame), None)?;
    }
    // Close even after a failed send, so an adapter is not left with an open channel.
    let closed = bus.close().with_context(|| format!("closing {url}"));
    outcome.with_context(|| format!("sending on {url}"))?;
    closed?;
    Ok(ExitCode::SUCCESS)
}

/// How long `amiro send` listens before a publish request on a live bus, unless `--listen` says.
const DEFAULT_LISTEN: std::time::Duration = std::time::Duration::from_secs(1);

/// Feeds a log of the bus to the admission check (verdicts in it are printed).
fn learn_from_log(checker: &mut crate::admission::Checker, path: &Path) -> Result<()> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    for line in text_lines(BufReader::new(file)) {
        let (_, line) = line.with_context(|| format!("cannot read {}", path.display()))?;
        if let Ok(Some(logged)) = line.and_then(|line| parse_line(&line)) {
            if let Some(verdict) = checker.heard(&logged) {
                eprintln!("heard: {verdict}");
            }
        }
    }
    Ok(())
}

/// Listens to a live bus for `listen`, teaching the admission check what runs.
fn listen_first(
    bus: &mut dyn bus::Bus,
    checker: &mut crate::admission::Checker,
    listen: std::time::Duration,
) -> Result<()> {
    let until = std::time::Instant::now() + listen;
    loop {
        let left = until.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        match bus.receive(Some(left))? {
            bus::Reception::Frame(mut logged) => {
                logged
                    .timestamp
                    .get_or_insert_with(crate::frame::Timestamp::now);
                if let Some(verdict) = checker.heard(&logged) {
                    eprintln!("heard: {verdict}");
                }
            }
            _ => return Ok(()),
        }
    }
}

/// The frames `send` was asked for, each checked against the decoder unless `raw`.
fn frames_to_send(
    message: Option<&MessageArgs>,
    texts: &[String],
    raw: bool,
) -> Result<Vec<RawFrame>> {
    if let Some(message) = message {
        return Ok(vec![encode::frame(&encode::message(message)?)?]);
    }
    if texts.is_empty() {
        bail!("nothing to send: give frames such as 205#01840302, or a command such as `publish gyroscope ...`");
    }
    let mut frames = Vec::with_capacity(texts.len());
    for text in texts {
        let frame = parse_compact(text).with_context(|| format!("cannot send {text:?}"))?;
        if !raw {
            if let Err(error) = decode_frame(&frame) {
                bail!("{frame} is not a valid AMiRo frame: {error} [{}] (use --raw to send it anyway)", error.kind_name());
            }
        }
        frames.push(frame);
    }
    Ok(frames)
}

fn bus_url(bus: Option<&str>) -> Result<BusUrl> {
    let Some(bus) = bus else {
        bail!("no bus given: add --bus socketcan:can0 (or slcan:/dev/ttyUSB0, file:out.log), or set AMIRO_BUS");
    };
    BusUrl::parse(bus)
}

/// `amiro monitor` (the receiver's view lives in `session`).
pub fn monitor(args: &MonitorArgs) -> Result<ExitCode> {
    crate::session::monitor(args)
}

/// `amiro topics`.
pub fn topics() -> Result<ExitCode> {
    let mut out = io::stdout().lock();
    writeln!(
        out,
        "{:<5} {:<16} {:<16} {:<8} {:>3} {:>6} {:>9}  payload",
        "topic", "name", "board", "kind", "dlc", "frames", "default"
    )?;
    for info in TOPICS {
        let (kind, default) = if info.is_sensor {
            ("sensor", human_micros(u64::from(info.default_period_us)))
        } else {
            ("actuator", "-".to_string())
        };
        writeln!(
            out,
            "0x{:02X}  {:<16} {:<16} {:<8} {:>3} {:>6} {:>9}  {}",
            info.topic.byte(),
            info.name,
            info.board.name(),
            kind,
            info.dlc,
            info.frames_per_sample,
            default,
            info.layout
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `amiro dbc`: the protocol as a DBC file, on standard output or into `--output`.
pub fn dbc(args: &DbcArgs) -> Result<ExitCode> {
    let text = crate::dbc::generate();
    match &args.output {
        Some(path) => std::fs::write(path, text)
            .with_context(|| format!("cannot write {}", path.display()))?,
        None => io::stdout().lock().write_all(text.as_bytes())?,
    }
    Ok(ExitCode::SUCCESS)
}
