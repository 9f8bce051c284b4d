//! `cargo xtask flash`: every board through DiWheelDrive's serial port and AMiRo-BLT (`--port`),
//! or one board through probe-rs over SWD (`--probe`). The protocol is `amiro-blt`; this module
//! is the serial-port adapter, the progress display and the CI run against a simulated robot.
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use amiro_blt::target::{robot, IdSet};
use amiro_blt::{
    Event, Flasher, Identification, Image, MainBoardId, Observer, Options, Phase, RestartOutcome,
    Target,
};
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
    /// The device ids the robot's bootloaders answer to (1-2, 1-1 or legacy), stated instead of
    /// learnt. Without it the robot's revision is read from the main board's bootloader; with it
    /// a main board of the other revision is refused, and a bootloader whose id cannot be read
    /// is trusted to be the one stated. Either way the images of that revision are written, and
    /// a board without one, or an image of the other revision, is refused before anything is
    /// erased.
    #[arg(long, value_name = "1-2|1-1|legacy")]
    pub ids: Option<String>,
    /// Over SWD (`--probe`): the revision of the board on the probe (1-2, 1-1). Default: its newest.
    #[arg(long, value_name = "1-2|1-1", requires = "probe")]
    pub revision: Option<String>,
    /// Reset the robot through the cable's RTS line instead of asking for the reset button.
    #[arg(long)]
    pub reset_line: bool,
}

/// A board to flash with the images it may take: one per revision built (the serial path picks
/// the robot's) or the one ELF a runner was given.
pub type Job = (&'static Board, Vec<PathBuf>);

/// `cargo xtask flash …`.
pub fn run(root: &Path, args: &FlashArgs) -> Result<()> {
    let selected = select(&args.boards)?;
    match &args.port {
        Some(port) => {
            let stated = args.ids.as_deref().map(ids).transpose()?;
            let choice = match stated {
                // Stated: only that revision's images, and a board without one is refused here,
                // before the port is opened.
                Some(id_set) => Choice::Robot(robot_revision(id_set)),
                // Learnt from the robot: every revision of each board, so the images are ready
                // when the main board has told which one (it leaves flashing mode 30 s after the
                // host falls silent, too soon for a build).
                None => Choice::All,
            };
            let plan = revision::plan(&selected, &choice).with_context(|| {
                format!(
                    "the robot answers to the {} ids (--ids); nothing was erased",
                    args.ids.as_deref().unwrap_or("")
                )
            })?;
            let reports = crate::workspace::build_boards(root, &plan, false)?;
            let jobs: Vec<Job> = selected
                .iter()
                .map(|board| {
                    let elfs = reports
                        .iter()
                        .filter(|r| r.board == board.name)
                        .map(|r| r.elf.clone())
                        .collect();
                    (*board, elfs)
                })
                .collect();
            serial(port, &jobs, &options(args), stated).map(|_| ())
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
            let reports = crate::workspace::build_boards(root, &plan, false)?;
            let report = reports.first().context("one image built")?;
            println!("{} {} image", board.name, report.revision);
            flash_elf(board, &report.elf)
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

/// How the robot's ids became known, for messages.
#[derive(Debug, Clone)]
pub enum Source {
    /// Stated with `--ids` (or `AMIRO_IDS`).
    Stated(String),
    /// Read from the main board's bootloader: its board and id.
    MainBoard(MainBoardId),
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::Stated(text) => write!(f, "stated with --ids {text}"),
            Source::MainBoard(m) => write!(
                f,
                "its main board's bootloader is {} with device id {:#010x}",
                m.board, m.id
            ),
        }
    }
}

/// Of `elfs`, the image for the board whose bootloader has `target`'s id. Refuses, naming the
/// board, its id and revision and each image's revision, when the board's revision has no
/// image or every image given is of another revision: the id names the revision
/// (`boards::Revision::device_ids`), the ELF declares its own (`AMIRO_DEVICE_ID`; an image
/// without it is the board's only revision).
pub fn choose_image(
    board: &Board,
    target: &Target,
    elfs: &[PathBuf],
    source: &Source,
) -> Result<PathBuf> {
    let robot = robot_revision_of(target);
    let Some(wanted) = board.revision_of_id(target.device_id) else {
        bail!(
            "{}: this is a revision-{robot} robot ({source}), so its {} has device id {:#010x}, \
             a revision this firmware has no image for (its revisions: {}); nothing was erased",
            board.name,
            board.name,
            target.device_id,
            revision::names(board)
        );
    };
    let mut others = Vec::new();
    for elf in elfs {
        let image = revision::of_elf(board, elf)?;
        if image == wanted {
            return Ok(elf.clone());
        }
        others.push(format!(
            "{} is the {} {} image",
            elf.display(),
            board.name,
            image.name
        ));
    }
    bail!(
        "{}: {}, but this is a revision-{robot} robot ({source}), so its {} has device id {:#010x} \
         ({} {}); nothing was erased (build that revision: cargo xtask build {} --revision {})",
        board.name,
        if others.is_empty() { "no image".to_string() } else { others.join("; ") },
        board.name,
        target.device_id,
        board.name,
        wanted.name,
        board.name,
        wanted.robot()
    )
}

/// The robot revision a target's id belongs to (for messages).
fn robot_revision_of(target: &Target) -> &'static str {
    [IdSet::Rev12, IdSet::Rev11, IdSet::Legacy]
        .into_iter()
        .find(|set| robot(*set).iter().any(|t| t.device_id == target.device_id))
        .map_or("?", robot_revision)
}

/// The boards' `cargo run --release` runner: serial when `AMIRO_PORT` names a port, else SWD.
pub fn run_elf(board: &'static Board, elf: &Path) -> Result<()> {
    match std::env::var(PORT_ENV) {
        Ok(port) if !port.is_empty() => {
            let opts = Options {
                reset_line: std::env::var("AMIRO_RESET_LINE").is_ok_and(|v| v == "1"),
                ..Options::default()
            };
            let stated = match std::env::var("AMIRO_IDS") {
                Ok(text) if !text.is_empty() => Some(ids(&text)?),
                _ => None,
            };
            let image = revision::of_elf(board, elf)?;
            println!("{} {} image", board.name, image.name);
            serial(&port, &[(board, vec![elf.to_path_buf()])], &opts, stated).map(|_| ())
        }
        _ => {
            let image = revision::of_elf(board, elf)?;
            println!("{} {} image", board.name, image.name);
            flash_elf(board, elf)
        }
    }
}

/// The robot's ids: the main board's revision as read from its bootloader, checked against
/// `stated`; a stated set where the bootloader's id could not be read; else a refusal.
fn robot_ids(seen: &Identification, stated: Option<IdSet>) -> Result<(IdSet, Source)> {
    match (seen.main_board(), stated) {
        (Some(main), None) => {
            println!(
                "main board: {} with device id {:#010x}: a revision-{} robot",
                main.board,
                main.id,
                robot_revision(main.robot)
            );
            Ok((main.robot, Source::MainBoard(main)))
        }
        (Some(main), Some(id_set)) => {
            ensure!(
                robot_revision(id_set) == robot_revision(main.robot),
                "--ids {} names a revision-{} robot, but the main board's bootloader is {} with \
                 device id {:#010x} (revision {}); nothing was erased (drop --ids, or pass --ids {})",
                id_set_name(id_set),
                robot_revision(id_set),
                main.board,
                main.id,
                robot_revision(main.robot),
                robot_revision(main.robot)
            );
            println!(
                "main board: {} with device id {:#010x}, as --ids {} states",
                main.board,
                main.id,
                id_set_name(id_set)
            );
            Ok((id_set, Source::MainBoard(main)))
        }
        (None, Some(id_set)) => {
            println!(
                "main board: its bootloader holds {}; trusting --ids {}",
                seen.describe(),
                id_set_name(id_set)
            );
            Ok((id_set, Source::Stated(id_set_name(id_set).into())))
        }
        (None, None) => bail!(
            "cannot tell the robot's revision: the main board's bootloader holds {} (one of \
             DiWheelDrive 0x01000101/0x01000102 or PowerManagement 0x01010101/0x01010102 was \
             expected); nothing was erased. State it: --ids 1-2 or --ids 1-1",
            seen.describe()
        ),
    }
}

fn id_set_name(ids: IdSet) -> &'static str {
    match ids {
        IdSet::Rev12 => "1-2",
        IdSet::Rev11 => "1-1",
        IdSet::Legacy => "legacy",
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

/// Flashes `jobs` through AMiRo-BLT on `port`, restarts the robot and prints a summary. The
/// robot's ids are read from the main board's bootloader (or `stated`; both, and they must
/// agree); each board then gets the image of its revision, every board answers to its id before
/// any is erased. Fails unless every board was flashed and verified.
pub fn serial(port: &str, jobs: &[Job], opts: &Options, stated: Option<IdSet>) -> Result<usize> {
    // Every image's layout, and with stated ids every board's revision, before the port opens.
    let mut images = Vec::new();
    for (board, elfs) in jobs {
        for elf in elfs {
            images.push((elf.clone(), image_of(board, elf)?));
        }
        if let Some(id_set) = stated {
            let source = Source::Stated(id_set_name(id_set).into());
            choose_image(board, &target_of(board, id_set)?, elfs, &source)?;
        }
    }
    let link = SerialLink::open(port)?;
    let mut flasher = Flasher::new(link, opts.clone());
    let mut show = Progress::default();
    println!("waiting for the main board's bootloader on {port} …");
    flasher.enter_flash_mode(&mut show)?;
    println!("reading the main board's bootloader for its device id …");
    let seen = flasher.identify_main_board()?;
    let (id_set, source) = robot_ids(&seen, stated)?;
    // Which image each board takes: every refusal before any board is connected to.
    let mut plan = Vec::new();
    for (board, elfs) in jobs {
        let target = target_of(board, id_set)?;
        let elf = choose_image(board, &target, elfs, &source)?;
        let image = images
            .iter()
            .find(|(e, _)| *e == elf)
            .map(|(_, i)| i.clone())
            .context("checked image")?;
        println!(
            "{:<13} device id {:#010x} (revision {}): {}",
            board.name,
            target.device_id,
            board
                .revision_of_id(target.device_id)
                .map_or("?", |r| r.name),
            elf.display()
        );
        plan.push((*board, target, image));
    }
    // Every board answers to its id (and is the chip its image is for) before any is erased.
    for (board, target, _) in &plan {
        flasher
            .greet(target)
            .with_context(|| format!("{}: nothing was erased", board.name))?;
        println!("{:<13} answers to {:#010x}", board.name, target.device_id);
    }
    let jobs = plan;
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
/// behind DiWheelDrive's bootloader, then behind PowerManagement's, whose code holds its id only
/// in compares), the robot's revision read from its main board's bootloader as on a real robot:
/// each robot gets its revision's images, each board's simulated flash is compared with its ELF
/// as the probe path would write it (`elf::write_checksum`), byte for byte, and the robot
/// started. Then the refusals, each with nothing erased on any board and the robot not hung: a
/// board without an image for the robot's revision, an image of the other revision (both ways,
/// and with PowerManagement on the cable), `--ids` naming the other revision, and a bootloader
/// whose id cannot be read. `reports`: the images `cargo xtask build --revision all` built.
pub fn simulated_robot(root: &Path, reports: &[crate::elf::SizeReport]) -> Result<()> {
    use amiro_blt_sim::{BoardSpec, IdInCode};
    let elf = |board: &str, revision: &str| -> Result<PathBuf> {
        reports
            .iter()
            .find(|r| r.board == board && r.revision == revision)
            .map(|r| r.elf.clone())
            .with_context(|| format!("no {board} {revision} image was built"))
    };
    let by = |name: &str| boards::by_name(name).context("board");
    let dwd = by("diwheeldrive")?;
    let pm = by("powermgmt")?;
    let lr = by("lightring")?;
    // Every image built, as `cargo xtask flash … --port` offers them without --ids.
    let all_of = |board: &Board| -> Vec<PathBuf> {
        reports
            .iter()
            .filter(|r| r.board == board.name)
            .map(|r| r.elf.clone())
            .collect()
    };
    let (dwd_all, pm_all, lr_all) = (all_of(dwd), all_of(pm), all_of(lr));
    let revision_on = |board: &Board, robot: &str| board.revision_for(robot).map(|r| r.name);
    // A 1-2 robot: DiWheelDrive 1-2, PowerManagement 1-2, and LightRing once it has a 1-2 image.
    let mut jobs = vec![(dwd, dwd_all.clone()), (pm, pm_all.clone())];
    let mut expected = vec![("diwheeldrive", "1-2"), ("powermgmt", "1-2")];
    if let Some(name) = revision_on(lr, "1-2") {
        jobs.push((lr, lr_all.clone()));
        expected.push(("lightring", name));
    }
    flash_simulated(root, BoardSpec::robot_1_2(), None, &jobs, &expected)?;
    // A 1-1 robot: every board.
    flash_simulated(
        root,
        BoardSpec::robot_1_1(),
        None,
        &[
            (dwd, dwd_all.clone()),
            (pm, pm_all.clone()),
            (lr, lr_all.clone()),
        ],
        &[
            ("diwheeldrive", "1-1"),
            ("powermgmt", "1-1"),
            (
                "lightring",
                revision_on(lr, "1-1").context("lightring on a 1-1 robot")?,
            ),
        ],
    )?;
    // Both robots with PowerManagement on the cable: its bootloaders hold the id only in
    // compares (CMP.W #0x01010101, CMN.W #0xFEFEFEFE), as GCC builds them.
    for (robot, revision) in [
        (BoardSpec::robot_1_1(), "1-1"),
        (BoardSpec::robot_1_2(), "1-2"),
    ] {
        flash_simulated(
            root,
            BoardSpec::with_main(robot, "powermgmt").context("powermgmt in the robot")?,
            None,
            &[(pm, pm_all.clone()), (dwd, dwd_all.clone())],
            &[("powermgmt", revision), ("diwheeldrive", revision)],
        )?;
    }
    // The same with the ids stated, as they agree with the bootloader's.
    flash_simulated(
        root,
        BoardSpec::robot_1_1(),
        Some(IdSet::Rev11),
        &[(dwd, vec![elf("diwheeldrive", "1-1")?])],
        &[("diwheeldrive", "1-1")],
    )?;
    // Refusals, before anything is erased.
    let mut unreadable = BoardSpec::robot_1_2();
    unreadable[0].id_in_code = IdInCode::Absent;
    // What is refused: the robot, the ids stated, the jobs, and what the refusal must say.
    type Refusal<'a> = (&'a str, Vec<BoardSpec>, Option<IdSet>, Vec<Job>, &'a str);
    let mut refused: Vec<Refusal<'_>> = vec![(
            "the runner's 1-1 DiWheelDrive image on a 1-2 robot",
            BoardSpec::robot_1_2(),
            None,
            vec![(dwd, vec![elf("diwheeldrive", "1-1")?])],
            "is the diwheeldrive 1-1 image, but this is a revision-1-2 robot (its main board's \
             bootloader is diwheeldrive with device id 0x01000102), so its diwheeldrive has \
             device id 0x01000102 (diwheeldrive 1-2)",
        ),
        (
            "the runner's 1-2 DiWheelDrive image on a 1-1 robot",
            BoardSpec::robot_1_1(),
            None,
            vec![(dwd, vec![elf("diwheeldrive", "1-2")?])],
            "is the diwheeldrive 1-2 image, but this is a revision-1-1 robot (its main board's \
             bootloader is diwheeldrive with device id 0x01000101), so its diwheeldrive has \
             device id 0x01000101 (diwheeldrive 1-1)",
        ),
        (
            "the 1-0 LightRing image on a 1-2 robot",
            BoardSpec::robot_1_2(),
            None,
            vec![(lr, vec![elf("lightring", "1-0")?])],
            "is the lightring 1-0 image, but this is a revision-1-2 robot (its main board's \
             bootloader is diwheeldrive with device id 0x01000102), so its lightring has \
             device id 0x017f0102 (lightring 1-2)",
        ),
        (
            "the 1-2 LightRing image on a 1-1 robot",
            BoardSpec::robot_1_1(),
            None,
            vec![(lr, vec![elf("lightring", "1-2")?])],
            "is the lightring 1-2 image, but this is a revision-1-1 robot (its main board's \
             bootloader is diwheeldrive with device id 0x01000101), so its lightring has \
             device id 0x017f0100 (lightring 1-0)",
        ),
        (
            "the runner's 1-1 DiWheelDrive image on a 1-2 robot, PowerManagement on the cable",
            BoardSpec::with_main(BoardSpec::robot_1_2(), "powermgmt")
                .context("powermgmt in the robot")?,
            None,
            vec![(dwd, vec![elf("diwheeldrive", "1-1")?])],
            "is the diwheeldrive 1-1 image, but this is a revision-1-2 robot (its main board's \
             bootloader is powermgmt with device id 0x01010102), so its diwheeldrive has \
             device id 0x01000102 (diwheeldrive 1-2)",
        ),
        (
            "the 1-1 PowerManagement image on a 1-2 robot",
            BoardSpec::robot_1_2(),
            None,
            vec![(pm, vec![elf("powermgmt", "1-1")?])],
            "is the powermgmt 1-1 image, but this is a revision-1-2 robot (its main board's \
             bootloader is diwheeldrive with device id 0x01000102), so its powermgmt has \
             device id 0x01010102 (powermgmt 1-2)",
        ),
        (
            "the 1-2 PowerManagement image on a 1-1 robot, PowerManagement on the cable",
            BoardSpec::with_main(BoardSpec::robot_1_1(), "powermgmt")
                .context("powermgmt in the robot")?,
            None,
            vec![(pm, vec![elf("powermgmt", "1-2")?])],
            "is the powermgmt 1-2 image, but this is a revision-1-1 robot (its main board's \
             bootloader is powermgmt with device id 0x01010101), so its powermgmt has \
             device id 0x01010101 (powermgmt 1-1)",
        ),
        (
            "--ids 1-1 on a 1-2 robot",
            BoardSpec::robot_1_2(),
            Some(IdSet::Rev11),
            vec![(dwd, vec![elf("diwheeldrive", "1-1")?])],
            "--ids 1-1 names a revision-1-1 robot, but the main board's bootloader is diwheeldrive \
             with device id 0x01000102 (revision 1-2)",
        ),
        (
            "a main board whose bootloader's id cannot be read",
            unreadable,
            None,
            vec![(dwd, dwd_all.clone())],
            "cannot tell the robot's revision: the main board's bootloader holds none of the known \
             main-board ids",
        ),
    ];
    // A board whose revision has no image: LightRing on a 1-2 robot, while it has none.
    if revision_on(lr, "1-2").is_none() {
        refused.push((
            "flash all on a 1-2 robot (no LightRing 1-2 image)",
            BoardSpec::robot_1_2(),
            None,
            vec![(dwd, dwd_all.clone()), (pm, pm_all.clone()), (lr, lr_all)],
            "so its lightring has device id 0x017f0102, a revision this firmware has no image for",
        ));
    }
    for (what, spec, stated, jobs, message) in refused {
        let error = match flash_simulated(root, spec, stated, &jobs, &[]) {
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

/// Flashes `jobs` into a simulated robot of `spec` through a pty, its ids read from the main
/// board's bootloader (and `stated`), and checks that each board got the image of `expected`
/// revision, byte for byte. On a refusal the robot must be neither erased nor hung.
fn flash_simulated(
    root: &Path,
    spec: Vec<amiro_blt_sim::BoardSpec>,
    stated: Option<IdSet>,
    jobs: &[Job],
    expected: &[(&str, &str)],
) -> Result<()> {
    use amiro_blt_sim::{pty::PtyRobot, Faults, Mode, Robot, Timing};
    let started = Instant::now();
    let ids: Vec<(String, u32)> = spec.iter().map(|b| (b.name.clone(), b.device_id)).collect();
    let sim = Robot::new(spec, Timing::instant(), Faults::default());
    let served = PtyRobot::serve(sim).context("starting the simulated robot on a pty")?;
    let port = served.path().to_string_lossy().into_owned();
    let opts = Options {
        window_patience: Duration::from_secs(10),
        ..Options::default()
    };
    let flashed = serial(&port, jobs, &opts, stated);
    let robot = served.stop();
    let bytes = match flashed {
        Ok(bytes) => bytes,
        Err(e) => {
            // Refused or failed: a refusal must not have erased anything, nor hung the robot.
            for (name, id) in &ids {
                let flash = robot.flash(*id);
                let origin = flash.chip().app_origin();
                let end = amiro_blt_sim::flash::FLASH_BASE + flash.chip().flash_size();
                ensure!(
                    flash.erases == 0 && flash.bytes(origin, end).iter().all(|b| *b == 0xFF),
                    "{name}: refused, but it was erased or written: {e:#}"
                );
            }
            ensure!(
                !matches!(robot.mode(), Mode::Hung(_)),
                "the refusal hung the main board: {:#?}",
                robot.log
            );
            return Err(e);
        }
    };
    for ((board, elfs), (name, revision)) in jobs.iter().zip(expected) {
        ensure!(board.name == *name, "expected boards in the jobs' order");
        let elf = elfs
            .iter()
            .find(|e| revision::of_elf(board, e).is_ok_and(|r| r.name == *revision))
            .with_context(|| format!("no {name} {revision} image"))?;
        let id = ids
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, id)| *id)
            .context("board in the robot")?;
        let patched = crate::workspace::target_dir(root).join(format!("{name}.sim-check.elf"));
        crate::elf::write_checksum(elf, &patched)?;
        let image = Image::from_elf(&std::fs::read(&patched)?)?;
        let flash = robot.flash(id);
        for segment in image.segments() {
            let got = flash.read(segment.address, segment.data.len());
            if let Some(i) = (0..got.len()).find(|&i| got[i] != segment.data[i]) {
                bail!(
                    "{name}: simulated flash differs from its {revision} image at {:#010x}",
                    segment.address + i as u32
                );
            }
        }
        if !flash.app_valid() || !robot.app_started(id) {
            bail!("{name}: the simulated bootloader did not start the application");
        }
    }
    println!(
        "flash through a simulated robot ({}): {} ({bytes} bytes) byte-for-byte equal to their ELFs, started ({:.1} s)",
        ids.iter()
            .map(|(n, id)| format!("{n} {id:#010x}"))
            .collect::<Vec<_>>()
            .join(", "),
        expected
            .iter()
            .map(|(b, r)| format!("{b} {r}"))
            .collect::<Vec<_>>()
            .join(", "),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Flashes `elf` through the probe (probe-rs as a library, the checksum word written), restarts
/// the board and prints its RTT log until Ctrl-C.
pub fn flash_elf(board: &Board, elf: &Path) -> Result<()> {
    let image = crate::probe::probe_image(board, elf)?;
    println!("flashing {} ({}) through the probe", board.name, board.chip);
    let mut session = crate::probe::session(board, None, true)?;
    crate::probe::flash(&mut session, &image)?;
    println!("flashed and restarted; the RTT log follows (Ctrl-C ends)");
    let bytes = std::fs::read(&image).ok();
    let mut link = crate::probe::RttLink::attach(session, bytes.as_deref())?;
    let interrupted = crate::bench::live::interrupt_flag()?;
    // The log only: the trace channel's bytes are decoded but nothing is shown or saved.
    let mut pipeline = crate::bench::live::Pipeline::new(1, None)?;
    let stop = crate::bench::live::Stop {
        after: None,
        idle: None,
        refresh: std::time::Duration::from_secs(3600),
    };
    crate::bench::live::run(
        &mut link,
        &mut pipeline,
        stop,
        &interrupted,
        |lines| lines.iter().for_each(|l| println!("{l}")),
        |_, _| Ok(()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_blt::identify::MAIN_BOARD_IDS;

    fn seen(found: &[MainBoardId]) -> Identification {
        Identification {
            found: found.to_vec(),
        }
    }

    #[test]
    fn the_main_boards_id_names_the_robot_and_a_stated_set_must_agree() {
        let dwd_1_2 = MAIN_BOARD_IDS[1];
        let (ids, _) = robot_ids(&seen(&[dwd_1_2]), None).unwrap();
        assert_eq!(ids, IdSet::Rev12);
        let e = robot_ids(&seen(&[dwd_1_2]), Some(IdSet::Rev11)).unwrap_err();
        assert!(e.to_string().contains(
            "--ids 1-1 names a revision-1-1 robot, but the main board's bootloader is \
             diwheeldrive with device id 0x01000102 (revision 1-2); nothing was erased"
        ));
        // Legacy ids are the 1-1 robot's.
        let (ids, _) = robot_ids(&seen(&[MAIN_BOARD_IDS[0]]), Some(IdSet::Legacy)).unwrap();
        assert_eq!(ids, IdSet::Legacy);
    }

    #[test]
    fn powermanagement_on_the_cable_names_the_robot_through_the_serial_port() {
        use amiro_blt_sim::{pty::PtyRobot, BoardSpec, Faults, Robot, Timing};
        // Its simulated bootloaders hold the id only as CMP.W/CMN.W with a modified immediate.
        // No images: identify, check --ids against it, restart. `refusal`: what a refusal names.
        for (robot, stated, refusal) in [
            (BoardSpec::robot_1_2(), None, None),
            (BoardSpec::robot_1_1(), Some(IdSet::Rev11), None),
            (
                BoardSpec::robot_1_1(),
                Some(IdSet::Rev12),
                Some("bootloader is powermgmt with device id 0x01010101 (revision 1-1)"),
            ),
            (
                BoardSpec::robot_1_2(),
                Some(IdSet::Rev11),
                Some("bootloader is powermgmt with device id 0x01010102 (revision 1-2)"),
            ),
        ] {
            let spec = BoardSpec::with_main(robot, "powermgmt").unwrap();
            let ids: Vec<u32> = spec.iter().map(|b| b.device_id).collect();
            let sim = Robot::new(spec, Timing::instant(), Faults::default());
            let served = PtyRobot::serve(sim).unwrap();
            let port = served.path().to_string_lossy().into_owned();
            let opts = Options {
                window_patience: Duration::from_secs(10),
                ..Options::default()
            };
            let result = serial(&port, &[], &opts, stated);
            let robot = served.stop();
            match (result, refusal) {
                (Ok(bytes), None) => assert_eq!(bytes, 0),
                (Err(e), Some(refusal)) => {
                    let e = format!("{e:#}");
                    assert!(
                        e.contains(refusal) && e.contains("nothing was erased"),
                        "{e}"
                    );
                }
                (result, _) => panic!("{stated:?}: {result:?}, expected {refusal:?}"),
            }
            for id in ids {
                assert_eq!(robot.flash(id).erases, 0);
            }
        }
    }

    #[test]
    fn an_unreadable_id_is_refused_unless_stated() {
        let e = robot_ids(&seen(&[]), None).unwrap_err();
        assert!(e.to_string().contains("cannot tell the robot's revision"));
        assert!(e.to_string().contains("nothing was erased"));
        let both = seen(&MAIN_BOARD_IDS[..2]);
        assert!(robot_ids(&both, None).is_err());
        let (ids, _) = robot_ids(&seen(&[]), Some(IdSet::Rev12)).unwrap();
        assert_eq!(ids, IdSet::Rev12);
    }
}
