//! PowerManagement revision 1-1/1-2 as the real chip sees it: the one place that names pins and
//! peripherals.
//!
//! Facts from `shared/reference/amiro-boards.md` §0, §1, §2, §5, §7: STM32F405 at 168 MHz from the
//! 8 MHz crystal (APB1 42 MHz, APB1 timers 84 MHz), CAN1 on PA11/PA12 (AF9) at 1 Mbit/s, I2C1 on
//! PB8/PB9 ("rear": mux #1, ring sensors 0/1/2/7, rear bq27500) and I2C2 on PB10/PB11 ("front":
//! mux #2, ring sensors 3/4/5/6, front bq27500) at 400 kHz, POWER_EN PB2 and SYS_REG_EN PA8 kept
//! high, SYS_WARMRST_N PC14 released, SYS_SYNC_N PC12, SYS_PD_N PC13 (EXTI line 13), chargers
//! bq24103A EN1_N PC3 / EN2_N PD2 (active low, open drain) with STAT1A PC0 / STAT2A PB4, power plug
//! PATH_DC PC8 (high = plug in), VSYS on PB1 = ADC1 IN9 (480-cycle sampling). TIM2 is the
//! monotonic; RTC_BKP0R carries the shutdown reason to AMiRo-BLT.
use crate::Board;
use amiro_firmware::bxcan::{self, Fifo0, Mailboxes, Mmio};
use amiro_firmware::signals::Lines;
use stm32f4xx_hal::gpio::{GpioExt, Input, OpenDrain, Output, PinState, PushPull};
use stm32f4xx_hal::gpio::{PA8, PB2, PB4, PC0, PC12, PC13, PC14, PC3, PC8, PD2};
use stm32f4xx_hal::pac::{self, Interrupt};
use stm32f4xx_hal::rcc::RccExt;

use crate::power::{self, ChargeLines};
use amiro_firmware::i2c::{self, Master};

/// System clock of the design clock plan (the runtime's `chip::clock_plan` has the CAN bit timing).
pub const SYSCLK_HZ: u32 = 168_000_000;
/// APB1 timer clock (2 × PCLK1): TIM2's input, as `init`'s clock plan set it up (84 MHz, or 16 MHz
/// on the internal oscillator).
static TIMER_CLOCK_HZ: core::sync::atomic::AtomicU32 =
    core::sync::atomic::AtomicU32::new(84_000_000);
/// EXTI line of SYS_PD_N (PC13).
const SYS_PD_LINE: u32 = 1 << 13;
/// ADC1 channel of VSYS (PB1).
const VSYS_CHANNEL: u32 = 9;
/// Polls of the end-of-conversion flag: a conversion takes 492 ADC clocks at 21 MHz (23 µs).
const ADC_POLLS: u32 = 20_000;

/// TIM2's registers (a 32-bit timer on the F405; the runtime's backend counts 16 bits on it as on
/// the F103's timers).
const TIM2_BASE: usize = 0x4000_0000;

amiro_firmware::timer_monotonic!(Tim2Backend, TIM2_BASE, Interrupt::TIM2, TIM2);

/// The board's clock: TIM2 ticks are microseconds.
pub type Clock = amiro_firmware::mono::TimerClock<Tim2Backend, 1>;
/// The CAN controller's transmit mailboxes (the runtime's register-level driver).
pub type CanTxPort = Mailboxes<Mmio>;
/// The CAN controller's receive FIFO 0 (the runtime's register-level driver).
pub type CanRxPort = Fifo0<Mmio>;
/// The CAN controller's error monitor.
pub type CanErrors = amiro_firmware::bxcan::ErrorMonitor<Mmio>;
/// I2C1, the rear bus.
pub type RearI2c = Master;
/// I2C2, the front bus.
pub type FrontI2c = Master;

/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: Interrupt = Interrupt::CAN1_TX;
/// Interrupt of the SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: Interrupt = Interrupt::EXTI15_10;

/// The fuel gauges' bus-free pause (66 µs after each transfer, `bq27500::BUS_FREE_NS`): a wait on
/// the DWT cycle counter (started in [`init`]), also bounded in polls (each takes several core
/// cycles) so it ends where the counter does not run. Not inlined, so its loop keeps its name for
/// the bounds file's stated wait (the pause itself), rather than a count of delay-loop passes each
/// at the cycle model's worst (a flash line fetch after every taken branch).
#[derive(Debug, Default, Clone, Copy)]
pub struct GaugeDelay;

impl embedded_hal::delay::DelayNs for GaugeDelay {
    #[inline(never)]
    fn delay_ns(&mut self, ns: u32) {
        let cycles = ns.div_ceil(1_000).saturating_mul(SYSCLK_HZ / 1_000_000);
        let start = cortex_m::peripheral::DWT::cycle_count();
        for _ in 0..cycles {
            if cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) >= cycles {
                return;
            }
        }
    }
}

/// POWER_EN, SYS_REG_EN, SYS_WARMRST_N: on / released, as AMiRo-BLT left them.
pub struct PowerLines {
    _power_en: PB2<Output<PushPull>>,
    _sys_reg_en: PA8<Output<OpenDrain>>,
    _sys_warmrst: PC14<Output<OpenDrain>>,
}

/// The module's system-bus signals: SYS_SYNC_N on PC12, SYS_PD_N on PC13 (EXTI line 13), which
/// this board also drives ([`Lines::drive_shutdown_request`]).
pub type SystemSignals = Lines<PC12<Output<OpenDrain>>, PC13<Output<OpenDrain>>, 13>;

/// The two bq24103A chargers, their status pins, the plug and the VSYS sense.
pub struct Charger {
    en1_n: PC3<Output<OpenDrain>>,
    en2_n: PD2<Output<OpenDrain>>,
    stat1a: PC0<Input>,
    stat2a: PB4<Input>,
    path_dc: PC8<Input>,
    enabled: bool,
}

/// Brings the board up: clocks, power lines, system signals, chargers off, I2C, ADC, CAN.
pub fn init(dp: pac::Peripherals, mut cp: cortex_m::Peripherals) -> Board {
    // The clock tree, every wait bounded: the PLL from the crystal, else from the internal
    // oscillator (168 MHz either way), else the internal oscillator alone at 16 MHz (logged, and
    // flagged on the diagnostics). The HAL is only constrained, never frozen: its `freeze` waits
    // for the PLL without a bound, and nothing here takes its frequencies from it.
    let clocks = amiro_firmware::chip::clock_plan();
    TIMER_CLOCK_HZ.store(clocks.timer_hz, core::sync::atomic::Ordering::Relaxed);
    // AMiRo-BLT used bxCAN: reset it (and the I2C blocks) so nothing of its set-up survives.
    dp.RCC.apb1rstr().modify(|_, w| {
        w.can1rst()
            .set_bit()
            .i2c1rst()
            .set_bit()
            .i2c2rst()
            .set_bit()
    });
    dp.RCC.apb1rstr().modify(|_, w| {
        w.can1rst()
            .clear_bit()
            .i2c1rst()
            .clear_bit()
            .i2c2rst()
            .clear_bit()
    });
    let mut rcc = dp.RCC.constrain();
    #[cfg(feature = "scripted-i2c")]
    scripted::set_clocks(clocks.pclk1_hz, clocks.sysclk_hz);
    #[cfg(feature = "scripted-i2c")]
    scripted::bind_engines(&mut cp.NVIC);
    // The I2C timeouts count core cycles (and the engine's condition wait, with `scripted-i2c`).
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let gpiod = dp.GPIOD.split(&mut rcc);

    // Power master lines first, in the state AMiRo-BLT left them (the output latch is written
    // before the pin becomes an output, so there is no glitch).
    let power_lines = PowerLines {
        _power_en: gpiob.pb2.into_push_pull_output_in_state(PinState::High),
        _sys_reg_en: gpioa.pa8.into_open_drain_output_in_state(PinState::High),
        _sys_warmrst: gpioc.pc14.into_open_drain_output_in_state(PinState::High),
    };
    // Chargers off until VSYS says otherwise.
    let charger = Charger {
        en1_n: gpioc.pc3.into_open_drain_output_in_state(PinState::High),
        en2_n: gpiod.pd2.into_open_drain_output_in_state(PinState::High),
        stat1a: gpioc.pc0.into_floating_input(),
        stat2a: gpiob.pb4.into_floating_input(),
        path_dc: gpioc.pc8.into_floating_input(),
        enabled: false,
    };
    let _vsys = gpiob.pb1.into_analog();
    adc_init();

    // SYS_SYNC_N stays low (as AMiRo-BLT left it) until the app is initialised; SYS_PD_N is a
    // wired-OR open-drain line released high, watched for a falling edge on EXTI line 13.
    let signals = SystemSignals::new(
        gpioc.pc12.into_open_drain_output_in_state(PinState::Low),
        gpioc.pc13.into_open_drain_output_in_state(PinState::High),
    );
    // As AMiRo-BLT left them.
    amiro_firmware::log!("power lines: POWER_EN, SYS_REG_EN on; SYS_WARMRST_N released; SYS_SYNC_N low; chargers off");
    // SAFETY: single bits in registers only init touches (the HAL has consumed its RCC handle);
    // EXTICR4 bits 4..8 select the port of line 13 (C = 2), nothing else uses lines 12..15.
    unsafe {
        let rcc = &*pac::RCC::ptr();
        rcc.apb2enr().modify(|_, w| w.syscfgen().set_bit());
        rcc.apb1enr()
            .modify(|_, w| w.can1en().set_bit().i2c1en().set_bit().i2c2en().set_bit());
        (*pac::SYSCFG::ptr())
            .exticr4()
            .modify(|r, w| w.bits((r.bits() & !(0xF << 4)) | (0x2 << 4)));
        let exti = &*pac::EXTI::ptr();
        exti.ftsr().modify(|r, w| w.bits(r.bits() | SYS_PD_LINE));
        exti.imr().modify(|r, w| w.bits(r.bits() | SYS_PD_LINE));
    }

    // I2C pins: alternate function 4, open drain (the boards have external pull-ups).
    let _i2c_pins = (
        gpiob.pb8.into_alternate_open_drain::<4>(),
        gpiob.pb9.into_alternate_open_drain::<4>(),
        gpiob.pb10.into_alternate_open_drain::<4>(),
        gpiob.pb11.into_alternate_open_drain::<4>(),
    );
    // SAFETY: I2C1 and I2C2 are used by these two values only, their pins (PB8/PB9, PB10/PB11,
    // alternate open drain above) by their bus clears only.
    let (rear_i2c, front_i2c) = unsafe {
        (
            Master::new(
                i2c::I2C1,
                i2c::Pins::new(i2c::GPIOB, 8, 9),
                clocks.pclk1_hz,
                clocks.sysclk_hz,
            ),
            Master::new(
                i2c::I2C2,
                i2c::Pins::new(i2c::GPIOB, 10, 11),
                clocks.pclk1_hz,
                clocks.sysclk_hz,
            ),
        )
    };

    // CAN1 on PA11/PA12, AF9. The runtime's driver configures the controller: only command frames
    // pass the hardware filter; TX mailboxes are served by identifier; automatic bus-off recovery.
    let _can_pins = (
        gpioa.pa11.into_alternate::<9>(),
        gpioa.pa12.into_alternate::<9>(),
    );
    let can = bxcan::bring_up(clocks.can_btr);
    Board {
        can_tx: can.tx,
        can_rx: can.rx,
        can_errors: can.errors,
        rear_i2c,
        front_i2c,
        charger,
        signals,
        power_lines,
    }
}

/// ADC1: clock on, ADCCLK = PCLK2 / 4 = 21 MHz, channel 9 alone with 480-cycle sampling.
fn adc_init() {
    // SAFETY: init owns the ADC; documented bit patterns (RM0090 §13.13).
    unsafe {
        (*pac::RCC::ptr())
            .apb2enr()
            .modify(|_, w| w.adc1en().set_bit());
        (*pac::ADC_COMMON::ptr())
            .ccr()
            .modify(|r, w| w.bits((r.bits() & !(0b11 << 16)) | (0b01 << 16)));
        let adc = &*pac::ADC1::ptr();
        adc.smpr2()
            .modify(|r, w| w.bits(r.bits() | (0b111 << (3 * VSYS_CHANNEL))));
        adc.sqr1().write(|w| w.bits(0));
        adc.sqr3().write(|w| w.bits(VSYS_CHANNEL));
        adc.cr2().write(|w| w.bits(1));
    }
}

impl Charger {
    /// VSYS in mV, or `None` if the conversion did not finish in its bound.
    pub fn vsys_mv(&mut self) -> Option<u32> {
        // SAFETY: the ADC belongs to this value (set up once in init); SWSTART, then poll EOC.
        let adc = unsafe { &*pac::ADC1::ptr() };
        adc.sr().write(|w| unsafe { w.bits(0) });
        adc.cr2()
            .modify(|r, w| unsafe { w.bits(r.bits() | (1 << 30)) });
        (0..ADC_POLLS)
            .any(|_| adc.sr().read().bits() & (1 << 1) != 0)
            .then(|| power::vsys_mv(adc.dr().read().bits() as u16))
    }

    /// Enables or disables both chargers.
    pub fn set_enabled(&mut self, on: bool) {
        if on {
            self.en1_n.set_low();
            self.en2_n.set_low();
        } else {
            self.en1_n.set_high();
            self.en2_n.set_high();
        }
        self.enabled = on;
    }

    /// The plug, the enables and the chargers' status pins.
    pub fn lines(&mut self) -> ChargeLines {
        ChargeLines {
            plug: self.path_dc.is_high(),
            enabled: self.enabled,
            stat: [self.stat1a.is_high(), self.stat2a.is_high()],
        }
    }

    /// Whether the chargers are enabled.
    pub fn enabled(&self) -> bool {
        self.enabled
    }
}

/// PowerManagement's safe state, from any context: both chargers off (EN1_N, EN2_N released high).
/// A board that faulted cannot supervise VSYS, so it must not charge; the power lines stay as they
/// are (the watchdog reset goes through AMiRo-BLT, which owns the power sequence, and cutting the
/// other modules' supply would skip their own shutdown).
pub fn chargers_off() {
    // SAFETY: single BSRR writes (set PC3, set PD2), atomic with respect to any other pin writes.
    unsafe {
        (*pac::GPIOC::ptr()).bsrr().write(|w| w.bits(1 << 3));
        (*pac::GPIOD::ptr()).bsrr().write(|w| w.bits(1 << 2));
    }
}

/// Writes the shutdown reason to byte 0 of RTC_BKP0R, where AMiRo-BLT reads it (reference §2).
pub fn write_shutdown_reason(reason: u8) {
    // SAFETY: PWR clock on and DBP set unlock the backup domain; BKP0R is written read-modify-write
    // so bytes 1..3 (secondary reason, wake-up flags) keep what AMiRo-BLT put there.
    unsafe {
        (*pac::RCC::ptr())
            .apb1enr()
            .modify(|_, w| w.pwren().set_bit());
        (*pac::PWR::ptr())
            .cr()
            .modify(|r, w| w.bits(r.bits() | (1 << 8)));
        let rtc = &*pac::RTC::ptr();
        rtc.bkpr(0)
            .modify(|r, w| w.bits((r.bits() & !0xFF) | u32::from(reason)));
    }
}

/// Whether SYS_SYNC_N (PC12) reads low: another module has taken the shutdown request.
pub fn sync_reads_low() -> bool {
    amiro_firmware::chip::port_c_reads_low::<12>()
}

/// Starts the TIM2 monotonic (the runtime's half-period timer backend).
pub fn start_monotonic(priority: u8) {
    // SAFETY: init owns RCC at this point; only TIM2's enable and reset bits change.
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.apb1enr().modify(|_, w| w.tim2en().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim2rst().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim2rst().clear_bit());
    Tim2Backend::start(
        TIMER_CLOCK_HZ.load(core::sync::atomic::Ordering::Relaxed),
        priority,
    );
}

/// With `scripted-i2c`: the I2C blocks driven by their interrupts once the app runs
/// (`amiro_firmware::i2c_bus`: the engine, a slot per client task), after the boot set the
/// devices up on the polled master (docs/i2c.md).
#[cfg(feature = "scripted-i2c")]
pub mod scripted {
    use amiro_firmware::i2c::{self, Master};
    use amiro_firmware::i2c_block::{hand_over, EngineBuses, Registers};
    use amiro_firmware::i2c_bus::I2cBus;
    use amiro_firmware::scripted::I2cPort;
    use amiro_sensors::drivers::bq27500::BatteryStatus;
    use amiro_sensors::drivers::ring::RingBus;
    use amiro_sensors::drivers::scripted::OnI2c;
    use stm32f4xx_hal::pac::{interrupt, Interrupt, NVIC};

    use super::{Clock, SYSCLK_HZ};
    use crate::levels;
    use crate::sensors::scripted::{ScriptedBus, CLIENTS, TIMEOUT_ALLOWANCE_US};

    /// One I2C block's bus once the app runs.
    pub type ScriptBus = I2cBus<Registers, CLIENTS>;
    /// A client task's slot on a [`ScriptBus`], its timeout on the board's clock.
    pub type Port = I2cPort<'static, Clock, Registers, CLIENTS>;

    /// The clients' RTIC priorities, by slot (`sensors::scripted::CLIENTS`): the bus's owner
    /// task (`ring_rear`, `ring_front`), at the power monitor's level.
    const CLIENT_PRIORITIES: [u8; CLIENTS] = [levels::POWER_MONITOR];

    /// I2C1, the rear bus.
    // SAFETY: the block is touched only after `boot_rear` took it from the polled master.
    pub static I2C1_BUS: ScriptBus = I2cBus::new(
        unsafe { Registers::new(i2c::I2C1, SYSCLK_HZ / 4, SYSCLK_HZ) },
        CLIENT_PRIORITIES,
    );
    /// I2C2, the front bus.
    // SAFETY: as I2C1's, after `boot_front`.
    pub static I2C2_BUS: ScriptBus = I2cBus::new(
        unsafe { Registers::new(i2c::I2C2, SYSCLK_HZ / 4, SYSCLK_HZ) },
        CLIENT_PRIORITIES,
    );
    /// Both, for the wiring amiro-firmware shares with DiWheelDrive 1-1's trial.
    static BUSES: EngineBuses<CLIENTS> = EngineBuses {
        i2c1: &I2C1_BUS,
        i2c2: &I2C2_BUS,
    };

    /// I2C1's events: the rear bus's engine advances its script (docs/i2c.md).
    #[interrupt]
    fn I2C1_EV() {
        I2C1_BUS.on_event();
    }

    /// I2C1's errors (a missing acknowledge, a bus error, arbitration lost, an overrun).
    #[interrupt]
    fn I2C1_ER() {
        I2C1_BUS.on_error();
    }

    /// I2C2's events: the front bus's engine.
    #[interrupt]
    fn I2C2_EV() {
        I2C2_BUS.on_event();
    }

    /// I2C2's errors.
    #[interrupt]
    fn I2C2_ER() {
        I2C2_BUS.on_error();
    }

    /// The four handlers at one priority, RTIC's `levels::I2C_ENGINE` (so that neither pre-empts
    /// another's critical step; above every client, below the CAN interrupts; RTIC's locks mask
    /// them as they mask a task of that priority), and unmasked (`EngineBuses::bind_engines`, as
    /// DiWheelDrive 1-1's trial binds them).
    pub(crate) fn bind_engines(nvic: &mut NVIC) {
        BUSES.bind_engines(
            nvic,
            [
                Interrupt::I2C1_EV,
                Interrupt::I2C1_ER,
                Interrupt::I2C2_EV,
                Interrupt::I2C2_ER,
            ],
            levels::I2C_ENGINE,
        );
    }

    /// Keeps the clock plan's APB1 and core clocks for the blocks' hand-over.
    pub(crate) fn set_clocks(pclk1_hz: u32, sysclk_hz: u32) {
        BUSES.set_clocks(pclk1_hz, sysclk_hz);
    }

    /// `which`'s sensors and gauge set up (and the gauge's status read) by their scripts on the
    /// polled master `boot` (the gauge's bus-free pauses on the core clock, `GaugeDelay`), then
    /// `boot`'s block handed to `bus` (`i2c_block::hand_over`).
    fn boot_on(
        which: RingBus,
        boot: Master,
        bus: &ScriptBus,
    ) -> (ScriptedBus, Option<BatteryStatus>) {
        // The polled master is consumed here: the block is the engine's from now on.
        let booted = ScriptedBus::boot(which, &mut OnI2c(boot), &mut super::GaugeDelay);
        hand_over(bus);
        booted
    }

    /// I2C1's devices set up on its polled master, then I2C1 handed to its engine.
    pub fn boot_rear(boot: Master) -> (ScriptedBus, Option<BatteryStatus>) {
        boot_on(RingBus::I2c1, boot, &I2C1_BUS)
    }

    /// I2C2's devices set up on its polled master, then I2C2 handed to its engine.
    pub fn boot_front(boot: Master) -> (ScriptedBus, Option<BatteryStatus>) {
        boot_on(RingBus::I2c2, boot, &I2C2_BUS)
    }

    /// Client `CLIENT`'s slots on I2C1 and I2C2.
    pub fn ports<const CLIENT: usize>() -> (Port, Port) {
        BUSES.ports::<CLIENT, Clock>(TIMEOUT_ALLOWANCE_US)
    }

    /// The re-arm task's loop for `bus`, its watch (`I2cBus::serve_watch`): each script timed to
    /// its deadline (its wire time and 200 µs an event; past it the script ends with
    /// `Failure::Stretched`, the lines are cleared on `clear` and the next script runs), and a
    /// repeated START the gauge stretches past the engine's condition wait looked at every
    /// `STRETCH_REARM_US` (docs/i2c.md, "A script's deadline", "A stretched repeated START").
    async fn rearm(bus: &'static ScriptBus, clear: &'static i2c::BusClear) -> ! {
        bus.serve_watch::<Clock>(|| {
            // A bus still held is the next script's fault (its own deadline), reported there.
            let _ = clear.clear();
        })
        .await
    }

    /// I2C1's clear on PB8/PB9 (as `board::boot`'s master).
    // SAFETY: I2C1's own pins; used only while its bus recovers (`BusClear::new`).
    static I2C1_CLEAR: i2c::BusClear =
        unsafe { i2c::BusClear::new(i2c::I2C1, i2c::Pins::new(i2c::GPIOB, 8, 9), SYSCLK_HZ) };
    /// I2C2's clear on PB10/PB11.
    // SAFETY: as I2C1's.
    static I2C2_CLEAR: i2c::BusClear =
        unsafe { i2c::BusClear::new(i2c::I2C2, i2c::Pins::new(i2c::GPIOB, 10, 11), SYSCLK_HZ) };

    /// I2C1's re-arm loop.
    pub async fn rearm_rear() -> ! {
        rearm(&I2C1_BUS, &I2C1_CLEAR).await
    }

    /// I2C2's re-arm loop.
    pub async fn rearm_front() -> ! {
        rearm(&I2C2_BUS, &I2C2_CLEAR).await
    }
}
#[cfg(feature = "scripted-i2c")]
pub use scripted::{boot_front, boot_rear, ports, rearm_front, rearm_rear};
