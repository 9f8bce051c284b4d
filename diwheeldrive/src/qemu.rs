//! The QEMU build's platform: the same app, with the chip replaced by what QEMU can run.
//!
//! QEMU emulates neither the STM32F103's clock tree nor bxCAN, so this build sets up no clock and
//! no CAN hardware. Instead:
//! - the monotonic is SysTick (see `mono`), in deterministic virtual time under `-icount`;
//! - the CAN bus is a stimulus log replayed from the host (read through semihosting) into a virtual
//!   3-frame receive FIFO that raises the real `can_rx` interrupt, and three virtual transmit
//!   mailboxes that print every frame in `candump -l` format with its virtual-time stamp;
//! - the sensors are amiro-sensors' register-level simulators behind the real drivers;
//! - the motors and encoders are a simulated wheel plant.
//!
//! Trace events and the human log are printed as lines starting with `#`.
use core::cell::RefCell;
use core::fmt::Write as _;

use cortex_m_semihosting::{debug, hprintln, syscall};
use critical_section::Mutex;
use heapless::{Deque, String};
use stm32f1xx_hal::pac::{self, Interrupt};

use amiro_sensors::motion::{Duty, MotorPwm};

use crate::can::{CanRx, CanTx, RxFrame, Transmit};

pub use amiro_sensors::sim::{
    SimAccelerometer as AccelSpi, SimCompassBus as CompassI2c, SimFloorBus as FloorI2c,
    SimGyroscope as GyroSpi,
};

/// The QEMU build has no SPI bus object: each simulated device is its own `SpiDevice`.
pub type ImuBus = ();
/// Interrupt of the (not simulated) SYS_PD_N line.
pub const SHUTDOWN_INTERRUPT: Interrupt = Interrupt::EXTI9_5;
/// Interrupt that runs the transmit path.
pub const CAN_TX_INTERRUPT: Interrupt = Interrupt::USB_HP_CAN_TX;
/// SysTick's clock in QEMU's netduino2 (the STM32F205 core clock).
pub const CORE_CLOCK_HZ: u32 = 120_000_000;

static RX_FIFO: Mutex<RefCell<Deque<RxFrame, 3>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_OVERRUN: Mutex<RefCell<bool>> = Mutex::new(RefCell::new(false));
static SYS_PD_LOW: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
static SYST: Mutex<RefCell<Option<cortex_m::peripheral::SYST>>> = Mutex::new(RefCell::new(None));
static PLANT: Mutex<RefCell<Option<amiro_sensors::sim::WheelPlant>>> =
    Mutex::new(RefCell::new(None));

/// What `init` hands on to the tasks (same shape as the real board's).
pub struct Board {
    /// Virtual transmit mailboxes.
    pub can_tx: CanTxPort,
    /// Virtual receive FIFO.
    pub can_rx: CanRxPort,
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
    /// No watchdog in QEMU.
    pub watchdog: Watchdog,
}

const STACK_PAINT: u32 = 0x5A5A_A5A5;

extern "C" {
    static mut __sheap: u32;
    static _stack_start: u32;
}

/// Fills the free stack below the current stack pointer with a pattern, so the end of the run
/// can tell how deep the stack ever went.
fn paint_stack() {
    let sp = cortex_m::register::msp::read() as usize;
    // SAFETY: `__sheap` marks the end of .bss/.uninit; everything from there up to a margin below
    // the live stack pointer is unused memory nobody else writes to.
    unsafe {
        let mut p = core::ptr::addr_of_mut!(__sheap) as usize;
        while p + 64 < sp {
            core::ptr::write_volatile(p as *mut u32, STACK_PAINT);
            p += 4;
        }
    }
}

/// The deepest the stack has been, in bytes (from the top of RAM to the lowest overwritten word).
pub fn stack_high_water() -> usize {
    // SAFETY: reads the painted region back; see `paint_stack`.
    unsafe {
        let bottom = core::ptr::addr_of_mut!(__sheap) as usize;
        let top = core::ptr::addr_of!(_stack_start) as usize;
        let mut p = bottom;
        while p < top && core::ptr::read_volatile(p as *const u32) == STACK_PAINT {
            p += 4;
        }
        top - p
    }
}

/// Static RAM (.data + .bss + .uninit), in bytes.
pub fn static_ram() -> usize {
    // Only the address of a linker symbol is taken.
    core::ptr::addr_of_mut!(__sheap) as usize - 0x2000_0000
}

/// Brings the simulated board up (touches no STM32 peripheral: QEMU's machine is a different chip).
pub fn init(
    _dp: pac::Peripherals,
    cp: cortex_m::Peripherals,
    _spi_cell: &'static mut Option<embedded_hal_bus::util::AtomicCell<ImuBus>>,
) -> (Board, cortex_m::peripheral::NVIC) {
    paint_stack();
    critical_section::with(|cs| {
        SYST.borrow_ref_mut(cs).replace(cp.SYST);
        PLANT
            .borrow_ref_mut(cs)
            .replace(amiro_sensors::sim::WheelPlant::new());
    });
    (
        Board {
            can_tx: CanTxPort,
            can_rx: CanRxPort,
            gyro_spi: GyroSpi::new(),
            accel_spi: AccelSpi::new(),
            compass_i2c: CompassI2c::new(),
            floor_i2c: FloorI2c::new(),
            motors: Motors,
            encoders: Encoders,
            signals: SystemSignals,
            watchdog: Watchdog,
        },
        cp.NVIC,
    )
}

/// Starts the SysTick monotonic.
pub fn start_monotonic(_priority: u8) {
    if let Some(syst) = critical_section::with(|cs| SYST.borrow_ref_mut(cs).take()) {
        crate::mono::start(syst, CORE_CLOCK_HZ);
    }
}

/// Virtual transmit mailboxes: a frame is on the bus the moment it is offered.
pub struct CanTxPort;

impl CanTx for CanTxPort {
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit {
        let mut line: String<64> = String::new();
        let now = crate::mono::now_us();
        let _ = write!(
            line,
            "({}.{:06}) can0 {:03X}#",
            now / 1_000_000,
            now % 1_000_000,
            frame.id().raw()
        );
        for b in frame.data() {
            let _ = write!(line, "{b:02X}");
        }
        hprintln!("{}", line);
        Transmit::Queued
    }

    fn completed(&mut self, _requeue: &mut dyn FnMut(amiro_can::Frame)) {}
}

/// Virtual receive FIFO (three frames deep, like bxCAN's).
pub struct CanRxPort;

impl CanRx for CanRxPort {
    fn receive(&mut self) -> Option<Result<RxFrame, ()>> {
        critical_section::with(|cs| {
            if core::mem::replace(&mut *RX_OVERRUN.borrow_ref_mut(cs), false) {
                return Some(Err(()));
            }
            RX_FIFO.borrow_ref_mut(cs).pop_front().map(Ok)
        })
    }
}

/// A stimulus record's size: `u64` µs, `u16` ID, `u8` length, `u8` flags, 8 data bytes.
const RECORD: usize = 20;

/// Replays `stimulus.bin` from the host into the virtual receive FIFO, then ends the run.
pub async fn replay_stimulus() {
    let Some(file) = HostFile::open(b"stimulus.bin\0") else {
        hprintln!("# qemu: cannot open stimulus.bin");
        exit(false);
        return;
    };
    let mut header = [0u8; 16];
    if !file.read_exact(&mut header) || &header[..8] != b"AMSTIM1\0" {
        hprintln!("# qemu: stimulus.bin has no AMSTIM1 header");
        exit(false);
        return;
    }
    let duration = u64::from_le_bytes([
        header[8], header[9], header[10], header[11], header[12], header[13], header[14],
        header[15],
    ]);
    let mut record = [0u8; RECORD];
    while file.read_exact(&mut record) {
        let at = u64::from_le_bytes([
            record[0], record[1], record[2], record[3], record[4], record[5], record[6], record[7],
        ]);
        if at > duration {
            break;
        }
        crate::mono::delay_until_us(at).await;
        if record[11] & 2 != 0 {
            // SYS_PD_N falls: the same interrupt the real pin raises.
            SYS_PD_LOW.store(true, core::sync::atomic::Ordering::SeqCst);
            rtic::pend(SHUTDOWN_INTERRUPT);
            continue;
        }
        let mut frame = RxFrame {
            id: u16::from_le_bytes([record[8], record[9]]),
            len: record[10].min(8),
            data: [0; 8],
        };
        frame.data.copy_from_slice(&record[12..20]);
        critical_section::with(|cs| {
            let mut fifo = RX_FIFO.borrow_ref_mut(cs);
            if fifo.push_back(frame).is_err() {
                *RX_OVERRUN.borrow_ref_mut(cs) = true;
            }
        });
        rtic::pend(Interrupt::USB_LP_CAN_RX0);
    }
    crate::mono::delay_until_us(duration).await;
    finish("end of run");
}

/// Prints the run's last line (receive drops, static RAM, the stack's high-water mark) and ends it.
fn finish(why: &str) {
    hprintln!(
        "# qemu: {} at {} us; rx dropped {}; ram static {} stack {}",
        why,
        crate::mono::now_us(),
        crate::publisher::rx_dropped(),
        static_ram(),
        stack_high_water()
    );
    exit(true);
}

/// Ends the QEMU run.
pub fn exit(success: bool) {
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
}

struct HostFile(usize);

impl HostFile {
    fn open(name_nul: &[u8]) -> Option<Self> {
        // SAFETY: semihosting OPEN with a NUL-terminated name, mode 1 ("rb"), length without the NUL.
        let fd = unsafe { syscall!(OPEN, name_nul.as_ptr(), 1, name_nul.len() - 1) };
        (fd as isize >= 0).then_some(Self(fd))
    }

    fn read_exact(&self, buf: &mut [u8]) -> bool {
        // SAFETY: semihosting READ into a buffer we own; it returns the number of bytes NOT read.
        let left = unsafe { syscall!(READ, self.0, buf.as_mut_ptr(), buf.len()) };
        left == 0
    }
}

/// Prints a trace event as a `#` line.
pub fn print_trace(event: &amiro_sensors::trace::TraceEvent) {
    hprintln!("# {}", event);
}

/// Reports a panic on the console.
pub fn log_panic(info: &core::panic::PanicInfo<'_>) {
    hprintln!("# panic: {}", info);
}

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
        let now = crate::mono::now_us();
        critical_section::with(|cs| {
            PLANT
                .borrow_ref_mut(cs)
                .as_mut()
                .map(|p| p.counts(now))
                .unwrap_or((0, 0))
        })
    }
}

/// Simulated system signals (printed).
pub struct SystemSignals;

impl SystemSignals {
    /// Releases SYS_SYNC_N.
    pub fn release_sync(&mut self) {
        hprintln!("# qemu: SYS_SYNC_N released");
    }

    /// Nothing to acknowledge.
    pub fn clear_shutdown_interrupt(&mut self) {}

    /// SYS_PD_N, as the stimulus drives it.
    pub fn shutdown_requested(&self) -> bool {
        SYS_PD_LOW.load(core::sync::atomic::Ordering::SeqCst)
    }

    /// Prints the SYS_SYNC_N edge.
    pub fn pull_sync_low(&mut self) {
        hprintln!("# qemu: SYS_SYNC_N pulled low");
    }
}

/// No watchdog in QEMU (QEMU's machine has no STM32F1 IWDG).
pub struct Watchdog;

/// Starts the watchdog (nothing in QEMU).
pub fn start_watchdog(_dog: &mut Watchdog, _timeout_ms: u32) {}

/// Feeds the watchdog (nothing in QEMU).
pub fn feed_watchdog(_dog: &mut Watchdog) {}

/// No bootloader in QEMU: end the run.
pub fn hand_over_shutdown() {
    finish("shutdown hand-over");
}
