//! The generic publisher loop every board runs, one task per CAN priority level.
//!
//! A publisher task sleeps until the earliest due topic of its level (or until the command handler
//! wakes it because the table changed), takes the due releases from the sensor-data handler, asks
//! the board's [`Sampler`] for each topic's sample, and queues the frames. The board provides only
//! "what to sample for this topic" — and its sampler locks only the device it reads, so a level
//! blocks another only for one device transfer.
use amiro_can::{Priority, Topic};
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::handler::SensorDataHandler;
use amiro_sensors::trace::{TraceEvent, TraceKind};
use amiro_sensors::tx_queue::{PushOutcome, TxQueue};
use cortex_m::interrupt::InterruptNumber;
use rtic_core::Mutex;
use rtic_sync::channel::Receiver;

use crate::mono::Clock;
use crate::telemetry;

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

// One copy for the four publisher tasks (they are generic over their locks).
#[inline(never)]
fn trace_push(at: u64, id: u16, outcome: &PushOutcome) {
    for kind in TraceKind::for_push(id, outcome) {
        telemetry::trace(&TraceEvent::new(at, kind));
    }
}

/// Serves the topics of CAN priority `level` forever; `tx_interrupt` is the board's CAN transmit
/// interrupt, pended after each sample's frames are queued.
pub async fn serve_level<C: Clock, const N: usize>(
    level: Priority,
    wake: &mut Receiver<'static, (), 1>,
    mut handler: impl Mutex<T = SensorDataHandler>,
    mut tx_queue: impl Mutex<T = TxQueue<N>>,
    mut sampler: impl Sampler,
    tx_interrupt: impl InterruptNumber,
) -> ! {
    loop {
        match handler.lock(|h| h.next_due(level)) {
            Some(due) => {
                let _ = C::timeout_at_us(due, wake.recv()).await;
            }
            None => {
                let _ = wake.recv().await;
            }
        }
        let now = C::now_us();
        // Take the due releases under the handler's lock, sample after releasing it.
        let releases = handler.lock(|h| h.take_due_releases(level, now));
        for release in releases {
            if let Some(missed) = TraceKind::for_release(&release) {
                telemetry::trace(&TraceEvent::new(now, missed));
            }
            let topic = release.topic;
            let taken = C::now_us();
            let samples = sampler.sample(topic, taken);
            telemetry::trace(&TraceEvent::new(
                taken,
                TraceKind::SampleTaken {
                    topic,
                    release_us: release.release_us,
                },
            ));
            for data in samples {
                let frame = data.encode(release.priority);
                let outcome = tx_queue.lock(|q| q.push(frame));
                trace_push(C::now_us(), frame.id().raw(), &outcome);
            }
            cortex_m::peripheral::NVIC::pend(tx_interrupt);
        }
    }
}
