//! One board of the robot: its QEMU process (the board's QEMU build under `-icount`, the console
//! on a pipe), the two named pipes it trades over with the coordinator, and what it printed. The
//! one place a board's exchange happens: `Board::receive` takes its report, `Board::send` gives
//! its answer (the messages are `amiro_trace::robot_link`'s).
use std::cell::RefCell;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::rc::Rc;
use std::time::{Duration, Instant};

use amiro_bus_sim::{NodeId, MAILBOXES};
use amiro_trace::robot_link::{
    Done, Down, Up, DONE_LEN, DOWN_READINGS, DOWN_RESTART, DRIVES_SYNC_LOW, MAX_DONE, QUANTUM_US,
    UP_LEN, UP_WHEELS,
};
use amiro_trace::world_link::{Readings, Wheels, WHEELS_LEN};
use anyhow::{bail, Context, Result};

use crate::cost::Overlap;
use crate::{Firmware, NODES};

/// The real-time priority (`SCHED_RR`) of a live run's QEMUs: above every ordinary process, so a
/// build beside the run no longer holds a board up for a time slice (the lags above 5 ms were such
/// moments, docs/qemu.md "Live"). The host's is one higher ([`live_priority`]).
pub(crate) const LIVE_RT_PRIORITY: i32 = 10;
/// The nice value a live run's QEMUs and host fall back to where real-time priority is not
/// permitted (the default is 0).
pub(crate) const LIVE_NICE: i32 = -10;

/// Puts the calling thread (or, in a child between fork and exec, the process) at real-time
/// priority `rt`, else at [`LIVE_NICE`]; what it got: `Some(true)` real-time, `Some(false)` the
/// nice value, `None` neither (not permitted). Async-signal-safe (two system calls).
pub(crate) fn live_priority(rt: i32) -> Option<bool> {
    let param = libc::sched_param { sched_priority: rt };
    // SAFETY: sched_setscheduler and setpriority on the calling thread, with a parameter we own.
    unsafe {
        if libc::sched_setscheduler(0, libc::SCHED_RR, &param) == 0 {
            Some(true)
        } else if libc::setpriority(libc::PRIO_PROCESS, 0, LIVE_NICE) == 0 {
            Some(false)
        } else {
            None
        }
    }
}

/// A board's process and the coordinator's view of it.
pub(crate) struct Board {
    pub(crate) index: usize,
    /// Its node on the bus model.
    pub(crate) node: NodeId,
    pub(crate) firmware: Firmware,
    pub(crate) dir: PathBuf,
    pub(crate) child: Option<Child>,
    pub(crate) up: Option<File>,
    pub(crate) down: Option<File>,
    pub(crate) out: Option<ChildStdout>,
    pub(crate) partial: Vec<u8>,
    pub(crate) lines: Vec<String>,
    /// Global virtual time of the board's clock zero (its last start).
    pub(crate) offset: u64,
    pub(crate) alive: bool,
    pub(crate) drives: u8,
    /// Global virtual time before which the board does nothing of its own (its last report).
    pub(crate) wakes_at: u64,
    /// Mailboxes (bit per mailbox) whose abort it asked for in its last report, and those whose
    /// frame the bus gave back (the answer tells it).
    pub(crate) aborts: u8,
    pub(crate) aborted: u8,
    /// Per mailbox, when the frame in it was released into the board's transmit queue.
    pub(crate) released: [u64; MAILBOXES],
    /// The boundary the board reported at last (global virtual time).
    pub(crate) at: u64,
    /// The boundary it was sent on to and reports at next; `None` while it waits for its answer
    /// (it reported at `at` and sleeps past the next boundary: it is left waiting until needed).
    pub(crate) next: Option<u64>,
    /// The boundary it wants its next exchange at (from its last report).
    pub(crate) wants: u64,
    /// The line flags of its last answer.
    pub(crate) flags: u8,
    /// Lines it printed up to its last report (those after it are still in `lines`).
    pub(crate) ready: Vec<String>,
    /// The wheel ticks that followed its last report (the DiWheelDrive in a run with a world).
    pub(crate) wheels: Option<Wheels>,
    /// A report taken ahead of the host's boundary, with the boundary it is for: a board sent
    /// ahead together with another reported later than the other (`None` inside: its run
    /// ended). The host takes it when it reaches that boundary.
    pub(crate) held: Option<(u64, Option<Up>)>,
    /// Part of a live run (its QEMU runs at [`LIVE_RT_PRIORITY`], else at [`LIVE_NICE`]).
    pub(crate) live: bool,
    /// It was given a command frame that may drive a line (a shutdown command; anything but a
    /// sensor request, an LED or the motor command: `run::may_drive_a_line`) and has not slept
    /// since, so it is not sent ahead together with another board meanwhile.
    pub(crate) commanded: bool,
    /// What its QEMUs cost (summed over its starts), taken as each is reaped.
    pub(crate) cost: crate::cost::Cost,
    /// Its QEMU's main loop runs at [`MAIN_LOOP_NICE`] (set at its first report).
    pub(crate) main_loop_lowered: bool,
    /// When it was last sent on, while it runs towards its report (`None` while it waits).
    pub(crate) running_since: Option<Instant>,
    /// The run's record of how the boards ran side by side (shared by its boards).
    pub(crate) overlap: Rc<RefCell<Overlap>>,
    /// The wall time of its last run, from being sent on to its report.
    pub(crate) last_run: Duration,
    /// A live board's QEMU's vCPU thread's clock (from its first report), with its reading when
    /// the board was last sent on.
    pub(crate) vcpu: Option<(crate::cost::ThreadClock, Option<(u64, u64)>)>,
    /// What its vCPU thread did in its last run: ran and waited for a core (live runs).
    pub(crate) last_run_cpu: Option<(Duration, Duration)>,
    /// A live board's QEMU's main loop's clock, read as [`Board::vcpu`]'s: the main loop may hold
    /// QEMU's global lock, which the vCPU thread then waits for, neither running nor waiting for
    /// a core.
    pub(crate) main_loop: Option<(crate::cost::ThreadClock, Option<(u64, u64)>)>,
    /// What its main loop did in its last run: ran and waited for a core (live runs).
    pub(crate) last_run_main_loop: Option<(Duration, Duration)>,
    /// The frames it completed itself under a grant, from its last report (`Up::done`).
    pub(crate) done: Vec<Done>,
    /// It was granted the bus with its last answer, until this global virtual time
    /// (`Down::free_until_us`).
    pub(crate) granted: Option<u64>,
}

/// The nice value of a board's QEMU main loop (its process's first thread; the vCPU thread and
/// the rest keep the process's). Under `-icount` the vCPU thread runs the expired timers itself,
/// but every timer expiry and every SysTick restart still notifies the main loop, which then
/// wakes on the same core (the QEMU is pinned), pre-empts the vCPU thread and contends for QEMU's
/// global lock: 13 task switches per exchange. At the lowest priority it runs when the vCPU
/// thread waits (for its answer) instead, and takes up the notifications in one turn: 2 switches
/// per exchange, and 15 % less QEMU CPU in the thesis demo (docs/qemu.md, "Speed"). Nothing in
/// the virtual timeline depends on it: two runs still print the same bytes.
pub(crate) const MAIN_LOOP_NICE: i32 = 19;

fn make_fifo(path: &Path) -> Result<()> {
    let _ = std::fs::remove_file(path);
    let name = std::ffi::CString::new(path.as_os_str().as_encoded_bytes())?;
    // SAFETY: a NUL-terminated path we own.
    if unsafe { libc::mkfifo(name.as_ptr(), 0o600) } != 0 {
        bail!(
            "mkfifo {}: {}",
            path.display(),
            std::io::Error::last_os_error()
        );
    }
    Ok(())
}

/// Makes a descriptor non-blocking.
pub(crate) fn set_nonblocking(fd: i32) {
    // SAFETY: fcntl on a descriptor we own.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK);
    }
}

impl Board {
    /// Board `index` of the robot (not started): its bus node, its build, its folder, whether the
    /// run is live.
    pub(crate) fn new(
        index: usize,
        node: NodeId,
        firmware: Firmware,
        dir: PathBuf,
        live: bool,
    ) -> Self {
        Self {
            index,
            node,
            firmware,
            dir,
            child: None,
            up: None,
            down: None,
            out: None,
            partial: Vec::new(),
            lines: Vec::new(),
            offset: 0,
            alive: false,
            drives: DRIVES_SYNC_LOW,
            wakes_at: 0,
            aborts: 0,
            aborted: 0,
            released: [0; MAILBOXES],
            at: 0,
            next: None,
            wants: 0,
            flags: 0,
            ready: Vec::new(),
            wheels: None,
            held: None,
            commanded: false,
            live,
            cost: crate::cost::Cost::default(),
            main_loop_lowered: false,
            running_since: None,
            overlap: Rc::default(),
            last_run: Duration::ZERO,
            vcpu: None,
            last_run_cpu: None,
            main_loop: None,
            last_run_main_loop: None,
            done: Vec::new(),
            granted: None,
        }
    }

    pub(crate) fn start(&mut self, at: u64) -> Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let (up, down) = (self.dir.join("robot-up"), self.dir.join("robot-down"));
        make_fifo(&up)?;
        make_fifo(&down)?;
        // Read and write: opening never blocks and the pipe never reads as closed while the board
        // restarts; the board's end shows as its process ending.
        let open = |p: &Path| {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(p)
                .with_context(|| format!("opening {}", p.display()))
        };
        self.up = Some(open(&up)?);
        self.down = Some(open(&down)?);
        // The single-board stimulus the firmware would read is never opened in a robot run; the
        // header keeps a board started by hand in this folder from misreading it.
        std::fs::write(
            self.dir.join("stimulus.bin"),
            crate::log::encode_stimulus(&[], 0),
        )?;
        let stderr = File::create(self.dir.join("qemu-stderr.log"))?;
        let mut command = Command::new("qemu-system-arm");
        // Each board's QEMU on one core of its own (modulo the cores there are): its vCPU thread
        // and its main loop hand QEMU's global lock and the timer notifications to each other at
        // every exchange, and on one core that costs no wake-up across cores; the boards still
        // run side by side. Halved the thesis demo's wall time on the 2-core machine at load 9
        // (docs/qemu.md, "Speed"). Virtual time does not depend on it.
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        let cpu = (cores > 1).then_some(self.index % cores);
        // A live run's boards (and host, `run`) at a raised priority: the wall clock is theirs
        // to keep up with, other work on the machine can wait (needs the privilege; a refusal
        // keeps the default priority, which the run's first line says).
        let live = self.live;
        {
            use std::os::unix::process::CommandExt;
            // SAFETY: sched_setaffinity and setpriority on the child between fork and exec (both
            // async-signal-safe); a refusal leaves the child as it was.
            unsafe {
                command.pre_exec(move || {
                    if let Some(cpu) = cpu {
                        let mut set: libc::cpu_set_t = std::mem::zeroed();
                        libc::CPU_SET(cpu, &mut set);
                        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
                    }
                    if live {
                        live_priority(LIVE_RT_PRIORITY);
                    }
                    Ok(())
                });
            }
        }
        let mut child = command
            .args(["-machine", self.firmware.machine, "-nographic"])
            // Named threads: a live run reads its vCPU thread's scheduler clock (`ThreadClock`).
            .args(["-name", &format!("{},debug-threads=on", NODES[self.index])])
            .args(["-monitor", "none", "-serial", "none"])
            // The console as a chardev on stdout: every semihosting write is a write(2) that has
            // happened when the board's next exchange arrives (lines are assigned to quanta).
            .args(["-chardev", "stdio,id=console,signal=off"])
            .args([
                "-semihosting-config",
                "enable=on,target=native,chardev=console",
            ])
            .args([
                "-icount",
                &format!("shift={},align=off,sleep=off", crate::log::ICOUNT_SHIFT),
            ])
            .arg("-kernel")
            .arg(&self.firmware.elf)
            .current_dir(&self.dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
            .spawn()
            .context("starting qemu-system-arm (install it: apt-get install qemu-system-arm)")?;
        let out = child.stdout.take().context("QEMU stdout")?;
        set_nonblocking(out.as_raw_fd());
        // Room for what a board prints between two of its exchanges, which is when the host reads
        // it (a full pipe would hold the board up until the next read); the default is kept if
        // the system refuses.
        // SAFETY: fcntl on a descriptor we own.
        unsafe { libc::fcntl(out.as_raw_fd(), libc::F_SETPIPE_SZ, 1 << 20) };
        self.out = Some(out);
        self.child = Some(child);
        self.new_console();
        self.main_loop_lowered = false;
        self.vcpu = None;
        self.main_loop = None;
        self.booted(at);
        Ok(())
    }

    /// The console of a new QEMU of the board: what the last one printed stays, for the host to
    /// emit. The host emits a board's lines at the end of its boundary (`board_lines`), and a
    /// reset (`run`, `Action::Reset`) is taken before that: `stop` moves the old QEMU's lines into
    /// `ready`, where they wait for it. (Until 2026-12-05 they were cleared here: a LightRing reset
    /// by SYS_WARMRST_N lost everything it printed since its last report the host had emitted, e.g.
    /// `reset`'s LED command at 10 ms when no other traffic kept LightRing exchanging before the
    /// pulse at 50 ms, the board sent ahead to the pulse's boundary.)
    fn new_console(&mut self) {
        self.flush_partial();
        self.ready.append(&mut self.lines);
    }

    /// Restarts the board in its running QEMU at boundary `at` (a system reset, [`DOWN_RESTART`]):
    /// it must be waiting for its answer (reported, not sent on). The code QEMU translated for it
    /// stays, so what it ran before costs no translation again (a live run's warm-up). Its lines
    /// so far stay in `lines`.
    pub(crate) fn restart(&mut self, at: u64) -> Result<()> {
        if self.next.is_some() || self.down.is_none() {
            bail!("{} restarted while it runs", NODES[self.index]);
        }
        self.send(&Down {
            flags: DOWN_RESTART,
            ..Down::default()
        })?;
        self.booted(at);
        Ok(())
    }

    /// The coordinator's view of a board that boots at boundary `at` (started or restarted).
    fn booted(&mut self, at: u64) {
        self.offset = at;
        self.alive = true;
        // A module holds SYS_SYNC_N low until it is initialised.
        self.drives = DRIVES_SYNC_LOW;
        self.wakes_at = at;
        self.aborts = 0;
        self.aborted = 0;
        self.released = [at; MAILBOXES];
        // Its first exchange is at its own first boundary.
        self.at = at;
        self.next = Some(at + QUANTUM_US);
        self.wants = at + QUANTUM_US;
        self.flags = 0;
        self.held = None;
        self.commanded = false;
        self.done.clear();
        self.granted = None;
        self.last_run_cpu = None;
        self.last_run_main_loop = None;
        self.run_from(Instant::now());
    }

    /// Reads what the board printed so far (never blocks); `false` once its output has closed.
    pub(crate) fn drain(&mut self) -> bool {
        let Some(out) = self.out.as_mut() else {
            return false;
        };
        let mut chunk = [0u8; 4096];
        loop {
            match out.read(&mut chunk) {
                Ok(0) => {
                    self.out = None;
                    self.flush_partial();
                    return false;
                }
                Ok(n) => {
                    self.partial.extend_from_slice(&chunk[..n]);
                    while let Some(at) = self.partial.iter().position(|&b| b == b'\n') {
                        let line: Vec<u8> = self.partial.drain(..=at).collect();
                        self.lines
                            .push(String::from_utf8_lossy(&line[..at]).into_owned());
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return true,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => {
                    self.out = None;
                    return false;
                }
            }
        }
    }

    fn flush_partial(&mut self) {
        if !self.partial.is_empty() {
            let line = String::from_utf8_lossy(&self.partial).into_owned();
            self.lines.push(line);
            self.partial.clear();
        }
    }

    /// Waits for the board's next exchange; `None` if the board has ended (its QEMU exited).
    pub(crate) fn receive(&mut self, guard: Instant, limit: Duration) -> Result<Option<Up>> {
        let mut message = [0u8; UP_LEN + MAX_DONE * DONE_LEN + WHEELS_LEN];
        let (mut got, mut want) = (0, UP_LEN);
        let up_fd = self.up.as_ref().context("no pipe")?.as_raw_fd();
        loop {
            // Only the report wakes the host: the console is read when the report is in (a board's
            // lines belong to the quantum they were printed in, and they are all in the pipe by
            // then), or when the wait is long (a board printing much, a board that ended). Waking
            // for every console write as well cost the host a task switch per line.
            let mut fds = [libc::pollfd {
                fd: up_fd,
                events: libc::POLLIN,
                revents: 0,
            }];
            // SAFETY: one pollfd structure we own.
            let ready = unsafe { libc::poll(fds.as_mut_ptr(), 1, 10) };
            if ready <= 0 {
                self.drain();
            }
            if fds[0].revents & libc::POLLIN != 0 {
                let n = self
                    .up
                    .as_mut()
                    .context("no pipe")?
                    .read(&mut message[got..want])?;
                got += n;
                if got == UP_LEN {
                    // The frames completed under a grant follow the report, then the wheels.
                    let up = Up::decode(message[..UP_LEN].try_into()?);
                    want = UP_LEN + up.done_len();
                    if up.flags & UP_WHEELS != 0 {
                        want += WHEELS_LEN;
                    }
                }
                if got == want {
                    self.stopped(Instant::now());
                    if !self.main_loop_lowered {
                        self.lower_main_loop();
                    }
                    // Everything the board printed before this exchange is in its pipe by now.
                    self.drain();
                    self.ready.append(&mut self.lines);
                    let up = Up::decode(message[..UP_LEN].try_into()?);
                    let wheels_at = UP_LEN + up.done_len();
                    self.done = message[UP_LEN..wheels_at]
                        .chunks_exact(DONE_LEN)
                        .filter_map(|r| r.try_into().ok().map(Done::decode))
                        .collect();
                    self.wheels = if want > wheels_at {
                        Some(Wheels::decode(message[wheels_at..want].try_into()?))
                    } else {
                        None
                    };
                    return Ok(Some(up));
                }
                continue;
            }
            if ready <= 0 {
                if let Some(child) = self.child.as_ref() {
                    if crate::cost::ended(child.id()) {
                        self.stopped(Instant::now());
                        while self.drain() {}
                        self.flush_partial();
                        self.ready.append(&mut self.lines);
                        return Ok(None);
                    }
                }
            }
            if guard.elapsed() > limit {
                bail!(
                    "{} did not answer within {limit:?} of wall time (a hang?); last lines:\n{}",
                    NODES[self.index],
                    self.lines
                        .iter()
                        .rev()
                        .take(10)
                        .rev()
                        .map(|l| format!("  {l}\n"))
                        .collect::<String>()
                );
            }
        }
    }

    /// Puts the QEMU's main loop at [`MAIN_LOOP_NICE`] (live, at real-time priority: one below the
    /// vCPU thread's): at the board's first report its threads are all there, and only the first
    /// (the main loop's, whose thread id is the process id) changes. A refusal leaves it as it was.
    fn lower_main_loop(&mut self) {
        self.main_loop_lowered = true;
        if let Some(child) = self.child.as_ref() {
            if self.live {
                self.vcpu = crate::cost::ThreadClock::vcpu(child.id()).map(|c| (c, None));
                self.main_loop = crate::cost::ThreadClock::main_loop(child.id()).map(|c| (c, None));
            }
            let tid = child.id() as libc::pid_t;
            // SAFETY: sched_getscheduler, sched_setscheduler and setpriority on one thread of our
            // child (Linux: a thread id names one thread), with parameters we own.
            unsafe {
                if libc::sched_getscheduler(tid) == libc::SCHED_RR {
                    // A live run's QEMU at real-time priority: its main loop one below the vCPU
                    // thread, so it never pre-empts it but is never held up by ordinary processes
                    // either (it may hold QEMU's global lock, which the vCPU thread then waits for).
                    let param = libc::sched_param {
                        sched_priority: LIVE_RT_PRIORITY - 1,
                    };
                    libc::sched_setscheduler(tid, libc::SCHED_RR, &param);
                } else {
                    libc::setpriority(libc::PRIO_PROCESS, child.id(), MAIN_LOOP_NICE);
                }
            }
        }
    }

    /// The board runs from `now` (it was started or sent on).
    fn run_from(&mut self, now: Instant) {
        if self.running_since.is_none() {
            self.running_since = Some(now);
            self.overlap.borrow_mut().started(now);
            for (clock, at) in self.vcpu.iter_mut().chain(self.main_loop.iter_mut()) {
                *at = clock.read();
            }
        }
    }

    /// The board stopped running at `now` (it reported or ended).
    fn stopped(&mut self, now: Instant) {
        if let Some(since) = self.running_since.take() {
            self.overlap.borrow_mut().stopped(now);
            self.last_run = now.duration_since(since);
            let since = |(clock, at): &(crate::cost::ThreadClock, Option<(u64, u64)>)| {
                let ((ran0, waited0), (ran1, waited1)) = ((*at)?, clock.read()?);
                Some((
                    Duration::from_nanos(ran1.saturating_sub(ran0)),
                    Duration::from_nanos(waited1.saturating_sub(waited0)),
                ))
            };
            self.last_run_cpu = self.vcpu.as_ref().and_then(since);
            self.last_run_main_loop = self.main_loop.as_ref().and_then(since);
        }
    }

    pub(crate) fn send(&mut self, answer: &Down) -> Result<()> {
        self.send_with(answer, None)
    }

    /// Sends `answer`, with the world's `readings` after it if there are any.
    pub(crate) fn send_with(&mut self, answer: &Down, readings: Option<Readings>) -> Result<()> {
        if let Some(down) = self.down.as_mut() {
            match readings {
                Some(r) => {
                    let flagged = Down {
                        flags: answer.flags | DOWN_READINGS,
                        ..*answer
                    };
                    let mut m = flagged.encode().to_vec();
                    m.extend_from_slice(&r.encode());
                    down.write_all(&m)?;
                }
                None => down.write_all(&answer.encode())?,
            }
            if answer.flags & amiro_trace::robot_link::DOWN_END == 0 {
                self.run_from(Instant::now());
            }
        }
        Ok(())
    }

    pub(crate) fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            if !crate::cost::ended(child.id()) {
                let _ = child.kill();
            }
            // Reaped here with what it cost (not through `child`, which is dropped unwaited).
            self.cost += crate::cost::reap(child.id());
        }
        while self.drain() {}
        self.flush_partial();
        self.ready.append(&mut self.lines);
        self.alive = false;
        self.next = None;
        self.stopped(Instant::now());
    }
}

/// A board's new lines behind its name, each handler event's text line before its `# T` record
/// (as the single-board runner prints them).
pub(crate) fn board_lines(b: &mut Board) -> Vec<String> {
    let lines = std::mem::take(&mut b.ready);
    if lines.is_empty() {
        return Vec::new();
    }
    let text = crate::log::with_event_lines(&(lines.join("\n") + "\n"));
    text.lines()
        .map(|l| format!("{}: {l}", NODES[b.index]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_qemu_keeps_what_the_last_one_printed_until_the_host_emits_it() {
        let firmware = Firmware {
            elf: "none.elf".into(),
            machine: "netduino2",
        };
        let mut b = Board::new(2, 2, firmware, "board-2".into(), false);
        // Its report at the reset's boundary was taken (those lines are ready), a line after it
        // and one cut short are still in the pipe's buffers when the host stops it.
        b.ready
            .push("# (0.010110) trace led-set led=3 rgb=FF8020".into());
        b.lines.push("# after the report".into());
        b.partial.extend_from_slice(b"# cut short");
        b.stop();
        b.new_console();
        assert_eq!(
            board_lines(&mut b),
            [
                "lightring: # (0.010110) trace led-set led=3 rgb=FF8020",
                "lightring: # after the report",
                "lightring: # cut short",
            ]
        );
    }
}
