//! A Parquet footer, and its pages' headers, checked before the `parquet` crate reads them.
//!
//! The crate trusts the counts a footer declares: a list's length, a schema element's number of
//! children. It reserves memory for them before it has read the elements, so a footer of a few
//! dozen bytes can make it reserve gigabytes (found by fuzzing: a schema element declaring two
//! billion children). This walks the footer's Thrift compact encoding without building
//! anything and refuses, with the byte offset, every count that the bytes left cannot hold:
//! a list of N elements needs at least N bytes, and a schema element's children are the
//! elements that follow it. Then whatever the crate reserves is bounded by the footer's size,
//! which is bounded by the file's.
//!
//! Page headers are walked the same way ([`check_pages`]): found by fuzzing, a 5 KB file whose
//! page header declares a string of billions of bytes kept the crate skipping past the file's
//! end, a read call at a time, for minutes; and the crate reserves a page's declared
//! uncompressed size before decompressing it.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};

use crate::candump::LogError;

/// Nesting deeper than this is refused (Parquet's own footers nest a handful of levels).
const MAX_DEPTH: usize = 64;

/// A page's declared uncompressed size above this is refused: writers make pages of about
/// 1 MiB (parquet-rs, pyarrow and Spark by default), and the crate reserves the size it is told.
const MAX_PAGE_BYTES: u64 = 256 << 20;

/// A page header is looked for in this many bytes, then (if it goes on) in [`MAX_HEADER_BYTES`].
const HEADER_WINDOW: u64 = 8 << 10;

/// A page header longer than this is refused (its statistics would be megabytes).
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// The footer of `file` checked (its end position restored is not needed: the reader seeks).
pub(crate) fn check(file: &mut File) -> Result<(), LogError> {
    let fail = |offset: u64, what: String| LogError::Binary { offset, what };
    let length = file
        .seek(SeekFrom::End(0))
        .map_err(|e| fail(0, format!("cannot seek: {e}")))?;
    if length < 12 {
        return Err(fail(0, format!("{length} bytes: too short for Parquet")));
    }
    let mut tail = [0u8; 8];
    file.seek(SeekFrom::Start(length - 8))
        .and_then(|_| file.read_exact(&mut tail))
        .map_err(|e| fail(length - 8, format!("cannot read the footer: {e}")))?;
    let [a, b, c, d, magic @ ..] = tail;
    if magic != *b"PAR1" {
        return Err(fail(length - 4, "no Parquet magic at the end".into()));
    }
    let footer_length = u64::from(u32::from_le_bytes([a, b, c, d]));
    let Some(start) = length.checked_sub(8 + footer_length).filter(|s| *s >= 4) else {
        return Err(fail(
            length - 8,
            format!("a footer of {footer_length} bytes in a file of {length}"),
        ));
    };
    let mut footer = vec![0u8; usize::try_from(footer_length).unwrap_or(0)];
    file.seek(SeekFrom::Start(start))
        .and_then(|_| file.read_exact(&mut footer))
        .map_err(|e| fail(start, format!("cannot read the footer: {e}")))?;
    let mut walker = Walker {
        bytes: &footer,
        at: 0,
    };
    walker
        .file_metadata()
        .map_err(|(at, what)| fail(start + at as u64, format!("Parquet footer: {what}")))
}

/// Every page header of the column chunks `chunks` (each its first byte and length, as the
/// footer declares them) checked: each chunk within the file, each page within its chunk, its
/// counts held by its bytes, its uncompressed size at most [`MAX_PAGE_BYTES`]. Bounded by the
/// chunks' bytes: each page moves on by its header's length at least.
pub(crate) fn check_pages(
    file: &mut File,
    chunks: impl Iterator<Item = (i64, i64)>,
) -> Result<(), LogError> {
    let fail = |offset: u64, what: String| LogError::Binary { offset, what };
    let length = file
        .seek(SeekFrom::End(0))
        .map_err(|e| fail(0, format!("cannot seek: {e}")))?;
    let mut window = Vec::new();
    for (declared_start, declared_size) in chunks {
        let within = u64::try_from(declared_start)
            .ok()
            .zip(u64::try_from(declared_size).ok())
            .and_then(|(start, size)| Some((start, start.checked_add(size)?)))
            .filter(|(_, end)| *end <= length);
        let Some((start, end)) = within else {
            return Err(fail(
                length,
                format!(
                    "a column chunk of {declared_size} bytes at {declared_start}, not within the file's {length}"
                ),
            ));
        };
        let mut at = start;
        while at < end {
            let (header, page) = page_at(file, at, end, &mut window)?;
            at = at
                .checked_add(header)
                .and_then(|a| a.checked_add(page))
                .filter(|next| *next <= end)
                .ok_or_else(|| fail(at, format!("a page of {page} bytes past its column chunk")))?;
        }
    }
    Ok(())
}

/// The page header at `at` (its chunk ends at `end`): its length and its page's.
fn page_at(
    file: &mut File,
    at: u64,
    end: u64,
    window: &mut Vec<u8>,
) -> Result<(u64, u64), LogError> {
    let fail = |offset: u64, what: String| LogError::Binary { offset, what };
    for most in [HEADER_WINDOW, MAX_HEADER_BYTES] {
        let size = most.min(end - at);
        window.resize(usize::try_from(size).unwrap_or(0), 0);
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(window))
            .map_err(|e| fail(at, format!("cannot read a page header: {e}")))?;
        let mut walker = Walker {
            bytes: window,
            at: 0,
        };
        match walker.page_header() {
            Ok((uncompressed, compressed)) => {
                if uncompressed > MAX_PAGE_BYTES {
                    return Err(fail(
                        at,
                        format!("a page of {uncompressed} bytes uncompressed (at most {MAX_PAGE_BYTES})"),
                    ));
                }
                return Ok((walker.at as u64, compressed));
            }
            // The window held less than the chunk has left: whatever it found wanting (the
            // header's end, or bytes for a long statistics string), look again in a larger one.
            Err(_) if size < end - at && most < MAX_HEADER_BYTES => continue,
            Err((offset, what)) => {
                return Err(fail(
                    at + offset as u64,
                    format!("Parquet page header: {what}"),
                ))
            }
        }
    }
    Err(fail(
        at,
        format!("a page header over {MAX_HEADER_BYTES} bytes"),
    ))
}

/// A problem at a footer offset.
type Problem = (usize, String);

/// Thrift compact protocol types.
const STOP: u8 = 0;
const TRUE: u8 = 1;
const FALSE: u8 = 2;
const BYTE: u8 = 3;
const I16: u8 = 4;
const I32: u8 = 5;
const I64: u8 = 6;
const DOUBLE: u8 = 7;
const BINARY: u8 = 8;
const LIST: u8 = 9;
const SET: u8 = 10;
const MAP: u8 = 11;
const STRUCT: u8 = 12;
const UUID: u8 = 13;

struct Walker<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Walker<'_> {
    fn problem(&self, what: impl Into<String>) -> Problem {
        (self.at, what.into())
    }

    fn left(&self) -> usize {
        self.bytes.len().saturating_sub(self.at)
    }

    fn byte(&mut self) -> Result<u8, Problem> {
        let byte = *self
            .bytes
            .get(self.at)
            .ok_or_else(|| self.problem("ends early"))?;
        self.at += 1;
        Ok(byte)
    }

    fn skip_bytes(&mut self, n: usize) -> Result<(), Problem> {
        if n > self.left() {
            return Err(self.problem(format!("{n} bytes declared, {} left", self.left())));
        }
        self.at += n;
        Ok(())
    }

    fn varint(&mut self) -> Result<u64, Problem> {
        let mut value = 0u64;
        for shift in (0..64).step_by(7) {
            let byte = self.byte()?;
            value |= u64::from(byte & 0x7F) << shift;
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(self.problem("a number longer than 10 bytes"))
    }

    fn zigzag(&mut self) -> Result<i64, Problem> {
        let raw = self.varint()?;
        let magnitude = i64::from_ne_bytes((raw >> 1).to_ne_bytes());
        Ok(if raw & 1 == 0 { magnitude } else { !magnitude })
    }

    /// A count that the bytes left must hold at `per` bytes an element at least.
    fn count(&mut self, declared: u64, per: usize, what: &str) -> Result<usize, Problem> {
        let most = self.left() / per.max(1);
        usize::try_from(declared)
            .ok()
            .filter(|n| *n <= most)
            .ok_or_else(|| self.problem(format!("{what} of {declared} elements in {most} bytes")))
    }

    /// A list or set header: its element type and length.
    fn list_header(&mut self) -> Result<(u8, usize), Problem> {
        let header = self.byte()?;
        let element = header & 0x0F;
        let declared = match header >> 4 {
            15 => self.varint()?,
            short => u64::from(short),
        };
        Ok((element, self.count(declared, 1, "a list")?))
    }

    /// A field header: `None` at the struct's end, else the field id and its type.
    fn field(&mut self, last: &mut i64) -> Result<Option<(i64, u8)>, Problem> {
        let header = self.byte()?;
        let kind = header & 0x0F;
        if kind == STOP {
            return Ok(None);
        }
        let id = match header >> 4 {
            0 => self.zigzag()?,
            delta => *last + i64::from(delta),
        };
        *last = id;
        Ok(Some((id, kind)))
    }

    fn skip(&mut self, kind: u8, depth: usize) -> Result<(), Problem> {
        if depth > MAX_DEPTH {
            return Err(self.problem("nested too deep"));
        }
        match kind {
            TRUE | FALSE => Ok(()),
            BYTE => self.skip_bytes(1),
            I16 | I32 | I64 => self.varint().map(|_| ()),
            DOUBLE => self.skip_bytes(8),
            UUID => self.skip_bytes(16),
            BINARY => {
                let n = self.varint()?;
                let n = self.count(n, 1, "a string")?;
                self.skip_bytes(n)
            }
            LIST | SET => {
                let (element, n) = self.list_header()?;
                for _ in 0..n {
                    self.skip_element(element, depth + 1)?;
                }
                Ok(())
            }
            MAP => {
                let declared = self.varint()?;
                let n = self.count(declared, 2, "a map")?;
                if n > 0 {
                    let types = self.byte()?;
                    for _ in 0..n {
                        self.skip_element(types >> 4, depth + 1)?;
                        self.skip_element(types & 0x0F, depth + 1)?;
                    }
                }
                Ok(())
            }
            STRUCT => {
                let mut last = 0;
                // Each field consumes at least a byte: bounded by the footer's length.
                while let Some((_, kind)) = self.field(&mut last)? {
                    self.skip(kind, depth + 1)?;
                }
                Ok(())
            }
            other => Err(self.problem(format!("unknown Thrift type {other}"))),
        }
    }

    /// An element of a list, set or map (a boolean there is a byte of its own).
    fn skip_element(&mut self, kind: u8, depth: usize) -> Result<(), Problem> {
        match kind {
            TRUE | FALSE => self.skip_bytes(1),
            other => self.skip(other, depth),
        }
    }

    /// `FileMetaData`: every count checked, and the schema's children against its elements.
    fn file_metadata(&mut self) -> Result<(), Problem> {
        let mut last = 0;
        while let Some((id, kind)) = self.field(&mut last)? {
            if id == 2 && kind == LIST {
                self.schema()?;
            } else {
                self.skip(kind, 1)?;
            }
        }
        Ok(())
    }

    /// `PageHeader`: every count checked; its uncompressed and compressed sizes (fields 2 and
    /// 3, required).
    fn page_header(&mut self) -> Result<(u64, u64), Problem> {
        let (mut uncompressed, mut compressed) = (None, None);
        let mut last = 0;
        while let Some((id, kind)) = self.field(&mut last)? {
            match (id, kind) {
                (2, I32) => uncompressed = Some(self.zigzag()?),
                (3, I32) => compressed = Some(self.zigzag()?),
                _ => self.skip(kind, 1)?,
            }
        }
        let size = |declared: Option<i64>, what: &str| {
            declared
                .and_then(|n| u64::try_from(n).ok())
                .ok_or_else(|| self.problem(format!("no {what} page size, or a negative one")))
        };
        Ok((
            size(uncompressed, "uncompressed")?,
            size(compressed, "compressed")?,
        ))
    }

    /// The schema: a depth-first list of elements, each declaring how many children follow.
    fn schema(&mut self) -> Result<(), Problem> {
        let (element, n) = self.list_header()?;
        if element != STRUCT {
            return Err(self.problem("the schema is not a list of elements"));
        }
        for index in 0..n {
            let mut last = 0;
            while let Some((id, kind)) = self.field(&mut last)? {
                if id == 5 && kind == I32 {
                    let children = self.zigzag()?;
                    let following = n - index - 1;
                    if usize::try_from(children).map_or(true, |c| c > following) {
                        return Err(self.problem(format!(
                            "schema element {index} declares {children} children, {following} elements follow"
                        )));
                    }
                } else {
                    self.skip(kind, 2)?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn walk(bytes: &[u8]) -> Result<(), Problem> {
        Walker { bytes, at: 0 }.file_metadata()
    }

    /// version 1; schema [root "schema" with `children` children]; num_rows 0; no row groups.
    fn footer(children: &[u8]) -> Vec<u8> {
        let mut f = vec![0x15, 0x02, 0x19, 0x1C, 0x48, 0x06];
        f.extend(b"schema");
        f.push(0x15);
        f.extend(children);
        f.extend([0x00, 0x16, 0x00, 0x19, 0x0C, 0x00]);
        f
    }

    #[test]
    fn a_plain_footer_passes_and_crafted_counts_are_refused_where_they_stand() {
        assert_eq!(walk(&footer(&[0x00])), Ok(()));
        // Two billion children (zigzag varint of 2e9).
        let (at, what) = walk(&footer(&[0x80, 0xD0, 0xAC, 0xF3, 0x0E])).unwrap_err();
        assert!(what.contains("declares 2000000000 children"), "{what}");
        assert_eq!(at, 18);
        // A list declaring 2^31 elements in a few bytes.
        let (_, what) = walk(&[0x19, 0xFC, 0x80, 0x80, 0x80, 0x80, 0x08, 0x00]).unwrap_err();
        assert!(what.contains("a list of 2147483648 elements"), "{what}");
        // Negative children, deep nesting, truncation.
        assert!(walk(&footer(&[0x01])).is_err());
        let deep: Vec<u8> = std::iter::repeat_n(0x1C, 100).collect();
        assert!(walk(&deep).unwrap_err().1.contains("too deep"));
        assert!(walk(&[0x15]).unwrap_err().1.contains("ends early"));
    }

    /// `chunk` as a file's only column chunk, after 4 bytes of magic, its pages checked.
    fn check_chunk(chunk: &[u8], declared: i64) -> Result<(), LogError> {
        let path = std::env::temp_dir().join(format!(
            "bywire-pages-{}-{declared}.bin",
            std::process::id()
        ));
        let mut bytes = b"PAR1".to_vec();
        bytes.extend(chunk);
        std::fs::write(&path, &bytes).unwrap();
        let result = check_pages(&mut File::open(&path).unwrap(), [(4, declared)].into_iter());
        std::fs::remove_file(&path).unwrap();
        result
    }

    #[test]
    fn page_headers_are_walked_page_by_page_and_crafted_ones_refused_where_they_stand() {
        // A data page header: type 0, 4 bytes uncompressed, 4 compressed; then its 4 bytes.
        let page = [0x15, 0x00, 0x15, 0x08, 0x15, 0x08, 0x00, 1, 2, 3, 4];
        let two: Vec<u8> = page.iter().chain(&page).copied().collect();
        assert!(check_chunk(&two, 22).is_ok());
        // The chunk declared a byte longer than its pages, or past the file's end.
        let error = check_chunk(&two, 23).unwrap_err().to_string();
        assert!(error.contains("not within the file"), "{error}");
        let error = check_chunk(&two[..21], 21).unwrap_err().to_string();
        assert!(error.contains("past its column chunk"), "{error}");
        // 1 GiB uncompressed, declared by a header of a few bytes.
        let huge = [
            0x15, 0x00, 0x15, 0x80, 0x80, 0x80, 0x80, 0x08, 0x15, 0x00, 0x00,
        ];
        let error = check_chunk(&huge, 11).unwrap_err().to_string();
        assert!(
            error.contains("1073741824 bytes uncompressed") && error.contains("byte 4"),
            "{error}"
        );
        // A string of 2^31 bytes in a header's field 4.
        let string = [
            0x15, 0x00, 0x15, 0x00, 0x15, 0x00, 0x18, 0x80, 0x80, 0x80, 0x80, 0x08, 0x00,
        ];
        let error = check_chunk(&string, 13).unwrap_err().to_string();
        assert!(error.contains("a string of 2147483648 elements"), "{error}");
        // A header longer than the first window (a 10,000-byte string in it) is read whole.
        let mut long = vec![0x15, 0x00, 0x15, 0x08, 0x15, 0x08, 0x18, 0x90, 0x4E];
        long.extend([7u8; 10_000]);
        long.extend([0x00, 1, 2, 3, 4]);
        assert!(check_chunk(&long, i64::try_from(long.len()).unwrap()).is_ok());
    }
}
