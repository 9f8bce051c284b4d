//! A topic's sample whose bus work is I2C scripts (docs/i2c.md): the publisher suspends while
//! the bus runs them, instead of polling the bus under its device group's lock.
//!
//! A group's sample is a *job* of one or more rounds (amiro-sensors' `drivers::scripted`: the
//! driver code recorded into a script, replayed on its readings; a check that passed may call for
//! a further script). [`sample_on_bus`] runs a job: under the group's lock the group says what the
//! next round needs ([`ScriptedGroup::step`]: a script, or the frames); with the lock released the
//! publisher hands the script to the bus through its own client slot ([`ScriptPort::run`]) and
//! awaits it; under the lock again the group takes the outcome ([`ScriptedGroup::complete`]). No
//! lock of a device group is held across the bus, so a publisher that waits for the bus blocks no
//! other task; the bus itself orders the scripts (its queue, one script at a time, by the
//! clients' priorities).
//!
//! A group runs one job at a time ([`OneJobAtATime`]): its rounds carry the job's log, so a
//! publisher of another level that wants the same group while a job is under way waits for that
//! job's end (its waker is kept and woken then), suspended like a publisher waiting for the bus.
//!
//! A script that does not end — a device that stretches SCL for ever, a bus stuck low — is ended by
//! the client's timeout on the monotonic ([`I2cPort`]): the script's time on the wire at the bus's
//! [`SCL_HZ`] plus the board's stated allowance (the devices' clock stretching and the other
//! clients' scripts it may wait behind). The dropped transfer aborts the script and resets the
//! block (`i2c_bus`); the group sees [`BusFault::Timeout`], the fault it reports as before.
use core::future::{poll_fn, Future};
use core::task::{Poll, Waker};

use amiro_can::Topic;
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::script::{Readings, Script, ScriptError};
use rtic_core::Mutex;

use crate::i2c_bus::{Client, I2cBus};
use crate::i2c_engine::Block;

/// The sensor buses' SCL rate: 400 kHz on I2C1 and I2C2 of every board (amiro-boards.md; the
/// block's set-up never exceeds it, `i2c_block::Registers`).
pub const SCL_HZ: u32 = 400_000;

/// What the next round of a group's sample needs ([`ScriptedGroup::step`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// The job is done: its frames (none when a device failed or the group is missing; the group
    /// counted it).
    Done(Samples),
    /// Run `script` on the bus, `settle_us` after now at the earliest (a part's settling time
    /// after the previous script's last write), then hand its outcome to
    /// [`ScriptedGroup::complete`].
    Run {
        /// The round's bus work.
        script: Script,
        /// The wait before it (µs; 0 mostly).
        settle_us: u32,
    },
}

/// Why a script gave no readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusFault {
    /// The script failed on the bus (a NACK, a bus error, arbitration lost, an overrun), in the
    /// operation named.
    Script(ScriptError),
    /// The script did not end within its client's timeout: the block was reset.
    Timeout,
}

/// A sensor group whose sample is a job of scripts and their decoding, one job at a time.
pub trait ScriptedGroup {
    /// Rounds a job of this group takes at most; a job still asking for scripts after them is
    /// given up ([`ScriptedGroup::abandon`]) and publishes nothing.
    const MAX_ROUNDS: usize;

    /// The next round of the sample of `topic` at `now_us` (the first, or the one after the last
    /// [`complete`](Self::complete)).
    fn step(&mut self, topic: Topic, now_us: u64) -> Step;

    /// The outcome of the script the last [`step`](Self::step) asked for.
    fn complete(&mut self, outcome: Result<Readings, BusFault>);

    /// Gives the job under way up (its rounds ran out): the group is as before it.
    fn abandon(&mut self);
}

/// A [`ScriptedGroup`] shared by `CLIENTS` publisher tasks (clients `0..CLIENTS`, as their
/// ports number them): the job under way is one client's, and another client's
/// [`step`](Self::step) waits until it is done.
pub struct OneJobAtATime<G, const CLIENTS: usize> {
    group: G,
    /// The client whose job is under way.
    owner: Option<u8>,
    /// The clients waiting for its end, one waker each.
    waiting: [Option<Waker>; CLIENTS],
}

impl<G: ScriptedGroup, const CLIENTS: usize> OneJobAtATime<G, CLIENTS> {
    /// The group, no job under way.
    pub const fn new(group: G) -> Self {
        Self {
            group,
            owner: None,
            waiting: [const { None }; CLIENTS],
        }
    }

    /// The group between jobs (its health report, a test's look).
    pub fn group(&self) -> &G {
        &self.group
    }

    /// The group between jobs.
    pub fn group_mut(&mut self) -> &mut G {
        &mut self.group
    }

    /// The next round of `client`'s sample of `topic` at `now_us`, or `None` (with `waker`
    /// kept, and woken at the job's end) while another client's job is under way. A client past
    /// `CLIENTS` (a wiring mistake) is answered with no frames and never waits.
    pub fn step(&mut self, client: u8, topic: Topic, now_us: u64, waker: &Waker) -> Option<Step> {
        if self.owner.is_some_and(|owner| owner != client) {
            let Some(slot) = self.waiting.get_mut(usize::from(client)) else {
                return Some(Step::Done(Samples::new()));
            };
            match slot {
                Some(kept) if kept.will_wake(waker) => {}
                _ => *slot = Some(waker.clone()),
            }
            return None;
        }
        let step = self.group.step(topic, now_us);
        match step {
            Step::Run { .. } => self.owner = Some(client),
            Step::Done(_) => self.end_job(),
        }
        Some(step)
    }

    /// The outcome of `client`'s script (ignored unless its job is under way).
    pub fn complete(&mut self, client: u8, outcome: Result<Readings, BusFault>) {
        if self.owner == Some(client) {
            self.group.complete(outcome);
        }
    }

    /// Gives `client`'s job up (its rounds ran out).
    pub fn abandon(&mut self, client: u8) {
        if self.owner == Some(client) {
            self.group.abandon();
            self.end_job();
        }
    }

    fn end_job(&mut self) {
        self.owner = None;
        for waker in self.waiting.iter_mut().filter_map(Option::take) {
            waker.wake();
        }
    }
}

/// A publisher task's way to its bus: the bus and the task's client slot on it.
pub trait ScriptPort {
    /// The client's index among the bus's clients (its publisher task's).
    fn client(&self) -> u8;

    /// Runs `script` on the bus, `settle_us` from now at the earliest, and gives its readings,
    /// or why it gave none (its client's timeout included). Dropping the future cancels the
    /// script.
    fn run(
        &mut self,
        script: Script,
        settle_us: u32,
    ) -> impl Future<Output = Result<Readings, BusFault>>;
}

/// One sample of `topic`, taken at `taken_us`, of the group behind `group`: each round's script
/// run on `port` with the group's lock released while the bus runs it.
pub async fn sample_on_bus<G: ScriptedGroup, const CLIENTS: usize>(
    group: &mut impl Mutex<T = OneJobAtATime<G, CLIENTS>>,
    port: &mut impl ScriptPort,
    topic: Topic,
    taken_us: u64,
) -> Samples {
    let client = port.client();
    for _ in 0..G::MAX_ROUNDS {
        let step = poll_fn(|cx| {
            group
                .lock(|g| g.step(client, topic, taken_us, cx.waker()))
                .map_or(Poll::Pending, Poll::Ready)
        })
        .await;
        match step {
            Step::Done(samples) => return samples,
            Step::Run { script, settle_us } => {
                let outcome = port.run(script, settle_us).await;
                group.lock(|g| g.complete(client, outcome));
            }
        }
    }
    group.lock(|g| g.abandon(client));
    Samples::new()
}

/// The monotonic as a client's timeout sees it (the tasks' `mono::Clock` on the chips).
pub trait Deadline {
    /// Microseconds since the monotonic started.
    fn now_us() -> u64;
    /// Waits until the monotonic reaches `at_us`.
    fn delay_until_us(at_us: u64) -> impl Future<Output = ()>;
    /// Runs `future` until it completes or the monotonic reaches `at_us`, whichever is first.
    fn timeout_at_us<F: Future>(at_us: u64, future: F) -> impl Future<Output = Option<F::Output>>;
}

#[cfg(target_os = "none")]
impl<C: crate::mono::Clock> Deadline for C {
    fn now_us() -> u64 {
        C::now_us()
    }

    fn delay_until_us(at_us: u64) -> impl Future<Output = ()> {
        C::delay_until_us(at_us)
    }

    fn timeout_at_us<F: Future>(at_us: u64, future: F) -> impl Future<Output = Option<F::Output>> {
        C::timeout_at_us(at_us, future)
    }
}

/// The timeout of a script: its time on the wire at [`SCL_HZ`], rounded up to the microsecond,
/// plus `allowance_us`.
pub fn script_timeout_us(script: &Script, allowance_us: u32) -> u64 {
    script.bus_time_ns(SCL_HZ).div_ceil(1000) + u64::from(allowance_us)
}

/// A publisher task's client slot on an interrupt-driven [`I2cBus`], with its timeout on the
/// monotonic `D`.
pub struct I2cPort<'a, D, B, const SLOTS: usize> {
    bus: &'a I2cBus<B, SLOTS>,
    client: Client<SLOTS>,
    allowance_us: u32,
    deadline: core::marker::PhantomData<D>,
}

impl<'a, D, B, const SLOTS: usize> I2cPort<'a, D, B, SLOTS> {
    /// The port of `client` on `bus`; a script's timeout is its wire time plus `allowance_us`
    /// ([`script_timeout_us`]).
    pub const fn new(bus: &'a I2cBus<B, SLOTS>, client: Client<SLOTS>, allowance_us: u32) -> Self {
        Self {
            bus,
            client,
            allowance_us,
            deadline: core::marker::PhantomData,
        }
    }
}

impl<D: Deadline, B: Block, const SLOTS: usize> ScriptPort for I2cPort<'_, D, B, SLOTS> {
    fn client(&self) -> u8 {
        // A client's index is below 256 (`I2cBus::client`).
        self.client.index() as u8
    }

    async fn run(&mut self, script: Script, settle_us: u32) -> Result<Readings, BusFault> {
        if settle_us > 0 {
            D::delay_until_us(D::now_us() + u64::from(settle_us)).await;
        }
        let at_us = D::now_us() + script_timeout_us(&script, self.allowance_us);
        match D::timeout_at_us(at_us, self.bus.run(self.client, script)).await {
            Some(Ok(readings)) => Ok(readings),
            Some(Err(error)) => Err(BusFault::Script(error)),
            None => Err(BusFault::Timeout),
        }
    }
}
