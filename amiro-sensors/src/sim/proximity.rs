//! Simulated VCNL4020 proximity sensors behind a simulated PCA9544A multiplexer.

use super::{triangle, I2cTarget, RegisterDevice, RegisterPointer, SimBus};
use crate::drivers::pca9544a;
use crate::drivers::vcnl4020::{self, reg};

/// A simulated VCNL4020.
///
/// Pattern (one step per read of the proximity result's high byte): proximity counts 2000 + 500 ×
/// index plus the magnitude of a 6000-count triangle over 64 samples (an object coming and going),
/// phase-shifted by sensor; ambient 400 + 20 × index plus a ±100 triangle. Results read zero until
/// self-timed measurement with the respective enable is on. As on the part, the proximity rate
/// register only takes writes while self-timed measurement is off, the LED register's top two bits
/// are a read-only fuse ID (here 01), and COMMAND reads back with the config-lock bit and the
/// data-ready flags set. [`SimVcnl4020::set_proximity`] replaces the proximity pattern with counts
/// from outside (what a world's wall or floor reflects).
#[derive(Debug, Clone)]
pub struct SimVcnl4020 {
    index: u8,
    command: u8,
    proximity_rate: u8,
    led_current: u8,
    ambient_parameter: u8,
    pointer: RegisterPointer,
    samples: u16,
    rejected_writes: u8,
    input_counts: Option<u16>,
}

/// COMMAND bit 7: config lock, always reads 1.
const CONFIG_LOCK: u8 = 0x80;
/// COMMAND bits 6..5: ALS and proximity data ready.
const DATA_READY: u8 = 0x60;
/// LED register bits 7..6: fuse programming ID (read-only).
const FUSE_ID: u8 = 0x40;

impl SimVcnl4020 {
    /// Sensor number `index` (shapes its pattern) at power-on: everything off, LED 20 mA.
    pub const fn new(index: u8) -> Self {
        Self {
            index,
            command: 0,
            proximity_rate: 0,
            led_current: 2,
            ambient_parameter: 0x0D,
            pointer: RegisterPointer::new(),
            samples: 0,
            rejected_writes: 0,
            input_counts: None,
        }
    }

    /// From now on the proximity result reads `counts`; `None` goes back to the pattern.
    pub fn set_proximity(&mut self, counts: Option<u16>) {
        self.input_counts = counts;
    }

    /// COMMAND (enable bits), PROX_RATE, LED_CURRENT, AMBIENT_PARAMETER as stored.
    pub const fn registers(&self) -> [u8; 4] {
        [
            self.command,
            self.proximity_rate,
            self.led_current,
            self.ambient_parameter,
        ]
    }

    /// Whether the host configured the AMiRo set-up and started self-timed measurement.
    pub const fn is_configured_for_amiro(&self) -> bool {
        let c = vcnl4020::Config::AMIRO;
        self.command == vcnl4020::COMMAND_SELF_TIMED
            && self.proximity_rate == c.proximity_rate
            && self.led_current == c.led_current
            && self.ambient_parameter == c.ambient_parameter
    }

    /// Writes the part refused (rate changes while measuring, read-only registers).
    pub const fn rejected_writes(&self) -> u8 {
        self.rejected_writes
    }

    /// Proximity results read so far.
    pub const fn samples(&self) -> u16 {
        self.samples
    }

    /// Simulated proximity counts of sensor `index` at sample `n`.
    pub const fn proximity_at(index: u8, n: u16) -> u16 {
        let wave = triangle(n as u32 + 16 * index as u32, 64, 6000).unsigned_abs();
        (2000 + 500 * index as u32 + wave) as u16
    }

    /// Simulated ambient counts of sensor `index` at sample `n`.
    pub const fn ambient_at(index: u8, n: u16) -> u16 {
        (400 + 20 * index as i32 + triangle(n as u32, 128, 100)) as u16
    }

    fn measuring(&self, enable: u8) -> bool {
        self.command & 0x01 != 0 && self.command & enable != 0
    }

    fn result(&self, register: u8) -> u8 {
        let value = match register {
            0x85 | 0x86 if self.measuring(0x04) => Self::ambient_at(self.index, self.samples),
            0x87 | 0x88 if self.measuring(0x02) => match self.input_counts {
                Some(counts) => counts,
                None => Self::proximity_at(self.index, self.samples),
            },
            _ => 0,
        };
        let [high, low] = value.to_be_bytes();
        if register % 2 == 1 {
            high
        } else {
            low
        }
    }
}

impl RegisterDevice for SimVcnl4020 {
    const ADDRESS: u8 = vcnl4020::ADDRESS;

    fn pointer(&mut self) -> &mut RegisterPointer {
        &mut self.pointer
    }

    fn write_register(&mut self, register: u8, byte: u8) {
        match register {
            reg::COMMAND => self.command = byte & 0x07,
            reg::PROXIMITY_RATE if self.command & 0x01 == 0 => self.proximity_rate = byte & 0x07,
            reg::LED_CURRENT => self.led_current = byte & 0x3F,
            reg::AMBIENT_PARAMETER => self.ambient_parameter = byte,
            _ => self.rejected_writes = self.rejected_writes.saturating_add(1),
        }
    }

    fn read_register(&mut self, register: u8) -> u8 {
        let value = match register {
            reg::COMMAND => {
                let ready = if self.command & 0x01 != 0 {
                    DATA_READY
                } else {
                    0
                };
                CONFIG_LOCK | ready | self.command
            }
            reg::PRODUCT_ID => vcnl4020::PRODUCT_ID_VALUE,
            reg::PROXIMITY_RATE => self.proximity_rate,
            reg::LED_CURRENT => FUSE_ID | self.led_current,
            reg::AMBIENT_PARAMETER => self.ambient_parameter,
            0x85..=0x88 => self.result(register),
            _ => 0,
        };
        // A sample is one proximity conversion, consumed by reading its low byte.
        if register == 0x88 && self.measuring(0x02) {
            self.samples = self.samples.wrapping_add(1);
        }
        value
    }
}

/// A simulated PCA9544A with four VCNL4020s behind its channels.
#[derive(Debug, Clone)]
pub struct SimMuxedProximity {
    control: u8,
    sensors: [SimVcnl4020; 4],
    selections: u32,
}

impl SimMuxedProximity {
    /// A mux at 0x77 (all channels off) with sensors numbered `first..first + 4` on channels 0..3.
    pub const fn new(first: u8) -> Self {
        Self {
            control: 0,
            sensors: [
                SimVcnl4020::new(first),
                SimVcnl4020::new(first.wrapping_add(1)),
                SimVcnl4020::new(first.wrapping_add(2)),
                SimVcnl4020::new(first.wrapping_add(3)),
            ],
            selections: 0,
        }
    }

    /// The mux's control register.
    pub const fn control(&self) -> u8 {
        self.control
    }

    /// Control-register writes so far.
    pub const fn selections(&self) -> u32 {
        self.selections
    }

    /// The sensor on `channel` (0..=3).
    pub fn sensor(&self, channel: usize) -> Option<&SimVcnl4020> {
        self.sensors.get(channel)
    }

    /// Feeds the sensor on `channel` (see [`SimVcnl4020::set_proximity`]); `false` if there is
    /// no such channel.
    pub fn set_proximity(&mut self, channel: usize, counts: Option<u16>) -> bool {
        match self.sensors.get_mut(channel) {
            Some(sensor) => {
                sensor.set_proximity(counts);
                true
            }
            None => false,
        }
    }

    fn selected(&mut self) -> Option<&mut SimVcnl4020> {
        if self.control & pca9544a::ENABLE == 0 {
            return None;
        }
        self.sensors.get_mut(usize::from(self.control & 0x03))
    }
}

impl I2cTarget for SimMuxedProximity {
    fn acknowledges(&self, address: u8) -> bool {
        address == pca9544a::AMIRO_ADDRESS
            || (address == vcnl4020::ADDRESS && self.control & pca9544a::ENABLE != 0)
    }

    fn start(&mut self, address: u8, read: bool) {
        if address != pca9544a::AMIRO_ADDRESS {
            if let Some(sensor) = self.selected() {
                sensor.start(address, read);
            }
        }
    }

    fn write_byte(&mut self, address: u8, byte: u8) {
        if address == pca9544a::AMIRO_ADDRESS {
            self.control = byte & 0x07;
            self.selections = self.selections.wrapping_add(1);
        } else if let Some(sensor) = self.selected() {
            sensor.write_byte(address, byte);
        }
    }

    fn read_byte(&mut self, address: u8) -> u8 {
        if address == pca9544a::AMIRO_ADDRESS {
            self.control
        } else {
            self.selected()
                .map_or(0xFF, |sensor| sensor.read_byte(address))
        }
    }
}

impl SimBus<SimMuxedProximity> {
    /// The simulated mux and sensors.
    pub const fn proximity(&self) -> &SimMuxedProximity {
        &self.target
    }

    /// The simulated mux and sensors, to feed them.
    pub fn proximity_mut(&mut self) -> &mut SimMuxedProximity {
        &mut self.target
    }
}
