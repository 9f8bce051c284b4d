//! LightRing's static RTIC priorities, in one place (checked at compile time).
//!
//! LightRing publishes only its diagnostics and acts on LED commands: the command path (CAN receive
//! → command handler → LED latch) runs above the diagnostics publisher and the watchdog, and the
//! receive interrupt above everything but the shutdown request and the monotonic.

/// The one publisher task: LightRing publishes only its diagnostics topic, at every CAN priority,
/// from one task below the LED path.
pub const PUBLISH: u8 = 2;
/// The LED latch: shifts the colours into the TLC5947 and latches them.
pub const LATCH: u8 = 4;
/// Command handling.
pub const CONTROL: u8 = 5;
/// The CAN transmit interrupt.
pub const CAN_TX: u8 = 6;
/// The CAN receive interrupt.
pub const CAN_RX: u8 = 7;
/// The shutdown request (falling SYS_PD_N).
pub const SHUTDOWN: u8 = 7;
/// The monotonic's timer interrupt: above every task.
pub const MONOTONIC: u8 = 8;
/// The watchdog feeder: the least urgent level.
pub const WATCHDOG: u8 = 1;

const _: () = {
    assert!(WATCHDOG < PUBLISH && PUBLISH < LATCH);
    assert!(CONTROL < CAN_TX && CAN_TX < CAN_RX);
    assert!(LATCH < CONTROL);
    assert!(CONTROL < CAN_RX);
    assert!(SHUTDOWN < MONOTONIC && CAN_RX < MONOTONIC);
};
