//! DiWheelDrive firmware (STM32F103xE, board revisions 1-1 and 1-2, one per build: feature
//! `rev-1-1` or `rev-1-2`, the default): the RTIC app.
//!
//! This file is wiring only: resources, bindings, priorities. Every task body locks what it needs
//! and calls the runtime (`amiro-firmware`) or host-tested code from `amiro-can` and
//! `amiro-sensors`; the chip is behind `board` (or `qemu` for the QEMU build of this same app).
//!
//! Task priorities (RTIC, higher = more urgent; the mapping of CAN priorities lives in `levels`):
//! `shutdown`, `can_rx`, `can_status` 7 · `can_tx` 6 · `handle_commands` 5 · `publish_urgent` 4 ·
//! `publish_high` 3 · `publish_medium` 2 · `publish_low`, `watchdog`, `motor_control`,
//! `shutdown_sequence` 1.
//! `cargo xtask analyze` reads these tasks, priorities and shared resources from this file.
#![no_std]
#![no_main]

mod actuators;
mod levels;
mod sensors;

#[cfg(not(feature = "qemu"))]
mod board;
#[cfg(not(feature = "qemu"))]
mod mono;
#[cfg(not(feature = "qemu"))]
use board as platform;
#[cfg(feature = "qemu")]
mod qemu;
#[cfg(feature = "qemu")]
use qemu as platform;

#[cfg(all(feature = "rev-1-1", feature = "rev-1-2"))]
compile_error!(
    "choose one board revision: `rev-1-1` or `rev-1-2` (with --no-default-features for 1-1)"
);
#[cfg(not(any(feature = "rev-1-1", feature = "rev-1-2")))]
compile_error!("choose a board revision: feature `rev-1-1` or `rev-1-2`");
#[cfg(all(feature = "scripted-i2c", not(feature = "rev-1-1")))]
compile_error!("`scripted-i2c` wires revision 1-1's I2C groups (the compass and the floor) only");

// The trace numbers of the tasks below (`trace_task::CAN_RX`, …), from this file.
amiro_firmware::trace_tasks!();

// Panic, HardFault and the hand-over stop the motors first.
amiro_firmware::safe_state!(platform::emergency_motors_off);

/// The AMiRo-BLT checksum slot (see `amiro_firmware::layout`): erased flash until the bootloader or
/// `cargo xtask flash` writes the word that makes the first vector words sum to zero.
#[cfg(not(any(feature = "bare-chip", feature = "qemu")))]
#[link_section = ".blt_checksum"]
#[used]
static BLT_CHECKSUM: u32 = 0xFFFF_FFFF;

/// The board revision this image is for, as its AMiRo-BLT device id (`shared/reference` §2):
/// `cargo xtask flash` reads this symbol and refuses to write the image into a board whose
/// bootloader answers with another revision's id.
#[no_mangle]
#[used]
pub static AMIRO_DEVICE_ID: u32 = if cfg!(feature = "rev-1-1") {
    0x0100_0101
} else {
    0x0100_0102
};

/// Depth of the queue between the CAN receive interrupt and command handling.
pub const RX_QUEUE_LEN: usize = 16;
/// Depth of the transmit queue (frames waiting for a mailbox).
pub const TX_QUEUE_LEN: usize = 16;
/// Motor control period.
pub const MOTOR_PERIOD_US: u64 = 10_000;
/// Watchdog check period; the IWDG resets the board if it is not fed for `WATCHDOG_TIMEOUT_MS`.
pub const WATCHDOG_PERIOD_US: u64 = 100_000;
/// Independent watchdog timeout once the board is up (set at the end of `init`, `tasks::come_up`).
pub const WATCHDOG_TIMEOUT_MS: u32 = 500;
/// The watchdog's timeout during the boot (started first thing in `init`).
pub const BOOT_WATCHDOG_TIMEOUT_MS: u32 = 2_000;
/// The admission task starts at most `ADMISSION_BURST` analysed commands (publish and one-shot
/// requests of any board) in any window of `ADMISSION_WINDOW_US` (`amiro_firmware::admission::Pacing`):
/// a burst of requests is decided back to back, and the pacing bounds how often the check runs. The
/// analysis needs no rate: it bounds each step from its start (docs/analysis.md, "What the analysis
/// reserves"). Other commands (stops, policies: no analysis) wait
/// `ADMISSION_NOTE_INTERVAL_US`.
pub const ADMISSION_BURST: usize = 5;
/// See `ADMISSION_BURST`.
pub const ADMISSION_WINDOW_US: u64 = 220_000;
/// After a command that ran no analysis (a stop, which the command handler has already applied, or a
/// policy command) the admission task waits this long: their cost stays a small part of its budget.
pub const ADMISSION_NOTE_INTERVAL_US: u64 = 2_500;
/// This board's one-shot samples are at least this far apart (the interval a one-shot is decided at).
pub const ONE_SHOT_INTERVAL_US: u64 = amiro_firmware::admission::ONE_SHOT_INTERVAL_MS as u64 * 1000;
/// Depth of the queue from the command handler to the admission task (a burst waits here; a full
/// queue refuses this board's requests with a verdict, `RefusalReason::Busy`).
pub const ADMISSION_QUEUE_LEN: usize = 8;
/// The admission task's pacing state type.
pub type AdmissionPacing = amiro_firmware::admission::Pacing<ADMISSION_BURST>;

/// The clock every task uses (TIM5 on the robot, SysTick in QEMU).
type Clock = platform::Clock;

/// Everything the platform's `init` hands on to the tasks: the same fields on the chip (`board`)
/// and in QEMU (`qemu`), each platform's types behind the names.
pub struct Board {
    /// CAN transmit mailboxes.
    pub can_tx: platform::CanTxPort,
    /// CAN receive FIFO 0 (command frames only).
    pub can_rx: platform::CanRxPort,
    /// CAN error-state monitor.
    pub can_errors: platform::CanErrors,
    /// The sensors' buses.
    pub sensors: sensors::SensorBuses,
    /// Motor PWM and POWER_EN.
    pub motors: platform::Motors,
    /// Wheel encoders.
    pub encoders: platform::Encoders,
    /// System signals.
    pub signals: platform::SystemSignals,
}

// The robot's admission table, generated from the apps and timing files (`board-build.rs`).
amiro_firmware::admission_table!();

/// This board's admission state (`docs/analysis.md`, "The on-chip admission check"): zero bytes
/// at reset, in `.bss`.
type AdmissionState = amiro_firmware::admission::State<
    { admission_table::MAX_TASKS },
    { admission_table::MAX_PUBLISHERS },
>;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [UART4, UART5, TIM6, TIM7, SDIO, DMA2_CHANNEL1])]
mod app {
    use crate::sensors::{self, Compass, Floor, Imu};
    use crate::{
        actuators, levels, platform, Clock, ADMISSION_QUEUE_LEN, RX_QUEUE_LEN, TX_QUEUE_LEN,
    };
    use amiro_can::MotorCommand;
    use amiro_can::{Board as CanBoard, Command, Priority};
    use amiro_firmware::liveness::Liveness;
    use amiro_firmware::mono::Clock as _;
    use amiro_firmware::signals;
    use amiro_firmware::{bootloader, publisher, tasks};
    use amiro_sensors::handler::{Outcome, SensorDataHandler};
    use amiro_sensors::motion::DriveController;
    use amiro_sensors::tx_queue::TxQueue;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    /// A wake-up for one publisher level: the publisher table changed.
    type Wake = Receiver<'static, (), 1>;

    #[shared]
    struct Shared {
        /// The sensor-data handler: the publisher table and the command counters.
        handler: SensorDataHandler,
        /// Frames waiting for a transmit mailbox, most urgent ID first.
        tx_queue: TxQueue<TX_QUEUE_LEN>,
        /// The last motor command and when it was heard, until motor control takes it: the command
        /// handler's only share of the drive (a copy under the lock, at priority 5).
        motor_command: Option<(MotorCommand, u64)>,
        /// The pose and velocity motor control published after its last step, for the odometry and
        /// velocity topics (a copy under the lock, at priority 4). The controller itself is motor
        /// control's own.
        drive: sensors::DriveSample,
        /// Gyroscope and accelerometer (1-1: on SPI1; 1-2: the BNO055 on I2C1, magnetometer too).
        imu: Imu,
        /// 1-1: the magnetometer on I2C1 (1-2: empty, its magnetometer is in `imu`).
        compass: Compass,
        /// Floor sensors behind the I2C2 multiplexer.
        floor: Floor,
        /// Motor control's progress mark for the watchdog.
        alive: Liveness,
        /// The CAN controller's error state (status interrupt, and polled by the watchdog task).
        can_errors: platform::CanErrors,
    }

    #[local]
    struct Local {
        can_rx: platform::CanRxPort,
        can_tx: platform::CanTxPort,
        rx_frames: amiro_firmware::rx_queue::Producer<'static, RX_QUEUE_LEN>,
        commands: amiro_firmware::rx_queue::Consumer<'static, RX_QUEUE_LEN>,
        to_admission: amiro_firmware::rx_queue::Producer<'static, ADMISSION_QUEUE_LEN>,
        requests: amiro_firmware::rx_queue::Consumer<'static, ADMISSION_QUEUE_LEN>,
        wake_levels: [Sender<'static, (), 1>; 4],
        wake_urgent: Wake,
        wake_high: Wake,
        wake_medium: Wake,
        wake_low: Wake,
        motors: platform::Motors,
        encoders: platform::Encoders,
        /// Wheel speed control, odometry and velocity: motor control's own.
        controller: DriveController,
        signals: platform::SystemSignals,
    }

    #[init(local = [spi_bus: Option<embedded_hal_bus::util::AtomicCell<platform::ImuBus>> = None])]
    fn init(cx: init::Context) -> (Shared, Local) {
        tasks::boot("DiWheelDrive", crate::BOOT_WATCHDOG_TIMEOUT_MS);
        let (hw, _nvic) = platform::init(cx.device, cx.core, cx.local.spi_bus);
        let (rx_frames, commands) = amiro_firmware::frame_queue!(RX_QUEUE_LEN);
        let (to_admission, requests) = amiro_firmware::frame_queue!(ADMISSION_QUEUE_LEN);
        let (wake_u, wake_urgent) = make_channel!((), 1);
        let (wake_h, wake_high) = make_channel!((), 1);
        let (wake_m, wake_medium) = make_channel!((), 1);
        let (wake_l, wake_low) = make_channel!((), 1);

        let (imu, compass, floor) = sensors::groups(hw.sensors);
        let mut signals = hw.signals;
        amiro_firmware::log!(
            "DiWheelDrive: sensors ",
            sensors::summary(&imu, &compass, &floor)
        );

        platform::start_monotonic(levels::MONOTONIC);
        publish_urgent::spawn().ok();
        publish_high::spawn().ok();
        publish_medium::spawn().ok();
        publish_low::spawn().ok();
        handle_commands::spawn().ok();
        admit_requests::spawn().ok();
        drain_trace::spawn().ok();
        motor_control::spawn().ok();
        watchdog::spawn().ok();
        #[cfg(feature = "qemu")]
        stimulus::spawn().ok();

        tasks::come_up(
            &mut signals,
            platform::SHUTDOWN_INTERRUPT,
            crate::WATCHDOG_TIMEOUT_MS,
        );
        (
            Shared {
                handler: SensorDataHandler::new(CanBoard::DiWheelDrive),
                tx_queue: TxQueue::new(),
                motor_command: None,
                drive: sensors::DriveSample::default(),
                imu,
                compass,
                floor,
                alive: Liveness::new(),
                can_errors: hw.can_errors,
            },
            Local {
                can_rx: hw.can_rx,
                can_tx: hw.can_tx,
                rx_frames,
                commands,
                to_admission,
                requests,
                wake_levels: [wake_u, wake_h, wake_m, wake_l],
                wake_urgent,
                wake_high,
                wake_medium,
                wake_low,
                motors: hw.motors,
                encoders: hw.encoders,
                controller: DriveController::new(Default::default()),
                signals,
            },
        )
    }

    /// CAN receive FIFO 0: move frames into the bounded command queue; a full queue drops and counts.
    #[task(binds = USB_LP_CAN_RX0, priority = 7, local = [can_rx, rx_frames])]
    fn can_rx(cx: can_rx::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_RX);
        tasks::receive_frames(cx.local.can_rx, cx.local.rx_frames);
    }

    /// CAN transmit mailboxes: fill them from the priority queue, most urgent first. A frame that a
    /// more urgent one displaces from a mailbox goes back into the queue.
    #[task(binds = USB_HP_CAN_TX, priority = 6, shared = [tx_queue], local = [can_tx])]
    fn can_tx(mut cx: can_tx::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_TX);
        let port = cx.local.can_tx;
        cx.shared
            .tx_queue
            .lock(|queue| tasks::transmit_pending::<Clock, TX_QUEUE_LEN>(port, queue));
    }

    /// CAN status change (error warning, error-passive, bus-off): counted and traced.
    #[task(binds = CAN_SCE, priority = 7, shared = [can_errors])]
    fn can_status(mut cx: can_status::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_STATUS);
        cx.shared.can_errors.lock(tasks::on_can_status::<Clock, _>);
    }

    /// Decodes each command and sets the motor target; sensor and admission-policy commands go to
    /// `admit_requests` in the order heard; at most one command per
    /// `admission::COMMAND_MIN_INTERVAL_US`.
    #[task(priority = 5, shared = [handler, motor_command], local = [commands, to_admission])]
    async fn handle_commands(mut cx: handle_commands::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::HANDLE_COMMANDS);
        tasks::serve_commands::<Clock, RX_QUEUE_LEN>(
            cx.local.commands,
            amiro_firmware::admission::COMMAND_MIN_INTERVAL_US,
            |frame| {
                match tasks::route(&frame) {
                    tasks::Route::Admission(sensor) => {
                        tasks::route_to_admission::<Clock, ADMISSION_QUEUE_LEN>(
                            &frame,
                            sensor,
                            CanBoard::DiWheelDrive,
                            &mut cx.shared.handler,
                            cx.local.to_admission,
                        )
                    }
                    tasks::Route::Handler(decoded) => {
                        if let Some((now, Outcome::Command(Command::Motor { command, .. }))) =
                            tasks::handle_command::<Clock>(&frame, decoded, &mut cx.shared.handler)
                        {
                            // Motor control takes it at its next step (the same step the controller's
                            // target changed at when the handler set it directly).
                            cx.shared
                                .motor_command
                                .lock(|pending| *pending = Some((command, now)));
                        }
                    }
                }
            },
        )
        .await;
    }

    /// Admission control in the background (priority 0, thread mode: it delays no other task,
    /// only its locks can block them briefly): checks each publish and one-shot request against the
    /// robot's schedule before it changes anything (a refused request is answered with a verdict and
    /// changes nothing), then updates the publisher table and wakes the levels whose schedule
    /// changed; at most `ADMISSION_BURST` analysed requests per `ADMISSION_WINDOW_US`.
    #[task(
        priority = 0,
        shared = [handler, tx_queue],
        local = [
            requests,
            wake_levels,
            admission: crate::AdmissionState = crate::AdmissionState::new(),
            pacing: crate::AdmissionPacing = crate::AdmissionPacing::new(
                crate::ADMISSION_WINDOW_US,
                crate::ONE_SHOT_INTERVAL_US,
                crate::ADMISSION_NOTE_INTERVAL_US,
            ),
        ]
    )]
    async fn admit_requests(cx: admit_requests::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::ADMIT_REQUESTS);
        let mut admission = amiro_firmware::admission::Admission::new(
            &crate::admission_table::ROBOT,
            CanBoard::DiWheelDrive,
            cx.local.admission,
        );
        tasks::serve_admission::<
            Clock,
            _,
            _,
            TX_QUEUE_LEN,
            ADMISSION_QUEUE_LEN,
            { crate::ADMISSION_BURST },
        >(
            &mut admission,
            cx.local.pacing,
            cx.local.requests,
            cx.shared.handler,
            cx.shared.tx_queue,
            platform::CAN_TX_INTERRUPT,
            cx.local.wake_levels,
        )
        .await;
    }

    /// The wheel speed controller at 100 Hz, with the dead-man stop. Below the command handler and
    /// the publishers (`levels::MOTOR_CONTROL`: its 10 ms deadline is the longest of the board's
    /// periodic work but the odometry's), with the controller its own: the handler waits only for
    /// the section that takes the command and reads the encoders and the clock (`motor_command`,
    /// at the handler's priority, so that no task below the CAN interrupts runs between the counts
    /// and their time), the publishers only for the copy of the published pose and velocity
    /// (`drive`); no lock holds a control step.
    #[task(priority = 1, shared = [motor_command, drive, alive], local = [motors, encoders, controller])]
    async fn motor_control(mut cx: motor_control::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::MOTOR_CONTROL);
        let controller = cx.local.controller;
        let mut next = Clock::now_us();
        loop {
            next += crate::MOTOR_PERIOD_US;
            Clock::delay_until_us(next).await;
            let encoders = &*cx.local.encoders;
            // A command heard since the last step, with the time it was heard (the dead-man
            // counts from there), and the encoders' counts with their time, read together.
            let (command, left, right, now) = cx.shared.motor_command.lock(|pending| {
                let (left, right) = encoders.counts();
                (pending.take(), left, right, Clock::now_us())
            });
            if let Some((command, heard)) = command {
                controller.set_target(command, heard);
            }
            let output = controller.update(now, left, right);
            actuators::apply_drive(cx.local.motors, now, &output);
            let sample = sensors::DriveSample::of(controller);
            cx.shared.drive.lock(|d| *d = sample);
            cx.shared.alive.lock(|a| a.mark());
        }
    }

    /// Publisher for topics at CAN priority urgent.
    #[task(priority = 4, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_urgent])]
    async fn publish_urgent(cx: publish_urgent::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_URGENT);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        let sampler = sensors::sampler(s.imu, s.compass, s.floor, s.drive);
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Urgent],
            cx.local.wake_urgent,
            s.handler,
            s.tx_queue,
            sampler,
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The compass's and the floor's samples suspend this task on its slots of I2C1 and I2C2.
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level_suspending::<Clock, TX_QUEUE_LEN>(
            &[Priority::Urgent],
            cx.local.wake_urgent,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.imu, s.compass, s.floor, s.drive, platform::ports::<0>()),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority high.
    #[task(priority = 3, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_high])]
    async fn publish_high(cx: publish_high::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_HIGH);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        let sampler = sensors::sampler(s.imu, s.compass, s.floor, s.drive);
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::High],
            cx.local.wake_high,
            s.handler,
            s.tx_queue,
            sampler,
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The compass's and the floor's samples suspend this task on its slots of I2C1 and I2C2.
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level_suspending::<Clock, TX_QUEUE_LEN>(
            &[Priority::High],
            cx.local.wake_high,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.imu, s.compass, s.floor, s.drive, platform::ports::<1>()),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority medium.
    #[task(priority = 2, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_medium])]
    async fn publish_medium(cx: publish_medium::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_MEDIUM);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        let sampler = sensors::sampler(s.imu, s.compass, s.floor, s.drive);
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Medium],
            cx.local.wake_medium,
            s.handler,
            s.tx_queue,
            sampler,
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The compass's and the floor's samples suspend this task on its slots of I2C1 and I2C2.
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level_suspending::<Clock, TX_QUEUE_LEN>(
            &[Priority::Medium],
            cx.local.wake_medium,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.imu, s.compass, s.floor, s.drive, platform::ports::<2>()),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority low.
    #[task(priority = 1, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_low])]
    async fn publish_low(cx: publish_low::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_LOW);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        let sampler = sensors::sampler(s.imu, s.compass, s.floor, s.drive);
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Low],
            cx.local.wake_low,
            s.handler,
            s.tx_queue,
            sampler,
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The compass's and the floor's samples suspend this task on its slots of I2C1 and I2C2.
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level_suspending::<Clock, TX_QUEUE_LEN>(
            &[Priority::Low],
            cx.local.wake_low,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.imu, s.compass, s.floor, s.drive, platform::ports::<3>()),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Feeds the independent watchdog — from the least urgent level, and only while motor control
    /// keeps running: a fed dog proves the whole schedule is alive.
    #[task(priority = 1, shared = [alive, can_errors])]
    async fn watchdog(cx: watchdog::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::WATCHDOG);
        let s = cx.shared;
        tasks::feed_watchdog::<Clock, _>(crate::WATCHDOG_PERIOD_US, s.alive, s.can_errors).await;
    }

    /// SYS_PD_N fell: another module requests shutdown. Motors off first, then hand over.
    #[task(binds = EXTI9_5, priority = 7, local = [signals])]
    fn shutdown(cx: shutdown::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::SHUTDOWN);
        if signals::on_shutdown_edge(cx.local.signals) {
            platform::emergency_motors_off();
            shutdown_sequence::spawn().ok();
        }
    }

    /// Stops every publisher, lets the transmit queue drain, then calls AMiRo-BLT's shutdown handler.
    #[task(priority = 1, shared = [handler, tx_queue])]
    async fn shutdown_sequence(mut cx: shutdown_sequence::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::SHUTDOWN_SEQUENCE);
        let now = Clock::now_us();
        cx.shared.handler.lock(|h| h.stop_all());
        // Motor control runs at this priority (`levels::SHUTDOWN_SEQUENCE`), so it cannot be half-way
        // through re-enabling them; its later steps see the shutdown and keep them off.
        platform::emergency_motors_off();
        actuators::trace_shutdown_stop(now);
        // Give the queued frames up to 10 ms to leave, then hand over regardless.
        tasks::drain_tx_queue::<Clock, TX_QUEUE_LEN>(&mut cx.shared.tx_queue, 10_000).await;
        bootloader::hand_over(bootloader::Callback::HandleShutdownRequest);
    }

    /// QEMU only: replays the stimulus log as if its frames arrived on the bus.
    #[cfg(feature = "qemu")]
    #[task(priority = 7)]
    async fn stimulus(_cx: stimulus::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::STIMULUS);
        amiro_firmware::qemu::replay_stimulus(
            platform::CAN_RX_INTERRUPT,
            platform::SHUTDOWN_INTERRUPT,
            <platform::Clock as amiro_firmware::mono::Clock>::delay_until_us,
        )
        .await;
    }

    /// Writes the trace out (priority 0, thread mode, beside `admit_requests`): each job encodes at
    /// most `tracing::DRAIN_BATCH` of the records the tasks copied into the trace ring and writes
    /// them to the trace channel, and one log line a handler deferred. Not traced itself.
    #[task(priority = 0)]
    async fn drain_trace(_cx: drain_trace::Context) {
        amiro_firmware::tracing::serve_drain().await;
    }
}
