//! What a run costs the machine, in figures that do not depend on its load: the CPU time of each
//! board's QEMU (user and kernel, all its threads, from `wait4` when the host reaps it), its task
//! switches and its read and write system calls (`/proc/PID/io`, read while it is a zombie: the
//! exchange's pipe, the semihosting writes of its console and trace, QEMU's own event
//! notifications), and the host's CPU time (`getrusage`). `cargo xtask robot --bench` prints
//! them per virtual second (docs/qemu.md, "Speed").
use std::ops::AddAssign;

/// One process's cost, summed over its starts (a board reset starts a new QEMU).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct Cost {
    /// CPU seconds in user space.
    pub user_s: f64,
    /// CPU seconds in the kernel.
    pub sys_s: f64,
    /// Task switches where it waited (a blocking read, a lock, the main loop's poll).
    pub voluntary: u64,
    /// Task switches where the scheduler took the core from it.
    pub involuntary: u64,
    /// `read`-family system calls.
    pub reads: u64,
    /// `write`-family system calls.
    pub writes: u64,
}

impl AddAssign for Cost {
    fn add_assign(&mut self, o: Self) {
        self.user_s += o.user_s;
        self.sys_s += o.sys_s;
        self.voluntary += o.voluntary;
        self.involuntary += o.involuntary;
        self.reads += o.reads;
        self.writes += o.writes;
    }
}

impl Cost {
    /// What was spent since `before` (an earlier reading of the same process).
    pub fn since(&self, before: &Self) -> Self {
        Self {
            user_s: self.user_s - before.user_s,
            sys_s: self.sys_s - before.sys_s,
            voluntary: self.voluntary.saturating_sub(before.voluntary),
            involuntary: self.involuntary.saturating_sub(before.involuntary),
            reads: self.reads.saturating_sub(before.reads),
            writes: self.writes.saturating_sub(before.writes),
        }
    }

    /// CPU seconds, user and kernel.
    pub fn cpu_s(&self) -> f64 {
        self.user_s + self.sys_s
    }

    /// Task switches of both kinds.
    pub fn switches(&self) -> u64 {
        self.voluntary + self.involuntary
    }
}

fn seconds(t: libc::timeval) -> f64 {
    t.tv_sec as f64 + t.tv_usec as f64 / 1e6
}

fn from_rusage(u: &libc::rusage) -> Cost {
    Cost {
        user_s: seconds(u.ru_utime),
        sys_s: seconds(u.ru_stime),
        voluntary: u.ru_nvcsw as u64,
        involuntary: u.ru_nivcsw as u64,
        reads: 0,
        writes: 0,
    }
}

/// This process's CPU time and task switches so far (the host: the bus model, the coordinator).
pub fn own() -> Cost {
    // SAFETY: getrusage fills the structure we own.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: as above.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    from_rusage(&u)
}

/// Whether child `pid` has ended, without reaping it (its `/proc` entry stays for [`reap`]).
pub(crate) fn ended(pid: u32) -> bool {
    // Not ours any more (already reaped) counts as ended.
    !matches!(wait_leaving_zombie(pid, libc::WNOHANG), Some(0))
}

/// `waitid` for child `pid`'s end with `WNOWAIT` (the child stays waitable) and `flags`: `None`
/// when the call fails (not our child, or already reaped), else the pid it reports (0: no change
/// yet, under `WNOHANG`).
fn wait_leaving_zombie(pid: u32, flags: libc::c_int) -> Option<libc::pid_t> {
    // SAFETY: waitid fills the structure we own.
    let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
    // SAFETY: as above.
    let r = unsafe {
        libc::waitid(
            libc::P_PID,
            pid as libc::id_t,
            &mut info,
            libc::WEXITED | libc::WNOWAIT | flags,
        )
    };
    // SAFETY: si_pid is valid for a child state change, and 0 when none happened.
    (r == 0).then(|| unsafe { info.si_pid() })
}

/// The read and write system calls of process `pid` so far (`None` where `/proc` has none).
fn io_calls(pid: u32) -> Option<(u64, u64)> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/io")).ok()?;
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().parse().ok())
    };
    Some((field("syscr:")?, field("syscw:")?))
}

/// Waits for child `pid` to end and reaps it: its CPU time and task switches (all its threads),
/// and its system calls as its zombie's `/proc` entry counts them. Once this returns the child is
/// gone: the caller must not wait for it again.
pub(crate) fn reap(pid: u32) -> Cost {
    // WNOWAIT leaves the zombie for wait4 below, its `/proc` entry readable meanwhile.
    let calls = wait_leaving_zombie(pid, 0).and_then(|_| io_calls(pid));
    // SAFETY: wait4 fills the structures we own.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let mut status = 0;
    // SAFETY: as above.
    let reaped = unsafe { libc::wait4(pid as libc::pid_t, &mut status, 0, &mut usage) };
    let mut cost = if reaped == pid as libc::pid_t {
        from_rusage(&usage)
    } else {
        Cost::default()
    };
    if let Some((reads, writes)) = calls {
        cost.reads = reads;
        cost.writes = writes;
    }
    cost
}

/// How the boards' emulation overlapped in wall time: a board runs from the answer that sends it
/// on to its next report (its QEMU emulates meanwhile, or waits for a core); the wall time with
/// none, one, two or three boards running. Two boards running side by side is what two cores
/// give: a run with little of it waits for one board while the other emulates.
#[derive(Debug, Default, Clone, Copy)]
pub struct Overlap {
    /// Wall µs with 0, 1, 2 and 3 boards running.
    pub running_us: [u64; 4],
    /// Boards running now.
    running: usize,
    /// When `running` last changed.
    since: Option<std::time::Instant>,
}

impl Overlap {
    fn change(&mut self, now: std::time::Instant, by: isize) {
        if let Some(since) = self.since {
            let slot = self.running.min(3);
            self.running_us[slot] += now.duration_since(since).as_micros() as u64;
        }
        self.running = self.running.saturating_add_signed(by);
        self.since = Some(now);
    }

    /// A board was sent on (its answer written).
    pub(crate) fn started(&mut self, now: std::time::Instant) {
        self.change(now, 1);
    }

    /// A board reported (or ended).
    pub(crate) fn stopped(&mut self, now: std::time::Instant) {
        self.change(now, -1);
    }

    /// Wall µs with at least one board running.
    pub fn busy_us(&self) -> u64 {
        self.running_us[1..].iter().sum()
    }

    /// Wall µs with two or more boards running side by side.
    pub fn side_by_side_us(&self) -> u64 {
        self.running_us[2..].iter().sum()
    }
}

/// The machine's processors' time (`/proc/stat`'s first line, in clock ticks): all of it, and the
/// part the hypervisor gave to other guests ("steal"). On a virtual machine that shares its host
/// the steal is wall time in which this machine's cores ran nothing of its own; the run reports
/// it beside its real-time factor, since no scheduling inside the machine can win it back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Machine {
    /// Every state's ticks summed (user, nice, system, idle, iowait, irq, softirq, steal).
    pub total: u64,
    /// The steal ticks.
    pub steal: u64,
}

impl Machine {
    /// Now (`None` where `/proc/stat` is not readable, as off Linux).
    pub fn now() -> Option<Self> {
        Self::parse(&std::fs::read_to_string("/proc/stat").ok()?)
    }

    /// From `/proc/stat`'s text: its `cpu ` line's first eight fields (guest time is already
    /// inside user and nice, so the fields after steal are not added).
    pub fn parse(text: &str) -> Option<Self> {
        let line = text.lines().find(|l| l.starts_with("cpu "))?;
        let fields: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .take(8)
            .map(str::parse)
            .collect::<Result<_, _>>()
            .ok()?;
        (fields.len() == 8).then(|| Self {
            total: fields.iter().sum(),
            steal: fields[7],
        })
    }

    /// What passed since `before`.
    pub fn since(&self, before: &Self) -> Self {
        Self {
            total: self.total.saturating_sub(before.total),
            steal: self.steal.saturating_sub(before.steal),
        }
    }

    /// The share of the cores' time stolen (0.0-1.0; 0 with no time passed).
    pub fn steal_share(&self) -> f64 {
        if self.total == 0 {
            0.0
        } else {
            self.steal as f64 / self.total as f64
        }
    }
}

/// A live board's QEMU's vCPU thread's scheduler clock (`/proc/PID/task/TID/schedstat`): the
/// nanoseconds it ran and waited for a core, so a board run that took long in wall time is told
/// apart as emulation (its CPU) or a wait behind other work on the machine.
pub(crate) struct ThreadClock(std::fs::File);

impl ThreadClock {
    /// The vCPU thread of QEMU process `pid` (QEMU started with `-name …,debug-threads=on` calls
    /// it `ALL CPUs/TCG` under `-icount`, `CPU 0/TCG` otherwise), if there is one.
    pub(crate) fn vcpu(pid: u32) -> Option<Self> {
        let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
        tasks.flatten().find_map(|task| {
            let comm = std::fs::read_to_string(task.path().join("comm")).ok()?;
            comm.trim_end()
                .ends_with("/TCG")
                .then(|| std::fs::File::open(task.path().join("schedstat")).ok())
                .flatten()
                .map(Self)
        })
    }

    /// The calling thread (`/proc/thread-self`): a live run's host.
    pub(crate) fn own() -> Option<Self> {
        std::fs::File::open("/proc/thread-self/schedstat")
            .ok()
            .map(Self)
    }

    /// The main loop of QEMU process `pid`: its first thread, whose thread id is the process id.
    pub(crate) fn main_loop(pid: u32) -> Option<Self> {
        std::fs::File::open(format!("/proc/{pid}/task/{pid}/schedstat"))
            .ok()
            .map(Self)
    }

    /// Nanoseconds on a core and waiting for one, so far.
    pub(crate) fn read(&self) -> Option<(u64, u64)> {
        use std::os::unix::fs::FileExt;
        let mut buf = [0u8; 96];
        let n = self.0.read_at(&mut buf, 0).ok()?;
        let text = std::str::from_utf8(&buf[..n]).ok()?;
        let mut fields = text.split_whitespace().map(|f| f.parse::<u64>().ok());
        Some((fields.next()??, fields.next()??))
    }
}

/// A board's reports made more than a quantum after the boundary they are for: the board's
/// exchange ran late (held off by work of the exchange's priority or above, a critical section, or
/// a deadline its clock missed), so the host's answer for that boundary, a frame due in the quantum
/// after it, reached the board late. Expected none; the table names them (docs/qemu.md, "What the
/// clock's readings cost").
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Late {
    /// How many.
    pub reports: u64,
    /// The latest, µs after its boundary.
    pub worst_us: u64,
}

impl Late {
    /// Takes a report for the boundary at `at_us` made at the board's `now_us`.
    pub fn note(&mut self, at_us: u64, now_us: u64) {
        let after = now_us.saturating_sub(at_us);
        if after > crate::QUANTUM_US {
            self.reports += 1;
            self.worst_us = self.worst_us.max(after);
        }
    }
}

/// Where a run's CPU went, one row per board's QEMU and one for the host, per virtual second of
/// `virtual_s` and per board exchange; then the CPU summed and what it means for two cores (the
/// QEMUs overlap there at best), and the boards' late reports if there were any ([`Late`]).
pub fn table(work: &crate::Work, virtual_s: f64) -> String {
    use std::fmt::Write;
    let per = |x: f64| x / virtual_s.max(1e-9);
    let mut out = format!(
        "  {:<13} {:>9} {:>7} {:>7} {:>9} {:>8} {:>8} | per exchange: {:>8} {:>6} {:>6} {:>7}\n",
        "per virtual s",
        "exchanges",
        "usr s",
        "sys s",
        "switches",
        "reads",
        "writes",
        "switches",
        "reads",
        "writes",
        "CPU µs"
    );
    for (k, c) in work.boards.iter().enumerate() {
        let exchanges = work.per_board[k];
        let each = |x: f64| {
            if exchanges == 0 {
                "-".to_string()
            } else {
                format!("{:.1}", x / exchanges as f64)
            }
        };
        let _ = writeln!(
            out,
            "  {:<13} {:>9.0} {:>7.3} {:>7.3} {:>9.0} {:>8.0} {:>8.0} | {:>22} {:>6} {:>6} {:>7}",
            crate::NODES[k],
            per(exchanges as f64),
            per(c.user_s),
            per(c.sys_s),
            per(c.switches() as f64),
            per(c.reads as f64),
            per(c.writes as f64),
            each(c.switches() as f64),
            each(c.reads as f64),
            each(c.writes as f64),
            each(c.cpu_s() * 1e6),
        );
    }
    let h = &work.host;
    let _ = writeln!(
        out,
        "  {:<13} {:>9} {:>7.3} {:>7.3} {:>9.0} {:>8} {:>8} |",
        "host",
        "",
        per(h.user_s),
        per(h.sys_s),
        per(h.switches() as f64),
        "",
        ""
    );
    let qemu: f64 = work.boards.iter().map(Cost::cpu_s).sum();
    let all = qemu + h.cpu_s();
    let _ = writeln!(
        out,
        "  CPU per virtual s: {:.3} s (QEMUs {:.3}, host {:.3}): at best {:.3} s of wall per virtual s on 2 cores, {:.3} on one",
        per(all),
        per(qemu),
        per(h.cpu_s()),
        per(all) / 2.0,
        per(all)
    );
    let o = &work.overlap;
    let busiest = work.boards.iter().map(Cost::cpu_s).fold(0.0, f64::max);
    let _ = writeln!(
        out,
        "  wall per virtual s with the boards running: none {:.3}, one {:.3}, two or more side by side {:.3}; the busiest QEMU's CPU {:.3}",
        per(o.running_us[0] as f64 / 1e6),
        per(o.running_us[1] as f64 / 1e6),
        per(o.side_by_side_us() as f64 / 1e6),
        per(busiest),
    );
    if let Some(m) = work.machine {
        let _ = writeln!(
            out,
            "  the machine's cores were taken by its hypervisor for {:.1} % of the run (steal, /proc/stat): a share no scheduling here wins back",
            m.steal_share() * 100.0
        );
    }
    let late: Vec<String> = work
        .late
        .iter()
        .zip(crate::NODES)
        .filter(|(l, _)| l.reports > 0)
        .map(|(l, node)| format!("{node} {} (the latest {} µs after)", l.reports, l.worst_us))
        .collect();
    if !late.is_empty() {
        let _ = writeln!(
            out,
            "  reports more than a quantum after their boundary: {}",
            late.join(", ")
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_more_than_a_quantum_late_is_counted_with_the_latest() {
        let mut late = Late::default();
        late.note(30_040, 30_050);
        late.note(30_040, 30_040 + crate::QUANTUM_US);
        assert_eq!(late, Late::default());
        late.note(30_840, 31_540);
        late.note(95_520, 95_860);
        assert_eq!(
            late,
            Late {
                reports: 2,
                worst_us: 700
            }
        );
        let work = crate::Work {
            late: [late, Late::default(), Late::default()],
            ..crate::Work::default()
        };
        let text = table(&work, 1.0);
        assert!(
            text.contains("after their boundary: diwheeldrive 2 (the latest 700 µs after)"),
            "{text}"
        );
        assert!(!table(&crate::Work::default(), 1.0).contains("after their boundary"));
    }

    #[test]
    fn the_machines_steal_is_read_from_proc_stat_and_shared_over_all_its_time() {
        let before = Machine::parse("cpu  100 0 50 800 10 0 5 35 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\n")
            .expect("a cpu line");
        assert_eq!(
            before,
            Machine {
                total: 1000,
                steal: 35
            }
        );
        let after = Machine::parse("cpu  300 0 150 1200 10 0 5 335 7 0\n").expect("a cpu line");
        let run = after.since(&before);
        assert_eq!(
            run,
            Machine {
                total: 1000,
                steal: 300
            }
        );
        assert!((run.steal_share() - 0.3).abs() < 1e-9);
        // A line too short, or not a number, is no reading.
        assert_eq!(Machine::parse("cpu  1 2 3\n"), None);
        assert_eq!(Machine::parse("cpu  1 2 3 x 5 6 7 8\n"), None);
        assert_eq!(Machine::default().steal_share(), 0.0);
        let work = crate::Work {
            machine: Some(run),
            ..crate::Work::default()
        };
        assert!(
            table(&work, 1.0).contains("hypervisor for 30.0 % of the run"),
            "{}",
            table(&work, 1.0)
        );
        assert!(!table(&crate::Work::default(), 1.0).contains("hypervisor"));
    }

    #[test]
    fn a_child_that_reads_and_writes_is_reaped_with_its_calls_and_cpu() {
        // A shell that spins a little and writes 200 lines to /dev/null, one write each.
        let child = std::process::Command::new("sh")
            .args([
                "-c",
                "i=0; while [ $i -lt 200 ]; do echo $i; i=$((i+1)); done >/dev/null",
            ])
            .spawn()
            .expect("sh starts");
        let pid = child.id();
        while !ended(pid) {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        // Ended, not reaped: still a zombie with its /proc entry.
        assert!(std::path::Path::new(&format!("/proc/{pid}")).exists());
        let cost = reap(pid);
        assert!(cost.writes >= 200, "{cost:?}");
        assert!(!std::path::Path::new(&format!("/proc/{pid}/io")).exists());
        // Once reaped it counts as ended (it is no child of ours any more).
        assert!(ended(pid));
        std::mem::forget(child);
    }

    #[test]
    fn a_thread_clock_counts_the_cpu_a_thread_spends() {
        // This test's own thread, as a live run's host reads its own.
        let clock = ThreadClock::own().expect("schedstat is readable");
        // The thread's CPU as getrusage counts it (µs), whatever the machine's load.
        let thread_cpu = || {
            // SAFETY: getrusage fills the structure we own.
            let mut u: libc::rusage = unsafe { std::mem::zeroed() };
            // SAFETY: as above.
            unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut u) };
            (seconds(u.ru_utime) + seconds(u.ru_stime)) * 1e6
        };
        let (before, _) = clock.read().expect("two numbers");
        let from = thread_cpu();
        // Spin until the thread has run 20 ms on a core (at most 10 s of wall time).
        let spin = std::time::Instant::now();
        while thread_cpu() - from < 20_000.0 && spin.elapsed().as_secs() < 10 {
            std::hint::black_box(0u64);
        }
        let (after, _) = clock.read().expect("two numbers");
        assert!(after - before >= 10_000_000, "{before} -> {after}");
        // Not a QEMU: no vCPU thread; the process's first thread (a QEMU's main loop) is there.
        assert!(ThreadClock::vcpu(std::process::id()).is_none());
        assert!(ThreadClock::main_loop(std::process::id())
            .and_then(|c| c.read())
            .is_some());
    }

    #[test]
    fn costs_add_up() {
        let mut a = Cost {
            user_s: 1.0,
            sys_s: 0.5,
            voluntary: 3,
            involuntary: 4,
            reads: 5,
            writes: 6,
        };
        a += a;
        assert_eq!(
            a,
            Cost {
                user_s: 2.0,
                sys_s: 1.0,
                voluntary: 6,
                involuntary: 8,
                reads: 10,
                writes: 12,
            }
        );
    }
}
