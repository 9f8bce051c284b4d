//! PowerManagement firmware (STM32F405xG, board revision 1-1/1-2; one image per robot revision): the RTIC app.
//!
//! This file is wiring only: resources, bindings, priorities. The proximity ring and the fuel
//! gauges are sampled through `sensors` (one resource per I2C bus), the power master's decisions
//! are `power`'s, and everything every board does the same way (CAN, monotonic, telemetry, fault
//! policy, system signals, AMiRo-BLT hand-over, watchdog, QEMU platform) is the runtime's
//! (`amiro-firmware`). The chip is behind `board` (or `qemu` for the QEMU build of this same app).
//!
//! Task priorities (RTIC, higher = more urgent; the constants live in `levels`):
//! `shutdown`, `can_rx` 7 · `can_tx` 6 · `handle_commands`, `shutdown_sequence` 5 ·
//! `publish_urgent` 4 · `publish_high` 3 · `publish_medium` 2 ·
//! `publish_low`, `power_monitor`, `watchdog` 1 (with `scripted-i2c` also the bus owners
//! `ring_rear`, `ring_front` 1 and the buses' re-arm tasks 5).
//! `cargo xtask analyze` reads these tasks, priorities and shared resources from this file.
#![no_std]
#![no_main]

mod levels;
mod power;
// With `scripted-i2c` the blocking buses are not used (the scripted ones are).
#[cfg_attr(feature = "scripted-i2c", allow(dead_code))]
mod sensors;

#[cfg(not(feature = "qemu"))]
mod board;
#[cfg(not(feature = "qemu"))]
use board as platform;
#[cfg(feature = "qemu")]
mod qemu;
#[cfg(feature = "qemu")]
use qemu as platform;

// The trace numbers of the tasks below (`trace_task::CAN_RX`, …), from this file.
amiro_firmware::trace_tasks!();

// Panic, HardFault and the hand-over switch the chargers off first.
amiro_firmware::safe_state!(platform::chargers_off);

/// The AMiRo-BLT checksum slot (see `amiro_firmware::layout`): erased flash until the bootloader or
/// `cargo xtask flash` writes the word that makes the first vector words sum to zero.
#[cfg(not(any(feature = "bare-chip", feature = "qemu")))]
#[link_section = ".blt_checksum"]
#[used]
static BLT_CHECKSUM: u32 = 0xFFFF_FFFF;

/// Depth of the queue between the CAN receive interrupt and command handling.
pub const RX_QUEUE_LEN: usize = 16;
/// Depth of the transmit queue (frames waiting for a mailbox): two ring samples.
pub const TX_QUEUE_LEN: usize = 16;
/// The power monitor's period: one transfer to a fuel gauge a job, so a round of both gauges (20
/// transfers, 26 at most) takes about a second, the gauges' own update period (docs/boards.md,
/// "PowerManagement": the decision). The only reads of the gauges after the boot's round.
pub const POWER_MONITOR_PERIOD_US: u64 = 50_000;
/// The power monitor regulates the chargers every this many periods (100 ms).
pub const REGULATE_EVERY: u32 = 2;
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
/// A shutdown this board initiates waits at most this long for another module to take the
/// request (it pulls SYS_SYNC_N low when it does).
pub const OTHERS_ACK_TIMEOUT_US: u64 = 100_000;
/// … and then this long for the modules to stop and hand over to their bootloaders (DiWheelDrive
/// drains its transmit queue for up to 10 ms).
pub const OTHERS_SETTLE_US: u64 = 20_000;
/// Queued frames get up to this long to leave before the hand-over.
pub const TX_DRAIN_US: u64 = 10_000;

/// The clock every task uses (TIM2 on the robot, SysTick in QEMU).
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
    /// I2C1, the rear bus.
    pub rear_i2c: platform::RearI2c,
    /// I2C2, the front bus.
    pub front_i2c: platform::FrontI2c,
    /// Chargers, their status, the plug and VSYS.
    pub charger: platform::Charger,
    /// System signals.
    pub signals: platform::SystemSignals,
    /// The power lines this board keeps on (held so nothing else reconfigures them).
    pub power_lines: platform::PowerLines,
}

// The robot's admission table, generated from the apps and timing files (`board-build.rs`).
amiro_firmware::admission_table!();

/// This board's admission state (`docs/analysis.md`, "The on-chip admission check"): zero bytes
/// at reset, in `.bss`.
type AdmissionState = amiro_firmware::admission::State<
    { admission_table::MAX_TASKS },
    { admission_table::MAX_PUBLISHERS },
>;

#[rtic::app(device = stm32f4xx_hal::pac, dispatchers = [UART4, UART5, TIM7, SDIO, DMA2_STREAM0, DMA2_STREAM1])]
mod app {
    use crate::sensors;
    #[cfg(feature = "scripted-i2c")]
    use crate::sensors::scripted::{ScriptedBus as RearBus, ScriptedBus as FrontBus};
    #[cfg(not(feature = "scripted-i2c"))]
    use crate::sensors::{FrontBus, RearBus};
    use crate::{levels, platform, power, Clock, ADMISSION_QUEUE_LEN, RX_QUEUE_LEN, TX_QUEUE_LEN};
    use amiro_can::{Board as CanBoard, Command, Priority, ShutdownMode};
    use amiro_firmware::liveness::Liveness;
    use amiro_firmware::mono::Clock as _;
    use amiro_firmware::signals::{self, SystemSignals as _};
    use amiro_firmware::{bootloader, publisher, tasks};
    #[cfg(not(feature = "scripted-i2c"))]
    use amiro_sensors::drivers::ring::RingBus;
    use amiro_sensors::handler::{Outcome, SensorDataHandler};
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
        /// I2C1: ring sensors 0, 1, 2, 7 and the rear fuel gauge.
        rear_bus: RearBus,
        /// I2C2: ring sensors 3, 4, 5, 6 and the front fuel gauge.
        front_bus: FrontBus,
        /// The chargers, their status lines, the plug and VSYS.
        charger: platform::Charger,
        /// SYS_SYNC_N and SYS_PD_N.
        signals: platform::SystemSignals,
        /// The power monitor's latest round of both fuel gauges, which the power-status sample
        /// takes (the gauges are read by the power monitor alone).
        batteries: power::LatestRound,
        /// The power monitor's progress mark for the watchdog.
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
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        tasks::boot("PowerManagement", crate::BOOT_WATCHDOG_TIMEOUT_MS);
        let hw = platform::init(cx.device, cx.core);
        let (rx_frames, commands) = amiro_firmware::frame_queue!(RX_QUEUE_LEN);
        let (to_admission, requests) = amiro_firmware::frame_queue!(ADMISSION_QUEUE_LEN);
        let (wake_u, wake_urgent) = make_channel!((), 1);
        let (wake_h, wake_high) = make_channel!((), 1);
        let (wake_m, wake_medium) = make_channel!((), 1);
        let (wake_l, wake_low) = make_channel!((), 1);
        // The boot reads a whole round of both gauges, so a power-status sample taken after it
        // has one to report (the power monitor then makes a transfer a job).
        let mut batteries = power::LatestRound::new();
        #[cfg(not(feature = "scripted-i2c"))]
        let (rear_bus, rear_status) =
            RearBus::new(RingBus::I2c1, hw.rear_i2c, platform::GaugeDelay);
        #[cfg(not(feature = "scripted-i2c"))]
        let (front_bus, front_status) =
            FrontBus::new(RingBus::I2c2, hw.front_i2c, platform::GaugeDelay);
        // The devices set up (and the gauge's status read) by their scripts on the polled master,
        // then each block handed to its engine (QEMU: the simulated buses).
        #[cfg(feature = "scripted-i2c")]
        let (rear_bus, rear_status) = platform::boot_rear(hw.rear_i2c);
        #[cfg(feature = "scripted-i2c")]
        let (front_bus, front_status) = platform::boot_front(hw.front_i2c);
        batteries.record(false, front_status);
        batteries.record(true, rear_status);
        let mut signals = hw.signals;
        // The power lines keep their configuration; nothing in the app touches them again.
        let _power_lines = hw.power_lines;

        platform::start_monotonic(levels::MONOTONIC);
        publish_urgent::spawn().ok();
        publish_high::spawn().ok();
        publish_medium::spawn().ok();
        publish_low::spawn().ok();
        handle_commands::spawn().ok();
        admit_requests::spawn().ok();
        drain_trace::spawn().ok();
        power_monitor::spawn().ok();
        watchdog::spawn().ok();
        #[cfg(feature = "scripted-i2c")]
        rearm_rear::spawn().ok();
        #[cfg(feature = "scripted-i2c")]
        rearm_front::spawn().ok();
        #[cfg(feature = "scripted-i2c")]
        ring_rear::spawn().ok();
        #[cfg(feature = "scripted-i2c")]
        ring_front::spawn().ok();
        #[cfg(feature = "qemu")]
        stimulus::spawn().ok();
        amiro_firmware::log!("PowerManagement up");

        tasks::come_up(
            &mut signals,
            platform::SHUTDOWN_INTERRUPT,
            crate::WATCHDOG_TIMEOUT_MS,
        );
        (
            Shared {
                handler: SensorDataHandler::new(CanBoard::PowerManagement),
                tx_queue: TxQueue::new(),
                rear_bus,
                front_bus,
                charger: hw.charger,
                signals,
                batteries,
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
            },
        )
    }

    /// CAN receive FIFO 0: move frames into the bounded command queue; a full queue drops and counts.
    #[task(binds = CAN1_RX0, priority = 7, local = [can_rx, rx_frames])]
    fn can_rx(cx: can_rx::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_RX);
        tasks::receive_frames(cx.local.can_rx, cx.local.rx_frames);
    }

    /// CAN transmit mailboxes: fill them from the priority queue, most urgent first.
    #[task(binds = CAN1_TX, priority = 6, shared = [tx_queue], local = [can_tx])]
    fn can_tx(mut cx: can_tx::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_TX);
        let port = cx.local.can_tx;
        cx.shared
            .tx_queue
            .lock(|queue| tasks::transmit_pending::<Clock, TX_QUEUE_LEN>(port, queue));
    }

    /// Decodes each command; the operator's shutdown command starts the robot's shutdown; sensor
    /// and admission-policy commands go to `admit_requests` in the order heard. At most one
    /// command per `admission::COMMAND_MIN_INTERVAL_US`.
    #[task(priority = 5, shared = [handler], local = [commands, to_admission])]
    async fn handle_commands(mut cx: handle_commands::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::HANDLE_COMMANDS);
        tasks::serve_commands::<Clock, RX_QUEUE_LEN>(
            cx.local.commands,
            amiro_firmware::admission::COMMAND_MIN_INTERVAL_US,
            |frame| match tasks::route(&frame) {
                tasks::Route::Admission(sensor) => {
                    tasks::route_to_admission::<Clock, ADMISSION_QUEUE_LEN>(
                        &frame,
                        sensor,
                        CanBoard::PowerManagement,
                        &mut cx.shared.handler,
                        cx.local.to_admission,
                    )
                }
                tasks::Route::Handler(decoded) => {
                    if let Some((_, Outcome::Command(Command::Shutdown { mode, .. }))) =
                        tasks::handle_command::<Clock>(&frame, decoded, &mut cx.shared.handler)
                    {
                        shutdown_sequence::spawn(Some(mode)).ok();
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
            CanBoard::PowerManagement,
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

    /// Publisher for topics at CAN priority urgent.
    #[task(priority = 4, shared = [handler, tx_queue, rear_bus, front_bus, charger, batteries], local = [wake_urgent])]
    async fn publish_urgent(cx: publish_urgent::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_URGENT);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Urgent],
            cx.local.wake_urgent,
            s.handler,
            s.tx_queue,
            sensors::sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The ring's sample is the owner tasks' latest reading, no script (`ring_rear`, `ring_front`).
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Urgent],
            cx.local.wake_urgent,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority high.
    #[task(priority = 3, shared = [handler, tx_queue, rear_bus, front_bus, charger, batteries], local = [wake_high])]
    async fn publish_high(cx: publish_high::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_HIGH);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::High],
            cx.local.wake_high,
            s.handler,
            s.tx_queue,
            sensors::sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The ring's sample is the owner tasks' latest reading, no script (`ring_rear`, `ring_front`).
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::High],
            cx.local.wake_high,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority medium.
    #[task(priority = 2, shared = [handler, tx_queue, rear_bus, front_bus, charger, batteries], local = [wake_medium])]
    async fn publish_medium(cx: publish_medium::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_MEDIUM);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Medium],
            cx.local.wake_medium,
            s.handler,
            s.tx_queue,
            sensors::sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The ring's sample is the owner tasks' latest reading, no script (`ring_rear`, `ring_front`).
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Medium],
            cx.local.wake_medium,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Publisher for topics at CAN priority low.
    #[task(priority = 1, shared = [handler, tx_queue, rear_bus, front_bus, charger, batteries], local = [wake_low])]
    async fn publish_low(cx: publish_low::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH_LOW);
        let s = cx.shared;
        #[cfg(not(feature = "scripted-i2c"))]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Low],
            cx.local.wake_low,
            s.handler,
            s.tx_queue,
            sensors::sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
        // The ring's sample is the owner tasks' latest reading, no script (`ring_rear`, `ring_front`).
        #[cfg(feature = "scripted-i2c")]
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[Priority::Low],
            cx.local.wake_low,
            s.handler,
            s.tx_queue,
            sensors::scripted_sampler(s.rear_bus, s.front_bus, s.charger, s.batteries),
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// The power master's periodic duty: the chargers run only while VSYS allows it (every
    /// `REGULATE_EVERY` periods, from the first job on); each job makes one transfer of the
    /// round of both fuel gauges (a `BatteryRound` kept across jobs: the only reads of the gauges
    /// after the boot's, kept for the power-status sample), and a round that ends, or the boot's
    /// round at the first job, is checked for a critically low battery, which shuts the robot
    /// down. Marks the watchdog's progress. With `scripted-i2c` the bus owners (`ring_rear`,
    /// `ring_front`) read the gauges and check each read that ends; this task regulates and checks
    /// the boot's round.
    #[task(priority = 1, shared = [rear_bus, front_bus, charger, batteries, alive])]
    async fn power_monitor(mut cx: power_monitor::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::POWER_MONITOR);
        let mut next = Clock::now_us();
        let mut job = 0u32;
        #[cfg(not(feature = "scripted-i2c"))]
        let mut gauges = sensors::BatteryRound::new();
        // The first wait is for the time the task starts (it ends at once).
        loop {
            Clock::delay_until_us(next).await;
            next += crate::POWER_MONITOR_PERIOD_US;
            if !signals::shutting_down() {
                if job.is_multiple_of(crate::REGULATE_EVERY) {
                    cx.shared.charger.lock(power::regulate_charging);
                }
                #[cfg(not(feature = "scripted-i2c"))]
                let ended = gauges.step(
                    &mut cx.shared.rear_bus,
                    &mut cx.shared.front_bus,
                    &mut cx.shared.batteries,
                );
                // With `scripted-i2c` the bus owners read the gauges and check each read that
                // ends (`ring_rear`, `ring_front`); this job checks the boot's round only.
                #[cfg(feature = "scripted-i2c")]
                let ended = false;
                if ended || job == 0 {
                    let lines = cx.shared.charger.lock(|c| c.lines());
                    if cx.shared.batteries.lock(|b| b.critically_low(&lines)) {
                        amiro_firmware::channels::defer_log(
                            "battery critically low: shutting down",
                        );
                        shutdown_sequence::spawn(Some(power::LOW_BATTERY_MODE)).ok();
                    }
                }
                job = job.wrapping_add(1);
                cx.shared.alive.lock(|a| a.mark());
            }
            // A job that ran past its next release skips it: the task waits before each job.
            next = amiro_firmware::timer_queue::next_release(
                next,
                Clock::now_us(),
                crate::POWER_MONITOR_PERIOD_US,
            );
        }
    }

    /// CAN status change (error warning, error-passive, bus-off): counted and traced.
    #[task(binds = CAN1_SCE, priority = 7, shared = [can_errors])]
    fn can_status(mut cx: can_status::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::CAN_STATUS);
        cx.shared.can_errors.lock(tasks::on_can_status::<Clock, _>);
    }

    /// Feeds the independent watchdog — from the least urgent level, and only while the power
    /// monitor keeps running: a fed dog proves the whole schedule is alive.
    #[task(priority = 1, shared = [alive, can_errors])]
    async fn watchdog(cx: watchdog::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::WATCHDOG);
        let s = cx.shared;
        tasks::feed_watchdog::<Clock, _>(crate::WATCHDOG_PERIOD_US, s.alive, s.can_errors).await;
    }

    /// SYS_PD_N fell: another module requests shutdown (this board's own request is already
    /// marked, so its edge does nothing here).
    #[task(binds = EXTI15_10, priority = 7, shared = [signals])]
    fn shutdown(mut cx: shutdown::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::SHUTDOWN);
        if cx.shared.signals.lock(signals::on_shutdown_edge) {
            platform::chargers_off();
            shutdown_sequence::spawn(None).ok();
        }
    }

    /// The shutdown: initiated here (`Some(mode)`: the operator's command or a low battery) or
    /// requested from outside (`None`). An initiated one drives SYS_PD_N, stops the publishers,
    /// waits (bounded) for the other modules, writes the reason for AMiRo-BLT and calls the
    /// callback of the mode; a requested one stops and calls the shutdown-request handler.
    #[task(priority = 5, shared = [handler, tx_queue, signals])]
    async fn shutdown_sequence(
        mut cx: shutdown_sequence::Context,
        initiated: Option<ShutdownMode>,
    ) {
        amiro_firmware::tracing::enter(crate::trace_task::SHUTDOWN_SEQUENCE);
        let now = Clock::now_us();
        if let Some(mode) = initiated {
            if signals::shutting_down() {
                return;
            }
            // Marked first: our own falling edge on SYS_PD_N is then not taken for a request.
            signals::request_shutdown();
            cx.shared.signals.lock(|s| s.drive_shutdown_request());
            cx.shared.handler.lock(|h| h.stop_all());
            // The lines before the hand-over go to the trace drain: a store, where an RTT write
            // under interrupts off cost the job most of its bound (docs/analysis.md, *Held
            // bounds*, the shutdown sequence). The hand-over's line names the mode.
            amiro_firmware::channels::defer_log("shutdown: SYS_PD_N low, publishers stopped");
            let deadline = now + crate::OTHERS_ACK_TIMEOUT_US;
            while !platform::sync_reads_low() && Clock::now_us() < deadline {
                Clock::delay_until_us(Clock::now_us() + 1_000).await;
            }
            amiro_firmware::channels::defer_log(if platform::sync_reads_low() {
                "shutdown: other modules took the request"
            } else {
                "shutdown: other modules silent (timeout)"
            });
            Clock::delay_until_us(Clock::now_us() + crate::OTHERS_SETTLE_US).await;
            tasks::drain_tx_queue::<Clock, TX_QUEUE_LEN>(
                &mut cx.shared.tx_queue,
                crate::TX_DRAIN_US,
            )
            .await;
            cx.shared.signals.lock(|s| s.pull_sync_low());
            platform::write_shutdown_reason(mode.blt_reason());
            amiro_firmware::log!("shutdown: hand over to AMiRo-BLT (", mode.name(), ")");
            bootloader::hand_over(power::callback(mode));
        } else {
            cx.shared.handler.lock(|h| h.stop_all());
            tasks::drain_tx_queue::<Clock, TX_QUEUE_LEN>(
                &mut cx.shared.tx_queue,
                crate::TX_DRAIN_US,
            )
            .await;
            // Written on the way to the hand-over, which never returns: a deferred line could
            // find the hand-over before the trace drain ran.
            amiro_firmware::log!("shutdown requested from outside: publishers stopped");
            bootloader::hand_over(bootloader::Callback::HandleShutdownRequest);
        }
    }

    /// With `scripted-i2c`: I2C1's re-arm task, which brings back a repeated START the rear gauge
    /// stretched past the engine's condition wait (docs/i2c.md, "A stretched repeated START").
    #[cfg(feature = "scripted-i2c")]
    #[task(priority = 5)]
    async fn rearm_rear(_cx: rearm_rear::Context) {
        platform::rearm_rear().await;
    }

    /// With `scripted-i2c`: I2C2's re-arm task (the front gauge).
    #[cfg(feature = "scripted-i2c")]
    #[task(priority = 5)]
    async fn rearm_front(_cx: rearm_front::Context) {
        platform::rearm_front().await;
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

    /// With `scripted-i2c`: I2C1's owner (docs/i2c.md, "PowerManagement with `scripted-i2c`"):
    /// every 62.5 ms its ring sensors read (one script of a missing sensor's set-up first, at
    /// most) and one transfer of the rear gauge's read, its scripts on its own slot of I2C1; the
    /// publishers take its latest reading, the power status the gauges' latest reads. At the lowest level: its
    /// CPU delays no publisher, and the readings' age bound is its period and response.
    #[cfg(feature = "scripted-i2c")]
    #[task(priority = 1, shared = [rear_bus, charger, batteries])]
    async fn ring_rear(cx: ring_rear::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::RING_REAR);
        let s = cx.shared;
        let (port, _) = platform::ports::<{ sensors::scripted::OWNER_CLIENT }>();
        sensors::scripted::serve_owner(port, s.rear_bus, s.charger, s.batteries, critically_low)
            .await;
    }

    /// With `scripted-i2c`: I2C2's owner, as [`ring_rear`] (its ring sensors and the front gauge).
    #[cfg(feature = "scripted-i2c")]
    #[task(priority = 1, shared = [front_bus, charger, batteries])]
    async fn ring_front(cx: ring_front::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::RING_FRONT);
        let s = cx.shared;
        let (_, port) = platform::ports::<{ sensors::scripted::OWNER_CLIENT }>();
        sensors::scripted::serve_owner(port, s.front_bus, s.charger, s.batteries, critically_low)
            .await;
    }

    /// With `scripted-i2c`: a bus owner found a battery critically low after its gauge's read.
    #[cfg(feature = "scripted-i2c")]
    fn critically_low() {
        amiro_firmware::channels::defer_log("battery critically low: shutting down");
        shutdown_sequence::spawn(Some(power::LOW_BATTERY_MODE)).ok();
    }
}

// Below the app, so that the app's lines (the bounds files name some) stay where they were.
#[cfg(all(feature = "rev-1-1", feature = "rev-1-2"))]
compile_error!(
    "choose one robot revision: `rev-1-1` or `rev-1-2` (with --no-default-features for 1-1)"
);
#[cfg(not(any(feature = "rev-1-1", feature = "rev-1-2")))]
compile_error!("choose a robot revision: feature `rev-1-1` or `rev-1-2`");

/// The robot revision this image is for, as its AMiRo-BLT device id (`shared/reference` §2). The
/// board's revisions 1-1 and 1-2 differ only in PA1, which the firmware leaves alone, so the images
/// differ only in the admission table: the robot's (docs/boards.md, "Revisions"). `cargo xtask
/// flash` reads this symbol and refuses to write the image into a board whose bootloader answers
/// with another revision's id.
#[no_mangle]
#[used]
pub static AMIRO_DEVICE_ID: u32 = if cfg!(feature = "rev-1-1") {
    0x0101_0101
} else {
    0x0101_0102
};
