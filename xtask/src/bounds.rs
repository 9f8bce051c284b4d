//! Analysed bounds the QEMU scenarios check against.
use std::path::Path;

use anyhow::{bail, Result};

/// Worst-case latency from a publisher's release to its frame in a mailbox.
pub fn publisher_bound_us(_root: &Path, topic: &str, level: &str, period_us: u64) -> Result<u64> {
    bail!("analysis bound for {topic} at {level} every {period_us} µs not wired yet")
}
