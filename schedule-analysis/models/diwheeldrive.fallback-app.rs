//! FALLBACK — not firmware, never compiled. The DiWheelDrive RTIC app's task declarations as
//! `diwheeldrive.timing.json` budgets them, for `cargo xtask analyze` to read while
//! `diwheeldrive/src/main.rs` is still a skeleton that declares none of these tasks. As soon as the
//! real app declares them, the analysis reads the real app instead (and this file is only a test
//! fixture of `schedule_analysis::rtic_source`).
//!
//! Only what the analysis reads matters here: the `#[rtic::app]` dispatchers, the `#[shared]` and
//! `#[local]` fields, and each task's binding, priority and resources. Bodies are empty.

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [UART4, UART5, TIM6, TIM7, SDIO, DMA2_CHANNEL1])]
mod app {
    #[shared]
    struct Shared {
        handler: SensorDataHandler,
        tx_queue: TxQueue<16>,
        drive: DriveController,
        imu: Imu,
        compass: Compass,
        floor: Floor,
        alive: Liveness,
    }

    #[local]
    struct Local {
        can_rx: CanRxPort,
        can_tx: CanTxPort,
        rx_frames: Sender<'static, RxFrame, 16>,
        commands: Receiver<'static, RxFrame, 16>,
        wake_levels: [Sender<'static, (), 1>; 4],
        wake_urgent: Wake,
        wake_high: Wake,
        wake_medium: Wake,
        wake_low: Wake,
        motors: Motors,
        encoders: Encoders,
        signals: SystemSignals,
        watchdog: Watchdog,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {}

    #[task(binds = USB_LP_CAN_RX0, priority = 6, local = [can_rx, rx_frames])]
    fn can_rx(cx: can_rx::Context) {}

    #[task(binds = USB_HP_CAN_TX, priority = 6, shared = [tx_queue], local = [can_tx])]
    fn can_tx(cx: can_tx::Context) {}

    #[task(priority = 5, shared = [handler, drive], local = [commands, to_admission])]
    async fn handle_commands(cx: handle_commands::Context) {}

    #[task(priority = 0, shared = [handler, tx_queue], local = [requests, wake_levels, admission])]
    async fn admit_requests(cx: admit_requests::Context) {}

    #[task(priority = 5, shared = [drive, alive], local = [motors, encoders])]
    async fn motor_control(cx: motor_control::Context) {}

    #[task(priority = 4, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_urgent])]
    async fn publish_urgent(cx: publish_urgent::Context) {}

    #[task(priority = 3, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_high])]
    async fn publish_high(cx: publish_high::Context) {}

    #[task(priority = 2, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_medium])]
    async fn publish_medium(cx: publish_medium::Context) {}

    #[task(priority = 1, shared = [handler, tx_queue, drive, imu, compass, floor], local = [wake_low])]
    async fn publish_low(cx: publish_low::Context) {}

    #[task(priority = 1, shared = [alive], local = [watchdog])]
    async fn watchdog(cx: watchdog::Context) {}

    #[task(binds = EXTI9_5, priority = 7, local = [signals])]
    fn shutdown(cx: shutdown::Context) {}

    #[task(priority = 5, shared = [handler, tx_queue])]
    async fn shutdown_sequence(cx: shutdown_sequence::Context) {}

    #[cfg(feature = "qemu")]
    #[task(priority = 7)]
    async fn stimulus(cx: stimulus::Context) {}
}
