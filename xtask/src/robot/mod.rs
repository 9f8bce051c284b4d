//! `cargo xtask robot`: the QEMU builds of DiWheelDrive, PowerManagement and LightRing on one
//! simulated CAN bus (`amiro-bus-sim`), with the system lines between them, in lock-step.
//!
//! Each board's QEMU trades with this coordinator every [`QUANTUM_US`] of virtual time through
//! two named pipes in its work directory (`amiro-firmware/src/qemu/robot.rs` is the other side).
//! A board blocked in that read stands still in virtual time, so the coordinator decides when each
//! quantum ends: once every board has handed over the frames it queued before the boundary, the
//! bus model runs every transmission that starts before it, and each board gets the frame that
//! completes in its next quantum (at most one: a frame takes at least 44 bit times) with the
//! levels of SYS_SYNC_N (wired-AND) and SYS_PD_N. Everything happens at fixed virtual times, so a
//! run is a function of its stimulus: two runs print the same bytes.
//!
//! The output is the single-board runner's: every frame on the bus as a `candump -l` line stamped
//! with the virtual time it completed, each board's `#` lines behind its name, and the bus's own
//! notes (error frames, line levels) behind `bus:`.
use std::collections::VecDeque;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use amiro_bus_sim::{BitFault, Bus, ErrorState, Event, Frame, NodeId, MAILBOXES};
use anyhow::{bail, Context, Result};

pub mod cli;
pub mod report;
pub mod scenarios;
pub mod slcan;
pub mod stimulus;

use stimulus::{Action, Timed, BOARDS};

pub use amiro_trace::robot_link::QUANTUM_US;
use amiro_trace::robot_link::{
    Down, Up, DOWN_END, DOWN_FRAME, DOWN_OWN, DOWN_PD_LOW, DOWN_SYNC_LOW, DRIVES_PD_LOW,
    DRIVES_SYNC_LOW, UP_LEN,
};
/// The operator's adapter: the fourth node, after the boards.
pub const OPERATOR: usize = 3;
/// Names of the bus's nodes, in order.
pub const NODES: [&str; 4] = ["diwheeldrive", "powermgmt", "lightring", "operator"];

/// A board's QEMU build and machine.
#[derive(Debug, Clone)]
pub struct Firmware {
    /// The ELF.
    pub elf: PathBuf,
    /// The QEMU machine.
    pub machine: &'static str,
}

/// A frame as it went over the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transfer {
    /// The transmitter (an index into [`NODES`]).
    pub node: usize,
    /// Its mailbox.
    pub mailbox: usize,
    /// The frame.
    pub frame: Frame,
    /// When its node queued it (put it into a mailbox).
    pub queued_at: u64,
    /// When it entered its node's transmit queue (a board's driver gives one frame of an
    /// identifier a mailbox at a time, so a sample's later frames wait there): where its response
    /// starts. The adapter's and a babbling controller's frames: when queued.
    pub released_at: u64,
    /// Start of frame of the attempt that succeeded.
    pub start: u64,
    /// Completion.
    pub end: u64,
}

/// What a robot run produced.
#[derive(Debug, Default)]
pub struct Outcome {
    /// Everything printed, in order.
    pub text: String,
    /// Every frame that went over the bus, in order.
    pub transfers: Vec<Transfer>,
    /// Error frames on the bus.
    pub error_frames: usize,
    /// The virtual time the run ended at (µs).
    pub ended_at: u64,
    /// Exchanges with the boards (quanta in which nothing could happen are skipped).
    pub exchanges: u64,
}

struct Board {
    index: usize,
    firmware: Firmware,
    dir: PathBuf,
    child: Option<Child>,
    up: Option<File>,
    down: Option<File>,
    out: Option<ChildStdout>,
    partial: Vec<u8>,
    lines: Vec<String>,
    /// Global virtual time of the board's clock zero (its last start).
    offset: u64,
    alive: bool,
    drives: u8,
    /// Global virtual time before which the board does nothing of its own (its last report).
    wakes_at: u64,
    /// Mailboxes (bit per mailbox) whose abort it asked for in its last report, and those whose
    /// frame the bus gave back (the answer tells it).
    aborts: u8,
    aborted: u8,
    /// Per mailbox, when the frame in it was released into the board's transmit queue.
    released: [u64; MAILBOXES],
}

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

fn set_nonblocking(fd: i32) {
    // SAFETY: fcntl on a descriptor we own.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK);
    }
}

impl Board {
    fn start(&mut self, at: u64) -> Result<()> {
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
            crate::qemu::encode_stimulus(&[], 0),
        )?;
        let stderr = File::create(self.dir.join("qemu-stderr.log"))?;
        let mut child = Command::new("qemu-system-arm")
            .args(["-machine", self.firmware.machine, "-nographic"])
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
                &format!("shift={},align=off,sleep=off", crate::qemu::ICOUNT_SHIFT),
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
        self.out = Some(out);
        self.child = Some(child);
        self.partial.clear();
        self.offset = at;
        self.alive = true;
        // A module holds SYS_SYNC_N low until it is initialised.
        self.drives = DRIVES_SYNC_LOW;
        self.wakes_at = at;
        self.aborts = 0;
        self.aborted = 0;
        self.released = [at; MAILBOXES];
        Ok(())
    }

    /// Reads what the board printed so far (never blocks); `false` once its output has closed.
    fn drain(&mut self) -> bool {
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
    fn receive(&mut self, guard: Instant, limit: Duration) -> Result<Option<Up>> {
        let mut message = [0u8; UP_LEN];
        let mut got = 0;
        let up_fd = self.up.as_ref().context("no pipe")?.as_raw_fd();
        loop {
            let out_fd = self.out.as_ref().map_or(-1, AsRawFd::as_raw_fd);
            let mut fds = [
                libc::pollfd {
                    fd: up_fd,
                    events: libc::POLLIN,
                    revents: 0,
                },
                libc::pollfd {
                    fd: out_fd,
                    events: libc::POLLIN,
                    revents: 0,
                },
            ];
            // SAFETY: two pollfd structures we own; a negative fd is ignored by poll.
            let ready = unsafe { libc::poll(fds.as_mut_ptr(), 2, 100) };
            if fds[1].revents != 0 {
                self.drain();
            }
            if fds[0].revents & libc::POLLIN != 0 {
                let n = self
                    .up
                    .as_mut()
                    .context("no pipe")?
                    .read(&mut message[got..])?;
                got += n;
                if got == UP_LEN {
                    // Everything the board printed before this exchange is in its pipe by now.
                    self.drain();
                    return Ok(Some(Up::decode(&message)));
                }
                continue;
            }
            if ready <= 0 || self.out.is_none() {
                if let Some(child) = self.child.as_mut() {
                    if child.try_wait()?.is_some() {
                        while self.drain() {}
                        self.flush_partial();
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

    fn send(&mut self, answer: &Down) -> Result<()> {
        if let Some(down) = self.down.as_mut() {
            down.write_all(&answer.encode())?;
        }
        Ok(())
    }

    fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
        while self.drain() {}
        self.flush_partial();
        self.alive = false;
    }
}

/// A board's new lines behind its name, each handler event's text line before its `# T` record
/// (as the single-board runner prints them).
fn board_lines(b: &mut Board) -> Vec<String> {
    let lines = std::mem::take(&mut b.lines);
    if lines.is_empty() {
        return Vec::new();
    }
    let text = crate::qemu::with_event_lines(&(lines.join("\n") + "\n"));
    text.lines()
        .map(|l| format!("{}: {l}", NODES[b.index]))
        .collect()
}

/// Formats a completed frame as a `candump -l` line.
pub fn candump_line(end: u64, frame: &Frame) -> String {
    let data: String = frame.payload().iter().map(|b| format!("{b:02X}")).collect();
    format!(
        "({}.{:06}) can0 {:03X}#{data}",
        end / 1_000_000,
        end % 1_000_000,
        frame.id
    )
}

fn stamp(t: u64) -> String {
    format!("({}.{:06})", t / 1_000_000, t % 1_000_000)
}

/// What the coordinator's output goes to as it is produced.
pub trait Sink {
    /// One output line (without its newline).
    fn line(&mut self, line: &str);
}

impl Sink for Vec<String> {
    fn line(&mut self, line: &str) {
        self.push(line.to_string());
    }
}

/// A live run (`--slcan`): paced to the wall clock, the adapter a client drives, stopped by Ctrl-C.
pub struct Live {
    /// The SLCAN pseudo-terminal.
    pub slcan: slcan::Slcan,
    /// Set by Ctrl-C.
    pub stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

/// When the next exchange is due after the one at `t`: one quantum on, or, while the bus is idle
/// (no frame queued, none on its way to a board, none heard in the coming quantum: `busy`
/// otherwise, as in a live run) and no board has work, the quantum in which the
/// first board's next deadline, the next stimulus action or the run's end falls. No board acts
/// before its deadline but on a frame or a line level from the bus, and the bus has none to give,
/// so every frame and line change lands in the same quantum as it would quantum by quantum.
#[allow(clippy::too_many_arguments)]
fn next_exchange(
    t: u64,
    duration_us: u64,
    boards: &[Board],
    bus: &Bus,
    nodes: &[NodeId],
    operator: &VecDeque<(u64, Frame)>,
    deliveries: &VecDeque<Transfer>,
    next_action: Option<u64>,
    busy: bool,
) -> u64 {
    let step = t + QUANTUM_US;
    let bus_idle = operator.is_empty()
        && deliveries.is_empty()
        && nodes
            .iter()
            .all(|&n| bus.mailboxes(n).iter().all(Option::is_none) && !bus.babbling(n, t));
    if busy || !bus_idle {
        return step;
    }
    // An action at `a` is taken at the first boundary after it; a deadline at `w` is seen at the
    // first boundary at or after it; the run ends at the first boundary at or after its duration.
    let after = |a: u64| (a / QUANTUM_US + 1) * QUANTUM_US;
    let at_or_after = |w: u64| w.div_ceil(QUANTUM_US) * QUANTUM_US;
    let mut until = at_or_after(duration_us);
    if let Some(a) = next_action {
        until = until.min(after(a));
    }
    for b in boards.iter().filter(|b| b.alive) {
        until = until.min(at_or_after(b.wakes_at));
    }
    until.max(step)
}

/// Runs the robot for `duration_us` of virtual time against `actions`, in `work`; with `live`,
/// paced to the wall clock with a client's adapter on the bus.
pub fn run(
    firmware: &[Firmware; 3],
    actions: &[Timed],
    duration_us: u64,
    work: &Path,
    sink: &mut dyn Sink,
    mut live: Option<&mut Live>,
) -> Result<Outcome> {
    let wall_start = Instant::now();
    std::fs::create_dir_all(work)?;
    let mut bus = Bus::new();
    let mut boards: Vec<Board> = (0..3)
        .map(|k| Board {
            index: k,
            firmware: firmware[k].clone(),
            dir: work.join(BOARDS[k]),
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
        })
        .collect();
    let nodes: Vec<NodeId> = (0..4).map(|_| bus.add_node()).collect();
    for b in &mut boards {
        b.start(0)?;
    }
    let mut outcome = Outcome::default();
    let emit = |outcome: &mut Outcome, sink: &mut dyn Sink, line: String| {
        sink.line(&line);
        outcome.text.push_str(&line);
        outcome.text.push('\n');
    };
    let mut pending = actions.iter().peekable();
    let mut operator: VecDeque<(u64, Frame)> = VecDeque::new();
    let mut deliveries: VecDeque<Transfer> = VecDeque::new();
    let mut pd_from_outside = false;
    let (mut sync_low, mut pd_low) = (true, false);
    let limit = Duration::from_secs(30);
    let mut t = 0;
    let result: Result<()> = (|| loop {
        t += QUANTUM_US;
        outcome.exchanges += 1;
        let mut notes: Vec<String> = Vec::new();
        for b in boards.iter_mut().filter(|b| b.alive) {
            match b.receive(Instant::now(), limit)? {
                Some(report) => {
                    b.drives = report.drives;
                    b.aborts = report.aborts & 0b111;
                    b.wakes_at = match report.sleeps_us {
                        u32::MAX => u64::MAX,
                        us => t.saturating_add(u64::from(us)),
                    };
                    for q in report.queued() {
                        let queued = q.at_us + b.offset;
                        if let Some(slot) = b.released.get_mut(usize::from(q.mailbox)) {
                            *slot = q.released_us.min(q.at_us) + b.offset;
                        }
                        let Some(frame) = Frame::new(q.id, q.payload()) else {
                            notes.push(format!(
                                "bus: # {} {} queued an invalid frame",
                                stamp(t),
                                NODES[b.index]
                            ));
                            continue;
                        };
                        if let Err(e) =
                            bus.queue(nodes[b.index], usize::from(q.mailbox), frame, queued)
                        {
                            notes.push(format!(
                                "bus: # {} {}: mailbox {}: {e:?}",
                                stamp(t),
                                NODES[b.index],
                                q.mailbox
                            ));
                        }
                    }
                }
                None => {
                    // The board ended (its hand-over, or a failure): off the bus from here on.
                    b.alive = false;
                    b.drives = 0;
                    bus.reset_node(nodes[b.index], t);
                    bus.set_plugged(nodes[b.index], false, t);
                    notes.push(format!(
                        "bus: # {} {} left the bus (its run ended)",
                        stamp(t),
                        NODES[b.index]
                    ));
                }
            }
        }
        while let Some(a) = pending.next_if(|a| a.at_us < t) {
            match &a.action {
                Action::Frame { id, data } => {
                    if let Some(frame) = Frame::new(*id, data) {
                        operator.push_back((a.at_us, frame));
                    }
                }
                Action::PowerDown => pd_from_outside = true,
                Action::Reset(k) => {
                    let b = &mut boards[*k];
                    b.stop();
                    bus.reset_node(nodes[*k], t);
                    notes.push(format!("bus: # {} {} reset", stamp(t), NODES[*k]));
                    b.start(t)?;
                }
                Action::Unplug(k) => {
                    bus.set_plugged(nodes[*k], false, a.at_us);
                    notes.push(format!("bus: # {} {} unplugged", stamp(a.at_us), NODES[*k]));
                }
                Action::Plug(k) => {
                    bus.set_plugged(nodes[*k], true, a.at_us);
                    notes.push(format!(
                        "bus: # {} {} plugged back in",
                        stamp(a.at_us),
                        NODES[*k]
                    ));
                }
                Action::Babble { board, id, data } => {
                    if let Some(frame) = Frame::new(*id, data) {
                        bus.babble(nodes[*board], frame, a.at_us, u64::MAX);
                        notes.push(format!(
                            "bus: # {} {}'s CAN controller babbles {:03X} back to back",
                            stamp(a.at_us),
                            NODES[*board],
                            id
                        ));
                    }
                }
                Action::Quiet(board) => {
                    bus.stop_babbling(nodes[*board], a.at_us);
                    notes.push(format!(
                        "bus: # {} {}'s CAN controller stops babbling",
                        stamp(a.at_us),
                        NODES[*board]
                    ));
                }
                Action::BitError(id) => bus.inject(BitFault {
                    id: *id,
                    not_before: a.at_us,
                    at_bit: 20,
                }),
            }
        }
        if let Some(live) = live.as_deref_mut() {
            for frame in live.slcan.poll() {
                operator.push_back((t, frame));
            }
            // Never ahead of the wall clock (behind it when the host is too slow).
            let ahead = Duration::from_micros(t).saturating_sub(wall_start.elapsed());
            if ahead > Duration::from_millis(2) {
                std::thread::sleep(ahead);
            }
        }
        // The adapter's three mailboxes, filled in the order the stimulus gives.
        for mailbox in 0..3 {
            if bus.mailboxes(nodes[OPERATOR])[mailbox].is_none() {
                if let Some((at, frame)) = operator.pop_front() {
                    let _ = bus.queue(nodes[OPERATOR], mailbox, frame, at);
                }
            }
        }
        for event in bus.run_until(t) {
            match event {
                Event::Sent {
                    node,
                    mailbox,
                    frame,
                    queued_at,
                    start,
                    end,
                    ..
                } => {
                    let released_at = boards
                        .get(node)
                        .and_then(|b| b.released.get(mailbox))
                        .copied()
                        .unwrap_or(queued_at);
                    let transfer = Transfer {
                        node,
                        mailbox,
                        frame,
                        queued_at,
                        released_at,
                        start,
                        end,
                    };
                    deliveries.push_back(transfer);
                    outcome.transfers.push(transfer);
                }
                Event::ErrorFrame {
                    node,
                    frame,
                    at,
                    kind,
                    ..
                } => {
                    outcome.error_frames += 1;
                    notes.push(format!(
                        "bus: # {} error frame: {kind:?} error in {:03X} from {}",
                        stamp(at),
                        frame.id,
                        NODES[node]
                    ));
                }
                Event::StateChange { node, at, state } => notes.push(format!(
                    "bus: # {} {} is {}",
                    stamp(at),
                    NODES[node],
                    match state {
                        ErrorState::Active => "error-active",
                        ErrorState::Passive => "error-passive",
                        ErrorState::BusOff => "bus-off",
                    }
                )),
            }
        }
        // Aborts take what has not started by this boundary (a frame that did, completes): the
        // request is as late as the exchange that carried it.
        for b in boards.iter_mut().filter(|b| b.alive) {
            for mailbox in (0..MAILBOXES).filter(|&k| b.aborts & 1 << k != 0) {
                if let Some(p) = bus.abort(nodes[b.index], mailbox) {
                    b.aborted |= 1 << mailbox;
                    notes.push(format!(
                        "bus: # {} {} aborts {:03X} in mailbox {mailbox} for a more urgent frame",
                        stamp(t),
                        NODES[b.index],
                        p.frame.id
                    ));
                }
            }
            b.aborts = 0;
        }
        let now_sync_low = boards.iter().any(|b| b.drives & DRIVES_SYNC_LOW != 0);
        if now_sync_low != sync_low {
            sync_low = now_sync_low;
            notes.push(if sync_low {
                let holders: Vec<&str> = boards
                    .iter()
                    .filter(|b| b.drives & DRIVES_SYNC_LOW != 0)
                    .map(|b| NODES[b.index])
                    .collect();
                format!(
                    "bus: # {} SYS_SYNC_N low (held by {})",
                    stamp(t),
                    holders.join(", ")
                )
            } else {
                format!(
                    "bus: # {} SYS_SYNC_N high (every module released it)",
                    stamp(t)
                )
            });
        }
        let pm_drives = boards[1].drives & DRIVES_PD_LOW != 0;
        if !pd_low && (pd_from_outside || pm_drives) {
            pd_low = true;
            notes.push(format!(
                "bus: # {} SYS_PD_N low (driven by {})",
                stamp(t),
                if pm_drives {
                    "powermgmt"
                } else {
                    "the stimulus"
                }
            ));
        }
        let end = t >= duration_us
            || live
                .as_deref()
                .is_some_and(|l| l.stop.load(std::sync::atomic::Ordering::Relaxed));
        let now = deliveries
            .front()
            .copied()
            .filter(|d| d.end < t + QUANTUM_US);
        if let Some(d) = now {
            deliveries.pop_front();
            if d.node != OPERATOR {
                if let Some(live) = live.as_deref_mut() {
                    live.slcan.deliver(d.end, &d.frame);
                }
            }
        }
        let next = if end {
            t + QUANTUM_US
        } else {
            next_exchange(
                t,
                duration_us,
                &boards,
                &bus,
                &nodes,
                &operator,
                &deliveries,
                pending.peek().map(|a| a.at_us),
                // Boards that hear a frame in the coming quantum act on it, as do those whose
                // aborted frame comes back.
                live.is_some() || now.is_some() || boards.iter().any(|b| b.aborted != 0),
            )
        };
        // A board restarted at this boundary has not traded yet: its first answer is the next one.
        for b in boards.iter_mut().filter(|b| b.alive && b.offset != t) {
            let mut answer = Down {
                next_us: next - b.offset,
                aborted: b.aborted,
                ..Down::default()
            };
            b.aborted = 0;
            if pd_low {
                answer.flags |= DOWN_PD_LOW;
            }
            if sync_low {
                answer.flags |= DOWN_SYNC_LOW;
            }
            if end {
                answer.flags |= DOWN_END;
            }
            if let Some(d) = now {
                // A frame that started before the board's last reset is no longer in its mailboxes.
                // A babbling controller's frame is the fault's, not the board's: it hears
                // nothing of it (a controller does not receive its own frames).
                let own = d.node == b.index && d.start >= b.offset && d.mailbox < MAILBOXES;
                let heard = d.node != b.index && bus.plugged(nodes[b.index]);
                if own || heard {
                    answer.flags |= DOWN_FRAME | if own { DOWN_OWN } else { 0 };
                    answer.at_us = d.end.saturating_sub(b.offset);
                    answer.mailbox = d.mailbox as u8;
                    answer.id = d.frame.id;
                    answer.len = d.frame.len;
                    answer.data = d.frame.data;
                }
            }
            b.send(&answer)?;
        }
        // What the boards printed in the quantum that ended, what the bus saw at its boundary, and
        // the frame that completes in the next one.
        for b in &mut boards {
            for line in board_lines(b) {
                emit(&mut outcome, sink, line);
            }
        }
        for note in notes {
            emit(&mut outcome, sink, note);
        }
        if let Some(d) = now {
            emit(&mut outcome, sink, candump_line(d.end, &d.frame));
        }
        if end {
            outcome.ended_at = t;
            return Ok(());
        }
        t = next - QUANTUM_US;
    })();
    // The boards print their end lines and exit; whatever they still say is kept.
    for b in &mut boards {
        let started = Instant::now();
        while b
            .child
            .as_mut()
            .is_some_and(|c| c.try_wait().ok().flatten().is_none())
            && started.elapsed() < Duration::from_secs(10)
        {
            b.drain();
            std::thread::sleep(Duration::from_millis(5));
        }
        b.stop();
        for line in board_lines(b) {
            emit(&mut outcome, sink, line);
        }
    }
    result?;
    Ok(outcome)
}
