//! The coordinator: steps the robot from boundary to boundary, with lookahead.
use std::collections::VecDeque;
use std::path::Path;
use std::time::{Duration, Instant};

use amiro_bus_sim::{frame_bits, BitFault, Bus, ErrorState, Event, Frame, NodeId, MAILBOXES};
use amiro_trace::robot_link::{
    reaches_software, Done, Down, Queued, Up, DOWN_EARLY, DOWN_END, DOWN_FRAME, DOWN_OWN,
    DOWN_PD_LOW, DOWN_SYNC_LOW, DRIVES_PD_LOW, DRIVES_SYNC_LOW, QUANTUM_US,
};
use anyhow::{anyhow, bail, Result};

use crate::board::{board_lines, Board};
use crate::stimulus::{Action, Timed, BOARDS};
use crate::world::WorldRun;
use crate::{candump_line, pace, stamp, Firmware, Live, Outcome, Sink, Transfer, NODES, OPERATOR};

/// How far a live run's host steps without a board's exchange at most: the adapter's frames are
/// queued at the boundary the host is at, so this is how late one can come on (virtual time).
const LIVE_STEP_US: u64 = 1_000;

/// A live run's boards have started when each has made its first exchange and gone idle (the
/// boot's code runs for the first time then, 10 ms of wall time for LightRing's first virtual
/// millisecond), at the latest at this virtual time: its wall clock starts there.
const BOOT_LIMIT_US: u64 = 100_000;

/// How long the host waits for a board's report before it calls the board hung.
const REPORT_LIMIT: Duration = Duration::from_secs(30);

/// Counts of a run's work, for `--bench` and the closing line.
#[derive(Debug, Default, Clone, Copy)]
pub struct Work {
    /// Boundaries the host stepped through (the bus model run to each).
    pub steps: u64,
    /// Board exchanges (a board's report and its answer).
    pub exchanges: u64,
    /// Of those, each board's.
    pub per_board: [u64; 3],
    /// Of those, boards brought to a boundary from a wait (a frame, a line, the end was due).
    pub catch_ups: u64,
    /// Answers that granted a board the bus (it completes its own sensor frames itself).
    pub grants: u64,
    /// Frames boards completed themselves under a grant (each checked against the bus model).
    pub local_frames: u64,
    /// Wall time spent waiting for boards' reports (their emulation), µs.
    pub waiting_us: u64,
    /// Wall time live runs slept to stay behind the wall clock, µs.
    pub pacing_us: u64,
    /// What each board's QEMU cost (CPU, task switches, system calls; summed over its starts).
    pub boards: [crate::cost::Cost; 3],
    /// What the host cost in the run (this process: the bus model, the coordinator, the pipes).
    pub host: crate::cost::Cost,
    /// How the boards ran side by side in wall time.
    pub overlap: crate::cost::Overlap,
    /// The board run that took the most wall time beyond its virtual time since a live run's
    /// pacing last took it (`pace::Pace::hold`).
    pub slowest: Option<pace::SlowRun>,
    /// Each board's reports made more than a quantum after their boundary.
    pub late: [crate::cost::Late; 3],
    /// The machine's processors over the run: how much of them its hypervisor took (`None` off
    /// Linux).
    pub machine: Option<crate::cost::Machine>,
}

/// What a board must get at boundary `t`: the frame that completes in the coming quantum if it is
/// the board's own or passes its receive filter, an abort answer, a new line level, the end.
fn due(b: &Board, d: Option<&Transfer>, bus: &Bus, flags: u8, end: bool) -> bool {
    end || b.aborted != 0 || flags != b.flags || d.is_some_and(|d| meant_for(b, d, bus))
}

/// Whether `d` is given to board `b`: its own frame (not one from before its last reset, nor its
/// babbling controller's), or another node's while it is plugged in.
fn given(b: &Board, d: &Transfer, bus: &Bus) -> (bool, bool) {
    let own = d.node == b.index && d.start >= b.offset && d.mailbox < MAILBOXES;
    let heard = d.node != b.index && bus.plugged(b.node);
    (own, heard)
}

/// Whether a command frame with identifier `id` may make a board that hears it drive a line (the
/// shutdown command drives SYS_PD_N) or do something else the host does not vouch for (a topic it
/// does not know): such a board goes ahead with no other until it sleeps again
/// (`Board::commanded`). A sensor request (a diagnostics topic's admission policy too), an LED or
/// the motor command makes a board decide, sample, light and publish sensor frames, which no
/// other board's filter passes: the
/// boards deciding one go ahead together as in the steady state (before, each such command put
/// all three boards quantum by quantum through their admission decision, some 30 exchanges of
/// 0.2–0.5 ms of wall time each, a live run 5–11 ms behind the wall clock at each request).
fn may_drive_a_line(id: u16) -> bool {
    use amiro_can::Topic;
    reaches_software(id)
        && !u8::try_from(id & 0xFF)
            .ok()
            .and_then(|byte| Topic::try_from(byte).ok())
            .is_some_and(|t| t.is_sensor() || t.led_number().is_some() || t == Topic::MotorCommand)
}

/// Whether `d` makes board `b` act: its own completion, or a frame its filter passes.
fn meant_for(b: &Board, d: &Transfer, bus: &Bus) -> bool {
    let (own, heard) = given(b, d, bus);
    own || (heard && reaches_software(d.frame.id))
}

/// Runs the robot for `duration_us` of virtual time against `actions`, in `work`; with `live`,
/// paced to the wall clock with a client's adapter on the bus.
///
/// The host steps from boundary to boundary (multiples of [`QUANTUM_US`]); at each it takes the
/// reports of the boards due there, runs the bus model to it and answers. A board that sleeps past
/// the next boundary (lookahead: it reported its next timer deadline, and nothing but a frame its
/// filter passes, its own frame's completion, an abort or a line level can wake it) is left
/// waiting in its read, its answer held back: when something is due for it the host sends it on
/// to that boundary first (it runs there idle and reports nothing new), then answers as it would
/// have. Every board therefore sees every input at the same boundary as in plain lock-step, and
/// the exchanges stay at fixed virtual instants: a run is a function of its stimulus.
pub fn run(
    firmware: &[Firmware; 3],
    actions: &[Timed],
    duration_us: u64,
    work: &Path,
    sink: &mut dyn Sink,
    live: Option<&mut Live>,
) -> Result<Outcome> {
    run_in_world(firmware, actions, duration_us, work, sink, live, None)
}

/// As [`run`], with the robot in `world` when there is one: the DiWheelDrive's wheel ticks move
/// it and the sensor boards get its readings with their answers (`crate::world`).
pub fn run_in_world(
    firmware: &[Firmware; 3],
    actions: &[Timed],
    duration_us: u64,
    work: &Path,
    sink: &mut dyn Sink,
    mut live: Option<&mut Live>,
    mut world: Option<&mut WorldRun>,
) -> Result<Outcome> {
    std::fs::create_dir_all(work)?;
    let host_before = crate::cost::own();
    let machine_before = crate::cost::Machine::now();
    // How the boards run side by side, kept by the boards as they are sent on and report.
    let overlap = std::rc::Rc::new(std::cell::RefCell::new(crate::cost::Overlap::default()));
    let mut bus = Bus::new();
    // The three boards' nodes, then the operator's adapter's (`OPERATOR`).
    let nodes: Vec<NodeId> = (0..4).map(|_| bus.add_node()).collect();
    let mut boards: Vec<Board> = (0..3)
        .map(|k| {
            let dir = work.join(BOARDS[k]);
            let mut b = Board::new(k, nodes[k], firmware[k].clone(), dir, live.is_some());
            b.overlap = overlap.clone();
            b
        })
        .collect();
    if live.is_some() {
        // The host's thread too, one above the boards (it answers them): see
        // `board::LIVE_RT_PRIORITY`. Put back when the run ends.
        match crate::board::live_priority(crate::board::LIVE_RT_PRIORITY + 1) {
            Some(true) => {}
            Some(false) => eprintln!(
                "robot: live: no real-time priority for the host and the boards (not permitted), nice {} instead: other work on the machine can hold them up for a time slice",
                crate::board::LIVE_NICE
            ),
            None => eprintln!(
                "robot: live: the host and the boards keep the default priority ({}): other work on the machine can hold them up",
                std::io::Error::last_os_error()
            ),
        }
    }
    for b in &mut boards {
        b.start(0)?;
    }
    // A live run keeps running figures only (it has no end): `Outcome::bounded`.
    let mut outcome = if live.is_some() {
        Outcome::bounded()
    } else {
        Outcome::default()
    };
    let emit = |outcome: &mut Outcome, sink: &mut dyn Sink, line: String| outcome.emit(sink, &line);
    // A live run's warm-up (`crate::warm`): its requests first, the boards restarted in their
    // QEMUs at `warm_end`; the run's own stimulus and duration count from there.
    let warm_end = live
        .as_ref()
        .filter(|l| l.warm_up && world.is_none())
        .map(|_| crate::warm::RESTART_US);
    let mut warming = warm_end.is_some();
    let warm_end = warm_end.unwrap_or(0);
    let warm_started = Instant::now();
    let shifted: Vec<Timed>;
    let actions: &[Timed] = if warming {
        shifted = crate::warm::actions()
            .into_iter()
            .chain(actions.iter().map(|a| Timed {
                at_us: a.at_us.saturating_add(warm_end),
                action: a.action.clone(),
            }))
            .collect();
        &shifted
    } else {
        actions
    };
    let duration_us = duration_us.saturating_add(warm_end);
    let mut pending = actions.iter().peekable();
    let mut operator: VecDeque<(u64, Frame)> = VecDeque::new();
    // A live run's frames from the adapter that wait for the host to catch up with the boards.
    let mut adapter_waiting: Vec<Frame> = Vec::new();
    let mut deliveries: VecDeque<Transfer> = VecDeque::new();
    let mut pd_from_outside = false;
    let (mut sync_low, mut pd_low) = (true, false);
    let mut pace = live.as_ref().map(|_| pace::Pace::new(Instant::now()));
    // A live run is paced from the end of its boards' start.
    let mut paced = false;
    // A live run's frames for the client, handed over at their time (`Pace::hold`).
    let mut outbox: pace::Outbox<Frame> = pace::Outbox::default();
    let mut t = QUANTUM_US;
    // `AMIRO_ROBOT_NO_GRANT=1`: no board is granted the bus (the run as before the grant, for
    // comparing the two on one build; docs/qemu.md, "Lookahead").
    let grants_on = std::env::var_os("AMIRO_ROBOT_NO_GRANT").is_none_or(|v| v != "1");
    // The boards sent ahead at the last boundary `from` (the only ones with work, everything else
    // quiet): each reports at the first boundary after it queued a frame, asked for an abort or
    // changed a line, at the latest at `t`. The host goes on from the earliest report; a later
    // one is held until the host reaches its boundary.
    let mut ahead: Vec<usize> = Vec::new();
    let mut from = 0;
    let result: Result<()> = (|| loop {
        outcome.work.steps += 1;
        let mut notes: Vec<String> = Vec::new();
        if !ahead.is_empty() {
            for &k in &ahead {
                let b = &mut boards[k];
                let (at, mut report) = take_report(b, from + QUANTUM_US..=t, &mut outcome.work)?;
                if let Some(free_until) = b.granted {
                    // A board granted the bus: the frames it completed itself go through the bus
                    // model now (checked), and the ones it hands over are queued at once — some
                    // may have waited since before another board's report the host takes first.
                    let done = std::mem::take(&mut b.done);
                    for d in replay_done(&mut bus, b, &done)? {
                        outcome.work.local_frames += 1;
                        outcome.transfer(d);
                        emit(&mut outcome, sink, candump_line(d.end, &d.frame));
                        if live.is_some() && !warming {
                            outbox.push(d.end, d.frame);
                        }
                    }
                    if let Some(r) = report.as_mut() {
                        // Those queued before the grant's end (held back for the board's own
                        // arbitration, then starting past the grant's end, or queued before
                        // a command frame ended it) are queued at once: they may be older than
                        // another board's report the host takes first. The rest when the host
                        // reaches the report, as any board's.
                        let (old, recent): (Vec<Queued>, Vec<Queued>) = r
                            .queued()
                            .iter()
                            .copied()
                            .partition(|q| q.at_us + b.offset < free_until);
                        let mut early = Up { count: 0, ..*r };
                        for q in old {
                            early.push(q);
                        }
                        queue_reported(b, at, &early, &mut bus, &mut notes);
                        r.count = 0;
                        for q in recent {
                            r.push(q);
                        }
                    }
                    b.granted = None;
                }
                b.held = Some((at, report));
                b.next = Some(at);
            }
            t = ahead
                .drain(..)
                .filter_map(|k| boards[k].next)
                .min()
                .unwrap_or(t);
        }
        // The boards due at this boundary report (those sent on to it at the last answer), and
        // those left waiting whose deadline falls here are sent on to it first — all of them
        // before any report is taken, so they run side by side meanwhile.
        for b in boards.iter_mut() {
            if b.alive && b.next.is_none() && b.at < t && b.wants <= t {
                send_on(b, t, &mut outcome.work)?;
            }
        }
        for b in boards.iter_mut() {
            if b.alive && b.next == Some(t) {
                exchange(b, t..=t, &mut bus, &mut notes, &mut outcome.work)?;
            }
        }
        if warming && t >= warm_end {
            // The warm-up is over: every board waits for its answer here (nothing was sent past
            // this boundary), and restarts in its QEMU with the code it ran translated. What the
            // warm-up put on the bus goes with it; the bus report covers the live run.
            warming = false;
            for (k, b) in boards.iter_mut().enumerate().filter(|(_, b)| b.alive) {
                if b.next.is_none() {
                    b.restart(t)?;
                } else {
                    b.stop();
                    b.start(t)?;
                }
                bus.reset_node(nodes[k], t);
            }
            operator.clear();
            deliveries.clear();
            outcome.forget_transfers();
            outcome.error_frames = 0;
            notes.push(format!(
                "bus: # {} warm-up over: the boards restart in their QEMUs, the code they ran translated",
                stamp(t)
            ));
            eprintln!(
                "robot: live: warm-up: {:.0} ms of virtual time in {:.1} s of wall time (every sensor topic requested, sampled and stopped, the LEDs, the motor, the thesis load); the boards restart with their code translated",
                warm_end as f64 / 1e3,
                warm_started.elapsed().as_secs_f64()
            );
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
        if let Some(w) = world.as_deref_mut() {
            // The controller's ticks up to here: its frames go on the bus now.
            operator.extend(w.ticks(t)?.into_iter().map(|f| (t, f)));
        }
        if let (Some(live), Some(pace)) = (live.as_deref_mut(), pace.as_mut()) {
            if !paced
                && !warming
                && (t >= warm_end + BOOT_LIMIT_US
                    || boards.iter().filter(|b| b.alive).all(|b| b.wakes_at > t))
            {
                // The robot's wall clock starts once its boards have started: each has made its
                // first exchange and gone idle (`Pace::start_at`).
                paced = true;
                pace.start_at(t);
                // The boards' start is not a run that holds the robot up.
                outcome.work.slowest = None;
                if let Some(ready) = live.ready.take() {
                    ready();
                }
            }
            if paced {
                // Never ahead of the wall clock (behind it when the host is too slow: said at
                // once, with the board run that held it up).
                if let Some(slow) = outcome.work.slowest.take() {
                    pace.note(slow);
                }
                if live.stop.load(std::sync::atomic::Ordering::Relaxed) {
                    pace.stop_requested(t);
                }
                outcome.work.pacing_us += pace.hold(t, &mut outbox, |end, frame| {
                    crate::pace::timed(crate::pace::Io::Port, || live.slcan.deliver(end, &frame));
                });
            }
            // While boards sent ahead together hold reports beyond this boundary (at most a live
            // step), the adapter's frames wait (and no board is sent ahead together meanwhile):
            // a command frame queued now could reach such a board only after the time it
            // completes. Queued once the host has caught up, they are what the adapter sent a
            // little later.
            // The client's frames wait in the port until the wall clock runs (it is announced then).
            if paced {
                adapter_waiting.extend(crate::pace::timed(crate::pace::Io::Port, || {
                    live.slcan.poll()
                }));
            }
            if !boards
                .iter()
                .any(|b| b.alive && b.held.as_ref().is_some_and(|&(at, _)| at > t))
            {
                operator.extend(adapter_waiting.drain(..).map(|frame| (t, frame)));
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
                    outcome.transfer(transfer);
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
                if let Some(p) = bus.abort(b.node, mailbox) {
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
            if d.node != OPERATOR && live.is_some() && !warming {
                outbox.push(d.end, d.frame);
            }
        }
        let mut flags = 0;
        if pd_low {
            flags |= DOWN_PD_LOW;
        }
        if sync_low {
            flags |= DOWN_SYNC_LOW;
        }
        // Boards left waiting at an earlier boundary that must get something at this one: sent on
        // to it first (they run there idle and report), all before any report is taken.
        let mut caught_up = [false; 3];
        for (k, b) in boards.iter_mut().enumerate() {
            if b.alive && b.next.is_none() && b.at < t && due(b, now.as_ref(), &bus, flags, end) {
                send_on(b, t, &mut outcome.work)?;
                caught_up[k] = true;
            }
        }
        for (k, b) in boards.iter_mut().enumerate() {
            if caught_up[k] {
                exchange(b, t..=t, &mut bus, &mut notes, &mut outcome.work)?;
            }
        }
        // A board sent ahead together with others and still ahead of this boundary gets what is
        // due for it here only at its report (never silently).
        for b in boards.iter().filter(|b| b.alive && b.held.is_some()) {
            if let Some(at) = b.next.filter(|&at| at > t) {
                if due(b, now.as_ref(), &bus, flags, end) {
                    notes.push(format!(
                        "bus: # {} {} was sent ahead with another board: what is due for it here reaches it at {}",
                        stamp(t),
                        NODES[b.index],
                        stamp(at)
                    ));
                }
            }
        }
        if let Some(w) = world.as_deref_mut() {
            w.step(t, &mut boards);
        }
        // What each board at this boundary wants next: the coming quantum if it has work or gets
        // something now, else the boundary of its deadline (with a world, a sensor board's last
        // boundary before it: `WorldRun::wake_boundary`).
        for b in boards.iter_mut() {
            if b.alive && b.next.is_none() && b.at == t {
                let busy = b.wakes_at <= t || due(b, now.as_ref(), &bus, flags, end);
                b.wants = if busy {
                    t + QUANTUM_US
                } else if world.as_deref().is_some_and(WorldRun::feeds) {
                    WorldRun::wake_boundary(b.index, t, b.wakes_at)
                } else {
                    at_or_after(b.wakes_at)
                };
            }
        }
        let next = if end {
            t + QUANTUM_US
        } else {
            let bus_idle = operator.is_empty()
                && deliveries.is_empty()
                && nodes
                    .iter()
                    .all(|&n| bus.mailboxes(n).iter().all(Option::is_none) && !bus.babbling(n, t));
            let mut until = at_or_after(duration_us);
            if let Some(a) = pending.peek() {
                until = until.min(after(a.at_us));
            }
            if warming {
                // No board goes past the warm-up's restart.
                until = until.min(warm_end);
            }
            for b in boards.iter().filter(|b| b.alive) {
                until = until.min(b.next.unwrap_or(b.wants));
            }
            if !bus_idle {
                // The bus model runs quantum by quantum while it has work (no board needs to).
                until = t + QUANTUM_US;
            }
            if live.is_some() {
                until = until.min(t + LIVE_STEP_US);
            }
            if let Some(tick) = world.as_deref().and_then(WorldRun::next_tick) {
                until = until.min(tick);
            }
            until.max(t + QUANTUM_US)
        };
        // Lookahead for a busy board: when it is the only one with work and the bus is quiet
        // (nothing queued, nothing on its way, no babbling), nothing can reach it before it
        // queues a frame, asks for an abort or changes a line itself, nor reach another board
        // before that or before the next deadline of theirs: it is sent ahead to that deadline
        // (or the next stimulus action, the run's end) and reports early if it does one of those.
        let busy: Vec<usize> = (0..boards.len())
            .filter(|&k| {
                let b = &boards[k];
                b.alive && b.next.is_none() && b.at == t && b.wants == t + QUANTUM_US
            })
            .collect();
        // The horizon a board `k` may be sent ahead to: the run's end, the next stimulus action,
        // every other board's next boundary, a live run's step, the world's next tick.
        let limits = Limits {
            end: at_or_after(duration_us),
            action: pending
                .peek()
                .map(|a| after(a.at_us))
                .into_iter()
                .chain(warming.then_some(warm_end))
                .min(),
            live: live.is_some().then_some(t + LIVE_STEP_US),
            tick: world.as_deref().and_then(WorldRun::next_tick),
        };
        let mailboxes_empty = operator.is_empty()
            && nodes
                .iter()
                .all(|&n| bus.mailboxes(n).iter().all(Option::is_none) && !bus.babbling(n, t));
        let mut next = next;
        let mut now = now;
        let mut busy = busy;
        // The steady state, in which several boards with work may be sent ahead together (below):
        // every module has released SYS_SYNC_N, nobody drives SYS_PD_N, no board is busy with a
        // command or gets one now, no world. Live, a live step at most, and the adapter's frames
        // wait meanwhile (above), none of them waiting now.
        let steady = steady_state(
            flags,
            now.is_some_and(|d| reaches_software(d.frame.id)),
            !adapter_waiting.is_empty() || world.is_some(),
            &boards,
        );
        // Lookahead through a board's own frame: when the one thing on the bus is a frame of a
        // board that reported here, already started (nothing can pre-empt it, nothing else
        // completes before it) and no other board has work (in the steady state: the boards with
        // work go ahead with it), its completion is answered now rather than at the boundary it
        // falls in, and the board is sent ahead (below). It
        // delivers the completion at its time, as it would have a quantum later; if it has
        // something to report first, it reports and keeps the completion (its report says it
        // wakes then). Outside a world (the controller hears the bus frame by frame, tick by tick).
        if let (false, None, true, true, [d]) = (
            end,
            now,
            mailboxes_empty,
            world.is_none(),
            deliveries.make_contiguous(),
        ) {
            let d = *d;
            let own_waiting = boards.get(d.node).is_some_and(|b| {
                b.alive
                    && b.next.is_none()
                    && b.at == t
                    && b.aborted == 0
                    && b.flags == flags
                    && !reaches_software(d.frame.id)
                    && given(b, &d, &bus).0
            });
            let mut group = busy.clone();
            if !group.contains(&d.node) {
                group.push(d.node);
            }
            let horizon = if steady {
                limits.widen(&boards, &mut group)
            } else {
                limits.horizon(&boards, &group)
            };
            if own_waiting
                && (group.len() == 1 || (steady && horizon < duration_us))
                && horizon > d.end
                && d.end >= t + QUANTUM_US
            {
                deliveries.pop_front();
                if live.is_some() && !warming {
                    outbox.push(d.end, d.frame);
                }
                now = Some(d);
                boards[d.node].wants = t + QUANTUM_US;
                busy = group;
            }
        }
        let quiet = mailboxes_empty && deliveries.is_empty();
        // Several boards with work, in the steady state (every module has released SYS_SYNC_N,
        // nobody drives SYS_PD_N, no board is busy with a command, no world): they are
        // sent ahead together. The boards send sensor frames only, which no other board's filter
        // passes, so one's report cannot concern another but through the bus, which the host runs
        // after the reports. A line is driven in the steady state only by a shutdown, which a
        // command starts (or PowerManagement's low battery): a line change or a command frame
        // from a board sent ahead with others reaches them at their own next report, and a bus
        // note says so.
        if !end && quiet && (busy.len() == 1 || steady) {
            let horizon = if steady {
                limits.widen(&boards, &mut busy)
            } else {
                limits.horizon(&boards, &busy)
            };
            // A frame answered now completes before the boards' next boundary; boards sent ahead
            // together report before the run's end.
            if horizon > t + QUANTUM_US
                && now.is_none_or(|d| d.end < horizon)
                && !busy.is_empty()
                && (busy.len() == 1 || horizon < duration_us)
            {
                next = horizon;
                ahead = busy.clone();
                from = t;
            }
        }
        // Grants: a board sent ahead in the steady state completes its own sensor frames itself
        // while no other node can have one pending (`grant_until`).
        let bound = [
            pending.peek().map(|a| a.at_us),
            warming.then_some(warm_end),
            live.is_some().then_some(t + LIVE_STEP_US),
            Some(duration_us),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(duration_us);
        let bus_quiet = mailboxes_empty && deliveries.is_empty() && grants_on;
        let grants: Vec<Option<(u64, u64, u8)>> = (0..boards.len())
            .map(|k| {
                let b = &boards[k];
                if !ahead.contains(&k) || b.at != t || end {
                    return None;
                }
                let own = now.map(|d| (d.node, d.end));
                let free_until = grant_until(&boards, k, t, steady && bus_quiet, own, bound)?;
                let idle = bus.alone_from(b.node)?;
                let held = bus
                    .mailboxes(b.node)
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| m.is_some())
                    .fold(0u8, |mask, (i, _)| mask | 1 << i);
                Some((free_until, idle, held))
            })
            .collect();
        // Answers: every board at this boundary that wants the next one gets what is due; one
        // that sleeps past it waits (its answer held back); one waiting from before whose
        // deadline is the next boundary is sent on to it.
        for (k, b) in boards.iter_mut().enumerate() {
            if !b.alive || b.next.is_some() {
                continue;
            }
            let sent_ahead = ahead.contains(&k);
            if b.at == t && (b.wants <= next || end || sent_ahead) {
                let mut answer = Down {
                    next_us: next - b.offset,
                    aborted: b.aborted,
                    flags,
                    ..Down::default()
                };
                b.aborted = 0;
                if end {
                    answer.flags |= DOWN_END;
                }
                if sent_ahead {
                    answer.flags |= DOWN_EARLY;
                }
                b.granted = None;
                if let Some((free_until, idle, held)) = grants[k] {
                    answer.free_until_us = free_until - b.offset;
                    answer.idle_from_us = idle.max(b.offset) - b.offset;
                    answer.held = held;
                    b.granted = Some(free_until);
                    outcome.work.grants += 1;
                }
                if let Some(d) = now {
                    let (own, heard) = given(b, &d, &bus);
                    if own || heard {
                        b.commanded |= heard && may_drive_a_line(d.frame.id);
                        answer.flags |= DOWN_FRAME | if own { DOWN_OWN } else { 0 };
                        answer.at_us = d.end.saturating_sub(b.offset);
                        answer.mailbox = d.mailbox as u8;
                        answer.id = d.frame.id;
                        answer.len = d.frame.len;
                        answer.data = d.frame.data;
                    }
                }
                b.flags = flags;
                // A board given the end has nothing more to report.
                b.next = (!end).then_some(next);
                let readings = world
                    .as_deref_mut()
                    .and_then(|w| w.readings_for(k, t, b.offset));
                b.send_with(&answer, readings)?;
            } else if b.at < t && sent_ahead {
                // A board left waiting for its deadline, sent ahead with the others (`widen`).
                let on = Down {
                    next_us: next - b.offset,
                    flags: b.flags | DOWN_EARLY,
                    ..Down::default()
                };
                b.next = Some(next);
                b.send(&on)?;
            } else if b.at < t && b.wants == next && ahead.is_empty() {
                let on = Down {
                    next_us: next - b.offset,
                    flags: b.flags,
                    ..Down::default()
                };
                b.next = Some(next);
                b.send(&on)?;
            }
        }
        // What the boards printed up to their reports, what the bus saw at this boundary, and
        // the frame that completes in the next quantum.
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
            if let Some(w) = world.as_deref_mut() {
                w.frame(d.end, &d.frame)?;
            }
        }
        if end {
            outcome.ended_at = t;
            return Ok(());
        }
        t = next;
    })();
    // What a live run computed ahead of the wall clock still reaches the client.
    if let Some(live) = live {
        outbox.flush(|end, frame| live.slcan.deliver(end, &frame));
        if live.slcan.dropped() > 0 {
            eprintln!(
                "robot: live: {} message(s) to the client dropped whole: it did not read them in time (more than 64 KiB waited)",
                live.slcan.dropped()
            );
        }
    }
    // A live run stopped by Ctrl-C ends at the host's boundary while boards sent ahead (at most a
    // live step) still run towards theirs: each reports there and gets the end then. (A run that
    // reaches its duration never sends a board past it.) Without this a board sent ahead waited
    // for its answer until the wait below gave up and killed it, 10 s later, without its end line.
    if result.is_ok() {
        for b in boards.iter_mut().filter(|b| b.alive && b.next.is_some()) {
            let reported = match b.held.take() {
                Some((_, report)) => Ok(report),
                None => b.receive(Instant::now(), REPORT_LIMIT),
            };
            if let Ok(Some(_)) = reported {
                let _ = b.send(&Down {
                    flags: DOWN_END,
                    ..Down::default()
                });
            }
        }
    }
    // The boards print their end lines and exit; whatever they still say is kept.
    for b in &mut boards {
        let started = Instant::now();
        while b
            .child
            .as_ref()
            .is_some_and(|c| !crate::cost::ended(c.id()))
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
    for (cost, b) in outcome.work.boards.iter_mut().zip(&boards) {
        *cost = b.cost;
    }
    outcome.work.host = crate::cost::own().since(&host_before);
    outcome.work.machine = crate::cost::Machine::now()
        .zip(machine_before)
        .map(|(now, before)| now.since(&before));
    outcome.work.overlap = *overlap.borrow();
    if pace.is_some() {
        // The host's thread back to the ordinary class for what follows the run (the report).
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: sched_setscheduler and setpriority on the calling thread.
        unsafe {
            libc::sched_setscheduler(0, libc::SCHED_OTHER, &param);
            libc::setpriority(libc::PRIO_PROCESS, 0, 0);
        }
    }
    if let Some(pace) = pace {
        outcome.pace = Some(pace.summary());
    }
    result?;
    Ok(outcome)
}

/// What bounds how far ahead a board may be sent, besides the other boards.
struct Limits {
    /// The run's last boundary.
    end: u64,
    /// The boundary the next stimulus action is taken at.
    action: Option<u64>,
    /// A live run's longest step from here.
    live: Option<u64>,
    /// The world's next controller tick.
    tick: Option<u64>,
}

impl Limits {
    /// The latest boundary the boards `group` may run to without the others: nothing reaches
    /// them from elsewhere before.
    fn horizon(&self, boards: &[Board], group: &[usize]) -> u64 {
        let others = boards
            .iter()
            .filter(|b| b.alive && !group.contains(&b.index))
            .map(|b| b.next.unwrap_or(b.wants));
        [self.action, self.live, self.tick]
            .into_iter()
            .flatten()
            .chain(others)
            .fold(self.end, u64::min)
    }

    /// The horizon of the boards `group` sent ahead together in the steady state, with every board
    /// left waiting for a deadline before it taken into the group (until none is): such a board
    /// would otherwise bound the horizon, and the group would report there only to go on. Sent
    /// ahead too, it wakes at its deadline by itself and reports only when it has something to (a
    /// frame, an abort, a line), as the others do. At most the last boundary before the run's end.
    fn widen(&self, boards: &[Board], group: &mut Vec<usize>) -> u64 {
        let last = self.end.saturating_sub(QUANTUM_US);
        loop {
            let horizon = self.horizon(boards, group).min(last);
            let before = group.len();
            group.extend(
                boards
                    .iter()
                    .filter(|b| {
                        b.alive
                            && b.next.is_none()
                            && b.wants <= horizon
                            && !group.contains(&b.index)
                    })
                    .map(|b| b.index)
                    .collect::<Vec<_>>(),
            );
            if group.len() == before {
                return horizon;
            }
        }
    }
}

/// The steady state, in which boards with work may be sent ahead together and a board may be
/// granted the bus: no line is low (`flags`), no command frame completes now (`command`), nothing
/// else holds it up (`held`: adapter frames waiting, a world), and no board drives a line, waits
/// for an abort's answer or is busy with a command.
fn steady_state(flags: u8, command: bool, held: bool, boards: &[Board]) -> bool {
    flags == 0
        && !command
        && !held
        && boards
            .iter()
            .all(|b| b.drives == 0 && b.aborted == 0 && !b.commanded)
}

/// The grant for board `k`, answered at boundary `t` and sent ahead: the earliest time any other
/// node could have a frame pending on the bus — each other board's current time if it has work or
/// runs, its deadline if it waits (it does nothing before it: no frame that reaches it comes in the
/// steady state), the frames or the work of the report it holds for a later boundary (sent ahead
/// together, it reported there) — and `bound` (the next stimulus action, the warm-up's
/// end, a live step, the run's end; `own`: another board's own frame answered now, whose
/// completion wakes it). `None` outside the steady state with a quiet bus (`steady`:
/// nothing queued, nothing on its way, no babbling) and when it would not reach past `t`. Until
/// then the board may arbitrate and complete its own sensor frames itself (docs/qemu.md,
/// "Lookahead").
fn grant_until(
    boards: &[Board],
    k: usize,
    t: u64,
    steady: bool,
    own: Option<(usize, u64)>,
    bound: u64,
) -> Option<u64> {
    if !steady {
        return None;
    }
    // Another board given its own frame's completion now acts on it then (its next frame).
    let bound = match own {
        Some((node, end)) if node != k => bound.min(end),
        _ => bound,
    };
    let free_until = boards
        .iter()
        .filter(|b| b.alive && b.index != k)
        .map(|b| match (&b.held, b.next) {
            // Its report at a later boundary is in: the frames in it, else its work or deadline
            // from that boundary on.
            (Some((at, Some(up))), _) => {
                let work = match up.sleeps_us {
                    0 => *at,
                    u32::MAX => u64::MAX,
                    us => at.saturating_add(u64::from(us)),
                };
                up.queued()
                    .iter()
                    .map(|q| q.at_us + b.offset)
                    .fold(work, u64::min)
            }
            (Some((_, None)), _) => u64::MAX,
            (None, Some(_)) => b.at,
            (None, None) if b.wakes_at <= b.at => b.at,
            (None, None) => b.wakes_at,
        })
        .fold(bound, u64::min);
    (free_until > t).then_some(free_until)
}

/// Puts the frames board `b` completed itself under its grant through the bus model, each queued
/// at its time, and checks that the model completes each as the board did: a board and the model
/// that disagree fail the run with both figures. Returns them as transfers, in order.
fn replay_done(bus: &mut Bus, b: &Board, done: &[Done]) -> Result<Vec<Transfer>> {
    let name = NODES[b.index];
    let frames: Vec<Frame> = done
        .iter()
        .map(|d| {
            Frame::new(d.frame.id, d.frame.payload())
                .ok_or_else(|| anyhow!("{name} completed an invalid frame {:03X}", d.frame.id))
        })
        .collect::<Result<_>>()?;
    let mut queued = vec![false; done.len()];
    let mut out = Vec::new();
    for (k, (d, frame)) in done.iter().zip(&frames).enumerate() {
        let end = d.completed_us + b.offset;
        let start = end.saturating_sub(u64::from(frame_bits(frame)));
        for (j, (e, f)) in done.iter().zip(&frames).enumerate() {
            let at = e.frame.at_us + b.offset;
            if !queued[j] && (at <= start || j == k) {
                queued[j] = true;
                bus.queue(b.node, usize::from(e.frame.mailbox), *f, at)
                    .map_err(|err| {
                        anyhow!(
                            "{name}'s frame {:03X} completed under its grant: mailbox {} at {at} µs: {err:?}",
                            f.id,
                            e.frame.mailbox
                        )
                    })?;
            }
        }
        let idle_before = bus.idle_from();
        let events = bus.run_until(start + 1);
        let model = match events.as_slice() {
            [Event::Sent {
                node,
                mailbox,
                frame: sent,
                queued_at,
                start: s,
                end: e,
                ..
            }] if *node == b.node && *mailbox == usize::from(d.frame.mailbox) && sent == frame => {
                if *e == end {
                    out.push(Transfer {
                        node: b.index,
                        mailbox: *mailbox,
                        frame: *frame,
                        queued_at: *queued_at,
                        released_at: (d.frame.released_us + b.offset).min(*queued_at),
                        start: *s,
                        end,
                    });
                    continue;
                }
                format!("completes it at {e} µs (start {s} µs)")
            }
            [] => {
                // Where the model does complete it, for the message.
                let later = bus.run_until(end + 10_000);
                match later.iter().find_map(|e| match e {
                    Event::Sent {
                        frame: sent, end, ..
                    } if sent == frame => Some(*end),
                    _ => None,
                }) {
                    Some(e) => format!("completes it at {e} µs"),
                    None => "does not complete it".to_string(),
                }
            }
            [Event::Sent {
                node,
                mailbox,
                frame: sent,
                start: s,
                end: e,
                ..
            }] => format!(
                "starts {:03X} of {} (mailbox {mailbox}) at {s} µs instead, completing at {e} µs",
                sent.id,
                NODES.get(*node).unwrap_or(&"a node")
            ),
            other => format!("runs {other:?}"),
        };
        bail!(
            "{name} completed its frame {:03X} (mailbox {}, queued at {} µs) itself at {end} µs under its grant, but the bus model {model} (the bus idle from {} µs before)",
            frame.id,
            d.frame.mailbox,
            d.frame.at_us + b.offset,
            idle_before
        );
    }
    Ok(out)
}

/// The first boundary after `a` (where an action at `a` is taken).
fn after(a: u64) -> u64 {
    (a / QUANTUM_US + 1) * QUANTUM_US
}

/// The first boundary at or after `w` (where a deadline at `w` is seen).
fn at_or_after(w: u64) -> u64 {
    w.div_ceil(QUANTUM_US).saturating_mul(QUANTUM_US)
}

/// Takes board `b`'s report at boundary `t`: its frames onto the bus, its lines, its deadline.
///
/// `within`: the boundaries it may report at (one, unless it was sent ahead); returns the one it
/// reported at (the last, if its run ended).
fn exchange(
    b: &mut Board,
    within: std::ops::RangeInclusive<u64>,
    bus: &mut Bus,
    notes: &mut Vec<String>,
    work: &mut Work,
) -> Result<u64> {
    let (t, report) = match b.held.take() {
        Some(held) => held,
        None => take_report(b, within, work)?,
    };
    // A granted board reports as one sent ahead, where its completed frames are put through the
    // bus model: any left here would be lost from the bus.
    if !b.done.is_empty() {
        bail!(
            "{} reported {} frame(s) it completed itself at {t} µs outside a grant of the bus",
            NODES[b.index],
            b.done.len()
        );
    }
    apply(b, t, report, bus, notes);
    Ok(t)
}

/// Sends board `b`, left waiting at an earlier boundary, on to boundary `t`: it runs there idle
/// and reports (an exchange at `t` takes the report).
fn send_on(b: &mut Board, t: u64, work: &mut Work) -> Result<()> {
    let on = Down {
        next_us: t - b.offset,
        flags: b.flags,
        ..Down::default()
    };
    b.send(&on)?;
    b.next = Some(t);
    work.catch_ups += 1;
    Ok(())
}

/// Waits for board `b`'s report at one of the boundaries `within` (the last, if its run ended).
fn take_report(
    b: &mut Board,
    within: std::ops::RangeInclusive<u64>,
    work: &mut Work,
) -> Result<(u64, Option<Up>)> {
    let waited = Instant::now();
    let report = crate::pace::timed(crate::pace::Io::Boards, || b.receive(waited, REPORT_LIMIT))?;
    work.waiting_us += waited.elapsed().as_micros() as u64;
    let t = match &report {
        Some(r) => r.at_us.saturating_add(b.offset),
        None => *within.end(),
    };
    if !within.contains(&t) {
        bail!(
            "{} reported for the boundary at {t} µs, expected {} to {} µs (the board and the host disagree on the robot link)",
            NODES[b.index],
            within.start(),
            within.end()
        );
    }
    work.exchanges += 1;
    if let (Some(r), Some(late)) = (&report, work.late.get_mut(b.index)) {
        late.note(r.at_us, r.now_us);
    }
    // What this run of the board took: `b.at`, its last boundary, to `t`.
    let run = pace::SlowRun {
        board: b.index,
        from_us: b.at,
        to_us: t,
        wall: b.last_run,
        cpu: b.last_run_cpu,
        main_loop: b.last_run_main_loop,
    };
    if work.slowest.is_none_or(|s| run.excess() > s.excess()) {
        work.slowest = Some(run);
    }
    if let Some(n) = work.per_board.get_mut(b.index) {
        *n += 1;
    }
    Ok((t, report))
}

/// Takes board `b`'s report at boundary `t` (`None`: its run ended).
fn apply(b: &mut Board, t: u64, report: Option<Up>, bus: &mut Bus, notes: &mut Vec<String>) {
    b.at = t;
    b.next = None;
    let Some(report) = report else {
        // The board ended (its hand-over, or a failure): off the bus from here on.
        b.alive = false;
        b.drives = 0;
        bus.reset_node(b.node, t);
        bus.set_plugged(b.node, false, t);
        notes.push(format!(
            "bus: # {} {} left the bus (its run ended)",
            stamp(t),
            NODES[b.index]
        ));
        return;
    };
    b.drives = report.drives;
    b.aborts = report.aborts & 0b111;
    b.wakes_at = match report.sleeps_us {
        u32::MAX => u64::MAX,
        us => t.saturating_add(u64::from(us)),
    };
    // A board that sleeps has done what a command asked of it.
    b.commanded &= b.wakes_at <= t;
    queue_reported(b, t, &report, bus, notes);
}

/// Queues the frames board `b` handed over in its report at boundary `t` into the bus model, each
/// at the time the board put it into its mailbox.
fn queue_reported(b: &mut Board, t: u64, report: &Up, bus: &mut Bus, notes: &mut Vec<String>) {
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
        if let Err(e) = bus.queue(b.node, usize::from(q.mailbox), frame, queued) {
            notes.push(format!(
                "bus: # {} {}: mailbox {}: {e:?}",
                stamp(t),
                NODES[b.index],
                q.mailbox
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boards() -> Vec<Board> {
        (0..3)
            .map(|k| {
                let firmware = Firmware {
                    elf: "none.elf".into(),
                    machine: "netduino2",
                };
                let mut b = Board::new(k, k, firmware, format!("board-{k}").into(), false);
                b.alive = true;
                b
            })
            .collect()
    }

    /// A run to 10 ms with no stimulus action, live step or tick.
    const PLAIN: Limits = Limits {
        end: 10_000,
        action: None,
        live: None,
        tick: None,
    };

    #[test]
    fn the_horizon_is_the_earliest_boundary_outside_the_group() {
        let limits = PLAIN;
        let mut b = boards();
        b[0].wants = 400;
        b[1].next = Some(800);
        b[2].wants = 1_200;
        // Board 0 alone runs to board 1's next boundary; with board 1, to board 2's deadline.
        assert_eq!(limits.horizon(&b, &[0]), 800);
        assert_eq!(limits.horizon(&b, &[0, 1]), 1_200);
        assert_eq!(limits.horizon(&b, &[0, 1, 2]), 10_000);
        // A board that has ended bounds nothing; a stimulus action, a live step or a tick does.
        b[2].alive = false;
        assert_eq!(limits.horizon(&b, &[0, 1]), 10_000);
        let sooner = Limits {
            action: Some(2_000),
            tick: Some(1_600),
            ..limits
        };
        assert_eq!(sooner.horizon(&b, &[0, 1]), 1_600);
    }

    #[test]
    fn a_grant_reaches_the_earliest_time_another_node_could_send() {
        let mut b = boards();
        b.iter_mut().for_each(|x| x.drives = 0);
        // At 400: board 0 has work; board 1 waits for its deadline at 1_234, board 2 for none.
        for x in b.iter_mut() {
            x.at = 400;
        }
        b[0].wakes_at = 400;
        b[1].wakes_at = 1_234;
        b[2].wakes_at = u64::MAX;
        let steady = steady_state(0, false, false, &b);
        assert!(steady);
        // The waiting board's deadline bounds it (not its boundary: it queues nothing before).
        assert_eq!(grant_until(&b, 0, 400, steady, None, 10_000), Some(1_234));
        // Another board's own frame completing (answered now) wakes it; the board's own does not.
        assert_eq!(
            grant_until(&b, 0, 400, steady, Some((2, 1_000)), 10_000),
            Some(1_000)
        );
        assert_eq!(
            grant_until(&b, 0, 400, steady, Some((0, 1_000)), 10_000),
            Some(1_234)
        );
        // The next stimulus action (or a live step, the run's end) comes first.
        assert_eq!(grant_until(&b, 0, 400, steady, None, 900), Some(900));
        // A board waiting for a deadline gets none while another has work.
        assert_eq!(grant_until(&b, 1, 400, steady, None, 10_000), None);
        // Another board with work, or one sent on (running, or holding its report): none.
        b[1].wakes_at = 400;
        assert_eq!(grant_until(&b, 0, 400, steady, None, 10_000), None);
        b[1].wakes_at = 1_234;
        b[2].next = Some(800);
        assert_eq!(grant_until(&b, 0, 400, steady, None, 10_000), None);
        b[2].next = None;
        // A board that has ended bounds nothing.
        b[1].alive = false;
        assert_eq!(grant_until(&b, 0, 400, steady, None, 10_000), Some(10_000));
        b[1].alive = true;
        // Nothing past the board's own boundary: none.
        assert_eq!(grant_until(&b, 0, 400, steady, None, 400), None);
    }

    #[test]
    fn no_grant_outside_the_steady_state() {
        let mut b = boards();
        for x in b.iter_mut() {
            x.at = 400;
            x.wakes_at = 5_000;
            x.drives = 0;
        }
        b[0].wakes_at = 400;
        let grant = |b: &[Board], steady| grant_until(b, 0, 400, steady, None, 10_000);
        assert_eq!(grant(&b, steady_state(0, false, false, &b)), Some(5_000));
        // A line low, a command frame completing now, a world (or adapter frames waiting).
        assert_eq!(
            grant(&b, steady_state(DOWN_SYNC_LOW, false, false, &b)),
            None
        );
        assert_eq!(grant(&b, steady_state(0, true, false, &b)), None);
        assert_eq!(grant(&b, steady_state(0, false, true, &b)), None);
        // A board busy with a command, one driving a line, one waiting for an abort's answer.
        b[2].commanded = true;
        assert_eq!(grant(&b, steady_state(0, false, false, &b)), None);
        b[2].commanded = false;
        b[1].drives = DRIVES_PD_LOW;
        assert_eq!(grant(&b, steady_state(0, false, false, &b)), None);
        b[1].drives = 0;
        b[1].aborted = 1;
        assert_eq!(grant(&b, steady_state(0, false, false, &b)), None);
        b[1].aborted = 0;
        // A babbling controller (the bus is not quiet: the caller's `steady && quiet`), or one
        // that may not complete a frame as computed (`Bus::alone_from`).
        assert_eq!(grant(&b, false), None);
        let mut bus = Bus::new();
        let nodes: Vec<NodeId> = (0..4).map(|_| bus.add_node()).collect();
        bus.babble(nodes[0], Frame::new(0x700, &[]).unwrap(), 0, u64::MAX);
        assert_eq!(bus.alone_from(nodes[0]), None);
    }

    #[test]
    fn only_a_command_that_may_drive_a_line_keeps_the_boards_apart() {
        use amiro_can::{CanId, Kind, Priority, Topic};
        let command =
            |topic: Topic| CanId::new(Kind::Command, Priority::Medium, topic.byte()).raw();
        // The shutdown command drives SYS_PD_N; a topic the host does not know is not vouched for.
        assert!(may_drive_a_line(command(Topic::Shutdown)));
        assert!(may_drive_a_line(0x2FF));
        assert!(may_drive_a_line(0x203));
        // Requests (a diagnostics topic's too, and its admission policy), LEDs and the motor: the
        // boards decide, sample, light and publish.
        for topic in [
            Topic::MagnetometerX,
            Topic::Gyroscope,
            Topic::ProximityRing,
            Topic::DiWheelDriveDiagnostics,
        ] {
            assert!(!may_drive_a_line(command(topic)), "{topic:?}");
        }
        assert!(!may_drive_a_line(command(Topic::Led3)));
        assert!(!may_drive_a_line(command(Topic::MotorCommand)));
        // A sensor frame reaches no board's software at all.
        assert!(!may_drive_a_line(
            CanId::new(Kind::Sensor, Priority::Medium, Topic::Shutdown.byte()).raw()
        ));
    }

    fn done(id: u16, data: &[u8], mailbox: u8, at_us: u64, completed_us: u64) -> Done {
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Done {
            frame: Queued {
                at_us,
                released_us: at_us,
                id,
                len: data.len() as u8,
                mailbox,
                data: d,
            },
            completed_us,
        }
    }

    #[test]
    fn frames_completed_under_a_grant_are_checked_against_the_bus_model() {
        let b = &boards()[0];
        let bits = |id, data: &[u8]| u64::from(frame_bits(&Frame::new(id, data).unwrap()));
        let fresh = || {
            let mut bus = Bus::new();
            (0..4).for_each(|_| {
                bus.add_node();
            });
            bus
        };
        // Two frames queued at 100 (the lower identifier first, whatever its mailbox), a third in
        // the first's mailbox once it completed: back to back, an intermission apart.
        let e1 = 100 + bits(0x605, &[1, 2]);
        let e2 = e1 + 3 + bits(0x606, &[3]);
        let e3 = e2 + 3 + bits(0x605, &[4, 5]);
        let good = [
            done(0x605, &[1, 2], 1, 100, e1),
            done(0x606, &[3], 0, 100, e2),
            done(0x605, &[4, 5], 1, e1 + 20, e3),
        ];
        let mut bus = fresh();
        let transfers = replay_done(&mut bus, b, &good).unwrap();
        let ends: Vec<u64> = transfers.iter().map(|t| t.end).collect();
        assert_eq!(ends, [e1, e2, e3]);
        assert_eq!(bus.idle_from(), e3 + 3);
        // A board that computed one bit more: the run fails, with both figures.
        let mut bad = good;
        bad[1].completed_us += 1;
        let err = replay_done(&mut fresh(), b, &bad).unwrap_err().to_string();
        assert!(err.contains(&format!("itself at {} µs", e2 + 1)), "{err}");
        assert!(err.contains(&format!("completes it at {e2} µs")), "{err}");
        // One that started the higher identifier first: the model runs the other.
        let mut swapped = good;
        swapped.swap(0, 1);
        swapped[0].completed_us = 100 + bits(0x606, &[3]);
        let err = replay_done(&mut fresh(), b, &swapped)
            .unwrap_err()
            .to_string();
        assert!(err.contains("its frame 606"), "{err}");
        assert!(
            err.contains(&format!(
                "starts 605 of diwheeldrive (mailbox 1) at 100 µs instead, completing at {e1} µs"
            )),
            "{err}"
        );
    }

    #[test]
    fn a_board_waiting_for_a_deadline_before_the_horizon_joins_the_group() {
        let limits = PLAIN;
        let mut b = boards();
        // Board 0 has work; board 1 waits for its deadline at 800, board 2 for one at 4_000.
        b[0].wants = 40;
        b[1].wants = 800;
        b[2].wants = 4_000;
        let mut group = vec![0];
        // Both join (board 2's deadline bounds the horizon once board 1 has joined): the group
        // runs to the last boundary before the run's end.
        assert_eq!(limits.widen(&b, &mut group), 9_960);
        assert_eq!(group, [0, 1, 2]);
        // A board already sent on to a boundary (or holding a report) bounds the horizon and
        // stays out; one with no deadline bounds nothing and stays out too.
        b[1].next = Some(1_200);
        b[2].wants = u64::MAX;
        let mut group = vec![0];
        assert_eq!(limits.widen(&b, &mut group), 1_200);
        assert_eq!(group, [0]);
        // A stimulus action before a waiting board's deadline keeps it out.
        b[1].next = None;
        let sooner = Limits {
            action: Some(600),
            ..limits
        };
        let mut group = vec![0];
        assert_eq!(sooner.widen(&b, &mut group), 600);
        assert_eq!(group, [0]);
    }
}
