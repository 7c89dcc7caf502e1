//! The can-utils compact text form of a frame, both ways, as `cansend` reads it and `candump`
//! prints it:
//!
//! | text                     | frame                                                   |
//! |--------------------------|---------------------------------------------------------|
//! | `123#DEADBEEF`           | standard ID 0x123, 4 data bytes                         |
//! | `123#DE.AD.BE.EF`        | the same, with optional byte separators                 |
//! | `1ABCDEF0#`              | extended ID (8 digits), no data                         |
//! | `123#R`, `123#R5`        | remote frame, DLC 0 / 5                                 |
//! | `123#1122334455667788_E` | classic frame with 8 bytes and raw DLC 14               |
//! | `123##5DEADBEEF`         | CAN FD, flags nibble (1 = BRS, 2 = ESI, 4 = FDF), then data |
//! | `20000080#0000000000000000` | error frame (ERR flag 0x20000000 in the 8-digit ID)  |

use core::fmt;
use core::str::FromStr;

use super::{ClassicFrame, Dlc, ErrorFrame, FdFrame, Frame, FrameError, Id, EFF_MASK, ERR_FLAG};

/// FD flags nibble: bit rate switch.
const FLAG_BRS: u8 = 0x01;
/// FD flags nibble: error state indicator.
const FLAG_ESI: u8 = 0x02;
/// FD flags nibble: FD format (set by Linux on every FD frame).
const FLAG_FDF: u8 = 0x04;

/// Why a text frame was refused, with the 1-based column where the problem is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("column {column}: {kind}")]
pub struct ParseFrameError {
    /// 1-based column (character position) of the problem.
    pub column: usize,
    /// What is wrong.
    pub kind: ParseFrameErrorKind,
}

/// What is wrong with a text frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ParseFrameErrorKind {
    /// No `#` after a 3-digit (standard) or 8-digit (extended) identifier.
    #[error(
        "expected '#' after a 3-digit or 8-digit hex identifier (e.g. 123#... or 1ABCDEF0#...)"
    )]
    MissingSeparator,
    /// A character that is not a hex digit where one is needed.
    #[error("'{0}' is not a hex digit")]
    NotHex(char),
    /// An odd number of hex digits in the data.
    #[error("data ends in half a byte")]
    HalfByte,
    /// More data than the frame kind holds.
    #[error("more than {0} data bytes")]
    TooMuchData(usize),
    /// A remote frame DLC that is not 0–8.
    #[error("remote frame length '{0}' is not 0-8")]
    RemoteLength(char),
    /// A raw DLC suffix (`_X`) that is not 9–F, or not after 8 bytes.
    #[error("raw DLC suffix '_{0}' needs exactly 8 data bytes and a DLC of 9-F")]
    RawDlc(char),
    /// Identifier flag bits other than the error flag in an 8-digit ID.
    #[error("identifier {0:#010X} has bits set above the 29-bit range")]
    IdFlags(u32),
    /// Characters after the frame.
    #[error("unexpected '{0}' after the frame")]
    Trailing(char),
    /// The frame itself is invalid.
    #[error("{0}")]
    Frame(FrameError),
}

fn err(column: usize, kind: ParseFrameErrorKind) -> ParseFrameError {
    ParseFrameError { column, kind }
}

/// Each byte's value as a hex digit, or 0xFF.
const HEX_VALUE: [u8; 256] = hex_values();

// Indices are a byte's value, below 256; a digit's value is below 16.
#[allow(clippy::indexing_slicing, clippy::cast_possible_truncation)]
const fn hex_values() -> [u8; 256] {
    let mut table = [0xFF; 256];
    let mut digit = 0;
    while digit < 16 {
        table[b"0123456789abcdef"[digit] as usize] = digit as u8;
        table[b"0123456789ABCDEF"[digit] as usize] = digit as u8;
        digit += 1;
    }
    table
}

/// A cursor over the ASCII bytes of the text, with 0-based position `pos`.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Cursor<'_> {
    fn peek(&self) -> Option<u8> {
        self.bytes.get(self.pos).copied()
    }

    fn error(&self, kind: ParseFrameErrorKind) -> ParseFrameError {
        err(self.pos + 1, kind)
    }

    fn current_char(&self) -> char {
        self.peek().map_or(' ', char::from)
    }

    fn hex_digit(&mut self) -> Result<u8, ParseFrameError> {
        let c = self
            .peek()
            .ok_or_else(|| self.error(ParseFrameErrorKind::HalfByte))?;
        // A match rather than `char::to_digit`: logs are mostly hex digits.
        let value = match c {
            b'0'..=b'9' => c - b'0',
            b'a'..=b'f' => c - b'a' + 10,
            b'A'..=b'F' => c - b'A' + 10,
            _ => return Err(self.error(ParseFrameErrorKind::NotHex(char::from(c)))),
        };
        self.pos += 1;
        Ok(value)
    }

    /// Data bytes with optional '.' separators, up to `max`, into `out`; returns the count.
    fn data(&mut self, out: &mut [u8; 64], max: usize) -> Result<usize, ParseFrameError> {
        // The usual case first: pairs of hex digits, by table, up to the first other byte.
        let value = |b: u8| HEX_VALUE.get(usize::from(b)).copied().unwrap_or(0xFF);
        let rest = self.bytes.get(self.pos..).unwrap_or_default();
        let mut len = 0;
        for (slot, pair) in out.iter_mut().zip(rest.chunks_exact(2)).take(max) {
            let &[high, low] = pair else { break };
            let (high, low) = (value(high), value(low));
            if (high | low) > 15 {
                break;
            }
            *slot = (high << 4) | low;
            len += 1;
        }
        self.pos += 2 * len;
        // Separators, odd digits and errors, with their columns. Each byte consumes at least
        // two characters, so the text length bounds the loop.
        while let Some(c) = self.peek() {
            if c == b'.' {
                self.pos += 1;
                continue;
            }
            if c == b'_' {
                break;
            }
            if len == max {
                return Err(self.error(ParseFrameErrorKind::TooMuchData(max)));
            }
            let high = self.hex_digit()?;
            if self.peek().is_none() {
                return Err(self.error(ParseFrameErrorKind::HalfByte));
            }
            let low = self.hex_digit()?;
            if let Some(slot) = out.get_mut(len) {
                *slot = (high << 4) | low;
            }
            len += 1;
        }
        Ok(len)
    }

    /// An optional `_X` raw DLC suffix (9..=F) valid only after exactly 8 bytes.
    fn raw_dlc(&mut self, len: usize) -> Result<Option<Dlc>, ParseFrameError> {
        if self.peek() != Some(b'_') {
            return Ok(None);
        }
        self.pos += 1;
        let c = self.current_char();
        let at = self.pos;
        let value = self.hex_digit().ok().filter(|v| *v > 8 && len == 8);
        value
            .and_then(Dlc::new)
            .map(Some)
            .ok_or_else(|| err(at + 1, ParseFrameErrorKind::RawDlc(c)))
    }

    fn end(&self) -> Result<(), ParseFrameError> {
        match self.peek() {
            None => Ok(()),
            Some(c) => Err(self.error(ParseFrameErrorKind::Trailing(char::from(c)))),
        }
    }
}

impl FromStr for Frame {
    type Err = ParseFrameError;

    fn from_str(text: &str) -> Result<Frame, ParseFrameError> {
        Frame::from_ascii(text.as_bytes())
    }
}

impl Frame {
    /// [`Frame::from_str`] over bytes not known to be UTF-8 (the form is ASCII, so any other
    /// byte is an error at its column): for readers that parse a line before checking it.
    pub fn from_ascii(bytes: &[u8]) -> Result<Frame, ParseFrameError> {
        let digits = match (bytes.get(3), bytes.get(8)) {
            (Some(b'#'), _) => 3,
            (_, Some(b'#')) => 8,
            _ => return Err(err(1, ParseFrameErrorKind::MissingSeparator)),
        };
        let mut cur = Cursor { bytes, pos: 0 };
        let mut raw_id = 0u32;
        for _ in 0..digits {
            raw_id = (raw_id << 4) | u32::from(cur.hex_digit()?);
        }
        cur.pos += 1; // '#'
        let frame_err = |kind: FrameError| err(1, ParseFrameErrorKind::Frame(kind));
        let mut data = [0u8; 64];

        if digits == 8 && raw_id & ERR_FLAG != 0 {
            if raw_id & !(ERR_FLAG | EFF_MASK) != 0 {
                return Err(err(1, ParseFrameErrorKind::IdFlags(raw_id)));
            }
            let len = cur.data(&mut data, 8)?;
            cur.end()?;
            return ErrorFrame::new(raw_id & EFF_MASK, data.get(..len).unwrap_or(&[]))
                .map(Frame::Error)
                .map_err(frame_err);
        }
        let id = if digits == 3 {
            Id::standard(raw_id).map_err(frame_err)?
        } else if raw_id & !EFF_MASK != 0 {
            return Err(err(1, ParseFrameErrorKind::IdFlags(raw_id)));
        } else {
            Id::extended(raw_id).map_err(frame_err)?
        };

        match cur.peek() {
            Some(b'R' | b'r') => {
                cur.pos += 1;
                let mut dlc = Dlc(0);
                if let Some(c) = cur.peek().filter(|c| *c != b'_') {
                    let value = char::from(c).to_digit(10).filter(|v| *v <= 8);
                    dlc = value
                        .and_then(|v| u8::try_from(v).ok())
                        .and_then(Dlc::new)
                        .ok_or_else(|| {
                            cur.error(ParseFrameErrorKind::RemoteLength(char::from(c)))
                        })?;
                    cur.pos += 1;
                }
                if let Some(raw) = cur.raw_dlc(dlc.classic_len())? {
                    dlc = raw;
                }
                cur.end()?;
                Ok(Frame::remote(id, dlc))
            }
            Some(b'#') => {
                cur.pos += 1;
                // Flags nibble: BRS and ESI; FDF (4, set by newer kernels) is implied by `##`.
                let flags = cur.hex_digit()?;
                let len = cur.data(&mut data, 64)?;
                cur.end()?;
                // can-utils accepts any byte count; the controller pads to the next FD length.
                FdFrame::padded(
                    id,
                    data.get(..len).unwrap_or(&[]),
                    flags & FLAG_BRS != 0,
                    flags & FLAG_ESI != 0,
                )
                .map(Frame::Fd)
                .map_err(frame_err)
            }
            _ => {
                let len = cur.data(&mut data, 8)?;
                let raw = cur.raw_dlc(len)?;
                cur.end()?;
                let payload = data.get(..len).unwrap_or(&[]);
                let frame = match raw {
                    Some(dlc) => ClassicFrame::with_dlc(id, dlc, payload),
                    None => ClassicFrame::new(id, payload),
                };
                frame.map(Frame::Classic).map_err(frame_err)
            }
        }
    }
}

/// A frame's compact text, built on the stack: what [`Frame`]'s `Display` prints, as bytes for
/// writers that copy them (formatting each field through `core::fmt` cost ten times more). At
/// most 139 bytes: an extended identifier, `##`, the flags and 64 data bytes in hex.
#[derive(Clone, Copy)]
pub struct FrameText {
    bytes: [u8; FrameText::CAPACITY],
    len: usize,
}

impl FrameText {
    const CAPACITY: usize = 140;
    const DIGITS: &'static [u8; 16] = b"0123456789ABCDEF";

    /// The text's bytes (ASCII).
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }

    fn push(&mut self, byte: u8) {
        if let Some(slot) = self.bytes.get_mut(self.len) {
            *slot = byte;
            self.len += 1;
        }
    }

    /// `value`'s last `digits` hex digits, upper case (the identifiers' `{:03X}`/`{:08X}`).
    fn push_hex(&mut self, value: u32, digits: u32) {
        for shift in (0..digits).rev() {
            let nibble = value.checked_shr(4 * shift).unwrap_or(0) & 0xF;
            self.push(Self::digit(nibble));
        }
    }

    fn push_data(&mut self, data: &[u8]) {
        for byte in data {
            self.push(Self::digit(u32::from(byte >> 4)));
            self.push(Self::digit(u32::from(byte & 0xF)));
        }
    }

    fn push_id(&mut self, id: Id) {
        match id {
            Id::Standard(s) => self.push_hex(u32::from(s.as_raw()), 3),
            Id::Extended(e) => self.push_hex(e.as_raw(), 8),
        }
        self.push(b'#');
    }

    fn digit(nibble: u32) -> u8 {
        usize::try_from(nibble)
            .ok()
            .and_then(|n| Self::DIGITS.get(n))
            .copied()
            .unwrap_or(b'0')
    }
}

impl Frame {
    /// The compact can-utils form, byte-identical to `candump`'s (what `Display` prints).
    pub fn text(&self) -> FrameText {
        let mut text = FrameText {
            bytes: [0; FrameText::CAPACITY],
            len: 0,
        };
        match self {
            Frame::Classic(c) => {
                text.push_id(c.id());
                let dlc = c.dlc().as_raw();
                if c.is_remote() {
                    text.push(b'R');
                    if dlc > 0 {
                        // A remote frame's length is at most 8: one digit.
                        text.push_hex(u32::try_from(c.len()).unwrap_or(0), 1);
                    }
                } else {
                    text.push_data(c.data());
                }
                if dlc > 8 {
                    text.push(b'_');
                    text.push_hex(u32::from(dlc), 1);
                }
            }
            Frame::Fd(d) => {
                text.push_id(d.id());
                // FDF (4) is always set, as Linux and can-utils write it.
                let mut flags = FLAG_FDF;
                if d.brs() {
                    flags |= FLAG_BRS;
                }
                if d.esi() {
                    flags |= FLAG_ESI;
                }
                text.push(b'#');
                text.push_hex(u32::from(flags), 1);
                text.push_data(d.data());
            }
            Frame::Error(e) => {
                text.push_hex(ERR_FLAG | e.class_bits(), 8);
                text.push(b'#');
                text.push_data(e.data());
            }
        }
        text
    }
}

/// Prints the compact can-utils form, byte-identical to `candump`'s.
impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text().as_str())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    fn round(text: &str) -> std::string::String {
        text.parse::<Frame>().unwrap().to_string()
    }

    #[test]
    fn parses_every_can_utils_form() {
        assert_eq!(round("123#DEADBEEF"), "123#DEADBEEF");
        assert_eq!(round("123#de.ad.be.ef"), "123#DEADBEEF");
        assert_eq!(round("1ABCDEF0#"), "1ABCDEF0#");
        assert_eq!(round("00000123#11"), "00000123#11");
        assert_eq!(round("123#R"), "123#R");
        assert_eq!(round("123#r5"), "123#R5");
        assert_eq!(round("123#R8_E"), "123#R8_E");
        assert_eq!(round("123#1122334455667788_F"), "123#1122334455667788_F");
        assert_eq!(round("123##1DEADBEEF"), "123##5DEADBEEF");
        assert_eq!(round("123##3"), "123##7");
        assert_eq!(round("123##0.11.22"), "123##41122");
        // Nine bytes are padded to the next FD length, as the controller sends them.
        assert_eq!(
            round("123##0112233445566778899"),
            "123##4112233445566778899000000"
        );
        assert_eq!(
            round("20000080#0000000000000000"),
            "20000080#0000000000000000"
        );
        let f: Frame = "1ABCDEF0##5".parse().unwrap();
        assert!(f.is_fd() && f.id().unwrap().is_extended());
        let Frame::Fd(fd) = f else { panic!() };
        assert!(fd.brs() && !fd.esi());
    }

    #[test]
    fn refuses_bad_text_naming_the_column() {
        let e = |t: &str| t.parse::<Frame>().unwrap_err();
        assert_eq!(e("12#34").kind, ParseFrameErrorKind::MissingSeparator);
        assert_eq!(e("12G#00"), err(3, ParseFrameErrorKind::NotHex('G')));
        assert_eq!(e("123#0"), err(6, ParseFrameErrorKind::HalfByte));
        assert_eq!(
            e("123#00112233445566778"),
            err(21, ParseFrameErrorKind::TooMuchData(8))
        );
        assert_eq!(e("123#R9"), err(6, ParseFrameErrorKind::RemoteLength('9')));
        assert_eq!(e("123#11_E"), err(8, ParseFrameErrorKind::RawDlc('E')));
        assert_eq!(
            e("123#1122334455667788_5"),
            err(22, ParseFrameErrorKind::RawDlc('5'))
        );
        assert_eq!(e("123#R x").kind, ParseFrameErrorKind::RemoteLength(' '));
        assert_eq!(e("123#11 "), err(7, ParseFrameErrorKind::NotHex(' ')));
        assert_eq!(
            e("FFF#00").kind,
            ParseFrameErrorKind::Frame(FrameError::StandardIdRange(0xFFF))
        );
        assert_eq!(
            e("C0000000#").kind,
            ParseFrameErrorKind::IdFlags(0xC000_0000)
        );
        assert_eq!(e("123##G").kind, ParseFrameErrorKind::NotHex('G'));
        assert_eq!(e("").kind, ParseFrameErrorKind::MissingSeparator);
        assert_eq!(e("12G#00").to_string(), "column 3: 'G' is not a hex digit");
    }
}
