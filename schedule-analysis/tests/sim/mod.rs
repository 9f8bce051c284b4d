//! Discrete-event simulators the analyses are checked against: an RTIC-like board scheduler (fixed priorities,
//! preemption only above the running priority, SRP locks raising it to the resource ceiling, equal priorities in
//! FIFO order) and a CAN bus (non-preemptive arbitration by identifier whenever the bus falls idle).
//!
//! Times are integer nanoseconds. The simulators know nothing of the analysis; they only replay job patterns.
#![allow(dead_code)]

/// A piece of a job: `length` ns, holding `lock` (a resource index) or no lock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segment {
    pub length: u64,
    pub lock: Option<usize>,
}

/// One job to replay on the board.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Job {
    pub task: usize,
    /// Nominal activation: responses are measured from here.
    pub arrival: u64,
    /// When it becomes ready (arrival + release jitter).
    pub release: u64,
    pub segments: Vec<Segment>,
}

/// Replays `jobs` (each task's jobs in release order) on a board with the given task priorities and resource
/// ceilings; returns every job's response (finish − arrival) in the order of `jobs`.
pub fn board_run(priorities: &[u32], ceilings: &[u32], jobs: &[Job]) -> Vec<u64> {
    struct Active {
        job: usize,
        segment: usize,
        left: u64,
    }
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by_key(|&j| (jobs[j].release, j));
    let mut response = vec![0u64; jobs.len()];
    // Released, not yet started jobs per task, oldest first: a task runs its jobs one after the other (RTIC
    // runs one instance of a task at a time).
    let mut queues: Vec<std::collections::VecDeque<usize>> =
        vec![Default::default(); priorities.len()];
    let mut busy_task = vec![false; priorities.len()];
    let mut stack: Vec<Active> = Vec::new();
    let mut next_release = 0usize; // index into `order` of the first job not yet released
    let mut t = 0u64;
    let mut finished = 0usize;

    let running_priority = |stack: &Vec<Active>| -> Option<u32> {
        stack
            .iter()
            .map(|a| {
                let job = &jobs[a.job];
                let own = priorities[job.task];
                // A lock is held once its segment has started running: at a segment boundary nothing is held,
                // so back-to-back critical sections do not merge into one.
                match job.segments.get(a.segment) {
                    Some(Segment {
                        lock: Some(r),
                        length,
                    }) if a.left < *length => own.max(ceilings[*r]),
                    _ => own,
                }
            })
            .max()
    };

    while finished < jobs.len() {
        while next_release < order.len() && jobs[order[next_release]].release <= t {
            let j = order[next_release];
            queues[jobs[j].task].push_back(j);
            next_release += 1;
        }
        // A segment that ends now ends before anything released now can preempt it.
        if let Some(top) = stack.last_mut() {
            if top.left == 0 {
                top.segment += 1;
                match jobs[top.job].segments.get(top.segment) {
                    Some(s) => top.left = s.length,
                    None => {
                        let j = top.job;
                        response[j] = t - jobs[j].arrival;
                        busy_task[jobs[j].task] = false;
                        finished += 1;
                        stack.pop();
                    }
                }
                continue;
            }
        }
        // The job that would start: highest priority, then earliest release (FIFO within a level).
        let candidate = queues
            .iter()
            .enumerate()
            .filter(|(task, _)| !busy_task[*task])
            .filter_map(|(_, q)| q.front().copied())
            .min_by_key(|&j| {
                (
                    std::cmp::Reverse(priorities[jobs[j].task]),
                    jobs[j].release,
                    j,
                )
            });
        if let Some(j) = candidate {
            let preempts = match running_priority(&stack) {
                None => true,
                Some(p) => priorities[jobs[j].task] > p,
            };
            if preempts {
                queues[jobs[j].task].pop_front();
                busy_task[jobs[j].task] = true;
                let left = jobs[j].segments.first().map_or(0, |s| s.length);
                stack.push(Active {
                    job: j,
                    segment: 0,
                    left,
                });
                continue;
            }
        }
        let Some(top) = stack.last_mut() else {
            // Idle until the next release.
            match order.get(next_release) {
                Some(&j) => t = jobs[j].release,
                None => break,
            }
            continue;
        };
        // Run until the segment ends or the next job is released, whichever comes first.
        let run = match order.get(next_release) {
            Some(&j) => top.left.min(jobs[j].release - t),
            None => top.left,
        };
        top.left -= run;
        t += run;
    }
    response
}

/// A message for the bus simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimMessage {
    pub key: u32,
    pub frame_time: u64,
    pub frames: u32,
    pub period: u64,
    pub jitter: u64,
}

/// One activation of a message: `frames` frames queued together at `queued`, nominally due at `arrival`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Activation {
    pub message: usize,
    pub arrival: u64,
    pub queued: u64,
}

/// Replays the activations on a bus; returns each activation's response (end of its last frame − arrival).
pub fn can_run(messages: &[SimMessage], activations: &[Activation]) -> Vec<u64> {
    // Pending frames: (key, queued, activation index, frames left after this one).
    let mut order: Vec<usize> = (0..activations.len()).collect();
    order.sort_by_key(|&a| (activations[a].queued, a));
    let mut pending: Vec<(u32, u64, usize, u32)> = Vec::new();
    let mut response = vec![0u64; activations.len()];
    let mut next = 0usize;
    let mut t = 0u64;
    loop {
        while next < order.len() && activations[order[next]].queued <= t {
            let a = order[next];
            let m = messages[activations[a].message];
            for left in (0..m.frames).rev() {
                pending.push((m.key, activations[a].queued, a, left));
            }
            next += 1;
        }
        // Arbitration: lowest key wins; one message's frames go in queuing order.
        let winner = pending
            .iter()
            .enumerate()
            .min_by_key(|(i, (key, queued, a, left))| {
                (*key, *queued, *a, std::cmp::Reverse(*left), *i)
            })
            .map(|(i, _)| i);
        match winner {
            Some(i) => {
                let (_, _, a, left) = pending.remove(i);
                let m = messages[activations[a].message];
                t += m.frame_time;
                if left == 0 {
                    response[a] = t - activations[a].arrival;
                }
            }
            None => match order.get(next) {
                Some(&a) => t = activations[a].queued,
                None => break,
            },
        }
    }
    response
}

/// Worst response per message when every message is queued at 0 and then strictly periodically, until `horizon`.
pub fn can_synchronous_worst(messages: &[SimMessage], horizon: u64) -> Vec<u64> {
    let mut activations = Vec::new();
    for (m, msg) in messages.iter().enumerate() {
        let mut at = 0;
        while at <= horizon {
            activations.push(Activation {
                message: m,
                arrival: at,
                queued: at,
            });
            at += msg.period;
        }
    }
    let responses = can_run(messages, &activations);
    let mut worst = vec![0u64; messages.len()];
    for (a, r) in activations.iter().zip(responses) {
        worst[a.message] = worst[a.message].max(r);
    }
    worst
}

/// Worst response per task when every task is released at 0 and then strictly periodically with its full
/// execution time and no locks, until `horizon`.
pub fn board_synchronous_worst(
    priorities: &[u32],
    wcets: &[u64],
    periods: &[u64],
    horizon: u64,
) -> Vec<u64> {
    let mut jobs = Vec::new();
    for task in 0..priorities.len() {
        let mut at = 0;
        while at <= horizon {
            jobs.push(Job {
                task,
                arrival: at,
                release: at,
                segments: vec![Segment {
                    length: wcets[task],
                    lock: None,
                }],
            });
            at += periods[task];
        }
    }
    let responses = board_run(priorities, &[], &jobs);
    let mut worst = vec![0u64; priorities.len()];
    for (job, r) in jobs.iter().zip(responses) {
        worst[job.task] = worst[job.task].max(r);
    }
    worst
}

#[test]
fn board_simulator_preempts_and_respects_ceilings() {
    // Low (prio 1) locks resource 0 (ceiling 3) from 0 to 4; high (prio 3) released at 1 waits until 4;
    // mid (prio 2) released at 1 waits for high.
    let jobs = vec![
        Job {
            task: 0,
            arrival: 0,
            release: 0,
            segments: vec![
                Segment {
                    length: 4,
                    lock: Some(0),
                },
                Segment {
                    length: 2,
                    lock: None,
                },
            ],
        },
        Job {
            task: 1,
            arrival: 1,
            release: 1,
            segments: vec![Segment {
                length: 3,
                lock: None,
            }],
        },
        Job {
            task: 2,
            arrival: 1,
            release: 1,
            segments: vec![Segment {
                length: 1,
                lock: Some(0),
            }],
        },
    ];
    let r = board_run(&[1, 2, 3], &[3], &jobs);
    // high: 4..5 → 4; mid: 5..8 → 7; low: resumes 8..10 → 10.
    assert_eq!(r, vec![10, 7, 4]);
}

#[test]
fn can_simulator_never_preempts_a_frame() {
    let messages = [
        SimMessage {
            key: 1,
            frame_time: 10,
            frames: 1,
            period: 100,
            jitter: 0,
        },
        SimMessage {
            key: 2,
            frame_time: 30,
            frames: 2,
            period: 100,
            jitter: 0,
        },
    ];
    let activations = [
        Activation {
            message: 1,
            arrival: 0,
            queued: 0,
        },
        Activation {
            message: 0,
            arrival: 5,
            queued: 5,
        },
    ];
    // Frame 1 of message 1 runs 0..30; message 0 waits until 30, runs 30..40; message 1's second frame 40..70.
    assert_eq!(can_run(&messages, &activations), vec![70, 35]);
}

/// A piece of a job that may suspend: CPU (with or without a lock), a script on a sensor bus, during which the job
/// is suspended, or a wait of its own (a settle time) during which it is suspended and the buses are free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Piece {
    Cpu(Segment),
    /// The script's time on bus 0, ns.
    Script(u64),
    /// A script on the given bus, its time on it, ns.
    ScriptOn(usize, u64),
    /// The job's own wait, ns.
    Settle(u64),
}

/// One job of a board whose jobs may suspend on the sensor bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SuspendingJob {
    pub task: usize,
    /// Nominal activation: responses are measured from here.
    pub arrival: u64,
    /// When it becomes ready (arrival + release jitter).
    pub release: u64,
    pub pieces: Vec<Piece>,
}

/// Replays `jobs` on a board (as [`board_run`]: preemption above the running priority, SRP locks, one job of a
/// task at a time) whose jobs may suspend on sensor buses. Each bus serves one script at a time, start to end;
/// when it falls idle it starts the waiting script of the most urgent job (its task's priority; equal priorities
/// in submission order). A job is suspended from its script's submission to its end, and for its settles, then
/// ready again at its priority; it keeps its RTIC task (`serial[task]`) busy all the while, so the task's next job
/// waits for it. Returns every job's response (finish − arrival) in the order of `jobs`.
pub fn suspending_run(
    priorities: &[u32],
    serial: &[usize],
    ceilings: &[u32],
    jobs: &[SuspendingJob],
) -> Vec<u64> {
    #[derive(Clone, Copy)]
    struct Active {
        job: usize,
        left: u64,
    }
    let groups = serial.iter().copied().max().map_or(0, |g| g + 1);
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by_key(|&j| (jobs[j].release, j));
    let mut response = vec![0u64; jobs.len()];
    let mut piece = vec![0usize; jobs.len()];
    let mut queues: Vec<std::collections::VecDeque<usize>> = vec![Default::default(); groups];
    let mut busy_group = vec![false; groups];
    // Jobs whose script has ended, waiting to run again: (job, since).
    let mut resumed: Vec<(usize, u64)> = Vec::new();
    let mut stack: Vec<Active> = Vec::new();
    // Scripts waiting for a bus: (job, submitted, bus, length); the one on each bus: (job, end).
    let buses = jobs
        .iter()
        .flat_map(|j| j.pieces.iter())
        .filter_map(|p| match p {
            Piece::ScriptOn(b, _) => Some(b + 1),
            _ => None,
        })
        .max()
        .unwrap_or(1);
    let mut waiting: Vec<(usize, u64, usize, u64)> = Vec::new();
    let mut on_bus: Vec<Option<(usize, u64)>> = vec![None; buses];
    // Jobs in a settle: (job, until).
    let mut sleeping: Vec<(usize, u64)> = Vec::new();
    let mut next_release = 0usize;
    let mut t = 0u64;
    let mut finished = 0usize;
    let priority_of = |j: usize| priorities[jobs[j].task];

    let running_priority = |stack: &Vec<Active>, piece: &Vec<usize>| -> Option<u32> {
        stack
            .iter()
            .map(|a| {
                let own = priority_of(a.job);
                match jobs[a.job].pieces.get(piece[a.job]) {
                    Some(Piece::Cpu(Segment {
                        lock: Some(r),
                        length,
                    })) if a.left < *length => own.max(ceilings[*r]),
                    _ => own,
                }
            })
            .max()
    };

    while finished < jobs.len() {
        while next_release < order.len() && jobs[order[next_release]].release <= t {
            let j = order[next_release];
            queues[serial[jobs[j].task]].push_back(j);
            next_release += 1;
        }
        for slot in on_bus.iter_mut() {
            if let Some((j, end)) = *slot {
                if end <= t {
                    *slot = None;
                    piece[j] += 1;
                    resumed.push((j, t));
                }
            }
        }
        for k in (0..sleeping.len()).rev() {
            let (j, until) = sleeping[k];
            if until <= t {
                sleeping.remove(k);
                piece[j] += 1;
                resumed.push((j, t));
            }
        }
        let mut started = false;
        for (b, slot) in on_bus.iter_mut().enumerate() {
            if slot.is_some() {
                continue;
            }
            let pick = waiting
                .iter()
                .enumerate()
                .filter(|(_, w)| w.2 == b)
                .min_by_key(|(_, &(j, submitted, _, _))| {
                    (std::cmp::Reverse(priority_of(j)), submitted, j)
                })
                .map(|(i, _)| i);
            if let Some(i) = pick {
                let (j, _, _, length) = waiting.remove(i);
                *slot = Some((j, t + length));
                started = true;
            }
        }
        if started {
            continue;
        }
        // The running piece has ended: the job's next piece runs, suspends it, or it is done.
        if let Some(top) = stack.last().copied() {
            if top.left == 0 {
                stack.pop();
                piece[top.job] += 1;
                resumed.push((top.job, t));
                // Re-entered at once below (it is the most urgent candidate at or above the running priority).
            }
        }
        // A resumed job whose next piece is not CPU: submit, or finish.
        let mut settled = false;
        for k in (0..resumed.len()).rev() {
            let (j, _) = resumed[k];
            match jobs[j].pieces.get(piece[j]) {
                Some(Piece::Script(length)) => {
                    waiting.push((j, t, 0, *length));
                    resumed.remove(k);
                    settled = true;
                }
                Some(Piece::ScriptOn(bus, length)) => {
                    waiting.push((j, t, *bus, *length));
                    resumed.remove(k);
                    settled = true;
                }
                Some(Piece::Settle(length)) => {
                    sleeping.push((j, t + length));
                    resumed.remove(k);
                    settled = true;
                }
                None => {
                    response[j] = t - jobs[j].arrival;
                    busy_group[serial[jobs[j].task]] = false;
                    finished += 1;
                    resumed.remove(k);
                    settled = true;
                }
                Some(Piece::Cpu(s)) if s.length == 0 => {
                    piece[j] += 1;
                    settled = true;
                }
                Some(Piece::Cpu(_)) => {}
            }
        }
        if settled {
            continue;
        }
        // The job that would run: a resumed one or a new one, highest priority, then the earliest.
        let fresh = queues
            .iter()
            .enumerate()
            .filter(|(g, _)| !busy_group[*g])
            .filter_map(|(_, q)| q.front().copied())
            .map(|j| (j, jobs[j].release, true));
        let candidate = resumed
            .iter()
            .map(|&(j, since)| (j, since, false))
            .chain(fresh)
            .min_by_key(|&(j, since, _)| (std::cmp::Reverse(priority_of(j)), since, j));
        if let Some((j, _, is_fresh)) = candidate {
            let preempts = match running_priority(&stack, &piece) {
                None => true,
                Some(p) => priority_of(j) > p,
            };
            if preempts {
                if is_fresh {
                    queues[serial[jobs[j].task]].pop_front();
                    busy_group[serial[jobs[j].task]] = true;
                    resumed.push((j, t));
                    continue;
                }
                resumed.retain(|&(k, _)| k != j);
                let left = match jobs[j].pieces.get(piece[j]) {
                    Some(Piece::Cpu(s)) => s.length,
                    _ => 0,
                };
                stack.push(Active { job: j, left });
                continue;
            }
        }
        let next_event = [order.get(next_release).map(|&j| jobs[j].release)]
            .into_iter()
            .chain(on_bus.iter().map(|slot| slot.map(|(_, end)| end)))
            .chain(sleeping.iter().map(|&(_, until)| Some(until)))
            .flatten()
            .min();
        let Some(top) = stack.last_mut() else {
            match next_event {
                Some(at) => t = at,
                None => break,
            }
            continue;
        };
        let run = match next_event {
            Some(at) => top.left.min(at - t),
            None => top.left,
        };
        top.left -= run;
        t += run;
    }
    response
}

#[test]
fn suspending_simulator_serves_the_bus_by_priority_without_preemption() {
    // Task 0 (prio 1) submits a 10 ns script at 0; task 1 (prio 3) submits a 5 ns script at 2, task 2 (prio 2) a
    // 5 ns script at 1. The bus runs 0's 0..10 (never preempted), then 1's 10..15, then 2's 15..20.
    let script = |length, arrival| SuspendingJob {
        task: 0,
        arrival,
        release: arrival,
        pieces: vec![Piece::Script(length)],
    };
    let jobs = vec![
        script(10, 0),
        SuspendingJob {
            task: 1,
            ..script(5, 2)
        },
        SuspendingJob {
            task: 2,
            ..script(5, 1)
        },
    ];
    assert_eq!(
        suspending_run(&[1, 3, 2], &[0, 1, 2], &[], &jobs),
        vec![10, 13, 19]
    );
}

#[test]
fn suspending_simulator_lets_lower_tasks_run_and_keeps_the_rtic_task_busy() {
    // Task 0 (prio 2) runs 2, suspends 6, runs 1; task 1 (prio 1) released at 0 runs 4 in its suspension.
    // Task 2 shares task 0's RTIC task (serial 0): released at 1, it waits for task 0's job to end.
    let cpu = |length| Piece::Cpu(Segment { length, lock: None });
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(2), Piece::Script(6), cpu(1)],
        },
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![cpu(4)],
        },
        SuspendingJob {
            task: 2,
            arrival: 1,
            release: 1,
            pieces: vec![cpu(1)],
        },
    ];
    // Task 0: 0..2, bus 2..8, 8..9 → 9. Task 1: 2..6 → 6. Task 2: 9..10 → 9 after its arrival at 1.
    assert_eq!(
        suspending_run(&[2, 1, 2], &[0, 1, 0], &[], &jobs),
        vec![9, 6, 9]
    );
}

#[test]
fn suspending_simulator_runs_two_buses_at_once_and_frees_them_in_a_settle() {
    // Task 0 (prio 2): a 10 ns script on bus 0, a settle of 4, a 6 ns script on bus 1. Task 1 (prio 1): a 7 ns
    // script on bus 1 at 0, then a 3 ns script on bus 0 at once. Bus 1: task 1's 0..7, task 0's 14..20 (the settle
    // 10..14). Bus 0: task 0's 0..10, task 1's 10..13 (submitted at 7, the bus busy until 10).
    let jobs = vec![
        SuspendingJob {
            task: 0,
            arrival: 0,
            release: 0,
            pieces: vec![
                Piece::ScriptOn(0, 10),
                Piece::Settle(4),
                Piece::ScriptOn(1, 6),
            ],
        },
        SuspendingJob {
            task: 1,
            arrival: 0,
            release: 0,
            pieces: vec![Piece::ScriptOn(1, 7), Piece::ScriptOn(0, 3)],
        },
    ];
    assert_eq!(suspending_run(&[2, 1], &[0, 1], &[], &jobs), vec![20, 13]);
}

/// Who holds the bus in [`node_run`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OnBus {
    /// The board's mailbox.
    Mailbox(usize),
    /// Another node's frame (an activation's index).
    Other(usize),
}

/// One of the board's transmit mailboxes in [`node_run`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Mailbox {
    key: u32,
    activation: usize,
    /// Its abort was asked for.
    abort: bool,
    /// Its completion, set and not yet collected: `Some(true)` sent, `Some(false)` aborted.
    done: Option<bool>,
}

/// One board's transmit path beside the other nodes' frames, on a bus with arbitration by identifier: the board's
/// frames (`own`, messages `0..own.len()` of the activations) go into an identifier-ordered queue when queued,
/// and into bxCAN's three mailboxes only in a job of the transmit interrupt, as the firmware does
/// (`amiro_firmware::can::{collect_completions, fill_mailboxes}`, `bxcan::Mailboxes`): a job collects every completion (an
/// aborted frame back into the queue), then fills mailboxes from the queue's head until the head is refused — a
/// mailbox holds its identifier, or all three are taken, where it asks for the abort of the least urgent pending
/// frame if it beats it, none under way and no completion uncollected. An abort takes effect at once, or, that
/// frame on the bus, never (it ends sent: no errors here). A completion and a queued frame pend the interrupt; a
/// pend while a job is pending merges into it. The other nodes' frames (`others`, messages `own.len()..`) are in
/// arbitration when queued.
///
/// A job acts at one instant, `delay(latest)` after the pend that started it (`delay` returns at most `latest`):
/// `latest` is `tx_response` for a job a pend started, and, for the job an abort's immediate completion pends,
/// what is left of the asking job's `tx_response` (the two are one busy window of the interrupt). An activation
/// queues its message's `frames` frames together (the board's into its queue in order, one identifier: a ring
/// sample's frames, a verdict's pages; another node's into arbitration). Returns each activation's response: its
/// last frame's end − its arrival.
pub fn node_run(
    own: &[SimMessage],
    others: &[SimMessage],
    activations: &[Activation],
    tx_response: u64,
    delay: &mut dyn FnMut(u64) -> u64,
) -> Vec<u64> {
    let message = |m: usize| {
        if m < own.len() {
            own[m]
        } else {
            others[m - own.len()]
        }
    };
    let mut order: Vec<usize> = (0..activations.len()).collect();
    order.sort_by_key(|&a| (activations[a].queued, a));
    let mut response = vec![0u64; activations.len()];
    // Each activation's frames not yet sent.
    let mut left: Vec<u32> = activations
        .iter()
        .map(|a| message(a.message).frames.max(1))
        .collect();
    // The board's queue: (key, order queued, activation); the other nodes' frames in arbitration.
    let mut queue: Vec<(u32, usize, usize)> = Vec::new();
    let mut other_frames: Vec<(u32, usize)> = Vec::new();
    let mut mailboxes: [Option<Mailbox>; 3] = [None; 3];
    let mut bus: Option<(OnBus, u64)> = None;
    // The pending job: when it acts, and when the busy window of the interrupt it is in started.
    let mut job: Option<(u64, u64)> = None;
    let mut next = 0usize;
    let mut seq = 0usize;
    let mut t = 0u64;
    loop {
        // A frame ends.
        if let Some((who, end)) = bus.filter(|&(_, end)| end == t) {
            let _ = end;
            bus = None;
            match who {
                OnBus::Mailbox(i) => {
                    if let Some(mb) = mailboxes[i].as_mut() {
                        mb.done = Some(true);
                        left[mb.activation] -= 1;
                        if left[mb.activation] == 0 {
                            response[mb.activation] = t - activations[mb.activation].arrival;
                        }
                    }
                    if job.is_none() {
                        job = Some((t + delay(tx_response), t));
                    }
                }
                OnBus::Other(a) => {
                    left[a] -= 1;
                    if left[a] == 0 {
                        response[a] = t - activations[a].arrival;
                    }
                }
            }
        }
        // Frames queued.
        while next < order.len() && activations[order[next]].queued <= t {
            let a = order[next];
            let m = activations[a].message;
            if m < own.len() {
                for _ in 0..own[m].frames.max(1) {
                    queue.push((own[m].key, seq, a));
                    seq += 1;
                }
                if job.is_none() {
                    job = Some((t + delay(tx_response), t));
                }
            } else {
                for _ in 0..message(m).frames.max(1) {
                    other_frames.push((message(m).key, a));
                }
            }
            next += 1;
        }
        // The transmit interrupt's job.
        if let Some((at, window)) = job.filter(|&(at, _)| at == t) {
            let _ = at;
            job = None;
            for slot in mailboxes.iter_mut() {
                if let Some(mb) = *slot {
                    if let Some(sent) = mb.done {
                        if !sent {
                            queue.push((mb.key, seq, mb.activation));
                            seq += 1;
                        }
                        *slot = None;
                    }
                }
            }
            while let Some(h) = (0..queue.len()).min_by_key(|&i| (queue[i].0, queue[i].1)) {
                let (key, _, a) = queue[h];
                let pending = |mb: &Option<Mailbox>| mb.filter(|mb| mb.done.is_none());
                if mailboxes
                    .iter()
                    .any(|mb| pending(mb).is_some_and(|mb| mb.key == key))
                {
                    break;
                }
                if let Some(free) = mailboxes.iter().position(Option::is_none) {
                    mailboxes[free] = Some(Mailbox {
                        key,
                        activation: a,
                        abort: false,
                        done: None,
                    });
                    queue.remove(h);
                    continue;
                }
                // All taken: the least urgent pending one, the later mailbox among equals.
                let least = (0..3)
                    .filter_map(|i| pending(&mailboxes[i]).map(|mb| (mb.key, i)))
                    .max();
                let uncollected = mailboxes
                    .iter()
                    .any(|mb| mb.is_some_and(|mb| mb.done.is_some()));
                if let Some((least_key, i)) = least {
                    let under_way = mailboxes[i].is_some_and(|mb| mb.abort);
                    if key < least_key && !under_way && !uncollected {
                        let on_bus = bus.is_some_and(|(who, _)| who == OnBus::Mailbox(i));
                        if let Some(mb) = mailboxes[i].as_mut() {
                            mb.abort = true;
                            if !on_bus {
                                mb.done = Some(false);
                                // Its completion pends the interrupt: a job in this one's busy window.
                                job = Some((
                                    t + delay((window + tx_response).saturating_sub(t)),
                                    window,
                                ));
                            }
                        }
                    }
                }
                break;
            }
        }
        // Arbitration when the bus is idle: the lowest key among the pending mailboxes and the other nodes' frames.
        if bus.is_none() {
            let mine = (0..3)
                .filter_map(|i| {
                    mailboxes[i]
                        .filter(|mb| mb.done.is_none())
                        .map(|mb| (mb.key, i))
                })
                .min();
            let theirs =
                // Equal identifiers in queuing order (the first minimum).
                (0..other_frames.len()).min_by_key(|&i| other_frames[i].0);
            match (mine, theirs) {
                (Some((k, i)), Some(o)) if k <= other_frames[o].0 => {
                    bus = Some((
                        OnBus::Mailbox(i),
                        t + own[activations[mailboxes[i].map_or(0, |mb| mb.activation)].message]
                            .frame_time,
                    ));
                }
                (_, Some(o)) => {
                    let (_, a) = other_frames.remove(o);
                    bus = Some((
                        OnBus::Other(a),
                        t + message(activations[a].message).frame_time,
                    ));
                }
                (Some((_, i)), None) => {
                    bus = Some((
                        OnBus::Mailbox(i),
                        t + own[activations[mailboxes[i].map_or(0, |mb| mb.activation)].message]
                            .frame_time,
                    ));
                }
                (None, None) => {}
            }
        }
        let upcoming = [
            bus.map(|(_, end)| end),
            job.map(|(at, _)| at),
            order.get(next).map(|&a| activations[a].queued),
        ];
        match upcoming.into_iter().flatten().min() {
            Some(at) => t = at.max(t),
            None => break,
        }
        if bus.is_none() && job.is_none() && next >= order.len() && queue.is_empty() {
            break;
        }
    }
    response
}
