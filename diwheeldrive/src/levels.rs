//! The one place that maps the robot's four CAN priorities to static RTIC priorities.
//!
//! A command's priority bits decide which publisher task serves the topic; the RTIC priorities of
//! those tasks are fixed at compile time (RTIC needs static priorities). The `#[task(priority = ..)]`
//! attributes in `main.rs` use these constants, and the schedule analysis reads them from there.
use amiro_can::Priority;

/// RTIC priority of the publisher serving CAN priority `Urgent`.
pub const PUBLISH_URGENT: u8 = 4;
/// RTIC priority of the publisher serving CAN priority `High`.
pub const PUBLISH_HIGH: u8 = 3;
/// RTIC priority of the publisher serving CAN priority `Medium`.
pub const PUBLISH_MEDIUM: u8 = 2;
/// RTIC priority of the publisher serving CAN priority `Low`.
pub const PUBLISH_LOW: u8 = 1;
/// Command handling runs above every publisher and above motor control: a motor command waits for
/// no control step, only for the copy of the command motor control takes under the
/// `motor_command` lock.
pub const CONTROL: u8 = 5;
/// Motor control (100 Hz, a 10 ms deadline) runs at the low publisher's level, below command
/// handling and every other publisher: its deadline is longer than the jitter budgets of the
/// topics the publishers above serve (deadline-monotonic), so its job (about 180 µs bounded from
/// the machine code) delays none of them. The drive controller is its own, so no lock of the
/// command handler's or the publishers' holds a control step.
pub const MOTOR_CONTROL: u8 = 1;
/// The shutdown sequence runs at motor control's level, so that its motors-off comes after any
/// control step in progress (which may have read the shutdown flag before it was set).
pub const SHUTDOWN_SEQUENCE: u8 = 1;
/// The I2C blocks' event and error interrupts (with `scripted-i2c`: the sensor buses' engines), at
/// command handling's level: above every publisher, whose scripts they run, below the CAN
/// interrupts.
pub const I2C_ENGINE: u8 = 5;
/// The CAN transmit interrupt.
pub const CAN_TX: u8 = 6;
/// The CAN receive interrupt: above transmit, so the 3-frame receive FIFO is emptied even while
/// the transmit path is busy.
pub const CAN_RX: u8 = 7;
/// The shutdown request (falling SYS_PD_N) pre-empts everything but the monotonic.
pub const SHUTDOWN: u8 = 7;
/// The monotonic's timer interrupt: above every task.
pub const MONOTONIC: u8 = 8;

/// The RTIC priority of the publisher task that serves CAN priority `p`.
pub const fn rtic_priority(p: Priority) -> u8 {
    match p {
        Priority::Urgent => PUBLISH_URGENT,
        Priority::High => PUBLISH_HIGH,
        Priority::Medium => PUBLISH_MEDIUM,
        Priority::Low => PUBLISH_LOW,
    }
}

// The mapping is checked where it is defined, at compile time: a more urgent CAN priority must get a
// strictly higher RTIC priority, and every publisher must stay below command handling, which stays
// below the CAN interrupts, which stay below the shutdown request and the monotonic; motor control
// (and the shutdown sequence with it) at the lowest publisher's level.
const _: () = {
    assert!(rtic_priority(Priority::Urgent) > rtic_priority(Priority::High));
    assert!(rtic_priority(Priority::High) > rtic_priority(Priority::Medium));
    assert!(rtic_priority(Priority::Medium) > rtic_priority(Priority::Low));
    assert!(rtic_priority(Priority::Low) >= 1);
    assert!(CONTROL > PUBLISH_URGENT);
    assert!(CONTROL > MOTOR_CONTROL);
    assert!(MOTOR_CONTROL == PUBLISH_LOW);
    assert!(SHUTDOWN_SEQUENCE == MOTOR_CONTROL);
    assert!(CAN_TX > CONTROL);
    assert!(I2C_ENGINE > PUBLISH_URGENT && I2C_ENGINE < CAN_TX);
    assert!(CAN_RX > CAN_TX);
    assert!(SHUTDOWN > CAN_TX);
    assert!(MONOTONIC > SHUTDOWN);
};
