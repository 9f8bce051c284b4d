//! Applying the drive controller's output to the motors (or keeping them off while the board
//! shuts down), and tracing a dead-man stop.
use amiro_firmware::telemetry;
use amiro_sensors::motion::DriveOutput;
use amiro_sensors::trace::{StopReason, TraceEvent, TraceKind};

use crate::platform::Motors;

/// Drives the motors with the controller's output (or keeps them off while shutting down).
pub fn apply_drive(motors: &mut Motors, now: u64, output: &DriveOutput) {
    if amiro_firmware::signals::shutting_down() {
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

/// Traces the motors stopping for the shutdown.
pub fn trace_shutdown_stop(now: u64) {
    telemetry::trace(&TraceEvent::new(
        now,
        TraceKind::MotorsStopped {
            reason: StopReason::Shutdown,
        },
    ));
}
