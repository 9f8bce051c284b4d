//! DiWheelDrive's QEMU board: the same app, with this board's devices simulated.
//!
//! The platform (SysTick clock, virtual CAN, stimulus replay, stack painting, the end line,
//! simulated system signals) is the runtime's `amiro_firmware::qemu`; this file adds only what is
//! DiWheelDrive's own: amiro-sensors' register-level simulators behind the real drivers (1-1: the
//! L3G4200D, LIS331DLH and HMC5883L; 1-2: the BNO055 of a robot at rest in Bielefeld), and a
//! simulated wheel plant for the motors and encoders.
//!
//! **QEMU-only control frames** (revision 1-2), as on PowerManagement: command frames on
//! [`amiro_firmware::qemu::SIM_CONTROL_ID`] (`0x3F0`, topic 0xF0, which the protocol leaves
//! free) are taken out by the receive port before the command queue:
//!
//! | data | effect |
//! |---|---|
//! | `01` | the BNO055 stops answering (its address is not acknowledged: a dead or absent part) |
//! | `02` | the BNO055 answers again (a part that came back; the supervisor's retry finds it) |
use crate::sensors::SensorBuses;
use crate::Board;
use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, Ordering};

use critical_section::Mutex;
use stm32f1xx_hal::pac::{self, Interrupt};

use amiro_sensors::motion::{Duty, MotorPwm};

pub use amiro_firmware::mono::QemuClock as Clock;
use amiro_firmware::qemu::robot;
pub use amiro_firmware::qemu::{CanErrors, CanTxPort, Signals as SystemSignals};
/// The simulated parts need no time between transfers.
#[cfg(feature = "rev-1-2")]
pub use amiro_sensors::sim::NoDelay as ImuDelay;
use amiro_sensors::sim::SimFloorBus;
#[cfg(feature = "rev-1-1")]
use amiro_sensors::sim::{SimAccelerometer, SimCompassBus, SimGyroscope};
use robot::world_link::{Readings, FLOOR};

/// The floor sensors' bus, fed from the world in a robot run with one.
pub type FloorI2c = Fed<SimFloorBus>;
/// The L3G4200D, fed from the world in a robot run with one.
#[cfg(feature = "rev-1-1")]
pub type GyroSpi = Fed<SimGyroscope>;
/// The LIS331DLH, fed from the world in a robot run with one.
#[cfg(feature = "rev-1-1")]
pub type AccelSpi = Fed<SimAccelerometer>;
/// The HMC5883L's bus, fed from the world in a robot run with one.
#[cfg(feature = "rev-1-1")]
pub type CompassI2c = Fed<SimCompassBus>;

/// A simulated device that takes the world's latest readings (`robot::readings`, docs/world.md)
/// before each transfer; without a world it keeps its own pattern.
pub struct Fed<T>(T);

/// A simulator's part of the world's readings.
pub trait TakeReadings {
    /// Hands the simulator its values from `r` (if `r` carries its group).
    fn take(&mut self, r: &Readings);
}

impl<T: TakeReadings> Fed<T> {
    fn fed(&mut self) -> &mut T {
        if let Some(r) = robot::readings() {
            self.0.take(&r);
        }
        &mut self.0
    }
}

impl<T: embedded_hal::i2c::ErrorType> embedded_hal::i2c::ErrorType for Fed<T> {
    type Error = T::Error;
}

impl<T: embedded_hal::i2c::I2c + TakeReadings> embedded_hal::i2c::I2c for Fed<T> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [embedded_hal::i2c::Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.fed().transaction(address, operations)
    }
}

#[cfg(feature = "rev-1-1")]
impl<T: embedded_hal::spi::ErrorType> embedded_hal::spi::ErrorType for Fed<T> {
    type Error = T::Error;
}

#[cfg(feature = "rev-1-1")]
impl<T: embedded_hal::spi::SpiDevice + TakeReadings> embedded_hal::spi::SpiDevice for Fed<T> {
    fn transaction(
        &mut self,
        operations: &mut [embedded_hal::spi::Operation<'_, u8>],
    ) -> Result<(), Self::Error> {
        self.fed().transaction(operations)
    }
}

impl TakeReadings for SimFloorBus {
    fn take(&mut self, r: &Readings) {
        if r.has(FLOOR) {
            amiro_sensors::sim::feed_floor(&mut self.target, Some(r.floor));
        }
    }
}

#[cfg(feature = "rev-1-1")]
impl TakeReadings for SimGyroscope {
    fn take(&mut self, r: &Readings) {
        if r.has(robot::world_link::IMU_1_1) {
            self.set_measured(Some(r.rate));
        }
    }
}

#[cfg(feature = "rev-1-1")]
impl TakeReadings for SimAccelerometer {
    fn take(&mut self, r: &Readings) {
        if r.has(robot::world_link::IMU_1_1) {
            self.set_measured(Some(r.accel));
        }
    }
}

#[cfg(feature = "rev-1-1")]
impl TakeReadings for SimCompassBus {
    fn take(&mut self, r: &Readings) {
        if r.has(robot::world_link::IMU_1_1) {
            self.target.set_field(Some(r.field_nt));
        }
    }
}

#[cfg(feature = "rev-1-2")]
impl TakeReadings for amiro_sensors::sim::SimImuBus {
    fn take(&mut self, r: &Readings) {
        if r.has(robot::world_link::IMU_1_2) {
            self.imu_mut()
                .set_motion(Some(amiro_sensors::sim::Bno055Motion {
                    accel_mg: r.accel,
                    field_nt: r.field_nt,
                    rate_digits: r.rate,
                }));
        }
    }
}

/// Whether the simulated BNO055 has stopped answering (control frame `01`).
static IMU_DEAD: AtomicBool = AtomicBool::new(false);

/// The virtual receive FIFO, with the QEMU-only control frames taken out for `apply_control`.
pub type CanRxPort = amiro_firmware::qemu::ControlledRxPort;

fn apply_control(data: &[u8]) {
    match data.first() {
        Some(1) if cfg!(feature = "rev-1-2") => {
            IMU_DEAD.store(true, Ordering::SeqCst);
            amiro_firmware::qemu::print_line("# qemu: the BNO055 stops answering");
        }
        Some(2) if cfg!(feature = "rev-1-2") => {
            IMU_DEAD.store(false, Ordering::SeqCst);
            amiro_firmware::qemu::print_line("# qemu: the BNO055 answers again");
        }
        _ => amiro_firmware::qemu::print_line("# qemu: unknown control frame"),
    }
}

/// Revision 1-2's I2C1: the simulated BNO055, which stops answering on a control frame.
#[cfg(feature = "rev-1-2")]
pub struct ImuI2c(amiro_sensors::sim::SimImuBus);

#[cfg(feature = "rev-1-2")]
impl embedded_hal::i2c::ErrorType for ImuI2c {
    type Error = amiro_sensors::sim::NoAcknowledge;
}

#[cfg(feature = "rev-1-2")]
impl embedded_hal::i2c::I2c for ImuI2c {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [embedded_hal::i2c::Operation<'_>],
    ) -> Result<(), Self::Error> {
        if let Some(r) = robot::readings() {
            self.0.take(&r);
        }
        self.0.set_nack(IMU_DEAD.load(Ordering::SeqCst));
        self.0.transaction(address, operations)
    }
}

#[cfg(feature = "rev-1-1")]
fn sensor_buses() -> SensorBuses {
    SensorBuses {
        gyro_spi: Fed(SimGyroscope::new()),
        accel_spi: Fed(SimAccelerometer::new()),
        compass_i2c: Fed(SimCompassBus::new()),
        floor_i2c: Fed(SimFloorBus::new()),
    }
}

#[cfg(feature = "rev-1-2")]
fn sensor_buses() -> SensorBuses {
    SensorBuses {
        imu_i2c: ImuI2c(amiro_sensors::sim::SimImuBus::new()),
        imu_delay: ImuDelay,
        floor_i2c: Fed(SimFloorBus::new()),
    }
}

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

/// Brings the simulated board up (touches no STM32 peripheral: QEMU's machine is a different chip).
pub fn init(
    _dp: pac::Peripherals,
    cp: cortex_m::Peripherals,
    _spi_cell: &'static mut Option<embedded_hal_bus::util::AtomicCell<ImuBus>>,
) -> (Board, cortex_m::peripheral::NVIC) {
    // Paint the free RAM before anything runs deep, and start SysTick.
    amiro_firmware::mono::start_qemu(cp.SYST);
    critical_section::with(|cs| {
        PLANT
            .borrow_ref_mut(cs)
            .replace(amiro_sensors::sim::WheelPlant::new());
    });
    robot::report_wheels(wheel_ticks);
    (
        Board {
            can_tx: CanTxPort,
            can_rx: CanRxPort::new(apply_control),
            can_errors: amiro_firmware::qemu::can_errors(),
            sensors: sensor_buses(),
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

/// The plant's whole ticks (left, right) at `now_us`, for the world (robot runs with one).
fn wheel_ticks(now_us: u64) -> (i64, i64) {
    critical_section::with(|cs| {
        PLANT.borrow_ref_mut(cs).as_mut().map_or((0, 0), |p| {
            p.advance_to(now_us);
            (p.left.ticks(), p.right.ticks())
        })
    })
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

/// With `scripted-i2c`: the compass's and the floor's buses as the QEMU build runs their scripts
/// (`amiro_firmware::i2c_sim`: each script answered by the simulated devices, fed from the world,
/// after its time on the wire). The devices live in the bus from the start; the boot's set-up
/// runs on them too (the boot bus values `init` hands over are not used).
#[cfg(feature = "scripted-i2c")]
pub mod scripted {
    use amiro_firmware::i2c_sim::{SimBus, SimPort};
    use amiro_sensors::drivers::floor::FloorSensors;
    use amiro_sensors::drivers::scripted::{OnI2c, ScriptBus, ScriptedSensors, Scripts};
    use amiro_sensors::drivers::suite::{self, Supervised};
    use amiro_sensors::sim::{NoDelay, SimCompassBus, SimFloorBus};

    use super::{Clock, CompassI2c, Fed, FloorI2c};
    use crate::sensors::TIMEOUT_ALLOWANCE_US;

    /// I2C1's simulated HMC5883L, fed from the world.
    type CompassDevices = OnI2c<Fed<SimCompassBus>>;
    /// I2C2's simulated PCA9544A and floor sensors, fed from the world.
    type FloorDevices = OnI2c<Fed<SimFloorBus>>;
    /// The task's slot on I2C1 (the compass).
    pub type CompassPort = SimPort<'static, Clock, CompassDevices>;
    /// The task's slot on I2C2 (the floor).
    pub type FloorPort = SimPort<'static, Clock, FloorDevices>;

    /// I2C1.
    pub static I2C1_BUS: SimBus<CompassDevices> = SimBus::new(OnI2c(Fed(SimCompassBus::new())));
    /// I2C2.
    pub static I2C2_BUS: SimBus<FloorDevices> = SimBus::new(OnI2c(Fed(SimFloorBus::new())));

    /// `group` set up by its scripts on `bus`'s devices (no waits: the simulated parts need none).
    fn boot_on<G: ScriptedSensors, D: ScriptBus>(group: G, bus: &SimBus<D>) -> Supervised<G> {
        bus.with_devices(|devices| Supervised::boot(group, devices, &mut NoDelay))
    }

    /// The compass set up on I2C1's simulated part.
    pub fn boot_compass(_boot: CompassI2c) -> Supervised<suite::Compass<Scripts>> {
        boot_on(suite::Compass::scripted(), &I2C1_BUS)
    }

    /// The floor set up on I2C2's simulated parts.
    pub fn boot_floor(_boot: FloorI2c) -> Supervised<FloorSensors<Scripts>> {
        boot_on(FloorSensors::scripted(), &I2C2_BUS)
    }

    /// Publisher task `CLIENT`'s clients of I2C1 and I2C2.
    pub fn ports<const CLIENT: usize>() -> (CompassPort, FloorPort) {
        const { assert!(CLIENT < crate::sensors::CLIENTS) };
        (
            SimPort::new(&I2C1_BUS, TIMEOUT_ALLOWANCE_US),
            SimPort::new(&I2C2_BUS, TIMEOUT_ALLOWANCE_US),
        )
    }
}
#[cfg(feature = "scripted-i2c")]
pub use scripted::{boot_compass, boot_floor, ports, CompassPort, FloorPort};
