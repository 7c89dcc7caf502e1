//! The candump log format: one frame per line,
//!
//! ```text
//! (1699999999.123456) can0 123#DEADBEEF
//! (1699999999.123789) can1 1ABCDEF0##5001122
//! (1699999999.124000) can0 20000080#0000000000000000
//! ```
//!
//! The timestamp is seconds since the Unix epoch with a fraction (candump writes six digits;
//! up to nine are read, so nanosecond logs keep their precision); the interface name; the frame
//! in can-utils' compact form (FD flags, remote frames, raw DLCs and error frames included).
//! Newer can-utils may append a direction (`R` or `T`); it is read and kept.

use std::fmt;
use std::io::{self, BufRead, Write};
use std::ops::ControlFlow;

use bywire_core::frame::{FrameText, ParseFrameErrorKind};
use bywire_core::{ClassicFrame, Dlc, Frame, Timestamp};

use crate::lines::{line_ref, CappedLines, LineBytes, LineRef};

/// One line of a candump log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogRecord {
    /// When the frame was on the bus, in nanoseconds since the Unix epoch.
    pub timestamp: Timestamp,
    /// The interface it was on (`can0`, `vcan1`).
    pub interface: String,
    /// The frame.
    pub frame: Frame,
    /// `Some('R')` or `Some('T')` when the line carries a direction.
    pub direction: Option<char>,
}

/// A record lent by a reader, its interface name still in the line it was read from: for
/// callers that need no copy of it (counting, filtering), see [`Reader::for_each_ref`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogRecordRef<'a> {
    /// When the frame was on the bus, in nanoseconds since the Unix epoch.
    pub timestamp: Timestamp,
    /// The interface it was on.
    pub interface: &'a str,
    /// The frame.
    pub frame: Frame,
    /// `Some('R')` or `Some('T')` when the line carries a direction.
    pub direction: Option<char>,
}

impl LogRecordRef<'_> {
    /// The record with its own copy of the interface name.
    pub fn to_record(&self) -> LogRecord {
        LogRecord {
            timestamp: self.timestamp,
            interface: self.interface.to_string(),
            frame: self.frame,
            direction: self.direction,
        }
    }
}

impl LogRecord {
    /// The record lent as a [`LogRecordRef`].
    pub fn as_record_ref(&self) -> LogRecordRef<'_> {
        LogRecordRef {
            timestamp: self.timestamp,
            interface: &self.interface,
            frame: self.frame,
            direction: self.direction,
        }
    }
}

/// A line that is not a candump log line, with where the problem is.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LogError {
    /// The line is malformed.
    #[error("line {line}, column {column}: {kind}")]
    Syntax {
        /// 1-based line number.
        line: u64,
        /// 1-based column (character position).
        column: usize,
        /// What is wrong.
        kind: LogErrorKind,
    },
    /// A binary log (pcapng, BLF) is malformed or could not be read at this byte.
    #[error("byte {offset}: {what}")]
    Binary {
        /// Where the block at fault starts (or reading stopped).
        offset: u64,
        /// What is wrong.
        what: String,
    },
    /// A binary log ends inside a record at this byte: cut short (a kill, a full disk). What
    /// came before it was read whole; readers that can say so call it a warning.
    #[error(
        "byte {offset}: {what}: the file is cut short there (read up to its last whole record)"
    )]
    CutShort {
        /// Where the record cut short starts (or where the file ends).
        offset: u64,
        /// Which record.
        what: String,
    },
    /// A record of a binary log that no frame can hold (a standard identifier above 0x7FF):
    /// passed over, and the reading goes on.
    #[error("byte {offset}: {what} (passed over)")]
    Unrepresentable {
        /// Where its container or block starts.
        offset: u64,
        /// What it holds.
        what: String,
    },
    /// A table (Parquet) is malformed at this row.
    #[error("row {row}: {what}")]
    Table {
        /// The 0-based row (of the whole file) where the batch at fault starts, or the row.
        row: u64,
        /// What is wrong.
        what: String,
    },
    /// Reading failed.
    #[error("line {line}: {message}")]
    Io {
        /// The line being read.
        line: u64,
        /// The I/O error, as text (so the error stays comparable).
        message: String,
    },
}

/// What is wrong with a log line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LogErrorKind {
    /// The line does not start with `(`.
    #[error("expected '(' and a timestamp, as in (1699999999.123456) can0 123#DEADBEEF")]
    NoTimestamp,
    /// The timestamp is not SECONDS.FRACTION.
    #[error("timestamp is not SECONDS.FRACTION with 1-9 fraction digits: {0}")]
    BadTimestamp(&'static str),
    /// No interface name after the timestamp.
    #[error("expected an interface name after the timestamp")]
    NoInterface,
    /// No frame after the interface name.
    #[error("expected a frame after the interface name")]
    NoFrame,
    /// The frame text is invalid.
    #[error("frame: {0}")]
    Frame(ParseFrameErrorKind),
    /// The line is longer than any log line (skipped; reading goes on).
    #[error("{0} bytes: longer than a log line")]
    TooLong(u64),
    /// The line is not UTF-8 (from this column on).
    #[error("not UTF-8")]
    NotUtf8,
    /// A line of another log format that is malformed (what, in words).
    #[error("{0}")]
    Format(String),
    /// Something after the frame other than a direction.
    #[error("unexpected '{0}' after the frame (only a direction R or T may follow)")]
    Trailing(String),
}

/// Parse one log line. Columns in errors are 1-based.
pub fn parse_line(text: &str) -> Result<LogRecord, (usize, LogErrorKind)> {
    parse_line_ref(text).map(|record| record.to_record())
}

/// [`parse_line`], the interface name lent from `text`.
pub fn parse_line_ref(text: &str) -> Result<LogRecordRef<'_>, (usize, LogErrorKind)> {
    parse_plain_line(text.as_bytes()).map_or_else(|| parse_line_in_full(text), Ok)
}

/// [`parse_line`] for any line, each problem named with its column.
fn parse_line_in_full(text: &str) -> Result<LogRecordRef<'_>, (usize, LogErrorKind)> {
    let rest = text
        .strip_prefix('(')
        .ok_or((1, LogErrorKind::NoTimestamp))?;
    let close = rest
        .find(')')
        .ok_or((2, LogErrorKind::BadTimestamp("no closing ')'")))?;
    let timestamp = parse_timestamp(rest.get(..close).unwrap_or(""))
        .map_err(|why| (2, LogErrorKind::BadTimestamp(why)))?;
    // ')' is at column close + 2; one space, then the interface.
    let mut column = close + 4;
    let mut fields = rest.get(close + 1..).unwrap_or("").split(' ');
    if fields.next() != Some("") {
        return Err((column - 1, LogErrorKind::NoInterface));
    }
    let interface = fields
        .next()
        .filter(|s| !s.is_empty())
        .ok_or((column, LogErrorKind::NoInterface))?;
    column += interface.chars().count() + 1;
    let frame_text = fields
        .next()
        .filter(|s| !s.is_empty())
        .ok_or((column, LogErrorKind::NoFrame))?;
    let frame = frame_text
        .parse::<Frame>()
        .map_err(|e| (column + e.column - 1, LogErrorKind::Frame(e.kind)))?;
    column += frame_text.chars().count() + 1;
    let direction = match fields.next() {
        None => None,
        Some("R") => Some('R'),
        Some("T") => Some('T'),
        Some(other) => return Err((column, LogErrorKind::Trailing(other.to_string()))),
    };
    if let Some(extra) = fields.next() {
        return Err((column + 2, LogErrorKind::Trailing(extra.to_string())));
    }
    Ok(LogRecordRef {
        timestamp,
        interface,
        frame,
        direction,
    })
}

/// The common line — `(SECONDS.FRACTION) IFACE FRAME`, perhaps ` R` or ` T` after, single
/// spaces — read in one pass without the column bookkeeping an error needs; `None` for
/// anything else, which [`parse_line`]'s full path then reads or names. Most of a log's time
/// goes here; a property test holds the two paths to the same records.
/// The line's bytes are taken as they come: what it reads is ASCII but for the interface's
/// name, checked on its own, so a line read here needs no UTF-8 check of its whole.
// Inlined into the caller's loop so the record is built where it is used: returned through
// memory, its just-written bytes were read back before they had landed (a store-forwarding
// stall of about a tenth of `log stats`' time).
#[inline(always)]
fn parse_plain_line(bytes: &[u8]) -> Option<LogRecordRef<'_>> {
    if bytes.first() != Some(&b'(') {
        return None;
    }
    let (secs, dot) = plain_digits(bytes, 1)?;
    if dot == 1 || bytes.get(dot) != Some(&b'.') {
        return None;
    }
    let (fraction, close) = plain_digits(bytes, dot + 1)?;
    let fraction_digits = u32::try_from(close - dot - 1).ok()?;
    if !(1..=9).contains(&fraction_digits) || bytes.get(close..close + 2) != Some(b") ") {
        return None;
    }
    let timestamp = secs
        .checked_mul(1_000_000_000)?
        .checked_add(fraction * 10u64.pow(9 - fraction_digits))
        .map(Timestamp::from_nanos)?;
    let interface_start = close + 2;
    let interface_end = interface_start
        + bytes
            .get(interface_start..)?
            .iter()
            .position(|&b| b == b' ')?;
    let frame_start = interface_end + 1;
    // A direction is the line's last two bytes; a space anywhere else fails the frame's parse.
    let (frame_end, direction) = match bytes.get(bytes.len().saturating_sub(2)..) {
        Some(b" R") => (bytes.len() - 2, Some('R')),
        Some(b" T") => (bytes.len() - 2, Some('T')),
        _ => (bytes.len(), None),
    };
    if interface_end == interface_start || frame_end <= frame_start {
        return None;
    }
    let frame = Frame::from_ascii(bytes.get(frame_start..frame_end)?).ok()?;
    Some(LogRecordRef {
        timestamp,
        interface: std::str::from_utf8(bytes.get(interface_start..interface_end)?).ok()?,
        frame,
        direction,
    })
}

/// The decimal number from `start` up to the first non-digit, and where that is; `None` for
/// more than 19 digits (the full path reads or names those).
fn plain_digits(bytes: &[u8], start: usize) -> Option<(u64, usize)> {
    let rest = bytes.get(start..)?;
    let mut value = 0u64;
    let mut count = 0;
    // Eight digits at a time while they last (a timestamp's seconds), then one at a time.
    while let Some(eight) = rest
        .get(count..count + 8)
        .filter(|_| count + 8 <= 19)
        .and_then(|chunk| <[u8; 8]>::try_from(chunk).ok())
        .and_then(eight_digits)
    {
        value = value * 100_000_000 + eight;
        count += 8;
    }
    for &b in rest.get(count..)? {
        let digit = b.wrapping_sub(b'0');
        if digit > 9 {
            break;
        }
        if count == 19 {
            return None;
        }
        // Nineteen digits or fewer fit a u64.
        value = value * 10 + u64::from(digit);
        count += 1;
    }
    Some((value, start + count))
}

/// Eight ASCII digits as their number, all at once in a u64 (`None` when one is not a digit).
fn eight_digits(chunk: [u8; 8]) -> Option<u64> {
    const HIGH: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    const ZEROS: u64 = 0x3030_3030_3030_3030;
    let text = u64::from_le_bytes(chunk);
    // A digit is 0x30-0x39: its high half is 3, and adding 6 to it leaves that so.
    if text & HIGH != ZEROS || (text + 0x0606_0606_0606_0606) & HIGH != ZEROS {
        return None;
    }
    // The first digit is the lowest byte: pairs, then fours, then all eight, each step
    // joining neighbours (what spills into the lanes above is masked off).
    let digits = text - ZEROS;
    let pairs = (digits.wrapping_mul(10) + (digits >> 8)) & 0x00FF_00FF_00FF_00FF;
    let fours = (pairs.wrapping_mul(100) + (pairs >> 16)) & 0x0000_FFFF_0000_FFFF;
    Some((fours.wrapping_mul(10_000) + (fours >> 32)) & 0xFFFF_FFFF)
}

fn parse_timestamp(text: &str) -> Result<Timestamp, &'static str> {
    let (secs, fraction) = text.split_once('.').ok_or("no '.'")?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !digits(secs) || !digits(fraction) {
        return Err("not digits");
    }
    if fraction.len() > 9 {
        return Err("more than 9 fraction digits");
    }
    let secs: u64 = secs.parse().map_err(|_| "seconds out of range")?;
    let scale = 10u64.pow(9 - u32::try_from(fraction.len()).unwrap_or(9));
    let fraction: u64 = fraction.parse().map_err(|_| "not digits")?;
    secs.checked_mul(1_000_000_000)
        .and_then(|n| n.checked_add(fraction * scale))
        .map(Timestamp::from_nanos)
        .ok_or("seconds out of range")
}

/// Reads a candump log one line at a time, in bounded memory (a line longer than
/// [`crate::lines::DEFAULT_MAX_LINE`] is an error naming it, and skipped). Blank lines are
/// skipped; every other line is a record or an error naming its line (reading goes on after an
/// error).
pub struct Reader<R> {
    lines: CappedLines<R>,
    line: u64,
    log_lines_only: bool,
}

impl<R: BufRead> Reader<R> {
    /// A reader over `input`.
    pub fn new(input: R) -> Self {
        Reader {
            lines: CappedLines::new(input),
            line: 0,
            log_lines_only: false,
        }
    }

    /// Skip lines that do not start with `(` instead of reporting them, as canplayer does
    /// (line numbers in errors stay the file's).
    pub fn log_lines_only(mut self) -> Self {
        self.log_lines_only = true;
        self
    }

    /// The number of the line read last (1-based; 0 before the first).
    pub fn line(&self) -> u64 {
        self.line
    }
}

/// The next line of text of a text log with its number (kept in `last`), or the error that
/// line is: an I/O error, a line too long, one not UTF-8. Shared by the text formats' readers.
pub(crate) fn next_text<'a, R: BufRead>(
    lines: &'a mut CappedLines<R>,
    last: &mut u64,
) -> Option<Result<(u64, &'a str), LogError>> {
    let (number, line) = match lines.next_str()? {
        Ok(next) => next,
        Err(e) => return Some(Err(read_error(*last, &e))),
    };
    *last = number;
    Some(text_of(number, line).map(|text| (number, text)))
}

/// The error a read that failed after line `last` is.
fn read_error(last: u64, e: &io::Error) -> LogError {
    LogError::Io {
        line: last + 1,
        message: e.to_string(),
    }
}

/// Line `number` as text, or the error naming why it cannot be read (too long, not UTF-8).
fn text_of(number: u64, line: LineRef<'_>) -> Result<&str, LogError> {
    let syntax = |column, kind| LogError::Syntax {
        line: number,
        column,
        kind,
    };
    match line {
        LineRef::Text(text) => Ok(text),
        LineRef::TooLong { bytes } => Err(syntax(1, LogErrorKind::TooLong(bytes))),
        LineRef::NotUtf8 { at } => Err(syntax(at + 1, LogErrorKind::NotUtf8)),
    }
}

impl<R: BufRead> Reader<R> {
    /// Hand each record to `each`, lent rather than copied (no allocation per line), until
    /// the input ends (`None`) or `each` breaks (what it broke with). Errors are handed on
    /// as the iterator gives them; reading goes on after one unless `each` breaks.
    pub fn for_each_ref<B>(
        &mut self,
        mut each: impl FnMut(Result<&LogRecordRef<'_>, LogError>) -> ControlFlow<B>,
    ) -> Option<B> {
        // Bounded by the input's lines.
        loop {
            let (number, line) = match self.lines.next_bytes()? {
                Ok(next) => next,
                Err(e) => match each(Err(read_error(self.line, &e))) {
                    ControlFlow::Break(b) => return Some(b),
                    ControlFlow::Continue(()) => continue,
                },
            };
            self.line = number;
            let unplain = match line {
                // Most lines are read here, without a UTF-8 check of the whole line.
                LineBytes::Bytes(bytes) => match parse_plain_line(strip_cr(bytes)) {
                    Some(record) => match each(Ok(&record)) {
                        ControlFlow::Break(b) => return Some(b),
                        ControlFlow::Continue(()) => continue,
                    },
                    None => line_ref(bytes),
                },
                LineBytes::TooLong { bytes } => LineRef::TooLong { bytes },
            };
            let record = match text_of(number, unplain) {
                Ok(text)
                    if !text.starts_with('(')
                        && (self.log_lines_only || text.trim().is_empty()) =>
                {
                    continue
                }
                Ok(text) => parse_line_in_full(text).map_err(|(column, kind)| LogError::Syntax {
                    line: number,
                    column,
                    kind,
                }),
                Err(e) => Err(e),
            };
            // Lent by reference: a record is not copied on its way to `each`.
            let flow = match record {
                Ok(ref record) => each(Ok(record)),
                Err(e) => each(Err(e)),
            };
            if let ControlFlow::Break(b) = flow {
                return Some(b);
            }
        }
    }
}

/// A line's bytes without a `\r` at its end.
fn strip_cr(line: &[u8]) -> &[u8] {
    line.strip_suffix(b"\r").unwrap_or(line)
}

impl<R: BufRead> Iterator for Reader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.for_each_ref(|record| ControlFlow::Break(record.map(|r| r.to_record())))
    }
}

/// How many fraction digits timestamps are written with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// Six, as candump writes them (what canplayer expects).
    #[default]
    Micros,
    /// Nine.
    Nanos,
}

/// The frame as candump prints it: with `raw_dlc` (candump `-8`) a classic frame's DLC above 8
/// shows as `_X`; without, the frame is printed as its 8 bytes.
pub fn frame_text(frame: &Frame, raw_dlc: bool) -> impl fmt::Display + '_ {
    CandumpFrame(frame, raw_dlc)
}

struct CandumpFrame<'a>(&'a Frame, bool);

impl CandumpFrame<'_> {
    fn text(&self) -> FrameText {
        match self.0 {
            Frame::Classic(c) if !self.1 && c.dlc().as_raw() > 8 => {
                let plain = if c.is_remote() {
                    Dlc::from_classic_len(8).map(|eight| ClassicFrame::remote(c.id(), eight))
                } else {
                    ClassicFrame::new(c.id(), c.data()).ok()
                };
                plain.map_or_else(|| self.0.text(), |p| Frame::Classic(p).text())
            }
            other => other.text(),
        }
    }
}

impl fmt::Display for CandumpFrame<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text().as_str())
    }
}

/// A timestamp as `SECONDS.FRACTION` (ten-digit zero-padded seconds, as candump prints them).
pub fn timestamp_text(timestamp: Timestamp, precision: Precision) -> impl fmt::Display {
    TimestampText(timestamp, precision)
}

struct TimestampText(Timestamp, Precision);

impl TimestampText {
    /// The text in a buffer on the stack (at most 11 digits of seconds, a point and 9 of
    /// fraction), and its length.
    fn bytes(&self) -> ([u8; 24], usize) {
        let nanos = self.0.as_nanos();
        let (secs, sub) = (nanos / 1_000_000_000, nanos % 1_000_000_000);
        let (fraction, digits) = match self.1 {
            Precision::Micros => (sub / 1000, 6),
            Precision::Nanos => (sub, 9),
        };
        let mut text = [0u8; 24];
        let mut len = push_decimal(&mut text, 0, secs, 10);
        if let Some(point) = text.get_mut(len) {
            *point = b'.';
            len += 1;
        }
        len = push_decimal(&mut text, len, fraction, digits);
        (text, len)
    }
}

/// `value` in decimal at `at` in `text`, zero-padded to `width` digits; where it ends. Two
/// digits a step through a table (a division by 10 a digit cost most of a line's writing).
fn push_decimal(text: &mut [u8], at: usize, value: u64, width: usize) -> usize {
    const PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
        2021222324252627282930313233343536373839\
        4041424344454647484950515253545556575859\
        6061626364656667686970717273747576777879\
        8081828384858687888990919293949596979899";
    // At most 20 digits in a u64, filled from the right.
    let mut digits = [b'0'; 20];
    let mut start = digits.len();
    let mut rest = value;
    while rest >= 10 {
        let pair = usize::try_from(rest % 100).unwrap_or(0) * 2;
        rest /= 100;
        start = start.saturating_sub(2);
        if let (Some(slot), Some(two)) =
            (digits.get_mut(start..start + 2), PAIRS.get(pair..pair + 2))
        {
            slot.copy_from_slice(two);
        }
    }
    if rest > 0 || start == digits.len() {
        start = start.saturating_sub(1);
        if let Some(slot) = digits.get_mut(start) {
            *slot = b'0' + u8::try_from(rest).unwrap_or(0);
        }
    }
    // Zero-padded: the leading zeros are already in place.
    let start = start.min(digits.len().saturating_sub(width));
    let shown = digits.get(start..).unwrap_or(&[]);
    let end = (at + shown.len()).min(text.len());
    if let Some(slot) = text.get_mut(at..end) {
        slot.copy_from_slice(shown.get(..end - at).unwrap_or(&[]));
    }
    end
}

impl fmt::Display for TimestampText {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (text, len) = self.bytes();
        f.write_str(std::str::from_utf8(text.get(..len).unwrap_or(&[])).unwrap_or(""))
    }
}

/// Writes candump log lines.
pub struct Writer<W> {
    output: W,
    precision: Precision,
    raw_dlc: bool,
    line: Vec<u8>,
}

impl<W: Write> Writer<W> {
    /// A writer with candump's defaults (microseconds, no raw DLC).
    pub fn new(output: W) -> Self {
        Writer {
            output,
            precision: Precision::Micros,
            raw_dlc: false,
            line: Vec::with_capacity(192),
        }
    }

    /// Write timestamps with this precision.
    pub fn precision(mut self, precision: Precision) -> Self {
        self.precision = precision;
        self
    }

    /// Write classic DLCs above 8 as `_X` (candump `-8`).
    pub fn raw_dlc(mut self, on: bool) -> Self {
        self.raw_dlc = on;
        self
    }

    /// Write one line; the whole line is built first (bytes copied, not formatted), so a
    /// failed write never leaves a partial line from this call in the output buffer's logic.
    pub fn write(
        &mut self,
        timestamp: Timestamp,
        interface: &str,
        frame: &Frame,
    ) -> io::Result<()> {
        self.write_line(timestamp, interface, frame, None)
    }

    /// Write a record (its direction too).
    pub fn write_record(&mut self, record: &LogRecord) -> io::Result<()> {
        self.write_line(
            record.timestamp,
            &record.interface,
            &record.frame,
            record.direction,
        )
    }

    fn write_line(
        &mut self,
        timestamp: Timestamp,
        interface: &str,
        frame: &Frame,
        direction: Option<char>,
    ) -> io::Result<()> {
        let line = &mut self.line;
        line.clear();
        let (stamp, stamp_len) = TimestampText(timestamp, self.precision).bytes();
        line.push(b'(');
        line.extend_from_slice(stamp.get(..stamp_len).unwrap_or(&[]));
        line.extend_from_slice(b") ");
        line.extend_from_slice(interface.as_bytes());
        line.push(b' ');
        line.extend_from_slice(CandumpFrame(frame, self.raw_dlc).text().as_bytes());
        if let Some(direction) = direction {
            let mut utf8 = [0u8; 4];
            line.push(b' ');
            line.extend_from_slice(direction.encode_utf8(&mut utf8).as_bytes());
        }
        line.push(b'\n');
        self.output.write_all(line)
    }

    /// Flush the output.
    pub fn flush(&mut self) -> io::Result<()> {
        self.output.flush()
    }

    /// The output back.
    pub fn into_inner(self) -> W {
        self.output
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Lines near the common shape: well-formed ones, and ones with a piece missing, doubled or
    /// out of range (odd spacing, long fractions, huge seconds, bad hex, extra fields).
    fn near_log_lines() -> impl Strategy<Value = String> {
        let well_formed = (
            0u64..4_000_000_000,
            "[0-9]{1,9}",
            "(can|vcan|slcan)[0-9]",
            "[0-7][0-9A-F]{2}#([0-9A-F]{2}){0,8}|[0-9A-F]{8}#([0-9A-Fa-f]{2}){0,8}|[0-9A-F]{3}##[0-7]([0-9A-F]{2}){0,12}|[0-9A-F]{3}#R[0-8]?",
            prop_oneof![Just(""), Just(" R"), Just(" T")],
        )
            .prop_map(|(secs, fraction, iface, frame, dir)| {
                format!("({secs}.{fraction}) {iface} {frame}{dir}")
            });
        let mangled = "\\(?[0-9]{0,21}\\.?[0-9]{0,11}\\)? {0,2}[a-z0-9]{0,5} {0,2}[0-9A-Fa-fR#._]{0,22}( {0,2}[RTX]{0,2}){0,2}";
        prop_oneof![well_formed, mangled]
    }

    /// A log of such lines, some with a `\r`, blank or with bytes that are not UTF-8.
    fn near_logs() -> impl Strategy<Value = Vec<u8>> {
        let line = prop_oneof![
            8 => near_log_lines().prop_map(String::into_bytes),
            1 => Just(Vec::new()),
            1 => near_log_lines().prop_map(|l| format!("{l}\r").into_bytes()),
            1 => (near_log_lines(), any::<usize>(), 0x80u8..).prop_map(|(l, at, bad)| {
                let mut bytes = l.into_bytes();
                let at = at % (bytes.len() + 1);
                bytes.insert(at, bad);
                bytes
            }),
            1 => (near_log_lines(), "[ a-zé]{1,6}").prop_map(|(l, iface)| {
                l.replacen("can", &iface, 1).into_bytes()
            }),
        ];
        proptest::collection::vec(line, 0..12).prop_map(|lines| lines.join(&b'\n'))
    }

    proptest! {
        /// The reader parses most lines before checking them to be UTF-8: what it reads is
        /// what checking each line first, then parsing it, reads.
        #[test]
        fn the_reader_reads_what_checked_lines_parse_to(log in near_logs(), only_log_lines in any::<bool>()) {
            let mut reader = Reader::new(&log[..]);
            if only_log_lines {
                reader = reader.log_lines_only();
            }
            let got: Vec<_> = reader.collect();
            let mut expected = Vec::new();
            let mut lines = CappedLines::new(&log[..]);
            let mut last = 0;
            while let Some(next) = next_text(&mut lines, &mut last) {
                let (number, text) = match next {
                    Ok(next) => next,
                    Err(e) => {
                        expected.push(Err(e));
                        continue;
                    }
                };
                if text.trim().is_empty() || (only_log_lines && !text.starts_with('(')) {
                    continue;
                }
                expected.push(parse_line(text).map_err(|(column, kind)| LogError::Syntax {
                    line: number,
                    column,
                    kind,
                }));
            }
            prop_assert_eq!(got, expected);
        }

        #[test]
        fn the_plain_path_reads_lines_as_the_full_path_does(line in near_log_lines()) {
            if let Some(record) = parse_plain_line(line.as_bytes()) {
                prop_assert_eq!(parse_line_in_full(&line), Ok(record), "{}", line);
            }
        }
    }

    proptest! {
        /// A line built from bytes is the line `format!` builds field by field from candump's
        /// forms: `{secs:010}.{micros:06}` (or nanoseconds), the interface, the frame (a raw DLC
        /// shown or not), the direction.
        #[test]
        fn lines_are_built_as_format_builds_them(
            nanos in prop_oneof![any::<u64>(), 0u64..2_000_000_000_000_000_000],
            nanoseconds in any::<bool>(),
            raw_dlc in any::<bool>(),
            interface in "[a-z]{1,5}[0-9]",
            id in 0u32..=0x7FF,
            data in any::<[u8; 8]>(),
            dlc in 0u8..=15,
            direction in prop::option::of(prop_oneof![Just('R'), Just('T')]),
        ) {
            let id = bywire_core::Id::standard(id).unwrap();
            let dlc = Dlc::new(dlc).unwrap();
            let data = &data[..dlc.classic_len()];
            let frame = Frame::Classic(ClassicFrame::with_dlc(id, dlc, data).unwrap());
            let (secs, sub) = (nanos / 1_000_000_000, nanos % 1_000_000_000);
            let stamp = if nanoseconds {
                format!("{secs:010}.{sub:09}")
            } else {
                format!("{secs:010}.{:06}", sub / 1000)
            };
            let shown = if raw_dlc || dlc.as_raw() <= 8 {
                frame.to_string()
            } else {
                Frame::Classic(ClassicFrame::new(id, data).unwrap()).to_string()
            };
            let tail = direction.map(|d| format!(" {d}")).unwrap_or_default();
            let expected = format!("({stamp}) {interface} {shown}{tail}\n");
            let precision = if nanoseconds { Precision::Nanos } else { Precision::Micros };
            let mut w = Writer::new(Vec::new()).precision(precision).raw_dlc(raw_dlc);
            w.write_record(&LogRecord {
                timestamp: Timestamp::from_nanos(nanos),
                interface: interface.clone(),
                frame,
                direction,
            })
            .unwrap();
            prop_assert_eq!(String::from_utf8(w.into_inner()).unwrap(), expected.clone());
            let displayed = format!(
                "({}) {interface} {}{tail}\n",
                timestamp_text(Timestamp::from_nanos(nanos), precision),
                frame_text(&frame, raw_dlc)
            );
            prop_assert_eq!(displayed, expected);
        }

        #[test]
        fn decimals_are_written_as_format_writes_them(value in prop_oneof![any::<u64>(), 0u64..1000], width in 0usize..=20) {
            let mut text = [0u8; 24];
            let end = push_decimal(&mut text, 2, value, width);
            let expected = format!("{value:0width$}");
            prop_assert_eq!(&text[2..end], expected.as_bytes());
        }

        #[test]
        fn eight_digits_at_once_read_as_one_at_a_time(chunk in any::<[u8; 8]>(), digits in "[0-9]{8}") {
            let one_at_a_time = |chunk: [u8; 8]| {
                chunk.iter().try_fold(0u64, |v, b| b.is_ascii_digit().then(|| v * 10 + u64::from(b - b'0')))
            };
            prop_assert_eq!(eight_digits(chunk), one_at_a_time(chunk));
            let chunk = <[u8; 8]>::try_from(digits.as_bytes()).unwrap();
            prop_assert_eq!(eight_digits(chunk), Some(digits.parse::<u64>().unwrap()));
        }
    }

    #[test]
    fn the_plain_path_takes_the_common_lines() {
        for line in [
            "(1700000000.000137) can1 338#8B8E1503FD9E1FFF",
            "(0.1) vcan0 12345678#",
            "(1.000000000) can0 123##1DEADBEEF R",
            "(5.5) can0 7FF#R8 T",
        ] {
            assert!(parse_plain_line(line.as_bytes()).is_some(), "{line}");
            assert_eq!(parse_line_ref(line), parse_line_in_full(line), "{line}");
        }
        for line in [
            "(1.000000) can0  123#00",
            "(1.0000000000) can0 123#00",
            "(99999999999999999999.0) can0 123#00",
            "(1.5)can0 123#00",
            "(1.5) can0 123#00 R X",
            "(1.5) can0 123#00 ",
        ] {
            assert!(parse_plain_line(line.as_bytes()).is_none(), "{line}");
            assert!(parse_line(line).is_err(), "{line}");
        }
    }

    #[test]
    fn a_line_too_long_or_not_utf8_is_an_error_naming_it_and_reading_goes_on() {
        let mut log = b"(1.000000) can0 123#01\n".to_vec();
        log.extend(std::iter::repeat_n(b'x', 100_000));
        log.extend(b"\n(2.000000) can0 123#\xff\n(3.000000) can0 124#02\n");
        let results: Vec<_> = Reader::new(&log[..]).collect();
        assert_eq!(results.len(), 4);
        assert!(results[0].is_ok() && results[3].is_ok());
        assert!(matches!(
            results[1],
            Err(LogError::Syntax {
                line: 2,
                kind: LogErrorKind::TooLong(100_000),
                ..
            })
        ));
        assert!(matches!(
            results[2],
            Err(LogError::Syntax {
                line: 3,
                column: 21,
                kind: LogErrorKind::NotUtf8
            })
        ));
    }

    #[test]
    fn reads_candump_lines() {
        let r = parse_line("(1699999999.123456) can0 123#DEADBEEF").unwrap();
        assert_eq!(r.timestamp.as_nanos(), 1_699_999_999_123_456_000);
        assert_eq!(r.interface, "can0");
        assert_eq!(r.frame.to_string(), "123#DEADBEEF");
        let r = parse_line("(0.5) vcan1 1ABCDEF0##5AA T").unwrap();
        assert_eq!(r.timestamp.as_nanos(), 500_000_000);
        assert_eq!(r.direction, Some('T'));
        let r = parse_line("(1.000000001) x 20000080#0000000000000000").unwrap();
        assert!(r.frame.is_error());
        assert_eq!(r.timestamp.as_nanos(), 1_000_000_001);
    }

    #[test]
    fn names_the_column_of_a_problem() {
        let e = |t: &str| parse_line(t).unwrap_err();
        assert_eq!(e("1.0 can0 123#00").0, 1);
        assert_eq!(e("(1) can0 123#00").1, LogErrorKind::BadTimestamp("no '.'"));
        assert_eq!(e("(1.0000000001) can0 123#00").0, 2);
        assert_eq!(e("(1.0)").1, LogErrorKind::NoInterface);
        assert_eq!(e("(1.0) can0").1, LogErrorKind::NoFrame);
        // The frame starts at column 12; its G at 14.
        let (column, kind) = e("(1.0) can0 12G#00");
        assert_eq!(column, 14);
        assert!(matches!(kind, LogErrorKind::Frame(_)));
        let (column, kind) = e("(1.0) can0 123#0G");
        assert_eq!(column, 17);
        assert!(matches!(kind, LogErrorKind::Frame(_)));
        assert_eq!(
            e("(1.0) can0 123#00 X").1,
            LogErrorKind::Trailing("X".into())
        );
        assert_eq!(e("(99999999999999999999.0) can0 123#00").0, 2);
    }

    #[test]
    fn writes_what_it_reads() {
        let text =
            "(1699999999.123456) can0 123#DEADBEEF\n\n(1699999999.200000) can1 1ABCDEF0##5AA T\n";
        let records: Vec<_> = Reader::new(text.as_bytes())
            .collect::<Result<_, _>>()
            .unwrap();
        let mut w = Writer::new(Vec::new());
        for r in &records {
            w.write_record(r).unwrap();
        }
        assert_eq!(
            String::from_utf8(w.into_inner()).unwrap(),
            text.replace("\n\n", "\n")
        );
    }

    #[test]
    fn errors_name_the_line_and_reading_goes_on() {
        let text = "(1.0) can0 123#00\nnot a log line\n(2.0) can0 124#01\n";
        let results: Vec<_> = Reader::new(text.as_bytes()).collect();
        assert_eq!(results.len(), 3);
        assert!(matches!(
            results[1],
            Err(LogError::Syntax {
                line: 2,
                column: 1,
                ..
            })
        ));
        assert_eq!(results[2].as_ref().unwrap().frame.to_string(), "124#01");
    }

    #[test]
    fn raw_dlc_and_nanoseconds_on_request() {
        let frame: Frame = "123#1122334455667788_E".parse().unwrap();
        let ts = Timestamp::from_nanos(1_000_000_123);
        let mut w = Writer::new(Vec::new());
        w.write(ts, "can0", &frame).unwrap();
        let mut w8 = Writer::new(Vec::new())
            .raw_dlc(true)
            .precision(Precision::Nanos);
        w8.write(ts, "can0", &frame).unwrap();
        assert_eq!(
            String::from_utf8(w.into_inner()).unwrap(),
            "(0000000001.000000) can0 123#1122334455667788\n"
        );
        assert_eq!(
            String::from_utf8(w8.into_inner()).unwrap(),
            "(0000000001.000000123) can0 123#1122334455667788_E\n"
        );
    }
}
