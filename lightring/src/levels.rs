//! LightRing's static RTIC priorities, in one place (checked at compile time).
//!
//! LightRing publishes nothing but acts on LED commands: the command path (CAN receive → command
//! handler → LED latch) runs above the watchdog, and the receive interrupt above everything but the
//! shutdown request and the monotonic.

/// The LED latch: shifts the colours into the TLC5947 and latches them.
pub const LATCH: u8 = 4;
/// Command handling.
pub const CONTROL: u8 = 5;
/// The CAN receive interrupt.
pub const CAN_RX: u8 = 7;
/// The shutdown request (falling SYS_PD_N).
pub const SHUTDOWN: u8 = 7;
/// The monotonic's timer interrupt: above every task.
pub const MONOTONIC: u8 = 8;
/// The watchdog feeder: the least urgent level.
pub const WATCHDOG: u8 = 1;

const _: () = {
    assert!(WATCHDOG < LATCH);
    assert!(LATCH < CONTROL);
    assert!(CONTROL < CAN_RX);
    assert!(SHUTDOWN < MONOTONIC && CAN_RX < MONOTONIC);
};
