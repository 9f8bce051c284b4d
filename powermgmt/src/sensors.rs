//! PowerManagement's two I2C buses as RTIC resources, and what the board samples for a topic.
//!
//! Each bus is one resource: I2C1 (the "rear" bus: PCA9544A #1 with ring sensors 0, 1, 2, 7 and
//! the rear bq27500) and I2C2 (the "front" bus: PCA9544A #2 with ring sensors 3, 4, 5, 6 and the
//! front bq27500). A ring sample locks one bus, reads its four sensors, releases it, then does the
//! same on the other, so a publisher at another level waits for at most one bus's transfers, and
//! a failing bus costs bounded time (`amiro_firmware::i2c::FLAG_TIMEOUT_US` per transfer on the robot) — after
//! which its missing sensors are skipped until their retry, so they do not delay the other bus's
//! sensors on every sample. A sensor that does not answer yields no frame for its index, is
//! counted (`missed`), and is set up again at most once per [`RETRY_US`], at most one sensor per bus
//! per sample (so a ring release costs one sensor's set-up per bus, not four).
//!
//! The devices are amiro-sensors' drivers (`Pca9544a`, `Vcnl4020`, `Bq27500`) with the ring's
//! wiring table `WIRING`; amiro-sensors' `ProximityRing` holds both buses in one value, which
//! would make one resource of them, so this module binds the same drivers per bus.
use amiro_can::{SensorData, Topic};
use amiro_sensors::drivers::bq27500::{self, BatteryStatus, Bq27500, StatusRead};
use amiro_sensors::drivers::pca9544a::{Channel, Pca9544a};
use amiro_sensors::drivers::proximity::ProximityCalibration;
use amiro_sensors::drivers::ring::{RingBus, RING_SENSORS, WIRING};
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::drivers::vcnl4020::{Config, Vcnl4020};
use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use crate::platform::{Charger, FrontI2c, GaugeDelay, RearI2c};
use crate::power;

/// How long a sensor or gauge that did not answer is left alone before it is set up again.
pub const RETRY_US: u64 = 200_000;
/// Ring sensors per bus.
const PER_BUS: usize = RING_SENSORS / 2;

/// The distances of one ring sample by sensor index; `None` = no reading this time.
pub type RingSample = [Option<u16>; RING_SENSORS];

#[derive(Debug, Clone, Copy)]
struct RingSlot {
    index: u8,
    channel: Channel,
    ready: bool,
    last_try_us: u64,
    missed: u32,
}

/// One I2C bus: its multiplexer, its four ring sensors and its fuel gauge.
pub struct SensorBus<I, D> {
    bus: RingBus,
    mux: Pca9544a<I>,
    delay: D,
    slots: [RingSlot; PER_BUS],
    calibration: [ProximityCalibration; PER_BUS],
    gauge_faults: u32,
}

impl<I: I2c, D: DelayNs> SensorBus<I, D> {
    /// The devices of `bus` on `i2c`; sets up the four ring sensors (a sensor that does not answer
    /// is retried later), checks the gauge's identity (logged) and reads its status (the boot's
    /// round: `None`, counted, when it did not answer).
    pub fn new(bus: RingBus, i2c: I, delay: D) -> (Self, Option<BatteryStatus>) {
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
            mux: Pca9544a::new(i2c),
            delay,
            slots,
            calibration: [ProximityCalibration::DEFAULT; PER_BUS],
            gauge_faults: 0,
        };
        for k in 0..PER_BUS {
            this.set_up(k, 0);
        }
        let gauge = Bq27500::new(this.mux.bus_mut(), &mut this.delay).init();
        if gauge.is_err() {
            amiro_firmware::log!(
                bus_name(bus),
                ": fuel gauge did not answer its identity check"
            );
        }
        let mut read = StatusRead::new();
        let mut status = None;
        for _ in 0..StatusRead::MAX_TRANSFERS {
            let ended = this.gauge_step(&mut read);
            this.delay.delay_ns(bq27500::BUS_FREE_NS);
            if let Some(ended) = ended {
                status = ended;
                break;
            }
        }
        (this, status)
    }

    /// Sets sensor slot `k` up; whether it now answers.
    fn set_up(&mut self, k: usize, now_us: u64) -> bool {
        let Some(slot) = self.slots.get_mut(k) else {
            return false;
        };
        slot.last_try_us = now_us;
        let ready = match self.mux.select(slot.channel) {
            Ok(muxed) => Vcnl4020::new(muxed).init(&Config::AMIRO).is_ok(),
            Err(_) => false,
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
        ready
    }

    /// Reads this bus's four ring sensors into `sample` (by sensor index).
    ///
    /// At most one missing sensor is set up again per call (the first whose [`RETRY_US`] has
    /// passed; the one set up gets its `last_try_us`, so the others take their turns at the
    /// next samples), before the reads and outside their loop: a ring release costs its reads and
    /// one sensor's set-up per bus, never four.
    #[inline(never)]
    pub fn sample_ring(&mut self, now_us: u64, sample: &mut RingSample) {
        let due = |s: &RingSlot| !s.ready && now_us.saturating_sub(s.last_try_us) >= RETRY_US;
        // The first missing sensor whose retry passed, if any: one set-up per call.
        if let Some(k) = self.slots.iter().position(due) {
            self.set_up(k, now_us);
        }
        for k in 0..PER_BUS {
            let Some(&slot) = self.slots.get(k) else {
                continue;
            };
            let reading = if slot.ready {
                self.mux
                    .select(slot.channel)
                    .ok()
                    .and_then(|muxed| Vcnl4020::new(muxed).read_proximity().ok())
            } else {
                None
            };
            let cal = self
                .calibration
                .get(k)
                .copied()
                .unwrap_or(ProximityCalibration::DEFAULT);
            match (reading, sample.get_mut(usize::from(slot.index))) {
                (Some(counts), Some(out)) => *out = Some(cal.counts_to_mm(counts)),
                _ => self.missed(k, now_us),
            }
        }
        self.report();
    }

    fn missed(&mut self, k: usize, now_us: u64) {
        if let Some(slot) = self.slots.get_mut(k) {
            slot.missed = slot.missed.saturating_add(1);
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

    /// Puts this bus's faults (missed ring samples and failed gauge reads) and whether a sensor is
    /// out of service now into the board's diagnostics (one sensor group per bus).
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

    /// One transfer of `read` to this bus's fuel gauge ([`StatusRead::step`]): `None` while the
    /// read goes on; at its end `Some` of the status, or of `None` (counted) when the gauge did not
    /// answer. Without the gauge's bus-free pause: the caller makes it after the transfer, with the
    /// bus given back ([`PauseAfterUnlock`]).
    #[inline(never)]
    pub fn gauge_step(&mut self, read: &mut StatusRead) -> Option<Option<BatteryStatus>> {
        let status = read
            .step(&mut Bq27500::new(self.mux.bus_mut(), PauseAfterUnlock))?
            .ok();
        if status.is_none() {
            self.gauge_faults = self.gauge_faults.saturating_add(1);
        }
        self.report();
        Some(status)
    }

    /// Samples without a frame per ring sensor of this bus: `(index, missed)`.
    pub fn missed_samples(&self) -> [(u8, u32); PER_BUS] {
        self.slots.map(|s| (s.index, s.missed))
    }

    /// Failed gauge reads so far.
    pub fn gauge_faults(&self) -> u32 {
        self.gauge_faults
    }

    /// Which bus this is.
    pub fn bus(&self) -> RingBus {
        self.bus
    }
}

/// The gauge driver's bus-free pause left to the caller of [`SensorBus::gauge_step`], who makes it
/// after the transfer with the bus's lock given back: the bq27500 asks for [`bq27500::BUS_FREE_NS`]
/// between packets addressed to it (TI's bq27xxx data sheets, 'I2C Command Waiting Time'), and
/// packets to the ring's devices may come in between, so the pause holds no lock and a publisher
/// waiting for the bus does not wait for it.
struct PauseAfterUnlock;

impl DelayNs for PauseAfterUnlock {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// The bus's name in the log.
const fn bus_name(bus: RingBus) -> &'static str {
    match bus {
        RingBus::I2c1 => "I2C1 (rear)",
        RingBus::I2c2 => "I2C2 (front)",
    }
}

/// I2C1: ring sensors 0, 1, 2, 7 and the rear fuel gauge (battery B).
pub type RearBus = SensorBus<RearI2c, GaugeDelay>;
/// I2C2: ring sensors 3, 4, 5, 6 and the front fuel gauge (battery A).
pub type FrontBus = SensorBus<FrontI2c, GaugeDelay>;

/// Both gauges read one transfer a call, front then rear, each transfer under its own lock of its
/// bus and the gauge's bus-free pause after it, outside the lock: a publisher waiting for either
/// bus waits for one transfer to a gauge, not a whole read, nor the pause.
/// The power monitor keeps one across its jobs and makes one call a job. Each gauge's status goes
/// to the power monitor's [`power::LatestRound`] as its read ends.
#[derive(Debug, Default)]
pub struct BatteryRound {
    read: StatusRead,
    /// The rear gauge's read is under way (the front one's has ended).
    at_rear: bool,
}

impl BatteryRound {
    /// A round not begun.
    pub const fn new() -> Self {
        Self {
            read: StatusRead::new(),
            at_rear: false,
        }
    }

    /// Makes the round's next transfer, under its bus's lock, then the gauge's bus-free pause with
    /// the lock given back; a gauge's read that ends puts its status (`None`: the gauge did not
    /// answer, counted) into `latest`.
    /// Whether the round has ended (the rear gauge's read with it; the next call begins a new
    /// round). A round takes at most 2 × [`StatusRead::MAX_TRANSFERS`] = 26 calls (20 when both
    /// gauges answer their reads).
    pub fn step(
        &mut self,
        rear: &mut impl rtic::Mutex<T = RearBus>,
        front: &mut impl rtic::Mutex<T = FrontBus>,
        latest: &mut impl rtic::Mutex<T = power::LatestRound>,
    ) -> bool {
        let read = &mut self.read;
        let ended = if self.at_rear {
            rear.lock(|b| b.gauge_step(read))
        } else {
            front.lock(|b| b.gauge_step(read))
        };
        GaugeDelay.delay_ns(bq27500::BUS_FREE_NS);
        let Some(status) = ended else {
            return false;
        };
        self.read.restart();
        let at_rear = self.at_rear;
        latest.lock(|l| l.record(at_rear, status));
        self.at_rear = !at_rear;
        at_rear
    }
}

/// What PowerManagement samples for a topic: the ring locks each bus in turn; power status takes
/// the power monitor's latest gauge round and reads the charge lines, no I2C (`power_status`).
/// Every other topic (the diagnostics topic is the runtime's) has no samples here.
pub fn sampler(
    mut rear: impl rtic::Mutex<T = RearBus>,
    mut front: impl rtic::Mutex<T = FrontBus>,
    mut charger: impl rtic::Mutex<T = Charger>,
    mut batteries: impl rtic::Mutex<T = power::LatestRound>,
) -> impl amiro_firmware::publisher::Sampler {
    move |topic: Topic, taken: u64| {
        let mut samples = Samples::new();
        match topic {
            Topic::ProximityRing => {
                let mut ring: RingSample = [None; RING_SENSORS];
                rear.lock(|b| b.sample_ring(taken, &mut ring));
                front.lock(|b| b.sample_ring(taken, &mut ring));
                for (sensor, mm) in (0u8..).zip(ring) {
                    if let Some(mm) = mm {
                        let _ = samples.push(SensorData::ProximityRing { sensor, mm });
                    }
                }
            }
            Topic::PowerStatus => {
                if let Some(status) = power_status(&mut batteries, &mut charger) {
                    let _ = samples.push(SensorData::PowerStatus(status));
                }
            }
            _ => {}
        }
        samples
    }
}

/// The power-status sample: the power monitor's latest gauge round and the charge lines read now
/// ([`power::LatestRound::status`]); `None` (no frame) when neither gauge has a status.
pub fn power_status(
    batteries: &mut impl rtic::Mutex<T = power::LatestRound>,
    charger: &mut impl rtic::Mutex<T = Charger>,
) -> Option<amiro_can::PowerStatus> {
    let lines = charger.lock(|c| c.lines());
    batteries.lock(|latest| latest.status(&lines))
}

/// With `scripted-i2c`: the buses sampled by script (docs/i2c.md), each bus's owner task
/// suspended while its scripts run.
#[cfg(feature = "scripted-i2c")]
pub mod scripted;

/// What PowerManagement samples for a topic with `scripted-i2c`: the ring takes each bus's
/// latest reading, its owner task's (`scripted::serve_owner`), under each bus's lock in turn, no
/// script; power status takes the gauges' latest reads and the charge lines ([`power_status`]).
/// Every other topic has no samples here.
#[cfg(feature = "scripted-i2c")]
pub fn scripted_sampler(
    mut rear: impl rtic::Mutex<T = scripted::ScriptedBus>,
    mut front: impl rtic::Mutex<T = scripted::ScriptedBus>,
    mut charger: impl rtic::Mutex<T = Charger>,
    mut batteries: impl rtic::Mutex<T = power::LatestRound>,
) -> impl amiro_firmware::publisher::Sampler {
    move |topic: Topic, _taken: u64| {
        let mut samples = Samples::new();
        match topic {
            Topic::ProximityRing => {
                let mut ring: RingSample = [None; RING_SENSORS];
                rear.lock(|b| b.latest_into(&mut ring));
                front.lock(|b| b.latest_into(&mut ring));
                for (sensor, mm) in (0u8..).zip(ring) {
                    if let Some(mm) = mm {
                        let _ = samples.push(SensorData::ProximityRing { sensor, mm });
                    }
                }
            }
            Topic::PowerStatus => {
                if let Some(status) = power_status(&mut batteries, &mut charger) {
                    let _ = samples.push(SensorData::PowerStatus(status));
                }
            }
            _ => {}
        }
        samples
    }
}
