//! The QEMU build's I2C bus: QEMU emulates no STM32 I2C block, so this bus completes each script
//! against the simulated devices after the script's time on the wire, on the monotonic. A
//! publisher that runs a script thus suspends for it in the emulated runs as it does on the chip
//! (`scripted`), and the bus's time is virtual time the other tasks run in.
//!
//! The bus runs one script at a time: a script starts when the bus is free (at its submission, or
//! when the script before it ends) and ends its wire time at [`SCL_HZ`](crate::scripted::SCL_HZ)
//! later, when the devices answer it (amiro-sensors' `ScriptBus`: its simulated buses run the
//! script's operations on their registers). Unlike the chip's queue (`i2c_bus`: the most urgent
//! waiting script next), scripts go in submission order, and one that fails at a refused address
//! still takes its whole wire time: either changes only when a sample's frames come, never what
//! they read. A client's timeout ([`SimPort`], the same rule as `scripted::I2cPort`'s) ends a
//! script that would end too late; its bus time stays taken, as a stuck script's would on the chip
//! until the reset.
use core::cell::RefCell;
use core::marker::PhantomData;

use amiro_sensors::drivers::scripted::ScriptBus;
use amiro_sensors::script::{Readings, Script, ScriptError};

use crate::scripted::{script_timeout_us, BusFault, Deadline, ScriptPort, SCL_HZ};

struct Inner<D> {
    devices: D,
    /// When the last script taken ends (µs on the monotonic).
    free_at_us: u64,
}

/// A simulated I2C bus and its devices.
pub struct SimBus<D> {
    inner: critical_section::Mutex<RefCell<Inner<D>>>,
}

impl<D: ScriptBus> SimBus<D> {
    /// The bus with `devices` on it, free.
    pub const fn new(devices: D) -> Self {
        Self {
            inner: critical_section::Mutex::new(RefCell::new(Inner {
                devices,
                free_at_us: 0,
            })),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut Inner<D>) -> R) -> R {
        critical_section::with(|cs| f(&mut self.inner.borrow_ref_mut(cs)))
    }

    /// Runs `f` on the devices (the world's readings handed to them, a test's look).
    pub fn with_devices<R>(&self, f: impl FnOnce(&mut D) -> R) -> R {
        self.with(|inner| f(&mut inner.devices))
    }

    /// Takes the bus for `script` submitted at `now_us`: when it ends.
    fn take(&self, script: &Script, now_us: u64) -> u64 {
        let wire_us = script.bus_time_ns(SCL_HZ).div_ceil(1000);
        self.with(|inner| {
            let ends = inner.free_at_us.max(now_us) + wire_us;
            inner.free_at_us = ends;
            ends
        })
    }

    fn answer(&self, script: &Script) -> Result<Readings, ScriptError> {
        self.with(|inner| inner.devices.run(script))
    }
}

/// A publisher task's client of a [`SimBus`], with its timeout on the monotonic `C`.
pub struct SimPort<'a, C, D> {
    bus: &'a SimBus<D>,
    allowance_us: u32,
    clock: PhantomData<C>,
}

impl<'a, C, D> SimPort<'a, C, D> {
    /// A client of `bus`; a script's timeout is its wire time plus `allowance_us`.
    pub const fn new(bus: &'a SimBus<D>, allowance_us: u32) -> Self {
        Self {
            bus,
            allowance_us,
            clock: PhantomData,
        }
    }
}

impl<C: Deadline, D: ScriptBus> ScriptPort for SimPort<'_, C, D> {
    async fn run(&mut self, script: Script, settle_us: u32) -> Result<Readings, BusFault> {
        if script.operations().is_empty() {
            return Ok(Readings::for_script(&script));
        }
        if settle_us > 0 {
            C::delay_until_us(C::now_us() + u64::from(settle_us)).await;
        }
        let now = C::now_us();
        let ends = self.bus.take(&script, now);
        let limit = now + script_timeout_us(&script, self.allowance_us);
        if ends > limit {
            C::delay_until_us(limit).await;
            return Err(BusFault::Timeout);
        }
        C::delay_until_us(ends).await;
        self.bus.answer(&script).map_err(BusFault::Script)
    }
}
