//! `cargo xtask flash`: every board through DiWheelDrive's serial port and AMiRo-BLT (`--port`),
//! or one board through probe-rs over SWD (`--probe`). The protocol is `amiro-blt`; this module
//! is the serial-port adapter, the progress display and the CI run against a simulated robot.
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use amiro_blt::target::{robot, IdSet};
use amiro_blt::{Event, Flasher, Image, Observer, Options, Phase, RestartOutcome, Target};
use anyhow::{bail, ensure, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serialport::SerialPort;

use crate::boards::{self, Board, BOARDS};
use crate::revision::{self, Choice};

/// The serial line's speed on every AMiRo-BLT.
const BAUD: u32 = 115_200;
/// Environment variable the boards' `cargo run` runner reads: a port means serial flashing.
pub const PORT_ENV: &str = "AMIRO_PORT";

/// Arguments of `cargo xtask flash`.
#[derive(clap::Args, Debug)]
pub struct FlashArgs {
    /// Boards to flash: diwheeldrive, powermgmt, lightring, or `all`.
    #[arg(required = true)]
    pub boards: Vec<String>,
    /// DiWheelDrive's programming port (e.g. /dev/ttyUSB0): flash through AMiRo-BLT.
    #[arg(long, conflicts_with = "probe")]
    pub port: Option<String>,
    /// Flash one board through probe-rs over SWD (a probe on that board's pins).
    #[arg(long)]
    pub probe: bool,
    /// The device ids the robot's bootloaders answer to: 1-2, 1-1 or legacy. They name the robot's
    /// revision, and so which image of each board is built and written (1-1 and legacy: the 1-1
    /// images); a board without an image for it, or an image of the other revision, is refused
    /// before anything is erased.
    #[arg(long, default_value = "1-2")]
    pub ids: String,
    /// Over SWD (`--probe`): the revision of the board on the probe (1-2, 1-1). Default: its newest.
    #[arg(long, value_name = "1-2|1-1", requires = "probe")]
    pub revision: Option<String>,
    /// Reset the robot through the cable's RTS line instead of asking for the reset button.
    #[arg(long)]
    pub reset_line: bool,
}

/// `cargo xtask flash …`.
pub fn run(root: &Path, args: &FlashArgs) -> Result<()> {
    let selected = select(&args.boards)?;
    match &args.port {
        Some(port) => {
            let id_set = ids(&args.ids)?;
            // Which image of each board this robot takes: refused here, before the port is
            // opened, when a board has none for its revision.
            let plan = revision::plan(&selected, &Choice::Robot(robot_revision(id_set)))
                .with_context(|| {
                    format!(
                        "the robot answers to the {} ids; nothing was erased",
                        args.ids
                    )
                })?;
            let reports = crate::build_boards(root, &plan, false)?;
            let elfs: Vec<PathBuf> = reports.iter().map(|r| r.elf.clone()).collect();
            serial(port, &selected, &elfs, &options(args), id_set).map(|_| ())
        }
        None => {
            let [board] = selected[..] else {
                bail!(
                    "over SWD one board at a time (a probe on its pins); for several boards \
                     use --port with DiWheelDrive's programming cable"
                );
            };
            let choice = Choice::parse(args.revision.as_deref())?;
            ensure!(choice != Choice::All, "one revision over SWD");
            let plan = revision::plan(&[board], &choice)?;
            let reports = crate::build_boards(root, &plan, false)?;
            let report = reports.first().context("one image built")?;
            println!("{} {} image", board.name, report.revision);
            crate::flash_elf(board, &report.elf)
        }
    }
}

/// The robot revision whose images a robot answering to `ids` takes.
pub fn robot_revision(ids: IdSet) -> &'static str {
    match ids {
        IdSet::Rev12 => "1-2",
        IdSet::Rev11 | IdSet::Legacy => "1-1",
    }
}

/// Refuses an image for a board whose bootloader answers to `target`'s id unless the image is for
/// that board's revision: the id names the revision (`boards::Revision::device_ids`), the ELF
/// declares its own (`AMIRO_DEVICE_ID`; an image without it is the board's only revision).
pub fn check_revision(board: &Board, target: &Target, elf: &Path) -> Result<()> {
    let Some(wanted) = board.revision_of_id(target.device_id) else {
        bail!(
            "{}: the robot's {} answers to device id {:#010x}, a revision this firmware has no image for \
             (its revisions: {}); nothing was erased",
            board.name,
            board.name,
            target.device_id,
            revision::names(board)
        );
    };
    let image = revision::of_elf(board, elf)?;
    if image != wanted {
        bail!(
            "{}: {} is the {} {} image, but the robot's {} answers to device id {:#010x} ({} {}); \
             nothing was erased (build that revision: cargo xtask build {} --revision {})",
            board.name,
            elf.display(),
            board.name,
            image.name,
            board.name,
            target.device_id,
            board.name,
            wanted.name,
            board.name,
            wanted.robot()
        );
    }
    Ok(())
}

/// The boards' `cargo run --release` runner: serial when `AMIRO_PORT` names a port, else SWD.
pub fn run_elf(board: &'static Board, elf: &Path) -> Result<()> {
    match std::env::var(PORT_ENV) {
        Ok(port) if !port.is_empty() => {
            let opts = Options {
                reset_line: std::env::var("AMIRO_RESET_LINE").is_ok_and(|v| v == "1"),
                ..Options::default()
            };
            let id_set = ids(&std::env::var("AMIRO_IDS").unwrap_or_else(|_| "1-2".into()))?;
            serial(&port, &[board], &[elf.to_path_buf()], &opts, id_set).map(|_| ())
        }
        _ => {
            let image = revision::of_elf(board, elf)?;
            println!("{} {} image", board.name, image.name);
            crate::flash_elf(board, elf)
        }
    }
}

fn options(args: &FlashArgs) -> Options {
    Options {
        reset_line: args.reset_line,
        ..Options::default()
    }
}

fn ids(text: &str) -> Result<IdSet> {
    IdSet::parse(text).with_context(|| format!("--ids {text}: expected 1-2, 1-1 or legacy"))
}

fn select(names: &[String]) -> Result<Vec<&'static Board>> {
    if names.iter().any(|n| n == "all") {
        return Ok(BOARDS.iter().collect());
    }
    names
        .iter()
        .map(|n| {
            boards::by_name(n).with_context(|| {
                format!("unknown board `{n}` (known: diwheeldrive, powermgmt, lightring, all)")
            })
        })
        .collect()
}

/// The image of a board's ELF, after the build's layout check (a bare-chip image is refused
/// here, before the port is even opened).
fn image_of(board: &Board, elf: &Path) -> Result<Image> {
    crate::elf::inspect(board, elf, true).with_context(|| {
        format!(
            "{} is not linked behind AMiRo-BLT; nothing was erased (rebuild without --bare-chip)",
            elf.display()
        )
    })?;
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    Image::from_elf(&bytes).with_context(|| format!("{}", elf.display()))
}

fn target_of(board: &Board, ids: IdSet) -> Result<Target> {
    let target = robot(ids)
        .into_iter()
        .find(|t| t.name == board.name)
        .with_context(|| format!("{} has no AMiRo-BLT device id", board.name))?;
    if u64::from(target.app_origin) != board.app_base
        || u64::from(target.checksum_offset) != board.checksum_slot
    {
        bail!(
            "{}: the bootloader layout in amiro-blt and xtask/src/boards.rs disagree",
            board.name
        );
    }
    Ok(target)
}

/// One board's line of the summary.
struct Outcome {
    board: &'static str,
    bytes: usize,
    took: Duration,
    result: std::result::Result<String, String>,
}

/// Flashes `boards` (with their ELFs) through AMiRo-BLT on `port`, restarts the robot and prints
/// a summary. Fails unless every board was flashed and verified.
pub fn serial(
    port: &str,
    boards: &[&'static Board],
    elfs: &[PathBuf],
    opts: &Options,
    ids: IdSet,
) -> Result<usize> {
    let mut jobs = Vec::new();
    for (board, elf) in boards.iter().zip(elfs) {
        let target = target_of(board, ids)?;
        check_revision(board, &target, elf)?;
        jobs.push((*board, target, image_of(board, elf)?));
    }
    let link = SerialLink::open(port)?;
    let mut flasher = Flasher::new(link, opts.clone());
    let mut show = Progress::default();
    println!("waiting for the main board's bootloader on {port} …");
    flasher.enter_flash_mode(&mut show)?;
    let mut outcomes = Vec::new();
    let mut failed = false;
    for (board, target, image) in &jobs {
        let started = Instant::now();
        let result = flasher.flash(target, image, &mut show);
        show.finish();
        let took = started.elapsed();
        failed |= result.is_err();
        outcomes.push(Outcome {
            board: board.name,
            bytes: image.len(),
            took,
            result: result
                .map(|r| {
                    format!(
                        "verified ({} round(s), {} repeated command(s))",
                        r.attempts, r.retries
                    )
                })
                .map_err(|e| e.to_string()),
        });
        if failed {
            break;
        }
    }
    let restart = if failed {
        None
    } else {
        Some(flasher.restart().context("restarting the robot")?)
    };
    println!(
        "\n{:<14} {:>8} {:>8} {:>9}  result",
        "board", "bytes", "time", "bytes/s"
    );
    for o in &outcomes {
        let rate = o.bytes as f64 / o.took.as_secs_f64().max(1e-6);
        let text = match &o.result {
            Ok(t) => t.clone(),
            Err(e) => format!("FAILED: {e}"),
        };
        println!(
            "{:<14} {:>8} {:>7.1}s {:>9.0}  {text}",
            o.board,
            o.bytes,
            o.took.as_secs_f64(),
            rate
        );
    }
    for (board, _, _) in jobs.iter().skip(outcomes.len()) {
        println!(
            "{:<14} {:>8} {:>8} {:>9}  not attempted",
            board.name, "-", "-", "-"
        );
    }
    match restart {
        Some(RestartOutcome::Started) => {
            println!("the robot was restarted and runs the new firmware")
        }
        Some(RestartOutcome::StayedInBootloader) => println!(
            "the main board answered PROGRAM_RESET but stayed in its bootloader: power-cycle the \
             robot (its start hook refuses after a connection in the window)"
        ),
        None => println!(
            "the robot was not restarted: the boards not marked verified stay in their \
             bootloaders; reset the robot and run again"
        ),
    }
    if failed {
        bail!("flashing failed (see the table above)");
    }
    Ok(outcomes.iter().map(|o| o.bytes).sum())
}

/// A progress bar per board: bytes, rate and time left.
#[derive(Default)]
struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish();
        }
    }
}

impl Observer for Progress {
    fn event(&mut self, event: Event<'_>) {
        match event {
            Event::PressReset => println!(
                "no answer: press the robot's reset button now (the bootloader listens for 500 ms)"
            ),
            Event::ResetLinePulsed => println!("reset the robot through RTS"),
            Event::FlashMode => println!("main board in flashing mode"),
            Event::Phase {
                target,
                phase,
                total,
            } => {
                self.finish();
                let verb = match phase {
                    Phase::Checking => "checking",
                    Phase::Erasing => "erasing",
                    Phase::Programming => "programming",
                    Phase::Verifying => "verifying",
                };
                let bar = ProgressBar::new(total as u64);
                let style = ProgressStyle::with_template(
                    "{prefix:<13} {msg:<11} [{bar:30}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
                bar.set_style(style);
                bar.set_prefix(target.name.clone());
                bar.set_message(verb);
                self.bar = Some(bar);
            }
            Event::Progress { done, .. } => {
                if let Some(bar) = &self.bar {
                    bar.set_position(done as u64);
                }
            }
            Event::Retry { reason } => match &self.bar {
                Some(bar) => bar.println(format!("retrying: {reason}")),
                None => println!("retrying: {reason}"),
            },
        }
    }
}

/// DiWheelDrive's programming cable as a [`amiro_blt::Transport`].
struct SerialLink {
    port: serialport::TTYPort,
    opened: Instant,
}

impl SerialLink {
    fn open(path: &str) -> Result<Self> {
        let mut port = serialport::new(path, BAUD)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(Duration::from_millis(10))
            .open_native()
            .with_context(|| format!("opening {path}"))?;
        // As SerialBoot does: DTR on, RTS off. Modem lines fail on a pty or some adapters, and
        // the cable's wiring of them is unknown, so this is best effort.
        let _ = port.write_data_terminal_ready(true);
        let _ = port.write_request_to_send(false);
        Ok(SerialLink {
            port,
            opened: Instant::now(),
        })
    }
}

impl amiro_blt::Transport for SerialLink {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.port.write_all(bytes)?;
        self.port.flush()
    }

    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.port
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .map_err(std::io::Error::other)?;
        match self.port.read(buf) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            Err(e) => Err(e),
        }
    }

    fn clock(&self) -> Duration {
        self.opened.elapsed()
    }

    fn pulse_reset(&mut self) -> std::io::Result<bool> {
        if self.port.write_request_to_send(true).is_err() {
            return Ok(false);
        }
        std::thread::sleep(Duration::from_millis(50));
        self.port
            .write_request_to_send(false)
            .map_err(std::io::Error::other)?;
        Ok(true)
    }
}

/// CI: `cargo xtask flash … --port <pty>` against simulated robots of both revisions (each board
/// behind DiWheelDrive's bootloader): each robot gets its revision's images, each board's simulated
/// flash is compared with its ELF as the probe path would write it (`elf::write_checksum`), byte
/// for byte, and the robot started; a board without an image for the robot's revision and an image
/// of the other revision are refused before the port is opened (the robot's flash untouched).
/// `reports`: the images `cargo xtask build --revision all` built.
pub fn simulated_robot(root: &Path, reports: &[crate::elf::SizeReport]) -> Result<()> {
    use amiro_blt_sim::BoardSpec;
    let elf = |board: &str, revision: &str| -> Result<PathBuf> {
        reports
            .iter()
            .find(|r| r.board == board && r.revision == revision)
            .map(|r| r.elf.clone())
            .with_context(|| format!("no {board} {revision} image was built"))
    };
    let by = |name: &str| boards::by_name(name).context("board");
    // A 1-2 robot: every board's 1-2 image.
    let dwd = by("diwheeldrive")?;
    let pm = by("powermgmt")?;
    let lr = by("lightring")?;
    flash_simulated(
        root,
        BoardSpec::robot_1_2(),
        IdSet::Rev12,
        &[
            (dwd, elf("diwheeldrive", "1-2")?),
            (pm, elf("powermgmt", "1-1/1-2")?),
            (lr, elf("lightring", "1-2")?),
        ],
    )?;
    // A 1-1 robot: every board, through the 32-bit ids.
    flash_simulated(
        root,
        BoardSpec::robot_1_1(),
        IdSet::Rev11,
        &[
            (dwd, elf("diwheeldrive", "1-1")?),
            (pm, elf("powermgmt", "1-1/1-2")?),
            (lr, elf("lightring", "1-0")?),
        ],
    )?;
    // Refusals, before anything is erased.
    let refused = [
        (
            "the 1-1 DiWheelDrive image for a 1-2 robot",
            BoardSpec::robot_1_2(),
            IdSet::Rev12,
            (dwd, elf("diwheeldrive", "1-1")?),
            "is the diwheeldrive 1-1 image, but the robot's diwheeldrive answers to device id 0x01000102",
        ),
        (
            "the 1-2 DiWheelDrive image for a 1-1 robot",
            BoardSpec::robot_1_1(),
            IdSet::Rev11,
            (dwd, elf("diwheeldrive", "1-2")?),
            "is the diwheeldrive 1-2 image, but the robot's diwheeldrive answers to device id 0x01000101",
        ),
        (
            "the 1-0 LightRing image for a 1-2 robot",
            BoardSpec::robot_1_2(),
            IdSet::Rev12,
            (lr, elf("lightring", "1-0")?),
            "is the lightring 1-0 image, but the robot's lightring answers to device id 0x017f0102",
        ),
        (
            "the 1-2 LightRing image for a 1-1 robot",
            BoardSpec::robot_1_1(),
            IdSet::Rev11,
            (lr, elf("lightring", "1-2")?),
            "is the lightring 1-2 image, but the robot's lightring answers to device id 0x017f0100",
        ),
    ];
    for (what, spec, ids, job, message) in refused {
        let error = match flash_simulated(root, spec, ids, &[job]) {
            Ok(()) => bail!("{what} was written"),
            Err(e) => format!("{e:#}"),
        };
        ensure!(
            error.contains(message) && error.contains("nothing was erased"),
            "{what}: refused with `{error}`, expected it to say `{message}`"
        );
        println!("flash through a simulated robot: {what} refused: {error}");
    }
    // And `cargo xtask flash all` picks each board's image of the robot's revision.
    let all: Vec<&'static Board> = BOARDS.iter().collect();
    for ids in [IdSet::Rev12, IdSet::Rev11] {
        let plan = revision::plan(&all, &Choice::Robot(robot_revision(ids)))?;
        let stems: Vec<String> = plan.iter().map(revision::Build::stem).collect();
        let lightring = if ids == IdSet::Rev12 { "1-2" } else { "1-0" };
        ensure!(
            stems.contains(&format!("lightring-{lightring}")),
            "flash all for a {} robot plans {stems:?}",
            robot_revision(ids)
        );
    }
    Ok(())
}

/// Flashes `jobs` into a simulated robot of `spec` answering to `ids`, through a pty, and checks
/// every board's flash against its ELF. On a refusal the robot must be untouched.
fn flash_simulated(
    root: &Path,
    spec: Vec<amiro_blt_sim::BoardSpec>,
    ids: IdSet,
    jobs: &[(&'static Board, PathBuf)],
) -> Result<()> {
    use amiro_blt_sim::{pty::PtyRobot, Faults, Robot, Timing};
    let started = Instant::now();
    let sim = Robot::new(spec, Timing::instant(), Faults::default());
    let served = PtyRobot::serve(sim).context("starting the simulated robot on a pty")?;
    let port = served.path().to_string_lossy().into_owned();
    let boards: Vec<&'static Board> = jobs.iter().map(|(b, _)| *b).collect();
    let elfs: Vec<PathBuf> = jobs.iter().map(|(_, e)| e.clone()).collect();
    let opts = Options {
        window_patience: Duration::from_secs(10),
        ..Options::default()
    };
    let flashed = serial(&port, &boards, &elfs, &opts, ids);
    let robot = served.stop();
    let bytes = match flashed {
        Ok(bytes) => bytes,
        Err(e) => {
            // Refused or failed: a refusal must not have touched the robot.
            if robot.log.is_empty() {
                for (board, _) in jobs {
                    let target = target_of(board, ids)?;
                    let flash = robot.flash(target.device_id);
                    let end = target.app_origin + 4096;
                    ensure!(
                        flash
                            .bytes(target.app_origin, end)
                            .iter()
                            .all(|b| *b == 0xFF),
                        "{}: refused, but its application region was written",
                        board.name
                    );
                }
            }
            if robot.log.is_empty() {
                return Err(e);
            }
            return Err(e.context(format!("the simulated robot's log: {:#?}", robot.log)));
        }
    };
    for (board, elf) in jobs {
        let target = target_of(board, ids)?;
        let patched = crate::target_dir(root).join(format!("{}.sim-check.elf", board.name));
        crate::elf::write_checksum(elf, &patched)?;
        let image = Image::from_elf(&std::fs::read(&patched)?)?;
        let flash = robot.flash(target.device_id);
        for segment in image.segments() {
            let got = flash.read(segment.address, segment.data.len());
            if let Some(i) = (0..got.len()).find(|&i| got[i] != segment.data[i]) {
                bail!(
                    "{}: simulated flash differs from the ELF at {:#010x}",
                    board.name,
                    segment.address + i as u32
                );
            }
        }
        if !flash.app_valid() || !robot.app_started(target.device_id) {
            bail!(
                "{}: the simulated bootloader did not start the application",
                board.name
            );
        }
    }
    println!(
        "flash through a simulated {} robot: {} ({bytes} bytes) byte-for-byte equal to their ELFs, started ({:.1} s)",
        robot_revision(ids),
        jobs.iter()
            .map(|(b, e)| format!("{} {}", b.name, e.file_name().and_then(|n| n.to_str()).unwrap_or("")))
            .collect::<Vec<_>>()
            .join(", "),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
