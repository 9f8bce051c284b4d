//! `cargo xtask robot --bench`: where a robot run's wall time goes, for an idle robot, the thesis
//! demo and a babbling board (docs/qemu.md, "Speed"). Prints figures; it asserts nothing about
//! them (they depend on the machine and its load, which it prints beside them).
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};

use amiro_robot::stimulus::{self, Action, Timed};

/// The load average (1 minute) now, as `/proc/loadavg` has it.
fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

/// Runs the three cases for `duration` (default 2 s) of virtual time each and prints the table.
pub fn command(root: &Path, duration: Option<&str>) -> Result<()> {
    let duration_us = match duration {
        Some(d) => crate::qemu::parse_duration(d)?,
        None => 2_000_000,
    };
    let firmware = super::firmware::firmware(root)?;
    let (thesis, _) = stimulus::read(&root.join("robot/scenarios/thesis-demo.log"))?;
    let mut babbling = thesis.clone();
    // LightRing's controller babbles 0x610 from 20 ms to the end (88 % of the bus), as in the
    // babbling-board scenario but for the whole run.
    babbling.push(Timed {
        at_us: 20_000,
        action: Action::Babble {
            board: 2,
            id: 0x610,
            data: vec![0xA5; 8],
        },
    });
    let cases: [(&str, Vec<Timed>); 3] = [
        ("idle", Vec::new()),
        ("thesis-demo", thesis),
        ("babbling", babbling),
    ];
    let virtual_s = duration_us as f64 / 1e6;
    println!(
        "robot bench: {virtual_s} s of virtual time per case, {} CPUs; per virtual second:",
        std::thread::available_parallelism().map_or(0, usize::from)
    );
    println!(
        "{:<12} {:>9} {:>10} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11}",
        "case",
        "steps",
        "exchanges",
        "wall s",
        "waiting",
        "one runs",
        "two run",
        "max qemu",
        "qemu usr",
        "qemu sys",
        "host cpu",
        "load 1 min"
    );
    let mut costs = Vec::new();
    for (name, actions) in cases {
        let work = crate::workspace::qemu_target_dir(root)
            .join("robot-bench")
            .join(name);
        let _ = std::fs::remove_dir_all(&work);
        let load_before = load();
        let started = Instant::now();
        let mut lines: Vec<String> = Vec::new();
        let outcome = amiro_robot::run(&firmware, &actions, duration_us, &work, &mut lines, None)
            .with_context(|| format!("bench case {name}"))?;
        let wall = started.elapsed().as_secs_f64();
        let per = |x: f64| x / virtual_s;
        let w = outcome.work;
        println!(
            "{name:<12} {:>9.0} {:>10.0} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>5}→{:<5}",
            per(w.steps as f64),
            per(w.exchanges as f64),
            per(wall),
            per(w.waiting_us as f64 / 1e6),
            per(w.overlap.running_us[1] as f64 / 1e6),
            per(w.overlap.side_by_side_us() as f64 / 1e6),
            per(w.boards.iter().map(|c| c.cpu_s()).fold(0.0, f64::max)),
            per(w.boards.iter().map(|c| c.user_s).sum()),
            per(w.boards.iter().map(|c| c.sys_s).sum()),
            per(w.host.cpu_s()),
            load_before,
            load()
        );
        costs.push((name, w));
    }
    println!(
        "steps: boundaries the host ran the bus to; exchanges: board reports (the rest of the \
         boards waited, lookahead); wall s: wall seconds per virtual second (below 1: faster than \
         real time); waiting: wall time the host waited for the boards' reports (their \
         emulation and the pipes); one runs / two run: wall time with one board's QEMU \
         running (from its answer to its report), and with two or more side by side (what the \
         second core gives); max qemu: the busiest board's QEMU's CPU (the least wall time the \
         run could take, its boards side by side); qemu usr/sys: the three QEMUs' CPU in user space (emulation) \
         and in the kernel (the exchanges' semihosting reads and writes, pipes, task switches); \
         host cpu: this process (the bus model, the coordinator)."
    );
    // The figures that do not depend on the machine's load: per board's QEMU, its CPU, task
    // switches and read/write system calls per virtual second and per exchange.
    for (name, w) in costs {
        println!("\n{name}: where the CPU goes");
        print!("{}", amiro_robot::cost::table(&w, virtual_s));
    }
    println!(
        "\nswitches: the QEMU's task switches (its vCPU thread and main loop hand QEMU's lock and \
         timer events to each other, the exchange's blocking read); reads/writes: its read and \
         write system calls (the exchange's pipes, semihosting writes of the console and the \
         trace, QEMU's event notifications); CPU µs: its CPU time per exchange."
    );
    Ok(())
}
