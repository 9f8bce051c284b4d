//! DiWheelDrive's QEMU board: the same app, with this board's devices simulated.
//!
//! The platform (SysTick clock, virtual CAN, stimulus replay, stack painting, the end line,
//! simulated system signals) is the runtime's `amiro_firmware::qemu`; this file adds only what is
//! DiWheelDrive's own: amiro-sensors' register-level simulators behind the real drivers, and a
//! simulated wheel plant for the motors and encoders.
use core::cell::RefCell;

use critical_section::Mutex;
use stm32f1xx_hal::pac::{self, Interrupt};

use amiro_sensors::motion::{Duty, MotorPwm};

pub use amiro_firmware::qemu::{CanErrors, CanRxPort, CanTxPort, Clock, Signals as SystemSignals};
pub use amiro_sensors::sim::{
    SimAccelerometer as AccelSpi, SimCompassBus as CompassI2c, SimFloorBus as FloorI2c,
    SimGyroscope as GyroSpi,
};

/// The QEMU build has no SPI bus object: each simulated device is its own `SpiDevice`.
pub type ImuBus = ();
/// Interrupt of the (simulated) SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: Interrupt = Interrupt::EXTI9_5;
/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: Interrupt = Interrupt::USB_HP_CAN_TX;
/// Interrupt of the CAN receive FIFO 0 (pended by the stimulus replay).
pub const CAN_RX_INTERRUPT: Interrupt = Interrupt::USB_LP_CAN_RX0;

static PLANT: Mutex<RefCell<Option<amiro_sensors::sim::WheelPlant>>> =
    Mutex::new(RefCell::new(None));

/// What `init` hands on to the tasks (same shape as the real board's).
pub struct Board {
    /// Virtual transmit mailboxes.
    pub can_tx: CanTxPort,
    /// Virtual receive FIFO.
    pub can_rx: CanRxPort,
    /// No CAN errors in QEMU.
    pub can_errors: CanErrors,
    /// Simulated L3G4200D.
    pub gyro_spi: GyroSpi,
    /// Simulated LIS331DLH.
    pub accel_spi: AccelSpi,
    /// Simulated HMC5883L bus.
    pub compass_i2c: CompassI2c,
    /// Simulated PCA9544A + floor sensors bus.
    pub floor_i2c: FloorI2c,
    /// Simulated motors.
    pub motors: Motors,
    /// Simulated encoders.
    pub encoders: Encoders,
    /// Simulated system signals.
    pub signals: SystemSignals,
}

/// Brings the simulated board up (touches no STM32 peripheral: QEMU's machine is a different chip).
pub fn init(
    _dp: pac::Peripherals,
    cp: cortex_m::Peripherals,
    _spi_cell: &'static mut Option<embedded_hal_bus::util::AtomicCell<ImuBus>>,
) -> (Board, cortex_m::peripheral::NVIC) {
    // Paint the free RAM before anything runs deep, and start SysTick.
    amiro_firmware::qemu::init(cp.SYST);
    critical_section::with(|cs| {
        PLANT
            .borrow_ref_mut(cs)
            .replace(amiro_sensors::sim::WheelPlant::new());
    });
    (
        Board {
            can_tx: CanTxPort,
            can_rx: CanRxPort,
            can_errors: amiro_firmware::qemu::can_errors(),
            gyro_spi: GyroSpi::new(),
            accel_spi: AccelSpi::new(),
            compass_i2c: CompassI2c::new(),
            floor_i2c: FloorI2c::new(),
            motors: Motors,
            encoders: Encoders,
            signals: SystemSignals,
        },
        cp.NVIC,
    )
}

/// The SysTick monotonic already runs (started in `init`).
pub fn start_monotonic(_priority: u8) {}

/// Simulated motors.
pub struct Motors;

impl Motors {
    /// Duties in 1/10000 of full scale.
    pub fn set(&mut self, left: i16, right: i16) {
        critical_section::with(|cs| {
            if let Some(plant) = PLANT.borrow_ref_mut(cs).as_mut() {
                plant.set_duty(
                    Duty::saturating(left.into()),
                    Duty::saturating(right.into()),
                );
            }
        });
    }

    /// Motor supply.
    pub fn power(&mut self, on: bool) {
        critical_section::with(|cs| {
            if let Some(plant) = PLANT.borrow_ref_mut(cs).as_mut() {
                plant.set_power(on);
            }
        });
    }
}

/// Stops the simulated motors from any context.
pub fn emergency_motors_off() {
    critical_section::with(|cs| {
        if let Some(plant) = PLANT.borrow_ref_mut(cs).as_mut() {
            plant.set_power(false);
            plant.set_duty(Duty::ZERO, Duty::ZERO);
        }
    });
}

/// Simulated encoders: the plant integrated up to now.
pub struct Encoders;

impl Encoders {
    /// Wrapping 16-bit counts (left, right).
    pub fn counts(&self) -> (u16, u16) {
        let now = <Clock as amiro_firmware::mono::Clock>::now_us();
        critical_section::with(|cs| {
            PLANT
                .borrow_ref_mut(cs)
                .as_mut()
                .map(|p| p.counts(now))
                .unwrap_or((0, 0))
        })
    }
}
