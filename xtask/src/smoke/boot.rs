//! One board's smoke run: QEMU started with the stand-in and the image, polled until the monotonic
//! has counted enough or the board handed over, halted or stalled, then checked.
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use object::{Object, ObjectSymbol};

use crate::boards::{Board, Via};
use crate::qemu::ICOUNT_SHIFT;

use super::checks::{check_log, check_timer};
use super::environment::{expected_ending, Ending};
use super::qmp::Qmp;
use super::rtt::rtt_up_channel;
use super::standin::{callback_at, flash_image, standin};
use super::{gdb, RAM_BASE, STANDIN_BASE};

/// How often the guest is stopped and looked at (wall time).
pub const POLL: Duration = Duration::from_millis(250);
/// How many half periods of the monotonic make a run: QEMU's timer model has no compare events,
/// so each of its update interrupts counts two (`timer_monotonic::advance`): 32 interrupts.
pub const HALF_PERIODS: u32 = 64;
/// How long the monotonic's counter may stand still, counted in CPU time QEMU got meanwhile (not
/// wall time: on a loaded machine a correct image's QEMU may wait for a core far longer than it
/// runs; issue 34).
const STALL: Duration = Duration::from_secs(15);
/// The CPU-time guard of one board's run (QEMU's own CPU time, as [`STALL`]).
const CPU_LIMIT: Duration = Duration::from_secs(120);
/// The wall-time guard of last resort (a QEMU that gets no CPU at all for this long is not
/// waited for): far beyond any correct run on a busy 2-core machine.
const WALL_LIMIT: Duration = Duration::from_secs(900);

/// The CPU time (user + system) process `pid` has had so far, from `/proc/PID/stat`; `None`
/// where that cannot be read (then the wall-time guards alone apply).
fn cpu_time(pid: u32) -> Option<Duration> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from after it.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    // SAFETY: sysconf has no preconditions.
    let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    let per_second = u64::try_from(per_second).ok().filter(|&n| n > 0)?;
    Some(Duration::from_millis(ticks * 1000 / per_second))
}

/// The symbols the run needs from the ELF.
struct Symbols {
    rtt: Option<u32>,
    /// The monotonic's half-period counter (`timer_monotonic::HalfPeriods`, its count first).
    counter: u32,
    /// `amiro_firmware::fault::halt`, where a panic or a HardFault parks the CPU.
    halt: std::ops::Range<u32>,
}

fn symbols(elf: &[u8]) -> Result<Symbols> {
    let file = object::File::parse(elf).context("parsing the firmware ELF")?;
    let find = |pred: &dyn Fn(&str) -> bool| {
        file.symbols()
            .find(|s| !s.is_undefined() && s.name().map(pred).unwrap_or(false) && s.address() != 0)
    };
    let counter = find(&|n| n.contains("HALF_PERIODS"))
        .context("no monotonic half-period counter (HALF_PERIODS) in the ELF")?;
    let halt = find(&|n| n.contains("14amiro_firmware5fault4halt"))
        .context("no amiro_firmware::fault::halt in the ELF")?;
    let start = (halt.address() & !1) as u32;
    Ok(Symbols {
        rtt: crate::elf::rtt_control_block(elf).map(|a| a as u32),
        counter: counter.address() as u32,
        halt: start..start + halt.size().max(2) as u32,
    })
}

/// One board's smoke run: its log, and what failed.
pub struct Outcome {
    /// The board's RTT log at the end of the run.
    pub log: String,
    /// The AMiRo-BLT callback the board handed over to, if it did.
    pub handed_over: Option<&'static str>,
    /// The monotonic's half periods counted during the run.
    pub half_periods: u32,
    /// Loads of a watched input set to the robot's level ([`Via::Watchpoint`]), if any.
    pub patched_loads: Option<u32>,
    /// Everything that went wrong (empty: passed).
    pub failures: Vec<String>,
}

/// Boots `board`'s production image (built and checked by `cargo xtask build`) in QEMU and checks
/// its boot. `work` holds the images, the RAM snapshots and QEMU's stderr.
pub fn run_board(board: &Board, elf_path: &Path, work: &Path) -> Result<Outcome> {
    std::fs::create_dir_all(work)?;
    // The bytes `cargo xtask flash` writes: the ELF with its AMiRo-BLT checksum word, its segments.
    let patched = work.join(format!("{}.blt.elf", board.name));
    crate::elf::write_checksum(elf_path, &patched)?;
    let elf = std::fs::read(&patched)?;
    let image = flash_image(&crate::elf::load_segments(&elf)?, board.app_base)?;
    let image_path = work.join("application.bin");
    std::fs::write(&image_path, &image)?;
    let standin_path = work.join("amiro-blt-standin.bin");
    std::fs::write(
        &standin_path,
        standin(
            board.app_base as u32,
            &board
                .qemu_inputs
                .iter()
                .filter(|input| input.via == Via::StandIn)
                .map(|input| (input.address, input.value))
                .collect::<Vec<_>>(),
        ),
    )?;
    let symbols = symbols(&elf)?;
    let stderr_path = work.join("qemu-stderr.log");

    let mut qemu = Command::new("qemu-system-arm");
    qemu.args(["-machine", board.qemu_machine, "-display", "none"])
        .args(["-monitor", "none", "-serial", "null"])
        .args([
            "-chardev",
            "stdio,id=qmp",
            "-mon",
            "chardev=qmp,mode=control",
        ])
        .args([
            "-icount",
            &format!("shift={ICOUNT_SHIFT},align=off,sleep=off"),
        ])
        .args(["-device", &loader(&standin_path, STANDIN_BASE.into())])
        .args(["-device", &loader(&image_path, board.app_base)])
        .current_dir(work);
    let watched: Vec<(u32, u32)> = board
        .qemu_inputs
        .iter()
        .filter(|input| input.via == Via::Watchpoint)
        .map(|input| (input.address, input.value))
        .collect();
    let gdb_socket = work.join("gdb.sock");
    if !watched.is_empty() {
        let _ = std::fs::remove_file(&gdb_socket);
        // Held at reset until the watchpoints are in; the gdbstub starts the guest.
        qemu.arg("-chardev")
            .arg(format!(
                "socket,id=gdb,path={},server=on,wait=off",
                gdb_socket.display()
            ))
            .args(["-gdb", "chardev:gdb", "-S"]);
    }

    let mut qmp = Qmp::start(&mut qemu)?;
    let steering = gdb::Steering::default();
    let patcher = if watched.is_empty() {
        None
    } else {
        Some(gdb::hold_inputs(&gdb_socket, watched, steering.clone())?)
    };
    let stderr = qmp.child.stderr.take();
    let stderr_file = std::fs::File::create(&stderr_path)?;
    if let Some(mut stderr) = stderr {
        let mut stderr_file = stderr_file;
        std::thread::spawn(move || std::io::copy(&mut stderr, &mut stderr_file));
    }

    let snapshot = work.join("ram.bin");
    let started = Instant::now();
    let mut first: Option<u32> = None;
    let pid = qmp.child.id();
    let cpu = || cpu_time(pid).unwrap_or_default();
    // The counter's last change: its value, the wall time and QEMU's CPU time then.
    let mut last = (0u32, Instant::now(), cpu());
    let mut log = String::new();
    let mut failures = Vec::new();
    let mut handed_over = None;
    let ending = expected_ending(board);
    loop {
        std::thread::sleep(POLL);
        if let Some(status) = qmp.child.try_wait()? {
            failures.push(format!("QEMU exited ({status})"));
            break;
        }
        if started.elapsed() > WALL_LIMIT {
            failures.push(format!(
                "the run did not end within the wall-time guard of {WALL_LIMIT:?} (QEMU had \
                 {:.1} s of CPU; the guest stayed stopped at a watched input?)",
                cpu().as_secs_f64()
            ));
            break;
        }
        let held = steering.lock().unwrap_or_else(|poison| poison.into_inner());
        qmp.execute("stop", None)?;
        let status = qmp.execute("query-status", None)?;
        if status.get("status").and_then(|s| s.as_str()) == Some("debug") {
            // Stopped at a watched input: the patcher's to resume.
            drop(held);
            continue;
        }
        let pc = qmp.pc()?;
        let ram = qmp.save_ram(board.ram_bytes, &snapshot)?;
        qmp.execute("cont", None)?;
        drop(held);
        if let Ok(bytes) = rtt_up_channel(&ram, symbols.rtt, 0) {
            log = String::from_utf8_lossy(&bytes).into_owned();
        }
        let at = (symbols.counter - RAM_BASE) as usize;
        let counter = ram
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .unwrap_or_default();
        if let Some(callback) = callback_at(pc) {
            handed_over = Some(callback);
            break;
        }
        if symbols.halt.contains(&(pc & !1)) {
            failures.push(format!(
                "the board halted in fault::halt (a panic or a HardFault; pc {pc:#010x})"
            ));
            break;
        }
        let base = *first.get_or_insert(counter);
        if counter != last.0 {
            last = (counter, Instant::now(), cpu());
        }
        if ending == Ending::Running && counter.wrapping_sub(base) >= HALF_PERIODS {
            break;
        }
        let stalled_cpu = cpu().saturating_sub(last.2);
        if stalled_cpu > STALL {
            failures.push(format!(
                "no progress: the monotonic's half-period counter stayed at {counter} while QEMU \
                 ran {:.1} s of CPU (the stall guard is {STALL:?} of QEMU's CPU; {:.1} s of wall \
                 time; pc {pc:#010x})",
                stalled_cpu.as_secs_f64(),
                last.1.elapsed().as_secs_f64()
            ));
            break;
        }
        if cpu() > CPU_LIMIT || started.elapsed() > WALL_LIMIT {
            failures.push(format!(
                "only {} of {HALF_PERIODS} half periods of the monotonic when the run's guard \
                 ended it: {:.1} s of QEMU's CPU (guard {CPU_LIMIT:?}), {:.1} s of wall time \
                 (guard {WALL_LIMIT:?})",
                counter.wrapping_sub(base),
                cpu().as_secs_f64(),
                started.elapsed().as_secs_f64()
            ));
            break;
        }
    }
    let half_periods = last.0.wrapping_sub(first.unwrap_or(last.0));
    // The monotonic's timer as the board left it (after a hand-over too: AMiRo-BLT's hand-over
    // masks the interrupts, it does not stop the timer).
    let timer = board.monotonic_timer;
    let timer_state = (|| -> Result<_> {
        let before = qmp.words(timer.base, 16)?;
        std::thread::sleep(Duration::from_millis(20));
        Ok((before, qmp.words(timer.base, 16)?))
    })();
    // The run is over: the patcher takes no stop after this (QEMU is killed with the QMP
    // connection, and a patch under way would find the gdbstub closed).
    let stopped_patching = steering.lock().map(|mut ending| *ending = true);
    drop(stopped_patching);
    drop(qmp);
    let mut patched_loads = None;
    if let Some(patcher) = patcher {
        match patcher.join() {
            Ok(Ok(patched)) => patched_loads = Some(patched),
            Ok(Err(error)) => failures.push(format!("holding the inputs: {error:#}")),
            Err(_) => failures.push("the input patcher panicked".into()),
        }
    }
    match timer_state {
        Ok((before, after)) => failures.extend(check_timer(
            &timer,
            &before,
            &after,
            board.internal_oscillator_hz,
        )),
        Err(error) => failures.push(format!(
            "could not read the monotonic's timer {} at {:#010x}: {error:#}",
            timer.name, timer.base
        )),
    }
    match (ending, handed_over) {
        (Ending::Running, Some(callback)) => failures.push(format!(
            "the board handed over to AMiRo-BLT's `{callback}` callback instead of running on"
        )),
        (Ending::HandOver(expected), None) => failures.push(format!(
            "the board did not hand over to AMiRo-BLT's `{expected}` callback"
        )),
        (Ending::HandOver(expected), Some(callback)) if callback != expected => failures.push(
            format!("the board handed over to `{callback}`, not `{expected}`"),
        ),
        _ => {}
    }
    failures.extend(check_log(&log, ending));
    Ok(Outcome {
        log,
        handed_over,
        half_periods,
        patched_loads,
        failures,
    })
}

fn loader(file: &Path, addr: u64) -> String {
    format!("loader,file={},addr={addr:#x},force-raw=on", file.display())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guards_read_a_process_cpu_time() {
        // This process has run (it is running this test); a process that does not exist has none.
        let mine = cpu_time(std::process::id()).expect("own /proc/PID/stat");
        let spin = Instant::now();
        let mut x = 0u64;
        while spin.elapsed() < Duration::from_millis(60) {
            x = x.wrapping_add(std::hint::black_box(1));
        }
        assert!(x > 0);
        assert!(cpu_time(std::process::id()).expect("again") >= mine);
        assert_eq!(cpu_time(u32::MAX), None);
    }
}
