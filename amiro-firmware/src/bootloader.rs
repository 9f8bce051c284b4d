//! The hand-over to AMiRo-BLT, which owns the start of flash and the low-power and shutdown modes.
//!
//! AMiRo-BLT publishes a callback table at a fixed flash address: a magic word ("A-BL"), three
//! version words, then function pointers (hibernate, deep sleep, transportation, restart, handle a
//! shutdown request, seven reserved) — `shared/reference/amiro-boards.md` §2.

use crate::layout::FLASH_BASE;

/// Address of the bootloader's callback table.
pub const CALLBACK_TABLE: usize = 0x0800_01C0;
/// The table's magic number, "A-BL".
pub const MAGIC: u32 = 0x412D_424C;

/// The bootloader's entry points, by byte offset in the callback table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Callback {
    /// Enter hibernate mode.
    Hibernate = 16,
    /// Enter deep-sleep mode.
    DeepSleep = 20,
    /// Enter transportation mode.
    Transportation = 24,
    /// Restart the system.
    Restart = 28,
    /// Handle a shutdown request another module initiated (passive modules).
    HandleShutdownRequest = 32,
}

#[cfg(feature = "f1")]
const FAMILY: crate::layout::Family = crate::layout::Family::F1;
#[cfg(feature = "f4")]
const FAMILY: crate::layout::Family = crate::layout::Family::F4;

/// The callback's address, if a valid table is present and the pointer is a Thumb address inside
/// the bootloader's region.
pub fn callback(which: Callback) -> Option<usize> {
    // SAFETY: the table lives in the bootloader's flash, which is always mapped and readable.
    let (magic, pointer) = unsafe {
        (
            core::ptr::read_volatile(CALLBACK_TABLE as *const u32),
            core::ptr::read_volatile((CALLBACK_TABLE + which as usize) as *const u32),
        )
    };
    let region = FLASH_BASE..FLASH_BASE + FAMILY.bootloader_bytes();
    (magic == MAGIC && pointer & 1 == 1 && region.contains(&(pointer & !1)))
        .then_some(pointer as usize)
}

/// Hands over to AMiRo-BLT's `which` callback (never returns on a robot); parks the CPU in the
/// safe state when there is no bootloader (a bare development chip).
///
/// The bootloader's handler must not be pre-empted and may wait for the other modules for a long
/// time, so first: the board's safe state, interrupts off and cleared, CAN interrupts off, and the
/// independent watchdog (which cannot be stopped) stretched to its longest period.
pub fn hand_over(which: Callback) -> ! {
    #[cfg(feature = "qemu")]
    {
        let _ = which;
        crate::fault::enter_safe_state();
        crate::qemu::finish("shutdown hand-over");
        crate::fault::halt()
    }
    #[cfg(not(feature = "qemu"))]
    hand_over_to_bootloader(which)
}

#[cfg(not(feature = "qemu"))]
fn hand_over_to_bootloader(which: Callback) -> ! {
    cortex_m::interrupt::disable();
    crate::fault::enter_safe_state();
    // SAFETY: from here on nothing else runs; these are the application's last register writes.
    unsafe {
        let nvic = &*cortex_m::peripheral::NVIC::PTR;
        for (enable, pending) in nvic.icer.iter().zip(nvic.icpr.iter()) {
            enable.write(u32::MAX);
            pending.write(u32::MAX);
        }
        let syst = &*cortex_m::peripheral::SYST::PTR;
        syst.csr.write(0);
    }
    // SAFETY: CAN1 exists at this address on both chips; nothing uses it any more.
    let can = unsafe { crate::bxcan::Mmio::new(crate::bxcan::CAN1_BASE) };
    crate::bxcan::disable_interrupts(&can);
    crate::watchdog::stretch_to_longest();
    if let Some(address) = callback(which) {
        // SAFETY: AMiRo-BLT documents each pointer as `void (*)(void)`; it takes over the system.
        let handler: extern "C" fn() = unsafe { core::mem::transmute(address) };
        handler();
    }
    crate::fault::halt()
}
