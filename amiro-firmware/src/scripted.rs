//! A topic's sample whose bus work is I2C scripts (docs/i2c.md): the publisher suspends while
//! the bus runs them, instead of polling the bus under its device group's lock.
//!
//! A group's sample is a *job* of one or more scripts (amiro-sensors' `drivers::scripted`: each
//! script built from the drivers' register maps and decoded by their decode functions; a check
//! that passed may call for a further script). Where the job stands is the publisher's own
//! ([`ScriptedGroup::Job`], a few bytes), so publishers of two levels whose samples of one group
//! overlap each keep theirs.
//! [`sample_on_bus`] runs a job: under the group's lock the group says what the sample needs first
//! ([`ScriptedGroup::begin`]: a script, or the frames); with the lock released the publisher hands
//! the script to the bus through its own client slot ([`ScriptPort::run`]) and awaits it; under
//! the lock again the group takes the outcome and says what comes next
//! ([`ScriptedGroup::resume`]). No lock of a device group is held across the bus, so a publisher
//! that waits for the bus blocks no other task; the bus itself orders the scripts (its queue, one
//! script at a time, by the clients' priorities).
//!
//! A script that does not end — a device that stretches SCL for ever, a bus stuck low — is ended by
//! the client's timeout on the monotonic ([`I2cPort`]): the script's time on the wire at the bus's
//! [`SCL_HZ`] plus the board's stated allowance (the devices' clock stretching and the other
//! clients' scripts it may wait behind). The dropped transfer aborts the script and resets the
//! block (`i2c_bus`); the group sees [`BusFault::Timeout`], the fault a polled master's timeout
//! was.
use core::future::Future;

use amiro_can::Topic;
use amiro_sensors::drivers::scripted::{self, Job, Next, ScriptResult, ScriptedSensors};
use amiro_sensors::drivers::suite::{Samples, Supervised};
use amiro_sensors::script::{Readings, Script, ScriptError};
use rtic_core::Mutex;

use crate::i2c_bus::{Client, I2cBus};
use crate::i2c_engine::Block;

/// The sensor buses' SCL rate ([`amiro_sensors::script::SCL_HZ`]; the block's set-up never
/// exceeds it, `i2c_block::Registers`).
pub use amiro_sensors::script::SCL_HZ;

/// What a group's sample needs next ([`ScriptedGroup::begin`], [`ScriptedGroup::resume`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// The sample is done: its frames (none when a device failed or the group is missing; the
    /// group counted it).
    Done(Samples),
    /// Run `script` on the bus, `settle_us` after now at the earliest (a part's settling time
    /// after the previous script's last write), then hand its outcome to
    /// [`ScriptedGroup::resume`].
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

/// A script's outcome as amiro-sensors' decoders take it (a client's timeout is the kind a polled
/// master's timeout had).
pub fn script_result(outcome: Result<Readings, BusFault>) -> ScriptResult {
    match outcome {
        Ok(readings) => Ok(readings),
        Err(BusFault::Script(error)) => Err(error),
        Err(BusFault::Timeout) => scripted::timed_out(),
    }
}

/// A sensor group whose sample is a job of scripts and their decoding.
pub trait ScriptedGroup {
    /// A sample's log between its scripts, kept by the publisher that takes the sample.
    type Job;

    /// Scripts a sample takes at most; a sample still asking for one after them publishes
    /// nothing (the group is as before it).
    const MAX_ROUNDS: usize;

    /// A job not begun.
    fn new_job() -> Self::Job;

    /// The sample of `topic` at `now_us`, begun in `job`: its first script, or its frames.
    fn begin(&mut self, job: &mut Self::Job, topic: Topic, now_us: u64) -> Step;

    /// The same sample with its last script's `outcome`: the next script, or its frames.
    fn resume(
        &mut self,
        job: &mut Self::Job,
        topic: Topic,
        now_us: u64,
        outcome: Result<Readings, BusFault>,
    ) -> Step;
}

fn step_of(next: Next<Samples>) -> Step {
    match next {
        Next::Done(samples) => Step::Done(samples),
        Next::Run { script, settle_us } => Step::Run { script, settle_us },
    }
}

/// amiro-sensors' supervised groups whose scripts they build and decode themselves
/// (`drivers::scripted`): the fault policy, the back-off and the stepwise set-up are the
/// blocking path's (`Supervised`'s, one code for both).
impl<G: ScriptedSensors> ScriptedGroup for Supervised<G> {
    type Job = Job<G::Stage>;
    const MAX_ROUNDS: usize = G::MAX_SCRIPTS;

    fn new_job() -> Self::Job {
        Job::new()
    }

    fn begin(&mut self, job: &mut Self::Job, topic: Topic, now_us: u64) -> Step {
        step_of(self.begin_scripted(job, topic, now_us))
    }

    fn resume(
        &mut self,
        job: &mut Self::Job,
        topic: Topic,
        now_us: u64,
        outcome: Result<Readings, BusFault>,
    ) -> Step {
        step_of(self.resume_scripted(job, topic, now_us, &script_result(outcome)))
    }
}

/// A publisher task's way to its bus: the bus and the task's client slot on it.
pub trait ScriptPort {
    /// Runs `script` on the bus, `settle_us` from now at the earliest, and gives its readings,
    /// or why it gave none (its client's timeout included). Dropping the future cancels the
    /// script.
    fn run(
        &mut self,
        script: Script,
        settle_us: u32,
    ) -> impl Future<Output = Result<Readings, BusFault>>;
}

/// One sample of `topic`, taken at `taken_us`, of the group behind `group`: each script run on
/// `port` with the group's lock released while the bus runs it.
pub async fn sample_on_bus<G: ScriptedGroup>(
    group: &mut impl Mutex<T = G>,
    port: &mut impl ScriptPort,
    topic: Topic,
    taken_us: u64,
) -> Samples {
    let mut job = G::new_job();
    let mut step = group.lock(|g| g.begin(&mut job, topic, taken_us));
    for _ in 0..G::MAX_ROUNDS {
        match step {
            Step::Done(samples) => return samples,
            Step::Run { script, settle_us } => {
                let outcome = port.run(script, settle_us).await;
                step = group.lock(|g| g.resume(&mut job, topic, taken_us, outcome));
            }
        }
    }
    match step {
        Step::Done(samples) => samples,
        Step::Run { .. } => Samples::new(),
    }
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
    async fn run(&mut self, script: Script, settle_us: u32) -> Result<Readings, BusFault> {
        if settle_us > 0 {
            D::delay_until_us(D::now_us() + u64::from(settle_us)).await;
        }
        // The transfer works the script's wire time out once (outside the bus's critical
        // section); the timeout is that and the allowance, as `script_timeout_us` has it.
        let transfer = self.bus.run(self.client, script);
        let at_us = D::now_us() + u64::from(transfer.wire_us()) + u64::from(self.allowance_us);
        match D::timeout_at_us(at_us, transfer).await {
            Some(Ok(readings)) => Ok(readings),
            Some(Err(error)) => Err(BusFault::Script(error)),
            None => Err(BusFault::Timeout),
        }
    }
}
