//! Project automation: `cargo xtask build | check | test | ci | analyze | flash | qemu`.
//!
//! CI calls only `cargo xtask ...`; everything a fresh machine lacks (thumb targets, llvm-tools,
//! QEMU) is installed from here, so the README's two commands are the whole set-up.
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, ensure, Context, Result};
use clap::{Parser, Subcommand};

mod admission_search;
mod analyze;
mod bench;
mod boards;
mod bounds;
mod campaign;
mod elf;
mod flash;
mod interop;
mod layers;
mod levels_check;
mod machine;
mod probe;
mod qemu;
mod revision;
mod robot;
mod scenarios;
mod smoke;
mod wcet;
mod wcet_gate;
mod wcet_qemu;
mod wcet_write;
mod workspace;

use boards::{select_boards, BOARDS};
use workspace::{
    build_boards, build_qemu, build_qemu_with, cargo, ensure_qemu, ensure_toolchain,
    qemu_target_dir, target_dir, workspace_root,
};

#[derive(Parser, Debug)]
#[command(
    name = "cargo xtask",
    about = "Build, check, test and analyse the AMiRo firmware suite"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Build the firmware for the real boards (release) and print the size table.
    Build {
        /// Boards to build (default: all): diwheeldrive, powermgmt, lightring.
        boards: Vec<String>,
        /// Print the size table as JSON instead.
        #[arg(long)]
        json: bool,
        /// Link for a bare chip at 0x08000000 instead of behind the AMiRo-BLT bootloader.
        #[arg(long)]
        bare_chip: bool,
        /// The robot revision to build for: 1-2, 1-1, or all (every revision of every board).
        /// Default: each board's newest.
        #[arg(long, value_name = "1-2|1-1|all")]
        revision: Option<String>,
    },
    /// The firmware runtime's layers, rustfmt check, clippy and rustdoc with warnings denied on the host
    /// crates and each firmware.
    Check,
    /// Host tests, firmware builds and the QEMU scenarios.
    Test,
    /// Everything CI runs: check, test, the analysis gate and the size report.
    Ci,
    /// Run a board's QEMU build against a stimulus log in deterministic virtual time and print
    /// every frame it puts on the bus (candump -l format) and its trace events (`#` lines).
    Qemu {
        /// The board: diwheeldrive, lightring or powermgmt.
        board: String,
        /// A candump -l log of timed command frames, timestamps relative to the start.
        #[arg(long)]
        stimulus: PathBuf,
        /// How much virtual time to run: e.g. 2s, 500ms, 900us.
        #[arg(long, default_value = "2s")]
        duration: String,
        /// The robot revision of the board (1-2, 1-1). Default: the board's newest.
        #[arg(long, value_name = "1-2|1-1")]
        revision: Option<String>,
    },
    /// The CAN tools' interop (part of `test`): cantools, python-can, can-utils, the MCAP reader, Foxglove's client
    /// and the example behaviours against `amiro` (tools/interop/, pinned in tools/requirements-ci.txt). Its bus-log
    /// checks read the QEMU scenarios' logs: run `scenarios` first.
    Interop,
    /// The hostile-bus campaign on every board with a QEMU build (part of `test`): seeded random
    /// and targeted frames, verdicts checked against an independent model of docs/protocol.md.
    Campaign {
        /// First seed (each further run adds one).
        #[arg(long, default_value_t = 12)]
        seed: u64,
        /// Spaced frames per run.
        #[arg(long, default_value_t = 3000)]
        frames: usize,
        /// The release campaign: ten runs of 20 000 frames per board.
        #[arg(long)]
        long: bool,
        /// Boards to run (default: every board with QEMU scenarios).
        boards: Vec<String>,
    },
    /// Run only the QEMU scenarios CI runs (part of `test`), of every board or of the boards named.
    Scenarios {
        /// Boards whose scenarios to run (default: all).
        boards: Vec<String>,
        /// Only the scenarios of this robot revision (1-2, 1-1). Default: every revision's.
        #[arg(long, value_name = "1-2|1-1")]
        revision: Option<String>,
        /// Build the QEMU images with these board features as well (a trial the shipped image
        /// does not enable: `scripted-i2c`); for `robot`, `board/feature` names one board's.
        #[arg(long, value_delimiter = ',')]
        features: Vec<String>,
    },
    /// The whole robot: the three boards' QEMU builds on one simulated CAN bus with the system
    /// lines between them, in lock-step virtual time (docs/qemu.md, "The whole robot").
    Robot(robot::cli::RobotArgs),
    /// Boot the production images (the bytes `cargo xtask flash` writes, behind a stand-in for
    /// AMiRo-BLT) in QEMU and check the boot from their RTT log (part of `test`; docs/faults.md).
    Smoke {
        /// Boards to boot (default: all).
        boards: Vec<String>,
        /// Only the production image of this robot revision (1-2, 1-1). Default: every revision's.
        #[arg(long, value_name = "1-2|1-1")]
        revision: Option<String>,
    },
    /// Decode a capture of a board's trace channel (RTT channel 1, "trace": `amiro-trace` records)
    /// into text lines; damaged stretches are skipped and counted.
    Trace {
        /// The raw bytes of RTT channel 1 as captured from the board.
        file: PathBuf,
    },
    /// The response-time report: worst-case response times of the board tasks and the CAN bus.
    Analyze(analyze::AnalyzeArgs),
    /// Search again for the admission check's costliest step (scenario `admission-search`'s sequence): the seeded
    /// search per revision, its winner against the stored log on today's tables, `--write` to store a costlier one,
    /// and the admission task's recorded worst steps and budgets (docs/qemu.md).
    AdmissionSearch(admission_search::SearchArgs),
    /// Execution-time bounds from the machine code: every task of the boards' built images, or one
    /// function of any ELF, in cycles on its chip (docs/analysis.md, "Execution-time bounds from the
    /// machine code").
    Wcet(wcet::WcetArgs),
    /// Measured timing against the analysis: per task jobs, execution and response times against
    /// the analysed WCRT, per topic jitter and latency to the queue and the bus; from a capture of
    /// the trace channel, a QEMU run, or QEMU outputs (docs/bench.md).
    Bench(bench::BenchArgs),
    /// Several boards' trace captures and a `candump -l` log of the bus on one time base, aligned by
    /// the frames both saw (docs/bench.md).
    Timeline(bench::timeline::TimelineArgs),
    /// Build and flash boards: all of them through DiWheelDrive's serial port and AMiRo-BLT
    /// (`--port /dev/ttyUSB0`), or one through probe-rs over SWD (`--probe`, writes the
    /// AMiRo-BLT checksum word and streams RTT).
    Flash(flash::FlashArgs),
    /// The flashing tests of `test` alone: every revision's images into simulated 1-1 and 1-2 robots
    /// through a pty, and the refusals (docs/flashing.md).
    FlashSim,
    /// Flash an already built ELF (the boards' `cargo run` runner): through AMiRo-BLT when
    /// `AMIRO_PORT` names the serial port, else through probe-rs with the checksum word written
    /// into a copy.
    FlashElf {
        /// The board the ELF is for.
        board: String,
        /// The ELF cargo built.
        elf: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cmd: Cmd) -> Result<bool> {
    let root = workspace_root();
    match cmd {
        Cmd::Build {
            boards,
            json,
            bare_chip,
            revision,
        } => {
            let plan = revision::plan(
                &select_boards(&boards)?,
                &revision::Choice::parse(revision.as_deref())?,
            )?;
            let reports = build_boards(&root, &plan, bare_chip)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&reports)?);
            } else {
                elf::print_table(&reports);
                machine::check_panics(&reports)?;
                machine::check_stacks(&root, &reports)?;
            }
            Ok(true)
        }
        Cmd::Check => check(&root).map(|()| true),
        Cmd::Test => test(&root).map(|()| true),
        Cmd::Ci => {
            let start = std::time::Instant::now();
            timed("checks (layers, rustfmt, clippy, rustdoc)", || check(&root))?;
            timed("the analysis gate", || analysis_gate(&root))?;
            test(&root)?;
            println!("ci: all steps took {:.0} s", start.elapsed().as_secs_f64());
            Ok(true)
        }
        Cmd::Qemu {
            board,
            stimulus,
            duration,
            revision,
        } => {
            let board =
                boards::by_name(&board).with_context(|| format!("unknown board `{board}`"))?;
            let choice = revision::Choice::parse(revision.as_deref())?;
            ensure!(choice != revision::Choice::All, "qemu runs one revision");
            let [build] = revision::plan(&[board], &choice)?[..] else {
                bail!("one image expected");
            };
            ensure_qemu()?;
            let elf = build_qemu(&root, &build)?;
            let frames = qemu::read_stimulus(&stimulus)?;
            let work = qemu::fresh_work_dir(&root, board.name);
            let out = qemu::run(
                &elf,
                board.qemu_machine,
                &frames,
                qemu::parse_duration(&duration)?,
                &work,
            )?;
            print!("{out}");
            // The bus alone, as a plain `candump -l` log other CAN tools read (python-can,
            // can-utils), and the trace lines apart.
            let (bus, trace) = qemu::split_output(&out);
            std::fs::write(work.join("bus.log"), bus)?;
            std::fs::write(work.join("trace.log"), trace)?;
            eprintln!(
                "bus log (candump -l): {}\ntrace: {}",
                work.join("bus.log").display(),
                work.join("trace.log").display()
            );
            Ok(true)
        }
        Cmd::Analyze(args) => {
            let passes = analyze::run(&args, &root)?;
            // An unschedulable set is a verdict, not an error: only `--check` turns it into a failure (a set with
            // expected failures passes when exactly those fail).
            Ok(passes || !args.check)
        }
        Cmd::Interop => interop::check(&root).map(|()| true),
        Cmd::Campaign {
            seed,
            frames,
            long,
            boards,
        } => {
            ensure_qemu()?;
            let (frames, runs) = if long { (20_000, 10) } else { (frames, 1) };
            campaign::run(&root, &select_boards(&boards)?, seed, frames, runs).map(|()| true)
        }
        // `robot` names the whole robot's scenarios (robot/scenarios/, docs/qemu.md).
        Cmd::Scenarios {
            boards,
            revision,
            features,
        } if boards.iter().any(|b| b == "robot") => {
            let extra: Vec<&str> = features.iter().map(String::as_str).collect();
            robot::scenarios::run_all_with(&root, &extra)?;
            let rest: Vec<String> = boards.into_iter().filter(|b| b != "robot").collect();
            if !rest.is_empty() {
                let choice = match revision.as_deref() {
                    None => revision::Choice::All,
                    some => revision::Choice::parse(some)?,
                };
                let plan = revision::plan(&select_boards(&rest)?, &choice)?;
                run_scenarios(&root, &plan, &extra)?;
            }
            Ok(true)
        }
        Cmd::Scenarios {
            boards,
            revision,
            features,
        } => {
            let choice = match revision.as_deref() {
                None => revision::Choice::All,
                some => revision::Choice::parse(some)?,
            };
            let plan = revision::plan(&select_boards(&boards)?, &choice)?;
            let features: Vec<&str> = features.iter().map(String::as_str).collect();
            run_scenarios(&root, &plan, &features).map(|()| true)
        }
        Cmd::Robot(args) => robot::cli::command(&root, &args),
        Cmd::Smoke { boards, revision } => {
            let choice = match revision.as_deref() {
                None => revision::Choice::All,
                some => revision::Choice::parse(some)?,
            };
            let plan = revision::plan(&select_boards(&boards)?, &choice)?;
            smoke::run(&root, &plan, false).map(|()| true)
        }
        Cmd::Trace { file } => {
            let bytes =
                std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
            // The resynchronising reader: a capture may start mid-record or hold garbage.
            let mut reader = amiro_trace::Reader::new();
            for record in bytes.iter().filter_map(|&b| reader.push(b)) {
                match record.kind {
                    amiro_trace::Kind::Event { record: event } => {
                        match amiro_sensors::trace::TraceEvent::decode(&event) {
                            Ok(event) => println!("{event}"),
                            Err(e) => println!("# cycle {}: {e}", record.cycles),
                        }
                    }
                    other => println!("# cycle {}: {other:?}", record.cycles),
                }
            }
            let stats = reader.stats();
            eprintln!(
                "{} records, {} damaged stretches ({} bytes) skipped",
                stats.records, stats.damaged, stats.skipped_bytes
            );
            Ok(stats.damaged == 0)
        }
        Cmd::Wcet(args) => wcet::wcet(&root, &args),
        Cmd::AdmissionSearch(args) => admission_search::run(&root, &args),
        Cmd::Bench(args) => bench::run(&root, &args),
        Cmd::Timeline(args) => bench::timeline::run(&root, &args).map(|()| true),
        Cmd::Flash(args) => flash::run(&root, &args).map(|()| true),
        Cmd::FlashSim => {
            let every = revision::plan(&BOARDS.iter().collect::<Vec<_>>(), &revision::Choice::All)?;
            let reports = build_boards(&root, &every, false)?;
            flash::simulated_robot(&root, &reports).map(|()| true)
        }
        Cmd::FlashElf { board, elf } => {
            let board =
                boards::by_name(&board).with_context(|| format!("unknown board `{board}`"))?;
            flash::run_elf(board, &elf).map(|()| true)
        }
    }
}

fn check(root: &Path) -> Result<()> {
    ensure_toolchain(root)?;
    layers::check(root)?;
    cargo(root, &["fmt", "--all", "--", "--check"])
        .context("rustfmt found unformatted code (run `cargo fmt --all`)")?;
    cargo(
        root,
        &["clippy", "--quiet", "--all-targets", "--", "-D", "warnings"],
    )
    .context("clippy on the host crates")?;
    // The host crates' documentation, its broken and private links refused (the firmware apps
    // are binaries for the chip: their clippy runs below).
    cargo(
        root,
        &[
            "doc",
            "--quiet",
            "--no-deps",
            "--workspace",
            "--exclude",
            "diwheeldrive",
            "--exclude",
            "powermgmt",
            "--exclude",
            "lightring",
            "--config",
            "build.rustdocflags=[\"-D\", \"warnings\"]",
        ],
    )
    .context("rustdoc on the host crates (warnings denied)")?;
    // Every revision of every board, for the chip and (where it has scenarios) for QEMU.
    let every = revision::plan(&BOARDS.iter().collect::<Vec<_>>(), &revision::Choice::All)?;
    let qemu_target = qemu_target_dir(root).to_string_lossy().into_owned();
    for build in &every {
        let board = build.board;
        build.select_models();
        let mut args = vec!["clippy".to_string(), "--quiet".into(), "--release".into()];
        args.extend(build.feature_args(&[]));
        args.extend(["--", "-D", "warnings"].map(String::from));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cargo(&root.join(board.name), &args)
            .with_context(|| format!("clippy on {}", build.stem()))?;
        if scenarios::for_revision(board.name, build.revision.name).is_empty() {
            continue;
        }
        let mut args = vec!["clippy".to_string(), "--quiet".into(), "--release".into()];
        args.extend(build.feature_args(&["qemu", "task-trace"]));
        args.extend(["--target-dir", &qemu_target, "--", "-D", "warnings"].map(String::from));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cargo(&root.join(board.name), &args)
            .with_context(|| format!("clippy on the QEMU build of {}", build.stem()))?;
    }
    // The `scripted-i2c` trials, DiWheelDrive 1-1's and PowerManagement's (docs/i2c.md; not in the
    // shipped images): linted for the chip and QEMU, and built for the chip in a target directory
    // of their own (their QEMU images are built and run by the scenarios).
    for build in revision::scripted_i2c_builds(&every) {
        build.select_models();
        let trial = workspace::trial_target_dir(root);
        let trial = trial.to_string_lossy().into_owned();
        for (command, extra, dir) in [
            ("clippy", &["scripted-i2c"][..], &trial),
            ("build", &["scripted-i2c"][..], &trial),
            (
                "clippy",
                &["qemu", "task-trace", "scripted-i2c"][..],
                &qemu_target,
            ),
        ] {
            let mut args = vec![command.to_string(), "--quiet".into(), "--release".into()];
            args.extend(build.feature_args(extra));
            args.extend(["--target-dir", dir.as_str()].map(String::from));
            if command == "clippy" {
                args.extend(["--", "-D", "warnings"].map(String::from));
            }
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            cargo(&root.join(build.board.name), &args).with_context(|| {
                format!("{command} on {} with {}", build.stem(), extra.join(","))
            })?;
        }
    }
    Ok(())
}

/// Runs one step of `ci`/`test` and prints its wall time (CI's whole run must stay within its
/// budget on a 2-core machine: the figures say which step to cut).
fn timed<T>(what: &str, step: impl FnOnce() -> Result<T>) -> Result<T> {
    let start = std::time::Instant::now();
    let out = step();
    println!(
        "ci: {what}: {:.0} s{}",
        start.elapsed().as_secs_f64(),
        if out.is_err() { " (failed)" } else { "" }
    );
    out
}

fn test(root: &Path) -> Result<()> {
    ensure_toolchain(root)?;
    timed("host tests", || {
        cargo(root, &["test", "--quiet"]).context("host tests")
    })?;
    // The libraries that run on the chips must build for both of them without a HAL: (package, its
    // features, what a failure names).
    let chip_libraries: [(&str, &[&str], &str); 4] = [
        (
            "amiro-can",
            &["--features", "bxcan,embedded-can"],
            "amiro-can",
        ),
        ("amiro-sensors", &[], "amiro-sensors"),
        ("amiro-trace", &[], "amiro-trace"),
        (
            "schedule-analysis",
            &["--no-default-features"],
            "the no_std core of schedule-analysis",
        ),
    ];
    timed("the chip libraries", || {
        for target in ["thumbv7m-none-eabi", "thumbv7em-none-eabihf"] {
            for (package, features, what) in chip_libraries {
                let mut args = vec!["build", "--quiet", "--target", target, "-p", package];
                args.extend_from_slice(features);
                cargo(root, &args).with_context(|| format!("{what} for {target}"))?;
            }
        }
        Ok(())
    })?;
    // Every revision of every board (docs/boards.md).
    let every = revision::plan(&BOARDS.iter().collect::<Vec<_>>(), &revision::Choice::All)?;
    // The bare-chip layout must keep linking (it is the documented switch for development chips).
    let reports = timed("the firmware images (bare-chip and release)", || {
        build_boards(root, &every, true)?;
        build_boards(root, &every, false)
    })?;
    timed("flashing a simulated robot", || {
        flash::simulated_robot(root, &reports)
    })?;
    elf::print_table(&reports);
    let over = elf::over_budget(&reports);
    ensure!(over.is_empty(), "flash budget: {}", over.join("; "));
    timed(
        "the machine-code checks (panics, stacks, bounds current)",
        || {
            machine::check_panics(&reports)?;
            machine::check_stacks(root, &reports)?;
            // The generated bounds files must be computed from these images (docs/analysis.md).
            wcet_gate::check_bounds_current(root)
        },
    )?;
    timed("the boards' QEMU scenarios", || {
        run_scenarios(root, &every, &[])
    })?;
    // DiWheelDrive 1-1's and PowerManagement's I2C groups sampled by script (feature
    // `scripted-i2c`, docs/i2c.md): not in the shipped images yet, their scenarios run all the same.
    let scripted = revision::scripted_i2c_builds(&every);
    timed("the scenarios with scripted-i2c", || {
        run_scenarios(root, &scripted, &["scripted-i2c"])
    })?;
    // The whole robot on one bus (issue 23), with its bus report against the analysis.
    timed("the robot scenarios", || robot::scenarios::run_all(root))?;
    // … and with PowerManagement sampling by script (its trial; DiWheelDrive 1-1's is not in it).
    timed("the robot scenarios with powermgmt/scripted-i2c", || {
        robot::scenarios::run_all_with(root, &["powermgmt/scripted-i2c"])
    })?;
    // The production images booted in QEMU (issue 21): every revision's, as built above.
    timed("the smoke runs", || smoke::run(root, &every, true))?;
    // After the scenarios: their bus logs are among what the other CAN tools must read.
    timed("the CAN tools' interop", || interop::check(root))?;
    // The hostile-bus campaign, one run of 3000 spaced frames per board (issue 12).
    timed("the hostile-bus campaign", || {
        campaign::run(root, &BOARDS.iter().collect::<Vec<_>>(), 12, 3000, 1)
    })
}

/// The analysis gate: every shipped scenario must be schedulable and within its jitter budgets, on a
/// robot of each revision, or fail exactly as its `expected_failures` say (a checked refusal;
/// `schedule-analysis/tests/revisions.rs` holds the same).
fn analysis_gate(root: &Path) -> Result<()> {
    let scenarios = schedule_analysis::scenario::scenario_names(root)
        .context("listing the shipped scenarios (schedule-analysis/models)")?;
    for robot in boards::ROBOT_REVISIONS {
        for name in &scenarios {
            let args = analyze::AnalyzeArgs {
                scenario: Some(name.clone()),
                model: None,
                frame_cost: None,
                format: schedule_analysis::report::Format::Table,
                output: Some(target_dir(root).join(format!("analysis-{name}-{robot}.txt"))),
                check: true,
                emit_model: None,
                revision: Some(robot.to_string()),
            };
            if !analyze::run(&args, root)? {
                bail!(
                    "scenario {name} is not schedulable (or not as its expected failures say) on a {robot} robot (see {})",
                    args.output
                        .as_ref()
                        .map(|p| p.display().to_string())
                        .unwrap_or_default()
                );
            }
            println!("analysis gate: scenario {name} as checked on a {robot} robot");
        }
    }
    Ok(())
}

/// Runs every board's QEMU scenarios and checks their output, the images built with the boards'
/// `extra` features as well.
fn run_scenarios(root: &Path, builds: &[revision::Build], extra: &[&str]) -> Result<()> {
    ensure_qemu()?;
    let bounds = scenarios::Bounds::from_analysis(root)?;
    let mut passed = 0;
    let mut failed = 0;
    for build in builds {
        let board = build.board;
        let list = scenarios::for_revision(board.name, build.revision.name);
        if list.is_empty() {
            continue;
        }
        // One QEMU build per board revision, shared by its scenarios; the analysis bounds of that
        // revision's timing files (`build_qemu` selects them).
        let elf = build_qemu_with(root, build, extra)?;
        let mut ram_high_water = 0;
        // The runs whose output the bench measures afterwards (no second QEMU run).
        let mut outputs = Vec::new();
        let works: Vec<PathBuf> = list
            .iter()
            .map(|scenario| {
                qemu_target_dir(root)
                    .join("scenarios")
                    .join(build.stem())
                    .join(scenario.name)
            })
            .collect();
        // The QEMU runs of this image side by side (`qemu::run_each`: one per core), checked below in order.
        let runs = qemu::run_each(
            &list.iter().zip(&works).collect::<Vec<_>>(),
            |(scenario, work)| {
                let path =
                    scenarios::log_path(root, board.name, build.revision.name, scenario.name);
                let frames = qemu::read_stimulus(&path)?;
                let duration = scenarios::duration_of(&path)?;
                qemu::run(&elf, board.qemu_machine, &frames, duration, work)
            },
        )?;
        for ((scenario, work), run) in list.iter().zip(works).zip(runs) {
            let result = (|| {
                let text = run?;
                let (bus, trace) = qemu::split_output(&text);
                std::fs::write(work.join("bus.log"), bus)?;
                std::fs::write(work.join("trace.log"), trace)?;
                outputs.push((scenario.name.to_string(), work.clone()));
                let mut out = scenarios::RunOutput::parse(&text)?;
                out.work = Some(work.clone());
                let (static_ram, stack) = out.ram_used()?;
                ram_high_water = ram_high_water.max(static_ram + stack);
                // The analysed bounds of this run: its received frames as its stimulus replays them.
                let bounds = bounds.for_run(&std::fs::read(work.join("stimulus.bin"))?)?;
                scenarios::verdicts_spaced(&out, board.name)?;
                (scenario.check)(&out, &bounds)
            })();
            match result {
                Ok(summary) => {
                    passed += 1;
                    println!(
                        "qemu {:<16} {:<16} ok: {summary}",
                        build.stem(),
                        scenario.name
                    );
                }
                Err(e) => {
                    failed += 1;
                    println!(
                        "qemu {:<16} {:<16} FAILED ({}): {e:#}",
                        build.stem(),
                        scenario.name,
                        scenario.about
                    );
                }
            }
        }
        // The board's RAM goal (including the stack), measured by stack painting in QEMU.
        let goal = scenarios::ram_goal(board.name, build.revision.name);
        println!(
            "{} RAM in QEMU (static + deepest stack): {ram_high_water} bytes of a {goal}-byte goal",
            board.name
        );
        // A trial's image (`extra` features: not the shipped one, and not the app the timing
        // files and bounds describe) is held to its scenarios' checks; its RAM and its jobs against
        // the shipped image's analysis are printed, not gated, until the analysis covers it.
        let trial = !extra.is_empty();
        if ram_high_water > goal {
            if trial {
                println!(
                    "{} with {}: RAM goal missed (a trial, not gated)",
                    board.name,
                    extra.join(",")
                );
            } else {
                failed += 1;
                println!("{} RAM goal missed", board.name);
            }
        }
        // Measured against analysed, from the same runs (`cargo xtask bench --qemu --check`).
        if let Err(e) = bench::check_scenario_runs(root, build, &elf, &outputs) {
            if trial {
                println!("{e:#} (a trial against the shipped image's analysis, not gated)");
            } else {
                failed += 1;
                println!("{e:#}");
            }
        }
    }
    println!("scenarios: {passed} passed, {failed} failed");
    if failed > 0 {
        bail!(
            "{failed} QEMU scenario(s) failed (outputs in {})",
            qemu_target_dir(root).join("scenarios").display()
        );
    }
    Ok(())
}
