//! Progress marks for the watchdog: a board feeds the independent watchdog from its least urgent
//! task, and only while its essential periodic work (motor control, LED refresh, …) keeps running,
//! so a fed dog proves the whole schedule is alive.

/// Whether the board's essential periodic work ran since the watchdog last looked.
pub struct Liveness {
    ran: bool,
}

impl Liveness {
    /// Nothing has run yet.
    pub const fn new() -> Self {
        Self { ran: false }
    }

    /// The essential work completed a period.
    pub fn mark(&mut self) {
        self.ran = true;
    }

    /// Whether it ran since the last call.
    pub fn take(&mut self) -> bool {
        core::mem::replace(&mut self.ran, false)
    }
}

impl Default for Liveness {
    fn default() -> Self {
        Self::new()
    }
}
