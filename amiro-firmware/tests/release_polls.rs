//! A release of a task that suspends on its scripts takes at most `schedule_analysis::bounds::release_polls` polls,
//! the count `cargo xtask wcet` multiplies one poll's bound by (docs/analysis.md, "A suspending release: the sum of
//! its polls"). Host-built: the firmware's sample of three scripts, the second after a settle
//! (`scripted::sample_on_bus`, its loop around the port's await), through the QEMU build's port
//! (`i2c_sim::SimPort`: a settle and each script one wait on the monotonic), inside a task that parks after the
//! sample as the publisher does; polled on every wake, with the wakes the count allows beside the resumptions (a
//! second wake in the poll that takes each script's end, as the chip's port's timeout and transfer may give; one
//! stale wake of the release point's channel during the release).
use std::cell::{Cell, RefCell};
use std::future::{poll_fn, Future};
use std::pin::pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll, Wake, Waker};

use amiro_can::Topic;
use amiro_firmware::i2c_sim::{SimBus, SimPort};
use amiro_firmware::scripted::{sample_on_bus, BusFault, Deadline, ScriptedGroup, Step};
use amiro_sensors::drivers::scripted::{ScriptBus, ScriptResult};
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::script::{Readings, Script};
use schedule_analysis::bounds::release_polls;

thread_local! {
    static NOW_US: Cell<u64> = const { Cell::new(0) };
}

/// The monotonic as the test moves it.
struct TestClock;

impl Deadline for TestClock {
    fn now_us() -> u64 {
        NOW_US.with(Cell::get)
    }

    fn delay_until_us(at_us: u64) -> impl Future<Output = ()> {
        poll_fn(move |_| {
            if Self::now_us() >= at_us {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
    }

    async fn timeout_at_us<F: Future>(at_us: u64, future: F) -> Option<F::Output> {
        let mut future = pin!(future);
        poll_fn(|cx| match future.as_mut().poll(cx) {
            Poll::Ready(output) => Poll::Ready(Some(output)),
            Poll::Pending if Self::now_us() >= at_us => Poll::Ready(None),
            Poll::Pending => Poll::Pending,
        })
        .await
    }
}

/// Devices that answer every script.
struct Answering;

impl ScriptBus for Answering {
    fn run(&mut self, script: &Script) -> ScriptResult {
        Ok(Readings::for_script(script))
    }
}

/// A group whose sample is three register reads, the second `SETTLE_US` after the first (longer than two of them:
/// a second script not held back by its settle would have ended before it).
#[derive(Default)]
struct ThreeReads {
    resumed: u32,
}

const SETTLE_US: u32 = 1_000;

fn read() -> Script {
    let mut script = Script::new();
    script.write_read(0x55, &[0x0C], 2).unwrap();
    script
}

impl ScriptedGroup for ThreeReads {
    type Job = ();
    const MAX_ROUNDS: usize = 4;

    fn new_job() {}

    fn begin(&mut self, _: &mut (), _: Topic, _: u64) -> Step {
        Step::Run {
            script: read(),
            settle_us: 0,
        }
    }

    fn resume(
        &mut self,
        _: &mut (),
        _: Topic,
        _: u64,
        outcome: Result<Readings, BusFault>,
    ) -> Step {
        assert!(outcome.is_ok());
        self.resumed += 1;
        match self.resumed {
            1 => Step::Run {
                script: read(),
                settle_us: SETTLE_US,
            },
            2 => Step::Run {
                script: read(),
                settle_us: 0,
            },
            _ => Step::Done(Samples::new()),
        }
    }
}

/// An RTIC resource's lock as the test sees it.
struct Lock<T>(RefCell<T>);

impl<T> rtic_core::Mutex for &Lock<T> {
    type T = T;

    fn lock<R>(&mut self, f: impl FnOnce(&mut T) -> R) -> R {
        f(&mut self.0.borrow_mut())
    }
}

/// Wakes not yet answered by a poll.
struct Pending(AtomicUsize);

impl Wake for Pending {
    fn wake(self: Arc<Self>) {
        self.0.fetch_add(1, Ordering::SeqCst);
    }
}

#[test]
fn a_release_of_three_scripts_one_settled_takes_at_most_its_counted_polls() {
    let bus = SimBus::new(Answering);
    let group = Lock(RefCell::new(ThreeReads::default()));
    let mut port = SimPort::<TestClock, _>::new(&bus, 100);
    let wakes = Arc::new(Pending(AtomicUsize::new(0)));
    let waker = Waker::from(wakes.clone());
    let mut cx = Context::from_waker(&waker);
    // The task: the release's sample, then its park at the release point (pending: the next release is not due).
    let done = Cell::new(false);
    let mut task = pin!(async {
        let mut lock = &group;
        let samples = sample_on_bus(&mut lock, &mut port, Topic::MagnetometerX, 0).await;
        assert!(samples.is_empty());
        done.set(true);
        poll_fn(|_| Poll::<()>::Pending).await;
    });
    // Where the sample is after a poll: scripts resumed, and whether it is done.
    let at = || (group.0.borrow().resumed, done.get());
    let mut polls = 0u64;
    // Polls once per wake pending (a wake while pending is merged into one), as the dispatcher does.
    let mut run = || {
        assert!(
            polls == 0 || wakes.0.swap(0, Ordering::SeqCst) > 0,
            "a poll only for a wake"
        );
        polls += 1;
        assert!(task.as_mut().poll(&mut cx).is_pending());
    };
    let wire_us = read()
        .bus_time_ns(amiro_firmware::scripted::SCL_HZ)
        .div_ceil(1000);
    let now = |t: u64| NOW_US.with(|n| n.set(t));
    // 1: the release is taken and its first script submitted.
    run();
    assert_eq!(at(), (0, false));
    // Its end resumes the task (2), which takes the result and starts the settle; the second waker of the
    // script's await fires during that poll (3), which finds the settle pending.
    now(wire_us);
    waker.wake_by_ref();
    run();
    assert_eq!(at(), (1, false));
    waker.wake_by_ref();
    run();
    // The channel's stale waker: a command's send during the release (4), after the second script would have
    // ended had it not waited for its settle.
    now(3 * wire_us);
    assert!(3 * wire_us < u64::from(SETTLE_US));
    waker.wake_by_ref();
    run();
    assert_eq!(at(), (1, false));
    // The settle ends (5): the second script is submitted, the task suspended on it.
    now(wire_us + u64::from(SETTLE_US));
    waker.wake_by_ref();
    run();
    assert_eq!(at(), (1, false), "a settle is a suspension of its own");
    // The second script ends (6) and its second wake (7); the third ends (8): the sample is done and the task
    // parks; its second wake polls the park (9).
    for (end, after) in [(2, (2, false)), (3, (3, true))] {
        now(wire_us * end + u64::from(SETTLE_US));
        waker.wake_by_ref();
        run();
        assert_eq!(at(), after);
        waker.wake_by_ref();
        run();
    }
    assert_eq!((polls, release_polls(&[false, true, false])), (9, 9));
}
