//! Vector ASC logs: the text format CANoe and CANalyzer write, read and written as python-can
//! and can-utils' `log2asc`/`asc2log` do.
//!
//! A file has a header (`date …`, `base hex|dec  timestamps absolute|relative`, `internal
//! events logged`), optionally a `Begin Triggerblock DATE` whose date the times count from,
//! then one event a line: `0.100000 1  123  Rx   d 4 DE AD BE EF` (channel, identifier with
//! `x` for extended, direction, `d DLC` and data, or `r [DLC]` for a remote frame),
//! `0.200000 1  ErrorFrame`, and CAN FD frames as `CANFD   1 Rx  123  1 0 8 8 11 22 …` (BRS,
//! ESI, DLC, data length, data, then duration, length and flags). Other events (statistics,
//! `Start of measurement`, comments) are passed over.
//!
//! Dates are read and written as UTC (the format has no time zone; Vector tools write local
//! time). Channels are numbered from 1: channel N is interface `can{N-1}`, and an interface
//! whose name ends in a number M is written as channel M+1 (as python-can maps them); an
//! interface the number does not name is given by a comment before its channel's first frame
//! (`// channel 2 = bus1`), which the reader takes and other readers pass over.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame};
use bywire_core::{Frame, Id, Timestamp};

use crate::calendar::{civil_from_days, days_from_civil};
use crate::candump::{LogError, LogRecord};
use crate::fields::{
    channel_comment, channel_comment_text, channel_number, column_of, data_bytes, dlc, fixed_point,
    syntax, WriteClock, MAX_CHANNEL_NAMES,
};
use crate::lines::CappedLines;

const NANOS_PER_SECOND: u64 = 1_000_000_000;

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];
const WEEKDAYS: [&str; 7] = ["Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"];

/// A month by its abbreviation, English or German (CANoe writes the locale's).
fn month_number(name: &str) -> Option<u32> {
    let lower = name.to_lowercase();
    let german = [("mär", 3), ("mrz", 3), ("mai", 5), ("okt", 10), ("dez", 12)];
    MONTHS
        .iter()
        .zip(1..)
        .find(|(m, _)| m.eq_ignore_ascii_case(&lower))
        .map(|(_, n)| n)
        .or_else(|| german.iter().find(|(m, _)| *m == lower).map(|(_, n)| *n))
}

/// A header or trigger-block date (`Tue Dec 01 19:00:00.000 2026`, the weekday optional, a
/// 12-hour clock with AM/PM accepted) as nanoseconds since the Unix epoch (UTC).
pub fn parse_date(text: &str) -> Option<u64> {
    let mut words: Vec<&str> = text.split_whitespace().collect();
    // The weekday (in any language) comes first, if at all.
    if words.first().is_some_and(|w| month_number(w).is_none()) {
        words.remove(0);
    }
    let (month, day, clock, rest) = match words.as_slice() {
        [month, day, clock, rest @ ..] => {
            (month_number(month)?, day.parse::<u32>().ok()?, *clock, rest)
        }
        _ => return None,
    };
    let (meridiem, year) = match rest {
        [year] => (None, year.parse::<i64>().ok()?),
        [m, year] => (Some(m.to_ascii_uppercase()), year.parse::<i64>().ok()?),
        _ => return None,
    };
    let (hms, fraction) = clock.split_once('.').unwrap_or((clock, ""));
    let mut parts = hms.split(':').map(|p| p.parse::<u64>().ok());
    let (mut hour, minute, second) = (parts.next()??, parts.next()??, parts.next()??);
    match meridiem.as_deref() {
        Some("PM") if hour < 12 => hour += 12,
        Some("AM") if hour == 12 => hour = 0,
        Some("AM" | "PM") | None => {}
        Some(_) => return None,
    }
    // Years a timestamp in nanoseconds since 1970 can hold (and the calendar's arithmetic).
    if !(1970..=2554).contains(&year)
        || !(1..=31).contains(&day)
        || hour > 23
        || minute > 59
        || second > 60
        || fraction.len() > 9
    {
        return None;
    }
    let nanos = if fraction.is_empty() {
        0
    } else {
        let digits: u64 = fraction.parse().ok()?;
        digits * 10u64.pow(9 - u32::try_from(fraction.len()).ok()?)
    };
    let days = u64::try_from(days_from_civil(year, month, day)).ok()?;
    // A year far from now must not overflow.
    let seconds = days
        .checked_mul(86_400)?
        .checked_add(hour * 3_600 + minute * 60 + second)?;
    seconds.checked_mul(NANOS_PER_SECOND)?.checked_add(nanos)
}

/// A date as ASC writes it: `Tue Dec 01 19:00:00 2026` (whole seconds, the form every reader
/// takes: can-utils' `asc2log` refuses a date with milliseconds).
pub fn format_date(at: Timestamp) -> String {
    let nanos = at.as_nanos();
    let seconds = nanos / NANOS_PER_SECOND;
    let days = i64::try_from(seconds / 86_400).unwrap_or(0);
    let (year, month, day) = civil_from_days(days);
    let in_day = seconds % 86_400;
    let weekday = WEEKDAYS
        .get(usize::try_from((days + 4).rem_euclid(7)).unwrap_or(0))
        .unwrap_or(&"Thu");
    let month_name = MONTHS
        .get(usize::try_from(month.saturating_sub(1)).unwrap_or(0))
        .unwrap_or(&"Jan");
    format!(
        "{weekday} {month_name} {day:02} {:02}:{:02}:{:02} {year}",
        in_day / 3_600,
        in_day % 3_600 / 60,
        in_day % 60
    )
}

/// How identifiers and data bytes are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Base {
    Hex,
    Dec,
}

impl Base {
    fn radix(self) -> u32 {
        match self {
            Base::Hex => 16,
            Base::Dec => 10,
        }
    }
}

/// Reads an ASC log one event at a time (bounded memory); `Item` is a frame record or an error
/// naming the line and column.
pub struct AscReader<R> {
    lines: CappedLines<R>,
    base: Base,
    relative: bool,
    /// Where the times count from (the trigger block's or the header's date).
    start: u64,
    /// The last event's time (relative timestamps add to it).
    last: u64,
    /// The number of the line read last.
    line: u64,
    /// Interface names by channel number, from `// channel N = NAME` comments.
    names: BTreeMap<u32, String>,
}

impl<R: BufRead> AscReader<R> {
    /// A reader over `input`.
    pub fn new(input: R) -> Self {
        AscReader {
            lines: CappedLines::new(input),
            base: Base::Hex,
            relative: false,
            start: 0,
            last: 0,
            line: 0,
            names: BTreeMap::new(),
        }
    }
}

/// The comment naming a channel's interface (`// channel 2 = bus1`), which bywire writes before
/// a channel's first frame: other readers pass comments over.
const CHANNEL_COMMENT: &str = "// channel ";

/// Seconds with a fraction (`0.100000`) as nanoseconds.
fn parse_seconds(text: &str) -> Option<u64> {
    fixed_point(text, 9)
}

/// What one line is.
enum Event {
    /// A CAN frame.
    Frame(LogRecord),
    /// Anything else (passed over).
    Other,
}

impl<R: BufRead> AscReader<R> {
    /// Header lines and trigger blocks change the reader's state; `Some` for an event line.
    fn header(&mut self, number: u64, text: &str) -> Result<bool, LogError> {
        if let Some((channel, name)) = channel_comment(text, CHANNEL_COMMENT) {
            if self.names.len() < MAX_CHANNEL_NAMES {
                self.names.insert(channel, name.to_string());
            }
            return Ok(true);
        }
        let lower = text.to_ascii_lowercase();
        let date = |rest: &str| {
            parse_date(rest)
                .ok_or_else(|| syntax(number, 1, format!("date not understood: '{}'", rest.trim())))
        };
        if let Some(rest) = lower.strip_prefix("date ") {
            let _ = rest;
            self.start = date(text.get(5..).unwrap_or(""))?;
            self.last = self.start;
            return Ok(true);
        }
        if lower.starts_with("base ") {
            let words: Vec<&str> = lower.split_whitespace().collect();
            self.base = match words.get(1) {
                Some(&"dec") => Base::Dec,
                Some(&"hex") => Base::Hex,
                _ => return Err(syntax(number, 6, "base is neither hex nor dec".into())),
            };
            self.relative = words.get(3) == Some(&"relative");
            return Ok(true);
        }
        if lower.starts_with("begin triggerblock") {
            let rest = text.get("begin triggerblock".len()..).unwrap_or("").trim();
            if !rest.is_empty() {
                self.start = date(rest)?;
            }
            self.last = self.start;
            return Ok(true);
        }
        Ok(false)
    }

    fn event(&mut self, number: u64, text: &str) -> Result<Event, LogError> {
        let mut words = text.split_whitespace();
        let Some(time_text) = words.next() else {
            return Ok(Event::Other);
        };
        // Events start with a time; anything else (comments, `End TriggerBlock`) is not one.
        let Some(time) = parse_seconds(time_text) else {
            return Ok(Event::Other);
        };
        let Some(channel) = words.next() else {
            return Ok(Event::Other);
        };
        let rest: Vec<&str> = words.collect();
        let at = if self.relative {
            self.last.saturating_add(time)
        } else {
            self.start.saturating_add(time)
        };
        let frame = if channel.eq_ignore_ascii_case("CANFD") {
            self.fd_event(number, text, &rest)?
        } else if channel.bytes().all(|b| b.is_ascii_digit()) {
            self.classic_event(number, text, channel, &rest)?
        } else {
            return Ok(Event::Other); // `Start of measurement`, statistics, J1939 …
        };
        let Some((channel_number, direction, frame)) = frame else {
            return Ok(Event::Other);
        };
        self.last = at;
        let n: u32 = channel_number.parse().map_err(|_| {
            syntax(
                number,
                column_of(text, channel_number),
                format!("channel '{channel_number}' is not a number"),
            )
        })?;
        Ok(Event::Frame(LogRecord {
            timestamp: Timestamp::from_nanos(at),
            interface: self
                .names
                .get(&n)
                .cloned()
                .unwrap_or_else(|| format!("can{}", n.saturating_sub(1))),
            frame,
            direction,
        }))
    }

    fn id(&self, number: u64, text: &str, word: &str) -> Result<Id, LogError> {
        let (digits, extended) = match word.strip_suffix(['x', 'X']) {
            Some(digits) => (digits, true),
            None => (word, false),
        };
        let raw = u32::from_str_radix(digits, self.base.radix()).map_err(|_| {
            syntax(
                number,
                column_of(text, word),
                format!("'{word}' is not an identifier"),
            )
        })?;
        let id = if extended {
            Id::extended(raw)
        } else {
            Id::standard(raw)
        };
        id.map_err(|e| syntax(number, column_of(text, word), e.to_string()))
    }

    fn bytes(
        &self,
        number: u64,
        text: &str,
        words: &[&str],
        count: usize,
    ) -> Result<Vec<u8>, LogError> {
        data_bytes(number, text, words, count, self.base.radix())
    }

    fn dlc(&self, number: u64, text: &str, word: &str) -> Result<Dlc, LogError> {
        dlc(number, text, word, self.base.radix())
    }

    /// A classic line's DLC word when it is a CAN FD data length beyond any DLC (over 15).
    fn fd_length(&self, word: &str) -> Option<usize> {
        let n = usize::from_str_radix(word, self.base.radix()).ok()?;
        (n > 15 && Dlc::from_fd_len(n).is_some_and(|d| d.fd_len() == n)).then_some(n)
    }

    /// `ID Rx|Tx d DLC DATA…`, `ID Rx|Tx r [DLC] [Length = …]` or `ErrorFrame` (the channel
    /// taken).
    #[allow(clippy::type_complexity)]
    fn classic_event<'t>(
        &self,
        number: u64,
        text: &'t str,
        channel: &'t str,
        rest: &[&'t str],
    ) -> Result<Option<(&'t str, Option<char>, Frame)>, LogError> {
        match rest {
            [error, ..] if error.eq_ignore_ascii_case("ErrorFrame") => {
                Ok(Some((channel, None, error_frame())))
            }
            [id, direction, kind, tail @ ..] => {
                let Some(direction) = parse_direction(direction) else {
                    return Ok(None);
                };
                let id = self.id(number, text, id)?;
                let frame = match (kind.to_ascii_lowercase().as_str(), tail) {
                    // The DLC is optional, and CANoe may follow with `Length = … BitCount = …`.
                    ("r", tail) => {
                        let dlc = tail.first().and_then(|w| self.dlc(number, text, w).ok());
                        Frame::remote(id, dlc.unwrap_or(Dlc::from_nibble(0)))
                    }
                    ("d", [dlc, data @ ..]) => match self.dlc(number, text, dlc) {
                        Ok(dlc_value) => {
                            let count = dlc_value.fd_len().min(8);
                            let bytes = self.bytes(number, text, data, count)?;
                            ClassicFrame::with_dlc(id, dlc_value, &bytes)
                                .map(Frame::Classic)
                                .map_err(|e| syntax(number, column_of(text, dlc), e.to_string()))?
                        }
                        // A length beyond a DLC's (0x40 = 64 in a hex file) can only be CAN FD.
                        Err(not_a_dlc) => {
                            let count = self.fd_length(dlc).ok_or(not_a_dlc)?;
                            let bytes = self.bytes(number, text, data, count)?;
                            FdFrame::new(id, &bytes, false, false)
                                .map(Frame::Fd)
                                .map_err(|e| syntax(number, column_of(text, dlc), e.to_string()))?
                        }
                    },
                    _ => {
                        return Err(syntax(
                            number,
                            column_of(text, kind),
                            format!("'{kind}': expected d (data) or r (remote) and a DLC"),
                        ))
                    }
                };
                Ok(Some((channel, Some(direction), frame)))
            }
            _ => Ok(None),
        }
    }

    /// `CHANNEL Rx|Tx ID [NAME] BRS ESI DLC LENGTH DATA… [DURATION LENGTH FLAGS …]`.
    #[allow(clippy::type_complexity)]
    fn fd_event<'t>(
        &self,
        number: u64,
        text: &'t str,
        rest: &[&'t str],
    ) -> Result<Option<(&'t str, Option<char>, Frame)>, LogError> {
        let [channel, direction, tail @ ..] = rest else {
            return Ok(None);
        };
        let Some(direction) = parse_direction(direction) else {
            return Ok(None);
        };
        if tail
            .first()
            .is_some_and(|w| w.eq_ignore_ascii_case("ErrorFrame"))
        {
            return Ok(Some((channel, Some(direction), error_frame())));
        }
        let [id, after_id @ ..] = tail else {
            return Err(syntax(
                number,
                text.len() + 1,
                "CANFD: no identifier".into(),
            ));
        };
        let id = self.id(number, text, id)?;
        // A symbolic name may stand between the identifier and BRS.
        let fields = match after_id {
            [name, more @ ..] if !name.bytes().all(|b| b.is_ascii_digit()) => more,
            all => all,
        };
        let [brs, esi, dlc, length, data @ ..] = fields else {
            return Err(syntax(
                number,
                text.len() + 1,
                "CANFD: BRS, ESI, DLC and data length expected".into(),
            ));
        };
        let flag = |w: &str| match w {
            "0" => Ok(false),
            "1" => Ok(true),
            _ => Err(syntax(
                number,
                column_of(text, w),
                format!("'{w}' is not 0 or 1"),
            )),
        };
        let (brs_on, esi_on) = (flag(brs)?, flag(esi)?);
        let dlc_value = self.dlc(number, text, dlc)?;
        let count: usize = length.parse().ok().filter(|n| *n <= 64).ok_or_else(|| {
            syntax(
                number,
                column_of(text, length),
                format!("'{length}' is not a data length (0-64)"),
            )
        })?;
        let bytes = self.bytes(number, text, data, count)?;
        // The flags after duration and bit count say whether it was an FD frame at all (bit
        // 12, EDL); without them it is taken as one.
        // More than 8 bytes can only be FD, whatever the flags say (CANoe 9.0 leaves EDL out).
        let edl = count > 8
            || data
                .get(count + 2)
                .and_then(|f| u32::from_str_radix(f, 16).ok())
                .is_none_or(|flags| flags & 0x1000 != 0);
        let frame = if edl {
            // A data length short of the DLC's (log2asc writes the bytes it has) is padded to
            // it, as SocketCAN pads; a longer one is an error.
            if count > dlc_value.fd_len() {
                return Err(syntax(
                    number,
                    column_of(text, length),
                    format!(
                        "data length {count} is longer than DLC {} ({} bytes)",
                        dlc_value.as_raw(),
                        dlc_value.fd_len()
                    ),
                ));
            }
            let mut padded = [0u8; 64];
            for (slot, byte) in padded.iter_mut().zip(&bytes) {
                *slot = *byte;
            }
            FdFrame::new(
                id,
                padded.get(..dlc_value.fd_len()).unwrap_or(&[]),
                brs_on,
                esi_on,
            )
            .map(Frame::Fd)
            .map_err(|e| syntax(number, column_of(text, length), e.to_string()))?
        } else if count == 0 && dlc_value.as_raw() > 0 {
            Frame::remote(id, dlc_value)
        } else {
            ClassicFrame::with_dlc(id, dlc_value, &bytes)
                .map(Frame::Classic)
                .map_err(|e| syntax(number, column_of(text, dlc), e.to_string()))?
        };
        Ok(Some((channel, Some(direction), frame)))
    }
}

fn parse_direction(word: &str) -> Option<char> {
    match word.to_ascii_lowercase().as_str() {
        "rx" => Some('R'),
        "tx" | "txrq" => Some('T'),
        _ => None,
    }
}

/// ASC's `ErrorFrame` carries no detail: it stands for a bus error (SocketCAN's
/// `CAN_ERR_BUSERROR`, as `asc2log` and python-can read it).
fn error_frame() -> Frame {
    const BUS_ERROR: u32 = 0x80;
    Frame::Error(ErrorFrame::from_array(BUS_ERROR, [0; 8]))
}

impl<R: BufRead> Iterator for AscReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        // Bounded by the input's lines.
        loop {
            let (number, text) = match crate::candump::next_text(&mut self.lines, &mut self.line)? {
                Ok((number, text)) => (number, text.to_string()),
                Err(e) => return Some(Err(e)),
            };
            let trimmed = text.trim();
            match self.header(number, trimmed) {
                Ok(true) => continue,
                Ok(false) => {}
                Err(e) => return Some(Err(e)),
            }
            // Columns count in the line as it stands.
            match self.event(number, &text) {
                Ok(Event::Frame(record)) => return Some(Ok(record)),
                Ok(Event::Other) => continue,
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

/// Push an identifier as ASC writes it: hex, `x` after an extended one.
fn push_id(line: &mut String, id: Id) {
    push_number(line, u64::from(id.as_raw()), 16, 1);
    if id.is_extended() {
        line.push('x');
    }
}

/// Push `value` in `radix` (10 or 16, upper case), zero-padded to `digits` at least: what
/// `write!` with `{:0N}` or `{:X}` writes, for the hot lines without the formatter's cost.
/// Widths beyond 4 are not padded by the caller above (`push_padded_left`).
fn push_number(line: &mut String, mut value: u64, radix: u64, digits: usize) {
    // A u64 has at most 20 digits in base 10; the buffer starts as the zero padding.
    let mut text = [b'0'; 20];
    let mut start = text.len();
    while value > 0 && start > 0 {
        start -= 1;
        if let (Some(slot), Some(digit)) = (
            text.get_mut(start),
            HEX_DIGITS.get(usize::try_from(value % radix).unwrap_or(0)),
        ) {
            *slot = *digit;
        }
        value /= radix;
    }
    let start = start.min(text.len().saturating_sub(digits.max(1)));
    line.push_str(std::str::from_utf8(text.get(start..).unwrap_or(&[])).unwrap_or(""));
}

/// Upper-case hex digits by value (identifiers and data bytes).
const HEX_DIGITS: &[u8; 16] = b"0123456789ABCDEF";

/// Push what `push` writes, padded with spaces on the left to `width` (right-aligned).
fn push_padded_left(line: &mut String, width: usize, push: impl FnOnce(&mut String)) {
    let before = line.len();
    push(line);
    let written = line.len() - before;
    let padding = width.saturating_sub(written).min(4);
    line.insert_str(before, "    ".get(..padding).unwrap_or(""));
}

/// Push what `push` writes, padded with spaces on the right to `width`.
fn push_padded(line: &mut String, width: usize, push: impl FnOnce(&mut String)) {
    let before = line.len();
    push(line);
    let written = line.len() - before;
    line.extend(std::iter::repeat_n(' ', width.saturating_sub(written)));
}

/// Push bytes as upper-case hex with a space between (ASC and TRC data).
pub(crate) fn push_hex(line: &mut String, data: &[u8]) {
    for (i, byte) in data.iter().enumerate() {
        if i > 0 {
            line.push(' ');
        }
        let digit = |n: u8| char::from(HEX_DIGITS.get(usize::from(n)).copied().unwrap_or(b'0'));
        line.push(digit(byte >> 4));
        line.push(digit(byte & 0x0F));
    }
}

/// Writes an ASC log as python-can does: the header and trigger block dated at the first
/// frame (to the second), each frame's time from there in microseconds, `End TriggerBlock` at
/// [`AscWriter::finish`].
pub struct AscWriter<W: Write> {
    output: W,
    /// The trigger block's start and the last time written.
    clock: WriteClock,
    channels: BTreeMap<String, u32>,
    line: String,
}

impl<W: Write> AscWriter<W> {
    /// A writer to `output`.
    pub fn new(output: W) -> Self {
        AscWriter {
            output,
            clock: WriteClock::default(),
            channels: BTreeMap::new(),
            line: String::new(),
        }
    }

    fn channel(&mut self, interface: &str) -> u32 {
        channel_number(&mut self.channels, interface)
    }

    /// The header and trigger block, dated at `start`.
    fn header(&mut self, start: u64) -> io::Result<()> {
        let date = format_date(Timestamp::from_nanos(start));
        write!(
            self.output,
            "date {date}\nbase hex  timestamps absolute\ninternal events logged\n// version 9.0.0\nBegin Triggerblock {date}\n   0.000000 Start of measurement\n"
        )?;
        Ok(())
    }

    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        // The trigger block starts on the whole second (the date's resolution); the frames'
        // times count from there in microseconds.
        let (offset, started) = self
            .clock
            .offset(record.timestamp.as_nanos(), |at| at - at % NANOS_PER_SECOND);
        if let Some(start) = started {
            self.header(start)?;
        }
        let known = self.channels.len();
        let channel = self.channel(&record.interface);
        // A channel's first frame: its interface's name first, unless the number says it
        // (`can1` is channel 2).
        if self.channels.len() > known {
            if let Some(comment) = channel_comment_text(CHANNEL_COMMENT, channel, &record.interface)
            {
                writeln!(self.output, "{comment}")?;
            }
        }
        let direction = if record.direction == Some('T') {
            "Tx"
        } else {
            "Rx"
        };
        self.line.clear();
        let micros = offset / 1_000;
        // Built in the line itself: no allocation a frame. Writing to a String cannot fail.
        let line = &mut self.line;
        // `{:>4}.{:06} `: the seconds right-aligned in four columns.
        push_padded_left(line, 4, |l| push_number(l, micros / 1_000_000, 10, 1));
        line.push('.');
        push_number(line, micros % 1_000_000, 10, 6);
        line.push(' ');
        match &record.frame {
            Frame::Error(_) => {
                let _ = write!(line, "{channel}  ErrorFrame");
            }
            Frame::Classic(f) => {
                push_number(line, u64::from(channel), 10, 1);
                line.push_str("  ");
                push_padded(line, 15, |l| push_id(l, f.id()));
                line.push(' ');
                line.push_str(direction);
                line.push_str("   ");
                // The DLC as one lower-case hex digit (`{:x}`: 0-f).
                let dlc = char::from_digit(u32::from(f.dlc().as_raw()), 16).unwrap_or('0');
                line.push(if f.is_remote() { 'r' } else { 'd' });
                line.push(' ');
                line.push(dlc);
                if !f.is_remote() {
                    line.push(' ');
                    push_hex(line, f.data());
                }
            }
            Frame::Fd(f) => {
                let mut flags = 0x1000u32;
                if f.brs() {
                    flags |= 0x2000;
                }
                if f.esi() {
                    flags |= 0x4000;
                }
                let _ = write!(line, "CANFD {channel:>3} {direction:<4} ");
                let before = line.len();
                push_id(line, f.id());
                let width = line.len() - before;
                line.insert_str(before, &" ".repeat(8usize.saturating_sub(width)));
                let _ = write!(
                    line,
                    "  {:>32} {} {} {:x} {:>2} ",
                    "",
                    u8::from(f.brs()),
                    u8::from(f.esi()),
                    f.dlc().as_raw(),
                    f.data().len()
                );
                push_hex(line, f.data());
                let _ = write!(
                    line,
                    " {:>8} {:>4} {flags:>8X} {:>8} {:>8} {:>8} {:>8} {:>8}",
                    0, 0, 0, 0, 0, 0, 0
                );
            }
        }
        self.line.push('\n');
        self.output.write_all(self.line.as_bytes())
    }

    /// Write out what is buffered: a file cut short after this reads up to here.
    pub fn flush(&mut self) -> io::Result<()> {
        self.output.flush()
    }

    /// End the trigger block (a file with no frames still gets a header) and flush; the output
    /// back.
    pub fn finish(mut self) -> io::Result<W> {
        if self.clock.unstarted() {
            self.header(0)?;
        }
        self.output.write_all(b"End TriggerBlock\n")?;
        self.output.flush()?;
        Ok(self.output)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Vec<Result<LogRecord, LogError>> {
        AscReader::new(text.as_bytes()).collect()
    }

    #[test]
    fn dates_convert_both_ways() {
        let at = parse_date("Tue Nov 14 22:13:20 2023").unwrap();
        assert_eq!(at, 1_700_000_000 * NANOS_PER_SECOND);
        assert_eq!(
            format_date(Timestamp::from_nanos(at + 123_456_789)),
            "Tue Nov 14 22:13:20 2023"
        );
        assert_eq!(
            parse_date("Tue Nov 14 22:13:20.123 2023"),
            Some(at + 123_000_000)
        );
        assert_eq!(
            parse_date("Nov 14 10:13:20.123 PM 2023"),
            Some(at + 123_000_000)
        );
        assert_eq!(
            parse_date("Di Dez 01 00:00:00 2026"),
            parse_date("Tue Dec 1 00:00:00 2026")
        );
        assert_eq!(
            parse_date("Feb 29 00:00:00 2024").map(|n| n / NANOS_PER_SECOND),
            Some(1_709_164_800)
        );
        for bad in [
            "",
            "Foo 14 22:13:20 2023",
            "Nov 32 22:13:20 2023",
            "Nov 14 25:00:00 2023",
            "Nov 14 22:13 2023",
            // Far beyond what nanoseconds since 1970 hold (found by fuzzing).
            "Nov 14 22:13:20 9999999999999",
            "Nov 14 22:13:20 -999999999999999999",
        ] {
            assert_eq!(parse_date(bad), None, "{bad}");
        }
        for days in [-1, 0, 59, 10_957, 20_000, 2_932_896] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days);
        }
    }

    #[test]
    fn every_kind_of_frame_reads() {
        let text = "date Tue Nov 14 22:13:20.000 2023\nbase hex  timestamps absolute\nno internal events logged\n\
            // a comment\n\
               0.000000 1  123             Rx   d 4 DE AD BE EF\n\
               0.100000 2  1ABCDEF0x       Tx   d 2 01 02  Length = 0 BitCount = 0 ID = 1\n\
               0.200000 1  123             Rx   r 3\n\
               0.250000 1  Statistic: D 0 R 0 XD 0 XR 0 E 0 O 0 B 0.00%\n\
               0.300000 1  ErrorFrame\n\
               0.400000 CANFD   1 Rx        123                                   1 1 9 10 11 22 33 44 55 66 77 88 99 00   130000  130     7000 0 0 0 0 0\n\
               0.500000 CANFD   1 Rx        7FF  Name 0 0 2 2 01 02        0    0      0 0 0 0 0 0\n";
        let records: Vec<LogRecord> = read(text).into_iter().collect::<Result<_, _>>().unwrap();
        let base = 1_700_000_000 * NANOS_PER_SECOND;
        let shown: Vec<(u64, &str, String, Option<char>)> = records
            .iter()
            .map(|r| {
                (
                    r.timestamp.as_nanos() - base,
                    r.interface.as_str(),
                    r.frame.to_string(),
                    r.direction,
                )
            })
            .collect();
        assert_eq!(
            shown,
            [
                (0, "can0", "123#DEADBEEF".to_string(), Some('R')),
                (100_000_000, "can1", "1ABCDEF0#0102".to_string(), Some('T')),
                (200_000_000, "can0", "123#R3".to_string(), Some('R')),
                (300_000_000, "can0", error_frame().to_string(), None),
                (
                    400_000_000,
                    "can0",
                    Frame::fd(
                        Id::standard(0x123).unwrap(),
                        &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88, 0x99, 0, 0, 0],
                        true,
                        true,
                    )
                    .unwrap()
                    .to_string(),
                    Some('R')
                ),
                (500_000_000, "can0", "7FF#0102".to_string(), Some('R')),
            ]
        );
    }

    #[test]
    fn relative_times_and_decimal_bases_and_trigger_blocks() {
        let text = "date Tue Nov 14 22:13:20 2023\nbase dec  timestamps relative\n\
            Begin Triggerblock Tue Nov 14 22:13:21.500 2023\n\
               0.100000 1  291             Rx   d 2 1 255\n\
               0.100000 1  291             Rx   d 1 16\n";
        let records: Vec<LogRecord> = read(text).into_iter().collect::<Result<_, _>>().unwrap();
        let base = 1_700_000_001_500_000_000u64;
        assert_eq!(records[0].timestamp.as_nanos(), base + 100_000_000);
        assert_eq!(records[1].timestamp.as_nanos(), base + 200_000_000);
        assert_eq!(records[0].frame.to_string(), "123#01FF");
    }

    #[test]
    fn bad_lines_name_their_place() {
        let cases = [
            ("   0.1 1  12G  Rx   d 1 00\n", 1, 11, "not an identifier"),
            (
                "   0.1 1  123  Rx   d 4 00 01\n",
                1,
                30,
                "4 data bytes expected, 2 found",
            ),
            (
                "   0.1 1  123  Rx   q 1\n",
                1,
                21,
                "expected d (data) or r (remote)",
            ),
            ("   0.1 1  123  Rx   d 1 1FF\n", 1, 25, "not a data byte"),
            ("date Someday\n", 1, 1, "date not understood"),
            (
                "   0.1 CANFD 1 Rx 123 1 0 8 9 00 00 00 00 00 00 00 00 00\n",
                1,
                29,
                "longer than DLC 8",
            ),
        ];
        for (text, line, column, what) in cases {
            let Some(Err(LogError::Syntax {
                line: l,
                column: c,
                kind,
            })) = read(text).into_iter().next()
            else {
                panic!("{text}: no error");
            };
            assert_eq!((l, c), (line, column), "{text}: {kind}");
            assert!(kind.to_string().contains(what), "{text}: {kind}");
        }
    }

    #[test]
    fn written_files_read_back_frame_for_frame() {
        let base = 1_700_000_000_123_456_789u64;
        let frames = [
            ("can0", "123#DEADBEEF", Some('R')),
            ("can1", "1ABCDEF0#", Some('T')),
            ("can0", "123#R2", None),
            ("vcan3", "7FF##2112233", None),
            ("can0", "000##0", None),
        ];
        let mut writer = AscWriter::new(Vec::new());
        for (i, (interface, frame, direction)) in frames.iter().enumerate() {
            writer
                .write(&LogRecord {
                    timestamp: Timestamp::from_nanos(base + u64::try_from(i).unwrap() * 1_500_000),
                    interface: (*interface).to_string(),
                    frame: frame.parse().unwrap(),
                    direction: *direction,
                })
                .unwrap();
        }
        let text = String::from_utf8(writer.finish().unwrap()).unwrap();
        assert!(
            text.starts_with("date Tue Nov 14 22:13:20 2023\nbase hex  timestamps absolute\n"),
            "{text}"
        );
        assert!(text.ends_with("End TriggerBlock\n"), "{text}");
        let back: Vec<LogRecord> = read(&text).into_iter().collect::<Result<_, _>>().unwrap();
        assert_eq!(back.len(), frames.len());
        for (i, (record, (interface, frame, direction))) in back.iter().zip(frames).enumerate() {
            // Microseconds survive (the trigger block starts on the second).
            let expected = (base + u64::try_from(i).unwrap() * 1_500_000) / 1_000 * 1_000;
            assert_eq!(record.timestamp.as_nanos(), expected);
            assert_eq!(record.frame, frame.parse::<Frame>().unwrap());
            assert_eq!(record.direction, Some(direction.unwrap_or('R')));
            // A name the number does not say comes back from its comment.
            assert_eq!(record.interface, interface);
        }
        assert!(text.contains("\n// channel 4 = vcan3\n"), "{text}");
        assert!(!text.contains("= can0"), "{text}");
    }
}
