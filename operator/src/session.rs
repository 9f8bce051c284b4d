//! The operator's session commands: `monitor` (the receiver), `drive`, `run` (scripts), `relay`, and `send`'s
//! frames from a file. Each opens one bus, shows what it hears through a `watch::View`, and closes the bus on
//! every path, so an SLCAN channel is never left open and a shared adapter's users are told when it goes away.

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, IsTerminal, Write};
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};

use crate::bus::{self, Bus, BusUrl, Direction, Reception};
use crate::cli::MonitorArgs;
use crate::cli_session::{DriveArgs, RecordArgs, RelayArgs, RunArgs};
use crate::describe::decode_frame;
use crate::drive::{drive, DriveEnd, HostClock};
use crate::frame::{parse_line, text_lines, LoggedFrame, RawFrame, Timestamp};
use crate::record::Recording;
use crate::script::{parse_script, planned_duration, Step};
use crate::watch::{Filter, Statistics, TimeBase, View};

/// The exit status of a run ended by Ctrl-C, as shells report it (128 + SIGINT).
const INTERRUPTED_EXIT: u8 = 130;

fn relative_time(url: &BusUrl) -> TimeBase {
    match url {
        // A log starts when its first frame does.
        BusUrl::File { .. } => TimeBase::Relative { origin: None },
        _ => TimeBase::Relative {
            origin: Some(Timestamp::now()),
        },
    }
}

/// `amiro monitor`.
pub fn monitor(args: &MonitorArgs) -> Result<ExitCode> {
    let url = BusUrl::parse(&args.bus)?;
    if args.realtime && !matches!(url, BusUrl::File { .. }) {
        bail!("--realtime paces a log file; {url} is a live bus, which is always in real time");
    }
    bus::catch_interrupts()?;
    let mut bus = bus::open(
        &url,
        Direction::Receive {
            realtime: args.realtime,
        },
    )?;
    let mut view = View {
        time: if args.absolute {
            TimeBase::Absolute
        } else {
            relative_time(&url)
        },
        json: args.json,
    };
    let filter = Filter {
        boards: args.board.clone(),
        topics: args.topic.clone(),
        sensor_data_only: args.sensor_data,
    };
    let mut statistics = Statistics::default();
    let mut taps = Taps {
        recording: args.record.as_deref().map(Recording::create).transpose()?,
        #[cfg(feature = "foxglove")]
        live: None,
    };
    if let Some(address) = &args.foxglove {
        serve_foxglove(&mut taps, address)?;
    }
    let outcome = if args.dashboard {
        crate::dashboard::monitor(bus.as_mut(), args, &filter, &mut statistics, &mut taps)
    } else {
        watch(
            bus.as_mut(),
            args,
            &filter,
            &mut view,
            &mut statistics,
            &mut taps,
        )
    };
    let closed = bus.close().with_context(|| format!("closing {url}"));
    if let (Some(recording), Some(path)) = (taps.recording.take(), &args.record) {
        let (frames, _) = recording.finish()?;
        eprintln!("recorded {frames} frames into {}", path.display());
    }
    if !args.no_summary {
        for line in statistics.summary() {
            eprintln!("{line}");
        }
    }
    outcome.with_context(|| format!("monitoring {url}"))?;
    closed?;
    let received = statistics.frames();
    match args.count {
        Some(count) if received < count => {
            eprintln!("only {received} of {count} frames arrived");
            Ok(ExitCode::FAILURE)
        }
        _ => Ok(ExitCode::SUCCESS),
    }
}

/// Where the frames a monitor hears go besides the screen: an MCAP recording, a live Foxglove server.
pub struct Taps {
    /// `--record FILE.mcap`.
    pub recording: Option<Recording<BufWriter<File>>>,
    /// `--foxglove`.
    #[cfg(feature = "foxglove")]
    pub live: Option<crate::live::LiveServer>,
}

impl Taps {
    /// Hands a frame heard to each tap.
    pub fn frame(&mut self, logged: &LoggedFrame) -> Result<()> {
        if let Some(recording) = self.recording.as_mut() {
            recording.record(logged)?;
        }
        #[cfg(feature = "foxglove")]
        if let Some(live) = self.live.as_mut() {
            live.frame(logged)?;
        }
        Ok(())
    }
}

#[cfg(feature = "foxglove")]
fn serve_foxglove(taps: &mut Taps, address: &str) -> Result<()> {
    let live = crate::live::LiveServer::start(address)?;
    let host = address.rsplit_once(':').map_or(address, |(host, _)| host);
    eprintln!(
        "foxglove: serving on ws://{host}:{} (in Foxglove: Open connection → Foxglove WebSocket)",
        live.port()
    );
    taps.live = Some(live);
    Ok(())
}

#[cfg(not(feature = "foxglove"))]
fn serve_foxglove(_taps: &mut Taps, _address: &str) -> Result<()> {
    bail!(
        "this amiro was built without Foxglove's live server: cargo install --path operator --features foxglove \
         (or record with --record FILE.mcap and open the file in Foxglove)"
    )
}

/// Prints admitted frames until the count, the timeout, the end of the log or Ctrl-C.
fn watch(
    bus: &mut dyn Bus,
    args: &MonitorArgs,
    filter: &Filter,
    view: &mut View,
    statistics: &mut Statistics,
    taps: &mut Taps,
) -> Result<()> {
    let mut out = io::stdout().lock();
    // In English, an admission verdict's two pages are followed by the verdict in one sentence, with what would
    // be accepted as far as the frames heard tell (docs/operator.md).
    let mut admission = (!view.json).then(|| crate::admission::Lazy::new(args.revision.as_deref()));
    let give_up = args.timeout.map(|timeout| Instant::now() + timeout);
    while args.count.is_none_or(|count| statistics.frames() < count) {
        let left = give_up.map(|give_up| give_up.saturating_duration_since(Instant::now()));
        if left.is_some_and(|left| left.is_zero()) {
            break;
        }
        match bus.receive(left)? {
            Reception::Frame(logged) => {
                taps.frame(&logged)?;
                let verdict = admission.as_mut().and_then(|checker| {
                    let mut stamped = logged.clone();
                    stamped.timestamp.get_or_insert_with(Timestamp::now);
                    checker.heard(&stamped)
                });
                if !filter.admits(&logged.frame) {
                    continue;
                }
                statistics.record(&logged);
                writeln!(out, "{}", view.line(&logged))?;
                if let Some(verdict) = verdict {
                    writeln!(out, "  → {verdict}")?;
                }
                out.flush()?;
            }
            Reception::TimedOut | Reception::Ended | Reception::Interrupted => break,
        }
    }
    Ok(())
}

/// Frames for `send --file`: every line a frame (any form `decode` reads), each checked unless `raw`. All bad
/// lines are reported, with their numbers, before anything is sent.
pub fn frames_from_file(path: &Path, raw: bool) -> Result<Vec<RawFrame>> {
    let (input, name): (Box<dyn BufRead>, String) = if path == Path::new("-") {
        if io::stdin().is_terminal() {
            eprintln!("Reading frames from the terminal, one per line; end with Ctrl-D.");
        }
        (Box::new(io::stdin().lock()), "standard input".into())
    } else {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        (Box::new(BufReader::new(file)), path.display().to_string())
    };
    let mut frames = Vec::new();
    let mut errors = Vec::new();
    for line in text_lines(input) {
        let (number, line) = line.with_context(|| format!("cannot read {name}"))?;
        match line.and_then(|line| parse_line(&line)) {
            Ok(Some(logged)) => match decode_frame(&logged.frame) {
                Err(error) if !raw => errors.push(format!(
                    "line {number}: {} is not a valid AMiRo frame: {error} [{}]",
                    logged.frame,
                    error.kind_name()
                )),
                _ => frames.push(logged.frame),
            },
            Ok(None) => {}
            Err(error) => errors.push(format!("line {number}: {error}")),
        }
    }
    if !errors.is_empty() {
        bail!(
            "{name} has lines that cannot be sent, nothing was sent (use --raw for frames the robot rejects):\n  {}",
            errors.join("\n  ")
        );
    }
    if frames.is_empty() {
        bail!("nothing to send: {name} holds no frames");
    }
    Ok(frames)
}

/// Prints frames as they go and come: `sent …` for ours, the receiver's line for the robot's.
struct Printer {
    view: View,
}

impl Printer {
    fn show(&mut self, logged: &LoggedFrame, sent: bool) -> Result<()> {
        let mut out = io::stdout().lock();
        if sent {
            // Stamped now, so the sent line shows when it went out.
            let stamped = LoggedFrame {
                timestamp: Some(Timestamp::now()),
                interface: None,
                frame: logged.frame,
            };
            let line = self.view.line(&stamped);
            if self.view.json {
                writeln!(out, "{}", line.replacen('{', "{\"sent\":true,", 1))?;
            } else {
                writeln!(out, "sent {line}")?;
            }
        } else {
            writeln!(out, "{}", self.view.line(logged))?;
        }
        out.flush()?;
        Ok(())
    }
}

/// The bus `bus_text` names, opened to send with Ctrl-C caught (a drive or a script then stops cleanly), and
/// the printer of what goes out and comes back.
fn open_to_send(bus_text: &str, json: bool) -> Result<(BusUrl, Box<dyn Bus>, Printer)> {
    let url = BusUrl::parse(bus_text)?;
    bus::catch_interrupts()?;
    let bus = bus::open(&url, Direction::Send)?;
    let printer = Printer {
        view: View {
            time: relative_time(&url),
            json,
        },
    };
    Ok((url, bus, printer))
}

/// `amiro drive`.
pub fn drive_command(args: &DriveArgs) -> Result<ExitCode> {
    let plan = args.motion.plan()?;
    let (url, mut bus, mut printer) = open_to_send(&args.bus, args.json)?;
    let outcome = drive(
        bus.as_mut(),
        &HostClock::start(),
        &plan,
        &mut |frame, sent| printer.show(frame, sent),
    );
    let closed = bus.close().with_context(|| format!("closing {url}"));
    let end = outcome.with_context(|| format!("driving on {url}"))?;
    closed?;
    Ok(match end {
        DriveEnd::Finished => ExitCode::SUCCESS,
        DriveEnd::Interrupted => ExitCode::from(INTERRUPTED_EXIT),
    })
}

/// `amiro run`.
pub fn run(args: &RunArgs) -> Result<ExitCode> {
    let text = if args.script == Path::new("-") {
        io::read_to_string(io::stdin()).context("cannot read the script from standard input")?
    } else {
        std::fs::read_to_string(&args.script)
            .with_context(|| format!("cannot read {}", args.script.display()))?
    };
    let script =
        parse_script(&text, args.raw).with_context(|| format!("in {}", args.script.display()))?;
    if args.check {
        let mut out = io::stdout().lock();
        for (number, line, step) in &script.steps {
            let what = match step {
                Step::Send(frames) => frames
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(" "),
                Step::Wait(duration) => format!(
                    "watch the bus for {}",
                    crate::period::human_micros(duration.as_micros() as u64)
                ),
                Step::Drive(plan) => format!("drive {}, then stop", plan.describe("")),
            };
            writeln!(out, "line {number:>3}: {line:<60} {what}")?;
        }
        writeln!(
            out,
            "{} steps, about {} s",
            script.steps.len(),
            planned_duration(&script).as_secs_f64()
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    let Some(bus_text) = &args.bus else {
        bail!("no bus given: add --bus slcan:/dev/ttyUSB0 (or socketcan:can0, file:out.log), or set AMIRO_BUS");
    };
    let (url, mut bus, mut printer) = open_to_send(bus_text, args.json)?;
    let outcome = play(bus.as_mut(), &script, &mut printer);
    let closed = bus.close().with_context(|| format!("closing {url}"));
    let completed =
        outcome.with_context(|| format!("running {} on {url}", args.script.display()))?;
    closed?;
    Ok(if completed {
        ExitCode::SUCCESS
    } else {
        eprintln!("interrupted; the script did not finish");
        ExitCode::from(INTERRUPTED_EXIT)
    })
}

/// Plays the steps; `Ok(false)` if Ctrl-C ended it.
fn play(bus: &mut dyn Bus, script: &crate::script::Script, printer: &mut Printer) -> Result<bool> {
    for (number, line, step) in &script.steps {
        if bus::interrupted() {
            return Ok(false);
        }
        if !printer.view.json {
            println!("# line {number}: {line}");
        }
        match step {
            Step::Send(frames) => {
                for frame in frames {
                    bus.send(frame)
                        .with_context(|| format!("line {number}: sending {frame}"))?;
                    printer.show(&LoggedFrame::bare(*frame), true)?;
                }
            }
            Step::Wait(duration) => {
                let until = Instant::now() + *duration;
                loop {
                    let left = until.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        break;
                    }
                    match bus.receive(Some(left))? {
                        Reception::Frame(frame) => printer.show(&frame, false)?,
                        Reception::Interrupted => return Ok(false),
                        Reception::TimedOut => break,
                        // A log file bus has no more to say: keep the script's timing anyway.
                        Reception::Ended => std::thread::sleep(left.min(Duration::from_millis(50))),
                    }
                }
            }
            Step::Drive(plan) => {
                let end = drive(bus, &HostClock::start(), plan, &mut |frame, sent| {
                    printer.show(frame, sent)
                })
                .with_context(|| format!("line {number}"))?;
                if end == DriveEnd::Interrupted {
                    return Ok(false);
                }
            }
        }
    }
    Ok(true)
}

/// `amiro relay`.
pub fn relay(args: &RelayArgs) -> Result<ExitCode> {
    let url = BusUrl::parse(&args.bus)?;
    let BusUrl::Slcan { path, .. } = &url else {
        bail!("{url} needs no relay: only an SLCAN adapter can have just one user (SocketCAN is shared by the kernel)");
    };
    bus::catch_interrupts()?;
    let mut bus = bus::open(&url, Direction::Receive { realtime: false })?;
    let (socket, _) = bus::relay::rendezvous(path)?;
    eprintln!(
        "holding {url}; other amiro commands on it go through {} — Ctrl-C to close the adapter",
        socket.display()
    );
    let outcome = loop {
        match bus.receive(None) {
            Ok(Reception::Interrupted) | Ok(Reception::Ended) => break Ok(()),
            Ok(_) => {}
            Err(error) => break Err(error),
        }
    };
    let closed = bus.close().with_context(|| format!("closing {url}"));
    outcome?;
    closed?;
    Ok(ExitCode::SUCCESS)
}

/// `amiro record`: every frame of a bus into an MCAP file, until the duration, the end of a log or Ctrl-C.
pub fn record(args: &RecordArgs) -> Result<ExitCode> {
    let arena = match &args.world {
        Some(path) => Some(amiro_world::Arena::load(path).map_err(|error| {
            let text = error.to_string();
            let shown = path.display().to_string();
            if text.contains(&shown) {
                anyhow!("--world: {text}")
            } else {
                anyhow!("--world {shown}: {text}")
            }
        })?),
        None => None,
    };
    let trajectory = match &args.trajectory {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("--trajectory: cannot read {}", path.display()))?;
            Some(
                amiro_world::Trajectory::read_csv(&text)
                    .with_context(|| format!("--trajectory {}", path.display()))?,
            )
        }
        None => None,
    };
    let url = BusUrl::parse(&args.bus)?;
    bus::catch_interrupts()?;
    let mut bus = bus::open(&url, Direction::Receive { realtime: false })?;
    let mut recording = Recording::create(&args.out)?;
    let poses = trajectory.as_ref().map(|t| t.samples.len());
    recording.world(arena.as_ref(), trajectory)?;
    let until = args.duration.map(|duration| Instant::now() + duration);
    if io::stderr().is_terminal() {
        eprintln!("recording {url} into {} (Ctrl-C ends)", args.out.display());
    }
    let outcome = (|| -> Result<()> {
        loop {
            let left = until.map(|until| until.saturating_duration_since(Instant::now()));
            if left.is_some_and(|left| left.is_zero()) {
                return Ok(());
            }
            match bus.receive(left)? {
                Reception::Frame(logged) => recording.record(&logged)?,
                Reception::TimedOut | Reception::Ended | Reception::Interrupted => return Ok(()),
            }
        }
    })();
    let closed = bus.close().with_context(|| format!("closing {url}"));
    // The file is finished whatever ended the recording, so what was heard is kept.
    let untimed = recording.untimed;
    let (frames, _) = recording.finish()?;
    match poses {
        Some(poses) => eprintln!(
            "recorded {frames} frames and {poses} poses into {}",
            args.out.display()
        ),
        None => eprintln!("recorded {frames} frames into {}", args.out.display()),
    }
    if untimed > 0 {
        eprintln!("note: {untimed} frames had no time; each took the previous frame's");
    }
    outcome.with_context(|| format!("recording {url}"))?;
    closed?;
    Ok(ExitCode::SUCCESS)
}
