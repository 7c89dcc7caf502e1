//! candump's screen form of a frame, as it prints it after the interface name:
//!
//! ```text
//! 123   [4]  DE AD BE EF
//! 12345678   [0]
//!      123  [03]  11 22 33          (FD; standard IDs indented once an extended one was seen)
//! 123   [3]  remote request
//! 20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME
//! ```
//!
//! [`FrameView`] writes it byte for byte as can-utils does (with the ASCII column of `-a` and
//! the error details of `-e`); [`parse_line`] reads a candump line of either form back.

use std::fmt::{self, Write as _};

use bywire_core::{ClassicFrame, Dlc, FdFrame, Frame, Id};

/// How a frame is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct View {
    /// Indent standard IDs to the width of extended ones (candump turns this on for good once
    /// it has shown an extended frame).
    pub indent_standard: bool,
    /// Printable data bytes as ASCII after the data (`candump -a`).
    pub ascii: bool,
    /// Error frames' classes and details on the following lines (`candump -e`).
    pub error_details: bool,
    /// Data bytes in binary, `10101010` (`candump -i`).
    pub binary: bool,
    /// Data bytes last to first, joined by a backquote (`candump -S`: a little-endian value
    /// read as a number).
    pub swap: bool,
}

/// A frame in the screen form with a view.
pub struct FrameView<'a> {
    /// The frame.
    pub frame: &'a Frame,
    /// The view.
    pub view: View,
}

impl fmt::Display for FrameView<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (frame, view) = (self.frame, self.view);
        match frame {
            Frame::Error(e) => {
                write!(f, "{:08X}  ", e.class_bits() | bywire_core::frame::ERR_FLAG)?
            }
            _ => match frame.id() {
                Some(Id::Extended(id)) => write!(f, "{:08X}  ", id.as_raw())?,
                Some(Id::Standard(id)) if view.indent_standard => {
                    write!(f, "     {:03X}  ", id.as_raw())?;
                }
                Some(Id::Standard(id)) => write!(f, "{:03X}  ", id.as_raw())?,
                None => {}
            },
        }
        let data = if frame.is_remote() {
            &[][..]
        } else {
            frame.data()
        };
        if frame.is_fd() {
            write!(f, "[{:02}] ", data.len())?;
        } else {
            let len = match frame {
                Frame::Classic(c) => c.len(),
                _ => data.len(),
            };
            write!(f, " [{len}] ")?;
            if frame.is_remote() {
                return f.write_str(" remote request");
            }
        }
        // Swapped, the bytes run last to first, a backquote between them.
        let between = if view.swap { '`' } else { ' ' };
        let ordered = || {
            (0..data.len()).filter_map(move |i| {
                let at = if view.swap { data.len() - 1 - i } else { i };
                data.get(at)
            })
        };
        for (i, byte) in ordered().enumerate() {
            f.write_char(if i == 0 { ' ' } else { between })?;
            if view.binary {
                write!(f, "{byte:08b}")?;
            } else {
                write!(f, "{byte:02X}")?;
            }
        }
        // The ASCII and ERRORFRAME columns start at a fixed place behind 8 bytes of data.
        let Some(missing) = 8usize.checked_sub(data.len()) else {
            return Ok(());
        };
        let byte_width = if view.binary { 9 } else { 3 };
        if let Frame::Error(e) = frame {
            write!(
                f,
                "{:>width$}",
                "ERRORFRAME",
                width = byte_width * missing + 13
            )?;
            if view.error_details {
                write!(f, "\n\t{}", e.describe_with("\n\t"))?;
            }
        } else if view.ascii {
            let quote = if view.swap { '`' } else { '\'' };
            write!(f, "{:>width$}", quote, width = byte_width * missing + 4)?;
            for byte in ordered() {
                let c = if (0x20..0x7F).contains(byte) {
                    char::from(*byte)
                } else {
                    '.'
                };
                f.write_char(c)?;
            }
            f.write_char(quote)?;
        }
        Ok(())
    }
}

/// The frame's text of a line in the log form as candump writes it, `(ts) can0 123#DEADBEEF`
/// (one space between the fields), found without splitting the line into words; `None` for
/// anything else, which the word-by-word path reads (to the same frame where both apply).
fn log_form_frame(line: &str) -> Option<&str> {
    let bytes = line.as_bytes();
    if bytes.first() != Some(&b'(') {
        return None;
    }
    // A word of printable ASCII (no whitespace of any kind) up to a space or the end.
    let word_end = |from: usize| {
        let rest = bytes.get(from..)?;
        let len = rest
            .iter()
            .position(|b| !b.is_ascii_graphic())
            .unwrap_or(rest.len());
        (len > 0 && rest.get(len).is_none_or(|&b| b == b' ')).then_some(from + len)
    };
    let stamp_end = word_end(0)?;
    if bytes.get(stamp_end - 1) != Some(&b')') {
        return None;
    }
    let interface_end = word_end(stamp_end + 1)?;
    let frame_end = word_end(interface_end + 1)?;
    let frame = line.get(interface_end + 1..frame_end)?;
    frame.contains('#').then_some(frame)
}

/// A frame from a candump line in either form: the log form `(ts) can0 123#DEADBEEF` or the
/// screen form `can0  123   [4]  DE AD BE EF` (with or without a leading `(timestamp)`).
/// `None` for anything else. Error frames' detail lines and the ASCII column are ignored.
pub fn parse_line(line: &str) -> Option<Frame> {
    match log_form_frame(line) {
        Some(frame_text) => frame_text.parse().ok(),
        None => parse_words(line),
    }
}

/// [`parse_line`] word by word, for every form.
fn parse_words(line: &str) -> Option<Frame> {
    let mut words = line.split_whitespace().peekable();
    if words.peek().is_some_and(|w| w.starts_with('(')) {
        // `-tA` timestamps have a space inside: skip to the word that closes them.
        for word in words.by_ref() {
            if word.ends_with(')') {
                break;
            }
        }
    }
    let _interface = words.next()?;
    let first = words.next()?;
    if first.contains('#') {
        return first.parse().ok();
    }
    if !first.bytes().all(|b| b.is_ascii_hexdigit()) || !matches!(first.len(), 3 | 8) {
        return None;
    }
    let raw = u32::from_str_radix(first, 16).ok()?;
    let length_word = words.next()?;
    let inner = length_word.strip_prefix('[')?.strip_suffix(']')?;
    let fd = inner.len() == 2;
    let len: usize = inner.parse().ok()?;
    let mut data = [0u8; 64];
    let mut count = 0;
    let mut remote = false;
    for word in words {
        if word == "remote" {
            remote = true;
            break;
        }
        if count == len {
            break;
        }
        *data.get_mut(count)? = u8::from_str_radix(word, 16).ok()?;
        count += 1;
    }
    if raw & bywire_core::frame::ERR_FLAG != 0 {
        let class = raw & !bywire_core::frame::ERR_FLAG;
        return bywire_core::ErrorFrame::new(class, data.get(..count)?)
            .ok()
            .map(Frame::Error);
    }
    let id = if first.len() == 8 {
        Id::extended(raw).ok()?
    } else {
        Id::standard(raw).ok()?
    };
    if remote {
        return Some(Frame::Classic(ClassicFrame::remote(
            id,
            Dlc::from_classic_len(len)?,
        )));
    }
    if count != len {
        return None;
    }
    let payload = data.get(..count)?;
    if fd {
        FdFrame::new(id, payload, false, false).ok().map(Frame::Fd)
    } else {
        ClassicFrame::new(id, payload).ok().map(Frame::Classic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn show(text: &str, view: View) -> String {
        let frame: Frame = text.parse().unwrap();
        FrameView {
            frame: &frame,
            view,
        }
        .to_string()
    }

    #[test]
    fn binary_and_swapped_views_are_candumps() {
        let binary = View {
            binary: true,
            ..View::default()
        };
        let swapped = View {
            swap: true,
            ascii: true,
            ..View::default()
        };
        assert_eq!(show("123#A501", binary), "123   [2]  10100101 00000001");
        assert_eq!(
            show("123#414243", swapped),
            "123   [3]  43`42`41                  `CBA`"
        );
        assert_eq!(
            show(
                "123#A501",
                View {
                    swap: true,
                    ..binary
                }
            ),
            "123   [2]  00000001`10100101"
        );
    }

    #[test]
    fn prints_as_candump_does() {
        let plain = View::default();
        let indent = View {
            indent_standard: true,
            ..View::default()
        };
        assert_eq!(show("123#DEADBEEF", plain), "123   [4]  DE AD BE EF");
        assert_eq!(show("12345678#", plain), "12345678   [0] ");
        assert_eq!(show("123#R3", indent), "     123   [3]  remote request");
        assert_eq!(show("123##5112233", indent), "     123  [03]  11 22 33");
        assert_eq!(show("7FF##4", indent), "     7FF  [00] ");
        let ascii = View {
            ascii: true,
            ..View::default()
        };
        assert_eq!(
            show("123#414243", ascii),
            "123   [3]  41 42 43                  'ABC'"
        );
        let details = View {
            error_details: true,
            ..View::default()
        };
        assert_eq!(
            show("2000000C#0108000000000F10", details),
            "2000000C   [8]  01 08 00 00 00 00 0F 10   ERRORFRAME\n\tcontroller-problem{tx-error-warning}\n\tprotocol-violation{{}{}}\n\terror-counter-tx-rx{{15}{16}}"
        );
    }

    #[test]
    fn reads_both_forms() {
        for (line, frame) in [
            ("  can0  123   [4]  DE AD BE EF", "123#DEADBEEF"),
            (" (1699999999.123456)  can0  12345678   [0] ", "12345678#"),
            (
                " (2024-01-01 12:00:00.000001)  can0  123   [3]  remote request",
                "123#R3",
            ),
            ("  vcan0       123  [03]  11 22 33", "123##4112233"),
            ("(1.0) can0 123#DEADBEEF", "123#DEADBEEF"),
            (
                "  can0  123   [3]  41 42 43                  'ABC'",
                "123#414243",
            ),
            (
                "  can0  20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME",
                "20000080#0000000000000000",
            ),
        ] {
            assert_eq!(parse_line(line), Some(frame.parse().unwrap()), "{line}");
        }
        for junk in [
            "",
            "hello world",
            "  can0  123   [9]  00",
            "  can0  12G  [1]  00",
        ] {
            assert_eq!(parse_line(junk), None, "{junk}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(4096))]

        /// The log form's shortcut reads every line it takes as the word-by-word path does:
        /// lines of candump's log form with other spacing (tabs, vertical tabs, no-break spaces,
        /// doubled spaces), timestamps with spaces, and stray brackets and hashes.
        #[test]
        fn the_log_form_shortcut_agrees_with_the_words(
            stamp in "[(]?[0-9.]{0,4}( [0-9:]{1,3})?[)]?",
            first in "[ ]|[ ]{2}|\t|\u{b}|\u{a0}|",
            interface in "can0|vcan1|c[)]|[#]|",
            second in "[ ]|[ ]{2}|\t|\u{b}|\u{a0}|",
            frame in "[0-9A-Fa-f]{0,9}#{0,2}[0-9A-Fa-fR_.]{0,6}",
            rest in "( R| T|[ ]{2}R|\u{a0}T| x#1)?",
        ) {
            let line = format!("{stamp}{first}{interface}{second}{frame}{rest}");
            if let Some(text) = log_form_frame(&line) {
                proptest::prop_assert_eq!(text.parse::<Frame>().ok(), parse_words(&line), "{:?}", line);
            }
        }

        #[test]
        fn log_lines_take_the_shortcut(
            seconds in 0u64..2_000_000_000,
            id in 0u32..0x800,
            data in proptest::collection::vec(proptest::num::u8::ANY, 0..=8),
            direction in "( R| T)?",
        ) {
            let hex: String = data.iter().map(|b| format!("{b:02X}")).collect();
            let line = format!("({seconds}.000001) can0 {id:03X}#{hex}{direction}");
            proptest::prop_assert!(log_form_frame(&line).is_some());
            proptest::prop_assert_eq!(parse_line(&line), parse_words(&line));
            proptest::prop_assert!(parse_line(&line).is_some());
        }
    }
}
