//! Host tests' register-level model of the STM32 I2C v1 block in master mode and the devices on
//! its bus, written from RM0008 §26.3.3's event sequences (EV5 SB, EV6 ADDR, EV7 RXNE, EV8_1 and
//! EV8 TXE, EV8_2 TXE with BTF, the BTF stall when DR and the shift register are both full, the
//! acknowledge latched as a byte's reception starts, POS moving it one byte on) and §26.3.4's
//! errors. It records every register access the engine makes, every symbol on the wire, and every
//! departure from the manual's rules (`violations`), so a test can check the order of both.
//!
//! Time: the bus moves only in [`Model::advance`] (one byte, or one condition, per call), which
//! the tests' driver calls between interrupts; an interrupt's actions are one instant, as the bus's
//! critical section makes them on the chip. The exceptions are a STOP and a repeated START: each
//! goes on the wire while the engine polls its CR1 bit (the poll is what lets it pass).
use crate::i2c_engine::*;

/// One register access of the engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    Sr1,
    Sr2,
    ReadDr(u8),
    WriteDr(u8),
    Cr1 { set: u16, clear: u16 },
    StopPoll,
    StartPoll,
    Enable(Interrupts),
    ClearSr1(u16),
    Reset,
}

/// One symbol on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wire {
    Start,
    RepeatedStart,
    /// A byte the master sent (address or data) and whether a device acknowledged it.
    Sent(u8, bool),
    /// A byte a device sent and whether the master acknowledged it.
    Received(u8, bool),
    Stop,
}

/// A device on the bus: a register file with an auto-incrementing pointer (the first written
/// byte of a transaction sets it), as the AMiRo's VCNL4020, HMC5883L, BNO055 and bq27500 are.
#[derive(Debug, Clone)]
pub struct Device {
    pub address: u8,
    pub registers: [u8; 256],
    pub pointer: u8,
    /// Behind the mux's channel (reachable only while it is connected).
    pub channel: Option<u8>,
    /// Refuses its address.
    pub nack_address: bool,
    /// Refuses the data byte with this index in a write transaction (0: the first after the
    /// address).
    pub nack_data: Option<usize>,
}

impl Device {
    pub fn new(address: u8) -> Self {
        let mut registers = [0u8; 256];
        for (n, r) in registers.iter_mut().enumerate() {
            *r = (n as u8) ^ address;
        }
        Self {
            address,
            registers,
            pointer: 0,
            channel: None,
            nack_address: false,
            nack_data: None,
        }
    }
}

/// A PCA9544A: its control byte written, the channel connected at the next STOP (its datasheet).
#[derive(Debug, Clone, Default)]
pub struct Mux {
    pub address: u8,
    pub control: u8,
    pub connected: Option<u8>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Target {
    None,
    Device(usize),
    Mux,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InFlight {
    None,
    Address(u8),
    Sent(u8),
    /// A byte being received, acknowledged or not as latched when it started.
    Received {
        ack: bool,
    },
}

/// The block and its bus.
pub struct Model {
    pub cr1: u16,
    pub cr2: u16,
    pub sr1: u16,
    master: bool,
    transmitter: bool,
    dr: Option<u8>,
    shift: Option<u8>,
    in_flight: InFlight,
    sr1_read: bool,
    /// A device refused a byte: the master waits for its STOP or repeated START.
    nacked: bool,
    /// The ACK the POS bit moved to the next byte (set when a byte's reception starts with POS).
    pos_next_ack: Option<bool>,
    /// The last received byte was acknowledged (the device goes on sending).
    last_rx_ack: bool,
    target: Target,
    data_index: usize,
    /// Wire bytes so far (the fault indices count these).
    bytes: usize,
    pub access: Vec<Access>,
    pub wire: Vec<Wire>,
    pub violations: Vec<String>,
    pub devices: Vec<Device>,
    pub mux: Option<Mux>,
    /// The bus stops before wire byte `n` (a device stretching SCL) until released.
    pub hold_at: Option<usize>,
    /// No START is ever granted (SCL or SDA held low).
    pub stuck: bool,
    /// The master loses arbitration on wire byte `n`.
    pub arbitration_loss_at: Option<usize>,
    /// A misplaced condition is seen during wire byte `n`.
    pub bus_error_at: Option<usize>,
    /// Polls of CR1.STOP (CR1.START) a STOP (a repeated START) takes to go on the wire.
    pub stop_polls: u32,
    /// The core's cycles each poll of CR1.STOP or CR1.START takes (0: no cycle counter, as in
    /// QEMU; the condition wait then ends at its poll cap).
    pub cycles_per_poll: u32,
    /// The condition wait's limit in those cycles (`Block::condition_cycles`).
    pub condition_cycles: u32,
    /// The cycle counter.
    pub now: u32,
    polls: u32,
}

impl Model {
    pub fn new(devices: Vec<Device>) -> Self {
        Self {
            cr1: CR1_PE,
            cr2: 36,
            sr1: 0,
            master: false,
            transmitter: false,
            dr: None,
            shift: None,
            in_flight: InFlight::None,
            sr1_read: false,
            nacked: false,
            pos_next_ack: None,
            last_rx_ack: false,
            target: Target::None,
            data_index: 0,
            bytes: 0,
            access: Vec::new(),
            wire: Vec::new(),
            violations: Vec::new(),
            devices,
            mux: None,
            hold_at: None,
            stuck: false,
            arbitration_loss_at: None,
            bus_error_at: None,
            stop_polls: 2,
            cycles_per_poll: 0,
            condition_cycles: u32::MAX,
            now: 0,
            polls: 0,
        }
    }

    fn violation(&mut self, what: &str) {
        self.violations
            .push(format!("{what} (after {:?})", self.access.last()));
    }

    /// An interrupt the block raises now: (event, error).
    pub fn pending(&self) -> (bool, bool) {
        let ev = self.cr2 & CR2_ITEVTEN != 0
            && (self.sr1 & (SR1_SB | SR1_ADDR | SR1_BTF) != 0
                || (self.cr2 & CR2_ITBUFEN != 0 && self.sr1 & (SR1_TXE | SR1_RXNE) != 0));
        let er = self.cr2 & CR2_ITERREN != 0 && self.sr1 & SR1_ERRORS != 0;
        (ev, er)
    }

    fn reachable(&self, address: u8) -> Target {
        if let Some(mux) = &self.mux {
            if mux.address == address {
                return Target::Mux;
            }
        }
        let connected = self.mux.as_ref().and_then(|m| m.connected);
        self.devices
            .iter()
            .position(|d| {
                d.address == address
                    && !d.nack_address
                    && (d.channel.is_none() || d.channel == connected)
            })
            .map_or(Target::None, Target::Device)
    }

    fn held(&self) -> bool {
        self.stuck || self.hold_at.is_some_and(|n| self.bytes >= n)
    }

    /// Lets a held bus go on.
    pub fn release(&mut self) {
        self.hold_at = None;
    }

    fn stop_now(&mut self) {
        self.wire.push(Wire::Stop);
        self.master = false;
        self.cr1 &= !(CR1_STOP | CR1_START);
        self.sr1 &= !(SR1_TXE | SR1_BTF);
        self.in_flight = InFlight::None;
        self.target = Target::None;
        self.nacked = false;
        if let Some(mux) = &mut self.mux {
            mux.connected = (mux.control & 0x04 != 0).then_some(mux.control & 0x03);
        }
    }

    fn start_now(&mut self) {
        self.wire.push(if self.master {
            Wire::RepeatedStart
        } else {
            Wire::Start
        });
        self.master = true;
        self.cr1 &= !CR1_START;
        self.sr1 = (self.sr1 & !(SR1_TXE | SR1_BTF | SR1_RXNE)) | SR1_SB;
        self.sr1_read = false;
        self.nacked = false;
        self.in_flight = InFlight::None;
        self.dr = None;
        self.shift = None;
        self.target = Target::None;
    }

    /// Whether the master is at a point where a STOP or START it was asked for goes out.
    fn at_boundary(&self) -> bool {
        if !self.master || self.in_flight != InFlight::None {
            return false;
        }
        if self.nacked {
            return true;
        }
        if self.sr1 & SR1_ADDR != 0 {
            return false;
        }
        if self.transmitter {
            self.dr.is_none() && self.shift.is_none()
        } else {
            // A receiver stops after a byte it did not acknowledge.
            !self.last_rx_ack
        }
    }

    fn begin_receive(&mut self) {
        let ack_bit = self.cr1 & CR1_ACK != 0;
        let ack = if self.cr1 & CR1_POS != 0 {
            // POS: ACK applies to the next byte; this one takes what was moved to it (the first
            // after the address is acknowledged).
            let this = self.pos_next_ack.unwrap_or(true);
            self.pos_next_ack = Some(ack_bit);
            this
        } else {
            ack_bit
        };
        self.in_flight = InFlight::Received { ack };
    }

    /// A START goes out if the bus lets it: from slave mode on a free bus, in master mode at a
    /// byte boundary.
    fn advance_start(&mut self) -> bool {
        let may = if self.master {
            !self.held() && (self.at_boundary() || (self.transmitter && self.sr1 & SR1_BTF != 0))
        } else {
            !self.held()
        };
        if may {
            self.start_now();
        }
        may
    }

    /// The bus moves by one byte or one condition; `false` when nothing can move.
    pub fn advance(&mut self) -> bool {
        if self.cr1 & CR1_STOP != 0 && self.at_boundary() && !self.stuck {
            self.stop_now();
            return true;
        }
        if self.cr1 & CR1_START != 0 && self.cr1 & CR1_STOP == 0 && self.advance_start() {
            return true;
        }
        if self.held() || !self.master {
            return false;
        }
        let index = self.bytes;
        match self.in_flight {
            InFlight::None => false,
            InFlight::Address(byte) => {
                self.bytes += 1;
                self.in_flight = InFlight::None;
                if self.fault(index) {
                    return true;
                }
                let target = self.reachable(byte >> 1);
                let ack = target != Target::None;
                self.wire.push(Wire::Sent(byte, ack));
                if ack {
                    self.target = target;
                    self.transmitter = byte & 1 == 0;
                    self.data_index = 0;
                    self.last_rx_ack = true;
                    self.pos_next_ack = None;
                    self.sr1 |= SR1_ADDR;
                    self.sr1_read = false;
                } else {
                    self.sr1 |= SR1_AF;
                    self.nacked = true;
                }
                true
            }
            InFlight::Sent(byte) => {
                self.bytes += 1;
                self.in_flight = InFlight::None;
                if self.fault(index) {
                    return true;
                }
                let ack = self.device_write(byte);
                self.wire.push(Wire::Sent(byte, ack));
                if !ack {
                    self.sr1 |= SR1_AF;
                    self.nacked = true;
                    return true;
                }
                if let Some(next) = self.dr.take() {
                    self.in_flight = InFlight::Sent(next);
                    self.sr1 |= SR1_TXE;
                } else {
                    self.sr1 |= SR1_BTF | SR1_TXE;
                }
                true
            }
            InFlight::Received { ack } => {
                self.bytes += 1;
                self.in_flight = InFlight::None;
                if self.fault(index) {
                    return true;
                }
                let byte = self.device_read();
                self.wire.push(Wire::Received(byte, ack));
                self.last_rx_ack = ack;
                if self.dr.is_none() {
                    self.dr = Some(byte);
                    self.sr1 |= SR1_RXNE;
                    if ack {
                        // The shift register is free: the next byte comes.
                        if self.cr1 & CR1_STOP != 0 {
                            self.violation("STOP after an acknowledged byte");
                        }
                        self.begin_receive();
                    } else if self.cr1 & (CR1_STOP | CR1_START) == 0 {
                        self.violation("a byte not acknowledged with no STOP programmed");
                    }
                } else {
                    // DR full: the byte waits in the shift register, SCL held (BTF).
                    self.shift = Some(byte);
                    self.sr1 |= SR1_BTF;
                }
                true
            }
        }
    }

    fn fault(&mut self, index: usize) -> bool {
        if self.arbitration_loss_at == Some(index) {
            self.sr1 |= SR1_ARLO;
            self.master = false;
            self.cr1 &= !(CR1_START | CR1_STOP);
            return true;
        }
        if self.bus_error_at == Some(index) {
            self.sr1 |= SR1_BERR;
            return true;
        }
        false
    }

    fn device_write(&mut self, byte: u8) -> bool {
        let index = self.data_index;
        self.data_index += 1;
        match self.target {
            Target::Mux => {
                if let Some(mux) = &mut self.mux {
                    mux.control = byte;
                }
                true
            }
            Target::Device(d) => {
                let device = &mut self.devices[d];
                if device.nack_data == Some(index) {
                    return false;
                }
                if index == 0 {
                    device.pointer = byte;
                } else {
                    device.registers[usize::from(device.pointer)] = byte;
                    device.pointer = device.pointer.wrapping_add(1);
                }
                true
            }
            Target::None => false,
        }
    }

    fn device_read(&mut self) -> u8 {
        match self.target {
            Target::Mux => self.mux.as_ref().map_or(0xFF, |m| m.control),
            Target::Device(d) => {
                let device = &mut self.devices[d];
                let byte = device.registers[usize::from(device.pointer)];
                device.pointer = device.pointer.wrapping_add(1);
                byte
            }
            Target::None => 0xFF,
        }
    }

    /// The wire without its acknowledge bits, in the script's terms.
    pub fn symbols(&self) -> Vec<amiro_sensors::script::Symbol> {
        use amiro_sensors::script::Symbol;
        let mut out = Vec::new();
        let mut after_condition = false;
        for w in &self.wire {
            out.push(match *w {
                Wire::Start => Symbol::Start,
                Wire::RepeatedStart => Symbol::RepeatedStart,
                Wire::Stop => Symbol::Stop,
                Wire::Sent(byte, _) if after_condition => Symbol::Address {
                    address: byte >> 1,
                    read: byte & 1 != 0,
                },
                Wire::Sent(byte, _) => Symbol::Written(byte),
                Wire::Received(_, ack) => Symbol::Read { last: !ack },
            });
            after_condition = matches!(w, Wire::Start | Wire::RepeatedStart);
        }
        out
    }
}

impl Block for Model {
    fn read_sr1(&mut self) -> u16 {
        self.access.push(Access::Sr1);
        self.sr1_read = true;
        self.sr1
    }

    fn read_sr2(&mut self) -> u16 {
        self.access.push(Access::Sr2);
        let value = u16::from(self.master) | (u16::from(self.master) << 1);
        if self.sr1 & SR1_ADDR != 0 {
            if !self.sr1_read {
                self.violation("SR2 read to clear ADDR without SR1 read first");
                return value;
            }
            // EV6 cleared: a transmitter's DR is empty (TXE, EV8_1); a receiver's first byte
            // starts.
            self.sr1 &= !SR1_ADDR;
            if self.transmitter {
                self.sr1 |= SR1_TXE;
            } else {
                self.begin_receive();
            }
        }
        value
    }

    fn read_dr(&mut self) -> u8 {
        let Some(byte) = self.dr.take() else {
            self.violation("DR read with nothing received");
            self.access.push(Access::ReadDr(0));
            return 0;
        };
        self.access.push(Access::ReadDr(byte));
        self.sr1 &= !(SR1_RXNE | SR1_BTF);
        if let Some(next) = self.shift.take() {
            // The shift register's byte moves up; the clock runs again.
            self.dr = Some(next);
            self.sr1 |= SR1_RXNE;
            if self.last_rx_ack {
                self.begin_receive();
            }
        }
        byte
    }

    fn write_dr(&mut self, byte: u8) {
        self.access.push(Access::WriteDr(byte));
        if self.sr1 & SR1_SB != 0 {
            if !self.sr1_read {
                self.violation("DR written after SB without SR1 read");
            }
            // EV5 cleared: the address goes out.
            self.sr1 &= !SR1_SB;
            self.in_flight = InFlight::Address(byte);
            return;
        }
        if !self.master || !self.transmitter || self.sr1 & SR1_ADDR != 0 {
            self.violation("DR written outside a transmission");
            return;
        }
        self.sr1 &= !SR1_BTF;
        if self.in_flight == InFlight::None {
            self.in_flight = InFlight::Sent(byte);
            self.sr1 |= SR1_TXE;
        } else if self.dr.is_none() {
            self.dr = Some(byte);
            self.sr1 &= !SR1_TXE;
        } else {
            self.violation("DR written while full");
        }
    }

    fn modify_cr1(&mut self, set: u16, clear: u16) {
        self.access.push(Access::Cr1 { set, clear });
        if self.cr1 & (CR1_STOP | CR1_START) != 0 {
            self.violation("CR1 written while a STOP or START is pending (RM0008 CR1 note)");
        }
        self.cr1 = (self.cr1 | set) & !clear;
    }

    fn cycles(&mut self) -> u32 {
        self.now
    }

    fn condition_cycles(&self) -> u32 {
        self.condition_cycles
    }

    fn stop_pending(&mut self) -> bool {
        self.access.push(Access::StopPoll);
        self.now = self.now.wrapping_add(self.cycles_per_poll);
        if self.cr1 & CR1_STOP == 0 {
            self.polls = 0;
            return false;
        }
        self.polls += 1;
        if self.polls >= self.stop_polls && self.at_boundary() && !self.stuck {
            self.polls = 0;
            self.stop_now();
            return false;
        }
        true
    }

    fn start_pending(&mut self) -> bool {
        self.access.push(Access::StartPoll);
        self.now = self.now.wrapping_add(self.cycles_per_poll);
        if self.cr1 & CR1_START == 0 {
            self.polls = 0;
            return false;
        }
        self.polls += 1;
        if self.polls >= self.stop_polls {
            self.polls = 0;
            // The START goes out if the bus lets it (`advance`'s rule).
            if self.cr1 & CR1_STOP == 0 && self.advance_start() {
                return false;
            }
        }
        true
    }

    fn set_interrupts(&mut self, interrupts: Interrupts) {
        self.access.push(Access::Enable(interrupts));
        self.cr2 = (self.cr2 & 0x3F) | interrupts.bits();
    }

    fn clear_sr1(&mut self, flags: u16) {
        self.access.push(Access::ClearSr1(flags));
        self.sr1 &= !flags;
    }

    fn reset(&mut self) {
        self.access.push(Access::Reset);
        self.cr1 = CR1_PE;
        self.cr2 = 36;
        self.sr1 = 0;
        self.master = false;
        self.dr = None;
        self.shift = None;
        self.in_flight = InFlight::None;
        self.target = Target::None;
        self.polls = 0;
        self.nacked = false;
        self.sr1_read = false;
        self.pos_next_ack = None;
    }
}
