//! The one place that maps the robot's four CAN priorities to PowerManagement's static RTIC
//! priorities, and the levels of its other tasks.
//!
//! A command's priority bits decide which publisher task serves the topic; the RTIC priorities of
//! those tasks are fixed at compile time (RTIC needs static priorities). The `#[task(priority = ..)]`
//! attributes in `main.rs` use these numbers, and the schedule analysis reads them from there.
use amiro_can::Priority;

/// RTIC priority of the publisher serving CAN priority `Urgent`.
pub const PUBLISH_URGENT: u8 = 4;
/// RTIC priority of the publisher serving CAN priority `High`.
pub const PUBLISH_HIGH: u8 = 3;
/// RTIC priority of the publisher serving CAN priority `Medium`.
pub const PUBLISH_MEDIUM: u8 = 2;
/// RTIC priority of the publisher serving CAN priority `Low`.
pub const PUBLISH_LOW: u8 = 1;
/// Command handling and the shutdown sequence run above every publisher.
pub const CONTROL: u8 = 5;
/// The power master's periodic work (VSYS → chargers, battery check) and the watchdog: the least
/// urgent level, so a fed watchdog proves every level above it leaves time.
pub const POWER_MONITOR: u8 = 1;
/// The I2C blocks' event and error interrupts (with `scripted-i2c`: the sensor buses' engines) and
/// the buses' re-arm tasks, at command handling's level: above every client of the buses, below
/// the CAN interrupts.
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

// Checked where it is defined, at compile time: a more urgent CAN priority gets a strictly higher
// RTIC priority, every publisher stays below command handling, which stays below the CAN
// interrupts, which stay below the shutdown request and the monotonic; the F405 has 16 levels.
const _: () = {
    assert!(rtic_priority(Priority::Urgent) > rtic_priority(Priority::High));
    assert!(rtic_priority(Priority::High) > rtic_priority(Priority::Medium));
    assert!(rtic_priority(Priority::Medium) > rtic_priority(Priority::Low));
    assert!(rtic_priority(Priority::Low) >= POWER_MONITOR);
    assert!(POWER_MONITOR >= 1);
    assert!(CONTROL > PUBLISH_URGENT);
    assert!(CAN_TX > CONTROL);
    assert!(I2C_ENGINE > PUBLISH_URGENT && I2C_ENGINE < CAN_TX);
    assert!(CAN_RX > CAN_TX);
    assert!(SHUTDOWN > CAN_TX);
    assert!(MONOTONIC > SHUTDOWN);
    assert!(MONOTONIC <= 15);
};
