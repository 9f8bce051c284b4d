//! The one seam between the session and the world: bytes out, bytes in with a timeout, a clock.
use std::io;
use std::time::Duration;

/// A byte link to the main board's bootloader (a serial port, a pty, a simulated robot).
pub trait Transport {
    /// Writes all bytes.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads what has arrived, waiting at most `timeout` for the first byte; `Ok(0)` on timeout.
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Monotonic time since the link was opened (virtual time for a simulated robot).
    fn clock(&self) -> Duration;
    /// Waits (between connection attempts).
    fn pause(&mut self, duration: Duration) {
        std::thread::sleep(duration);
    }
    /// Resets the main board through the cable's reset line (RTS) if the link has one wired;
    /// `Ok(false)` when it does not.
    fn pulse_reset(&mut self) -> io::Result<bool> {
        Ok(false)
    }
}
