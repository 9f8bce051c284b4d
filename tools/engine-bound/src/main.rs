//! The I2C engine's interrupt handlers as a board binds them (`I2cBus::on_event`, `on_error` over
//! I2C2's registers), in an image of their own so that `xtask wcet --elf` can bound them before a
//! board uses them (README.md).
#![no_std]
#![no_main]

use amiro_firmware::i2c::I2C2;
use amiro_firmware::i2c_block::Registers;
use amiro_firmware::i2c_bus::I2cBus;
use amiro_firmware::i2c_engine::{Engine, Progress};
use amiro_sensors::script::{Readings, Script};

#[cfg(feature = "f1")]
static BUS: I2cBus<Registers, 4> =
    // SAFETY: I2C2 is this image's only user of the block (the image never runs).
    I2cBus::new(
        unsafe { Registers::new(I2C2, 36_000_000, 72_000_000) },
        [4, 3, 2, 1],
    );

#[cfg(feature = "f4")]
static BUS: I2cBus<Registers, 5> =
    // SAFETY: as above.
    I2cBus::new(
        unsafe { Registers::new(I2C2, 42_000_000, 168_000_000) },
        [5, 4, 3, 2, 1],
    );

/// I2Cx_EV's handler.
#[no_mangle]
#[inline(never)]
pub extern "C" fn i2c_event() {
    BUS.on_event();
}

/// I2Cx_ER's handler.
#[no_mangle]
#[inline(never)]
pub extern "C" fn i2c_error() {
    BUS.on_error();
}

/// One look of the bus's re-arm task at a stalled repeated START (`I2cBus::rearm`: a poll of
/// CR1.START in a critical section, the event interrupt back on if it is out).
#[no_mangle]
#[inline(never)]
pub extern "C" fn i2c_rearm(stall: u32) {
    BUS.rearm(stall);
}

/// The engine's step for one event alone (`Engine::on_event`: the state machine and its register
/// actions), without the bus around it (its critical section, the script's end, the condition
/// wait), on a script and readings the caller passes (not inlined: bounded on its own).
#[no_mangle]
#[inline(never)]
pub extern "Rust" fn engine_event(
    engine: &mut Engine,
    sr1: u16,
    script: &Script,
    readings: &mut Readings,
    block: &mut Registers,
) -> Progress {
    engine.on_event(sr1, script, readings, block)
}

/// The engine's step for one error event alone (`Engine::on_error`).
#[no_mangle]
#[inline(never)]
pub extern "Rust" fn engine_error(
    engine: &mut Engine,
    sr1: u16,
    block: &mut Registers,
) -> Progress {
    engine.on_error(sr1, block)
}

/// What a finished client's waker does in a board's image (RTIC's executor `waker_wake` calls the
/// task's pend closure: one store to NVIC ISPR): the stated target of the engine's wakes.
#[no_mangle]
#[inline(never)]
pub extern "C" fn pend_dispatcher() {
    // SAFETY: NVIC ISPR0, write-1-to-set; bit 0 (no interrupt of this image).
    unsafe { core::ptr::write_volatile(0xE000_E200 as *mut u32, 1) }
}

#[used]
static HANDLERS: [extern "C" fn(); 3] = [i2c_event, i2c_error, pend_dispatcher];

#[used]
static REARM: extern "C" fn(u32) = i2c_rearm;

/// `engine_event`'s type.
type EventStep =
    extern "Rust" fn(&mut Engine, u16, &Script, &mut Readings, &mut Registers) -> Progress;
/// `engine_error`'s type.
type ErrorStep = extern "Rust" fn(&mut Engine, u16, &mut Registers) -> Progress;

#[used]
static STEPS: (EventStep, ErrorStep) = (engine_event, engine_error);

#[cortex_m_rt::entry]
fn main() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// The runtime's fault-policy hook (a board stops its motors there; nothing to stop here).
#[no_mangle]
pub extern "Rust" fn __amiro_board_safe_state() {}
