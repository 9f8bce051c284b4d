//! With `scripted-i2c`: PowerManagement's two buses sampled by script (docs/i2c.md,
//! "PowerManagement with `scripted-i2c`"). Each bus has one owner task ([`RingOwner`], the app's
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
//! answer yields no reading (no frame) and is counted; the log lines and the health report are
//! made when the job ends, from what it changed.
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
    calibration: [ProximityCalibration; PER_BUS],
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
            calibration: [ProximityCalibration::DEFAULT; PER_BUS],
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
                this.end_set_up(k, 0, ready);
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

    /// Slot `k`'s set-up ended (`ready`: it answers now), logged as the blocking path logs it.
    fn end_set_up(&mut self, k: usize, now_us: u64, ready: bool) {
        let Some(slot) = self.slots.get_mut(k) else {
            return;
        };
        let mut index = [0u8; 10];
        let index = amiro_firmware::telemetry::decimal(u32::from(slot.index), &mut index);
        if !ready && now_us > 0 {
            let mut missed = [0u8; 10];
            amiro_firmware::log!(
                "ring sensor ",
                index,
                " still missing (",
                amiro_firmware::telemetry::decimal(slot.missed, &mut missed),
                " samples without a frame)"
            );
        }
        if ready != slot.ready {
            amiro_firmware::log!(
                "ring sensor ",
                index,
                if ready { " ready" } else { " missing" }
            );
        }
        slot.ready = ready;
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

    /// The read's counts as the bus's latest reading; every slot without one missed.
    fn end_ring_read(&mut self, now_us: u64, read: &RingRead, places: [Option<usize>; PER_BUS]) {
        let counts = read.counts().unwrap_or([None; RING_BUS_SENSORS]);
        let mut read_at = [None; PER_BUS];
        for (place, count) in places.into_iter().zip(counts) {
            if let (Some(k), Some(count)) = (place, count) {
                if let Some(slot) = read_at.get_mut(k) {
                    *slot = Some(count);
                }
            }
        }
        for (k, count) in read_at.into_iter().enumerate() {
            let cal = self
                .calibration
                .get(k)
                .copied()
                .unwrap_or(ProximityCalibration::DEFAULT);
            let mm = count.map(|counts| cal.counts_to_mm(counts));
            if let Some(latest) = self.latest.get_mut(k) {
                *latest = mm;
            }
            if mm.is_none() {
                self.lost(k, now_us);
            }
        }
        self.read_once = true;
        self.report();
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
    fn lost(&mut self, k: usize, now_us: u64) {
        if let Some(slot) = self.slots.get_mut(k) {
            if slot.ready {
                slot.ready = false;
                slot.last_try_us = now_us;
                let mut index = [0u8; 10];
                amiro_firmware::log!(
                    "ring sensor ",
                    amiro_firmware::telemetry::decimal(u32::from(slot.index), &mut index),
                    " stopped answering"
                );
            }
        }
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

/// A missing sensor's set-up under way, one of its scripts a job ([`sample_ring`]): its slot, the
/// set-up, and the scripts it has run.
pub struct StepwiseSetUp {
    slot: usize,
    set_up: SensorSetUp,
    steps: usize,
}

/// One ring job on the bus behind `bus`, its scripts on `port`: one script of a missing sensor's
/// set-up (the one under way in `set_up`, or the first missing sensor's whose [`RETRY_US`] passed,
/// begun now), then the read of the sensors that answer into the bus's latest reading, each script
/// with the bus's lock released. A set-up thus takes [`SET_UP_SCRIPTS`] jobs (six, 375 ms at
/// [`OWNER_PERIOD_US`]), so that a job carries one set-up script at most (docs/i2c.md, "The owner
/// tasks": six in one job put more than the period on the bus). Not inlined: the analysis tells the
/// ring's job by the function.
#[inline(never)]
pub async fn sample_ring(
    bus: &mut impl rtic::Mutex<T = ScriptedBus>,
    port: &mut impl ScriptPort,
    set_up: &mut Option<StepwiseSetUp>,
    now_us: u64,
) {
    if set_up.is_none() {
        *set_up = bus
            .lock(|b| b.due_set_up(now_us))
            .map(|(slot, set_up)| StepwiseSetUp {
                slot,
                set_up,
                steps: 0,
            });
    }
    let ended = match set_up.as_mut() {
        Some(step) => {
            step.steps += 1;
            let outcome = match step.set_up.script() {
                Ok(script) => {
                    let result = script_result(port.run(script, 0).await);
                    step.set_up.complete(&result).map(|done| done.is_ok())
                }
                Err(_) => Some(false),
            };
            // A set-up that has not ended within its scripts has failed.
            match outcome {
                None if step.steps >= SET_UP_SCRIPTS => Some((step.slot, false)),
                None => None,
                Some(ready) => Some((step.slot, ready)),
            }
        }
        None => None,
    };
    if ended.is_some() {
        *set_up = None;
    }
    let (mut read, places) = bus.lock(|b| {
        if let Some((k, ready)) = ended {
            b.end_set_up(k, now_us, ready);
        }
        b.ring_read()
    });
    for _ in 0..RingRead::MAX_SCRIPTS {
        let script = match read.script() {
            Some(Ok(script)) => script,
            // A script the build refuses: the sensors still to read give no count this time.
            Some(Err(_)) | None => break,
        };
        let result = script_result(port.run(script, 0).await);
        read.complete(&result);
    }
    bus.lock(|b| b.end_ring_read(now_us, &read, places));
}

/// One transfer of the gauge's status read `read`, a script on `port` after the gauge's bus-free
/// time: `None` while the read goes on; at its end `Some` of the status, or of `None` (counted)
/// when the gauge did not answer. Not inlined, as [`sample_ring`].
#[inline(never)]
pub async fn gauge_transfer(
    read: &mut StatusRead,
    bus: &mut impl rtic::Mutex<T = ScriptedBus>,
    port: &mut impl ScriptPort,
) -> Option<Option<BatteryStatus>> {
    let status = match read.next_transfer() {
        Some(transfer) => {
            let outcome = match gauge_script(transfer) {
                Ok(script) => gauge_outcome(
                    transfer,
                    &script_result(port.run(script, GAUGE_SETTLE_US).await),
                ),
                Err(error) => Err(error),
            };
            read.complete(outcome)?.ok()
        }
        // A read past its end (a round restarts each read that ends): no status.
        None => None,
    };
    Some(bus.lock(|b| b.end_gauge_read(status)))
}

/// A bus's owner task's state: its slot on the bus and its gauge's status read, kept across jobs.
pub struct RingOwner<P> {
    port: P,
    read: StatusRead,
    set_up: Option<StepwiseSetUp>,
}

impl<P: ScriptPort> RingOwner<P> {
    /// An owner on its bus's slot `port`, its gauge read not begun.
    pub fn new(port: P) -> Self {
        Self {
            port,
            read: StatusRead::new(),
            set_up: None,
        }
    }

    /// One job at `now_us`: the bus's ring read ([`sample_ring`]: one script of a missing
    /// sensor's set-up at most, then the read), then one transfer of its gauge's status read ([`gauge_transfer`]);
    /// a gauge read that ends puts its status into `latest` and restarts. Whether one ended (the
    /// caller checks the battery then); a read takes at most [`StatusRead::MAX_TRANSFERS`] jobs.
    pub async fn job(
        &mut self,
        bus: &mut impl rtic::Mutex<T = ScriptedBus>,
        latest: &mut impl rtic::Mutex<T = LatestRound>,
        now_us: u64,
    ) -> bool {
        sample_ring(bus, &mut self.port, &mut self.set_up, now_us).await;
        let Some(status) = gauge_transfer(&mut self.read, bus, &mut self.port).await else {
            return false;
        };
        self.read.restart();
        let rear = bus.lock(|b| b.is_rear());
        latest.lock(|l| l.record(rear, status));
        true
    }
}

/// A bus's owner task's loop (the app's `ring_rear`, `ring_front`): a [`RingOwner::job`] every
/// [`OWNER_PERIOD_US`] from the task's start, none while the robot shuts down; after a gauge read
/// that ends, both gauges' latest statuses are checked against the charge lines read then, and a
/// critically low battery calls `critically_low` (the app's shutdown). A job that ran past its
/// next release skips it.
pub async fn serve_owner<P: ScriptPort>(
    port: P,
    mut bus: impl rtic::Mutex<T = ScriptedBus>,
    mut charger: impl rtic::Mutex<T = crate::platform::Charger>,
    mut latest: impl rtic::Mutex<T = LatestRound>,
    critically_low: impl Fn(),
) -> ! {
    use amiro_firmware::mono::Clock as _;
    let mut owner = RingOwner::new(port);
    let mut next = crate::Clock::now_us();
    loop {
        crate::Clock::delay_until_us(next).await;
        next += OWNER_PERIOD_US;
        if !amiro_firmware::signals::shutting_down() {
            let now_us = crate::Clock::now_us();
            if owner.job(&mut bus, &mut latest, now_us).await {
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
    }
}
