//! The XCP commands and replies AMiRo-BLT understands (its `xcp.c`), as bytes.
//!
//! Only the subset a flashing host needs is built here. Addresses and lengths inside a packet are
//! in the target's byte order, which CONNECT's reply announces (the STM32 boards say little-endian).
use std::fmt;

/// Command codes (first byte of a command packet).
pub mod code {
    /// CONNECT: opens a session; its mode field selects the board.
    pub const CONNECT: u8 = 0xFF;
    /// DISCONNECT: closes the session (a forwarding main board stops forwarding).
    pub const DISCONNECT: u8 = 0xFE;
    /// GET_STATUS.
    pub const GET_STATUS: u8 = 0xFD;
    /// SET_MTA: sets the memory transfer address.
    pub const SET_MTA: u8 = 0xF6;
    /// UPLOAD: reads bytes at the MTA and advances it.
    pub const UPLOAD: u8 = 0xF5;
    /// PROGRAM_START: opens programming; the reply carries MAX_CTO_PGM.
    pub const PROGRAM_START: u8 = 0xD2;
    /// PROGRAM_CLEAR: erases from the MTA.
    pub const PROGRAM_CLEAR: u8 = 0xD1;
    /// PROGRAM: writes up to MAX_CTO − 2 bytes at the MTA; zero bytes ends programming.
    pub const PROGRAM: u8 = 0xD0;
    /// PROGRAM_RESET: starts the application (on a main board: the robot).
    pub const PROGRAM_RESET: u8 = 0xCF;
    /// PROGRAM_MAX: writes exactly MAX_CTO_PGM − 1 bytes at the MTA.
    pub const PROGRAM_MAX: u8 = 0xC9;
}

/// First byte of a positive reply.
pub const PID_RES: u8 = 0xFF;
/// First byte of an error reply; the second byte is the [`ErrorCode`].
pub const PID_ERR: u8 = 0xFE;

/// How the target orders multi-byte fields (bit 0 of CONNECT's communication-mode byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ByteOrder {
    /// Intel order; what the STM32 bootloaders report.
    #[default]
    Little,
    /// Motorola order.
    Big,
}

impl ByteOrder {
    fn word(self, value: u32) -> [u8; 4] {
        match self {
            ByteOrder::Little => value.to_le_bytes(),
            ByteOrder::Big => value.to_be_bytes(),
        }
    }

    /// Reads a 32-bit word in this order.
    pub fn read_u32(self, bytes: [u8; 4]) -> u32 {
        match self {
            ByteOrder::Little => u32::from_le_bytes(bytes),
            ByteOrder::Big => u32::from_be_bytes(bytes),
        }
    }
}

/// Which board a CONNECT selects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Select {
    /// Id 0: the main board on the serial port itself.
    SerialBoard,
    /// A 32-bit device id (sent as a 5-byte CONNECT when it does not fit in one byte).
    Device(u32),
}

/// One command packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// CONNECT with its board selection.
    Connect(Select),
    /// DISCONNECT.
    Disconnect,
    /// SET_MTA to an address.
    SetMta(u32),
    /// UPLOAD of n bytes (1..=MAX_CTO − 1).
    Upload(u8),
    /// PROGRAM_START.
    ProgramStart,
    /// PROGRAM_CLEAR of a length in bytes from the MTA.
    ProgramClear(u32),
    /// PROGRAM of these bytes; empty ends programming (the bootloader then writes the checksum).
    Program(Vec<u8>),
    /// PROGRAM_MAX with exactly MAX_CTO_PGM − 1 bytes.
    ProgramMax(Vec<u8>),
    /// PROGRAM_RESET.
    ProgramReset,
}

impl Command {
    /// The packet bytes (without the SerialBoot length byte).
    pub fn encode(&self, order: ByteOrder) -> Vec<u8> {
        match self {
            Command::Connect(Select::SerialBoard) => vec![code::CONNECT, 0],
            Command::Connect(Select::Device(id)) if *id <= 0xFF => vec![code::CONNECT, *id as u8],
            Command::Connect(Select::Device(id)) => {
                let mut p = vec![code::CONNECT];
                // The bootloader reads the 5-byte form as little-endian regardless of byte order.
                p.extend_from_slice(&id.to_le_bytes());
                p
            }
            Command::Disconnect => vec![code::DISCONNECT],
            Command::SetMta(address) => {
                let mut p = vec![code::SET_MTA, 0, 0, 0];
                p.extend_from_slice(&order.word(*address));
                p
            }
            Command::Upload(n) => vec![code::UPLOAD, *n],
            Command::ProgramStart => vec![code::PROGRAM_START],
            Command::ProgramClear(len) => {
                let mut p = vec![code::PROGRAM_CLEAR, 0, 0, 0];
                p.extend_from_slice(&order.word(*len));
                p
            }
            Command::Program(data) => {
                let mut p = vec![code::PROGRAM, data.len() as u8];
                p.extend_from_slice(data);
                p
            }
            Command::ProgramMax(data) => {
                let mut p = vec![code::PROGRAM_MAX];
                p.extend_from_slice(data);
                p
            }
            Command::ProgramReset => vec![code::PROGRAM_RESET],
        }
    }

    /// The command's name as the XCP standard spells it.
    pub fn name(&self) -> &'static str {
        match self {
            Command::Connect(_) => "CONNECT",
            Command::Disconnect => "DISCONNECT",
            Command::SetMta(_) => "SET_MTA",
            Command::Upload(_) => "UPLOAD",
            Command::ProgramStart => "PROGRAM_START",
            Command::ProgramClear(_) => "PROGRAM_CLEAR",
            Command::Program(d) if d.is_empty() => "PROGRAM (end)",
            Command::Program(_) => "PROGRAM",
            Command::ProgramMax(_) => "PROGRAM_MAX",
            Command::ProgramReset => "PROGRAM_RESET",
        }
    }
}

/// The error codes AMiRo-BLT answers with (`0xFE`, code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    /// 0x00 ERR_CMD_SYNCH: the answer to SYNCH.
    CmdSynch,
    /// 0x10 ERR_CMD_BUSY: a command arrived before the previous answer left.
    CmdBusy,
    /// 0x20 ERR_CMD_UNKNOWN: unknown or unsupported command.
    CmdUnknown,
    /// 0x22 ERR_OUT_OF_RANGE: a length beyond the packet size.
    OutOfRange,
    /// 0x25 ERR_ACCESS_LOCKED: seed/key protection.
    AccessLocked,
    /// 0x26 ERR_PAGE_NOT_VALID: calibration page.
    PageNotValid,
    /// 0x29 ERR_SEQUENCE: commands out of order.
    Sequence,
    /// 0x31 ERR_GENERIC: an erase or write failed (protected sector, flash not erased, …).
    Generic,
    /// Any other code.
    Other(u8),
}

impl ErrorCode {
    /// Every named code, for tests and documentation.
    pub const NAMED: [ErrorCode; 8] = [
        ErrorCode::CmdSynch,
        ErrorCode::CmdBusy,
        ErrorCode::CmdUnknown,
        ErrorCode::OutOfRange,
        ErrorCode::AccessLocked,
        ErrorCode::PageNotValid,
        ErrorCode::Sequence,
        ErrorCode::Generic,
    ];

    /// Decodes the byte after `0xFE`.
    pub fn from_byte(byte: u8) -> Self {
        match byte {
            0x00 => ErrorCode::CmdSynch,
            0x10 => ErrorCode::CmdBusy,
            0x20 => ErrorCode::CmdUnknown,
            0x22 => ErrorCode::OutOfRange,
            0x25 => ErrorCode::AccessLocked,
            0x26 => ErrorCode::PageNotValid,
            0x29 => ErrorCode::Sequence,
            0x31 => ErrorCode::Generic,
            other => ErrorCode::Other(other),
        }
    }

    /// The byte on the wire.
    pub fn byte(self) -> u8 {
        match self {
            ErrorCode::CmdSynch => 0x00,
            ErrorCode::CmdBusy => 0x10,
            ErrorCode::CmdUnknown => 0x20,
            ErrorCode::OutOfRange => 0x22,
            ErrorCode::AccessLocked => 0x25,
            ErrorCode::PageNotValid => 0x26,
            ErrorCode::Sequence => 0x29,
            ErrorCode::Generic => 0x31,
            ErrorCode::Other(b) => b,
        }
    }

    /// What the user can do about it.
    pub fn advice(self) -> &'static str {
        match self {
            ErrorCode::CmdBusy => "the bootloader was still busy; run again",
            ErrorCode::CmdUnknown | ErrorCode::CmdSynch | ErrorCode::PageNotValid => {
                "this bootloader does not support the command: is it AMiRo-BLT?"
            }
            ErrorCode::OutOfRange => "a length the bootloader refuses; report this as a bug",
            ErrorCode::AccessLocked => {
                "the bootloader is locked with seed/key protection, which AMiRo-BLT does not use: \
                 is it a different bootloader?"
            }
            ErrorCode::Sequence => "commands out of order; reset the robot and run again",
            ErrorCode::Generic => {
                "an erase or write failed (a protected or worn sector, or a write onto unerased \
                 flash left over from an aborted run): reset the robot and run again"
            }
            ErrorCode::Other(_) => "an error code AMiRo-BLT does not define; reset and run again",
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self {
            ErrorCode::CmdSynch => "ERR_CMD_SYNCH",
            ErrorCode::CmdBusy => "ERR_CMD_BUSY",
            ErrorCode::CmdUnknown => "ERR_CMD_UNKNOWN",
            ErrorCode::OutOfRange => "ERR_OUT_OF_RANGE",
            ErrorCode::AccessLocked => "ERR_ACCESS_LOCKED",
            ErrorCode::PageNotValid => "ERR_PAGE_NOT_VALID",
            ErrorCode::Sequence => "ERR_SEQUENCE",
            ErrorCode::Generic => "ERR_GENERIC",
            ErrorCode::Other(_) => "unknown error",
        };
        write!(f, "{name} ({:#04x})", self.byte())
    }
}

/// A reply packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `0xFF` and the bytes after it.
    Ok(Vec<u8>),
    /// `0xFE` and its code.
    Err(ErrorCode),
}

impl Reply {
    /// Parses a reply packet; `None` when it starts with neither `0xFF` nor `0xFE`.
    pub fn parse(packet: &[u8]) -> Option<Reply> {
        match packet {
            [PID_RES, rest @ ..] => Some(Reply::Ok(rest.to_vec())),
            [PID_ERR, code, ..] => Some(Reply::Err(ErrorCode::from_byte(*code))),
            _ => None,
        }
    }
}

/// What CONNECT's reply says about the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnectInfo {
    /// Byte order of multi-byte fields.
    pub order: ByteOrder,
    /// Longest command packet the target takes.
    pub max_cto: u8,
    /// Longest data packet it sends.
    pub max_dto: u16,
}

impl ConnectInfo {
    /// Reads the 7 bytes after `0xFF`; `None` when the reply is too short or announces a
    /// packet size too small to program with.
    pub fn parse(body: &[u8]) -> Option<Self> {
        let [_resources, mode, max_cto, dto0, dto1, ..] = *body else {
            return None;
        };
        let order = if mode & 1 == 1 {
            ByteOrder::Big
        } else {
            ByteOrder::Little
        };
        let max_dto = match order {
            ByteOrder::Little => u16::from_le_bytes([dto0, dto1]),
            ByteOrder::Big => u16::from_be_bytes([dto0, dto1]),
        };
        (max_cto >= 8).then_some(ConnectInfo {
            order,
            max_cto,
            max_dto,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connect_takes_the_short_form_for_small_ids_and_the_long_form_otherwise() {
        let o = ByteOrder::Little;
        assert_eq!(Command::Connect(Select::SerialBoard).encode(o), [0xFF, 0]);
        assert_eq!(Command::Connect(Select::Device(3)).encode(o), [0xFF, 3]);
        assert_eq!(
            Command::Connect(Select::Device(0x0101_0102)).encode(o),
            [0xFF, 0x02, 0x01, 0x01, 0x01]
        );
        // SerialBoot would truncate this one to a 2-byte CONNECT for id 2.
        assert_eq!(
            Command::Connect(Select::Device(0x0000_0102)).encode(o),
            [0xFF, 0x02, 0x01, 0, 0]
        );
    }

    #[test]
    fn addresses_follow_the_target_byte_order() {
        assert_eq!(
            Command::SetMta(0x0800_6000).encode(ByteOrder::Little),
            [0xF6, 0, 0, 0, 0x00, 0x60, 0x00, 0x08]
        );
        assert_eq!(
            Command::ProgramClear(0x1234).encode(ByteOrder::Big),
            [0xD1, 0, 0, 0, 0, 0, 0x12, 0x34]
        );
        assert_eq!(
            Command::Program(vec![]).encode(ByteOrder::Little),
            [0xD0, 0]
        );
    }

    #[test]
    fn replies_and_error_codes_are_named() {
        assert_eq!(Reply::parse(&[0xFF, 1]), Some(Reply::Ok(vec![1])));
        for code in ErrorCode::NAMED {
            assert_eq!(ErrorCode::from_byte(code.byte()), code);
            assert_eq!(Reply::parse(&[0xFE, code.byte()]), Some(Reply::Err(code)));
            assert!(code.to_string().starts_with("ERR_"));
        }
        assert_eq!(Reply::parse(&[0x12]), None);
        assert_eq!(ErrorCode::from_byte(0x31).to_string(), "ERR_GENERIC (0x31)");
    }

    #[test]
    fn connect_info_reads_order_and_sizes() {
        let info = ConnectInfo::parse(&[0x10, 0, 255, 255, 0, 1, 1]).unwrap();
        assert_eq!(info.order, ByteOrder::Little);
        assert_eq!((info.max_cto, info.max_dto), (255, 255));
        assert_eq!(ConnectInfo::parse(&[0x10, 0]), None);
    }
}
