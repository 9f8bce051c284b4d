//! The `cargo xtask robot` command: builds the three QEMU builds, runs them on one bus, prints
//! the run as it goes and says where the bus log is and how fast it ran.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use amiro_robot::stimulus;
use amiro_robot::world::WorldRun;
use amiro_world::feed::ImuRevision;

/// `cargo xtask robot` options.
#[derive(clap::Args, Debug)]
pub struct RobotArgs {
    /// A stimulus: `candump -l` frames the operator's adapter sends, plus `(t) signal SYS_PD_N`,
    /// `(t) signal SYS_WARMRST_N` (restarts LightRing),
    /// `(t) reset BOARD`, `(t) unplug BOARD`, `(t) plug BOARD`, `(t) bit-error ID|any`,
    /// `(t) babble BOARD ID#DATA`, `(t) babble BOARD off`.
    #[arg(long)]
    pub stimulus: Option<PathBuf>,
    /// How much virtual time to run (e.g. 10s, 500ms); default: the stimulus's `# duration:`, or 2s.
    #[arg(long)]
    pub duration: Option<String>,
    /// Paced to the wall clock, with a pseudo-terminal that speaks SLCAN as the operator's adapter
    /// (printed as `slcan: /dev/pts/N`); runs until Ctrl-C or `--duration`.
    #[arg(long)]
    pub slcan: bool,
    /// Fail when a message's observed worst response exceeds its Davis bound (the bus report).
    #[arg(long)]
    pub check: bool,
    /// Live (`--slcan`): print the boards' trace and log lines and the frames on stdout too (off by
    /// default: printing them costs pace; they are in the run's output.log either way, its newest
    /// lines: see `--output-log-max`).
    #[arg(long)]
    pub trace: bool,
    /// Live (`--slcan`): no warm-up. By default the boards first run every sensor topic's
    /// request, sample and stop, the LEDs, the motor and the thesis load in virtual time and
    /// restart in their QEMUs, so that the code a client's commands run is translated before the
    /// wall clock starts (about 0.16 s of virtual time; the port is printed after it).
    #[arg(long, requires = "slcan")]
    pub no_warm_up: bool,
    /// Live (`--slcan`): rotate the run's output.log at SIZE (e.g. 64MiB, 1GiB; at least 1MiB):
    /// the newest lines in output.log, the ones before them in output.log.1, the two at most twice
    /// SIZE. Default 64MiB (the run prints about 530 KB a second with the thesis load).
    #[arg(long, value_name = "SIZE", requires = "slcan")]
    pub output_log_max: Option<String>,
    /// Live (`--slcan`): rotate the bus log the same way at SIZE (bus.log and bus.log.1). Default:
    /// kept whole, the recording candump -l would make (its growth is said at the start).
    #[arg(long, value_name = "SIZE", requires = "slcan")]
    pub bus_log_max: Option<String>,
    /// Put the robot in a world (JSON: walls, obstacles, floor, the robot's start; docs/world.md):
    /// the DiWheelDrive's wheels move it, the ring, floor and IMU read it. Ends with the line
    /// `world: travelled X m, contacts N, pose X Y HEADING`; the arena's SVG with the path goes
    /// beside the bus log.
    #[arg(long, value_name = "FILE", conflicts_with = "bench")]
    pub world: Option<PathBuf>,
    /// With `--world`: the noise seed (default: the world file's).
    #[arg(long, requires = "world")]
    pub seed: Option<u64>,
    /// With `--world`: write the trajectory (`t_s,x_m,y_m,heading_deg`, a row every 10 ms).
    #[arg(long, value_name = "OUT.csv", requires = "world")]
    pub trajectory: Option<PathBuf>,
    /// An operator-side behaviour in lock-step (the controller protocol, docs/world.md): every
    /// bus frame to its stdin as a `candump -l` line, `(T) tick` every `--controller-period`,
    /// its `ID#DATA` lines until `ok` sent on the bus at T. A command line, e.g.
    /// "python3 examples/obstacle_avoidance.py". Without `--world` the sensors read their
    /// simulators as in any run.
    #[arg(long, value_name = "PROGRAM", conflicts_with = "bench")]
    pub controller: Option<String>,
    /// The controller's tick period (a multiple of 40 µs).
    #[arg(long, default_value = "10ms", requires = "controller")]
    pub controller_period: String,
    /// Measure instead: an idle robot, the thesis demo and a babbling board, each for
    /// `--duration` (default 2s) of virtual time; prints exchanges per virtual second, wall
    /// seconds per virtual second and where the wall time goes.
    #[arg(long, conflicts_with_all = ["slcan", "stimulus", "check"])]
    pub bench: bool,
}

/// Prints a run's lines as they come; a live run without `--trace` only the bus's and the platforms' notes.
/// A run in virtual time writes them in blocks: a write per line (stdout's line buffering) was a
/// system call per frame on the host, the most of its kernel time and on the boards' critical path
/// (the thesis demo prints about 2 000 lines per virtual second). A live run writes each at once.
struct Print {
    all: bool,
    live: bool,
    out: std::io::BufWriter<std::io::Stdout>,
}

impl Print {
    fn new(all: bool, live: bool) -> Self {
        Self {
            all,
            live,
            out: std::io::BufWriter::with_capacity(1 << 16, std::io::stdout()),
        }
    }
}

impl amiro_robot::Sink for Print {
    fn line(&mut self, line: &str) {
        use std::io::Write;
        // A live run without `--trace` still says what the bus and the platforms say (`bus:` notes,
        // each board's `# qemu:` lines: its start, its end line with its receive losses).
        if self.all || line.starts_with("bus:") || line.contains(": # qemu:") {
            // A closed stdout (its reader gone) stops the printing, not the run: the lines are in
            // its output.log.
            let _ = writeln!(self.out, "{line}");
            if self.live {
                let _ = self.out.flush();
            }
        }
    }
}

/// The run's files wrapped so that a file's first rotation is said on stderr as it happens.
struct RotationNotes(amiro_robot::log::RunFiles);

impl amiro_robot::Sink for RotationNotes {
    fn line(&mut self, line: &str) {
        self.0.line(line);
        for note in self.0.take_rotation_notes() {
            eprintln!("robot: live: {note}");
        }
    }
}

/// How fast a bus log can grow at most: a saturated 1 Mbit/s bus of the shortest frames (an 11-bit
/// identifier, no data: 44 bits and 3 of interframe space, some 21 000 a second), each a `candump -l`
/// line of about 25 bytes.
const BUS_LOG_MOST: &str = "about 0.5 MB a second (1.9 GB an hour)";

/// The smallest rotation size the command takes: below it a file holds only seconds of the run.
const LEAST_ROTATION: u64 = 1 << 20;

/// A live run's files rotate at their sizes (`output.log` by default); a run in virtual time keeps
/// them whole (its duration bounds them, and the scenarios and tests read them whole).
fn log_bounds(args: &RobotArgs) -> Result<amiro_robot::log::LogBounds> {
    use amiro_robot::log::{parse_size, LogBounds, LIVE_OUTPUT_LOG_MAX};
    if !args.slcan {
        return Ok(LogBounds::default());
    }
    let size = |flag: &str, text: &str| -> Result<u64> {
        let size = parse_size(text).with_context(|| format!("--{flag}"))?;
        anyhow::ensure!(
            size >= LEAST_ROTATION,
            "--{flag} {text}: at least 1MiB (a file would hold only seconds of the run)"
        );
        Ok(size)
    };
    Ok(LogBounds {
        output: Some(match &args.output_log_max {
            Some(text) => size("output-log-max", text)?,
            None => LIVE_OUTPUT_LOG_MAX,
        }),
        bus: args
            .bus_log_max
            .as_deref()
            .map(|text| size("bus-log-max", text))
            .transpose()?,
    })
}

/// Runs `cargo xtask robot`.
pub fn command(root: &Path, args: &RobotArgs) -> Result<bool> {
    crate::workspace::ensure_qemu()?;
    if args.bench {
        return super::bench::command(root, args.duration.as_deref()).map(|()| true);
    }
    let (actions, header) = match &args.stimulus {
        Some(path) => stimulus::read(path)?,
        None => (Vec::new(), None),
    };
    let duration = match &args.duration {
        Some(d) => crate::qemu::parse_duration(d)?,
        // Live, the run lasts until Ctrl-C.
        None if args.slcan => u64::MAX / 2,
        None => header.unwrap_or(2_000_000),
    };
    let firmware = super::firmware::firmware(root)?;
    let work = crate::qemu::fresh_work_dir(root, "robot");
    let mut live = if args.slcan {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGINT, stop.clone())?;
        let slcan = amiro_robot::slcan::Slcan::new()?;
        let path = slcan.path().to_string();
        // Announced once the wall clock runs (after the warm-up and the boards' start): a client
        // that opens the port then is served at once.
        let ready = move || {
            println!("slcan: {path}");
            let _ = std::io::Write::flush(&mut std::io::stdout());
        };
        Some(amiro_robot::Live {
            slcan,
            stop,
            warm_up: !args.no_warm_up,
            ready: Some(Box::new(ready)),
        })
    } else {
        None
    };
    // The robot's DiWheelDrive is revision 1-1 (`super::firmware::ROBOT_REVISION`).
    let mut world = match (&args.world, &args.controller) {
        (Some(path), _) => Some(WorldRun::load(path, args.seed, ImuRevision::Rev1_1)?),
        // A controller alone: the robot link carries its ticks, no world.
        (None, Some(_)) => Some(WorldRun::without_world()),
        (None, None) => None,
    };
    if let (Some(world), Some(program)) = (world.as_mut(), &args.controller) {
        let period = crate::qemu::parse_duration(&args.controller_period)?;
        world.with_controller(program, period)?;
    }
    let started = Instant::now();
    let print = Print::new(!args.slcan || args.trace, args.slcan);
    // The run's output.log and bus.log are written as the lines come (a live run keeps none of
    // them: `Outcome::bounded`); live, flushed at least every 200 ms while it prints.
    std::fs::create_dir_all(&work)?;
    let bounds = log_bounds(args)?;
    let files = RotationNotes(amiro_robot::log::RunFiles::create(
        &work,
        args.slcan.then_some(std::time::Duration::from_millis(200)),
        bounds,
    )?);
    let mut sink = (print, files);
    if args.slcan {
        let kept = match bounds.bus {
            None => format!(
                "kept whole: it grows with the traffic, about 60 KB a second with the thesis load (216 MB an hour), at most {} on a saturated bus; --bus-log-max SIZE keeps the newest instead",
                BUS_LOG_MOST
            ),
            Some(max) => format!(
                "rotated at {} (bus.log.1 the older lines)",
                amiro_robot::log::size_text(max)
            ),
        };
        eprintln!(
            "robot: live: bus log (candump -l), written as it goes, {kept}: {}",
            work.join("bus.log").display()
        );
        if let Some(max) = bounds.output {
            eprintln!(
                "robot: live: output.log (every line, about 530 KB a second with the thesis load) rotated at {} (output.log.1 the older lines; --output-log-max SIZE)",
                amiro_robot::log::size_text(max)
            );
        }
    }
    let outcome = amiro_robot::run_in_world(
        &firmware,
        &actions,
        duration,
        &work,
        &mut sink,
        live.as_mut(),
        world.as_mut(),
    );
    let (mut print, RotationNotes(files)) = sink;
    let _ = std::io::Write::flush(&mut print.out);
    if let Some(world) = world.as_mut() {
        world.finish();
    }
    let outcome = outcome?;
    let rotated = files.rotation_summary();
    // A failed log write is said when it happens; the report below still comes, the error after it.
    let logs = files.finish();
    let duration = outcome.ended_at;
    let wall = started.elapsed().as_secs_f64();
    // A live run kept the report's running figures only; a run in virtual time every frame.
    let report = if outcome.bounded {
        if outcome.traffic.out_of_order() > 0 {
            eprintln!(
                "bus report: {} frame(s) came released before an earlier-folded one of their identifier (more than {} frames late): their bursts are approximate",
                outcome.traffic.out_of_order(),
                amiro_robot::report::WINDOW
            );
        }
        outcome.traffic.report(duration)
    } else {
        amiro_robot::report::analyse(&outcome.transfers, duration)
    };
    let table = amiro_robot::report::render(&report);
    print!("{table}");
    std::fs::write(work.join("bus-report.txt"), &table)?;
    let exceeded = report.iter().filter(|l| l.exceeds()).count();
    let virtual_s = duration as f64 / 1e6;
    eprintln!(
        "robot: {virtual_s:.3} s of virtual time in {wall:.1} s of wall time ({:.2} s wall per virtual s)",
        wall / virtual_s.max(1e-9)
    );
    eprintln!(
        "robot: {} board exchanges ({:?} per board, {} caught up from a wait; {} frames completed by the boards themselves under {} grants of the bus) at {} of {} boundaries of {} µs; {:.1} s waiting for the boards' emulation",
        outcome.work.exchanges,
        outcome.work.per_board,
        outcome.work.catch_ups,
        outcome.work.local_frames,
        outcome.work.grants,
        outcome.work.steps,
        duration / amiro_robot::QUANTUM_US,
        amiro_robot::QUANTUM_US,
        outcome.work.waiting_us as f64 / 1e6
    );
    eprint!(
        "robot: where the CPU went:\n{}",
        amiro_robot::cost::table(&outcome.work, virtual_s)
    );
    if let Some(pace) = outcome.pace {
        eprintln!(
            "robot: live: real-time factor {:.3}, worst lag {:.1} ms, {} time(s) behind by more than {} ms",
            pace.factor,
            pace.worst_lag_us as f64 / 1e3,
            pace.behind_episodes,
            amiro_robot::pace::LAG_LIMIT.as_millis()
        );
        eprintln!("robot: live: {}", pace.io.describe());
    }
    for line in rotated {
        eprintln!("robot: live: {line}");
    }
    eprintln!("bus log (candump -l): {}", work.join("bus.log").display());
    if exceeded > 0 {
        eprintln!("bus report: {exceeded} message(s) beyond their Davis bound");
    }
    if let Some(world) = world.as_ref().filter(|w| w.feeds()) {
        let svg = work.join("world.svg");
        std::fs::write(&svg, world.trajectory().svg(world.world().arena()))?;
        eprintln!("world: arena and path: {}", svg.display());
        if let Some(path) = &args.trajectory {
            let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
            world.trajectory().write_csv(&mut out)?;
            std::io::Write::flush(&mut out)?;
            eprintln!("world: trajectory: {}", path.display());
        }
        eprintln!(
            "world: its hooks took {:.3} s of the {wall:.1} s of wall time ({:.1} %)",
            world.wall.as_secs_f64(),
            100.0 * world.wall.as_secs_f64() / wall.max(1e-9)
        );
        println!("{}", world.summary());
    }
    logs?;
    Ok(!(args.check && exceeded > 0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_robot::log::{LogBounds, LIVE_OUTPUT_LOG_MAX};
    use clap::Parser;

    #[derive(clap::Parser)]
    struct Robot {
        #[command(flatten)]
        args: RobotArgs,
    }

    fn bounds(line: &[&str]) -> Result<LogBounds> {
        let robot = Robot::try_parse_from(std::iter::once("robot").chain(line.iter().copied()))?;
        log_bounds(&robot.args)
    }

    #[test]
    fn a_live_run_rotates_its_output_log_and_a_run_in_virtual_time_keeps_both_whole() {
        assert_eq!(
            bounds(&["--duration", "10s"]).unwrap(),
            LogBounds::default()
        );
        assert_eq!(
            bounds(&["--slcan"]).unwrap(),
            LogBounds {
                output: Some(LIVE_OUTPUT_LOG_MAX),
                bus: None
            }
        );
        assert_eq!(
            bounds(&[
                "--slcan",
                "--output-log-max",
                "1GiB",
                "--bus-log-max",
                "200MB"
            ])
            .unwrap(),
            LogBounds {
                output: Some(1 << 30),
                bus: Some(200_000_000)
            }
        );
        // A size too small to hold more than seconds, a malformed one, or a bound on a run in
        // virtual time (whose files the scenarios read whole) is refused.
        assert!(bounds(&["--slcan", "--bus-log-max", "64KiB"]).is_err());
        assert!(bounds(&["--slcan", "--output-log-max", "64M"]).is_err());
        assert!(bounds(&["--output-log-max", "1GiB"]).is_err());
    }
}
