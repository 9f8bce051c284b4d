//! Raw CAN frames as text: can-utils `ID#DATA`, `candump -l` log lines and candump's screen format.
//!
//! This layer knows nothing about the AMiRo protocol. It only turns text into the frame that was (or will be) on
//! the wire, so that the AMiRo decoder can judge it; frames the robot never sends (extended identifiers, remote
//! frames) are still read here, because an operator watching a bus wants to see them reported, not lost.

use std::fmt;

use amiro_can::candump::{self, CandumpError};
/// The frame, its identifier and a log line's timestamp are `amiro_can::candump`'s: one codec for
/// `ID#DATA` and `candump -l` text, which the firmware's QEMU build, the robot host and xtask use too.
pub use amiro_can::candump::{FrameId, RawFrame, Timestamp};

/// A frame with what a log line or a live bus adds to it: when and on which interface it was seen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoggedFrame {
    /// When the frame was seen, if known.
    pub timestamp: Option<Timestamp>,
    /// The interface it was seen on (`can0`), if known.
    pub interface: Option<String>,
    /// The frame itself.
    pub frame: RawFrame,
}

impl LoggedFrame {
    /// A frame without timestamp or interface (a command-line argument).
    pub fn bare(frame: RawFrame) -> Self {
        Self {
            timestamp: None,
            interface: None,
            frame,
        }
    }

    /// The line as `candump -l` writes it: `(1700000000.123456) can0 205#01840302`.
    /// Missing parts are filled with the current time and `can0`, so the line always replays with `canplayer`.
    /// The line is `amiro_can::candump`'s encoder's (an interface name is cut to 16 bytes, as Linux's are).
    pub fn to_log_line(&self) -> String {
        let timestamp = self.timestamp.unwrap_or_else(Timestamp::now);
        let interface = self.interface.as_deref().unwrap_or("can0");
        let mut line = [0u8; candump::MAX_LOG_LINE];
        let n = candump::encode_log_line(timestamp, interface, &self.frame, &mut line);
        String::from_utf8_lossy(&line[..n.saturating_sub(1)]).into_owned()
    }

    /// The prefix shown before a frame in human-readable output: `(ts) can0 ` or nothing.
    pub fn origin_prefix(&self) -> String {
        let mut prefix = String::new();
        if let Some(timestamp) = self.timestamp {
            prefix.push_str(&format!("({timestamp}) "));
        }
        if let Some(interface) = &self.interface {
            prefix.push_str(interface);
            prefix.push(' ');
        }
        prefix
    }
}

/// Why a line of text is not a CAN frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FrameTextError {
    /// Nothing that looks like a frame (no `#`, not candump's `ID [n] bytes` form).
    NotAFrame(String),
    /// The `(seconds.micros)` part does not parse.
    BadTimestamp(String),
    /// The identifier is not 3 hex digits (standard) or 8 (extended).
    BadIdentifier(String),
    /// The identifier has the right length but too large a value (standard above 7FF, extended above 1FFFFFFF).
    IdentifierOutOfRange(String),
    /// The data is not whole hex bytes.
    BadData(String),
    /// More than 8 data bytes.
    TooManyBytes(usize),
    /// A CAN FD frame (`##`): the AMiRo bus is classic CAN.
    CanFd,
    /// candump's `[n]` disagrees with the number of bytes that follow.
    LengthMismatch {
        /// The length in brackets.
        declared: usize,
        /// The bytes actually listed.
        found: usize,
    },
    /// Something follows the frame that is not part of any known format.
    TrailingText(String),
    /// The line is not UTF-8 text (a binary file, or a log damaged on disk).
    NotText {
        /// The line's bytes, with invalid sequences replaced by U+FFFD.
        lossy: String,
    },
}

impl FrameTextError {
    /// A short, stable name for the reason, as used in JSON output.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Self::NotAFrame(_) => "not-a-frame",
            Self::BadTimestamp(_) => "bad-timestamp",
            Self::BadIdentifier(_) => "bad-identifier",
            Self::IdentifierOutOfRange(_) => "identifier-out-of-range",
            Self::BadData(_) => "bad-data",
            Self::TooManyBytes(_) => "too-many-bytes",
            Self::CanFd => "can-fd",
            Self::LengthMismatch { .. } => "length-mismatch",
            Self::TrailingText(_) => "trailing-text",
            Self::NotText { .. } => "not-text",
        }
    }
}

impl fmt::Display for FrameTextError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotAFrame(text) => {
                write!(f, "not a CAN frame: {text:?} (expected e.g. 205#01840302 or a candump -l line)")
            }
            Self::BadTimestamp(text) => write!(f, "bad timestamp {text:?} (expected (seconds.microseconds))"),
            Self::BadIdentifier(text) => write!(
                f,
                "bad identifier {text:?}: expected 3 hex digits (standard, e.g. 205) or 8 (extended)"
            ),
            Self::IdentifierOutOfRange(text) => write!(
                f,
                "identifier {text} out of range (standard identifiers go up to 7FF, extended up to 1FFFFFFF)"
            ),
            Self::BadData(text) => write!(f, "bad data {text:?}: expected hex bytes such as 01840302"),
            Self::TooManyBytes(n) => write!(f, "{n} data bytes: a classic CAN frame carries at most 8"),
            Self::CanFd => f.write_str("CAN FD frame (##): the AMiRo bus is classic CAN"),
            Self::LengthMismatch { declared, found } => {
                write!(f, "length [{declared}] but {found} data bytes follow")
            }
            Self::TrailingText(text) => write!(f, "unexpected text after the frame: {text:?}"),
            Self::NotText { lossy } => write!(f, "not UTF-8 text: {lossy:?}"),
        }
    }
}

impl std::error::Error for FrameTextError {}

impl From<CandumpError<'_>> for FrameTextError {
    fn from(error: CandumpError<'_>) -> Self {
        match error {
            CandumpError::NotAFrame(text) => Self::NotAFrame(text.to_string()),
            CandumpError::BadTimestamp(text) => Self::BadTimestamp(text.to_string()),
            CandumpError::BadIdentifier(text) => Self::BadIdentifier(text.to_string()),
            CandumpError::IdentifierOutOfRange(text) => {
                Self::IdentifierOutOfRange(text.to_uppercase())
            }
            CandumpError::BadData(text) => Self::BadData(text.to_string()),
            CandumpError::TooManyBytes(n) => Self::TooManyBytes(n),
            CandumpError::CanFd => Self::CanFd,
            CandumpError::TrailingText(text) => Self::TrailingText(text.to_string()),
        }
    }
}

/// One numbered line from [`text_lines`]: its number, and its text or why it is not text.
pub type NumberedLine = std::io::Result<(usize, Result<String, FrameTextError>)>;

/// Reads numbered lines (from 1) from `input` without giving up on bytes that are not UTF-8: such a line comes
/// back as `Err(FrameTextError::NotText)` and reading goes on. Only an I/O error ends the iteration (with `Err`).
pub fn text_lines<R: std::io::BufRead>(mut input: R) -> impl Iterator<Item = NumberedLine> {
    let mut number = 0;
    let mut failed = false;
    std::iter::from_fn(move || {
        if failed {
            return None;
        }
        let mut bytes = Vec::new();
        match input.read_until(b'\n', &mut bytes) {
            Ok(0) => None,
            Ok(_) => {
                number += 1;
                if bytes.last() == Some(&b'\n') {
                    bytes.pop();
                    if bytes.last() == Some(&b'\r') {
                        bytes.pop();
                    }
                }
                let text = String::from_utf8(bytes).map_err(|error| FrameTextError::NotText {
                    lossy: String::from_utf8_lossy(error.as_bytes()).into_owned(),
                });
                Some(Ok((number, text)))
            }
            Err(error) => {
                failed = true;
                Some(Err(error))
            }
        }
    })
}

/// Parses one line of input: a bare `ID#DATA`, a `candump -l` line, or a candump screen line
/// (`can0  205   [4]  01 84 03 02`, with or without a timestamp).
///
/// Blank lines and comments (starting with `#` or `//`) give `Ok(None)`.
pub fn parse_line(line: &str) -> Result<Option<LoggedFrame>, FrameTextError> {
    if candump::is_blank_or_comment(line) {
        return Ok(None);
    }
    let line = line.trim();
    let mut tokens: Vec<&str> = line.split_whitespace().collect();

    let mut timestamp = None;
    if let Some(first) = tokens.first() {
        if first.starts_with('(') {
            timestamp = Some(candump::parse_timestamp(first)?);
            tokens.remove(0);
        }
    }

    // The frame token is the first containing '#'; an interface name may stand before it.
    if let Some(at) = tokens.iter().position(|t| t.contains('#')) {
        let interface = match at {
            0 => None,
            1 => Some(tokens[0].to_string()),
            _ => return Err(FrameTextError::NotAFrame(line.to_string())),
        };
        let frame = parse_compact(tokens[at])?;
        // Newer candump versions may log the direction (R = received, T = transmitted) after the frame.
        candump::check_direction(line, tokens[at + 1..].iter().copied())?;
        return Ok(Some(LoggedFrame {
            timestamp,
            interface,
            frame,
        }));
    }

    parse_screen(&tokens, line).map(|(interface, frame)| {
        Some(LoggedFrame {
            timestamp,
            interface,
            frame,
        })
    })
}

/// Parses just a compact frame `ID#DATA` (a command-line argument).
pub fn parse_compact(text: &str) -> Result<RawFrame, FrameTextError> {
    Ok(candump::parse_compact(text)?)
}

/// candump's screen form: `[iface] ID [n] b0 b1 ...` or `[iface] ID [n] remote request`.
fn parse_screen(tokens: &[&str], line: &str) -> Result<(Option<String>, RawFrame), FrameTextError> {
    let not_a_frame = || FrameTextError::NotAFrame(line.to_string());
    let bracket = tokens
        .iter()
        .position(|t| t.starts_with('[') && t.ends_with(']'))
        .ok_or_else(not_a_frame)?;
    let (interface, id_text) = match bracket {
        1 => (None, tokens[0]),
        2 => (Some(tokens[0].to_string()), tokens[1]),
        _ => return Err(not_a_frame()),
    };
    let id = candump::parse_id(id_text)?;
    let len_text = &tokens[bracket][1..tokens[bracket].len() - 1];
    let declared: usize = len_text.parse().map_err(|_| not_a_frame())?;
    if declared > 8 {
        return Err(FrameTextError::TooManyBytes(declared));
    }
    let rest = &tokens[bracket + 1..];
    if rest.starts_with(&["remote", "request"]) {
        let frame = RawFrame::remote_frame(id, declared as u8).ok_or_else(not_a_frame)?;
        return Ok((interface, frame));
    }
    // `candump -a` appends the bytes as ASCII in quotes; that is a copy of the data, not more data.
    let byte_tokens: Vec<&str> = rest
        .iter()
        .copied()
        .take_while(|t| !t.starts_with('\''))
        .collect();
    let mut bytes = Vec::with_capacity(byte_tokens.len());
    for token in &byte_tokens {
        match parse_hex_bytes(token).as_deref() {
            Some([byte]) => bytes.push(*byte),
            _ => return Err(FrameTextError::BadData((*token).to_string())),
        }
    }
    if bytes.len() != declared {
        return Err(FrameTextError::LengthMismatch {
            declared,
            found: bytes.len(),
        });
    }
    let frame = RawFrame::data_frame(id, &bytes).ok_or_else(not_a_frame)?;
    Ok((interface, frame))
}

/// Hex pairs to bytes; `None` if the count is odd or a character is not hex.
pub fn parse_hex_bytes(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) || !text.is_ascii() {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn standard(id: u16, bytes: &[u8]) -> RawFrame {
        RawFrame::data_frame(FrameId::Standard(id), bytes).unwrap()
    }

    #[test]
    fn malformed_frames_say_what_is_wrong() {
        assert_eq!(
            parse_compact("2050#01"),
            Err(FrameTextError::BadIdentifier("2050".into()))
        );
        assert_eq!(
            parse_compact("800#01"),
            Err(FrameTextError::IdentifierOutOfRange("800".into()))
        );
        assert_eq!(
            parse_compact("20G#01"),
            Err(FrameTextError::BadIdentifier("20G".into()))
        );
        assert_eq!(
            parse_compact("205#018"),
            Err(FrameTextError::BadData("018".into()))
        );
        assert_eq!(
            parse_compact("205#0102030405060708090A"),
            Err(FrameTextError::TooManyBytes(10))
        );
        assert_eq!(parse_compact("205##1"), Err(FrameTextError::CanFd));
        assert_eq!(
            parse_compact("205#R9"),
            Err(FrameTextError::BadData("R9".into()))
        );
        assert_eq!(
            parse_compact("hello"),
            Err(FrameTextError::NotAFrame("hello".into()))
        );
        assert_eq!(
            parse_compact("205#zz"),
            Err(FrameTextError::BadData("zz".into()))
        );
        assert_eq!(
            parse_compact("205#é1"),
            Err(FrameTextError::BadData("é1".into()))
        );
    }

    #[test]
    fn candump_log_lines_keep_timestamp_and_interface() {
        let logged = parse_line("(1700000000.123456) can0 605#D2FBFFFF")
            .unwrap()
            .unwrap();
        assert_eq!(
            logged.timestamp,
            Some(Timestamp {
                secs: 1_700_000_000,
                micros: 123_456
            })
        );
        assert_eq!(logged.interface.as_deref(), Some("can0"));
        assert_eq!(logged.frame, standard(0x605, &[0xD2, 0xFB, 0xFF, 0xFF]));
        assert_eq!(
            logged.to_log_line(),
            "(1700000000.123456) can0 605#D2FBFFFF"
        );
        // Direction flag of newer candump versions.
        assert!(parse_line("(1700000000.123456) can0 605#D2FBFFFF R")
            .unwrap()
            .is_some());
        // Relative timestamps and a short fraction.
        let relative = parse_line("(0.5) vcan0 205#02").unwrap().unwrap();
        assert_eq!(
            relative.timestamp,
            Some(Timestamp {
                secs: 0,
                micros: 500_000
            })
        );
    }

    #[test]
    fn candump_screen_lines_are_read() {
        let logged = parse_line("  can0  205   [4]  01 84 03 02")
            .unwrap()
            .unwrap();
        assert_eq!(logged.interface.as_deref(), Some("can0"));
        assert_eq!(logged.frame.to_string(), "205#01840302");
        let with_time =
            parse_line(" (1700000000.000001)  can0  608   [6]  FC FF 02 00 00 00   '......'")
                .unwrap();
        assert_eq!(with_time.unwrap().frame.to_string(), "608#FCFF02000000");
        let remote = parse_line("can0  205   [2]  remote request")
            .unwrap()
            .unwrap();
        assert!(remote.frame.is_remote());
        assert_eq!(
            parse_line("can0  205   [4]  01 84 03"),
            Err(FrameTextError::LengthMismatch {
                declared: 4,
                found: 3
            })
        );
    }

    #[test]
    fn blank_lines_and_comments_are_skipped() {
        assert_eq!(parse_line(""), Ok(None));
        assert_eq!(parse_line("   \t"), Ok(None));
        assert_eq!(parse_line("# a comment 205#01"), Ok(None));
        assert_eq!(parse_line("// another"), Ok(None));
    }

    #[test]
    fn garbage_lines_are_errors_not_frames() {
        assert!(parse_line("hello world").is_err());
        assert!(parse_line("(17x) can0 205#01").is_err());
        assert!(parse_line("(1700000000.1) can0 205#01 extra words").is_err());
        assert!(parse_line("a b c 205#01").is_err());
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn any_text_is_a_frame_a_skip_or_an_error_never_a_panic(line in "\\PC{0,60}") {
                let _ = parse_line(&line);
                let _ = parse_compact(&line);
            }

            #[test]
            fn frame_like_text_never_panics(line in "[ (]{0,2}[0-9.]{0,12}[) ]{0,2}[a-z0-9]{0,5} [0-9A-Fa-f]{0,9}[#R\\[\\] ]{0,3}[0-9A-Fa-f. ]{0,20}") {
                let _ = parse_line(&line);
            }
        }
    }
}
