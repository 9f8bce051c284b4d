//! With `scripted-i2c`: PowerManagement's two buses sampled by script (docs/i2c.md,
//! "PowerManagement with `scripted-i2c`"). Each bus has one owner task ([`serve_owner`], the app's
//! `ring_rear` and `ring_front`, every [`OWNER_PERIOD_US`]): its job reads the bus's ring sensors
//! (a missing sensor's set-up first, at most one) and makes one transfer of the bus's gauge read,
//! each a job of I2C scripts that the bus runs while the owner suspends on its client slot
//! (`ScriptPort`). The bus's state (which sensors answer, their missed samples, the gauge's
//! faults, and the latest ring reading the publishers take) is locked only to plan a job and to
//! take its outcome, never across the bus. The two owners suspend on independent blocks, so
//! neither waits for the other's bus.
//!
//! The scripts are amiro-sensors' (`drivers::scripted`: `RingRead`, `SensorSetUp`, the gauge's
//! `StatusRead` a transfer a script after its 66 µs of bus-free time, `GaugeIdentity`), built from
//! the drivers' register maps; the bus's policy is the blocking [`super::SensorBus`]'s: at most one
//! missing sensor set up again per job and bus, each after [`RETRY_US`]; a sensor that does not
//! answer yields no reading (no frame) and is counted; the health report is made under the lock as
//! the job takes its outcome, and the log lines are deferred after it ([`note`]).
use amiro_firmware::i2c_engine::FLAG_ALLOWANCE_US;
use amiro_firmware::scripted::{script_result, ScriptPort};
use amiro_sensors::drivers::bq27500::{BatteryStatus, StatusRead};
use amiro_sensors::drivers::pca9544a::{self, Channel};
use amiro_sensors::drivers::proximity::ProximityCalibration;
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::scripted::{
    gauge_outcome, gauge_script, GaugeIdentity, RingRead, ScriptBus, SensorSetUp, GAUGE_SETTLE_US,
    RING_BUS_SENSORS,
};
use amiro_sensors::drivers::vcnl4020::{self, Config};
use embedded_hal::delay::DelayNs;

use super::{bus_name, RingSample, RingSlot, PER_BUS, RETRY_US};
use crate::power::LatestRound;
use amiro_sensors::drivers::ring::RING_SENSORS;

/// The owner tasks' period, µs: the ring's fastest stated publication (the thesis demo's
/// 62.5 ms). The ring's sample a publisher takes is at most this plus the owner's response old
/// (docs/sensors.md, "PowerManagement's ring with `scripted-i2c`").
pub const OWNER_PERIOD_US: u64 = 62_500;

/// Scripts a sensor's set-up takes: its identity, then each set-up register written and read
/// back.
const SET_UP_SCRIPTS: usize = 1 + vcnl4020::set_up_writes(&Config::AMIRO).len();

const _: () = assert!(PER_BUS == RING_BUS_SENSORS);

/// Clients of each bus, by slot: its owner task alone (the publishers and the power monitor take
/// the owners' latest readings and run no script).
pub const CLIENTS: usize = 1;
/// The owner's slot.
pub const OWNER_CLIENT: usize = 0;

/// The longest deadline of the buses' scripts (`amiro_firmware::i2c_engine::deadline_us`), µs: a
/// ring read's 680 µs on the wire and 44 events at `FLAG_ALLOWANCE_US` (a set-up script's is
/// 3 420 µs, a gauge transfer's 1 520).
const LONGEST_DEADLINE_US: u32 = 680 + 44 * FLAG_ALLOWANCE_US;
/// After a script's deadline until its bus is free: the bus watch's response and the bus clear
/// (`i2c::BusClear`, 140 µs of stated waits and its code), µs: an estimate.
const RECOVERY_US: u32 = 300;

/// A script's timeout beyond its time on the wire at 400 kHz (`scripted::script_timeout_us`), µs:
/// the other clients' scripts it may wait behind (none since each bus has its owner alone,
/// 2026-12-06; four before), each ended by the bus's watch at its
/// deadline at the latest and the bus then cleared, and its own script's flags at
/// `FLAG_ALLOWANCE_US` and its clear. The client's timeout is thus the backstop behind the watch
/// (`amiro_firmware::i2c_bus::I2cBus::serve_watch`, which ends a script at its deadline with
/// `Failure::Stretched` and brings a stretched repeated START back), never before it; before
/// deadlines (2026-12-05) it was 4 × 680 + 4 000 µs, which ended a ring read stretched past
/// 7.4 ms before its 9.48 ms deadline. A stated allowance, not the analysis's bus response.
pub const TIMEOUT_ALLOWANCE_US: u32 = (CLIENTS as u32 - 1) * (LONGEST_DEADLINE_US + RECOVERY_US)
    + 44 * FLAG_ALLOWANCE_US
    + RECOVERY_US;

/// One bus's ring sensors and gauge as the scripted path keeps them: no bus inside (the job's
/// owner runs the scripts on its port).
pub struct ScriptedBus {
    bus: RingBus,
    slots: [RingSlot; PER_BUS],
    gauge_faults: u32,
    /// The owner's latest ring reading by slot (mm; `None`: no reading in its latest job, or no
    /// job yet).
    latest: [Option<u16>; PER_BUS],
    /// The owner has ended a ring read: from then on a sample without a slot's reading counts.
    read_once: bool,
}

impl ScriptedBus {
    /// The sensors of `bus` set up by their scripts on `boot` (the polled master before the
    /// engine takes the block, or the simulated devices), the gauge's identity checked (logged)
    /// and its status read (the boot's round: `None`, counted, when it did not answer), each
    /// gauge script after its bus-free time on `delay`.
    pub fn boot(
        bus: RingBus,
        boot: &mut impl ScriptBus,
        delay: &mut impl DelayNs,
    ) -> (Self, Option<BatteryStatus>) {
        let mut slots = [RingSlot {
            index: 0,
            channel: Channel::Ch0,
            ready: false,
            last_try_us: 0,
            missed: 0,
        }; PER_BUS];
        let mut n = 0;
        for (index, &(on, channel)) in (0u8..).zip(WIRING.iter()) {
            if on == bus {
                if let Some(slot) = slots.get_mut(n) {
                    slot.index = index;
                    slot.channel = channel;
                }
                n += 1;
            }
        }
        let mut this = Self {
            bus,
            slots,
            gauge_faults: 0,
            latest: [None; PER_BUS],
            read_once: false,
        };
        for k in 0..PER_BUS {
            if let Some(mut set_up) = this.begin_set_up(k, 0) {
                let mut ready = false;
                for _ in 0..SET_UP_SCRIPTS {
                    let result = match set_up.script() {
                        Ok(script) => boot.run(&script),
                        Err(_) => break,
                    };
                    if let Some(outcome) = set_up.complete(&result) {
                        ready = outcome.is_ok();
                        break;
                    }
                }
                for noted in this.end_set_up(k, 0, ready).into_iter().flatten() {
                    boot_note(noted);
                }
            }
        }
        let mut identity = GaugeIdentity::new();
        let mut checked = false;
        while let Some(transfer) = identity.next_transfer() {
            delay.delay_us(GAUGE_SETTLE_US);
            let outcome = match gauge_script(transfer) {
                Ok(script) => gauge_outcome(transfer, &boot.run(&script)),
                Err(error) => Err(error),
            };
            if let Some(result) = identity.complete(outcome) {
                checked = result.is_ok();
                break;
            }
        }
        if !checked {
            amiro_firmware::log!(
                bus_name(bus),
                ": fuel gauge did not answer its identity check"
            );
        }
        let mut read = StatusRead::new();
        let mut status = None;
        for _ in 0..StatusRead::MAX_TRANSFERS {
            let Some(transfer) = read.next_transfer() else {
                break;
            };
            delay.delay_us(GAUGE_SETTLE_US);
            let outcome = match gauge_script(transfer) {
                Ok(script) => gauge_outcome(transfer, &boot.run(&script)),
                Err(error) => Err(error),
            };
            if let Some(ended) = read.complete(outcome) {
                status = ended.ok();
                break;
            }
        }
        let status = this.end_gauge_read(status);
        (this, status)
    }

    /// Slot `k`'s set-up begun at `now_us` (its `last_try_us`, so no other job takes it up too).
    fn begin_set_up(&mut self, k: usize, now_us: u64) -> Option<SensorSetUp> {
        let slot = self.slots.get_mut(k)?;
        slot.last_try_us = now_us;
        Some(SensorSetUp::new(
            pca9544a::AMIRO_ADDRESS,
            slot.channel,
            Config::AMIRO,
        ))
    }

    /// Slot `k`'s set-up ended (`ready`: it answers now): the lines the blocking path logs, for
    /// the caller to log once the bus's lock is released ([`note`], [`boot_note`]).
    fn end_set_up(&mut self, k: usize, now_us: u64, ready: bool) -> [Option<Noted>; 2] {
        let Some(slot) = self.slots.get_mut(k) else {
            return [None; 2];
        };
        let still =
            (!ready && now_us > 0).then_some(Noted(slot.index, Note::StillMissing, slot.missed));
        let changed = (ready != slot.ready).then_some(Noted(
            slot.index,
            if ready { Note::Ready } else { Note::Missing },
            0,
        ));
        slot.ready = ready;
        [still, changed]
    }

    /// The first missing sensor whose retry passed, its set-up begun: one a job.
    fn due_set_up(&mut self, now_us: u64) -> Option<(usize, SensorSetUp)> {
        let due = |s: &RingSlot| !s.ready && now_us.saturating_sub(s.last_try_us) >= RETRY_US;
        let k = self.slots.iter().position(due)?;
        self.begin_set_up(k, now_us).map(|set_up| (k, set_up))
    }

    /// The read of the sensors that answer now, and which slot each of its places is.
    fn ring_read(&self) -> (RingRead, [Option<usize>; PER_BUS]) {
        let mut channels = [Channel::Ch0; PER_BUS];
        let mut places = [None; PER_BUS];
        let mut n = 0;
        for (k, slot) in self.slots.iter().enumerate() {
            if slot.ready {
                if let (Some(c), Some(p)) = (channels.get_mut(n), places.get_mut(n)) {
                    *c = slot.channel;
                    *p = Some(k);
                }
                n += 1;
            }
        }
        let read = RingRead::new(pca9544a::AMIRO_ADDRESS, channels.get(..n).unwrap_or(&[]));
        (read, places)
    }

    /// A ring read's millimetres ([`ring_mm`]) as the bus's latest reading; every slot without one
    /// missed. The sensors that stopped answering, for the caller to log ([`note`]).
    fn end_ring_read(
        &mut self,
        now_us: u64,
        mm: [Option<u16>; PER_BUS],
    ) -> [Option<Noted>; PER_BUS] {
        let mut lost = [None; PER_BUS];
        for ((k, mm), lost) in mm.into_iter().enumerate().zip(lost.iter_mut()) {
            if let Some(latest) = self.latest.get_mut(k) {
                *latest = mm;
            }
            if mm.is_none() {
                *lost = self.lost(k, now_us);
            }
        }
        self.read_once = true;
        self.report();
        lost
    }

    /// The owner's latest reading into `sample` (by sensor index): the publishers' ring sample. A
    /// slot without a reading is counted missed here, once a sample (a publication without its
    /// frame, as the blocking path counts it), once the owner has ended a read.
    pub fn latest_into(&mut self, sample: &mut RingSample) {
        let mut counted = false;
        for (slot, mm) in self.slots.iter_mut().zip(self.latest) {
            match (mm, sample.get_mut(usize::from(slot.index))) {
                (Some(mm), Some(out)) => *out = Some(mm),
                _ if self.read_once => {
                    slot.missed = slot.missed.saturating_add(1);
                    counted = true;
                }
                _ => {}
            }
        }
        if counted {
            self.report();
        }
    }

    /// Whether this is I2C1 (the rear bus).
    fn is_rear(&self) -> bool {
        self.bus == RingBus::I2c1
    }

    /// Slot `k` gave no reading in a ring read: a sensor that answered until now is out of
    /// service (logged), its set-up retried after [`RETRY_US`]. Counted where a sample goes
    /// without its frame ([`Self::latest_into`]).
    fn lost(&mut self, k: usize, now_us: u64) -> Option<Noted> {
        let slot = self.slots.get_mut(k)?;
        if !slot.ready {
            return None;
        }
        slot.ready = false;
        slot.last_try_us = now_us;
        Some(Noted(slot.index, Note::Stopped, 0))
    }

    /// A gauge read's end: a failed one counted, and the bus's faults reported.
    fn end_gauge_read(&mut self, status: Option<BatteryStatus>) -> Option<BatteryStatus> {
        if status.is_none() {
            self.gauge_faults = self.gauge_faults.saturating_add(1);
        }
        self.report();
        status
    }

    /// This bus's faults (missed ring samples and failed gauge reads) and whether a sensor is out
    /// of service now, into the board's diagnostics (one sensor group per bus).
    fn report(&self) {
        let missed = self
            .slots
            .iter()
            .fold(0u32, |sum, s| sum.saturating_add(s.missed));
        amiro_firmware::health::report_sensor_group(
            self.bus as usize,
            missed.saturating_add(self.gauge_faults),
            self.slots.iter().any(|s| !s.ready),
        );
    }
}

/// A missing sensor's set-up under way, one of its scripts a job ([`serve_owner`]): its slot,
/// the set-up, and the scripts it has run.
pub struct StepwiseSetUp {
    slot: usize,
    set_up: SensorSetUp,
    steps: usize,
}

/// A bus's owner task's loop (the app's `ring_rear`, `ring_front`): a job every
/// [`OWNER_PERIOD_US`] from the task's start, none while the robot shuts down; after a gauge read
/// that ends, both gauges' latest statuses are checked against the charge lines read then, and a
/// critically low battery calls `critically_low` (the app's shutdown). A job that ran past its
/// next release skips it.
///
/// A job: one script of a missing sensor's set-up (the one under way, or the first missing
/// sensor's whose [`RETRY_US`] passed, begun now), then the read of the sensors that answer into
/// the bus's latest reading, then one transfer of the gauge's status read (a read that ends puts
/// its status into `latest` and restarts; a read takes at most [`StatusRead::MAX_TRANSFERS`]
/// jobs), each script with the bus's lock released. A set-up thus takes [`SET_UP_SCRIPTS`] jobs
/// (six, 375 ms), so that a job carries one set-up script at most (docs/i2c.md, "The owner
/// tasks": six in one job put more than the period on the bus).
///
/// **Its stretches** (docs/i2c.md, "Session 24 (continued)"): the job is written as short
/// stretches, each ended by an await that returns pending on its first poll: after each script's
/// result a [`yield_now`] (a script found ready at once, refused at its submission or ended while
/// the owner was pre-empted, does not run the next stretch in the same poll), after the read's
/// last script, after the counts' conversion, and at the end of each pass of the loop (a release
/// point found ready at once is the next poll's). So one poll of the task runs one stretch: a
/// script's result decoded and the next submitted, or the counts converted and stored, or the
/// gauge's status taken and checked. No log line is made in a poll: the sensors' changes are
/// deferred ([`note`]).
pub async fn serve_owner<P: ScriptPort>(
    mut port: P,
    mut bus: impl rtic::Mutex<T = ScriptedBus>,
    mut charger: impl rtic::Mutex<T = crate::platform::Charger>,
    mut latest: impl rtic::Mutex<T = LatestRound>,
    critically_low: impl Fn(),
) -> ! {
    use amiro_firmware::mono::Clock as _;
    use amiro_firmware::timer_queue::yield_now;
    let mut read_gauge = StatusRead::new();
    let mut set_up: Option<StepwiseSetUp> = None;
    let mut next = crate::Clock::now_us();
    loop {
        crate::Clock::delay_until_us(next).await;
        next += OWNER_PERIOD_US;
        if !amiro_firmware::signals::shutting_down() {
            let now_us = crate::Clock::now_us();
            // A missing sensor's set-up: one script a job.
            if set_up.is_none() {
                set_up = bus
                    .lock(|b| b.due_set_up(now_us))
                    .map(|(slot, set_up)| StepwiseSetUp {
                        slot,
                        set_up,
                        steps: 0,
                    });
            }
            let mut ended = None;
            if let Some(step) = set_up.as_mut() {
                step.steps += 1;
                let outcome = match step.set_up.script() {
                    Ok(script) => {
                        let outcome = port.run(script, 0).await;
                        yield_now().await;
                        step.set_up
                            .complete(&script_result(outcome))
                            .map(|done| done.is_ok())
                    }
                    Err(_) => Some(false),
                };
                // A set-up that has not ended within its scripts has failed.
                ended = match outcome {
                    None if step.steps >= SET_UP_SCRIPTS => Some((step.slot, false)),
                    None => None,
                    Some(ready) => Some((step.slot, ready)),
                };
            }
            if ended.is_some() {
                set_up = None;
            }
            // The read of the sensors that answer.
            let (mut read, places, noted) = bus.lock(|b| {
                let noted = match ended {
                    Some((k, ready)) => b.end_set_up(k, now_us, ready),
                    None => [None; 2],
                };
                let (read, places) = b.ring_read();
                (read, places, noted)
            });
            let [still, changed] = noted;
            note(still);
            note(changed);
            for _ in 0..RingRead::MAX_SCRIPTS {
                let script = match read.script() {
                    Some(Ok(script)) => script,
                    // A script the build refuses: the sensors still to read give no count this
                    // time.
                    Some(Err(_)) | None => break,
                };
                let outcome = port.run(script, 0).await;
                yield_now().await;
                read.complete(&script_result(outcome));
            }
            yield_now().await;
            // The counts converted outside the bus's lock, then stored under it.
            let mm = ring_mm(&read, places);
            let lost = bus.lock(|b| b.end_ring_read(now_us, mm));
            // Straight-line, no loop over the lines (PER_BUS = 4).
            let [a, b, c, d] = lost;
            note(a);
            note(b);
            note(c);
            note(d);
            yield_now().await;
            // One transfer of the gauge's status read.
            let status = match read_gauge.next_transfer() {
                Some(transfer) => {
                    let outcome = match gauge_script(transfer) {
                        Ok(script) => {
                            let outcome = port.run(script, GAUGE_SETTLE_US).await;
                            yield_now().await;
                            gauge_outcome(transfer, &script_result(outcome))
                        }
                        Err(error) => Err(error),
                    };
                    read_gauge.complete(outcome).map(Result::ok)
                }
                // A read past its end (a read restarts each time it ends): no status.
                None => Some(None),
            };
            if let Some(status) = status {
                let status = bus.lock(|b| b.end_gauge_read(status));
                read_gauge.restart();
                let rear = bus.lock(|b| b.is_rear());
                latest.lock(|l| l.record(rear, status));
                let lines = charger.lock(|c| c.lines());
                if latest.lock(|l| l.critically_low(&lines)) {
                    critically_low();
                }
            }
        }
        next = amiro_firmware::timer_queue::next_release(
            next,
            crate::Clock::now_us(),
            OWNER_PERIOD_US,
        );
        yield_now().await;
    }
}

/// A ring read's counts as millimetres by slot (`None`: no reading), with the ring's calibration
/// (`ProximityCalibration::DEFAULT`, every sensor's, as the blocking path has it).
fn ring_mm(read: &RingRead, places: [Option<usize>; PER_BUS]) -> [Option<u16>; PER_BUS] {
    let counts = read.counts().unwrap_or([None; RING_BUS_SENSORS]);
    let mut mm = [None; PER_BUS];
    for (place, count) in places.into_iter().zip(counts) {
        if let (Some(k), Some(count)) = (place, count) {
            if let Some(slot) = mm.get_mut(k) {
                *slot = Some(ProximityCalibration::DEFAULT.counts_to_mm(count));
            }
        }
    }
    mm
}

/// A ring sensor's change the owner reports.
#[derive(Clone, Copy)]
enum Note {
    Ready = 0,
    Missing = 1,
    Stopped = 2,
    StillMissing = 3,
}

/// Each ring sensor's lines, by index and [`Note`]: static, so that the owner defers them.
const NOTES: [[&str; 4]; RING_SENSORS] = {
    macro_rules! lines {
        ($($i:literal),*) => {
            [$([
                concat!("ring sensor ", $i, " ready"),
                concat!("ring sensor ", $i, " missing"),
                concat!("ring sensor ", $i, " stopped answering"),
                concat!("ring sensor ", $i, " still missing"),
            ]),*]
        };
    }
    lines!(0, 1, 2, 3, 4, 5, 6, 7)
};

/// A ring sensor's line: its index, its change, and (for [`Note::StillMissing`]) the samples
/// it missed.
#[derive(Clone, Copy)]
struct Noted(u8, Note, u32);

/// Ring sensor `index`'s line, static ([`NOTES`]).
fn line(index: u8, what: Note) -> Option<&'static str> {
    NOTES
        .get(usize::from(index))
        .and_then(|lines| lines.get(what as usize))
        .copied()
}

/// A ring sensor's line at boot, written at once.
fn boot_note(Noted(index, what, _): Noted) {
    if let Some(line) = line(index, what) {
        amiro_firmware::log!(line);
    }
}

/// A ring sensor's line in a job, deferred to the trace drain (`channels::defer_log`: no
/// formatting and no log write in the owner's poll or under its bus's lock; a line that finds
/// the drain's two slots taken is dropped, the health report's counts stay). A sensor still
/// missing after a set-up says how many samples went without its frame in QEMU's log alone (the
/// scenario's count; on the chip the health report counts them). Inlined: a call kept in a
/// register (the compiler's, for four calls in a row) is a call the analysis cannot follow.
#[inline(always)]
fn note(noted: Option<Noted>) {
    let Some(Noted(index, what, missed)) = noted else {
        return;
    };
    #[cfg(feature = "qemu")]
    if let Note::StillMissing = what {
        let mut i = [0u8; 10];
        let mut m = [0u8; 10];
        amiro_firmware::log!(
            "ring sensor ",
            amiro_firmware::telemetry::decimal(u32::from(index), &mut i),
            " still missing (",
            amiro_firmware::telemetry::decimal(missed, &mut m),
            " samples without a frame)"
        );
        return;
    }
    let _ = missed;
    if let Some(line) = line(index, what) {
        amiro_firmware::channels::defer_log(line);
    }
}
