//! The `cargo xtask robot` command: builds the three QEMU builds, runs them on one bus, prints
//! the run as it goes and says where the bus log is and how fast it ran.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use super::{stimulus, Firmware};

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
}

/// The robot revision `cargo xtask robot` emulates.
pub const ROBOT_REVISION: &str = "1-1";

/// Builds the boards' QEMU builds (one cargo invocation each) in node order.
pub fn firmware(root: &Path) -> Result<[Firmware; 3]> {
    let mut out = Vec::new();
    for name in stimulus::BOARDS {
        let board = crate::boards::by_name(name).with_context(|| format!("no board {name}"))?;
        // The robot runs revision 1-1 (DiWheelDrive 1-1 with its L3G4200D, LIS331DLH and HMC5883L; the
        // robot scenarios' thesis demo is not schedulable on DiWheelDrive 1-2's BNO055, docs/analysis.md).
        let build =
            crate::revision::plan(&[board], &crate::revision::Choice::Robot(ROBOT_REVISION))?
                .into_iter()
                .next()
                .with_context(|| format!("no revision-{ROBOT_REVISION} image of {name}"))?;
        out.push(Firmware {
            elf: crate::build_qemu(root, &build)?,
            machine: board.qemu_machine,
        });
    }
    out.try_into()
        .map_err(|_| anyhow::anyhow!("three boards expected"))
}

struct Print;

impl super::Sink for Print {
    fn line(&mut self, line: &str) {
        println!("{line}");
    }
}

/// Runs `cargo xtask robot`.
pub fn command(root: &Path, args: &RobotArgs) -> Result<bool> {
    crate::ensure_qemu()?;
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
    let firmware = firmware(root)?;
    let work = crate::qemu::fresh_work_dir(root, "robot");
    let mut live = if args.slcan {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGINT, stop.clone())?;
        let slcan = super::slcan::Slcan::new()?;
        println!("slcan: {}", slcan.path());
        std::io::Write::flush(&mut std::io::stdout())?;
        Some(super::Live { slcan, stop })
    } else {
        None
    };
    let started = Instant::now();
    let outcome = super::run(
        &firmware,
        &actions,
        duration,
        &work,
        &mut Print,
        live.as_mut(),
    )?;
    let duration = outcome.ended_at;
    let wall = started.elapsed().as_secs_f64();
    std::fs::write(work.join("output.log"), &outcome.text)?;
    let (bus, _) = crate::qemu::split_output(&outcome.text);
    std::fs::write(work.join("bus.log"), bus)?;
    let report = super::report::analyse(&outcome.transfers, duration);
    let table = super::report::render(&report);
    print!("{table}");
    std::fs::write(work.join("bus-report.txt"), &table)?;
    let exceeded = report.iter().filter(|l| l.exceeds()).count();
    let virtual_s = duration as f64 / 1e6;
    eprintln!(
        "robot: {virtual_s:.3} s of virtual time in {wall:.1} s of wall time ({:.2} s wall per virtual s)",
        wall / virtual_s.max(1e-9)
    );
    eprintln!(
        "robot: {} exchanges for {} quanta of {} µs (the rest skipped: no board could act)",
        outcome.exchanges,
        duration / super::QUANTUM_US,
        super::QUANTUM_US
    );
    eprintln!("bus log (candump -l): {}", work.join("bus.log").display());
    if exceeded > 0 {
        eprintln!("bus report: {exceeded} message(s) beyond their Davis bound");
    }
    Ok(!(args.check && exceeded > 0))
}
