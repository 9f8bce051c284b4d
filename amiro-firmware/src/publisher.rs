//! The generic publisher loop every board runs, one task per CAN priority level.
//!
//! A publisher task sleeps until the earliest due topic of its level (or until the command handler
//! wakes it because the table changed), takes the due releases from the sensor-data handler, asks
//! the board's [`Sampler`] for each topic's sample, and queues the frames. The board provides only
//! "what to sample for this topic" — and its sampler locks only the device it reads, so a level
//! blocks another only for one device transfer.
use amiro_can::{Frame, Priority, Topic};
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::handler::{late_by, Release, SensorDataHandler};
use amiro_sensors::trace::{TraceEvent, TraceKind};
use amiro_sensors::tx_queue::{PushOutcome, TxQueue};
use cortex_m::interrupt::InterruptNumber;
use rtic_core::Mutex;
use rtic_sync::channel::Receiver;

use crate::mono::Clock;
use crate::publisher_walk::{next_due, take_next, After, Next, Ranks};
use crate::{health, telemetry};

/// What a board samples for a topic.
pub trait Sampler {
    /// One sample of `topic` taken at `taken_us`: its frames, or none when the device is missing or
    /// the read failed.
    fn sample(&mut self, topic: Topic, taken_us: u64) -> Samples;
}

impl<F: FnMut(Topic, u64) -> Samples> Sampler for F {
    fn sample(&mut self, topic: Topic, taken_us: u64) -> Samples {
        self(topic, taken_us)
    }
}

/// Serves the topics of the CAN priorities `levels` forever (a board with one publisher task per
/// level passes one; a board that publishes only its diagnostics may serve all four from one task);
/// `tx_interrupt` is the board's CAN transmit interrupt, pended after each sample's frames are
/// queued. The board's diagnostics topic is sampled here, from the runtime's health counters; every
/// other topic by the board's `sampler`.
///
/// Deadlines: a release that skipped earlier ones counts those as deadline misses of its level, and
/// a frame queued after its release's deadline (one period after the release) counts as one too and
/// is traced as `deadline-missed` with `missed=0` and how late it was.
pub async fn serve_level<C: Clock, const N: usize>(
    levels: &[Priority],
    wake: &mut Receiver<'static, (), 1>,
    mut handler: impl Mutex<T = SensorDataHandler>,
    mut tx_queue: impl Mutex<T = TxQueue<N>>,
    mut sampler: impl Sampler,
    tx_interrupt: impl InterruptNumber,
) -> ! {
    let ranks = Ranks::of(levels);
    // Nothing due at first (a fresh table's rows are stopped; publisher_walk's tests), and a command
    // giving a row a due time wakes the task; then each due time from the last pass's walk.
    let mut due: Option<u64> = None;
    loop {
        match due {
            Some(due) => {
                let _ = C::timeout_at_us(due, wake.recv()).await;
            }
            None => {
                let task = crate::tracing::suspend(None);
                let _ = wake.recv().await;
                crate::tracing::resume(task);
            }
        }
        due = serve_due::<C, N>(
            ranks,
            &mut handler,
            &mut tx_queue,
            &mut sampler,
            tx_interrupt,
        );
    }
}

// Generic over the task's locks (one copy per publisher task): only the locking is here, the
// work is in the non-generic functions below, so the copies stay small.
fn serve_due<C: Clock, const N: usize>(
    ranks: Ranks,
    handler: &mut impl Mutex<T = SensorDataHandler>,
    tx_queue: &mut impl Mutex<T = TxQueue<N>>,
    sampler: &mut impl Sampler,
    tx_interrupt: impl InterruptNumber,
) -> Option<u64> {
    let now = C::now_us();
    // Take the due releases one at a time under the handler's lock (the first served level's
    // first, each level's earliest first, as `take_due_releases` orders them), each sampled after
    // releasing it: one pass of this loop is one release, which the execution-time analysis
    // charges as one job of its topic (docs/analysis.md, "One topic's job"). Each take makes its
    // row not due at `now`, so the publisher table's size bounds the loop. The walk that takes a
    // release also says what comes after it (`After`), so the job's last release parks without a
    // walk of its own: one walk a release.
    let mut more = true;
    let mut park: Option<u64> = None;
    loop {
        // The loop's only way out, at its header: a walk that finds nothing due, or a release
        // after which nothing is, comes back here to leave (`black_box`: kept as a test of its
        // own, so the compiler does not fold it into the walk's or the sample's branches, and
        // the loop's way out holds neither a walk nor a sample).
        if !core::hint::black_box(more) {
            return park;
        }
        let (release, period_us) = match handler.lock(|h| take_next(h, ranks, now)) {
            Next::Release(release, period_us, after) => {
                (more, park) = match after {
                    After::More => (true, None),
                    After::Park(due) => (false, due),
                };
                (release, period_us)
            }
            Next::Park(due) => {
                (more, park) = (false, due);
                continue;
            }
        };
        serve_release::<C, N>(now, &release, period_us, handler, tx_queue, sampler);
        cortex_m::peripheral::NVIC::pend(tx_interrupt);
    }
}

/// One release taken at `now`: its sample (the board's `sampler`, or the runtime's diagnostics
/// from the health counters), its frames queued. Not inlined into the release loop: the topic
/// families' sample functions are called in here only, so that a topic's job, whose bound leaves
/// the other families' samples out (docs/analysis.md, "One topic's job"), leaves the loop with
/// no branch into a sample it does not take (a branch that ends nowhere, but that the loop's way
/// out would charge with the walk before it).
#[inline(never)]
fn serve_release<C: Clock, const N: usize>(
    now: u64,
    release: &Release,
    period_us: u32,
    handler: &mut impl Mutex<T = SensorDataHandler>,
    tx_queue: &mut impl Mutex<T = TxQueue<N>>,
    sampler: &mut impl Sampler,
) {
    let level = release.priority;
    note_release(now, level, release);
    let topic = release.topic;
    let taken = C::now_us();
    if let Some(board) = topic.diagnostics_of() {
        // The runtime's own topic: frames straight from the health counters.
        let counters = tx_queue.lock(|q| *q.counters());
        // The snapshot under the handler's lock, its six frames made after it.
        let diagnostics = handler.lock(|h| health::snapshot(h, &counters, taken));
        let frames = health::frames_now(&diagnostics, board, release.priority);
        let deadline = sample_deadline(taken, release, period_us);
        queue_frames::<C, N>(tx_queue, level, topic, deadline, frames);
    } else {
        let samples = sampler.sample(topic, taken);
        let deadline = sample_deadline(taken, release, period_us);
        // By reference: the sample stays where the sampler left it (no copy of its eight
        // slots into an iterator).
        let frames = samples.iter().map(|data| data.encode(release.priority));
        queue_frames::<C, N>(tx_queue, level, topic, deadline, frames);
    }
}

/// Queues one sample's frames, tracing each push and counting a frame queued after `deadline`.
fn queue_frames<C: Clock, const N: usize>(
    tx_queue: &mut impl Mutex<T = TxQueue<N>>,
    level: Priority,
    topic: Topic,
    deadline: Option<u64>,
    frames: impl IntoIterator<Item = Frame>,
) {
    for frame in frames {
        let outcome = tx_queue.lock(|q| crate::tasks::enqueue(q, frame));
        note_push(
            C::now_us(),
            level,
            topic,
            deadline,
            frame.id().raw(),
            &outcome,
        );
    }
}

/// Traces and counts the releases a publisher skipped.
#[inline(never)]
fn note_release(now: u64, level: Priority, release: &Release) {
    if let Some(missed) = TraceKind::for_release(release) {
        telemetry::trace(&TraceEvent::new(now, missed));
        health::count_deadline_misses(level, release.missed);
    }
}

/// Traces the sample taken; a periodic sample's deadline is its next release, one period of its
/// row (`period_us`, as the row had it when released) after it (`None` for a one-shot).
#[inline(never)]
fn sample_deadline(taken: u64, release: &Release, period_us: u32) -> Option<u64> {
    telemetry::trace(&TraceEvent::new(
        taken,
        TraceKind::SampleTaken {
            topic: release.topic,
            release_us: release.release_us,
        },
    ));
    if release.once {
        return None;
    }
    Some(release.release_us + u64::from(period_us))
}

/// Traces a frame's push, and counts and traces it as a deadline miss if it was queued after its
/// release's deadline.
#[inline(never)]
fn note_push(
    queued: u64,
    level: Priority,
    topic: Topic,
    deadline: Option<u64>,
    id: u16,
    outcome: &PushOutcome,
) {
    crate::tracing::frame_pushed(queued, id, outcome);
    if let Some(late_us) = late_by(queued, deadline) {
        health::count_late_frame(level);
        telemetry::trace(&TraceEvent::new(
            queued,
            TraceKind::DeadlineMissed {
                topic,
                missed: 0,
                late_us,
            },
        ));
    }
}

/// What a board samples for a topic when some of its groups run on an I2C bus: the sample of such
/// a topic suspends the publisher while the bus runs its scripts (`scripted::sample_on_bus`);
/// every other topic's is ready at once.
pub trait SuspendingSampler {
    /// One sample of `topic` taken at `taken_us`: its frames, or none when the device is missing or
    /// the read failed.
    fn sample(
        &mut self,
        topic: Topic,
        taken_us: u64,
    ) -> impl core::future::Future<Output = Samples>;
}

/// [`serve_level`] for a board whose sampler suspends ([`SuspendingSampler`]): the same releases,
/// deadlines, traces and frames, with the publisher task suspended while a sample's scripts run on
/// the bus (its job's CPU is the code before and after; docs/analysis.md, "Self-suspending
/// publishers and the sensor buses"). A board moves here when its I2C groups sample by script;
/// until every board has, the polled boards keep [`serve_level`], whose state machine has no
/// suspension inside a release (PowerManagement's flash budget pays for no unused one).
///
/// Every await is at the top of the loop: the sample of the release taken in the last pass, or,
/// with none taken, the park until the earliest due time (or the command handler's wake). After
/// them (the loop's join) a pass queues the sample's frames and takes the next release due, or,
/// where the take of that sample's release said nothing else was due, parks on its due time with
/// no walk. So one pass holds the end of one release and the start of the next, and a job — a
/// resumed await, then the code to the next await that is pending — is one pass (docs/analysis.md,
/// "One topic's job").
pub async fn serve_level_suspending<C: Clock, const N: usize>(
    levels: &[Priority],
    wake: &mut Receiver<'static, (), 1>,
    mut handler: impl Mutex<T = SensorDataHandler>,
    mut tx_queue: impl Mutex<T = TxQueue<N>>,
    mut sampler: impl SuspendingSampler,
    tx_interrupt: impl InterruptNumber,
) -> ! {
    let ranks = Ranks::of(levels);
    let mut next: Option<(Release, u32, u64)> = None;
    // The due time the last pass's walk found, when it took no release (`None`: walk for it).
    let mut parked: Option<Option<u64>> = None;
    // Where the last take said nothing else was due (`After::Park`), the park that follows the
    // service of its release, with no walk of its own.
    let mut hint: Option<Option<u64>> = None;
    loop {
        let sampled = match next.take() {
            Some((release, period_us, taken)) => {
                // The suspension: the sample's scripts on the bus (none for a topic off I2C).
                let samples = sampler.sample(release.topic, taken).await;
                // A periodic row stopped while its sample was suspended (a stop command, the
                // shutdown) publishes none of it; a one-shot's frames go out.
                let stopped = !release.once
                    && !handler.lock(|h| {
                        h.publisher(release.topic)
                            .is_some_and(|p| p.is_publishing())
                    });
                let samples = if stopped { Samples::new() } else { samples };
                Some((release, period_us, taken, samples))
            }
            None => {
                let due = match parked.take() {
                    Some(due) => due,
                    None => handler.lock(|h| next_due(h, ranks)),
                };
                match due {
                    Some(due) => {
                        let _ = C::timeout_at_us(due, wake.recv()).await;
                    }
                    None => {
                        let task = crate::tracing::suspend(None);
                        let _ = wake.recv().await;
                        crate::tracing::resume(task);
                    }
                }
                None
            }
        };
        let served = sampled.is_some();
        if let Some((release, period_us, taken, samples)) = sampled {
            let deadline = sample_deadline(taken, &release, period_us);
            let frames = samples
                .into_iter()
                .map(|data| data.encode(release.priority));
            queue_frames::<C, N>(
                &mut tx_queue,
                release.priority,
                release.topic,
                deadline,
                frames,
            );
            cortex_m::peripheral::NVIC::pend(tx_interrupt);
        }
        // The next release due now (the diagnostics' served here, a sensor's sampled at the top),
        // or the park: after a sample whose take said nothing else was due, that take's due time
        // (a row that fell due during the suspension, or a command's change, which wakes the
        // task, makes that park ready at once, and the walk after it finds the release).
        let now = C::now_us();
        let taken = match hint.take().filter(|_| served) {
            Some(due) => {
                parked = Some(due);
                None
            }
            None => match handler.lock(|h| take_next(h, ranks, now)) {
                Next::Release(release, period_us, after) => {
                    hint = match after {
                        After::More => None,
                        After::Park(due) => Some(due),
                    };
                    Some((release, period_us))
                }
                Next::Park(due) => {
                    parked = Some(due);
                    None
                }
            },
        };
        if let Some((release, period_us)) = taken {
            note_release(now, release.priority, &release);
            let taken = C::now_us();
            match release.topic.diagnostics_of() {
                Some(board) => {
                    let counters = tx_queue.lock(|q| *q.counters());
                    let diagnostics = handler.lock(|h| health::snapshot(h, &counters, taken));
                    let frames = health::frames_now(&diagnostics, board, release.priority);
                    let deadline = sample_deadline(taken, &release, period_us);
                    queue_frames::<C, N>(
                        &mut tx_queue,
                        release.priority,
                        release.topic,
                        deadline,
                        frames,
                    );
                    cortex_m::peripheral::NVIC::pend(tx_interrupt);
                    // The next release (if any is due) in the next pass, after a park that a due
                    // time past is ready at once: the take's own due time where it said nothing
                    // else was due, else the walk at the top (`next_due`).
                    parked = hint.take();
                }
                None => next = Some((release, period_us, taken)),
            }
        }
    }
}
