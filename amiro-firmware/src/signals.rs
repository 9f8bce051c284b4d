//! The robot's system signals as every module sees them, and the shutdown state.
//!
//! SYS_SYNC_N (open drain, wired-OR) is held low by AMiRo-BLT and by each module until it is
//! initialised; the system is up when the line reads high. A falling SYS_PD_N asks every module to
//! stop and hand over to the bootloader (`shared/reference/amiro-boards.md` §2, §7). A board's
//! `board.rs` hands its two pins to [`Lines`], which implements [`SystemSignals`] on them; the
//! QEMU platform simulates them.
use core::sync::atomic::{AtomicBool, Ordering};

use embedded_hal::digital::OutputPin;

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

/// SYS_SYNC_N and SYS_PD_N as every board wires them: both open-drain outputs the board holds
/// (SYS_PD_N released high: its input level and edge detector still work), SYS_PD_N on pin
/// `PD_PIN` of port C, its falling edge watched on EXTI line `PD_PIN` (the board's `init` sets the
/// edge detector up).
pub struct Lines<Sync, Pd, const PD_PIN: u8> {
    sync: Sync,
    pd: Pd,
}

impl<Sync: OutputPin, Pd: OutputPin, const PD_PIN: u8> Lines<Sync, Pd, PD_PIN> {
    /// The lines on these pins.
    pub const fn new(sync: Sync, pd: Pd) -> Self {
        Self { sync, pd }
    }

    /// Drives SYS_PD_N low: asks every module to shut down (the power board's privilege).
    pub fn drive_shutdown_request(&mut self) {
        // The HAL's pins cannot fail (`Infallible`).
        let _ = self.pd.set_low();
    }
}

impl<Sync: OutputPin, Pd: OutputPin, const PD_PIN: u8> SystemSignals for Lines<Sync, Pd, PD_PIN> {
    fn release_sync(&mut self) {
        let _ = self.sync.set_high();
    }

    fn pull_sync_low(&mut self) {
        let _ = self.sync.set_low();
    }

    fn shutdown_requested(&self) -> bool {
        crate::chip::port_c_reads_low::<PD_PIN>()
    }

    fn clear_shutdown_interrupt(&mut self) {
        crate::chip::clear_exti_pending::<PD_PIN>();
    }
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
