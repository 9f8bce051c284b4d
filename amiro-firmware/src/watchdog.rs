//! The independent watchdog (IWDG), at register level: the same block at the same address on the
//! F103 and the F405. It runs from the ~40 kHz (F1) / 32 kHz (F4) LSI and, once started, cannot be
//! stopped; only a reset does.
//!
//! Every board starts it first thing in `init` at the boot's timeout (so nothing in the boot can
//! spin for ever), switches it to its run-time timeout at the end of `init` (`tasks::come_up`),
//! feeds it from its least urgent task, and stretches it to its longest period before handing over
//! to AMiRo-BLT. The QEMU build has no watchdog (the calls do nothing).

const IWDG: usize = 0x4000_3000;
const KR: usize = 0x00;
const PR: usize = 0x04;
const RLR: usize = 0x08;
const SR: usize = 0x0C;

/// LSI frequency used to compute the reload value (the F1's nominal 40 kHz; the F4's 32 kHz makes
/// every timeout 25 % longer, still within the boards' margins).
pub const LSI_HZ: u32 = 40_000;
const _: () = assert!(
    LSI_HZ.is_multiple_of(4000),
    "divider() divides LSI_HZ by 4000 exactly"
);

fn write(offset: usize, value: u32) {
    // SAFETY: a register of the IWDG; writes are the documented key/prescaler/reload sequence.
    unsafe { core::ptr::write_volatile((IWDG + offset) as *mut u32, value) }
}

fn read(offset: usize) -> u32 {
    // SAFETY: as in `write`.
    unsafe { core::ptr::read_volatile((IWDG + offset) as *const u32) }
}

/// Prescaler code and reload value for `timeout_ms` (saturating at the longest the block can do).
pub const fn divider(timeout_ms: u32) -> (u32, u32) {
    let mut code = 0;
    while code < 6 {
        // LSI_HZ · t / (1000 · 4 · 2^code) as a shift: no 64-bit division in the flash.
        let ticks = ((LSI_HZ / 4000) as u64 * timeout_ms as u64) >> code;
        if ticks <= 0x1000 {
            let reload = if ticks == 0 { 0 } else { ticks - 1 };
            return (code, reload as u32);
        }
        code += 1;
    }
    (6, 0xFFF)
}

/// Starts the watchdog (or shortens/lengthens a running one) with a reset after `timeout_ms`
/// without a feed. The wait for the block to take the new values is bounded.
pub fn start(timeout_ms: u32) {
    if cfg!(feature = "qemu") {
        // QEMU's STM32 machines have no IWDG (an access would fault).
        return;
    }
    let (code, reload) = divider(timeout_ms);
    write(KR, 0xCCCC);
    write(KR, 0x5555);
    write(PR, code);
    write(RLR, reload);
    // PVU/RVU clear within a few LSI cycles; bounded so a dead LSI cannot hang the boot.
    for _ in 0..100_000 {
        if read(SR) & 0b11 == 0 {
            break;
        }
    }
    write(KR, 0xAAAA);
    // Logged only once the log runs (the boot's first start comes before it; `boot_report` says
    // that one ran): the run-time timeout at the end of `init`, and the hand-over's stretch.
    let mut digits = [0u8; 10];
    crate::log!(
        "watchdog: reset after ",
        crate::telemetry::decimal(timeout_ms.min(26_214), &mut digits),
        " ms without a feed"
    );
    crate::health::watchdog_started();
}

/// Reloads the counter. The first feed is logged (through the trace drain): the tasks and the
/// monotonic run.
pub fn feed() {
    use core::sync::atomic::{AtomicBool, Ordering};
    static FED: AtomicBool = AtomicBool::new(false);
    if cfg!(feature = "qemu") {
        return;
    }
    write(KR, 0xAAAA);
    if !FED.swap(true, Ordering::Relaxed) {
        // Written by the trace drain (priority 0): the feeding task only queues it.
        crate::channels::defer_log("watchdog: first feed");
    }
}

/// The longest period (~26 s at 40 kHz), before handing over to the bootloader.
pub fn stretch_to_longest() {
    start(u32::MAX);
}

// Checked at every firmware build (this module compiles for the chips only): 40 kHz / 4 = 10
// ticks per ms; 500 ms need 5000 ticks at /4 (over 4096), so /8; beyond /256 × 4096 ticks (≈ 26 s)
// the longest period.
const _: () = {
    assert!(matches!(divider(400), (0, 3_999)));
    assert!(matches!(divider(500), (1, 2_499)));
    assert!(matches!(divider(2_000), (3, 2_499)));
    assert!(matches!(divider(0), (0, 0)));
    assert!(matches!(divider(26_214), (6, 4_095)));
    assert!(matches!(divider(u32::MAX), (6, 0xFFF)));
};
