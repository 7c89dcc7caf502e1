//! Text lines from any reader, in bounded memory: a line longer than the cap is skipped and
//! reported with its number instead of being gathered whole (a 400 MB "line" must not cost
//! 400 MB), and a line that is not UTF-8 is reported instead of ending the input.

use std::io::{self, BufRead};

/// The default cap on one line: far longer than any CAN log or command line.
pub const DEFAULT_MAX_LINE: usize = 64 * 1024;

/// One line, without its end (`\n` or `\r\n`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// A line of text.
    Text(String),
    /// A line that is not UTF-8, with the byte offset of the first bad byte in it.
    NotUtf8 {
        /// Where in the line the bad bytes start.
        at: usize,
    },
    /// A line longer than the cap (skipped), with its length.
    TooLong {
        /// Its length in bytes.
        bytes: u64,
    },
}

/// One line as [`CappedLines::next_str`] lends it: the text borrowed until the next read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineRef<'a> {
    /// A line of text.
    Text(&'a str),
    /// A line that is not UTF-8, with the byte offset of the first bad byte in it.
    NotUtf8 {
        /// Where in the line the bad bytes start.
        at: usize,
    },
    /// A line longer than the cap (skipped), with its length.
    TooLong {
        /// Its length in bytes.
        bytes: u64,
    },
}

/// One line as [`CappedLines::next_bytes`] lends it: its bytes, not yet checked to be UTF-8.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineBytes<'a> {
    /// The line's bytes, without its newline (a `\r` before it kept).
    Bytes(&'a [u8]),
    /// A line longer than the cap (skipped), with its length.
    TooLong {
        /// Its length in bytes.
        bytes: u64,
    },
}

impl LineRef<'_> {
    /// The line, owned.
    pub fn to_owned_line(self) -> Line {
        match self {
            LineRef::Text(text) => Line::Text(text.to_string()),
            LineRef::NotUtf8 { at } => Line::NotUtf8 { at },
            LineRef::TooLong { bytes } => Line::TooLong { bytes },
        }
    }
}

impl Line {
    /// What keeps the line from being read as text (`None` for text).
    pub fn problem(&self) -> Option<String> {
        match self {
            Line::Text(_) => None,
            Line::NotUtf8 { at } => Some(format!("not UTF-8 at byte {at}")),
            Line::TooLong { bytes } => Some(format!("{bytes} bytes, longer than a line")),
        }
    }
}

/// Lines of `reader`, numbered from 1, each at most `max` bytes held.
pub struct CappedLines<R> {
    reader: R,
    max: usize,
    number: u64,
    buffer: Vec<u8>,
    /// Bytes of the reader's buffer lent out as the last line, consumed at the next call.
    lent: usize,
}

impl<R: BufRead> CappedLines<R> {
    /// Lines of `reader` with the default cap.
    pub fn new(reader: R) -> Self {
        CappedLines::with_max(reader, DEFAULT_MAX_LINE)
    }

    /// Lines of `reader`, at most `max` bytes each.
    pub fn with_max(reader: R, max: usize) -> Self {
        CappedLines {
            reader,
            max: max.max(1),
            number: 0,
            buffer: Vec::new(),
            lent: 0,
        }
    }

    /// The next line with its number; `None` at the end of the input. An I/O error ends
    /// nothing by itself: the caller decides.
    pub fn next_line(&mut self) -> Option<io::Result<(u64, Line)>> {
        self.next_str()
            .map(|next| next.map(|(number, line)| (number, line.to_owned_line())))
    }

    /// As [`CappedLines::next_line`], the text lent rather than copied into a new `String`
    /// (the readers of text logs parse it in place).
    pub fn next_str(&mut self) -> Option<io::Result<(u64, LineRef<'_>)>> {
        self.next_bytes().map(|next| {
            next.map(|(number, line)| match line {
                LineBytes::Bytes(bytes) => (number, line_ref(bytes)),
                LineBytes::TooLong { bytes } => (number, LineRef::TooLong { bytes }),
            })
        })
    }

    /// As [`CappedLines::next_str`], the line's bytes not yet checked to be UTF-8 (a reader
    /// that checks them as it parses need not go over them twice); a `\r` before the newline
    /// is kept.
    pub fn next_bytes(&mut self) -> Option<io::Result<(u64, LineBytes<'_>)>> {
        self.reader.consume(std::mem::take(&mut self.lent));
        self.buffer.clear();
        // Most lines lie whole in the reader's buffer: lent from there, not copied.
        let whole = match self.reader.fill_buf() {
            Ok(available) => memchr::memchr(b'\n', available).filter(|&end| end <= self.max),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => None,
            Err(e) => return Some(Err(e)),
        };
        if let Some(end) = whole {
            self.lent = end + 1;
            self.number += 1;
            // The buffer is as it was: a second fill_buf does not read.
            let available = self.reader.fill_buf().unwrap_or_default();
            let line = available.get(..end).unwrap_or_default();
            return Some(Ok((self.number, LineBytes::Bytes(line))));
        }
        let mut length: u64 = 0;
        let mut ended = false;
        // Each pass consumes what the reader has buffered: bounded by the line's length.
        loop {
            let available = match self.reader.fill_buf() {
                Ok(bytes) => bytes,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Some(Err(e)),
            };
            if available.is_empty() {
                break;
            }
            let (chunk, newline) = match memchr::memchr(b'\n', available) {
                Some(i) => (available.get(..i).unwrap_or_default(), true),
                None => (available, false),
            };
            let room = self.max.saturating_sub(self.buffer.len());
            self.buffer
                .extend_from_slice(chunk.get(..chunk.len().min(room)).unwrap_or_default());
            length = length.saturating_add(u64::try_from(chunk.len()).unwrap_or(u64::MAX));
            let used = chunk.len() + usize::from(newline);
            self.reader.consume(used);
            if newline {
                ended = true;
                break;
            }
        }
        if !ended && length == 0 {
            return None;
        }
        self.number += 1;
        if length > u64::try_from(self.max).unwrap_or(u64::MAX) {
            return Some(Ok((self.number, LineBytes::TooLong { bytes: length })));
        }
        Some(Ok((self.number, LineBytes::Bytes(&self.buffer))))
    }
}

impl<T: io::Read> CappedLines<io::BufReader<T>> {
    /// Whether a whole line is already read and waiting (the next line comes without waiting
    /// for the input).
    pub fn line_waiting(&self) -> bool {
        self.reader
            .buffer()
            .get(self.lent..)
            .is_some_and(|rest| rest.contains(&b'\n'))
    }
}

/// A line's bytes (its newline gone) as text, a `\r` before the newline dropped.
pub fn line_ref(line: &[u8]) -> LineRef<'_> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    match std::str::from_utf8(line) {
        Ok(text) => LineRef::Text(text),
        Err(e) => LineRef::NotUtf8 {
            at: e.valid_up_to(),
        },
    }
}

impl<R: BufRead> Iterator for CappedLines<R> {
    type Item = io::Result<(u64, Line)>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_line()
    }
}

/// The lines of a text log that start in the byte range `start..end` of a file: what one worker
/// reads when a big log is split among several (each line is read by exactly one range, so the
/// ranges of a split together read every line once). A [`std::io::Read`] over the range's bytes,
/// from the first line starting at or after `start` through the end of the line holding byte
/// `end - 1`.
pub struct LineRange<R> {
    inner: R,
    /// Offset of the next byte `inner` gives.
    position: u64,
    end: u64,
    done: bool,
}

impl<R: BufRead + io::Seek> LineRange<R> {
    /// The range `start..end` of `inner` (a seekable reader at any position).
    pub fn new(mut inner: R, start: u64, end: u64) -> io::Result<Self> {
        let mut position = start.saturating_sub(1);
        inner.seek(io::SeekFrom::Start(position))?;
        // The byte before `start` is a newline when a line starts at `start`; otherwise the
        // line it is part of belongs to the range before. Skipped without keeping it (each
        // pass consumes bytes, so this ends at the file's end at the latest).
        if start > 0 {
            loop {
                let buffer = inner.fill_buf()?;
                if buffer.is_empty() {
                    break;
                }
                let (taken, found) = match memchr::memchr(b'\n', buffer) {
                    Some(at) => (at + 1, true),
                    None => (buffer.len(), false),
                };
                inner.consume(taken);
                position += taken as u64;
                if found {
                    break;
                }
            }
        }
        Ok(LineRange {
            inner,
            position,
            end,
            done: position >= end,
        })
    }
}

impl<R: BufRead> io::Read for LineRange<R> {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.done {
            return Ok(0);
        }
        let buffer = self.inner.fill_buf()?;
        let mut n = buffer.len().min(out.len());
        // The last line is the one holding byte `end - 1`: stop after the first newline at
        // or past it.
        let last = self.end.saturating_sub(1).saturating_sub(self.position);
        if let Ok(last) = usize::try_from(last) {
            if last < n {
                let newline = buffer
                    .get(last..n)
                    .and_then(|rest| memchr::memchr(b'\n', rest));
                if let Some(at) = newline {
                    n = last + at + 1;
                    self.done = true;
                }
            }
        }
        if let (Some(to), Some(from)) = (out.get_mut(..n), buffer.get(..n)) {
            to.copy_from_slice(from);
        }
        self.inner.consume(n);
        self.position += n as u64;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn range(text: &[u8], start: u64, end: u64) -> Vec<u8> {
        let reader = io::BufReader::with_capacity(5, io::Cursor::new(text.to_vec()));
        let mut out = Vec::new();
        io::Read::read_to_end(&mut LineRange::new(reader, start, end).unwrap(), &mut out).unwrap();
        out
    }

    proptest::proptest! {
        #[test]
        fn ranges_of_a_split_read_every_line_once(
            lines in proptest::collection::vec("[a-z ]{0,12}", 0..20),
            last_newline: bool,
            cuts in proptest::collection::vec(0u64..400, 0..6),
        ) {
            let mut text = lines.join("\n");
            if last_newline {
                text.push('\n');
            }
            let len = text.len() as u64;
            let mut bounds: Vec<u64> = cuts.into_iter().map(|c| c % (len + 1)).collect();
            bounds.push(0);
            bounds.push(len);
            bounds.sort_unstable();
            let mut joined = Vec::new();
            for pair in bounds.windows(2) {
                let part = range(text.as_bytes(), pair[0], pair[1]);
                // Each range is whole lines: it starts a line, and ends one (or the text).
                if let Some(first) = part.first() {
                    let at = joined.len();
                    proptest::prop_assert!(at == 0 || text.as_bytes()[at - 1] == b'\n', "{first}");
                }
                joined.extend(part);
            }
            proptest::prop_assert_eq!(joined, text.into_bytes());
        }
    }

    fn lines(input: &[u8], max: usize) -> Vec<(u64, Line)> {
        CappedLines::with_max(io::BufReader::with_capacity(7, input), max)
            .map(Result::unwrap)
            .collect()
    }

    #[test]
    fn lines_are_numbered_and_capped() {
        let input = b"one\r\ntwo\n\nfar too long a line\n\xff\xfe\nlast";
        assert_eq!(
            lines(input, 8),
            vec![
                (1, Line::Text("one".into())),
                (2, Line::Text("two".into())),
                (3, Line::Text(String::new())),
                (4, Line::TooLong { bytes: 19 }),
                (5, Line::NotUtf8 { at: 0 }),
                (6, Line::Text("last".into())),
            ]
        );
        assert!(lines(b"", 8).is_empty());
        assert_eq!(lines(b"\n", 8), vec![(1, Line::Text(String::new()))]);
    }

    #[test]
    fn a_huge_line_is_not_held() {
        // 10 MB without a newline, read through a small buffer: only the cap is kept.
        let huge = vec![b'x'; 10 * 1024 * 1024];
        let mut reader = CappedLines::with_max(io::BufReader::new(&huge[..]), 1024);
        let (n, line) = reader.next().unwrap().unwrap();
        assert_eq!(
            (n, line),
            (
                1,
                Line::TooLong {
                    bytes: 10 * 1024 * 1024
                }
            )
        );
        assert!(
            reader.buffer.capacity() <= 64 * 1024,
            "{}",
            reader.buffer.capacity()
        );
        assert!(reader.next().is_none());
    }
}
