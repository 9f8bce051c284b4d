//! The flashing session: find the main board in its window, then per board connect, check,
//! erase, program, finish, verify, disconnect; restart the robot once at the end.
//!
//! The bootloader's packets carry no sequence number or checksum, so the session trusts a reply
//! only as far as it can check it: a lost or garbled reply is answered by resynchronising the
//! line (a burst of zero bytes completes any half-received packet, the rest are empty packets)
//! and repeating the command from a fresh SET_MTA; a refusal or a read-back that differs sends
//! the whole board round again from the erase. A board is reported done only after every byte
//! and the checksum word have been read back; if the read-back fails, the session erases the
//! first page again, so no half-written board is left with a valid checksum.
use std::time::Duration;

use crate::error::Error;
use crate::frame::{self, Deframer};
use crate::gateway;
use crate::identify::{self, Identification};
use crate::image::Image;
use crate::target::Target;
use crate::transport::Transport;
use crate::xcp::{ByteOrder, Command, ConnectInfo, ErrorCode, Reply, Select};

/// Where every AMiRo-BLT keeps its callback table, and the magics that mark it.
const CALLBACK_TABLE: u32 = 0x0800_01C0;
const BLT_MAGIC: u32 = 0x412D_424C;
const BLT_LEGACY_MAGIC: u32 = 0xFF66_9900;
/// Start of flash: the bootloader's own vector table.
const FLASH_BASE: u32 = 0x0800_0000;
/// Zero bytes sent to resynchronise: enough to complete the longest packet.
const RESYNC_BYTES: usize = 256;

/// Timeouts and retry counts.
#[derive(Debug, Clone)]
pub struct Options {
    /// How long to wait for the answer to one CONNECT.
    pub connect_reply: Duration,
    /// Pause between CONNECTs while knocking for the main board's window.
    pub knock_interval: Duration,
    /// How long to keep knocking before giving up with [`Error::NoAnswer`].
    pub window_patience: Duration,
    /// CONNECT attempts for a board behind the gateway (SerialBoot makes 50, 20 ms apart).
    pub connect_tries: u32,
    /// Timeout of an ordinary command.
    pub command_timeout: Duration,
    /// Timeout of PROGRAM_CLEAR and of the final PROGRAM (erase and flush are synchronous).
    pub erase_timeout: Duration,
    /// How often one command is repeated after a timeout, a garbled reply or ERR_CMD_BUSY.
    pub retries: u32,
    /// How often a board is started from the erase again after a refusal or a bad read-back.
    pub image_attempts: u32,
    /// Reset the main board through the cable's RTS line instead of asking the user.
    pub reset_line: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            connect_reply: Duration::from_millis(50),
            knock_interval: Duration::from_millis(20),
            window_patience: Duration::from_secs(60),
            connect_tries: 20,
            command_timeout: Duration::from_secs(2),
            erase_timeout: Duration::from_secs(30),
            retries: 3,
            image_attempts: 2,
            reset_line: false,
        }
    }
}

/// What the session is doing with a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Connecting and checking which board answered.
    Checking,
    /// PROGRAM_CLEAR of the application region.
    Erasing,
    /// Writing the image.
    Programming,
    /// Reading it back.
    Verifying,
}

/// Progress and prompts, for a front end to show.
#[derive(Debug)]
pub enum Event<'a> {
    /// Nothing answers: the user should press the robot's reset button now.
    PressReset,
    /// The session pulsed the cable's reset line.
    ResetLinePulsed,
    /// The main board answered and stays in its bootloader until the session restarts it.
    FlashMode,
    /// A board entered a phase; `total` is the byte count of the phase (0 where none).
    Phase {
        /// The board.
        target: &'a Target,
        /// The phase.
        phase: Phase,
        /// Bytes the phase moves.
        total: usize,
    },
    /// Bytes of the current phase done so far.
    Progress {
        /// The board.
        target: &'a Target,
        /// Bytes done.
        done: usize,
    },
    /// Something failed and is being tried again.
    Retry {
        /// What failed.
        reason: String,
    },
}

/// Receives [`Event`]s.
pub trait Observer {
    /// One event.
    fn event(&mut self, event: Event<'_>);
}

impl Observer for () {
    fn event(&mut self, _: Event<'_>) {}
}

/// What one board's flashing took.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Report {
    /// Bytes programmed (and read back).
    pub bytes: usize,
    /// Rounds from the erase (1 when nothing had to be repeated).
    pub attempts: u32,
    /// Commands repeated after a timeout, garbled reply or busy answer.
    pub retries: u32,
}

/// What the final PROGRAM_RESET did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestartOutcome {
    /// The main board went quiet: it started its application and the robot with it.
    Started,
    /// It answered and kept running its bootloader (its checksum does not verify, or the
    /// bootloader's start hook refused after a connection in the window): power-cycle the robot.
    StayedInBootloader,
}

/// Why one exchange failed.
#[derive(Debug)]
enum Trouble {
    Timeout,
    Garbled(String),
    Nak(ErrorCode),
    Io(std::io::Error),
}

impl Trouble {
    /// Whether trying again cannot help: a refusal other than busy, or the port failing.
    fn is_final(&self) -> bool {
        match self {
            Trouble::Nak(code) => *code != ErrorCode::CmdBusy,
            Trouble::Io(_) => true,
            Trouble::Timeout | Trouble::Garbled(_) => false,
        }
    }

    fn describe(&self) -> String {
        match self {
            Trouble::Timeout => "no reply".into(),
            Trouble::Garbled(why) => format!("garbled reply: {why}"),
            Trouble::Nak(code) => format!("refused with {code}"),
            Trouble::Io(e) => format!("port error: {e}"),
        }
    }
}

/// Drives AMiRo-BLT over a [`Transport`].
pub struct Flasher<T: Transport> {
    link: T,
    opts: Options,
    order: ByteOrder,
    max_cto: u8,
    max_dto: u16,
    deframer: Deframer,
    /// The MTA the target holds, as far as the session knows.
    mta: Option<u32>,
    retries: u32,
}

impl<T: Transport> Flasher<T> {
    /// A session over `link`.
    pub fn new(link: T, opts: Options) -> Self {
        Flasher {
            link,
            opts,
            order: ByteOrder::Little,
            max_cto: 8,
            max_dto: 8,
            deframer: Deframer::new(),
            mta: None,
            retries: 0,
        }
    }

    /// The link, for a caller that wants it back.
    pub fn link(&mut self) -> &mut T {
        &mut self.link
    }

    /// Knocks (CONNECT to the serial board) until the main board answers in its window after a
    /// reset, then disconnects: from then on it stays in its bootloader and forwards to others.
    pub fn enter_flash_mode(&mut self, obs: &mut dyn Observer) -> Result<(), Error> {
        let start = self.link.clock();
        let mut last_pulse: Option<Duration> = None;
        let mut prompted = false;
        let mut knocks = 0u32;
        loop {
            let now = self.link.clock();
            if self.opts.reset_line
                && last_pulse.is_none_or(|t| now.saturating_sub(t) >= Duration::from_secs(2))
                && self.link.pulse_reset()?
            {
                obs.event(Event::ResetLinePulsed);
                last_pulse = Some(now);
            }
            match self.exchange(
                &Command::Connect(Select::SerialBoard),
                self.opts.connect_reply,
            ) {
                Ok(Reply::Ok(body)) => {
                    self.learn(&body);
                    break;
                }
                Err(Trouble::Io(e)) => return Err(e.into()),
                _ => {}
            }
            knocks += 1;
            if knocks.is_multiple_of(5) {
                // A knock that lost a byte leaves the bootloader collecting a packet that
                // swallows the following knocks.
                self.resync();
            }
            if !prompted && last_pulse.is_none() {
                obs.event(Event::PressReset);
                prompted = true;
            }
            let waited = self.link.clock().saturating_sub(start);
            if waited >= self.opts.window_patience {
                return Err(Error::NoAnswer { waited });
            }
            self.link.pause(self.opts.knock_interval);
        }
        // The knock may have left a second answer on the way; DISCONNECT is harmless to repeat.
        self.plain(
            &Command::Disconnect,
            self.opts.command_timeout,
            "main board",
        )
        .map_err(|t| self.lost("main board", 0, 0, t))?;
        obs.event(Event::FlashMode);
        Ok(())
    }

    /// Learns which board is on the serial port, and so the robot's revision, without a CONNECT
    /// to any module: CONNECT(0) (always answered by the main board itself), UPLOAD of the
    /// first 24 KiB of its flash (its bootloader on either chip) and DISCONNECT; then looks
    /// for the known main boards' ids in that code ([`crate::identify`]). Call after
    /// [`Self::enter_flash_mode`]; it erases and writes nothing.
    pub fn identify_main_board(&mut self) -> Result<Identification, Error> {
        self.connect_serial_board()?;
        let (start, end) = identify::BOOTLOADER_SCAN;
        let limit = self.upload_limit();
        let mut code = Vec::with_capacity((end - start) as usize);
        let mut address = start;
        for size in upload_chunks((end - start) as usize, limit) {
            let body = self
                .at(
                    address,
                    &Command::Upload(size as u8),
                    self.opts.command_timeout,
                    "main board",
                )
                .map_err(|t| self.lost("the main board", 0, 0, t))?;
            code.extend_from_slice(&body[..size]);
            address += size as u32;
        }
        self.plain(
            &Command::Disconnect,
            self.opts.command_timeout,
            "main board",
        )
        .map_err(|t| self.lost("the main board", 0, 0, t))?;
        Ok(identify::ids_in_code(&code))
    }

    /// Connects and checks a board through the gateway, then disconnects: nothing is erased.
    /// A session calls this for every board of a run before flashing any, so a board that does
    /// not answer to its id stops the run while every board is still untouched.
    pub fn greet(&mut self, target: &Target) -> Result<(), Error> {
        self.connect(target)?;
        self.check_identity(target)?;
        self.plain(
            &Command::Disconnect,
            self.opts.command_timeout,
            &target.name,
        )
        .map_err(|t| self.lost(&target.name, 0, 0, t))?;
        Ok(())
    }

    /// Flashes one board: refuses an image that does not fit before anything is sent, then
    /// connects through the gateway, checks the board, erases, programs, finishes (the
    /// bootloader writes the checksum), reads everything back and disconnects.
    pub fn flash(
        &mut self,
        target: &Target,
        image: &Image,
        obs: &mut dyn Observer,
    ) -> Result<Report, Error> {
        image.check_for(target)?;
        let retries_before = self.retries;
        let mut attempt = 1;
        loop {
            match self.flash_once(target, image, obs) {
                Ok(()) => {
                    return Ok(Report {
                        bytes: image.len(),
                        attempts: attempt,
                        retries: self.retries - retries_before,
                    })
                }
                Err(e @ (Error::Xcp { .. } | Error::VerifyFailed { .. }))
                    if attempt < self.opts.image_attempts =>
                {
                    obs.event(Event::Retry {
                        reason: format!("{e}; starting {} again from the erase", target.name),
                    });
                    self.resync();
                    attempt += 1;
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Restarts the robot: CONNECT to the serial board and PROGRAM_RESET.
    pub fn restart(&mut self) -> Result<RestartOutcome, Error> {
        self.connect_serial_board()?;
        match self.exchange(&Command::ProgramReset, Duration::from_secs(1)) {
            Err(Trouble::Timeout) => Ok(RestartOutcome::Started),
            Ok(Reply::Ok(_)) => Ok(RestartOutcome::StayedInBootloader),
            Ok(Reply::Err(code)) => Err(Error::Xcp {
                board: "the main board".into(),
                command: "PROGRAM_RESET",
                code,
            }),
            Err(Trouble::Io(e)) => Err(e.into()),
            Err(t) => Err(self.lost("the main board", 0, 0, t)),
        }
    }

    fn flash_once(
        &mut self,
        target: &Target,
        image: &Image,
        obs: &mut dyn Observer,
    ) -> Result<(), Error> {
        let name = target.name.as_str();
        let total = image.len();
        obs.event(Event::Phase {
            target,
            phase: Phase::Checking,
            total: 0,
        });
        self.connect(target)?;
        self.check_identity(target)?;
        let start = self
            .plain(&Command::ProgramStart, self.opts.command_timeout, name)
            .map_err(|t| self.refused_or_lost(target, "PROGRAM_START", 0, total, t))?;
        // PROGRAM_START's reply: reserved, comm mode, MAX_CTO_PGM, ...
        let max_pgm = start.get(2).copied().unwrap_or(self.max_cto).max(8);

        obs.event(Event::Phase {
            target,
            phase: Phase::Erasing,
            total: 0,
        });
        let erase_len = image.end() - target.app_origin;
        self.at(
            target.app_origin,
            &Command::ProgramClear(erase_len),
            self.opts.erase_timeout,
            name,
        )
        .map_err(|t| self.refused_or_lost(target, "PROGRAM_CLEAR", 0, total, t))?;

        obs.event(Event::Phase {
            target,
            phase: Phase::Programming,
            total,
        });
        let mut done = 0;
        for segment in image.segments() {
            let mut address = segment.address;
            for size in program_chunks(segment.data.len(), max_pgm, self.max_cto) {
                let offset = (address - segment.address) as usize;
                let data = segment.data[offset..offset + size].to_vec();
                let command = if size + 1 == usize::from(max_pgm) {
                    Command::ProgramMax(data)
                } else {
                    Command::Program(data)
                };
                let name_of = command.name();
                self.at(address, &command, self.opts.command_timeout, name)
                    .map_err(|t| self.refused_or_lost(target, name_of, done, total, t))?;
                address += size as u32;
                done += size;
                obs.event(Event::Progress { target, done });
            }
        }
        // From here on the bootloader may have written the checksum: any failure invalidates.
        let finished = self
            .plain(&Command::Program(Vec::new()), self.opts.erase_timeout, name)
            .map_err(|t| self.refused_or_lost(target, "PROGRAM (end)", done, total, t));
        if let Err(e) = finished {
            self.invalidate(target);
            return Err(e);
        }

        obs.event(Event::Phase {
            target,
            phase: Phase::Verifying,
            total,
        });
        if let Err(e) = self.verify(target, image, obs) {
            self.invalidate(target);
            return Err(e);
        }
        self.plain(&Command::Disconnect, self.opts.command_timeout, name)
            .map_err(|t| self.lost(name, total, total, t))?;
        Ok(())
    }

    /// CONNECT(0): the board on the serial port answers itself, never the gateway.
    fn connect_serial_board(&mut self) -> Result<(), Error> {
        for _ in 0..self.opts.connect_tries {
            match self.exchange(
                &Command::Connect(Select::SerialBoard),
                self.opts.connect_reply,
            ) {
                Ok(Reply::Ok(body)) => {
                    self.learn(&body);
                    return Ok(());
                }
                Err(Trouble::Io(e)) => return Err(e.into()),
                _ => self.link.pause(self.opts.knock_interval),
            }
        }
        Err(Error::NoAnswerFromBoard {
            board: "the main board".into(),
            id: 0,
        })
    }

    /// The largest UPLOAD the connected board's CTO and DTO allow (at most 254 bytes).
    fn upload_limit(&self) -> usize {
        usize::from(self.max_cto)
            .min(usize::from(self.max_dto))
            .saturating_sub(1)
            .clamp(1, 254)
    }

    fn connect(&mut self, target: &Target) -> Result<(), Error> {
        let command = Command::Connect(Select::Device(target.device_id));
        for _ in 0..self.opts.connect_tries {
            match self.exchange(&command, self.opts.connect_reply) {
                Ok(Reply::Ok(body)) => {
                    self.learn(&body);
                    return Ok(());
                }
                Err(Trouble::Io(e)) => return Err(e.into()),
                _ => {
                    self.resync();
                    self.link.pause(self.opts.knock_interval);
                }
            }
        }
        Err(Error::NoAnswerFromBoard {
            board: target.name.clone(),
            id: target.device_id,
        })
    }

    /// Reads the answering bootloader's stack pointer and callback table: a board whose
    /// bootloader was linked for another chip, or that is no AMiRo-BLT, is refused before
    /// anything is erased.
    fn check_identity(&mut self, target: &Target) -> Result<(), Error> {
        let name = target.name.as_str();
        let sp = self
            .read_word(FLASH_BASE, name)
            .map_err(|t| self.refused_or_lost(target, "UPLOAD", 0, 0, t))?;
        let magic = self
            .read_word(CALLBACK_TABLE, name)
            .map_err(|t| self.refused_or_lost(target, "UPLOAD", 0, 0, t))?;
        let found = if !target.chip.accepts_stack_pointer(sp) {
            Some(format!(
                "its bootloader's initial stack pointer is {sp:#010x}, outside the RAM of an {}",
                target.chip
            ))
        } else if magic != BLT_MAGIC && magic != BLT_LEGACY_MAGIC {
            Some(format!(
                "no AMiRo-BLT callback table at {CALLBACK_TABLE:#010x} (found {magic:#010x})"
            ))
        } else {
            None
        };
        if let Some(found) = found {
            let _ = self.plain(&Command::Disconnect, self.opts.command_timeout, name);
            return Err(Error::WrongBoard {
                board: target.name.clone(),
                id: target.device_id,
                found,
            });
        }
        Ok(())
    }

    fn read_word(&mut self, address: u32, name: &str) -> Result<u32, Trouble> {
        let body = self.at(
            address,
            &Command::Upload(4),
            self.opts.command_timeout,
            name,
        )?;
        Ok(ByteOrder::Little.read_u32([body[0], body[1], body[2], body[3]]))
    }

    fn verify(
        &mut self,
        target: &Target,
        image: &Image,
        obs: &mut dyn Observer,
    ) -> Result<(), Error> {
        let name = target.name.as_str();
        let total = image.len();
        let limit = self.upload_limit();
        let mut done = 0;
        for segment in image.expected_flash(target) {
            let mut address = segment.address;
            for size in upload_chunks(segment.data.len(), limit) {
                let body = self
                    .at(
                        address,
                        &Command::Upload(size as u8),
                        self.opts.command_timeout,
                        name,
                    )
                    .map_err(|t| self.refused_or_lost(target, "UPLOAD", total, total, t))?;
                let offset = (address - segment.address) as usize;
                let expected = &segment.data[offset..offset + size];
                if let Some(i) = (0..size).find(|&i| body[i] != expected[i]) {
                    return Err(Error::VerifyFailed {
                        board: target.name.clone(),
                        address: address + i as u32,
                        expected: expected[i],
                        found: body[i],
                    });
                }
                address += size as u32;
                done = (done + size).min(total);
                obs.event(Event::Progress { target, done });
            }
        }
        Ok(())
    }

    /// Erases the page holding the vector table and checksum again (best effort): the board
    /// then stays in its bootloader instead of starting a partly written application.
    fn invalidate(&mut self, target: &Target) {
        self.resync();
        let _ = self.at(
            target.app_origin,
            &Command::ProgramClear(target.checksum_offset + 4),
            self.opts.erase_timeout,
            &target.name,
        );
    }

    /// A command at `address`: SET_MTA first unless the target's MTA is known to be there;
    /// repeated after a timeout, garbled reply or busy answer.
    fn at(
        &mut self,
        address: u32,
        command: &Command,
        timeout: Duration,
        _board: &str,
    ) -> Result<Vec<u8>, Trouble> {
        self.retried(Some(address), command, timeout)
    }

    /// A command that does not depend on the MTA, repeated like [`Self::at`].
    fn plain(
        &mut self,
        command: &Command,
        timeout: Duration,
        _board: &str,
    ) -> Result<Vec<u8>, Trouble> {
        self.retried(None, command, timeout)
    }

    /// [`Self::at`] (`address` given) and [`Self::plain`]: up to `retries` more attempts after a timeout, a
    /// garbled reply or a busy answer, each after a resync; the MTA, where it matters, is forgotten after a
    /// failed command (the board's may have moved).
    fn retried(
        &mut self,
        address: Option<u32>,
        command: &Command,
        timeout: Duration,
    ) -> Result<Vec<u8>, Trouble> {
        let mut last = Trouble::Timeout;
        for attempt in 0..=self.opts.retries {
            if attempt > 0 {
                self.retries += 1;
                self.resync();
            }
            if let Some(address) = address.filter(|&a| self.mta != Some(a)) {
                match self.checked(&Command::SetMta(address), self.opts.command_timeout) {
                    Ok(_) => self.mta = Some(address),
                    Err(t) if t.is_final() => return Err(t),
                    Err(t) => {
                        last = t;
                        continue;
                    }
                }
            }
            match self.checked(command, timeout) {
                Ok(body) => {
                    if let Some(address) = address {
                        self.mta = Some(address + advance(command));
                    }
                    return Ok(body);
                }
                Err(t) => {
                    if address.is_some() && !matches!(t, Trouble::Io(_)) {
                        self.mta = None;
                    }
                    if t.is_final() {
                        return Err(t);
                    }
                    last = t;
                }
            }
        }
        Err(last)
    }

    /// One exchange whose positive reply must have the length the command implies.
    fn checked(&mut self, command: &Command, timeout: Duration) -> Result<Vec<u8>, Trouble> {
        match self.exchange(command, timeout)? {
            Reply::Err(code) => Err(Trouble::Nak(code)),
            Reply::Ok(body) => {
                let expected = match command {
                    Command::Upload(n) => Some(usize::from(*n)),
                    Command::ProgramStart => Some(6),
                    Command::Connect(_) => Some(7),
                    Command::Disconnect
                    | Command::SetMta(_)
                    | Command::ProgramClear(_)
                    | Command::Program(_)
                    | Command::ProgramMax(_)
                    | Command::ProgramReset => Some(0),
                };
                match expected {
                    Some(n) if body.len() != n => Err(Trouble::Garbled(format!(
                        "{} answered with {} bytes, expected {}",
                        command.name(),
                        body.len() + 1,
                        n + 1
                    ))),
                    _ => Ok(body),
                }
            }
        }
    }

    /// Sends one command and waits for one reply packet.
    fn exchange(&mut self, command: &Command, timeout: Duration) -> Result<Reply, Trouble> {
        self.drain().map_err(Trouble::Io)?;
        let packet = command.encode(self.order);
        debug_assert!(gateway::is_forwardable(packet.len()), "{command:?}");
        let framed =
            frame::encode(&packet).ok_or_else(|| Trouble::Garbled("packet too long".into()))?;
        self.link.send(&framed).map_err(Trouble::Io)?;
        let deadline = self.link.clock() + timeout;
        let mut buf = [0u8; 512];
        loop {
            let left = deadline.saturating_sub(self.link.clock());
            if left.is_zero() {
                self.deframer.clear();
                return Err(Trouble::Timeout);
            }
            let n = self.link.receive(&mut buf, left).map_err(Trouble::Io)?;
            for (i, &byte) in buf[..n].iter().enumerate() {
                if let Some(reply) = self.deframer.push(byte) {
                    if i + 1 < n {
                        return Err(Trouble::Garbled("bytes after the reply".into()));
                    }
                    return Reply::parse(&reply).ok_or_else(|| {
                        Trouble::Garbled(format!("reply starts with {:#04x}", reply[0]))
                    });
                }
            }
        }
    }

    /// Drops whatever arrived unasked (a late reply to a command that timed out).
    fn drain(&mut self) -> std::io::Result<()> {
        let mut buf = [0u8; 512];
        while self.link.receive(&mut buf, Duration::ZERO)? > 0 {}
        self.deframer.clear();
        Ok(())
    }

    /// Completes any packet the bootloader is still collecting and discards what it answers.
    fn resync(&mut self) {
        self.mta = None;
        let _ = self.link.send(&[0u8; RESYNC_BYTES]);
        let mut buf = [0u8; 512];
        // Wait until the line has been quiet for a while (a completed junk command may answer).
        while let Ok(n) = self.link.receive(&mut buf, Duration::from_millis(100)) {
            if n == 0 {
                break;
            }
        }
        self.deframer.clear();
    }

    fn learn(&mut self, body: &[u8]) {
        if let Some(info) = ConnectInfo::parse(body) {
            self.order = info.order;
            self.max_cto = info.max_cto;
            self.max_dto = info.max_dto;
        }
        self.mta = None;
    }

    fn refused_or_lost(
        &self,
        target: &Target,
        command: &'static str,
        written: usize,
        total: usize,
        trouble: Trouble,
    ) -> Error {
        match trouble {
            Trouble::Nak(code) => Error::Xcp {
                board: target.name.clone(),
                command,
                code,
            },
            other => self.lost(&target.name, written, total, other),
        }
    }

    fn lost(&self, board: &str, written: usize, total: usize, trouble: Trouble) -> Error {
        match trouble {
            Trouble::Io(e) => Error::Io(e),
            other => Error::LostConnection {
                board: board.to_string(),
                written,
                total,
                reason: other.describe(),
            },
        }
    }
}

/// How far a command moves the MTA.
fn advance(command: &Command) -> u32 {
    match command {
        Command::Upload(n) => u32::from(*n),
        Command::Program(d) | Command::ProgramMax(d) => d.len() as u32,
        _ => 0,
    }
}

/// Chunk sizes for programming `len` bytes: PROGRAM_MAX's `max_pgm − 1` bytes while they last,
/// then PROGRAM (at most `max_cto − 2`), never a 4-byte packet (PROGRAM with 2 bytes), which
/// the gateway cannot forward.
pub fn program_chunks(len: usize, max_pgm: u8, max_cto: u8) -> Vec<usize> {
    let full = usize::from(max_pgm).saturating_sub(1).max(1);
    let program_max = usize::from(max_cto).saturating_sub(2).max(1);
    let mut chunks = Vec::new();
    let mut rest = len;
    while rest >= full {
        chunks.push(full);
        rest -= full;
    }
    split_avoiding(rest, program_max, 2, &mut chunks);
    chunks
}

/// Appends `len` bytes in chunks of at most `limit` to `chunks`, a chunk of `avoid` bytes (a size whose packet
/// the gateway cannot forward) one byte shorter.
fn split_avoiding(len: usize, limit: usize, avoid: usize, chunks: &mut Vec<usize>) {
    let mut rest = len;
    while rest > 0 {
        let mut n = rest.min(limit);
        if n == avoid {
            n -= 1;
        }
        chunks.push(n);
        rest -= n;
    }
}

/// Chunk sizes for reading `len` bytes back with UPLOAD (at most `limit` each), never a
/// 3-byte UPLOAD, whose 4-byte reply the gateway cannot forward.
pub fn upload_chunks(len: usize, limit: usize) -> Vec<usize> {
    let mut chunks = Vec::new();
    split_avoiding(len, limit, 3, &mut chunks);
    chunks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn programming_uses_the_largest_packets_and_skips_four_byte_ones() {
        assert_eq!(program_chunks(600, 255, 255), [254, 254, 92]);
        assert_eq!(program_chunks(256, 255, 255), [254, 1, 1]);
        for len in 0..2000 {
            let chunks = program_chunks(len, 255, 255);
            assert_eq!(chunks.iter().sum::<usize>(), len);
            assert!(chunks.iter().all(|&n| n != 2 && n <= 254));
        }
    }

    #[test]
    fn read_back_skips_three_byte_uploads() {
        assert_eq!(upload_chunks(257, 254), [254, 2, 1]);
        for len in 0..1000 {
            let chunks = upload_chunks(len, 254);
            assert_eq!(chunks.iter().sum::<usize>(), len);
            assert!(chunks.iter().all(|&n| n != 3));
        }
    }
}
