//! The body shared by the four publisher tasks, and the small bits of glue the tasks call.
//!
//! Each publisher task serves one CAN priority level: it sleeps until the earliest due topic of its
//! level (or until the command handler wakes it because the table changed), samples every due topic,
//! and queues the frames. Sampling locks only the device it reads, so a level blocks another only
//! for one device transfer.
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use amiro_can::{Priority, Topic};
use amiro_sensors::handler::{Outcome, Rejection, SensorDataHandler};
use amiro_sensors::motion::{DriveController, DriveOutput};
use amiro_sensors::trace::{StopReason, TraceEvent, TraceKind};

use amiro_sensors::tx_queue::TxQueue;
use rtic::Mutex;
use rtic_sync::channel::Receiver;

use crate::sensors::{Compass, Floor, Imu, Samples};
use crate::{mono, platform, telemetry, TX_QUEUE_LEN};

static RX_DROPPED: AtomicU32 = AtomicU32::new(0);
static SHUTTING_DOWN: AtomicBool = AtomicBool::new(false);

/// Counts a received frame that could not be queued (queue full or FIFO overrun).
pub fn count_rx_dropped() {
    RX_DROPPED.fetch_add(1, Ordering::Relaxed);
}

/// Frames lost on the receive side so far (reported at the end of a QEMU run).
#[cfg_attr(not(feature = "qemu"), allow(dead_code))]
pub fn rx_dropped() -> u32 {
    RX_DROPPED.load(Ordering::Relaxed)
}

/// Marks the board as shutting down: motor control keeps the motors off from now on.
pub fn request_shutdown() {
    SHUTTING_DOWN.store(true, Ordering::SeqCst);
}

/// Whether a shutdown request is being handled.
pub fn shutting_down() -> bool {
    SHUTTING_DOWN.load(Ordering::SeqCst)
}

/// Progress marks for the watchdog.
pub struct Liveness {
    motor_control_ran: bool,
}

impl Liveness {
    /// Nothing has run yet.
    pub const fn new() -> Self {
        Self {
            motor_control_ran: false,
        }
    }

    /// Motor control completed a period.
    pub fn motor_control_ran(&mut self) {
        self.motor_control_ran = true;
    }

    /// Whether motor control ran since the last call.
    pub fn take_motor_control_ran(&mut self) -> bool {
        core::mem::replace(&mut self.motor_control_ran, false)
    }
}

/// Emits the trace event for a command's outcome.
pub fn trace_outcome(now: u64, id: u16, outcome: &Result<Outcome, Rejection>) {
    telemetry::trace(&TraceEvent::new(now, TraceKind::for_command(id, outcome)));
}

/// Drives the motors with the controller's output (or keeps them off while shutting down).
pub fn apply_drive(motors: &mut platform::Motors, now: u64, output: &DriveOutput) {
    if SHUTTING_DOWN.load(Ordering::SeqCst) {
        motors.set(0, 0);
        motors.power(false);
        return;
    }
    motors.power(output.motors_enabled);
    motors.set(output.duty_left.get(), output.duty_right.get());
    if output.deadman_tripped {
        telemetry::trace(&TraceEvent::new(
            now,
            TraceKind::MotorsStopped {
                reason: StopReason::DeadMan,
            },
        ));
    }
}

#[inline(never)]
fn trace_push(id: u16, outcome: &amiro_sensors::tx_queue::PushOutcome) {
    let at = mono::now_us();
    for kind in TraceKind::for_push(id, outcome) {
        telemetry::trace(&TraceEvent::new(at, kind));
    }
}

/// Serves the topics of CAN priority `level` forever.
#[allow(clippy::too_many_arguments)]
pub async fn serve_level(
    level: Priority,
    wake: &mut Receiver<'static, (), 1>,
    mut handler: impl Mutex<T = SensorDataHandler>,
    mut tx_queue: impl Mutex<T = TxQueue<TX_QUEUE_LEN>>,
    mut drive: impl Mutex<T = DriveController>,
    mut imu: impl Mutex<T = Imu>,
    mut compass: impl Mutex<T = Compass>,
    mut floor: impl Mutex<T = Floor>,
) -> ! {
    loop {
        match handler.lock(|h| h.next_due(level)) {
            Some(due) => {
                let _ = mono::timeout_at_us(due, wake.recv()).await;
            }
            None => {
                let _ = wake.recv().await;
            }
        }
        let now = mono::now_us();
        // Take the due releases under the handler's lock, sample after releasing it.
        let releases = handler.lock(|h| h.take_due_releases(level, now));
        for release in releases {
            if let Some(missed) = TraceKind::for_release(&release) {
                telemetry::trace(&TraceEvent::new(now, missed));
            }
            let topic = release.topic;
            let taken = mono::now_us();
            let samples: Samples = match topic {
                Topic::Gyroscope | Topic::Accelerometer => imu.lock(|d| d.sample(topic, taken)),
                Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
                    compass.lock(|d| d.sample(topic, taken))
                }
                Topic::FloorProximity => floor.lock(|d| d.sample(topic, taken)),
                Topic::Odometry | Topic::Velocity => {
                    drive.lock(|d| crate::sensors::sample_drive(d, topic))
                }
                _ => Samples::new(),
            };
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
                trace_push(frame.id().raw(), &outcome);
            }
            rtic::pend(platform::CAN_TX_INTERRUPT);
        }
    }
}
