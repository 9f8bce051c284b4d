//! One I2C bus shared by its clients: a slot per client with a static priority, the
//! interrupt-driven [`Engine`] that runs one client's script at a time, and the future a client
//! awaits (docs/i2c.md, "The queue").
//!
//! - A client puts its script in its slot and awaits it ([`I2cBus::run`]): the [`Transfer`]
//!   submits on its first poll and starts the script at once if the bus is idle.
//! - The engine's interrupts ([`I2cBus::on_event`], [`I2cBus::on_error`]) advance the running
//!   script; at its end the slot holds the result, the client's waker is woken, and the most urgent
//!   waiting script starts (the highest priority; equal priorities in submission order). The bus
//!   is thus scheduled like CAN: non-preemptively, by fixed priority, one script at a time.
//! - A dropped [`Transfer`] (its client's timeout, or a task that gave up) cancels its own slot
//!   only: a waiting script is removed, a running one aborted (the block reset and set up again)
//!   and the next waiting one started.
//!
//! The state is shared by the interrupts and the clients under critical sections whose length is
//! bounded: the engine's actions for one event (at most five), a slot's script
//! and readings copied in, and at most one walk of the slots (no loop longer than the slot count).
//! The same section is what keeps the engine's uninterruptible steps uninterrupted
//! (`i2c_engine`). The waits for a STOP or a repeated START to go out are polled outside it, a
//! section per poll, for at most [`CONDITION_WAIT_NS`](crate::i2c_engine::CONDITION_WAIT_NS) (two SCL periods, on the cycle counter)
//! and at most [`CONDITION_POLLS`] polls. No heap; a slot holds its script and readings
//! by value.
//!
//! A repeated START a device delays past that wait stalls the script with the event interrupt
//! masked (`i2c_engine`); the board's watch task ([`I2cBus::serve_watch`]) looks at it every
//! [`STRETCH_REARM_US`] on the monotonic, at most
//! [`MAX_REARMS`](crate::i2c_engine::MAX_REARMS) times a script, so a device holding SCL costs
//! neither a handler re-entered at the engine's priority nor a wait in it. The same task ends a
//! script still on the bus at its deadline ([`deadline_us`]: its wire time and
//! [`FLAG_ALLOWANCE_US`](crate::i2c_engine::FLAG_ALLOWANCE_US) per event) with
//! [`Failure::Stretched`], has the board clear the lines, and lets the next script run.
use core::cell::UnsafeCell;
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll, Waker};

use amiro_sensors::script::{Failure, Readings, Script, ScriptError};

#[cfg(doc)]
use crate::i2c_engine::deadline_us;
use crate::i2c_engine::{
    deadline_after, wire_us, Block, Condition, Engine, Progress, CONDITION_POLLS, STRETCH_REARM_US,
};
use crate::scripted::Deadline;

/// A client of a bus with `SLOTS` slots: a slot index checked against that count when it was made
/// ([`I2cBus::client`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Client<const SLOTS: usize>(u8);

impl<const SLOTS: usize> Client<SLOTS> {
    /// The slot's index.
    pub fn index(self) -> usize {
        usize::from(self.0)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Free,
    /// Submitted, not started (the slot's `rank` orders it among the waiting).
    Waiting,
    Running,
    Finished(Result<(), ScriptError>),
}

struct Slot {
    priority: u8,
    state: State,
    /// Its rank among the waiting ([`rank`]) while it waits, else 0: worked out at the submission
    /// (in the client's job), so that a script's end compares one number per slot.
    rank: u64,
    script: Script,
    /// Its script's deadline ([`deadline_us`]): worked out at the submission, outside the
    /// critical section (in the client's job), so that a script's start only reads it.
    deadline_us: u32,
    readings: Readings,
    waker: Option<Waker>,
}

struct Inner<B, const SLOTS: usize> {
    block: B,
    engine: Engine,
    slots: [Slot; SLOTS],
    running: Option<usize>,
    submitted: u64,
    /// The re-arm task's waker ([`I2cBus::stalled`]; the watch's, [`I2cBus::serve_watch`]):
    /// woken at a stall and at each script's start.
    rearm: Option<Waker>,
    /// Scripts started so far (wrapping): the running one's number, for the watch.
    started: u32,
    /// The running script's deadline from its start (µs, [`deadline_us`]).
    deadline_us: u32,
    /// A script ended at its deadline and the lines not yet cleared ([`I2cBus::expire`] to
    /// [`I2cBus::recovered`]): no script starts.
    recovering: bool,
}

/// One I2C bus: its block, its engine and a slot per client.
pub struct I2cBus<B, const SLOTS: usize> {
    inner: UnsafeCell<Inner<B, SLOTS>>,
}

// SAFETY: every access to `inner` is inside a critical section (`with`), which on the single-core
// chips masks every interrupt, and on the host is the `std` implementation's lock.
unsafe impl<B: Send, const SLOTS: usize> Sync for I2cBus<B, SLOTS> {}

impl<B: Block, const SLOTS: usize> I2cBus<B, SLOTS> {
    /// The bus over `block`, with a slot per client at `priorities[client]` (higher is more
    /// urgent, as RTIC's priorities). At most 255 clients.
    pub const fn new(block: B, priorities: [u8; SLOTS]) -> Self {
        let mut slots = [const {
            Slot {
                priority: 0,
                state: State::Free,
                rank: 0,
                script: Script::new(),
                deadline_us: 0,
                readings: Readings::empty(),
                waker: None,
            }
        }; SLOTS];
        let mut i = 0;
        while i < SLOTS {
            slots[i].priority = priorities[i];
            i += 1;
        }
        Self {
            inner: UnsafeCell::new(Inner {
                block,
                engine: Engine::new(),
                slots,
                running: None,
                submitted: 0,
                rearm: None,
                started: 0,
                deadline_us: 0,
                recovering: false,
            }),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut Inner<B, SLOTS>) -> R) -> R {
        // SAFETY: the only access to `inner`, and inside the critical section (see `Sync`).
        critical_section::with(|_| f(unsafe { &mut *self.inner.get() }))
    }

    /// Client `index`, if the bus has that slot.
    pub fn client(&self, index: usize) -> Option<Client<SLOTS>> {
        (index < SLOTS && index <= usize::from(u8::MAX)).then_some(Client(index as u8))
    }

    /// Client `INDEX`, checked against the slot count when the program is built (a board's
    /// wiring: a task's fixed slot).
    pub const fn client_at<const INDEX: usize>(&self) -> Client<SLOTS> {
        const { assert!(INDEX < SLOTS && INDEX <= u8::MAX as usize) };
        Client(INDEX as u8)
    }

    /// Runs `script` for `client`: the future submits it on its first poll and gives its
    /// readings (or the failure and the operation it happened in) at its end. Dropping it
    /// cancels the script. Its wire time and deadline ([`deadline_us`]) are worked out here,
    /// once, outside the bus's critical section ([`Transfer::wire_us`]).
    pub fn run(&self, client: Client<SLOTS>, script: Script) -> Transfer<'_, B, SLOTS> {
        let wire_us = wire_us(&script);
        Transfer {
            bus: self,
            client: client.index(),
            deadline_us: deadline_after(&script, wire_us),
            wire_us,
            script,
            stage: Stage::New,
        }
    }

    /// The block's event interrupt (I2Cx_EV): reads SR1 and advances the running script.
    pub fn on_event(&self) {
        let after = self.with(|inner| {
            let sr1 = inner.block.read_sr1();
            let running = inner.running.and_then(|index| inner.slots.get_mut(index));
            let progress = match running {
                Some(slot) => {
                    inner
                        .engine
                        .on_event(sr1, &slot.script, &mut slot.readings, &mut inner.block)
                }
                None => {
                    inner.engine.on_stray_event(&mut inner.block);
                    Progress::Running
                }
            };
            inner.after(progress)
        });
        // The common event (a byte, an address) neither ends the script nor awaits a condition:
        // it returns here.
        match after {
            After::Nothing => {}
            After::Settle => self.after_start(),
            After::Ended(wakers) => self.after_end(wakers),
        }
    }

    /// The block's error interrupt (I2Cx_ER).
    pub fn on_error(&self) {
        let after = self.with(|inner| {
            let sr1 = inner.block.read_sr1();
            let progress = inner.engine.on_error(sr1, &mut inner.block);
            inner.after(progress)
        });
        match after {
            After::Nothing => {}
            After::Settle => self.after_start(),
            After::Ended(wakers) => self.after_end(wakers),
        }
    }

    /// After an interrupt's step that left the engine awaiting a condition (an operation's
    /// START, a repeated START): the condition wait ([`I2cBus::settle`]), then, if it stalled a
    /// repeated START, the re-arm task's wake. Not inlined and called only then, so that the
    /// execution-time analysis charges it per START, not per event (tools/engine-bound).
    #[inline(never)]
    fn after_start(&self) {
        if let Some(stalled) = self.settle() {
            wake(Some(stalled));
        }
    }

    /// After an interrupt's step that ended the script: the next script's first START, if one
    /// started ([`I2cBus::after_start`]), then the wakers the end handed out, outside the
    /// critical section, one call of [`wake`] each (a finished client's; a started one's, which
    /// only an empty script has). Not inlined and called only then: the per-script part
    /// (tools/engine-bound). A script's end stalls nothing (its wait, if any, is for a STOP).
    #[inline(never)]
    fn after_end(&self, [finished, started]: [Option<Waker>; 2]) {
        // Whether a next script started: asked here, once per script, not in the event.
        if self.with(|inner| inner.engine.awaiting().is_some()) {
            self.after_start();
        }
        wake(finished);
        wake(started);
    }

    /// Waits for the condition the engine awaits (a STOP to clear before a START, a repeated
    /// START to go out), each poll a critical section of its own, for at most
    /// [`CONDITION_WAIT_NS`](crate::i2c_engine::CONDITION_WAIT_NS) on the block's cycle counter and at most [`CONDITION_POLLS`] polls;
    /// then lets the engine go on. A client's abort and a new script between two polls change the
    /// wait's number, and the old wait ends without touching the new one. A repeated START that
    /// did not go out stalls the script (`Engine::resume`): the re-arm task's waker is returned,
    /// to be woken outside the critical section. Not inlined: the execution-time analysis states
    /// its loop as a peripheral wait (tools/engine-bound).
    #[inline(never)]
    fn settle(&self) -> Option<Waker> {
        let (wait, start, limit) = self.with(|inner| {
            let wait = inner.engine.awaiting()?;
            Some((wait, inner.block.cycles(), inner.block.condition_cycles()))
        })?;
        let mut cleared = false;
        for _ in 0..CONDITION_POLLS {
            let (pending, now) = self.with(|inner| {
                let pending = inner.engine.awaiting() == Some(wait)
                    && inner.engine.condition_pending(&mut inner.block);
                (pending, inner.block.cycles())
            });
            if !pending {
                cleared = true;
                break;
            }
            if now.wrapping_sub(start) > limit {
                break;
            }
        }
        self.with(|inner| {
            if inner.engine.awaiting() != Some(wait) {
                return None;
            }
            inner.engine.resume(cleared, &mut inner.block);
            match wait {
                // A stalled repeated START: the re-arm task takes over.
                (Condition::Start, _) if !cleared => {
                    inner.engine.stalled()?;
                    inner.rearm.take()
                }
                _ => None,
            }
        })
    }

    /// Resolves to the stall's number when the running script's repeated START is stalled (the
    /// event interrupt masked, `Engine::stalled`); the re-arm task's wait.
    pub fn stalled(&self) -> Stalled<'_, B, SLOTS> {
        Stalled { bus: self }
    }

    /// One look at stall `stall` (a poll of CR1.START in one critical section): the event
    /// interrupt back on if the START is out, else the stall goes on (`Engine::rearm`). A stall
    /// that has ended (the script aborted, failed or re-armed) is left alone.
    pub fn rearm(&self, stall: u32) {
        self.with(|inner| {
            if inner.engine.stalled() == Some(stall) {
                let pending = inner.block.start_pending();
                inner.engine.rearm(pending, &mut inner.block);
            }
        });
    }

    /// The bus's watch, a board task per bus at the engine's priority on the monotonic `D`: it
    /// times each script from its start (the bus wakes it there) to its deadline
    /// ([`deadline_us`]: the wire time and [`FLAG_ALLOWANCE_US`](crate::i2c_engine::FLAG_ALLOWANCE_US)
    /// per event), and looks at a stalled repeated START every
    /// [`STRETCH_REARM_US`] ([`I2cBus::rearm`], at most
    /// [`MAX_REARMS`](crate::i2c_engine::MAX_REARMS) a script). A script still on the bus at its
    /// deadline ends with [`Failure::Stretched`] ([`I2cBus::expire`]); then `clear` (the board's
    /// bus clear on the pins, outside any critical section: up to nine SCL pulses and a STOP,
    /// docs/i2c.md "The bus clear") and the bus goes on with the next script
    /// ([`I2cBus::recovered`]). The deadline runs from the watch's first look after the start:
    /// later than the start by the watch's response at its priority.
    pub async fn serve_watch<D: Deadline>(&self, mut clear: impl FnMut()) -> ! {
        loop {
            let (script, deadline) = self.next_script().await;
            let end = D::now_us() + u64::from(deadline);
            // The next look at a stall (µs), once one is seen.
            let mut look_at = None;
            loop {
                let now = D::now_us();
                let Some(stall) = self.watched(script) else {
                    // Ended (and maybe the next one started: timed from the loop's top).
                    break;
                };
                if now >= end {
                    if self.expire(script) {
                        clear();
                        self.recovered();
                    }
                    break;
                }
                let mut wake_at = end;
                match stall {
                    Some(stall) => {
                        let at = *look_at.get_or_insert(now + u64::from(STRETCH_REARM_US));
                        if now >= at {
                            self.rearm(stall);
                            look_at = None;
                            continue;
                        }
                        wake_at = wake_at.min(at);
                    }
                    None => look_at = None,
                }
                // Until then, or until the bus moves on (another script, a stall).
                D::timeout_at_us(wake_at, self.changed(script, stall)).await;
            }
        }
    }

    /// Resolves to the running script's number and deadline once one runs.
    fn next_script(&self) -> impl Future<Output = (u32, u32)> + '_ {
        core::future::poll_fn(move |cx| {
            self.with(|inner| {
                if inner.running.is_some() {
                    Poll::Ready((inner.started, inner.deadline_us))
                } else {
                    inner.watch_with(cx.waker());
                    Poll::Pending
                }
            })
        })
    }

    /// Whether script `script` still runs: `Some` with its stall, if any (`None`: it ended).
    fn watched(&self, script: u32) -> Option<Option<u32>> {
        self.with(|inner| {
            (inner.running.is_some() && inner.started == script).then(|| inner.engine.stalled())
        })
    }

    /// Resolves when the bus is no longer where the watch saw it: script `script` with `stall`.
    fn changed(&self, script: u32, stall: Option<u32>) -> impl Future<Output = ()> + '_ {
        core::future::poll_fn(move |cx| {
            self.with(|inner| {
                let same = inner.running.is_some()
                    && inner.started == script
                    && inner.engine.stalled() == stall;
                if same {
                    inner.watch_with(cx.waker());
                    Poll::Pending
                } else {
                    Poll::Ready(())
                }
            })
        })
    }

    /// Ends script `script` at its deadline if it still runs: the engine's
    /// [`Engine::expire`] (the block reset), its client's result [`Failure::Stretched`] and its
    /// client woken; no script starts until [`I2cBus::recovered`]. Whether it ended it.
    pub fn expire(&self, script: u32) -> bool {
        let finished = self.with(|inner| {
            if inner.running.is_none() || inner.started != script {
                return None;
            }
            let error = inner.engine.expire(&mut inner.block);
            inner.recovering = true;
            Some(inner.finish(Err(error)))
        });
        match finished {
            Some(waker) => {
                wake(waker);
                true
            }
            None => false,
        }
    }

    /// After the bus clear that follows an [`I2cBus::expire`]: the block set up again (its
    /// reset), and the next waiting script started.
    pub fn recovered(&self) {
        let started = self.with(|inner| {
            inner.recovering = false;
            inner.block.reset();
            inner.start_next()
        });
        let stalled = self.settle();
        wake(started);
        wake(stalled);
    }

    /// Runs `f` on the block (a test's model, or the board's look at the adapter), inside the
    /// critical section.
    pub fn with_block<R>(&self, f: impl FnOnce(&mut B) -> R) -> R {
        self.with(|inner| f(&mut inner.block))
    }
}

/// The rank among the waiting of a slot of `priority` submitted `seq`-th (a slot that does not
/// wait ranks 0): above every slot of lower priority, and among equal priorities the earlier
/// submission higher (the submission number's low 55 bits: 2^55 submissions, a thousand years
/// at a million a second, before it wraps).
fn rank(priority: u8, seq: u64) -> u64 {
    const SEQ: u64 = (1 << 55) - 1;
    (1 << 63) | (u64::from(priority) << 55) | (SEQ - (seq & SEQ))
}

/// Wakes a waker a script's end or start, or a stall, handed out. Not inlined: the execution-time
/// analysis states its call through the waker's vtable (tools/engine-bound).
#[inline(never)]
fn wake(waker: Option<Waker>) {
    if let Some(waker) = waker {
        waker.wake();
    }
}

/// What follows an interrupt's step outside its critical section.
enum After {
    /// Nothing: the script goes on and no condition is awaited (most events).
    Nothing,
    /// A condition to wait for (an operation's START, a repeated START).
    Settle,
    /// The script ended: the wakers its end handed out (a next script, if one started, has its
    /// first START's condition wait awaited as well).
    Ended([Option<Waker>; 2]),
}

impl<B: Block, const SLOTS: usize> Inner<B, SLOTS> {
    /// The watch's waker kept, to be woken at a stall or a script's start.
    fn watch_with(&mut self, waker: &Waker) {
        match &self.rearm {
            Some(kept) if kept.will_wake(waker) => {}
            _ => self.rearm = Some(waker.clone()),
        }
    }

    /// The script's end if the step finished it, and what is left to do outside the section.
    #[inline(always)]
    fn after(&mut self, progress: Progress) -> After {
        match progress {
            Progress::Finished(result) => After::Ended(self.end(result)),
            Progress::Running if self.engine.awaiting().is_some() => After::Settle,
            Progress::Running => After::Nothing,
        }
    }

    /// A script's end: its slot holds its result and its waker is handed out; the next script
    /// starts. At most two wakers: the finished client's and the watch's, at the next script's
    /// start (`start_next`). Once per script, not per event; not inlined, so that the
    /// execution-time analysis bounds it on its own (tools/engine-bound: the handler's
    /// per-script part).
    #[inline(never)]
    fn end(&mut self, result: Result<(), ScriptError>) -> [Option<Waker>; 2] {
        let finished = self.finish(result);
        [finished, self.start_next()]
    }

    fn finish(&mut self, result: Result<(), ScriptError>) -> Option<Waker> {
        let index = self.running.take()?;
        let slot = self.slots.get_mut(index)?;
        slot.state = State::Finished(result);
        slot.waker.take()
    }

    /// Starts the most urgent waiting script if the bus is idle: one walk of the slots, a pass
    /// per slot with no branch out of it (each slot's rank, [`rank`], stored at its submission,
    /// against the best so far), so that the loop is one counted loop of `SLOTS` passes.
    fn start_next(&mut self) -> Option<Waker> {
        if self.running.is_some() || self.recovering {
            return None;
        }
        let mut best = (0, 0);
        for index in 0..SLOTS {
            let key = self.slots.get(index).map_or(0, |slot| slot.rank);
            if key > best.1 {
                best = (index, key);
            }
        }
        if best.1 == 0 {
            return None;
        }
        let index = best.0;
        let slot = self.slots.get_mut(index)?;
        self.running = Some(index);
        slot.state = State::Running;
        slot.rank = 0;
        self.started = self.started.wrapping_add(1);
        self.deadline_us = slot.deadline_us;
        match self.engine.start(&slot.script, &mut self.block) {
            // The watch times it from here.
            Progress::Running => self.rearm.take(),
            // Only an empty script finishes at its start, and `Transfer` never submits one.
            Progress::Finished(result) => {
                self.running = None;
                slot.state = State::Finished(result);
                slot.waker.take()
            }
        }
    }
}

/// The re-arm task's wait for a stall ([`I2cBus::stalled`]).
pub struct Stalled<'a, B, const SLOTS: usize> {
    bus: &'a I2cBus<B, SLOTS>,
}

impl<B: Block, const SLOTS: usize> Future for Stalled<'_, B, SLOTS> {
    type Output = u32;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<u32> {
        self.bus.with(|inner| match inner.engine.stalled() {
            Some(stall) => Poll::Ready(stall),
            None => {
                match &inner.rearm {
                    Some(waker) if waker.will_wake(cx.waker()) => {}
                    _ => inner.rearm = Some(cx.waker().clone()),
                }
                Poll::Pending
            }
        })
    }
}

/// Where a [`Transfer`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Not polled yet.
    New,
    /// Its script is in the slot (waiting, running or finished).
    Submitted,
    /// Resolved (or refused): the slot is not its own.
    Done,
}

/// A client's script on the bus, awaited; see [`I2cBus::run`].
pub struct Transfer<'a, B: Block, const SLOTS: usize> {
    bus: &'a I2cBus<B, SLOTS>,
    client: usize,
    script: Script,
    /// The script's time on the wire at [`SCL_HZ`](amiro_sensors::script::SCL_HZ), µs rounded up.
    wire_us: u32,
    /// The script's deadline ([`deadline_us`]).
    deadline_us: u32,
    stage: Stage,
}

impl<B: Block, const SLOTS: usize> Transfer<'_, B, SLOTS> {
    /// The script's time on the wire at [`SCL_HZ`](amiro_sensors::script::SCL_HZ), µs rounded
    /// up (a client's timeout,
    /// `scripted::script_timeout_us`, without walking the wire again).
    pub fn wire_us(&self) -> u32 {
        self.wire_us
    }
}

/// The answer to a [`Transfer`] that cannot have the client's slot.
const BUSY: ScriptError = ScriptError {
    operation: 0,
    failure: Failure::Busy,
};

impl<B: Block, const SLOTS: usize> Future for Transfer<'_, B, SLOTS> {
    type Output = Result<Readings, ScriptError>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.get_mut();
        match this.stage {
            // Polled after it resolved: the slot may be another transfer's by now.
            Stage::Done => return Poll::Ready(Err(BUSY)),
            Stage::New if this.script.operations().is_empty() => {
                this.stage = Stage::Done;
                return Poll::Ready(Ok(Readings::for_script(&this.script)));
            }
            Stage::New | Stage::Submitted => {}
        }
        // The readings' layout is made here, outside the critical section.
        let readings = Readings::for_script(&this.script);
        let (poll, started) = this.bus.with(|inner| {
            let mut started = None;
            if this.stage == Stage::New {
                let Some(slot) = inner.slots.get_mut(this.client) else {
                    this.stage = Stage::Done;
                    return (Poll::Ready(Err(BUSY)), None);
                };
                if slot.state != State::Free {
                    // The client's slot holds another of its scripts (one at a time).
                    this.stage = Stage::Done;
                    return (Poll::Ready(Err(BUSY)), None);
                }
                slot.script = this.script;
                slot.deadline_us = this.deadline_us;
                slot.readings = readings;
                slot.state = State::Waiting;
                slot.rank = rank(slot.priority, inner.submitted);
                inner.submitted += 1;
                this.stage = Stage::Submitted;
                started = inner.start_next();
            }
            let Some(slot) = inner.slots.get_mut(this.client) else {
                this.stage = Stage::Done;
                return (Poll::Ready(Err(BUSY)), started);
            };
            if let State::Finished(result) = slot.state {
                slot.state = State::Free;
                slot.waker = None;
                this.stage = Stage::Done;
                return (Poll::Ready(result.map(|()| slot.readings)), started);
            }
            match &slot.waker {
                Some(waker) if waker.will_wake(cx.waker()) => {}
                _ => slot.waker = Some(cx.waker().clone()),
            }
            (Poll::Pending, started)
        });
        let stalled = this.bus.settle();
        wake(started);
        wake(stalled);
        poll
    }
}

impl<B: Block, const SLOTS: usize> Drop for Transfer<'_, B, SLOTS> {
    fn drop(&mut self) {
        if self.stage != Stage::Submitted {
            return;
        }
        let client = self.client;
        let started = self.bus.with(|inner| {
            let slot = inner.slots.get_mut(client)?;
            let was = slot.state;
            slot.state = State::Free;
            slot.rank = 0;
            slot.waker = None;
            if was == State::Running && inner.running == Some(client) {
                // The client's own script only: abort it, reset the block, start the next.
                inner.running = None;
                inner.engine.abort(&mut inner.block);
                inner.start_next()
            } else {
                None
            }
        });
        let stalled = self.bus.settle();
        wake(started);
        wake(stalled);
    }
}
