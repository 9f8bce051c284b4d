//! PowerManagement's QEMU board: the same app, with this board's devices and lines simulated.
//!
//! The platform (SysTick clock, virtual CAN, stimulus replay, stack painting, the end line, the
//! stimulus's SYS_PD_N) is the runtime's `amiro_firmware::qemu`; this file adds what is
//! PowerManagement's own: amiro-sensors' register-level simulators behind the real drivers (per
//! bus: a PCA9544A with four VCNL4020 and a bq27500, `SimPowerBus`), simulated chargers, plug and
//! VSYS, SYS_PD_N driven by this board, and the other modules' answer on SYS_SYNC_N.
//!
//! **QEMU-only control frames.** A stimulus changes the simulated world with command frames on
//! [`amiro_firmware::qemu::SIM_CONTROL_ID`] (`0x3F0`: a low-priority command to topic 0xF0,
//! which the protocol leaves free; on a robot it would be rejected as `unknown-topic`). The
//! receive port takes them out before the command queue, so the app never sees them:
//!
//! | data | effect |
//! |---|---|
//! | `01 ii` | ring sensor `ii` (0..7) stops answering (its address is not acknowledged) |
//! | `02 mm` | the gauges in mask `mm` (1 front, 2 rear) report a critically low battery |
//! | `03 vv vv pp` | VSYS = `vvvv` mV (u16 little-endian), power plug in if `pp` ≠ 0 |
use crate::Board;
use core::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};

use amiro_firmware::digits;
use amiro_firmware::mono::Clock as _;
use amiro_firmware::qemu::{print_line, print_line_around, robot};
use amiro_firmware::signals::SystemSignals as SystemSignalLines;
use amiro_sensors::drivers::bq27500::{self, cmd, Flags};
use amiro_sensors::drivers::pca9544a;
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::vcnl4020;
use amiro_sensors::sim::{NoAcknowledge, SimPowerBus};
use embedded_hal::i2c::{ErrorType, I2c, Operation};
use stm32f4xx_hal::pac::{self, Interrupt};

use crate::power::{self, ChargeLines};

pub use amiro_firmware::mono::QemuClock as Clock;
pub use amiro_firmware::qemu::{CanErrors, CanTxPort};
pub use amiro_sensors::sim::NoDelay as GaugeDelay;

/// Interrupt of the (simulated) SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: Interrupt = Interrupt::EXTI15_10;
/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: Interrupt = Interrupt::CAN1_TX;
/// Interrupt of the CAN receive FIFO 0 (pended by the stimulus replay).
pub const CAN_RX_INTERRUPT: Interrupt = Interrupt::CAN1_RX0;
/// The other modules pull SYS_SYNC_N low this long after SYS_PD_N falls (their edge interrupt).
pub const OTHERS_REACT_US: u64 = 50;

/// Ring sensors that do not answer (bit = index).
static DEAD_SENSORS: AtomicU8 = AtomicU8::new(0);
/// Gauges reporting a critically low battery (bit 0 front, bit 1 rear).
static CRITICAL_GAUGES: AtomicU8 = AtomicU8::new(0);
/// Simulated VSYS in mV: the battery alone (no plug) to start with.
static VSYS_MV: AtomicU32 = AtomicU32::new(7_400);
static PLUG: AtomicBool = AtomicBool::new(false);
static CHARGING: AtomicBool = AtomicBool::new(false);
/// When this board drove SYS_PD_N low (µs + 1; 0 = not yet).
static PD_DRIVEN_AT: AtomicU32 = AtomicU32::new(0);

/// The virtual receive FIFO, with the QEMU-only control frames taken out for `apply_control`.
pub type CanRxPort = amiro_firmware::qemu::ControlledRxPort;

///
/// Runs in the receive interrupt, whose bound the traced QEMU image's own analysis states
/// (docs/bench.md): its lines are printed in parts without `core::fmt` (whose loops over a
/// format's pieces have no bound the analysis can state), the numbers by `amiro_firmware::digits`'
/// loop-free helpers; the text is what `format!` would print (`{sensor}`, `{mask:#x}`, `{mv}`,
/// `{data:02X?}`), which the scenarios read.
fn apply_control(data: &[u8]) {
    match *data {
        [1, sensor, ..] if usize::from(sensor) < WIRING.len() => {
            DEAD_SENSORS.fetch_or(1 << sensor, Ordering::SeqCst);
            let mut buffer = [0; 5];
            let sensor = digits::decimal_u16(u16::from(sensor), &mut buffer);
            print_line_around(b"# qemu: ring sensor ", sensor, b" stops answering");
        }
        [2, mask, ..] => {
            CRITICAL_GAUGES.store(mask & 3, Ordering::SeqCst);
            let mut buffer = [0; 2];
            let mask = digits::hex_u8(mask, false, &mut buffer);
            print_line_around(
                b"# qemu: gauges 0x",
                mask,
                b" report a critically low battery",
            );
        }
        [3, low, high, plug, ..] => {
            let mv = u16::from_le_bytes([low, high]);
            VSYS_MV.store(u32::from(mv), Ordering::SeqCst);
            PLUG.store(plug != 0, Ordering::SeqCst);
            let mut buffer = [0; 5];
            let mv = digits::decimal_u16(mv, &mut buffer);
            let plug: &[u8] = if plug != 0 {
                b" mV, plug in"
            } else {
                b" mV, plug out"
            };
            print_line_around(b"# qemu: VSYS ", mv, plug);
        }
        _ => {
            // ", XX" per data byte (a frame has at most 8), the first one's ", " left out.
            let mut bytes = [0u8; 32];
            for (text, &byte) in bytes.chunks_exact_mut(4).zip(data) {
                let [high, low] = digits::hex_byte(byte, true);
                text.copy_from_slice(&[b',', b' ', high, low]);
            }
            let bytes = bytes.get(2..4 * data.len()).unwrap_or(&[]);
            print_line_around(b"# qemu: unknown control frame [", bytes, b"]");
        }
    }
}

/// One simulated PowerManagement bus (mux, four ring sensors, gauge) with the stimulus's faults.
pub struct SimBus {
    bus: SimPowerBus,
    which: RingBus,
    gauge_bit: u8,
    channel: Option<u8>,
}

impl SimBus {
    const fn new(which: RingBus) -> Self {
        let (first, gauge_bit) = match which {
            RingBus::I2c1 => (0, 2),
            RingBus::I2c2 => (4, 1),
        };
        Self {
            bus: SimPowerBus::new(first, false),
            which,
            gauge_bit,
            channel: None,
        }
    }

    fn sensor_dead(&self) -> bool {
        let dead = DEAD_SENSORS.load(Ordering::SeqCst);
        WIRING.iter().enumerate().any(|(index, &(bus, channel))| {
            bus == self.which && Some(channel.number()) == self.channel && dead & (1 << index) != 0
        })
    }
}

/// I2C1 in QEMU.
pub type RearI2c = SimBus;
/// I2C2 in QEMU.
pub type FrontI2c = SimBus;

impl ErrorType for SimBus {
    type Error = NoAcknowledge;
}

impl I2c for SimBus {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), NoAcknowledge> {
        self.bus
            .fuel_gauge_mut()
            .set_charging(CHARGING.load(Ordering::SeqCst));
        if let Some(r) = robot::readings().filter(|r| r.has(robot::world_link::RING)) {
            // The world's counts for this bus's four sensors (docs/world.md), by the wiring.
            for (index, &(bus, channel)) in WIRING.iter().enumerate() {
                if bus == self.which {
                    let counts = r.ring.get(index).copied();
                    let _ =
                        (self.bus.target.0).set_proximity(usize::from(channel.number()), counts);
                }
            }
        }
        if address == pca9544a::AMIRO_ADDRESS {
            if let Some(Operation::Write([control, ..])) = operations.first() {
                self.channel = (control & pca9544a::ENABLE != 0).then_some(control & 3);
            }
        }
        if address == vcnl4020::ADDRESS && self.sensor_dead() {
            return Err(NoAcknowledge { address });
        }
        let command = match operations.first() {
            Some(Operation::Write([command])) => Some(*command),
            _ => None,
        };
        self.bus.transaction(address, operations)?;
        if address == bq27500::ADDRESS
            && CRITICAL_GAUGES.load(Ordering::SeqCst) & self.gauge_bit != 0
        {
            let value = match command {
                Some(cmd::STATE_OF_CHARGE) => Some(1),
                Some(cmd::REMAINING_CAPACITY) => Some(20),
                Some(cmd::TIME_TO_EMPTY) => Some(2),
                Some(cmd::FLAGS) => Some(Flags::SOC_FINAL | Flags::SOC_LOW | Flags::DISCHARGING),
                _ => None,
            };
            if let (Some(value), Some(Operation::Read(buffer))) = (value, operations.get_mut(1)) {
                for (slot, byte) in buffer.iter_mut().zip(u16::to_le_bytes(value)) {
                    *slot = byte;
                }
            }
        }
        Ok(())
    }
}

/// The simulated chargers, plug and VSYS.
pub struct Charger {
    enabled: bool,
}

impl Charger {
    /// VSYS as the stimulus set it, through the divider and a 12-bit conversion as on the board.
    pub fn vsys_mv(&mut self) -> Option<u32> {
        let pin_mv = VSYS_MV.load(Ordering::SeqCst) * power::VSYS_DIVIDER.1 / power::VSYS_DIVIDER.0;
        let raw = (pin_mv * power::ADC_FULL_SCALE / power::ADC_VREF_MV).min(power::ADC_FULL_SCALE);
        Some(power::vsys_mv(raw as u16))
    }

    /// Enables or disables both chargers (printed).
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        CHARGING.store(on && PLUG.load(Ordering::SeqCst), Ordering::SeqCst);
        print_line(if on {
            "# qemu: chargers enabled (EN1_N, EN2_N low)"
        } else {
            "# qemu: chargers disabled"
        });
    }

    /// The plug, the enables and the chargers' status pins (charging while enabled and plugged).
    pub fn lines(&mut self) -> ChargeLines {
        let plug = PLUG.load(Ordering::SeqCst);
        let charging = self.enabled && plug;
        CHARGING.store(charging, Ordering::SeqCst);
        ChargeLines {
            plug,
            enabled: self.enabled,
            stat: [charging; 2],
        }
    }

    /// Whether the chargers are enabled.
    pub fn enabled(&self) -> bool {
        self.enabled
    }
}

/// The power lines need no simulation: they stay on.
pub struct PowerLines;

/// Simulated system signals: SYS_PD_N from the stimulus (the runtime's) or driven by this board.
pub struct SystemSignals(amiro_firmware::qemu::Signals);

impl SystemSignalLines for SystemSignals {
    fn release_sync(&mut self) {
        self.0.release_sync();
    }

    fn pull_sync_low(&mut self) {
        self.0.pull_sync_low();
    }

    fn shutdown_requested(&self) -> bool {
        self.0.shutdown_requested()
    }

    fn clear_shutdown_interrupt(&mut self) {
        self.0.clear_shutdown_interrupt();
    }
}

impl SystemSignals {
    /// Drives SYS_PD_N low (printed); the simulated other modules answer on SYS_SYNC_N.
    pub fn drive_shutdown_request(&mut self) {
        let now = Clock::now_us();
        PD_DRIVEN_AT.store(now as u32 + 1, Ordering::SeqCst);
        amiro_firmware::qemu::robot::drive_power_down();
        print_line("# qemu: SYS_PD_N driven low");
    }
}

/// Whether SYS_SYNC_N reads low: the other modules react [`OTHERS_REACT_US`] after SYS_PD_N.
/// In a robot run (`cargo xtask robot`) the line is the robot's: the other boards' answer.
pub fn sync_reads_low() -> bool {
    if amiro_firmware::qemu::robot::active() {
        return amiro_firmware::qemu::robot::sync_reads_low();
    }
    match PD_DRIVEN_AT.load(Ordering::SeqCst) {
        0 => false,
        at => Clock::now_us() >= u64::from(at - 1) + OTHERS_REACT_US,
    }
}

/// Brings the simulated board up (touches no STM32 peripheral but SysTick).
pub fn init(_dp: pac::Peripherals, cp: cortex_m::Peripherals) -> Board {
    amiro_firmware::mono::start_qemu(cp.SYST);
    Board {
        can_tx: CanTxPort,
        can_rx: CanRxPort::new(apply_control),
        can_errors: amiro_firmware::qemu::can_errors(),
        rear_i2c: SimBus::new(RingBus::I2c1),
        front_i2c: SimBus::new(RingBus::I2c2),
        charger: Charger { enabled: false },
        signals: SystemSignals(amiro_firmware::qemu::Signals),
        power_lines: PowerLines,
    }
}

/// The SysTick monotonic already runs (started in `init`).
pub fn start_monotonic(_priority: u8) {}

/// The safe state: chargers off (printed).
pub fn chargers_off() {
    CHARGING.store(false, Ordering::SeqCst);
    print_line("# qemu: safe state: chargers off");
}

/// RTC_BKP0R byte 0 (printed: QEMU's STM32F405 has no RTC backup domain).
pub fn write_shutdown_reason(reason: u8) {
    let mut buffer = [0; 5];
    let reason = digits::decimal_u16(u16::from(reason), &mut buffer);
    print_line_around(b"# qemu: RTC_BKP0R byte 0 = ", reason, b"");
}

/// With `scripted-i2c`: the buses as the QEMU build runs their scripts (`amiro_firmware::i2c_sim`:
/// each script answered by the simulated devices, with the stimulus's faults, after its time on
/// the wire). The devices live in the bus from the start; the boot's set-up runs on them too (the
/// boot bus values `init` hands over are not used).
#[cfg(feature = "scripted-i2c")]
pub mod scripted {
    use amiro_firmware::i2c_sim::{SimBus as ScriptSimBus, SimPort};
    use amiro_sensors::drivers::bq27500::BatteryStatus;
    use amiro_sensors::drivers::ring::RingBus;
    use amiro_sensors::drivers::scripted::OnI2c;
    use amiro_sensors::sim::NoDelay;

    use super::{Clock, SimBus};
    use crate::sensors::scripted::{ScriptedBus, CLIENTS, TIMEOUT_ALLOWANCE_US};

    /// A bus's simulated devices, each script's operations run on them as blocking transfers.
    type Devices = OnI2c<SimBus>;
    /// A client task's slot on a bus.
    pub type Port = SimPort<'static, Clock, Devices>;

    /// I2C1, the rear bus.
    pub static I2C1_BUS: ScriptSimBus<Devices> =
        ScriptSimBus::new(OnI2c(SimBus::new(RingBus::I2c1)));
    /// I2C2, the front bus.
    pub static I2C2_BUS: ScriptSimBus<Devices> =
        ScriptSimBus::new(OnI2c(SimBus::new(RingBus::I2c2)));

    /// I2C1's devices set up on its simulated parts.
    pub fn boot_rear(_boot: SimBus) -> (ScriptedBus, Option<BatteryStatus>) {
        I2C1_BUS.with_devices(|devices| ScriptedBus::boot(RingBus::I2c1, devices, &mut NoDelay))
    }

    /// I2C2's devices set up on its simulated parts.
    pub fn boot_front(_boot: SimBus) -> (ScriptedBus, Option<BatteryStatus>) {
        I2C2_BUS.with_devices(|devices| ScriptedBus::boot(RingBus::I2c2, devices, &mut NoDelay))
    }

    /// Client `CLIENT`'s slots on I2C1 and I2C2.
    pub fn ports<const CLIENT: usize>() -> (Port, Port) {
        const { assert!(CLIENT < CLIENTS) };
        (
            SimPort::new(&I2C1_BUS, TIMEOUT_ALLOWANCE_US),
            SimPort::new(&I2C2_BUS, TIMEOUT_ALLOWANCE_US),
        )
    }

    /// The simulated bus stretches no clock: the re-arm task has nothing to look at.
    pub async fn rearm_rear() -> ! {
        core::future::pending().await
    }

    /// As [`rearm_rear`].
    pub async fn rearm_front() -> ! {
        core::future::pending().await
    }
}
#[cfg(feature = "scripted-i2c")]
pub use scripted::{boot_front, boot_rear, ports, rearm_front, rearm_rear};
