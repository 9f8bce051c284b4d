//! The robot: the main board on the serial line (UART receiver, XCP, CAN gateway) and the
//! modules behind it on a CAN link, in virtual time.
use std::collections::VecDeque;

use crate::flash::{Flash, IdInCode, SimChip};

const CONNECT: u8 = 0xFF;
const DISCONNECT: u8 = 0xFE;
const SET_MTA: u8 = 0xF6;
const UPLOAD: u8 = 0xF5;
const PROGRAM_START: u8 = 0xD2;
const PROGRAM_CLEAR: u8 = 0xD1;
const PROGRAM: u8 = 0xD0;
const PROGRAM_RESET: u8 = 0xCF;
const PROGRAM_MAX: u8 = 0xC9;
const ERR_UNKNOWN: u8 = 0x20;
const ERR_OUT_OF_RANGE: u8 = 0x22;
const ERR_GENERIC: u8 = 0x31;
/// MAX_CTO the bootloaders report.
const MAX_CTO: usize = 255;

/// Line and flash timing; zero costs make everything instant (the windows stay).
#[derive(Debug, Clone)]
pub struct Timing {
    /// UART baud rate; 0 = bytes take no time.
    pub baud: u32,
    /// Nanoseconds per CAN bit (1000 at 1 Mbit/s); 0 = frames take no time.
    pub can_bit_ns: u64,
    /// Whether erase and program take their datasheet times.
    pub flash_costs: bool,
    /// The main board's window for a host after reset.
    pub window_ns: u64,
    /// Flashing mode ends after this long without host traffic (once CONNECT(0) was seen).
    pub flash_mode_timeout_ns: u64,
}

impl Timing {
    /// The robot as built: 115200 baud, 1 Mbit/s CAN, datasheet flash times.
    pub fn robot() -> Self {
        Timing {
            baud: 115_200,
            can_bit_ns: 1000,
            flash_costs: true,
            window_ns: 500_000_000,
            flash_mode_timeout_ns: 30_000_000_000,
        }
    }

    /// No transfer or flash costs (for a real-time pty session in CI).
    pub fn instant() -> Self {
        Timing {
            baud: 0,
            can_bit_ns: 0,
            flash_costs: false,
            ..Timing::robot()
        }
    }

    fn byte_ns(&self) -> u64 {
        if self.baud == 0 {
            0
        } else {
            10_000_000_000 / u64::from(self.baud)
        }
    }

    fn frame_ns(&self, dlc: usize) -> u64 {
        let bytes = dlc.min(8) as u64;
        (47 + 8 * bytes + (34 + 8 * bytes) / 8) * self.can_bit_ns
    }
}

/// One board of the simulated robot.
#[derive(Debug, Clone)]
pub struct BoardSpec {
    /// Name, for logs.
    pub name: String,
    /// 32-bit device id.
    pub device_id: u32,
    /// One-byte legacy id, if its bootloader defines one.
    pub legacy_id: Option<u8>,
    /// Chip.
    pub chip: SimChip,
    /// How its bootloader's code holds `device_id` (what a host can find by reading it).
    pub id_in_code: IdInCode,
}

impl BoardSpec {
    /// A revision 1-1 robot: DiWheelDrive 1-1 (main, on the serial port), PowerManagement 1-1 and
    /// LightRing 1-0, whose bootloaders also answer to the legacy one-byte ids 1, 2 and 3.
    /// DiWheelDrive's and LightRing's code holds the device id in literal pools (the 1-2 robot's
    /// as MOVW/MOVT pairs), PowerManagement's only in compares (CMP.W #0x01010101; the 1-2
    /// robot's CMN.W #0xFEFEFEFE), as GCC builds them: the two robots, with either main board
    /// on the cable ([`BoardSpec::with_main`]), exercise every way a host can find it.
    pub fn robot_1_1() -> Vec<BoardSpec> {
        vec![
            BoardSpec {
                name: "diwheeldrive".into(),
                device_id: 0x0100_0101,
                legacy_id: Some(1),
                chip: SimChip::F103,
                id_in_code: IdInCode::LiteralPool,
            },
            BoardSpec {
                name: "powermgmt".into(),
                device_id: 0x0101_0101,
                legacy_id: Some(2),
                chip: SimChip::F405,
                id_in_code: IdInCode::CompareImmediate,
            },
            BoardSpec {
                name: "lightring".into(),
                device_id: 0x017F_0100,
                legacy_id: Some(3),
                chip: SimChip::F103,
                id_in_code: IdInCode::LiteralPool,
            },
        ]
    }

    /// The three revision 1-2 boards: DiWheelDrive (main, on the serial port), PowerManagement,
    /// LightRing.
    pub fn robot_1_2() -> Vec<BoardSpec> {
        vec![
            BoardSpec {
                name: "diwheeldrive".into(),
                device_id: 0x0100_0102,
                legacy_id: None,
                chip: SimChip::F103,
                id_in_code: IdInCode::MovwMovt,
            },
            BoardSpec {
                name: "powermgmt".into(),
                device_id: 0x0101_0102,
                legacy_id: None,
                chip: SimChip::F405,
                id_in_code: IdInCode::CompareImmediate,
            },
            BoardSpec {
                name: "lightring".into(),
                device_id: 0x017F_0102,
                legacy_id: None,
                chip: SimChip::F103,
                id_in_code: IdInCode::MovwMovt,
            },
        ]
    }

    /// `boards` with the cable on `main`'s serial port instead (that board moved first, the
    /// others' order kept): PowerManagement is a main board too, with its own UART gateway.
    /// `None` when no board is called `main`.
    pub fn with_main(mut boards: Vec<BoardSpec>, main: &str) -> Option<Vec<BoardSpec>> {
        let at = boards.iter().position(|b| b.name == main)?;
        let board = boards.remove(at);
        boards.insert(0, board);
        Some(boards)
    }
}

/// A refusal to inject.
#[derive(Debug, Clone, Copy)]
pub struct Nak {
    /// The board that refuses.
    pub device_id: u32,
    /// The command code it refuses.
    pub command: u8,
    /// Which occurrence of the command (1 = the first) is refused.
    pub occurrence: u32,
    /// The error code.
    pub code: u8,
    /// Refuse every occurrence from then on.
    pub persistent: bool,
}

/// Faults to inject.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    /// Index (from 0, counting every byte the host sent) of a byte the UART loses.
    pub drop_host_byte: Option<u64>,
    /// Index of a host byte that arrives with these bits flipped.
    pub corrupt_host_byte: Option<(u64, u8)>,
    /// Index of a reply byte (counting every byte the robot sent) that arrives flipped.
    pub corrupt_reply_byte: Option<(u64, u8)>,
    /// A module that stops acknowledging CAN frames after receiving this many packets.
    pub silent_after: Option<(u32, u32)>,
    /// A refusal.
    pub nak: Option<Nak>,
}

/// What the main board is doing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mode {
    /// In the bootloader, listening (the window, or forever without a valid application).
    Bootloader,
    /// A host connected: the bootloader stays until PROGRAM_RESET or 30 s of silence.
    Flashing,
    /// The applications run; the UART no longer speaks SerialBoot.
    Application,
    /// Stuck until reset (SOS blinking, or waiting forever for a CAN acknowledgement).
    Hung(String),
}

struct Module {
    spec: BoardSpec,
    flash: Flash,
    connected: bool,
    mta: u32,
    started: bool,
    packets: u32,
    counts: [u32; 256],
    dead: bool,
    /// CAN reception: (bytes expected, bytes so far).
    rx: Option<(usize, Vec<u8>)>,
}

impl Module {
    fn new(spec: BoardSpec) -> Self {
        Module {
            flash: {
                let mut flash = Flash::new(spec.chip);
                flash.compile_device_id(spec.device_id, spec.id_in_code);
                flash
            },
            spec,
            connected: false,
            mta: 0,
            started: false,
            packets: 0,
            counts: [0; 256],
            dead: false,
            rx: None,
        }
    }

    fn answers_to(&self, id: u32) -> bool {
        id == self.spec.device_id || self.spec.legacy_id.is_some_and(|l| u32::from(l) == id)
    }
}

/// The simulated robot.
pub struct Robot {
    now: u64,
    modules: Vec<Module>,
    timing: Timing,
    faults: Faults,
    /// Whether the cable's RTS line resets the main board.
    pub rts_wired: bool,
    mode: Mode,
    window_until: u64,
    was_main_connection: bool,
    other: Option<u32>,
    last_traffic: u64,
    uart_rx: Option<(usize, Vec<u8>)>,
    busy_until: u64,
    out: VecDeque<(u64, u8)>,
    host_bytes: u64,
    reply_bytes: u64,
    /// What happened, one line per notable event.
    pub log: Vec<String>,
}

impl Robot {
    /// A robot of these boards (the first is the main board on the serial port), just reset,
    /// with erased application regions.
    pub fn new(boards: Vec<BoardSpec>, timing: Timing, faults: Faults) -> Self {
        let mut robot = Robot {
            now: 0,
            modules: boards.into_iter().map(Module::new).collect(),
            timing,
            faults,
            rts_wired: false,
            mode: Mode::Bootloader,
            window_until: 0,
            was_main_connection: false,
            other: None,
            last_traffic: 0,
            uart_rx: None,
            busy_until: 0,
            out: VecDeque::new(),
            host_bytes: 0,
            reply_bytes: 0,
            log: Vec::new(),
        };
        robot.restart_bootloaders();
        robot.log.clear();
        robot
    }

    /// Virtual time now, in ns.
    pub fn now(&self) -> u64 {
        self.now
    }

    /// The main board's state.
    pub fn mode(&self) -> &Mode {
        &self.mode
    }

    /// The flash of the board with this id.
    pub fn flash(&self, device_id: u32) -> &Flash {
        &self.module(device_id).flash
    }

    /// Mutable flash (to install an application as a probe would).
    pub fn flash_mut(&mut self, device_id: u32) -> &mut Flash {
        let i = self.index(device_id);
        &mut self.modules[i].flash
    }

    /// Whether the board's application was started.
    pub fn app_started(&self, device_id: u32) -> bool {
        self.module(device_id).started
    }

    /// Replaces the injected faults.
    pub fn set_faults(&mut self, faults: Faults) {
        self.faults = faults;
    }

    fn index(&self, device_id: u32) -> usize {
        self.modules
            .iter()
            .position(|m| m.spec.device_id == device_id)
            .expect("no board with that id")
    }

    fn module(&self, device_id: u32) -> &Module {
        &self.modules[self.index(device_id)]
    }

    /// The reset button (or RTS): every bootloader starts over, RAM buffers are lost, the main
    /// board's window opens.
    pub fn reset(&mut self) {
        // A module that stopped acknowledging works again after a reset.
        self.faults.silent_after = None;
        self.restart_bootloaders();
    }

    fn restart_bootloaders(&mut self) {
        for m in &mut self.modules {
            m.connected = false;
            m.started = false;
            m.dead = false;
            m.rx = None;
            m.flash.reset_buffers();
        }
        self.mode = Mode::Bootloader;
        self.window_until = self.now + self.timing.window_ns;
        self.was_main_connection = false;
        self.other = None;
        self.uart_rx = None;
        self.busy_until = self.now;
        self.out.clear();
        self.log.push(format!("{} reset", self.ms()));
    }

    /// The RTS line was pulsed; resets if the cable wires it.
    pub fn rts_pulse(&mut self) -> bool {
        if self.rts_wired {
            self.reset();
        }
        self.rts_wired
    }

    fn ms(&self) -> String {
        format!("[{:>9.3} ms]", self.now as f64 / 1e6)
    }

    /// Runs the timers up to `t`.
    pub fn advance(&mut self, t: u64) {
        self.now = self.now.max(t);
        let session_open = self.modules[0].connected || self.other.is_some();
        // Without a valid application the bootloader stays, whatever the timers say.
        if session_open || !self.modules[0].flash.app_valid() {
            return;
        }
        if self.mode == Mode::Bootloader && self.now >= self.window_until {
            self.start_robot("window closed");
        } else if self.mode == Mode::Flashing
            && self.was_main_connection
            && self.now >= self.last_traffic + self.timing.flash_mode_timeout_ns
        {
            self.start_robot("30 s without host traffic");
        }
    }

    fn start_robot(&mut self, why: &str) {
        self.mode = Mode::Application;
        for m in &mut self.modules {
            m.started = m.flash.app_valid();
            m.connected = false;
        }
        let started: Vec<&str> = self
            .modules
            .iter()
            .filter(|m| m.started)
            .map(|m| m.spec.name.as_str())
            .collect();
        self.log.push(format!(
            "{} applications started ({why}): {started:?}",
            self.ms()
        ));
    }

    /// When the next reply byte arrives at the host, if one is on its way.
    pub fn next_output_at(&self) -> Option<u64> {
        self.out.front().map(|(t, _)| *t)
    }

    /// The next reply byte if it has arrived by `t`.
    pub fn take_output(&mut self, t: u64) -> Option<u8> {
        match self.out.front() {
            Some((at, _)) if *at <= t => self.out.pop_front().map(|(_, b)| b),
            _ => None,
        }
    }

    /// One byte from the host, fully received at `t`.
    pub fn host_byte(&mut self, t: u64, byte: u8) {
        self.advance(t);
        let index = self.host_bytes;
        self.host_bytes += 1;
        if self.faults.drop_host_byte == Some(index) {
            self.log
                .push(format!("{} host byte {index} lost", self.ms()));
            return;
        }
        let byte = match self.faults.corrupt_host_byte {
            Some((i, mask)) if i == index => byte ^ mask,
            _ => byte,
        };
        if matches!(self.mode, Mode::Application | Mode::Hung(_)) {
            return;
        }
        match self.uart_rx.as_mut() {
            None if byte == 0 => {}
            None => self.uart_rx = Some((usize::from(byte), Vec::new())),
            Some((len, buf)) => {
                buf.push(byte);
                if buf.len() == *len {
                    let packet = std::mem::take(buf);
                    self.uart_rx = None;
                    let start = self.now.max(self.busy_until);
                    self.last_traffic = start;
                    let (reply, cost) = self.main_packet(&packet);
                    self.busy_until = start + cost;
                    if let Some(reply) = reply {
                        self.send_reply(&reply);
                    }
                }
            }
        }
    }

    fn send_reply(&mut self, reply: &[u8]) {
        let byte_ns = self.timing.byte_ns();
        let mut t = self.busy_until.max(self.out.back().map_or(0, |(t, _)| *t));
        let mut framed = vec![reply.len() as u8];
        framed.extend_from_slice(reply);
        for b in framed {
            let index = self.reply_bytes;
            self.reply_bytes += 1;
            let b = match self.faults.corrupt_reply_byte {
                Some((i, mask)) if i == index => b ^ mask,
                _ => b,
            };
            t += byte_ns;
            self.out.push_back((t, b));
        }
        // Transmission is blocking in the bootloader.
        self.busy_until = t;
    }

    /// The main board's handling of one UART packet: (reply, processing time).
    fn main_packet(&mut self, packet: &[u8]) -> (Option<Vec<u8>>, u64) {
        if packet[0] == CONNECT {
            let id = match packet.len() {
                2 => u32::from(packet[1]),
                5 => u32::from_le_bytes([packet[1], packet[2], packet[3], packet[4]]),
                n => {
                    self.hang(format!("SOS: CONNECT of {n} bytes"));
                    return (None, 0);
                }
            };
            if id == 0 || self.modules[0].answers_to(id) {
                self.other = None;
                if id == 0 {
                    self.was_main_connection = true;
                }
                if self.mode == Mode::Bootloader {
                    self.mode = Mode::Flashing;
                }
                return self.module_packet(0, packet);
            }
            self.modules[0].connected = false;
            self.other = Some(id);
            if self.mode == Mode::Bootloader {
                self.mode = Mode::Flashing;
            }
            return self.forward(id, packet.to_vec());
        }
        if self.modules[0].connected {
            if packet[0] == PROGRAM_RESET {
                self.modules[0].connected = false;
                if self.modules[0].flash.app_valid() {
                    self.start_robot("PROGRAM_RESET");
                    return (None, 0);
                }
                self.log.push(format!(
                    "{} PROGRAM_RESET: checksum invalid, staying",
                    self.ms()
                ));
                return (Some(vec![0xFF]), 0);
            }
            return self.module_packet(0, packet);
        }
        if let Some(id) = self.other {
            let mut packet = packet.to_vec();
            if packet[0] == PROGRAM_RESET {
                // Only the main board restarts the robot.
                packet[0] = DISCONNECT;
            }
            if packet[0] == DISCONNECT {
                self.other = None;
            }
            return self.forward(id, packet);
        }
        (None, 0)
    }

    fn hang(&mut self, why: String) {
        self.log
            .push(format!("{} main board hangs: {why}", self.ms()));
        self.mode = Mode::Hung(why);
    }

    /// Frames of a packet as the gateway's transmit routine builds them: (id, dlc, data).
    fn frames(packet: &[u8], base: u16, device_id: u32) -> Vec<(u16, usize, [u8; 8])> {
        let total = packet.len();
        let mut left = total;
        let mut out = Vec::new();
        let mut id = base;
        while left > 0 {
            let mut d = [0u8; 8];
            let (dlc, mut k) = if left == total {
                d[..4].copy_from_slice(&device_id.to_le_bytes());
                d[4] = left as u8;
                (if left > 4 { 8 } else { left + 5 }, 5)
            } else {
                d[0] = left as u8;
                (if left > 7 { 8 } else { left + 1 }, 1)
            };
            while left > 0 && k < 8 {
                d[k] = packet[total - left];
                k += 1;
                left -= 1;
            }
            out.push((id, dlc, d));
            id = base | 0x002;
        }
        out
    }

    /// Takes the payload of a received frame the way the receive routine does (the DLC can
    /// exceed 8; the byte past the mailbox reads as 0).
    fn payload(dlc: usize, data: &[u8; 8], from: usize) -> Vec<u8> {
        (from..dlc)
            .map(|i| data.get(i).copied().unwrap_or(0))
            .collect()
    }

    /// Forwards a packet to a module over CAN, frame by frame, each waiting for its
    /// acknowledgement; returns the module's reply as the gateway receives it.
    fn forward(&mut self, id: u32, packet: Vec<u8>) -> (Option<Vec<u8>>, u64) {
        let mut cost = 0;
        let ack_ns = self.timing.frame_ns(1);
        let mut delivered: Option<(usize, Vec<u8>)> = None;
        for (can_id, dlc, data) in Self::frames(&packet, 0x600, id) {
            cost += self.timing.frame_ns(dlc);
            let mut acked = false;
            for i in 1..self.modules.len() {
                let m = &mut self.modules[i];
                if m.dead {
                    continue;
                }
                let take = match (&m.rx, can_id) {
                    (None, 0x600) => {
                        let target = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
                        if m.answers_to(target) {
                            m.rx = Some((usize::from(data[4]), Vec::new()));
                            Some(5)
                        } else {
                            None
                        }
                    }
                    (Some(_), 0x602) => Some(1),
                    _ => None,
                };
                let Some(from) = take else { continue };
                let bytes = Self::payload(dlc, &data, from);
                let (want, buf) = m.rx.as_mut().expect("receiving");
                buf.extend(bytes);
                acked = true;
                cost += ack_ns;
                if buf.len() >= *want {
                    let mut got = std::mem::take(buf);
                    got.truncate(*want);
                    m.rx = None;
                    delivered = Some((i, got));
                }
                break;
            }
            if !acked {
                let why =
                    format!("waits forever for the acknowledgement of CAN frame {can_id:#05x}");
                self.hang(why);
                return (None, cost);
            }
        }
        let Some((i, got)) = delivered else {
            return (None, cost);
        };
        let stamp = self.ms();
        let m = &mut self.modules[i];
        m.packets += 1;
        if let Some((dev, after)) = self.faults.silent_after {
            if dev == m.spec.device_id && m.packets >= after {
                m.dead = true;
                let line = format!("{stamp} {} stops acknowledging", m.spec.name);
                self.log.push(line);
            }
        }
        let (reply, work) = self.module_packet(i, &got);
        cost += work;
        let Some(reply) = reply else {
            return (None, cost);
        };
        // Back to the gateway, which acknowledges each frame it takes.
        let mut at_gateway: Option<(usize, Vec<u8>)> = None;
        for (can_id, dlc, data) in Self::frames(&reply, 0x700, 0) {
            cost += self.timing.frame_ns(dlc);
            let take = match (&at_gateway, can_id) {
                (None, 0x700) if data[..4] == [0, 0, 0, 0] => {
                    at_gateway = Some((usize::from(data[4]), Vec::new()));
                    Some(5)
                }
                (Some(_), 0x702) => Some(1),
                _ => None,
            };
            let Some(from) = take else {
                let name = self.modules[i].spec.name.clone();
                self.modules[i].dead = true;
                self.log.push(format!(
                    "{} {name} waits forever for the gateway's acknowledgement",
                    self.ms()
                ));
                break;
            };
            let (want, buf) = at_gateway.as_mut().expect("receiving");
            buf.extend(Self::payload(dlc, &data, from));
            cost += ack_ns;
            if buf.len() >= *want {
                let mut whole = std::mem::take(buf);
                whole.truncate(*want);
                return (Some(whole), cost);
            }
        }
        (None, cost)
    }

    /// One board's XCP slave: (reply, processing time).
    fn module_packet(&mut self, i: usize, packet: &[u8]) -> (Option<Vec<u8>>, u64) {
        let costs = self.timing.flash_costs;
        let nak = self.faults.nak;
        let m = &mut self.modules[i];
        let code = packet[0];
        let arg = |k: usize| packet.get(k).copied().unwrap_or(0);
        let word = |k: usize| u32::from_le_bytes([arg(k), arg(k + 1), arg(k + 2), arg(k + 3)]);
        if code == CONNECT {
            if packet.len() != 2 && packet.len() != 5 {
                m.dead = true;
                return (None, 0);
            }
            m.connected = true;
            return (Some(vec![0xFF, 0x10, 0x00, MAX_CTO as u8, 255, 0, 1, 1]), 0);
        }
        if !m.connected {
            return (None, 0);
        }
        m.counts[usize::from(code)] += 1;
        if let Some(n) = nak {
            let count = m.counts[usize::from(code)];
            if n.device_id == m.spec.device_id
                && n.command == code
                && (count == n.occurrence || (n.persistent && count >= n.occurrence))
            {
                return (Some(vec![0xFE, n.code]), 0);
            }
        }
        let ok = |r: Result<(), crate::flash::FlashError>, f: &Flash| -> (Option<Vec<u8>>, u64) {
            let cost = if costs { f.last_cost_ns } else { 0 };
            match r {
                Ok(()) => (Some(vec![0xFF]), cost),
                Err(_) => (Some(vec![0xFE, ERR_GENERIC]), cost),
            }
        };
        match code {
            DISCONNECT => {
                m.connected = false;
                (Some(vec![0xFF]), 0)
            }
            SET_MTA => {
                m.mta = word(4);
                (Some(vec![0xFF]), 0)
            }
            UPLOAD => {
                let n = usize::from(arg(1));
                if n > MAX_CTO - 1 {
                    return (Some(vec![0xFE, ERR_OUT_OF_RANGE]), 0);
                }
                let mut r = vec![0xFF];
                r.extend(m.flash.read(m.mta, n));
                m.mta = m.mta.wrapping_add(n as u32);
                (Some(r), 0)
            }
            PROGRAM_START => (Some(vec![0xFF, 0, 0, MAX_CTO as u8, 0, 0, 0]), 0),
            PROGRAM_CLEAR => {
                let r = m.flash.erase(m.mta, word(4));
                ok(r, &m.flash)
            }
            PROGRAM => {
                let n = usize::from(arg(1));
                if n > MAX_CTO - 2 {
                    return (Some(vec![0xFE, ERR_OUT_OF_RANGE]), 0);
                }
                if n == 0 {
                    let r = m.flash.done();
                    return ok(r, &m.flash);
                }
                let data: Vec<u8> = (0..n).map(|k| arg(2 + k)).collect();
                let r = m.flash.write(m.mta, &data);
                m.mta = m.mta.wrapping_add(n as u32);
                ok(r, &m.flash)
            }
            PROGRAM_MAX => {
                let data: Vec<u8> = (0..MAX_CTO - 1).map(|k| arg(1 + k)).collect();
                let r = m.flash.write(m.mta, &data);
                m.mta = m.mta.wrapping_add(data.len() as u32);
                ok(r, &m.flash)
            }
            PROGRAM_RESET => {
                // A module never starts on its own: the main board turns a forwarded reset into
                // DISCONNECT. Reached only if a host talks to a module directly.
                m.connected = false;
                (Some(vec![0xFF]), 0)
            }
            _ => (Some(vec![0xFE, ERR_UNKNOWN]), 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn send(r: &mut Robot, t: &mut u64, packet: &[u8]) -> Vec<u8> {
        let mut framed = vec![packet.len() as u8];
        framed.extend_from_slice(packet);
        for b in framed {
            *t += 1000;
            r.host_byte(*t, b);
        }
        let mut out = Vec::new();
        while let Some(b) = r.take_output(u64::MAX) {
            out.push(b);
        }
        out
    }

    #[test]
    fn the_gateway_forwards_and_a_four_byte_packet_hangs_it() {
        let mut r = Robot::new(BoardSpec::robot_1_2(), Timing::instant(), Faults::default());
        let mut t = 0;
        assert_eq!(send(&mut r, &mut t, &[0xFF, 0])[..2], [8, 0xFF]);
        assert_eq!(send(&mut r, &mut t, &[0xFE]), [1, 0xFF]);
        let lr = 0x017F_0102u32;
        let mut connect = vec![0xFF];
        connect.extend(lr.to_le_bytes());
        assert_eq!(send(&mut r, &mut t, &connect)[..2], [8, 0xFF]);
        assert_eq!(
            send(&mut r, &mut t, &[0xF6, 0, 0, 0, 0, 0, 0, 8]),
            [1, 0xFF]
        );
        assert_eq!(send(&mut r, &mut t, &[0xF5, 4])[..2], [5, 0xFF]);
        assert_eq!(*r.mode(), Mode::Flashing);
        assert!(send(&mut r, &mut t, &[0xD0, 2, 1, 2]).is_empty());
        assert!(matches!(r.mode(), Mode::Hung(_)), "{:?}", r.log);
    }

    #[test]
    fn a_connect_to_an_absent_id_hangs_the_main_board() {
        let mut r = Robot::new(BoardSpec::robot_1_2(), Timing::instant(), Faults::default());
        let mut t = 0;
        assert!(send(&mut r, &mut t, &[0xFF, 9, 9, 9, 9]).is_empty());
        assert!(matches!(r.mode(), Mode::Hung(_)));
        r.reset();
        assert_eq!(send(&mut r, &mut t, &[0xFF, 0])[..2], [8, 0xFF]);
    }

    #[test]
    fn no_connect_to_a_module_id_is_safe_on_both_robots() {
        // A 1-2 robot knows no legacy ids, and neither robot owns the other's 32-bit ids: each
        // such CONNECT goes to the gateway and hangs the main board (why the host reads the
        // main board's own id from its bootloader instead of trying ids).
        for (robot, connect) in [
            (BoardSpec::robot_1_2(), vec![0xFF, 1]),
            (BoardSpec::robot_1_2(), vec![0xFF, 0x01, 0x01, 0x00, 0x01]),
            (BoardSpec::robot_1_1(), vec![0xFF, 0x02, 0x01, 0x00, 0x01]),
        ] {
            let mut r = Robot::new(robot, Timing::instant(), Faults::default());
            let mut t = 0;
            assert!(send(&mut r, &mut t, &connect).is_empty());
            assert!(matches!(r.mode(), Mode::Hung(_)), "{connect:x?}");
        }
    }
}
