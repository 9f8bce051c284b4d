//! The bodies of the tasks every board runs the same way: CAN receive, CAN transmit, command
//! handling. The board's RTIC app binds them to its interrupts and priorities (`levels`) and
//! passes its resources in; nothing here knows which board it runs on.
use core::sync::atomic::{AtomicU32, Ordering};

use amiro_can::Priority;
use amiro_sensors::handler::{Outcome, Rejection, SensorDataHandler};
use amiro_sensors::trace::{TraceEvent, TraceKind};
use amiro_sensors::tx_queue::{PushOutcome, TxQueue};
use rtic_sync::channel::Sender;

use crate::can::{CanRx, CanTx, RxEvent, RxFrame};
use crate::mono::Clock;
use crate::rx_queue::Producer;
use crate::{signals, telemetry};

/// Frames the board received but could not queue for the command handler (queue full).
pub fn rx_dropped() -> u32 {
    crate::health::rx_dropped()
}

/// Receive-FIFO overrun events: each lost at least one frame (a lower bound on frames lost).
pub fn rx_overruns() -> u32 {
    crate::health::rx_overruns()
}

/// The CAN receive interrupt: moves every frame from the FIFO into the bounded command queue, then
/// wakes the command handler once (not once per frame: `rx_queue`). A full queue drops the frame
/// and counts it ([`rx_dropped`]), an overrun is counted ([`rx_overruns`]); nothing here looks into
/// a frame (the command handler checks it), so each frame costs the same (docs/analysis.md, the
/// bounds files' `per_activation` charge of `can_rx`).
pub fn receive_frames<const N: usize>(port: &mut impl CanRx, queue: &mut Producer<'static, N>) {
    while let Some(event) = port.receive() {
        match event {
            RxEvent::Frame(frame) if queue.push(&frame) => {}
            RxEvent::Frame(_) => crate::health::count_rx_dropped(),
            RxEvent::Overrun => crate::health::count_rx_overrun(),
        }
    }
    // Also after a job that queued nothing (an overrun, or a frame an earlier job took): a
    // spurious wake costs the handler one poll that finds the queue empty, where a flag kept
    // across the drain cost every pass a stack slot and split the drain loop's header in two.
    queue.wake();
}

/// Puts `frame` into the transmit queue: every frame a board sends goes in here (a sample's, a
/// verdict's). The QEMU robot notes when, so its bus report counts the frame's response from here.
pub fn enqueue<const N: usize>(queue: &mut TxQueue<N>, frame: amiro_can::Frame) -> PushOutcome {
    #[cfg(feature = "qemu")]
    crate::qemu::can::released(&frame);
    queue.push(frame)
}

/// The CAN transmit interrupt: frames whose mailbox was aborted for a more urgent one go back into
/// the queue; then the mailboxes are filled from the queue, most urgent first (`can::collect_completions`,
/// `can::fill_mailboxes`).
pub fn transmit_pending<C: Clock, const N: usize>(port: &mut impl CanTx, queue: &mut TxQueue<N>) {
    crate::can::collect_completions(port, queue, |frame| {
        crate::tracing::frame_acked(frame.id().raw())
    });
    crate::can::fill_mailboxes(port, queue, |id| {
        // QEMU prints the frame itself as it enters the (virtual) mailbox: the event would say it
        // twice, at a cost the robot does not have.
        #[cfg(not(feature = "qemu"))]
        crate::tracing::frame_sent(C::now_us(), id);
        #[cfg(feature = "qemu")]
        let _ = id;
    });
}

/// The CAN status-change (error) interrupt, also polled periodically: reads the controller's error
/// state, counts error-passive and bus-off episodes for the diagnostics, and traces a change.
/// Recovery from bus-off is the controller's own (automatic bus-off management).
pub fn on_can_status<C: Clock, R: crate::bxcan::Registers>(
    monitor: &mut crate::bxcan::ErrorMonitor<R>,
) {
    use crate::bxcan::BusState;
    if let Some(change) = monitor.poll() {
        let state = match change.to {
            BusState::Active => 0,
            BusState::Warning => 1,
            BusState::Passive => 2,
            BusState::BusOff => 3,
        };
        crate::tracing::defer_event(&TraceEvent::new(
            C::now_us(),
            TraceKind::CanBusState {
                state,
                tec: change.tec,
                rec: change.rec,
            },
        ));
    }
    crate::health::set_can_errors(
        monitor.passive_episodes(),
        monitor.bus_off_episodes(),
        matches!(monitor.state(), BusState::Passive | BusState::BusOff),
    );
}

/// The start of every board's `init`: the independent watchdog first, at the boot's timeout
/// (nothing in the boot may hang for ever), then the reset cause for the diagnostics, the
/// telemetry channels and the boot report naming `board`.
pub fn boot(board: &str, boot_watchdog_timeout_ms: u32) {
    crate::watchdog::start(boot_watchdog_timeout_ms);
    crate::health::set_reset_cause(crate::chip::take_reset_cause());
    telemetry::init();
    telemetry::boot_report(board);
}

/// The end of every board's `init`: switches the independent watchdog from the boot's timeout to
/// its run-time `watchdog_timeout_ms` (a one-off cost, the register update wait, kept out of the
/// watchdog task's periodic jobs), releases SYS_SYNC_N (wired-OR: the system is up once every
/// module has released it), and, as a shutdown requested before the board was up has no edge to
/// catch, looks at SYS_PD_N's level and pends `shutdown_interrupt` if it is low.
pub fn come_up(
    signals: &mut impl signals::SystemSignals,
    shutdown_interrupt: impl cortex_m::interrupt::InterruptNumber,
    watchdog_timeout_ms: u32,
) {
    crate::watchdog::start(watchdog_timeout_ms);
    signals.release_sync();
    telemetry::init_done();
    if signals.shutdown_requested() {
        cortex_m::peripheral::NVIC::pend(shutdown_interrupt);
    }
}

/// The watchdog task every board runs at its least urgent level (the watchdog runs at its
/// run-time timeout since [`come_up`]): every `period_us` feeds it only if the board's progress
/// mark was set since the last look (a fed dog proves the whole schedule is alive), polls the
/// CAN controller's error state (it recovers from bus-off without an interrupt), and logs a fault
/// the monotonic's timer counted (`mono::Clock::take_fault_report`).
pub async fn feed_watchdog<C: Clock, R: crate::bxcan::Registers>(
    period_us: u64,
    mut alive: impl rtic_core::Mutex<T = crate::liveness::Liveness>,
    mut can_errors: impl rtic_core::Mutex<T = crate::bxcan::ErrorMonitor<R>>,
) -> ! {
    let mut next = C::now_us();
    loop {
        next += period_us;
        C::delay_until_us(next).await;
        if alive.lock(|a| a.take()) {
            crate::watchdog::feed();
        }
        can_errors.lock(on_can_status::<C, R>);
        if let Some(line) = C::take_fault_report() {
            crate::channels::defer_log(line);
        }
    }
}

/// Gives the queued frames up to `timeout_us` to leave (before a hand-over), looking every
/// millisecond.
pub async fn drain_tx_queue<C: Clock, const N: usize>(
    tx_queue: &mut impl rtic_core::Mutex<T = TxQueue<N>>,
    timeout_us: u64,
) {
    let deadline = C::now_us() + timeout_us;
    while tx_queue.lock(|q| q.len()) > 0 && C::now_us() < deadline {
        C::delay_until_us(C::now_us() + 1_000).await;
    }
}

/// Emits the trace event for a command's outcome.
pub fn trace_outcome(now: u64, id: u16, outcome: &Result<Outcome, Rejection>) {
    telemetry::trace(&TraceEvent::new(now, TraceKind::for_command(id, outcome)));
}

/// Handles one command frame: decodes it against the board's publisher table, traces the outcome,
/// wakes the publisher levels whose schedule changed, and returns an actuator outcome (motor, LED,
/// …) for the board to apply. `wake_levels` holds one sender per CAN priority level (urgent first),
/// or a single sender when one publisher task serves every level. While the board shuts down
/// nothing may start again: the frame is dropped unseen.
pub fn handle_command<C: Clock>(
    frame: &RxFrame,
    handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    wake_levels: &mut [Sender<'static, (), 1>],
) -> Option<(u64, Outcome)> {
    if signals::shutting_down() {
        return None;
    }
    handle_command_at(C::now_us(), frame, handler, wake_levels, true)
}

/// [`handle_command`] as of `now`.
fn handle_command_at(
    now: u64,
    frame: &RxFrame,
    mut handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    wake_levels: &mut [Sender<'static, (), 1>],
    traced: bool,
) -> Option<(u64, Outcome)> {
    let outcome = handler.lock(|h| h.on_frame(now, frame.id, frame.payload()));
    if traced {
        trace_outcome(now, frame.id, &outcome);
    }
    match outcome {
        Ok(Outcome::Sensor { wake, .. }) => {
            // Wake the levels whose schedule changed; each re-reads its next due time.
            for level in wake.iter() {
                let index = if wake_levels.len() == 1 {
                    0
                } else {
                    level_index(level)
                };
                if let Some(sender) = wake_levels.get_mut(index) {
                    let _ = sender.try_send(());
                }
            }
            None
        }
        Ok(other) => Some((now, other)),
        Err(_) => None,
    }
}

pub use crate::admission::{route, Route};

/// Whether a command belongs to the admission task ([`route`]).
pub fn for_admission(frame: &RxFrame) -> bool {
    matches!(route(frame), Route::Admission(_))
}

/// When the last busy verdict was sent (ms since boot, 0: never).
static LAST_BUSY_VERDICT_MS: AtomicU32 = AtomicU32::new(0);

/// The command handler's part of a sensor or admission-policy command (`docs/analysis.md`, "The
/// admission task"), `sensor` as [`route`] decoded it. A **stop** only removes load: it takes effect here,
/// at the handler's priority and within its deadline, and then goes to the admission task like every such
/// command, which brings its running set up to date in the order heard (and applies the stop again, in case
/// a request for the same topic was still waiting there). When the admission queue is full, one of this
/// board's publish or one-shot requests is refused unseen:
/// counted as [`amiro_can::RefusalReason::Busy`] and answered with a verdict through the transmit queue;
/// anything else is dropped and counted as a received frame dropped (the queue is bounded, as the receive
/// queue is).
#[allow(clippy::too_many_arguments)]
pub fn route_to_admission<C: Clock, const N: usize, const Q: usize>(
    frame: &RxFrame,
    sensor: Option<amiro_can::SensorCommand>,
    board: amiro_can::Board,
    handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    wake_levels: &mut [Sender<'static, (), 1>],
    requests: &mut Producer<'static, N>,
    mut tx_queue: impl rtic_core::Mutex<T = TxQueue<Q>>,
    tx_interrupt: impl cortex_m::interrupt::InterruptNumber,
) {
    let stop = sensor.is_some_and(|c| c.mode == amiro_can::SensorMode::Stop);
    if stop {
        let _ = handle_command::<C>(frame, handler, wake_levels);
    }
    if requests.push(frame) {
        requests.wake();
        return;
    }
    if stop {
        // A stop that finds the queue full has taken effect all the same (and is traced as handled);
        // only the admission task's view keeps the stream, which errs on the safe side (more load).
        return;
    }
    match sensor.and_then(|command| crate::admission::busy_verdict_for(board, &command)) {
        Some(verdict) => {
            crate::health::count_admission(true, amiro_can::RefusalReason::Busy);
            let now = C::now_us();
            // At most one busy verdict per one-shot interval: a flood of requests must not turn into a
            // flood of verdicts (each refusal is counted all the same).
            let last = LAST_BUSY_VERDICT_MS.load(Ordering::Relaxed);
            let now_ms = crate::admission::ticks_1024us(now);
            // 1024 µs units: 40 of them are at least the one-shot interval (40 ms).
            if last != 0
                && now_ms.wrapping_sub(last) < u32::from(crate::admission::ONE_SHOT_INTERVAL_MS)
            {
                return;
            }
            LAST_BUSY_VERDICT_MS.store(now_ms.max(1), Ordering::Relaxed);
            // Not traced as queued frames: no sample was released for them (the bench would take
            // them for late samples of the diagnostics topic). One lock per frame: the transmit task
            // waits for one frame's insertion at most.
            for verdict_frame in verdict {
                let _ = tx_queue.lock(|q| enqueue(q, verdict_frame));
            }
            cortex_m::peripheral::NVIC::pend(tx_interrupt);
        }
        None => {
            crate::health::count_rx_dropped();
        }
    }
}

/// The admission task's loop (`docs/analysis.md`, "The admission task"), the same on every board:
/// analyses every board once before the first request, then takes the commands the handler queued in
/// the order heard through [`handle_command_admitted`], paced by [`crate::admission::Pacing`]: at most
/// `K` analysed commands in any window, this board's one-shots at least the one-shot interval apart.
#[allow(clippy::too_many_arguments)]
pub async fn serve_admission<
    C: Clock,
    const N: usize,
    const M: usize,
    const Q: usize,
    const R: usize,
    const K: usize,
>(
    admission: &mut crate::admission::Admission<'_, N, M>,
    pacing: &mut crate::admission::Pacing<K>,
    requests: &mut crate::rx_queue::Consumer<'static, R>,
    mut handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    mut tx_queue: impl rtic_core::Mutex<T = TxQueue<Q>>,
    tx_interrupt: impl cortex_m::interrupt::InterruptNumber,
    wake_levels: &mut [Sender<'static, (), 1>],
) {
    // Every board analysed once with nothing running, before the first request (cheap: no stream runs yet, so
    // back to back, as one activation).
    admission.prepare();
    loop {
        let frame = parked(next_command(requests)).await;
        // A request whose period moves the analysis horizon changes every board's key: the other boards are
        // analysed first, one per step, so that the decision analyses only its own board and the bus.
        refresh_steps::<C, N, M, K>(admission, pacing, Some(&frame), false).await;
        let started = C::now_us();
        handle_command_admitted::<C, N, M, Q>(
            &frame,
            admission,
            &mut handler,
            &mut tx_queue,
            tx_interrupt,
            wake_levels,
        );
        let next = pacing.next_start(
            started,
            C::now_us(),
            admission.analysed(),
            admission.sampled(),
        );
        parked(C::delay_until_us(next)).await;
        if admission.stale() {
            // A stream left the running set (a stop, a one-shot): its board's kept analysis is redone now, as a
            // paced step of its own, so that no decision re-analyses more than its own board and the bus.
            refresh_steps::<C, N, M, K>(admission, pacing, None, true).await;
        }
    }
}

/// The admission task's refresh steps (`Admission::step`: `prepare_step` for the command `before`, else
/// `refresh_step`): one board analysed per step, each board at most once, paced. With `counted` each step counts in
/// the pacing's window like a decision (the refresh after a stop, as before it was split); the steps preparing a
/// decision wait only the pacing's interval after a note (the decision they prepare is counted).
async fn refresh_steps<C: Clock, const N: usize, const M: usize, const K: usize>(
    admission: &mut crate::admission::Admission<'_, N, M>,
    pacing: &mut crate::admission::Pacing<K>,
    before: Option<&RxFrame>,
    counted: bool,
) {
    let before = before.map(|frame| (frame.id, frame.payload()));
    let mut from = 0;
    loop {
        let started = C::now_us();
        let Some(board) = admission.step(before, from) else {
            break;
        };
        from = board + 1;
        #[cfg(feature = "qemu")]
        note_refresh::<C, N, M>(admission, started);
        let next = pacing.next_start(started, C::now_us(), counted, false);
        parked(C::delay_until_us(next)).await;
    }
}

/// The robot mode's idle mark around the admission task's waits (`qemu::robot::parked`); elsewhere
/// the wait itself.
#[cfg(feature = "qemu")]
use crate::qemu::robot::parked;
#[cfg(not(feature = "qemu"))]
async fn parked<F: core::future::Future>(future: F) -> F::Output {
    future.await
}

/// QEMU: the cost of a refresh step, as [`note_decision`] logs a decision's.
#[cfg(feature = "qemu")]
fn note_refresh<C: Clock, const N: usize, const M: usize>(
    admission: &crate::admission::Admission<'_, N, M>,
    started: u64,
) {
    let (last, _) = admission.iterations();
    let took = C::now_us().saturating_sub(started);
    let (mut b, mut c) = ([0u8; 10], [0u8; 10]);
    cortex_m::interrupt::free(|_| {
        crate::log!(
            "admission refresh iterations=",
            telemetry::decimal(u32::try_from(last).unwrap_or(u32::MAX), &mut b),
            " virtual_us=",
            telemetry::decimal(u32::try_from(took).unwrap_or(u32::MAX), &mut c)
        );
    });
}

/// Handles one command frame with admission control (`admission`, `docs/analysis.md`): every
/// command heard goes through the board's [`crate::admission::Admission`] first, which keeps the
/// robot's running publishers and decides this board's publish requests. A refused request never
/// reaches the sensor-data handler (the publisher table and the running grids stay as they are),
/// is counted, and is answered with the two verdict frames on the board's diagnostics topic
/// through the transmit queue; accept-and-warn applies it and sends the verdict as a warning.
/// Otherwise as [`handle_command`]. This is the hook every board's `handle_commands` calls.
pub fn handle_command_admitted<C: Clock, const N: usize, const M: usize, const Q: usize>(
    frame: &RxFrame,
    admission: &mut crate::admission::Admission<'_, N, M>,
    handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    mut tx_queue: impl rtic_core::Mutex<T = TxQueue<Q>>,
    tx_interrupt: impl cortex_m::interrupt::InterruptNumber,
    wake_levels: &mut [Sender<'static, (), 1>],
) -> Option<(u64, Outcome)> {
    use crate::admission::Check;
    if signals::shutting_down() {
        return None;
    }
    #[cfg(feature = "qemu")]
    let started = C::now_us();
    let check = admission.on_command(frame.id, frame.payload());
    #[cfg(feature = "qemu")]
    note_decision::<C, N, M>(frame.id, &check, admission, started);
    let (outcome, verdict) = match check {
        // As of now (after the check): a new publisher's grid starts when it can start.
        // A stop took effect (and was traced) in the command handler; applied again here, untraced, in
        // case a request for the same topic was still waiting in the queue.
        Check::Pass => {
            let traced = !crate::admission::is_stop(frame.id, frame.payload());
            return handle_command_at(C::now_us(), frame, handler, wake_levels, traced);
        }
        Check::Refused(frames, reason) => {
            crate::health::count_admission(true, reason);
            (None, frames)
        }
        Check::Warned(frames, reason) => {
            crate::health::count_admission(false, reason);
            (
                handle_command_at(C::now_us(), frame, handler, wake_levels, true),
                frames,
            )
        }
    };
    let now = C::now_us();
    for verdict_frame in verdict {
        let pushed = tx_queue.lock(|q| enqueue(q, verdict_frame));
        for kind in TraceKind::for_push(verdict_frame.id().raw(), &pushed) {
            telemetry::trace(&TraceEvent::new(now, kind));
        }
    }
    cortex_m::peripheral::NVIC::pend(tx_interrupt);
    outcome
}

/// QEMU: the cost of each decision that ran an analysis (the benchmark `cargo xtask scenarios`
/// reads): fixed-point iterations and virtual time (`-icount shift=3`: 8 ns per instruction).
#[cfg(feature = "qemu")]
fn note_decision<C: Clock, const N: usize, const M: usize>(
    id: u16,
    check: &crate::admission::Check,
    admission: &crate::admission::Admission<'_, N, M>,
    started: u64,
) {
    use crate::admission::Check;
    let (last, _) = admission.iterations();
    if !admission.analysed() {
        return;
    }
    let took = C::now_us().saturating_sub(started);
    let what = match check {
        Check::Pass => "pass",
        Check::Refused(..) => "refused",
        Check::Warned(..) => "warned",
    };
    let (mut a, mut b, mut c) = ([0u8; 10], [0u8; 10], [0u8; 10]);
    // The admission task runs at priority 0: one line, written in pieces, must not be split by a
    // more urgent task's output (QEMU only; a semihosting write takes no virtual time).
    cortex_m::interrupt::free(|_| {
        crate::log!(
            "admission id=",
            telemetry::decimal(u32::from(id), &mut a),
            " ",
            what,
            " iterations=",
            telemetry::decimal(u32::try_from(last).unwrap_or(u32::MAX), &mut b),
            " virtual_us=",
            telemetry::decimal(u32::try_from(took).unwrap_or(u32::MAX), &mut c)
        );
    });
}

/// Index of a CAN priority level in per-level arrays (0 = urgent).
pub const fn level_index(p: Priority) -> usize {
    p as usize
}

/// Waits for the next command frame.
pub async fn next_command<const N: usize>(
    commands: &mut crate::rx_queue::Consumer<'static, N>,
) -> RxFrame {
    let task = crate::tracing::suspend(None);
    let frame = commands.recv().await;
    crate::tracing::resume(task);
    frame
}

/// The command handler's one wait (`docs/analysis.md`, "The command handler"): until `not_before_us`
/// (the rate limit: `None` before the first command), then for the next frame the CAN receive
/// interrupt queued: a command is taken no earlier than `not_before_us`, which is what the
/// analysis's arrival model of the handler (`sporadic_us`, one command per interval) rests on.
///
/// One future polled through one function the compiler keeps apart (`NextFrame`'s `poll`), so the
/// handler's loop has one `await` and one place that polls it: a job (from a resume to the next
/// wait that is pending) runs the loop's body once, and the machine-code bound charges one
/// command's handling and two polls of the wait — the one that resumes the job and the next wait's
/// first. Each poll is cheap on every way through it: the rate limit compares the time with its
/// instant before it arms a timer (none when the frame comes late enough), a wait that has armed one
/// ends only once the timer's interrupt has taken it off the timer queue, so that the poll that
/// ends it never arms one (`timer_queue::Expiry`), and nothing is copied but the frame.
pub async fn next_frame_after<C: Clock, const N: usize>(
    frames: &mut crate::rx_queue::Consumer<'static, N>,
    not_before_us: Option<u64>,
) -> RxFrame {
    NextFrame::<C, N> {
        frames,
        not_before_us,
        limit: C::expiry_at_us(not_before_us.unwrap_or(0)),
        stopped: None,
    }
    .await
    .unpack()
}

/// [`next_frame_after`]'s two waits, in one future.
struct NextFrame<'c, C: Clock, const N: usize> {
    frames: &'c mut crate::rx_queue::Consumer<'static, N>,
    /// The rate limit's instant, `None` once it has passed (or without one).
    not_before_us: Option<u64>,
    /// The rate limit's wait (its instant, or 0 without one: never polled then). Once it has
    /// completed it holds no timer slot, so nothing is left for its drop to free.
    limit: C::Expiry,
    /// The task the trace stopped at the wait in progress ([`crate::tracing::suspend`]), `None`
    /// before that wait's first poll.
    stopped: Option<u8>,
}

impl<C: Clock, const N: usize> core::future::Future for NextFrame<'_, C, N> {
    type Output = crate::rx_queue::Packed;

    #[inline(never)]
    fn poll(
        self: core::pin::Pin<&mut Self>,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<crate::rx_queue::Packed> {
        use core::task::Poll;
        let this = self.get_mut();
        if let Some(at_us) = this.not_before_us {
            // The trace's next release: the rate limit's instant. The time is read in every build (the
            // QEMU runs' jobs are held to the release image's bound, which must hold their code).
            let task = *this
                .stopped
                .get_or_insert_with(|| crate::tracing::suspend(Some((at_us, C::now_us()))));
            if core::pin::Pin::new(&mut this.limit).poll(cx).is_pending() {
                return Poll::Pending;
            }
            this.not_before_us = None;
            crate::tracing::resume(task);
            this.stopped = None;
        }
        let task = *this
            .stopped
            .get_or_insert_with(|| crate::tracing::suspend(None));
        match this.frames.poll_recv_packed(cx) {
            Poll::Ready(frame) => {
                crate::tracing::resume(task);
                Poll::Ready(frame)
            }
            Poll::Pending => Poll::Pending,
        }
    }
}
