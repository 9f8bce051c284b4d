//! A topic's sample whose bus work is an I2C script (docs/i2c.md): the publisher suspends while
//! the bus runs it, instead of polling the bus under its device group's lock.
//!
//! [`sample_on_bus`] takes one sample in three steps: under the group's lock the group says what
//! the sample needs ([`ScriptedGroup::begin`]: a script, or the frames at once); with the lock
//! released the publisher hands the script to the bus through its own client slot
//! ([`ScriptPort::run`]) and awaits it; under the lock again the group decodes the outcome
//! ([`ScriptedGroup::finish`]). No lock of a device group is held across the bus, so a publisher
//! that waits for the bus blocks no other task; the bus itself orders the scripts (its queue, one
//! script at a time, by the clients' priorities).
//!
//! A script that does not end — a device that stretches SCL for ever, a bus stuck low — is ended by
//! the client's timeout on the monotonic ([`I2cPort`]): the script's time on the wire at the bus's
//! [`SCL_HZ`] plus the board's stated allowance (the devices' clock stretching and the other
//! clients' scripts it may wait behind). The dropped transfer aborts the script and resets the
//! block (`i2c_bus`); the group sees [`BusFault::Timeout`], the fault it reports as before.
use core::future::Future;

use amiro_can::Topic;
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::script::{Readings, Script, ScriptError};
use rtic_core::Mutex;

use crate::i2c_bus::{Client, I2cBus};
use crate::i2c_engine::Block;

/// The sensor buses' SCL rate: 400 kHz on I2C1 and I2C2 of every board (amiro-boards.md; the
/// block's set-up never exceeds it, `i2c_block::Registers`).
pub const SCL_HZ: u32 = 400_000;

/// What a topic's sample needs from its bus ([`ScriptedGroup::begin`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Begin {
    /// The frames are ready without the bus (a reading reused, a group in its back-off, a topic
    /// the group does not serve): the publisher does not suspend.
    Frames(Samples),
    /// The bus work of the sample (or of the group's next set-up step), to run before
    /// [`ScriptedGroup::finish`].
    Script(Script),
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

/// A sensor group whose sample is a script and its decoding.
///
/// Another publisher (of another level) may take the group's lock between a `begin` and its
/// `finish` and begin (or finish) a sample of its own: the group keeps no state between the two
/// that a second sample could break, and `finish` decodes from `outcome` and `topic` alone.
pub trait ScriptedGroup {
    /// What the sample of `topic` at `now_us` needs: its script, or its frames at once.
    fn begin(&mut self, topic: Topic, now_us: u64) -> Begin;

    /// The sample's frames from its script's `outcome` (none when the read failed: the group
    /// counts the failure and keeps its fault policy).
    fn finish(&mut self, topic: Topic, now_us: u64, outcome: Result<Readings, BusFault>)
        -> Samples;
}

/// A publisher task's way to its bus: the bus and the task's client slot on it.
pub trait ScriptPort {
    /// Runs `script` on the bus and gives its readings, or why it gave none (its client's
    /// timeout included). Dropping the future cancels the script.
    fn run(&mut self, script: Script) -> impl Future<Output = Result<Readings, BusFault>>;
}

/// One sample of `topic`, taken at `taken_us`, of the group behind `group`: its script run on
/// `port` with the group's lock released while the bus runs it.
pub async fn sample_on_bus<G: ScriptedGroup>(
    group: &mut impl Mutex<T = G>,
    port: &mut impl ScriptPort,
    topic: Topic,
    taken_us: u64,
) -> Samples {
    match group.lock(|g| g.begin(topic, taken_us)) {
        Begin::Frames(samples) => samples,
        Begin::Script(script) => {
            let outcome = port.run(script).await;
            group.lock(|g| g.finish(topic, taken_us, outcome))
        }
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
    async fn run(&mut self, script: Script) -> Result<Readings, BusFault> {
        let at_us = D::now_us() + script_timeout_us(&script, self.allowance_us);
        match D::timeout_at_us(at_us, self.bus.run(self.client, script)).await {
            Some(Ok(readings)) => Ok(readings),
            Some(Err(error)) => Err(BusFault::Script(error)),
            None => Err(BusFault::Timeout),
        }
    }
}
