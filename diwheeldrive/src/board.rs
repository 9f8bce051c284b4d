//! DiWheelDrive revisions 1-1 and 1-2 as the real chip sees them: the one place that names pins and
//! peripherals.
//!
//! Facts from `shared/reference/amiro-boards.md` §0, §4: 8 MHz crystal → 72 MHz, CAN1 on PA11/PA12
//! at 1 Mbit/s; revision 1-1: SPI1 (PA5/6/7) with the L3G4200D (CS PC14) and LIS331DLH (CS PC13),
//! I2C1 remapped to PB8/PB9 with the HMC5883L; revision 1-2: I2C1 remapped to PB8/PB9 with the
//! BNO055 (0x28), IMU_RESET_N PC2 (pulsed at boot), IMU_BOOT_LOAD_N PC12 (held high); both: I2C2 (PB10/PB11) with the PCA9544A mux and the four VCNL4020 floor
//! sensors, motor PWM on TIM2 partial remap 1 (PA15 left fwd, PB3 left back, PA2 right fwd,
//! PA3 right back) into an A3906, POWER_EN PB2, encoders on TIM3 full remap (PC6/PC7, left) and
//! TIM4 (PB6/PB7, right), SYS_SYNC_N PC1, SYS_PD_N PC8, status LED PA1 (active low).
use crate::sensors::SensorBuses;
use crate::Board;
use amiro_firmware::bxcan::{self, Fifo0, Mailboxes, Mmio};
use amiro_firmware::i2c::{self, Master};
use amiro_firmware::signals::Lines;
#[cfg(feature = "rev-1-1")]
use amiro_firmware::spi;
#[cfg(feature = "rev-1-1")]
use embedded_hal::spi::{Mode as SpiMode, Phase, Polarity};
#[cfg(feature = "rev-1-1")]
use embedded_hal_bus::spi::{AtomicDevice, NoDelay};
use embedded_hal_bus::util::AtomicCell;
use stm32f1xx_hal::afio::AfioExt;
use stm32f1xx_hal::gpio::{GpioExt, OpenDrain, Output, PinState, PushPull, PB2, PC1, PC8};
#[cfg(feature = "rev-1-1")]
use stm32f1xx_hal::gpio::{PC13, PC14};
use stm32f1xx_hal::pac;
use stm32f1xx_hal::prelude::*;

/// The IMU bus's fastest rate (the L3G4200D's limit is 10 MHz): PCLK2 / 4 on the crystal.
#[cfg(feature = "rev-1-1")]
pub const IMU_SPI_HZ: u32 = 9_000_000;
/// Motor PWM: 72 MHz timer clock, period 3600 → 20 kHz, as the original 1.x firmware.
pub const PWM_PERIOD: u16 = 3600;
/// System clock.
pub const SYSCLK_HZ: u32 = 72_000_000;
/// The APB1 timer clock (TIM5's input), as `init` set it up.
static TIMER_CLOCK_HZ: core::sync::atomic::AtomicU32 =
    core::sync::atomic::AtomicU32::new(SYSCLK_HZ);
/// EXTI line of SYS_PD_N (PC8).
const SYS_PD_LINE: u32 = 1 << 8;

/// SPI1 shared by the gyroscope and the accelerometer (1-1).
#[cfg(feature = "rev-1-1")]
pub type ImuBus = spi::Master<Mmio>;
/// No shared IMU bus object on 1-2 (the BNO055 owns I2C1 alone).
#[cfg(feature = "rev-1-2")]
pub type ImuBus = ();
/// The gyroscope's SPI device (chip select PC14).
#[cfg(feature = "rev-1-1")]
pub type GyroSpi = AtomicDevice<'static, ImuBus, PC14<Output<PushPull>>, NoDelay>;
/// The accelerometer's SPI device (chip select PC13).
#[cfg(feature = "rev-1-1")]
pub type AccelSpi = AtomicDevice<'static, ImuBus, PC13<Output<PushPull>>, NoDelay>;
/// I2C1 (remapped to PB8/PB9): the HMC5883L (the runtime's bounded master: a dead sensor holds
/// its bus lock, and so the publishers sharing it, for at most one 200 µs timeout per flag).
#[cfg(feature = "rev-1-1")]
pub type CompassI2c = Master;
/// I2C1 (remapped to PB8/PB9): the BNO055 (the runtime's bounded master, as the 1-1 compass).
#[cfg(feature = "rev-1-2")]
pub type ImuI2c = Master;
/// I2C2: the PCA9544A multiplexer and the floor sensors.
pub type FloorI2c = Master;
/// The CAN controller's transmit mailboxes (the runtime's register-level driver).
pub type CanTxPort = Mailboxes<Mmio>;
/// The CAN controller's receive FIFO 0 (the runtime's register-level driver).
pub type CanRxPort = Fifo0<Mmio>;
/// The CAN controller's error monitor (the runtime's driver).
pub type CanErrors = amiro_firmware::bxcan::ErrorMonitor<Mmio>;
/// The board's monotonic clock (TIM5).
pub type Clock = crate::mono::Clock;

/// A busy wait on the core clock, counted at the design plan's clock (a slower fallback clock
/// waits longer): 1-2's BNO055 mode-switch and boot waits (at most 800 ms at boot, 26 ms per
/// (re-)initialisation) and, with `scripted-i2c`, 1-1's boot's set-up waits (none of the
/// compass's or the floor's set-up steps states one today; the set-up's interface takes it).
/// Named for 1-2's use: a new name re-hashes the shipped image's symbols, which moves its code.
#[cfg(any(feature = "rev-1-2", feature = "scripted-i2c"))]
#[derive(Debug, Default, Clone, Copy)]
pub struct ImuDelay;

#[cfg(any(feature = "rev-1-2", feature = "scripted-i2c"))]
impl embedded_hal::delay::DelayNs for ImuDelay {
    fn delay_ns(&mut self, ns: u32) {
        cortex_m::asm::delay(ns.div_ceil(1_000).saturating_mul(SYSCLK_HZ / 1_000_000));
    }
}

/// The module's system-bus signals: SYS_SYNC_N on PC1, SYS_PD_N on PC8 (EXTI line 8).
pub type SystemSignals = Lines<PC1<Output<OpenDrain>>, PC8<Output<OpenDrain>>, 8>;

/// Brings the board up. `spi_cell` is the static home of the SPI bus the two IMU devices of 1-1 share.
pub fn init(
    dp: pac::Peripherals,
    mut cp: cortex_m::Peripherals,
    spi_cell: &'static mut Option<AtomicCell<ImuBus>>,
) -> (Board, cortex_m::peripheral::NVIC) {
    // The clock tree, every wait bounded (the runtime's `chip::clock_plan`): the PLL from the
    // crystal (72 MHz), else from the internal oscillator (64 MHz), else the internal oscillator
    // alone (8 MHz); each fault logged and flagged on the diagnostics. Then CAN1's reset.
    let clocks = amiro_firmware::chip::clock_plan();
    amiro_firmware::chip::reset_and_enable_can1();
    // The HAL's RCC only constrained, never frozen: its `freeze` waits for the crystal and the PLL
    // without a bound, and no driver here takes its frequencies from the HAL (they come from the
    // plan).
    let mut rcc = dp.RCC.constrain();
    // Only 1-1 has the SPI sensors; 1-2 leaves SPI1 off (its clock and the block's reset untouched).
    #[cfg(feature = "rev-1-1")]
    amiro_firmware::chip::reset_and_enable_spi1();
    TIMER_CLOCK_HZ.store(clocks.timer_hz, core::sync::atomic::Ordering::Relaxed);
    #[cfg(feature = "scripted-i2c")]
    scripted::set_clocks(clocks.pclk1_hz, clocks.sysclk_hz);
    #[cfg(feature = "scripted-i2c")]
    scripted::bind_engines(&mut cp.NVIC);
    // The blocking I2C driver times out on the DWT cycle counter (and the engine's condition wait
    // on it, with `scripted-i2c`).
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let mut afio = dp.AFIO.constrain(&mut rcc);
    let mut gpioa = dp.GPIOA.split(&mut rcc);
    let mut gpiob = dp.GPIOB.split(&mut rcc);
    let mut gpioc = dp.GPIOC.split(&mut rcc);

    // System signals first: SYS_SYNC_N stays low until `release_sync`, as AMiRo-BLT left it.
    let sys_sync = gpioc
        .pc1
        .into_open_drain_output_with_state(&mut gpioc.crl, PinState::Low);
    // SYS_PD_N is a wired-OR open-drain line that AMiRo-BLT also drives: keep it an open-drain
    // output released high (its input level and EXTI still work) and watch line 8 for a falling edge.
    let sys_pd = gpioc
        .pc8
        .into_open_drain_output_with_state(&mut gpioc.crh, PinState::High);
    let exti = dp.EXTI;
    // SAFETY: AFIO's clock is on (constrain above); EXTICR3 bits 0..4 select the port of line 8 and
    // nothing else in this firmware uses EXTI lines 8..11.
    unsafe {
        (*pac::AFIO::ptr())
            .exticr3()
            .modify(|r, w| w.bits((r.bits() & !0xF) | 0x2));
    }
    exti.ftsr()
        .modify(|r, w| unsafe { w.bits(r.bits() | SYS_PD_LINE) });
    exti.imr()
        .modify(|r, w| unsafe { w.bits(r.bits() | SYS_PD_LINE) });
    // The status LED (PA1, active low) lit while the application runs. Set once here; its pin
    // value is zero-sized, so the configuration stays when it goes out of scope.
    let _status_led_lit = gpioa
        .pa1
        .into_open_drain_output_with_state(&mut gpioa.crl, PinState::Low);

    // Motor power stays off until a motor command arrives.
    let power_en = gpiob
        .pb2
        .into_push_pull_output_with_state(&mut gpiob.crl, PinState::Low);
    amiro_firmware::log!("power lines: SYS_SYNC_N held low, SYS_PD_N released, motor power off");

    // JTAG off (its pins carry motor PWM), SWD kept for probe-rs; TIM2 partial remap 1, TIM3 full remap.
    let (pa15, pb3, _pb4) = afio.mapr.disable_jtag(gpioa.pa15, gpiob.pb3, gpiob.pb4);
    afio.mapr
        .modify_mapr(|_, w| unsafe { w.tim2_remap().bits(0b01).tim3_remap().bits(0b11) });
    let _pwm_pins = (
        pa15.into_alternate_push_pull(&mut gpioa.crh),
        pb3.into_alternate_push_pull(&mut gpiob.crl),
        gpioa.pa2.into_alternate_push_pull(&mut gpioa.crl),
        gpioa.pa3.into_alternate_push_pull(&mut gpioa.crl),
    );
    let _encoder_pins = (
        gpioc.pc6.into_floating_input(&mut gpioc.crl),
        gpioc.pc7.into_floating_input(&mut gpioc.crl),
        gpiob.pb6.into_floating_input(&mut gpiob.crl),
        gpiob.pb7.into_floating_input(&mut gpiob.crl),
    );
    let motors = Motors::new(dp.TIM2, power_en);
    let encoders = Encoders::new(dp.TIM3, dp.TIM4);

    // Revision 1-1: SPI1, mode 0 at up to 9 MHz (PCLK2 / 4 on the crystal), chip selects idle
    // high; SCK and MOSI alternate push-pull, MISO floating; the runtime's bounded master.
    #[cfg(feature = "rev-1-1")]
    let gyro_cs = gpioc
        .pc14
        .into_push_pull_output_with_state(&mut gpioc.crh, PinState::High);
    #[cfg(feature = "rev-1-1")]
    let accel_cs = gpioc
        .pc13
        .into_push_pull_output_with_state(&mut gpioc.crh, PinState::High);
    #[cfg(feature = "rev-1-1")]
    let _spi_pins = (
        gpioa.pa5.into_alternate_push_pull(&mut gpioa.crl),
        gpioa.pa6.into_floating_input(&mut gpioa.crl),
        gpioa.pa7.into_alternate_push_pull(&mut gpioa.crl),
    );
    let _ = dp.SPI1;
    #[cfg(feature = "rev-1-1")]
    // SAFETY: SPI1 is used by this value only.
    let spi = spi::Master::new(
        unsafe { Mmio::new(spi::SPI1) },
        clocks.pclk2_hz,
        IMU_SPI_HZ,
        SpiMode {
            polarity: Polarity::IdleLow,
            phase: Phase::CaptureOnFirstTransition,
        },
    );
    // Both devices live in the one `imu` resource, so the bus is never contended; the atomic
    // cell only makes the shared bus `Sync` without a critical section.
    #[cfg(feature = "rev-1-1")]
    let bus: &'static AtomicCell<ImuBus> = spi_cell.insert(AtomicCell::new(spi));
    #[cfg(feature = "rev-1-1")]
    let gyro_spi = AtomicDevice::new_no_delay(bus, gyro_cs).unwrap_or_else(|_| unreachable_pin());
    #[cfg(feature = "rev-1-1")]
    let accel_spi = AtomicDevice::new_no_delay(bus, accel_cs).unwrap_or_else(|_| unreachable_pin());
    #[cfg(feature = "rev-1-2")]
    let _ = spi_cell;

    // Revision 1-2: the BNO055 starts its application (IMU_BOOT_LOAD_N high) out of a reset pulse
    // on IMU_RESET_N (held low 1 ms; the datasheet asks for far less); `sensors::groups` waits for
    // it to answer. The pins keep their state after these handles are dropped.
    #[cfg(feature = "rev-1-2")]
    {
        let _boot_load = gpioc
            .pc12
            .into_push_pull_output_with_state(&mut gpioc.crh, PinState::High);
        let mut reset = gpioc
            .pc2
            .into_push_pull_output_with_state(&mut gpioc.crl, PinState::Low);
        cortex_m::asm::delay(SYSCLK_HZ / 1_000);
        reset.set_high();
    }

    // I2C1 remapped to PB8/PB9 and I2C2 on PB10/PB11, both 400 kHz: pins alternate open drain
    // (the board has pull-ups), the blocks reset and clocked, then the runtime's bounded master.
    afio.mapr.modify_mapr(|_, w| w.i2c1_remap().set_bit());
    let _i2c_pins = (
        gpiob.pb8.into_alternate_open_drain(&mut gpiob.crh),
        gpiob.pb9.into_alternate_open_drain(&mut gpiob.crh),
        gpiob.pb10.into_alternate_open_drain(&mut gpiob.crh),
        gpiob.pb11.into_alternate_open_drain(&mut gpiob.crh),
    );
    // SAFETY: I2C1/I2C2 reset and clock bits, owned by init.
    unsafe {
        let rcc = &*pac::RCC::ptr();
        rcc.apb1rstr()
            .modify(|_, w| w.i2c1rst().set_bit().i2c2rst().set_bit());
        rcc.apb1rstr()
            .modify(|_, w| w.i2c1rst().clear_bit().i2c2rst().clear_bit());
        rcc.apb1enr()
            .modify(|_, w| w.i2c1en().set_bit().i2c2en().set_bit());
    }
    let _ = (dp.I2C1, dp.I2C2);
    // SAFETY: I2C1 and I2C2 are used by these two values only, their pins (PB8/PB9, PB10/PB11,
    // alternate open drain above) by their bus clears only.
    let (i2c1, floor_i2c) = unsafe {
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

    // CAN1 on PA11/PA12 at 1 Mbit/s (no remap): RX floating input, TX alternate push-pull; the
    // runtime's driver configures the controller.
    let _can_rx_pin = gpioa.pa11.into_floating_input(&mut gpioa.crh);
    let _can_tx_pin = gpioa.pa12.into_alternate_push_pull(&mut gpioa.crh);
    let can = bxcan::bring_up(clocks.can_btr);

    let signals = SystemSignals::new(sys_sync, sys_pd);
    let _ = dp.IWDG;
    (
        Board {
            can_tx: can.tx,
            can_rx: can.rx,
            can_errors: can.errors,
            #[cfg(feature = "rev-1-1")]
            sensors: SensorBuses {
                gyro_spi,
                accel_spi,
                compass_i2c: i2c1,
                floor_i2c,
            },
            #[cfg(feature = "rev-1-2")]
            sensors: SensorBuses {
                imu_i2c: i2c1,
                imu_delay: ImuDelay,
                floor_i2c,
            },
            motors,
            encoders,
            signals,
        },
        cp.NVIC,
    )
}

/// Setting a push-pull chip select high cannot fail on this chip.
#[cfg(feature = "rev-1-1")]
fn unreachable_pin() -> ! {
    amiro_firmware::fault::halt()
}

/// The two DC motors: TIM2 PWM into the A3906 H-bridge, and the POWER_EN switch.
pub struct Motors {
    tim: pac::TIM2,
    power_en: PB2<Output<PushPull>>,
}

impl Motors {
    fn new(tim: pac::TIM2, power_en: PB2<Output<PushPull>>) -> Self {
        // SAFETY: enabling TIM2's clock is a single bit in a register only init touches.
        let rcc = unsafe { &*pac::RCC::ptr() };
        rcc.apb1enr().modify(|_, w| w.tim2en().set_bit());
        tim.psc().write(|w| w.psc().set(0));
        tim.arr().write(|w| w.arr().set(PWM_PERIOD - 1));
        // PWM mode 1 with preload on all four channels.
        tim.ccmr1_output().write(|w| {
            w.oc1m()
                .pwm_mode1()
                .oc1pe()
                .set_bit()
                .oc2m()
                .pwm_mode1()
                .oc2pe()
                .set_bit()
        });
        tim.ccmr2_output().write(|w| {
            w.oc3m()
                .pwm_mode1()
                .oc3pe()
                .set_bit()
                .oc4m()
                .pwm_mode1()
                .oc4pe()
                .set_bit()
        });
        for ch in 0..4 {
            tim.ccr(ch).write(|w| w.ccr().set(0));
        }
        tim.ccer().write(|w| {
            w.cc1e()
                .set_bit()
                .cc2e()
                .set_bit()
                .cc3e()
                .set_bit()
                .cc4e()
                .set_bit()
        });
        tim.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
        Self { tim, power_en }
    }

    /// Sets the duties in 1/10000 of full scale (sign = direction): per motor one input of the
    /// H-bridge gets the PWM, the other stays low.
    pub fn set(&mut self, left: i16, right: i16) {
        let (lf, lb) = split_duty(left);
        let (rf, rb) = split_duty(right);
        self.tim.ccr(0).write(|w| w.ccr().set(lf));
        self.tim.ccr(1).write(|w| w.ccr().set(lb));
        self.tim.ccr(2).write(|w| w.ccr().set(rf));
        self.tim.ccr(3).write(|w| w.ccr().set(rb));
    }

    /// Switches the motor supply.
    pub fn power(&mut self, on: bool) {
        if on {
            self.power_en.set_high();
        } else {
            self.power_en.set_low();
        }
    }
}

fn split_duty(duty: i16) -> (u16, u16) {
    let magnitude = u32::from(duty.unsigned_abs().min(10_000));
    let compare = (magnitude * u32::from(PWM_PERIOD) / 10_000) as u16;
    if duty >= 0 {
        (compare, 0)
    } else {
        (0, compare)
    }
}

/// DiWheelDrive's safe state, from any context, whatever state the program is in: POWER_EN low,
/// PWM zero. The runtime's panic, HardFault and hand-over paths call it first.
pub fn emergency_motors_off() {
    // SAFETY: single writes of "off" values; racing with a task at worst repeats them.
    unsafe {
        let gpiob = &*pac::GPIOB::ptr();
        gpiob.bsrr().write(|w| w.br2().set_bit());
        let tim2 = &*pac::TIM2::ptr();
        for ch in 0..4 {
            tim2.ccr(ch).write(|w| w.ccr().set(0));
        }
    }
}

/// The wheel encoders: TIM3 (left) and TIM4 (right) in encoder mode 3, counting both edges of both
/// channels (4 × 16 lines × 22:1 gear = 1408 counts per wheel turn).
pub struct Encoders {
    left: pac::TIM3,
    right: pac::TIM4,
}

impl Encoders {
    fn new(left: pac::TIM3, right: pac::TIM4) -> Self {
        // SAFETY: enabling the timers' clocks is owned by init.
        let rcc = unsafe { &*pac::RCC::ptr() };
        rcc.apb1enr()
            .modify(|_, w| w.tim3en().set_bit().tim4en().set_bit());
        // Left: both inputs direct, TI1 polarity inverted so forward counts up on both wheels
        // (the original inverts channel 1 of the quadrature pair).
        left.ccmr1_input().write(|w| w.cc1s().ti1().cc2s().ti2());
        // No input inverted on either wheel: the drive controller expects both counts to rise
        // driving forward (amiro-sensors' DriveConfig can invert a wheel if the bench disagrees).
        left.ccer().write(|w| unsafe { w.bits(0) });
        left.smcr().write(|w| w.sms().encoder_mode_3());
        left.arr().write(|w| w.arr().set(0xFFFF));
        left.cr1().write(|w| w.cen().set_bit());
        right.ccmr1_input().write(|w| w.cc1s().ti1().cc2s().ti2());
        right.ccer().write(|w| unsafe { w.bits(0) });
        right.smcr().write(|w| w.sms().encoder_mode_3());
        right.arr().write(|w| w.arr().set(0xFFFF));
        right.cr1().write(|w| w.cen().set_bit());
        Self { left, right }
    }

    /// The wrapping 16-bit counts (left, right).
    pub fn counts(&self) -> (u16, u16) {
        (
            self.left.cnt().read().cnt().bits(),
            self.right.cnt().read().cnt().bits(),
        )
    }
}

/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: pac::Interrupt = pac::Interrupt::USB_HP_CAN_TX;

/// Starts the TIM5 monotonic (APB1 timers run at 2 × PCLK1: 72 MHz, or 64 MHz on the fallback).
pub fn start_monotonic(priority: u8) {
    // SAFETY: init owns RCC at this point (only TIM5's enable and reset bits change); the
    // monotonic takes TIM5 over for good.
    let rcc = unsafe { &*pac::RCC::ptr() };
    let timer_clock = TIMER_CLOCK_HZ.load(core::sync::atomic::Ordering::Relaxed);
    crate::mono::start(rcc, timer_clock, priority);
}

/// Interrupt of the SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: pac::Interrupt = pac::Interrupt::EXTI9_5;

/// With `scripted-i2c`: the I2C blocks driven by their interrupts once the app runs
/// (`amiro_firmware::i2c_bus`: the engine, a slot per publisher task), after the boot set the
/// devices up on the polled master (docs/i2c.md).
#[cfg(feature = "scripted-i2c")]
pub mod scripted {
    use amiro_firmware::i2c::{self, Master};
    use amiro_firmware::i2c_block::{hand_over, EngineBuses, Registers};
    use amiro_firmware::i2c_bus::I2cBus;
    use amiro_firmware::scripted::I2cPort;
    use amiro_sensors::drivers::floor::FloorSensors;
    use amiro_sensors::drivers::scripted::{OnI2c, ScriptedSensors, Scripts};
    use amiro_sensors::drivers::suite::{self, Supervised};
    use stm32f1xx_hal::pac::{interrupt, Interrupt, NVIC};

    use super::{Clock, ImuDelay, SYSCLK_HZ};
    use crate::levels;
    use crate::sensors::{CLIENTS, TIMEOUT_ALLOWANCE_US};

    /// One I2C block's bus once the app runs.
    pub type ScriptBus = I2cBus<Registers, CLIENTS>;
    /// A publisher task's slot on a [`ScriptBus`], its timeout on the board's clock.
    pub type Port = I2cPort<'static, Clock, Registers, CLIENTS>;
    /// The task's slot on I2C1 (the compass).
    pub type CompassPort = Port;
    /// The task's slot on I2C2 (the floor).
    pub type FloorPort = Port;

    /// The clients' RTIC priorities, by slot: the bus serves the most urgent waiting script next.
    const CLIENT_PRIORITIES: [u8; CLIENTS] = [
        levels::PUBLISH_URGENT,
        levels::PUBLISH_HIGH,
        levels::PUBLISH_MEDIUM,
        levels::PUBLISH_LOW,
    ];

    /// I2C1: the HMC5883L.
    // SAFETY: the block is touched only after `boot_compass` took it from the polled master.
    pub static I2C1_BUS: ScriptBus = I2cBus::new(
        unsafe { Registers::new(i2c::I2C1, SYSCLK_HZ / 2, SYSCLK_HZ) },
        CLIENT_PRIORITIES,
    );
    /// I2C2: the PCA9544A and the four VCNL4020.
    // SAFETY: as I2C1's, after `boot_floor`.
    pub static I2C2_BUS: ScriptBus = I2cBus::new(
        unsafe { Registers::new(i2c::I2C2, SYSCLK_HZ / 2, SYSCLK_HZ) },
        CLIENT_PRIORITIES,
    );
    /// Both, for the wiring amiro-firmware shares with PowerManagement's trial.
    static BUSES: EngineBuses<CLIENTS> = EngineBuses {
        i2c1: &I2C1_BUS,
        i2c2: &I2C2_BUS,
    };

    /// I2C1's events: the compass bus's engine advances its script (docs/i2c.md).
    #[interrupt]
    fn I2C1_EV() {
        I2C1_BUS.on_event();
    }

    /// I2C1's errors (a missing acknowledge, a bus error, arbitration lost, an overrun).
    #[interrupt]
    fn I2C1_ER() {
        I2C1_BUS.on_error();
    }

    /// I2C2's events: the floor bus's engine.
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
    /// another's critical step; above every publisher, below the CAN interrupts; RTIC's locks
    /// mask them as they mask a task of that priority), and unmasked (`EngineBuses::bind_engines`;
    /// they become the app's tasks when the analysis takes the sensor buses, docs/i2c.md, "What
    /// step (c) wires").
    pub(super) fn bind_engines(nvic: &mut NVIC) {
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
    pub(super) fn set_clocks(pclk1_hz: u32, sysclk_hz: u32) {
        BUSES.set_clocks(pclk1_hz, sysclk_hz);
    }

    /// `group` set up by its scripts on the polled master `boot` (each script operation by
    /// operation, a part's settling time waited on the core clock, `ImuDelay`), then `boot`'s
    /// block handed to `bus` (`i2c_block::hand_over`).
    fn boot_on<G: ScriptedSensors>(group: G, boot: Master, bus: &ScriptBus) -> Supervised<G> {
        // The polled master is consumed here: the block is the engine's from now on.
        let booted = Supervised::boot(group, &mut OnI2c(boot), &mut ImuDelay);
        hand_over(bus);
        booted
    }

    /// The compass set up on I2C1's polled master, then I2C1 handed to its engine.
    pub fn boot_compass(boot: Master) -> Supervised<suite::Compass<Scripts>> {
        boot_on(suite::Compass::scripted(), boot, &I2C1_BUS)
    }

    /// The floor set up on I2C2's polled master, then I2C2 handed to its engine.
    pub fn boot_floor(boot: Master) -> Supervised<FloorSensors<Scripts>> {
        boot_on(FloorSensors::scripted(), boot, &I2C2_BUS)
    }

    /// Publisher task `CLIENT`'s slots on I2C1 and I2C2.
    pub fn ports<const CLIENT: usize>() -> (CompassPort, FloorPort) {
        BUSES.ports::<CLIENT, Clock>(TIMEOUT_ALLOWANCE_US)
    }
}
#[cfg(feature = "scripted-i2c")]
pub use scripted::{boot_compass, boot_floor, ports, CompassPort, FloorPort};
