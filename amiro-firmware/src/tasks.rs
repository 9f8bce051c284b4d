//! The bodies of the tasks every board runs the same way: CAN receive, CAN transmit, command
//! handling. The board's RTIC app binds them to its interrupts and priorities (`levels`) and
//! passes its resources in; nothing here knows which board it runs on.
use core::future::Future;

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

/// Handles one command frame the command handler keeps (an actuator command, or a frame no command
/// decodes from), and a stop before it goes on to the admission task: `decoded` is the frame as
/// [`route`] decoded it. Applies it to the board's publisher table (a stop takes effect here), traces
/// the outcome and returns an actuator outcome (motor, LED, …) for the board to apply. It wakes no
/// publisher level: a stop only removes work, and a level that slept until the stopped topic's next
/// release wakes then, finds nothing due and sleeps until its next (the admission task, which applies
/// the stop again, changes nothing more). While the board shuts down nothing may start again: the
/// frame is dropped unseen.
pub fn handle_command<C: Clock>(
    frame: &RxFrame,
    decoded: Result<amiro_can::Command, amiro_can::DecodeError>,
    mut handler: impl rtic_core::Mutex<T = SensorDataHandler>,
) -> Option<(u64, Outcome)> {
    if signals::shutting_down() {
        return None;
    }
    let now = C::now_us();
    let outcome = handler.lock(|h| h.on_command(now, frame.id, decoded));
    trace_outcome(now, frame.id, &outcome);
    match outcome {
        Ok(Outcome::Sensor { .. }) | Err(_) => None,
        Ok(other) => Some((now, other)),
    }
}

/// A command the admission task passed, as of `now`: applied to the publisher table, counted and traced when
/// `first` (a stop the command handler applied, counted and traced already is applied again, neither counted
/// nor traced), and the publisher levels whose schedule changed woken (`wake_levels`: one sender per CAN
/// priority level, urgent first, or a single sender when one publisher task serves every level).
fn handle_command_at(
    now: u64,
    frame: &RxFrame,
    mut handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    wake_levels: &mut [Sender<'static, (), 1>],
    first: bool,
) -> Option<(u64, Outcome)> {
    let outcome = handler.lock(|h| {
        if first {
            h.on_frame(now, frame.id, frame.payload())
        } else {
            h.on_frame_again(now, frame.id, frame.payload())
        }
    });
    if first {
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

/// The busy verdicts' rate: the command handler sets a refused request aside, the admission task takes it.
static BUSY_VERDICTS: crate::admission::BusyWindow = crate::admission::BusyWindow::new();

/// The command handler's part of a sensor or admission-policy command (`docs/analysis.md`, "The
/// admission task"), `sensor` as [`route`] decoded it. A **stop** only removes load: it takes effect here,
/// at the handler's priority and within its deadline ([`handle_command`]), and then goes to the admission task
/// like every such command, which brings its running set up to date in the order heard (and applies the stop
/// again, in case a request for the same topic was still waiting there). When the admission queue is full,
/// one of this board's publish or one-shot requests is refused unseen: counted as
/// [`amiro_can::RefusalReason::Busy`] and set aside beside the queue for the admission task, which answers it
/// with a verdict within its response ([`serve_admission`]); anything else is dropped and counted as a
/// received frame dropped (the queue is bounded, as the receive queue is).
pub fn route_to_admission<C: Clock, const N: usize>(
    frame: &RxFrame,
    sensor: Option<amiro_can::SensorCommand>,
    board: amiro_can::Board,
    handler: impl rtic_core::Mutex<T = SensorDataHandler>,
    requests: &mut Producer<'static, N>,
) {
    let stop = sensor.filter(|c| c.mode == amiro_can::SensorMode::Stop);
    if let Some(command) = stop {
        let _ = handle_command::<C>(frame, Ok(amiro_can::Command::Sensor(command)), handler);
    }
    if requests.push(frame) {
        requests.wake();
        return;
    }
    if stop.is_some() {
        // A stop that finds the queue full has taken effect all the same (and is traced as handled);
        // only the admission task's view keeps the stream, which errs on the safe side (more load).
        return;
    }
    match sensor {
        Some(command) if crate::admission::answers_busy(board, &command) => {
            crate::health::count_admission(true, amiro_can::RefusalReason::Busy);
            // At most one busy verdict per one-shot interval, counted from the last one sent, and one
            // waits at a time: a flood of requests must not turn into a flood of verdicts (each refusal
            // is counted all the same).
            let now_ms = crate::admission::ticks_1024us(C::now_us());
            if BUSY_VERDICTS.set_aside(requests, frame, now_ms) {
                requests.wake();
            }
        }
        _ => crate::health::count_rx_dropped(),
    }
}

/// The admission task's loop (`docs/analysis.md`, "The admission task"), the same on every board:
/// analyses every board once before the first request, then takes the commands the handler queued in
/// the order heard through [`handle_command_admitted`], paced by [`crate::admission::Pacing`]: at most
/// `K` analysed commands in any window, this board's one-shots at least the one-shot interval apart.
/// Each of its waits answers the request the command handler set aside for a busy verdict
/// ([`route_to_admission`]) as soon as it finds one (`AdmissionWaits`).
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
    tx_queue: impl rtic_core::Mutex<T = TxQueue<Q>>,
    tx_interrupt: impl cortex_m::interrupt::InterruptNumber,
    wake_levels: &mut [Sender<'static, (), 1>],
) {
    let mut waits = AdmissionWaits::<C, R, _, _> {
        clock: core::marker::PhantomData,
        board: admission.board(),
        requests,
        tx_queue,
        tx_interrupt,
    };
    // Every board analysed once with nothing running, before the first request (cheap: no stream runs yet, so
    // back to back, as one activation).
    admission.prepare();
    loop {
        let frame = parked(waits.next_command()).await;
        // A request whose period moves the analysis horizon changes every board's key: the other boards are
        // analysed first, one per step, so that the decision analyses only its own board and the bus.
        refresh_steps::<C, N, M, K, Q, R>(admission, pacing, Some(&frame), false, &mut waits).await;
        // The decision may answer with a verdict: it starts once the window since the last verdict (a busy one
        // or a decision's) has ended, so the verdicts are at least the window apart, the rate
        // `can_tx[admit_requests]` is charged at; a burst of accepted requests is still decided back to back.
        // At most one window per command: a busy refusal set aside as it ends is answered after the decision,
        // or counted only if the decision sent a verdict (below).
        if let Some(until) = BUSY_VERDICTS.open_until(C::now_us()) {
            // A plain wait: no busy verdict can be set aside before `until` (the handler sees the same
            // window), and one set aside after it loses to this decision instead of pushing it on for ever.
            parked(C::delay_until_us(until)).await;
        }
        let started = C::now_us();
        handle_command_admitted::<C, N, M, Q>(
            &frame,
            admission,
            &mut handler,
            &mut waits.tx_queue,
            waits.tx_interrupt,
            wake_levels,
        );
        if BUSY_VERDICTS.open_until(C::now_us()).is_some() {
            // The decision sent a verdict (the window was closed when it started): a request the handler set
            // aside meanwhile, before the window began again, is counted, not answered — its verdict would
            // follow this one within the window, as every refusal within it is.
            let _ = waits.requests.take_aside_after(|| ());
        }
        let next = pacing.next_start(
            started,
            C::now_us(),
            admission.analysed(),
            admission.sampled(),
        );
        let delay = core::pin::pin!(C::delay_until_us(next));
        parked(waits.until(delay)).await;
        if admission.stale() {
            // A stream left the running set (a stop, a one-shot): its board's kept analysis is redone now, as a
            // paced step of its own, so that no decision re-analyses more than its own board and the bus.
            refresh_steps::<C, N, M, K, Q, R>(admission, pacing, None, true, &mut waits).await;
        }
    }
}

/// The admission task's refresh steps (`Admission::step`: `prepare_step` for the command `before`, else
/// `refresh_step`): one board analysed per step, each board at most once, paced. With `counted` each step counts in
/// the pacing's window like a decision (the refresh after a stop, as before it was split); the steps preparing a
/// decision wait only the pacing's interval after a note (the decision they prepare is counted).
async fn refresh_steps<
    C: Clock,
    const N: usize,
    const M: usize,
    const K: usize,
    const Q: usize,
    const R: usize,
>(
    admission: &mut crate::admission::Admission<'_, N, M>,
    pacing: &mut crate::admission::Pacing<K>,
    before: Option<&RxFrame>,
    counted: bool,
    waits: &mut AdmissionWaits<
        '_,
        C,
        R,
        impl rtic_core::Mutex<T = TxQueue<Q>>,
        impl cortex_m::interrupt::InterruptNumber,
    >,
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
        let delay = core::pin::pin!(C::delay_until_us(next));
        parked(waits.until(delay)).await;
    }
}

/// The admission task's waits: for the next command the handler queued, or for the pacing's instant. Each
/// answers the request the command handler set aside for a busy verdict (`rx_queue`'s frame set aside, with
/// the queue's one wake) as soon as it finds it: looked for before the wait and again once the waker is stored,
/// as the ring is. So a busy verdict goes out within the admission task's response from the refusal: at once
/// from a wait, or once the step in progress has ended. Answering is an activation of its own (the task is
/// woken again and the wait goes on in its next poll), so an activation queues at most one verdict.
struct AdmissionWaits<'w, C, const R: usize, T, I> {
    clock: core::marker::PhantomData<C>,
    board: amiro_can::Board,
    requests: &'w mut crate::rx_queue::Consumer<'static, R>,
    tx_queue: T,
    tx_interrupt: I,
}

impl<'w, C: Clock, const R: usize, const Q: usize, T, I> AdmissionWaits<'w, C, R, T, I>
where
    T: rtic_core::Mutex<T = TxQueue<Q>>,
    I: cortex_m::interrupt::InterruptNumber,
{
    /// Waits for the next command the handler queued (the task trace's job ends here: `trace_task` is
    /// the task it stopped, resumed around an answer).
    async fn next_command(&mut self) -> RxFrame {
        let task = crate::tracing::suspend(None);
        let frame = core::future::poll_fn(|cx| {
            if self.answer_set_aside(cx, Some(task)) {
                return core::task::Poll::Pending;
            }
            if let core::task::Poll::Ready(frame) = self.requests.poll_recv(cx) {
                return core::task::Poll::Ready(frame);
            }
            // Set aside between the first look and the park.
            self.answer_set_aside(cx, Some(task));
            core::task::Poll::Pending
        })
        .await;
        crate::tracing::resume(task);
        frame
    }

    /// Waits for `delay` (until the pacing's next start). A future of its own ([`Until`]), no `async` body: the
    /// admission check's machine code must reach no panic, and an `async` state machine's poll after its end is
    /// one.
    fn until<'a, F: Future<Output = ()>>(
        &'a mut self,
        delay: core::pin::Pin<&'a mut F>,
    ) -> Until<'a, 'w, C, R, T, I, core::pin::Pin<&'a mut F>> {
        Until { waits: self, delay }
    }

    /// Sends the busy verdict of the request the handler set aside, if there is one (the busy verdicts'
    /// window starts now: `admission::BusyWindow`), and asks for the task to be polled again (the wait
    /// goes on then); `true` if it did.
    fn answer_set_aside(
        &mut self,
        cx: &mut core::task::Context<'_>,
        trace_task: Option<u8>,
    ) -> bool {
        // The QEMU build notes the very reading the window was stamped with.
        #[cfg(feature = "qemu")]
        let mut stamped = 0;
        let Some(frame) = BUSY_VERDICTS.take(self.requests, || {
            let now = C::now_us();
            #[cfg(feature = "qemu")]
            {
                stamped = now;
            }
            crate::admission::ticks_1024us(now)
        }) else {
            return false;
        };
        if let Some(task) = trace_task {
            crate::tracing::resume(task);
        }
        if let Some(verdict) = crate::admission::busy_verdict(self.board, frame.id, frame.payload())
        {
            #[cfg(feature = "qemu")]
            note_verdict(stamped);
            // Not traced as queued frames: no sample was released for them (the bench would take them for
            // late samples of the diagnostics topic). One lock per frame: the transmit task waits for one
            // frame's insertion at most.
            for verdict_frame in verdict {
                let _ = self.tx_queue.lock(|q| enqueue(q, verdict_frame));
            }
            cortex_m::peripheral::NVIC::pend(self.tx_interrupt);
        }
        if trace_task.is_some() {
            let _ = crate::tracing::suspend(None);
        }
        poll_again(cx.waker());
        true
    }
}

/// [`AdmissionWaits`]' wait for the pacing's instant (`delay`), answering a busy verdict meanwhile.
struct Until<'a, 'w, C, const R: usize, T, I, E> {
    waits: &'a mut AdmissionWaits<'w, C, R, T, I>,
    delay: E,
}

impl<C: Clock, const R: usize, const Q: usize, T, I, E> Future for Until<'_, '_, C, R, T, I, E>
where
    T: rtic_core::Mutex<T = TxQueue<Q>>,
    I: cortex_m::interrupt::InterruptNumber,
    E: Future<Output = ()> + Unpin,
{
    type Output = ();

    fn poll(
        self: core::pin::Pin<&mut Self>,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<()> {
        let this = self.get_mut();
        if this.waits.answer_set_aside(cx, None) {
            return core::task::Poll::Pending;
        }
        this.waits.requests.watch(cx.waker());
        if this.waits.answer_set_aside(cx, None) {
            return core::task::Poll::Pending;
        }
        core::pin::Pin::new(&mut this.delay).poll(cx)
    }
}

/// The robot mode's idle mark around the admission task's waits (`qemu::robot::parked`); elsewhere
/// the wait itself.
#[cfg(feature = "qemu")]
use crate::qemu::robot::parked;
#[cfg(not(feature = "qemu"))]
fn parked<F: core::future::Future>(future: F) -> F {
    future
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
        // A stop took effect (and was counted and traced) in the command handler; applied again here,
        // neither counted nor traced, in case a request for the same topic was still waiting in the queue.
        Check::Pass => {
            let first = !crate::admission::is_stop(frame.id, frame.payload());
            return handle_command_at(C::now_us(), frame, handler, wake_levels, first);
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
    // The busy verdicts' window starts again: every verdict the admission task sends, a decision's or a
    // busy one, is at least the window after the one before ([`serve_admission`] waits for it).
    BUSY_VERDICTS.stamp(crate::admission::ticks_1024us(now));
    #[cfg(feature = "qemu")]
    note_verdict(now);
    for verdict_frame in verdict {
        let pushed = tx_queue.lock(|q| enqueue(q, verdict_frame));
        crate::tracing::frame_pushed(now, verdict_frame.id().raw(), &pushed);
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

/// QEMU: when a verdict (a decision's or a busy one) is queued, which the scenarios hold to the spacing the
/// analysis charges (`xtask`'s `scenarios::verdicts_spaced`; the frames' completions bunch on a flooded bus).
#[cfg(feature = "qemu")]
fn note_verdict(now_us: u64) {
    let mut a = [0u8; 10];
    cortex_m::interrupt::free(|_| {
        crate::log!(
            "verdict queued at_us=",
            telemetry::decimal(u32::try_from(now_us).unwrap_or(u32::MAX), &mut a)
        );
    });
}

/// Index of a CAN priority level in per-level arrays (0 = urgent).
pub const fn level_index(p: Priority) -> usize {
    p as usize
}

/// Asks for the task to be polled again (`Waker::wake_by_ref`). Not inlined: its call through the
/// waker's vtable keeps a place of its own in the machine code.
#[inline(never)]
fn poll_again(waker: &core::task::Waker) {
    waker.wake_by_ref();
}

/// The command handler's loop (`docs/analysis.md`, "The command handler"), the same on every board:
/// takes the frames the CAN receive interrupt queued, one at a time, each no earlier than the previous
/// one's start plus `interval_us` (the rate limit the analysis's arrival model of the handler,
/// `sporadic_us`, one command per interval, rests on), and hands each to `handle`, the board's part
/// (routing it with [`route`], [`route_to_admission`], [`handle_command`]). Never returns. One poll is
/// one job ([`crate::command_job::ServeCommands`]).
pub async fn serve_commands<C: Clock, const N: usize>(
    frames: &mut crate::rx_queue::Consumer<'static, N>,
    interval_us: u64,
    handle: impl FnMut(RxFrame) + Unpin,
) {
    let never =
        crate::command_job::ServeCommands::<Traced<C>, N, _>::new(frames, interval_us, handle)
            .await;
    match never {}
}

/// The monotonic `C` and the task trace, as the command handler's job sees them.
struct Traced<C>(core::marker::PhantomData<C>);

impl<C: Clock> crate::command_job::JobClock for Traced<C> {
    #[inline(always)]
    fn now_us() -> u64 {
        C::now_us()
    }

    type Expiry = C::Expiry;

    #[inline(always)]
    fn expiry_at_us(at_us: u64) -> C::Expiry {
        C::expiry_at_us(at_us)
    }

    #[inline(always)]
    fn armed(expiry: &C::Expiry) -> bool {
        C::expiry_armed(expiry)
    }

    #[inline(always)]
    fn suspend(release: Option<(u64, u64)>) -> u8 {
        crate::tracing::suspend(release)
    }

    #[inline(always)]
    fn resume(task: u8) {
        crate::tracing::resume(task);
    }
}
