//! Raw CAN frames as can-utils writes them: the compact `ID#DATA` form and `candump -l` log lines
//! `(seconds.micros) iface ID#DATA`. The one encoder and decoder of that text: the firmware's QEMU
//! build prints its frames with [`encode_log_line`], the robot host and xtask read stimuli and bus
//! logs with [`parse_log_line`], the operator tool reads and writes logs with both (and adds
//! candump's screen form on top).
//!
//! This layer knows nothing of the AMiRo protocol: frames the robot never sends (extended
//! identifiers, remote frames) are read too, so a tool can report them rather than lose them.
//! `no_std`, allocation-free; malformed text is a [`CandumpError`] naming the offending part.
//!
//! Rules, as can-utils' `lib.c` and python-can's `CanutilsLogReader` read them: an identifier of 3
//! hex digits is standard, of 8 extended (the number of digits decides, not the value); data is
//! whole hex bytes, optionally with `.` between them; `R` (with an optional length digit) marks a
//! remote frame; `##` is CAN FD, which the AMiRo bus does not carry. A timestamp's fraction is a
//! decimal fraction of a second (`(0.5)` is half a second, `(0.000001)` one microsecond; digits
//! past the sixth are dropped). A log line may end in candump's direction flag (`R`/`T`).

use core::fmt;

/// Largest standard (11-bit) identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// Largest extended (29-bit) identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;
/// The longest `candump -l` line [`encode_log_line`] writes: a 20-digit second count, an
/// interface of up to 16 bytes, an extended frame with 8 bytes, the newline.
pub const MAX_LOG_LINE: usize = 1 + 20 + 1 + 6 + 2 + 16 + 1 + 8 + 1 + 16 + 1;

/// A CAN identifier as it appears on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameId {
    /// 11-bit base-format identifier: the only kind the AMiRo protocol uses.
    Standard(u16),
    /// 29-bit extended identifier.
    Extended(u32),
}

impl FrameId {
    /// The identifier's value.
    pub fn raw(self) -> u32 {
        match self {
            Self::Standard(id) => u32::from(id),
            Self::Extended(id) => id,
        }
    }

    fn in_range(self) -> bool {
        match self {
            Self::Standard(id) => u32::from(id) <= MAX_STANDARD_ID,
            Self::Extended(id) => id <= MAX_EXTENDED_ID,
        }
    }
}

/// One classic CAN frame (up to 8 data bytes), before anyone has decided what it means.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RawFrame {
    id: FrameId,
    remote: bool,
    len: u8,
    data: [u8; 8],
}

impl RawFrame {
    /// A data frame. `None` if the identifier is out of range or there are more than 8 bytes.
    pub fn data_frame(id: FrameId, bytes: &[u8]) -> Option<Self> {
        if !id.in_range() || bytes.len() > 8 {
            return None;
        }
        // Eight fixed passes, not a copy of the caller's length: the QEMU build's transmit
        // interrupt prints every frame sent through here, and a copy of a length the call does not
        // fix went through the image's shared `copy_from_slice` (a statement of its length would
        // speak for every other caller too: docs/bench.md, "QEMU image's own bound").
        let mut data = [0; 8];
        for (i, slot) in data.iter_mut().enumerate() {
            *slot = bytes.get(i).copied().unwrap_or(0);
        }
        Some(Self {
            id,
            remote: false,
            len: bytes.len() as u8,
            data,
        })
    }

    /// A remote (RTR) frame asking for `len` bytes. `None` if out of range.
    pub fn remote_frame(id: FrameId, len: u8) -> Option<Self> {
        if !id.in_range() || len > 8 {
            return None;
        }
        Some(Self {
            id,
            remote: true,
            len,
            data: [0; 8],
        })
    }

    /// The identifier.
    pub fn id(&self) -> FrameId {
        self.id
    }

    /// Whether this is a remote (RTR) frame, which carries a length but no data.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data length code.
    pub fn len(&self) -> u8 {
        self.len
    }

    /// Whether the data length code is zero.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.len)]
        }
    }

    /// The identifier as can-utils writes it: 3 hex digits (standard) or 8 (extended).
    pub fn id_hex(&self) -> IdHex {
        IdHex(self.id)
    }

    /// The data bytes as uppercase hex without separators, as can-utils writes them.
    pub fn data_hex(&self) -> DataHex<'_> {
        DataHex(self.data())
    }

    /// The compact form's bytes (`205#01840302`) into `out`.
    fn encode_compact(&self, out: &mut Cursor<'_>) {
        match self.id {
            FrameId::Standard(id) => out.hex(u32::from(id), 3),
            FrameId::Extended(id) => out.hex(id, 8),
        }
        out.byte(b'#');
        if self.remote {
            out.byte(b'R');
            if self.len > 0 {
                out.byte(b'0' + self.len);
            }
        } else {
            for &b in self.data() {
                out.hex(u32::from(b), 2);
            }
        }
    }
}

/// A frame's identifier as can-utils writes it ([`RawFrame::id_hex`]).
#[derive(Clone, Copy, Debug)]
pub struct IdHex(FrameId);

impl fmt::Display for IdHex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            FrameId::Standard(id) => write!(f, "{id:03X}"),
            FrameId::Extended(id) => write!(f, "{id:08X}"),
        }
    }
}

/// A frame's data as can-utils writes it ([`RawFrame::data_hex`]).
#[derive(Clone, Copy, Debug)]
pub struct DataHex<'a>(&'a [u8]);

impl fmt::Display for DataHex<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.iter().try_for_each(|b| write!(f, "{b:02X}"))
    }
}

/// can-utils compact form: `205#01840302`, `12345678#00`, `205#R`, `205#R4`.
impl fmt::Display for RawFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut buffer = [0u8; 32];
        let mut out = Cursor::new(&mut buffer);
        self.encode_compact(&mut out);
        f.write_str(out.text())
    }
}

/// Seconds and microseconds, as a log line writes `(1700000000.123456)`; integers, so nothing is
/// rounded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp {
    /// Whole seconds (since the epoch for `candump -l`, since the start for a run's log).
    pub secs: u64,
    /// Microseconds, 0..1_000_000.
    pub micros: u32,
}

impl Timestamp {
    /// A timestamp `micros` microseconds after its origin.
    pub const fn from_micros(micros: u64) -> Self {
        // One 64-bit division (a library call on the boards' cores), the remainder by a multiply.
        let secs = micros / 1_000_000;
        Self {
            secs,
            micros: (micros - secs * 1_000_000) as u32,
        }
    }

    /// The current wall-clock time (since the Unix epoch), with the `std` feature.
    #[cfg(feature = "std")]
    pub fn now() -> Self {
        let since_epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        Self {
            secs: since_epoch.as_secs(),
            micros: since_epoch.subsec_micros(),
        }
    }

    /// Microseconds since the timestamp's origin (saturating, far beyond any log's range).
    pub fn as_micros(&self) -> u64 {
        self.secs
            .saturating_mul(1_000_000)
            .saturating_add(u64::from(self.micros))
    }

    /// Microseconds since the timestamp's origin, `None` beyond a `u64` count.
    pub fn checked_micros(&self) -> Option<u64> {
        self.secs
            .checked_mul(1_000_000)?
            .checked_add(u64::from(self.micros))
    }

    fn encode(&self, out: &mut Cursor<'_>) {
        out.decimal(self.secs);
        out.byte(b'.');
        let mut scale = 100_000;
        while scale > 0 {
            out.byte(b'0' + ((self.micros / scale) % 10) as u8);
            scale /= 10;
        }
    }
}

/// `seconds.micros` (six fraction digits, seconds unpadded: python-can's log writer's form; for
/// wall-clock seconds it is candump's too).
impl fmt::Display for Timestamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{:06}", self.secs, self.micros)
    }
}

/// A `candump -l` line's parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LogLine<'a> {
    /// When the frame was seen.
    pub timestamp: Timestamp,
    /// The interface it was seen on (`can0`).
    pub interface: &'a str,
    /// The frame.
    pub frame: RawFrame,
}

/// Why text is not a frame; the `&str` is the offending part of the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CandumpError<'a> {
    /// Nothing that looks like a frame (no `#`), or a log line missing a part.
    NotAFrame(&'a str),
    /// The `(seconds.micros)` part does not parse.
    BadTimestamp(&'a str),
    /// The identifier is not 3 hex digits (standard) or 8 (extended).
    BadIdentifier(&'a str),
    /// The identifier has the right length but too large a value (standard above 7FF, extended
    /// above 1FFFFFFF).
    IdentifierOutOfRange(&'a str),
    /// The data is not whole hex bytes (or a remote frame's length is not 0..=8).
    BadData(&'a str),
    /// More than 8 data bytes.
    TooManyBytes(usize),
    /// A CAN FD frame (`##`): the AMiRo bus is classic CAN.
    CanFd,
    /// Something follows the frame that is not candump's direction flag.
    TrailingText(&'a str),
}

impl fmt::Display for CandumpError<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotAFrame(text) => write!(
                f,
                "not a CAN frame: {text:?} (expected e.g. 205#01840302 or a candump -l line)"
            ),
            Self::BadTimestamp(text) => {
                write!(f, "bad timestamp {text:?} (expected (seconds.microseconds))")
            }
            Self::BadIdentifier(text) => write!(
                f,
                "bad identifier {text:?}: expected 3 hex digits (standard, e.g. 205) or 8 (extended)"
            ),
            Self::IdentifierOutOfRange(text) => write!(
                f,
                "identifier {text} out of range (standard identifiers go up to 7FF, extended up to 1FFFFFFF)"
            ),
            Self::BadData(text) => {
                write!(f, "bad data {text:?}: expected hex bytes such as 01840302")
            }
            Self::TooManyBytes(n) => {
                write!(f, "{n} data bytes: a classic CAN frame carries at most 8")
            }
            Self::CanFd => f.write_str("CAN FD frame (##): the AMiRo bus is classic CAN"),
            Self::TrailingText(text) => write!(f, "unexpected text after the frame: {text:?}"),
        }
    }
}

/// Whether a line says nothing: blank, or a comment (`#` or `//`).
pub fn is_blank_or_comment(line: &str) -> bool {
    let line = line.trim();
    line.is_empty() || line.starts_with('#') || line.starts_with("//")
}

/// Parses a `candump -l` line `(seconds.micros) iface ID#DATA [R|T]`; blank lines and comments give
/// `None`.
pub fn parse_log_line(line: &str) -> Result<Option<LogLine<'_>>, CandumpError<'_>> {
    if is_blank_or_comment(line) {
        return Ok(None);
    }
    let line = line.trim();
    let mut tokens = line.split_whitespace();
    let stamp = tokens.next().ok_or(CandumpError::NotAFrame(line))?;
    let timestamp = parse_timestamp(stamp)?;
    let interface = tokens.next().ok_or(CandumpError::NotAFrame(line))?;
    let frame = parse_compact(tokens.next().ok_or(CandumpError::NotAFrame(line))?)?;
    check_direction(line, tokens)?;
    Ok(Some(LogLine {
        timestamp,
        interface,
        frame,
    }))
}

/// What may follow a frame on a log line: nothing, or candump's direction flag (`R` received, `T`
/// transmitted); anything else is [`CandumpError::TrailingText`] (from its first token to the end
/// of `line`).
pub fn check_direction<'a>(
    line: &'a str,
    mut rest: impl Iterator<Item = &'a str>,
) -> Result<(), CandumpError<'a>> {
    let first = rest.next();
    if matches!(first, None | Some("R" | "T")) && rest.next().is_none() {
        return Ok(());
    }
    let from = first.map_or(line.len(), |t| t.as_ptr() as usize - line.as_ptr() as usize);
    Err(CandumpError::TrailingText(line.get(from..).unwrap_or(line)))
}

/// Parses a compact frame `ID#DATA` (`205#01840302`, `12345678#AA`, `205#R4`, `61E#FF.00`).
pub fn parse_compact(text: &str) -> Result<RawFrame, CandumpError<'_>> {
    let Some((id_text, data_text)) = text.split_once('#') else {
        return Err(CandumpError::NotAFrame(text));
    };
    if data_text.starts_with('#') {
        return Err(CandumpError::CanFd);
    }
    let id = parse_id(id_text)?;
    let bad_data = CandumpError::BadData(data_text);
    if let Some(len_text) = data_text.strip_prefix(['R', 'r']) {
        let len = match len_text.as_bytes() {
            [] => 0,
            [d @ b'0'..=b'8'] => d - b'0',
            _ => return Err(bad_data),
        };
        return RawFrame::remote_frame(id, len).ok_or(bad_data);
    }
    // can-utils allows a '.' between bytes for readability.
    let mut data = [0u8; 8];
    let mut count = 0;
    let mut high = None;
    for b in data_text.bytes().filter(|&b| b != b'.') {
        let nibble = hex_value(b).ok_or(bad_data)?;
        match high.take() {
            None => high = Some(nibble),
            Some(h) => {
                if let Some(slot) = data.get_mut(count) {
                    *slot = h << 4 | nibble;
                }
                count += 1;
            }
        }
    }
    if high.is_some() {
        return Err(bad_data);
    }
    if count > 8 {
        return Err(CandumpError::TooManyBytes(count));
    }
    RawFrame::data_frame(id, &data[..count]).ok_or(bad_data)
}

/// Parses an identifier: 3 hex digits standard, 8 extended.
pub fn parse_id(text: &str) -> Result<FrameId, CandumpError<'_>> {
    let bad = CandumpError::BadIdentifier(text);
    if !text.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Err(bad);
    }
    let value = u32::from_str_radix(text, 16).map_err(|_| bad)?;
    // can-utils tells standard from extended by the number of digits, not by the value.
    match text.len() {
        3 if value <= MAX_STANDARD_ID => Ok(FrameId::Standard(value as u16)),
        8 if value <= MAX_EXTENDED_ID => Ok(FrameId::Extended(value)),
        3 | 8 => Err(CandumpError::IdentifierOutOfRange(text)),
        _ => Err(bad),
    }
}

/// Parses a `(seconds.fraction)` token ([`parse_seconds`] inside the parentheses).
pub fn parse_timestamp(token: &str) -> Result<Timestamp, CandumpError<'_>> {
    token
        .strip_prefix('(')
        .and_then(|t| t.strip_suffix(')'))
        .and_then(|inner| parse_seconds(inner).ok())
        .ok_or(CandumpError::BadTimestamp(token))
}

/// Parses `seconds.fraction` (a timestamp without its parentheses, as trace lines print a release):
/// the fraction is decimal (a short one is padded, digits past the sixth are dropped) and may be
/// absent.
pub fn parse_seconds(text: &str) -> Result<Timestamp, CandumpError<'_>> {
    let bad = CandumpError::BadTimestamp(text);
    let (secs_text, fraction) = text.split_once('.').unwrap_or((text, ""));
    if secs_text.is_empty()
        || !secs_text.bytes().all(|c| c.is_ascii_digit())
        || !fraction.bytes().all(|c| c.is_ascii_digit())
    {
        return Err(bad);
    }
    let secs = secs_text.parse().map_err(|_| bad)?;
    let mut micros: u32 = 0;
    for position in 0..6 {
        let digit = fraction
            .as_bytes()
            .get(position)
            .map_or(0, |d| u32::from(*d - b'0'));
        micros = micros * 10 + digit;
    }
    Ok(Timestamp { secs, micros })
}

/// Writes the `candump -l` line `(secs.micros) iface ID#DATA\n` of `frame` into `out` without
/// `core::fmt` (the firmware's emulated transmit path prints one per frame); returns its length.
/// An interface name longer than 16 bytes is cut to 16.
pub fn encode_log_line(
    timestamp: Timestamp,
    interface: &str,
    frame: &RawFrame,
    out: &mut [u8; MAX_LOG_LINE],
) -> usize {
    let mut cursor = Cursor::new(out);
    cursor.byte(b'(');
    timestamp.encode(&mut cursor);
    cursor.byte(b')');
    cursor.byte(b' ');
    let name = interface.as_bytes();
    name[..name.len().min(16)]
        .iter()
        .for_each(|&b| cursor.byte(b));
    cursor.byte(b' ');
    frame.encode_compact(&mut cursor);
    cursor.byte(b'\n');
    cursor.at
}

/// The value of a hex digit.
pub(crate) fn hex_value(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'a'..=b'f' => Some(b - b'a' + 10),
        b'A'..=b'F' => Some(b - b'A' + 10),
        _ => None,
    }
}

/// Bytes written into a fixed buffer (what does not fit is dropped: the buffers are sized for the
/// longest text).
pub(crate) struct Cursor<'a> {
    buffer: &'a mut [u8],
    pub(crate) at: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(buffer: &'a mut [u8]) -> Self {
        Self { buffer, at: 0 }
    }

    pub(crate) fn byte(&mut self, b: u8) {
        if let Some(slot) = self.buffer.get_mut(self.at) {
            *slot = b;
            self.at += 1;
        }
    }

    /// `value`'s low `digits` nibbles as uppercase hex.
    pub(crate) fn hex(&mut self, value: u32, digits: u32) {
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        for k in (0..digits).rev() {
            self.byte(HEX[((value >> (4 * k)) & 15) as usize]);
        }
    }

    /// `value` in decimal. Digits come from 32-bit divisions while the value fits 32 bits (the M3
    /// and M4 divide those in hardware; a 64-bit division is a library call of hundreds of
    /// instructions, and the emulated transmit task prints a line per frame).
    fn decimal(&mut self, value: u64) {
        let mut digits = [0u8; 20];
        let mut at = digits.len();
        let mut wide = value;
        while wide > u64::from(u32::MAX) {
            at -= 1;
            digits[at] = b'0' + (wide % 10) as u8;
            wide /= 10;
        }
        let mut rest = wide as u32;
        loop {
            at -= 1;
            digits[at] = b'0' + (rest % 10) as u8;
            rest /= 10;
            if rest == 0 {
                break;
            }
        }
        digits[at..].iter().for_each(|&b| self.byte(b));
    }

    pub(crate) fn text(&self) -> &str {
        core::str::from_utf8(&self.buffer[..self.at]).unwrap_or("")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn standard(id: u16, bytes: &[u8]) -> RawFrame {
        RawFrame::data_frame(FrameId::Standard(id), bytes).unwrap()
    }

    fn line_text(timestamp: Timestamp, frame: &RawFrame) -> String {
        let mut out = [0u8; MAX_LOG_LINE];
        let n = encode_log_line(timestamp, "can0", frame, &mut out);
        String::from_utf8(out[..n].to_vec()).unwrap()
    }

    #[test]
    fn compact_frames_read_and_write() {
        let frame = parse_compact("205#01840302").unwrap();
        assert_eq!(frame, standard(0x205, &[1, 0x84, 3, 2]));
        assert_eq!(frame.to_string(), "205#01840302");
        assert_eq!(parse_compact("61e#ff.00").unwrap().to_string(), "61E#FF00");
        assert_eq!(parse_compact("205#").unwrap().data(), &[] as &[u8]);
        let extended = parse_compact("12345678#AA").unwrap();
        assert_eq!(extended.id(), FrameId::Extended(0x1234_5678));
        assert_eq!(extended.to_string(), "12345678#AA");
        assert_eq!(parse_compact("205#R4").unwrap().to_string(), "205#R4");
        assert_eq!(parse_compact("205#R").unwrap().to_string(), "205#R");
        assert_eq!(extended.id_hex().to_string(), "12345678");
        assert_eq!(frame.data_hex().to_string(), "01840302");
    }

    #[test]
    fn malformed_text_is_a_typed_error() {
        use CandumpError::*;
        assert_eq!(parse_compact("2050#01"), Err(BadIdentifier("2050")));
        assert_eq!(parse_compact("800#01"), Err(IdentifierOutOfRange("800")));
        assert_eq!(parse_compact("20G#01"), Err(BadIdentifier("20G")));
        assert_eq!(parse_compact("205#018"), Err(BadData("018")));
        assert_eq!(
            parse_compact("205#0102030405060708090A"),
            Err(TooManyBytes(10))
        );
        assert_eq!(parse_compact("205##1"), Err(CanFd));
        assert_eq!(parse_compact("205#R9"), Err(BadData("R9")));
        assert_eq!(parse_compact("hello"), Err(NotAFrame("hello")));
        assert_eq!(parse_compact("205#é1"), Err(BadData("é1")));
        assert_eq!(parse_log_line("205#01"), Err(BadTimestamp("205#01")));
        assert_eq!(parse_log_line("(0.1)"), Err(NotAFrame("(0.1)")));
        let far = parse_log_line("(18446744073710.000000) can0 205#01");
        assert_eq!(far.unwrap().unwrap().timestamp.checked_micros(), None);
        assert_eq!(
            parse_log_line("(99999999999999999999.0) can0 205#01"),
            Err(BadTimestamp("(99999999999999999999.0)"))
        );
        assert_eq!(
            parse_log_line("(1.000000) can0 205#01 extra words"),
            Err(TrailingText("extra words"))
        );
        assert_eq!(
            parse_log_line("(1x.0) can0 205#01"),
            Err(BadTimestamp("(1x.0)"))
        );
    }

    #[test]
    fn log_lines_round_trip() {
        let line = parse_log_line("(1700000000.123456) can0 605#D2FBFFFF R")
            .unwrap()
            .unwrap();
        assert_eq!(
            line.timestamp,
            Timestamp {
                secs: 1_700_000_000,
                micros: 123_456
            }
        );
        assert_eq!(line.interface, "can0");
        assert_eq!(
            line_text(line.timestamp, &line.frame),
            "(1700000000.123456) can0 605#D2FBFFFF\n"
        );
        // A run's relative time, unpadded, and a short fraction read as a decimal fraction.
        assert_eq!(
            line_text(Timestamp::from_micros(10_000), &standard(0x205, &[1])),
            "(0.010000) can0 205#01\n"
        );
        assert_eq!(
            parse_log_line("(0.5) vcan0 205#02")
                .unwrap()
                .unwrap()
                .timestamp,
            Timestamp::from_micros(500_000)
        );
        assert_eq!(
            parse_log_line("(1.000000123) vcan0 205#02")
                .unwrap()
                .unwrap()
                .timestamp,
            Timestamp::from_micros(1_000_000)
        );
        assert_eq!(parse_log_line("  # a comment"), Ok(None));
        assert_eq!(parse_log_line("// another"), Ok(None));
        // The longest line fits.
        let longest = RawFrame::data_frame(FrameId::Extended(MAX_EXTENDED_ID), &[0xFF; 8]).unwrap();
        let mut out = [0u8; MAX_LOG_LINE];
        let stamp = Timestamp {
            secs: u64::MAX,
            micros: 999_999,
        };
        let n = encode_log_line(stamp, "sixteen-bytes-if", &longest, &mut out);
        assert_eq!(n, MAX_LOG_LINE);
        let text = core::str::from_utf8(&out[..n]).unwrap();
        let back = parse_log_line(text).unwrap().unwrap();
        assert_eq!((back.timestamp, back.frame), (stamp, longest));
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        fn any_frame() -> impl Strategy<Value = RawFrame> {
            let id = prop_oneof![
                (0u16..=0x7FF).prop_map(FrameId::Standard),
                (0u32..=0x1FFF_FFFF).prop_map(FrameId::Extended),
            ];
            (
                id,
                proptest::collection::vec(any::<u8>(), 0..=8),
                any::<bool>(),
            )
                .prop_map(|(id, bytes, remote)| {
                    if remote {
                        RawFrame::remote_frame(id, bytes.len() as u8).unwrap()
                    } else {
                        RawFrame::data_frame(id, &bytes).unwrap()
                    }
                })
        }

        proptest! {
            #[test]
            fn any_text_is_a_frame_a_skip_or_an_error_never_a_panic(line in "\\PC{0,60}") {
                let _ = parse_log_line(&line);
                let _ = parse_compact(&line);
            }

            #[test]
            fn every_frame_survives_its_log_line(frame in any_frame(), secs in 0u64..10_000_000_000, micros in 0u32..1_000_000) {
                let stamp = Timestamp { secs, micros };
                let text = line_text(stamp, &frame);
                prop_assert_eq!(text.trim_end(), format!("({stamp}) can0 {frame}"));
                let back = parse_log_line(&text).unwrap().unwrap();
                prop_assert_eq!((back.timestamp, back.interface, back.frame), (stamp, "can0", frame));
            }
        }
    }
}
