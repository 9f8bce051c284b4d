//! Hand-over to the AMiRo-BLT bootloader, which owns the start of flash and the shutdown sequence.
//!
//! AMiRo-BLT publishes a callback table at a fixed flash address: a magic word ("A-BL"), three
//! version words, then function pointers (hibernate, deep sleep, transportation, restart, handle a
//! shutdown request, seven reserved). DiWheelDrive is a passive module in the shutdown protocol: on a
//! falling SYS_PD_N it stops its peripherals and calls "handle shutdown request", which never returns.

/// Address of the bootloader's callback table.
pub const CALLBACK_TABLE: usize = 0x0800_01C0;
/// The table's magic number, "A-BL".
pub const MAGIC: u32 = 0x412D_424C;
/// Byte offset of the "handle shutdown request" callback in the table.
pub const HANDLE_SHUTDOWN_REQUEST: usize = 32;

/// Calls the bootloader's shutdown-request handler if a valid table is present.
///
/// Returns only when there is no usable table (a bare chip without AMiRo-BLT); the caller then parks
/// the CPU with everything off.
#[cfg(not(feature = "qemu"))]
pub fn hand_over_shutdown() {
    // SAFETY: the table lives in the bootloader's flash, which is always mapped and readable.
    let (magic, callback) = unsafe {
        (
            core::ptr::read_volatile(CALLBACK_TABLE as *const u32),
            core::ptr::read_volatile((CALLBACK_TABLE + HANDLE_SHUTDOWN_REQUEST) as *const u32),
        )
    };
    // A callback must be a Thumb address inside the bootloader's 24 KiB.
    let plausible = callback & 1 == 1 && (0x0800_0000..0x0800_6000).contains(&(callback & !1));
    if magic == MAGIC && plausible {
        // SAFETY: AMiRo-BLT documents this pointer as `void (*)(void)`; it takes over the system.
        let handler: extern "C" fn() = unsafe { core::mem::transmute(callback as usize) };
        handler();
    }
}
