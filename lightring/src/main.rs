//! LightRing firmware (STM32F103xE, board revisions 1-0 — one TLC5947, eight RGB LEDs — and 1-2 —
//! three chained TLC5947, 24 RGB LEDs —, one per build: feature `rev-1-0` or `rev-1-2`, the
//! default): the RTIC app.
//!
//! This file is wiring only: resources, bindings, priorities. LED commands from the bus set the
//! colours (`leds`), the latch task shifts them into the TLC5947; everything else (CAN, monotonic,
//! telemetry, fault policy, system signals, AMiRo-BLT hand-over, watchdog, QEMU platform) is the
//! runtime's (`amiro-firmware`). The chip is behind `board` (or `qemu` for the QEMU build).
//!
//! Task priorities (RTIC, higher = more urgent; the constants live in `levels`):
//! `shutdown`, `can_rx`, `can_status` 7 · `can_tx` 6 · `handle_commands`, `shutdown_sequence` 5 ·
//! `latch_leds` 4 · `publish` (diagnostics) 2 · `watchdog` 1 · `admit_requests` 0 (thread mode). `cargo xtask analyze` reads these tasks, priorities and shared resources from this
//! file.
#![no_std]
#![no_main]

mod leds;
mod levels;

#[cfg(not(feature = "qemu"))]
mod board;
#[cfg(not(feature = "qemu"))]
use board as platform;
#[cfg(feature = "qemu")]
mod qemu;
#[cfg(feature = "qemu")]
use qemu as platform;

#[cfg(all(feature = "rev-1-0", feature = "rev-1-2"))]
compile_error!(
    "choose one board revision: `rev-1-0` or `rev-1-2` (with --no-default-features for 1-0)"
);
#[cfg(not(any(feature = "rev-1-0", feature = "rev-1-2")))]
compile_error!("choose a board revision: feature `rev-1-0` or `rev-1-2`");

// The trace numbers of the tasks below (`trace_task::CAN_RX`, …), from this file.
amiro_firmware::trace_tasks!();

// Panic, HardFault and the hand-over blank the LEDs first.
amiro_firmware::safe_state!(platform::leds_dark);

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
pub static AMIRO_DEVICE_ID: u32 = if cfg!(feature = "rev-1-0") {
    0x017F_0100
} else {
    0x017F_0102
};

/// Depth of the queue between the CAN receive interrupt and command handling.
pub const RX_QUEUE_LEN: usize = 16;
/// Depth of the transmit queue (one diagnostics sample is six frames).
pub const TX_QUEUE_LEN: usize = 8;
/// The latch task refreshes the driver at least this often (a latch also follows every command),
/// so a glitch on the shift register never lasts, and the watchdog sees the schedule alive.
pub const REFRESH_PERIOD_US: u64 = 20_000;
/// Watchdog check period; the IWDG resets the board if it is not fed for `WATCHDOG_TIMEOUT_MS`.
pub const WATCHDOG_PERIOD_US: u64 = 100_000;
/// Independent watchdog timeout once the board is up (set at the end of `init`, `tasks::come_up`).
pub const WATCHDOG_TIMEOUT_MS: u32 = 500;
/// The watchdog's timeout during the boot (started first thing in `init`).
pub const BOOT_WATCHDOG_TIMEOUT_MS: u32 = 2_000;
/// The latch task starts at most one latch per this interval: LED commands handled meanwhile are
/// latched together (each LED shows its newest colour), so the latch costs at most about 175 µs
/// per millisecond whatever the bus carries. 1-0: one latch (36 bytes, 175 µs) per 1 ms, a command
/// latched within about 1.7 ms. 1-2: one latch (108 bytes, 530 µs) per 3 ms — the same share of
/// the CPU (1 ms would take 53 % and leave the admission task none: docs/boards.md) —, a command
/// latched within about 4.2 ms.
pub const LATCH_MIN_INTERVAL_US: u64 = if cfg!(feature = "rev-1-2") {
    3_000
} else {
    1_000
};

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

/// The clock every task uses (TIM3 on the robot, SysTick in QEMU).
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
    /// The LED driver's SPI device.
    pub led_spi: platform::LedSpi,
    /// TLC5947 BLANK.
    pub blank: platform::Blank,
    /// System signals.
    pub signals: platform::SystemSignals,
    /// The APB1 timer clock (TIM3's input) of the clock plan in use (unused in QEMU, whose
    /// SysTick runs from the core clock).
    pub timer_hz: u32,
}

// The robot's admission table, generated from the apps and timing files (`board-build.rs`).
amiro_firmware::admission_table!();

/// This board's admission state (`docs/analysis.md`, "The on-chip admission check"): zero bytes
/// at reset, in `.bss`.
type AdmissionState = amiro_firmware::admission::State<
    { admission_table::MAX_TASKS },
    { admission_table::MAX_PUBLISHERS },
>;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [UART4, UART5, TIM6, TIM7, SDIO])]
mod app {
    use crate::leds::{self, LedState};
    use crate::{levels, platform, Clock, ADMISSION_QUEUE_LEN, RX_QUEUE_LEN, TX_QUEUE_LEN};
    use amiro_can::{Board as CanBoard, Command, Priority};
    use amiro_firmware::liveness::Liveness;
    use amiro_firmware::mono::Clock as _;
    use amiro_firmware::signals;
    use amiro_firmware::{bootloader, publisher, tasks};
    use amiro_sensors::drivers::suite::Samples;
    use amiro_sensors::handler::{Outcome, SensorDataHandler};
    use amiro_sensors::tx_queue::TxQueue;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    #[shared]
    struct Shared {
        /// The sensor-data handler: decodes commands, counts rejections.
        handler: SensorDataHandler,
        /// The commanded colours, waiting for the latch.
        leds: LedState,
        /// The latch task's progress mark for the watchdog.
        alive: Liveness,
        /// Frames waiting for a transmit mailboxes (the diagnostics), most urgent ID first.
        tx_queue: TxQueue<TX_QUEUE_LEN>,
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
        wake_latch: Sender<'static, (), 1>,
        wake_publisher: [Sender<'static, (), 1>; 1],
        publisher_wakeups: Receiver<'static, (), 1>,
        latch_wakeups: Receiver<'static, (), 1>,
        ring: leds::Ring<platform::LedSpi>,
        blank: platform::Blank,
        signals: platform::SystemSignals,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        tasks::boot("LightRing", crate::BOOT_WATCHDOG_TIMEOUT_MS);
        let hw = platform::init(cx.device, cx.core);
        let (rx_frames, commands) = amiro_firmware::frame_queue!(RX_QUEUE_LEN);
        let (to_admission, requests) = amiro_firmware::frame_queue!(ADMISSION_QUEUE_LEN);
        let (wake_latch, latch_wakeups) = make_channel!((), 1);
        let (wake_publisher, publisher_wakeups) = make_channel!((), 1);
        let mut signals = hw.signals;

        platform::start_monotonic(levels::MONOTONIC, hw.timer_hz);
        handle_commands::spawn().ok();
        admit_requests::spawn().ok();
        drain_trace::spawn().ok();
        latch_leds::spawn().ok();
        publish::spawn().ok();
        watchdog::spawn().ok();
        #[cfg(feature = "qemu")]
        stimulus::spawn().ok();
        amiro_firmware::log!("LightRing up");

        tasks::come_up(
            &mut signals,
            platform::SHUTDOWN_INTERRUPT,
            crate::WATCHDOG_TIMEOUT_MS,
        );
        (
            Shared {
                handler: SensorDataHandler::new(CanBoard::LightRing),
                leds: LedState::new(),
                alive: Liveness::new(),
                tx_queue: TxQueue::new(),
                can_errors: hw.can_errors,
            },
            Local {
                can_rx: hw.can_rx,
                can_tx: hw.can_tx,
                rx_frames,
                commands,
                to_admission,
                requests,
                wake_latch,
                wake_publisher: [wake_publisher],
                publisher_wakeups,
                latch_wakeups,
                ring: leds::Ring::new(hw.led_spi),
                blank: hw.blank,
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

    /// CAN transmit mailboxes: fill them from the priority queue, most urgent first.
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

    /// Decodes each command and records LED colours (waking the latch); sensor and admission-policy
    /// commands go to `admit_requests` in the order heard; at most one command per
    /// `admission::COMMAND_MIN_INTERVAL_US`.
    #[task(priority = 5, shared = [handler, leds], local = [commands, to_admission, wake_latch])]
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
                        CanBoard::LightRing,
                        &mut cx.shared.handler,
                        cx.local.to_admission,
                    )
                }
                tasks::Route::Handler(decoded) => {
                    if let Some((now, Outcome::Command(Command::Led { command, .. }))) =
                        tasks::handle_command::<Clock>(&frame, decoded, &mut cx.shared.handler)
                    {
                        cx.shared.leds.lock(|l| l.apply(now, &command));
                        let _ = cx.local.wake_latch.try_send(());
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
            wake_publisher,
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
            CanBoard::LightRing,
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
            cx.local.wake_publisher,
        )
        .await;
    }

    /// Shifts the colours into the TLC5947 and latches them: after every change (at most one latch
    /// per `LATCH_MIN_INTERVAL_US`), and at least every `REFRESH_PERIOD_US`. The first latch (all
    /// dark) lifts BLANK.
    #[task(priority = 4, shared = [leds, alive], local = [latch_wakeups, ring, blank])]
    async fn latch_leds(mut cx: latch_leds::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::LATCH_LEDS);
        let mut shown = false;
        let mut next = Clock::now_us();
        loop {
            let started = Clock::now_us();
            let (colours, changed) = cx.shared.leds.lock(|l| l.take());
            if !signals::shutting_down() {
                leds::latch::<Clock, _>(cx.local.ring, &colours, changed);
                if !shown {
                    cx.local.blank.show();
                    shown = true;
                }
            }
            cx.shared.alive.lock(|a| a.mark());
            next += crate::REFRESH_PERIOD_US;
            let _ = Clock::timeout_at_us(next, cx.local.latch_wakeups.recv()).await;
            // At most one latch per LATCH_MIN_INTERVAL_US (the commands meanwhile are coalesced).
            Clock::delay_until_us(started + crate::LATCH_MIN_INTERVAL_US).await;
            next = next.max(Clock::now_us());
        }
    }

    /// LightRing's one publisher: its diagnostics topic, at whichever CAN priority it was asked for.
    #[task(priority = 2, shared = [handler, tx_queue], local = [publisher_wakeups])]
    async fn publish(cx: publish::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::PUBLISH);
        let s = cx.shared;
        // The runtime samples the diagnostics topic itself; LightRing has no other sensor topic.
        let nothing = |_topic, _taken| Samples::new();
        publisher::serve_level::<Clock, TX_QUEUE_LEN>(
            &[
                Priority::Urgent,
                Priority::High,
                Priority::Medium,
                Priority::Low,
            ],
            cx.local.publisher_wakeups,
            s.handler,
            s.tx_queue,
            nothing,
            platform::CAN_TX_INTERRUPT,
        )
        .await;
    }

    /// Feeds the independent watchdog — from the least urgent level, and only while the latch task
    /// keeps running: a fed dog proves the whole schedule is alive.
    #[task(priority = 1, shared = [alive, can_errors])]
    async fn watchdog(cx: watchdog::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::WATCHDOG);
        let s = cx.shared;
        tasks::feed_watchdog::<Clock, _>(crate::WATCHDOG_PERIOD_US, s.alive, s.can_errors).await;
    }

    /// SYS_PD_N fell: another module requests shutdown. LEDs dark first, then hand over.
    #[task(binds = EXTI15_10, priority = 7, local = [signals])]
    fn shutdown(cx: shutdown::Context) {
        let _job = amiro_firmware::tracing::job(crate::trace_task::SHUTDOWN);
        if signals::on_shutdown_edge(cx.local.signals) {
            platform::leds_dark();
            shutdown_sequence::spawn().ok();
        }
    }

    /// Stops everything and calls AMiRo-BLT's shutdown handler.
    #[task(priority = 5, shared = [handler, leds])]
    async fn shutdown_sequence(mut cx: shutdown_sequence::Context) {
        amiro_firmware::tracing::enter(crate::trace_task::SHUTDOWN_SEQUENCE);
        cx.shared.handler.lock(|h| h.stop_all());
        cx.shared.leds.lock(|l| l.clear());
        platform::leds_dark();
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
