//! The robot's system signals as every module sees them, and the shutdown state.
//!
//! SYS_SYNC_N (open drain, wired-OR) is held low by AMiRo-BLT and by each module until it is
//! initialised; the system is up when the line reads high. A falling SYS_PD_N asks every module to
//! stop and hand over to the bootloader (`shared/reference/amiro-boards.md` §2, §7). A board's
//! `board.rs` implements [`SystemSignals`] on its pins; the QEMU platform simulates them.
use core::sync::atomic::{AtomicBool, Ordering};

static SHUTTING_DOWN: AtomicBool = AtomicBool::new(false);

/// A module's system-signal lines.
pub trait SystemSignals {
    /// Releases SYS_SYNC_N: this module is initialised.
    fn release_sync(&mut self);
    /// Pulls SYS_SYNC_N low: the first step of the shutdown protocol.
    fn pull_sync_low(&mut self);
    /// Whether SYS_PD_N reads low (a shutdown is requested), whatever the edge detector saw.
    fn shutdown_requested(&self) -> bool;
    /// Acknowledges the SYS_PD_N edge interrupt.
    fn clear_shutdown_interrupt(&mut self);
}

/// Handles a SYS_PD_N edge interrupt: a glitch is not a request, so this acts only while the line
/// is really low. Returns whether the shutdown has started (the caller then puts its actuators in
/// their safe state and spawns its shutdown sequence).
pub fn on_shutdown_edge(signals: &mut impl SystemSignals) -> bool {
    signals.clear_shutdown_interrupt();
    if !signals.shutdown_requested() || SHUTTING_DOWN.swap(true, Ordering::SeqCst) {
        return false;
    }
    signals.pull_sync_low();
    true
}

/// Marks the board as shutting down (also for a shutdown this board initiates).
pub fn request_shutdown() {
    SHUTTING_DOWN.store(true, Ordering::SeqCst);
}

/// Whether a shutdown is being handled: nothing may start a publisher or an actuator again.
pub fn shutting_down() -> bool {
    SHUTTING_DOWN.load(Ordering::SeqCst)
}
