//! PEAK TRC logs (PCAN-View, PCAN-Explorer): versions 1.0, 1.1, 1.3, 2.0 and 2.1 read, 2.1
//! written (CAN FD in 2.x).
//!
//! Header lines start with `;`: `;$FILEVERSION=2.1`, `;$STARTTIME=` (days since 1899-12-30,
//! the OLE date), `;$COLUMNS=N,O,T,B,I,d,R,L,D` (2.x: message number, time offset in ms, type,
//! bus, identifier, direction, reserved, DLC, data). Types: `DT` data, `RR` remote request,
//! `FD`/`FB`/`FE`/`BI` CAN FD (BRS with `FB` and `FE`, ESI with `FE` and `BI`), `ER` an error
//! frame; status and other events are passed over. Version 1.x lines are `N) OFFSET [BUS] [Rx|Tx]
//! ID [-] DLC DATA|RTR`. Buses are numbered from 1: bus N is interface `can{N-1}`, or
//! the interface a comment before the bus's first frame names (`; bus 2 = bus1`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame};
use bywire_core::{Frame, Id, Timestamp};

use crate::candump::{LogError, LogRecord};
use crate::fields::{
    channel_comment, channel_comment_text, channel_number, column_of, data_bytes, dlc, fixed_point,
    syntax, WriteClock, MAX_CHANNEL_NAMES,
};
use crate::lines::CappedLines;

/// Days from the OLE epoch (1899-12-30) to the Unix epoch.
const OLE_TO_UNIX_DAYS: f64 = 25_569.0;
const NANOS_PER_DAY: f64 = 86_400e9;
const NANOS_PER_DAY_INT: u64 = 86_400_000_000_000;

/// A file version, as `;$FILEVERSION` names it (none: 1.0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Version {
    V1_0,
    V1_1,
    V1_3,
    V2,
}

/// Reads a TRC log one line at a time (bounded memory).
pub struct TrcReader<R> {
    lines: CappedLines<R>,
    version: Version,
    start: u64,
    /// 2.x: where each column stands.
    columns: BTreeMap<char, usize>,
    line: u64,
    /// Interface names by bus number, from `; bus N = NAME` comments.
    names: BTreeMap<u32, String>,
}

/// The comment naming a bus's interface (`; bus 2 = bus1`), which bywire writes before a bus's
/// first frame: other readers pass comments over.
const BUS_COMMENT: &str = "; bus ";

impl<R: BufRead> TrcReader<R> {
    /// A reader over `input`.
    pub fn new(input: R) -> Self {
        TrcReader {
            lines: CappedLines::new(input),
            version: Version::V1_0,
            start: 0,
            columns: BTreeMap::new(),
            line: 0,
            names: BTreeMap::new(),
        }
    }
}

/// Milliseconds with a fraction (`1059.900`) as nanoseconds.
fn parse_millis(text: &str) -> Option<u64> {
    fixed_point(text, 6)
}

/// An OLE date (days since 1899-12-30) as nanoseconds since the Unix epoch, to the
/// microsecond (the date's float carries no finer time).
fn ole_to_nanos(days: f64) -> Option<u64> {
    let nanos = (days - OLE_TO_UNIX_DAYS) * NANOS_PER_DAY;
    if !(0.0..1.8e19).contains(&nanos) {
        return None;
    }
    // Non-negative and below 2^64, checked above.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let micros = (nanos / 1_000.0).round() as u64;
    micros.checked_mul(1_000)
}

/// The ASC-style bus error frame an `ER` line stands for (its detail is not kept).
fn error_frame() -> Frame {
    const BUS_ERROR: u32 = 0x80;
    Frame::Error(ErrorFrame::from_array(BUS_ERROR, [0; 8]))
}

impl<R: BufRead> TrcReader<R> {
    fn header(&mut self, number: u64, text: &str) -> Result<(), LogError> {
        if let Some((bus, name)) = channel_comment(text, BUS_COMMENT) {
            if self.names.len() < MAX_CHANNEL_NAMES {
                self.names.insert(bus, name.to_string());
            }
            return Ok(());
        }
        let Some((key, value)) = text.trim_start_matches(';').split_once('=') else {
            return Ok(());
        };
        match key.trim() {
            "$FILEVERSION" => {
                self.version = match value.trim() {
                    "1.0" => Version::V1_0,
                    "1.1" => Version::V1_1,
                    "1.3" => Version::V1_3,
                    "2.0" | "2.1" => Version::V2,
                    other => {
                        return Err(syntax(
                            number,
                            14,
                            format!("file version {other} is not one of 1.0, 1.1, 1.3, 2.0, 2.1"),
                        ))
                    }
                };
            }
            "$STARTTIME" => {
                self.start = value
                    .trim()
                    .parse::<f64>()
                    .ok()
                    .and_then(ole_to_nanos)
                    .ok_or_else(|| {
                        syntax(
                            number,
                            13,
                            format!("start time '{}' is not a date", value.trim()),
                        )
                    })?;
            }
            "$COLUMNS" => {
                self.columns = value
                    .trim()
                    .split(',')
                    .enumerate()
                    .filter_map(|(i, c)| Some((c.trim().chars().next()?, i)))
                    .collect();
                for needed in ['O', 'T', 'I', 'd'] {
                    if !self.columns.contains_key(&needed) {
                        return Err(syntax(
                            number,
                            11,
                            format!("$COLUMNS has no {needed} column"),
                        ));
                    }
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn id(number: u64, text: &str, word: &str) -> Result<Id, LogError> {
        let raw = u32::from_str_radix(word, 16).map_err(|_| {
            syntax(
                number,
                column_of(text, word),
                format!("'{word}' is not an identifier"),
            )
        })?;
        // PEAK writes standard identifiers in four digits or fewer, extended in eight.
        let id = if word.len() > 4 {
            Id::extended(raw)
        } else {
            Id::standard(raw)
        };
        id.map_err(|e| syntax(number, column_of(text, word), e.to_string()))
    }

    fn bytes(number: u64, text: &str, words: &[&str], count: usize) -> Result<Vec<u8>, LogError> {
        data_bytes(number, text, words, count, 16)
    }

    fn dlc(number: u64, text: &str, word: &str) -> Result<Dlc, LogError> {
        dlc(number, text, word, 10)
    }

    fn time(&self, number: u64, text: &str, word: &str) -> Result<u64, LogError> {
        parse_millis(word)
            .map(|offset| self.start.saturating_add(offset))
            .ok_or_else(|| {
                syntax(
                    number,
                    column_of(text, word),
                    format!("'{word}' is not a time in ms"),
                )
            })
    }

    /// A 1.x line: `N) OFFSET [BUS] [Rx|Tx] ID [-] DLC DATA|RTR`.
    fn line_v1(&self, number: u64, text: &str) -> Result<Option<LogRecord>, LogError> {
        let words: Vec<&str> = text.split_whitespace().collect();
        let (offset, bus, direction, id, rest) = match (self.version, words.as_slice()) {
            (Version::V1_0, [_, offset, id, rest @ ..]) => (*offset, "1", None, *id, rest),
            (Version::V1_1, [_, offset, dir, id, rest @ ..]) => {
                (*offset, "1", Some(*dir), *id, rest)
            }
            (Version::V1_3, [_, offset, bus, dir, id, _, rest @ ..]) => {
                (*offset, *bus, Some(*dir), *id, rest)
            }
            _ => return Err(syntax(number, 1, "too few columns for a message".into())),
        };
        if id.eq_ignore_ascii_case("FFFFFFFF") {
            return Ok(None); // 1.0's bus information line
        }
        let direction = match direction {
            Some("Rx") => Some('R'),
            Some("Tx") => Some('T'),
            Some(_) => return Ok(None), // a status or error line of 1.1/1.3
            None => None,
        };
        let at = self.time(number, text, offset)?;
        let id = Self::id(number, text, id)?;
        let [dlc, data @ ..] = rest else {
            return Err(syntax(number, text.len() + 1, "no DLC".into()));
        };
        let dlc = Self::dlc(number, text, dlc)?;
        let frame = if data.first() == Some(&"RTR") {
            Frame::remote(id, dlc)
        } else {
            let bytes = Self::bytes(number, text, data, dlc.fd_len().min(8))?;
            ClassicFrame::with_dlc(id, dlc, &bytes)
                .map(Frame::Classic)
                .map_err(|e| syntax(number, 1, e.to_string()))?
        };
        Ok(Some(self.record(number, text, at, bus, direction, frame)?))
    }

    /// A 2.x line, by the file's columns.
    fn line_v2(&self, number: u64, text: &str) -> Result<Option<LogRecord>, LogError> {
        let last = self.columns.values().max().copied().unwrap_or(0);
        let words: Vec<&str> = text.split_whitespace().collect();
        let get = |column: char| {
            self.columns
                .get(&column)
                .and_then(|i| words.get(*i))
                .copied()
        };
        let Some(kind) = get('T') else {
            return Err(syntax(number, 1, "no type column".into()));
        };
        let (fd, brs, esi) = match kind {
            "DT" | "RR" => (false, false, false),
            "FD" => (true, false, false),
            "FB" => (true, true, false),
            "FE" => (true, true, true),
            "BI" => (true, false, true),
            "ER" => {
                let at = self.time(number, text, get('O').unwrap_or(""))?;
                let bus = get('B').unwrap_or("1");
                return Ok(Some(self.record(
                    number,
                    text,
                    at,
                    bus,
                    None,
                    error_frame(),
                )?));
            }
            _ => return Ok(None), // status, error counters, events
        };
        let at = self.time(number, text, get('O').unwrap_or(""))?;
        let id = Self::id(number, text, get('I').unwrap_or(""))?;
        let direction = match get('d') {
            Some("Rx") => Some('R'),
            Some("Tx") => Some('T'),
            other => {
                return Err(syntax(
                    number,
                    other.map_or(1, |w| column_of(text, w)),
                    "direction is neither Rx nor Tx".into(),
                ))
            }
        };
        // The DLC (`L`), or the data length (`l`) the DLC follows from.
        let dlc = match (get('L'), get('l')) {
            (Some(dlc), _) => Self::dlc(number, text, dlc)?,
            (None, Some(length)) => length
                .parse::<usize>()
                .ok()
                .and_then(if fd {
                    Dlc::from_fd_len
                } else {
                    Dlc::from_classic_len
                })
                .ok_or_else(|| {
                    syntax(
                        number,
                        column_of(text, length),
                        format!("'{length}' is not a data length"),
                    )
                })?,
            (None, None) => {
                return Err(syntax(
                    number,
                    1,
                    "neither a DLC nor a data length column".into(),
                ))
            }
        };
        let data_column = self.columns.get(&'D').copied().unwrap_or(last);
        let data = words.get(data_column..).unwrap_or(&[]);
        let frame = match (kind, fd) {
            ("RR", _) => Frame::remote(id, dlc),
            (_, false) => {
                let bytes = Self::bytes(number, text, data, dlc.fd_len().min(8))?;
                ClassicFrame::with_dlc(id, dlc, &bytes)
                    .map(Frame::Classic)
                    .map_err(|e| syntax(number, 1, e.to_string()))?
            }
            (_, true) => {
                let bytes = Self::bytes(number, text, data, dlc.fd_len())?;
                FdFrame::new(id, &bytes, brs, esi)
                    .map(Frame::Fd)
                    .map_err(|e| syntax(number, 1, e.to_string()))?
            }
        };
        Ok(Some(self.record(
            number,
            text,
            at,
            get('B').unwrap_or("1"),
            direction,
            frame,
        )?))
    }

    fn record(
        &self,
        number: u64,
        text: &str,
        at: u64,
        bus: &str,
        direction: Option<char>,
        frame: Frame,
    ) -> Result<LogRecord, LogError> {
        let n: u32 = bus.parse().map_err(|_| {
            syntax(
                number,
                column_of(text, bus),
                format!("bus '{bus}' is not a number"),
            )
        })?;
        Ok(LogRecord {
            timestamp: Timestamp::from_nanos(at),
            interface: self
                .names
                .get(&n)
                .cloned()
                .unwrap_or_else(|| format!("can{}", n.saturating_sub(1))),
            frame,
            direction,
        })
    }
}

impl<R: BufRead> Iterator for TrcReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        // Bounded by the input's lines.
        loop {
            let (number, text) = match crate::candump::next_text(&mut self.lines, &mut self.line)? {
                Ok((number, text)) => (number, text.to_string()),
                Err(e) => return Some(Err(e)),
            };
            let trimmed = text.trim();
            if trimmed.is_empty() {
                continue;
            }
            if trimmed.starts_with(';') {
                if let Err(e) = self.header(number, trimmed) {
                    return Some(Err(e));
                }
                continue;
            }
            let parsed = match self.version {
                Version::V2 => self.line_v2(number, &text),
                Version::V1_0 | Version::V1_1 | Version::V1_3 => self.line_v1(number, &text),
            };
            match parsed {
                Ok(Some(record)) => return Some(Ok(record)),
                Ok(None) => continue,
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

/// Writes a TRC 2.1 log: the header dated at the first frame's day, each frame's offset in
/// milliseconds to the microsecond. An error frame is written as an `ER` line
/// without its detail (TRC keeps a different kind of detail than SocketCAN).
pub struct TrcWriter<W: Write> {
    output: W,
    /// The header's start and the last time written.
    clock: WriteClock,
    number: u64,
    buses: BTreeMap<String, u32>,
    line: String,
}

impl<W: Write> TrcWriter<W> {
    /// A writer to `output`.
    pub fn new(output: W) -> Self {
        TrcWriter {
            output,
            clock: WriteClock::default(),
            number: 0,
            buses: BTreeMap::new(),
            line: String::new(),
        }
    }

    /// The bus number of an interface: its trailing number plus one, else the next free one.
    fn bus(&mut self, interface: &str) -> u32 {
        channel_number(&mut self.buses, interface)
    }

    /// The header, dated at `start` (a UTC midnight).
    fn header(&mut self, start: u64) -> io::Result<()> {
        let day = start / NANOS_PER_DAY_INT;
        // Days since 1970 are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let days = day as f64 + OLE_TO_UNIX_DAYS;
        write!(
            self.output,
            ";$FILEVERSION=2.1\r\n;$STARTTIME={days:.1}\r\n;$COLUMNS=N,O,T,B,I,d,R,L,D\r\n;\r\n;   Start time: {}\r\n;   Generated by bywire\r\n;---+-- ------+------ +- +- --+----- +- +- +--- +- -- -- -- -- -- -- --\r\n",
            crate::asc::format_date(Timestamp::from_nanos(start))
        )?;
        Ok(())
    }

    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        // The start is the first frame's day (UTC midnight): a whole number of days is exact in
        // the header's float, so every frame's time comes back to the microsecond (a start
        // within the day would carry the float's half-microsecond error into all of them).
        let (offset, started) = self.clock.offset(record.timestamp.as_nanos(), |at| {
            at - at % NANOS_PER_DAY_INT
        });
        if let Some(start) = started {
            self.header(start)?;
        }
        let micros = offset / 1_000;
        self.number += 1;
        let known = self.buses.len();
        let bus = self.bus(&record.interface);
        // A bus's first frame: its interface's name first, unless the number says it.
        if self.buses.len() > known {
            if let Some(comment) = channel_comment_text(BUS_COMMENT, bus, &record.interface) {
                write!(self.output, "{comment}\r\n")?;
            }
        }
        let direction = if record.direction == Some('T') {
            "Tx"
        } else {
            "Rx"
        };
        let id_text = |id: Id| {
            if id.is_extended() {
                format!("{:08X}", id.as_raw())
            } else {
                format!("{:04X}", id.as_raw())
            }
        };
        let (kind, id, dlc, data) = match &record.frame {
            Frame::Error(_) => ("ER", "0000".to_string(), 0, String::new()),
            Frame::Classic(f) if f.is_remote() => {
                ("RR", id_text(f.id()), f.dlc().as_raw(), String::new())
            }
            Frame::Classic(f) => ("DT", id_text(f.id()), f.dlc().as_raw(), hex(f.data())),
            Frame::Fd(f) => {
                let kind = match (f.brs(), f.esi()) {
                    (false, false) => "FD",
                    (true, false) => "FB",
                    (true, true) => "FE",
                    (false, true) => "BI",
                };
                (kind, id_text(f.id()), f.dlc().as_raw(), hex(f.data()))
            }
        };
        self.line.clear();
        // Writing to a String cannot fail.
        let _ = write!(
            self.line,
            "{:>7} {:>9}.{:03} {kind} {bus:>2} {id:>8} {direction} -  {dlc:<4} {data}",
            self.number,
            micros / 1_000,
            micros % 1_000
        );
        let end = self.line.trim_end().len();
        self.line.truncate(end);
        self.line.push_str("\r\n");
        self.output.write_all(self.line.as_bytes())
    }

    /// Write out what is buffered: a file cut short after this reads up to here.
    pub fn flush(&mut self) -> io::Result<()> {
        self.output.flush()
    }

    /// Flush (a file with no frames still gets a header); the output back.
    pub fn finish(mut self) -> io::Result<W> {
        if self.clock.unstarted() {
            self.header(0)?;
        }
        self.output.flush()?;
        Ok(self.output)
    }
}

fn hex(data: &[u8]) -> String {
    let mut text = String::with_capacity(data.len() * 3);
    crate::asc::push_hex(&mut text, data);
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Vec<Result<LogRecord, LogError>> {
        TrcReader::new(text.as_bytes()).collect()
    }

    fn frames(text: &str) -> Vec<(u64, String, String, Option<char>)> {
        read(text)
            .into_iter()
            .map(|r| {
                let r = r.unwrap();
                (
                    r.timestamp.as_nanos(),
                    r.interface,
                    r.frame.to_string(),
                    r.direction,
                )
            })
            .collect()
    }

    #[test]
    fn every_version_reads() {
        let v10 = ";##\n;   Columns\n   1)      1059 0300 8 00 01 02 03 04 05 06 07\n   2)      1060 FFFFFFFF 4 00 00 00 0C\n   3)      1061 18EFFF00 2 RTR\n";
        assert_eq!(
            frames(v10),
            [
                (
                    1_059_000_000,
                    "can0".into(),
                    "300#0001020304050607".into(),
                    None
                ),
                (1_061_000_000, "can0".into(), "18EFFF00#R2".into(), None),
            ]
        );
        // 1.1: 2021-01-01 00:00:00 UTC is OLE day 44197.
        let v11 = ";$FILEVERSION=1.1\n;$STARTTIME=44197\n     1)      1059.9  Rx         0300  2  00 01\n     2)      1060.5  Warng  FFFFFFFF  4  00 00 00 08  BUSHEAVY\n";
        let base = 1_609_459_200_000_000_000u64;
        assert_eq!(
            frames(v11),
            [(
                base + 1_059_900_000,
                "can0".into(),
                "300#0001".into(),
                Some('R')
            )]
        );
        let v13 =
            ";$FILEVERSION=1.3\n;$STARTTIME=44197\n     1)      1.5 2  Tx        0300 -  1  AA\n";
        assert_eq!(
            frames(v13),
            [(base + 1_500_000, "can1".into(), "300#AA".into(), Some('T'))]
        );
        let v20 = ";$FILEVERSION=2.0\n;$STARTTIME=44197\n;$COLUMNS=N,O,T,I,d,l,D\n      1         0.100 DT     0300 Rx 2  01 02\n      2         0.200 FB 18FF0000 Tx 12 00 01 02 03 04 05 06 07 08 09 0A 0B\n      3         0.300 ST Rx 00 00 00 08\n";
        let fd = Frame::fd(
            Id::extended(0x18FF_0000).unwrap(),
            &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
            true,
            false,
        )
        .unwrap();
        assert_eq!(
            frames(v20),
            [
                (base + 100_000, "can0".into(), "300#0102".into(), Some('R')),
                (base + 200_000, "can0".into(), fd.to_string(), Some('T')),
            ]
        );
    }

    #[test]
    fn bad_lines_name_their_place() {
        let head = ";$FILEVERSION=2.1\n;$STARTTIME=44197\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n";
        let cases = [
            (
                "      1         0.1 DT  1     0G00 Rx -  1    00\n",
                "not an identifier",
            ),
            (
                "      1         0.1 DT  1     0300 Rx -  4    00 01\n",
                "4 data bytes expected, 2 found",
            ),
            (
                "      1         x.1 DT  1     0300 Rx -  1    00\n",
                "not a time in ms",
            ),
            (
                "      1         0.1 DT  1     0300 Up -  1    00\n",
                "neither Rx nor Tx",
            ),
        ];
        for (line, what) in cases {
            let text = format!("{head}{line}");
            let Some(Err(LogError::Syntax { line: 4, kind, .. })) = read(&text).into_iter().next()
            else {
                panic!("{line}: no error on line 4");
            };
            assert!(kind.to_string().contains(what), "{line}: {kind}");
        }
        assert!(read(";$FILEVERSION=3.0\n")
            .into_iter()
            .next()
            .unwrap()
            .is_err());
        assert!(read(";$FILEVERSION=2.1\n;$COLUMNS=N,T\n")
            .into_iter()
            .next()
            .unwrap()
            .is_err());
    }

    #[test]
    fn interface_names_come_back_from_their_comments() {
        let mut writer = TrcWriter::new(Vec::new());
        for (i, interface) in ["bus1", "front", "can0", "bus1"].iter().enumerate() {
            writer
                .write(&LogRecord {
                    timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i as u64),
                    interface: (*interface).to_string(),
                    frame: "123#01".parse().unwrap(),
                    direction: None,
                })
                .unwrap();
        }
        let text = String::from_utf8(writer.finish().unwrap()).unwrap();
        assert!(text.contains("\r\n; bus 2 = bus1\r\n"), "{text}");
        assert_eq!(text.matches("; bus ").count(), 2, "{text}");
        let names: Vec<String> = read(&text)
            .into_iter()
            .map(|r| r.unwrap().interface)
            .collect();
        assert_eq!(names, ["bus1", "front", "can0", "bus1"]);
    }

    #[test]
    fn written_files_read_back_frame_for_frame() {
        let base = 1_700_000_000_123_456_789u64;
        let frames = [
            "123#DEADBEEF",
            "1ABCDEF0#",
            "123#R2",
            "7FF##2112233",
            "000##1",
            "20000080#0000000000000000",
        ];
        let mut writer = TrcWriter::new(Vec::new());
        for (i, frame) in frames.iter().enumerate() {
            let interface = if i % 2 == 0 { "can0" } else { "can1" };
            writer
                .write(&LogRecord {
                    timestamp: Timestamp::from_nanos(base + u64::try_from(i).unwrap() * 1_500_000),
                    interface: interface.into(),
                    frame: frame.parse().unwrap(),
                    direction: Some('T'),
                })
                .unwrap();
        }
        let text = String::from_utf8(writer.finish().unwrap()).unwrap();
        assert!(
            text.starts_with(";$FILEVERSION=2.1\r\n;$STARTTIME=45244.0\r\n"),
            "{text}"
        );
        let back: Vec<LogRecord> = read(&text).into_iter().collect::<Result<_, _>>().unwrap();
        assert_eq!(back.len(), frames.len());
        for (i, (record, frame)) in back.iter().zip(frames).enumerate() {
            let expected = (base + u64::try_from(i).unwrap() * 1_500_000) / 1_000 * 1_000;
            assert_eq!(record.timestamp.as_nanos(), expected, "{text}");
            assert_eq!(record.frame, frame.parse::<Frame>().unwrap());
            assert_eq!(record.interface, if i % 2 == 0 { "can0" } else { "can1" });
            assert_eq!(
                record.direction,
                if record.frame.is_error() {
                    None
                } else {
                    Some('T')
                }
            );
        }
    }
}
