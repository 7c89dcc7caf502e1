//! The log formats, chosen by a file's extension or sniffed from its first bytes, each with a
//! reader of records and a writer.

use std::io::{self, BufRead, Seek, Write};
use std::path::Path;

use crate::asc::{AscReader, AscWriter};
use crate::blf::{BlfReader, BlfWriter};
use crate::candump::{LogError, LogRecord, Reader, Writer};
use crate::mf4::{Mf4Reader, Mf4Writer};
use crate::pcapng::{PcapngReader, PcapngWriter};
use crate::trc::{TrcReader, TrcWriter};

pub use crate::options::{ParquetCompression, ParquetOptions};

/// A log format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// candump's log form, `(1699999999.123456) can0 123#DEADBEEF`.
    Candump,
    /// Vector ASC.
    Asc,
    /// PEAK TRC.
    Trc,
    /// pcapng with SocketCAN frames (Wireshark).
    Pcapng,
    /// Vector BLF.
    Blf,
    /// MCAP of ROS 2 `can_msgs/msg/Frame` (with the `mcap` feature).
    Mcap,
    /// Parquet, the raw frames' table (with the `parquet` feature).
    Parquet,
    /// ASAM MDF 4 bus logging.
    Mf4,
}

/// The records of a log, whatever its format.
pub type Records<'a> = Box<dyn Iterator<Item = Result<LogRecord, LogError>> + 'a>;

impl Format {
    /// Every format, with the names `--format` takes.
    pub const ALL: [(Format, &'static str); 8] = [
        (Format::Candump, "candump"),
        (Format::Asc, "asc"),
        (Format::Trc, "trc"),
        (Format::Pcapng, "pcapng"),
        (Format::Blf, "blf"),
        (Format::Mcap, "mcap"),
        (Format::Parquet, "parquet"),
        (Format::Mf4, "mf4"),
    ];

    /// The format a file name says (`.log`, `.candump`: candump; `.asc`: ASC).
    pub fn from_path(path: &Path) -> Option<Format> {
        let extension = path.extension()?.to_str()?.to_ascii_lowercase();
        match extension.as_str() {
            "log" | "candump" => Some(Format::Candump),
            "asc" => Some(Format::Asc),
            "trc" => Some(Format::Trc),
            "pcapng" | "pcap" => Some(Format::Pcapng),
            "blf" => Some(Format::Blf),
            "mcap" => Some(Format::Mcap),
            "parquet" | "pq" => Some(Format::Parquet),
            "mf4" => Some(Format::Mf4),
            _ => None,
        }
    }

    /// The format by its name (`candump`, `asc`).
    pub fn named(name: &str) -> Option<Format> {
        Format::ALL
            .iter()
            .find(|(_, n)| n.eq_ignore_ascii_case(name))
            .map(|(f, _)| *f)
    }

    /// The format of a log that starts with `start`: ASC's header words, TRC's `;` header or
    /// `N)` lines, else candump.
    pub fn sniff(start: &[u8]) -> Format {
        if start.starts_with(&[0x0A, 0x0D, 0x0D, 0x0A]) {
            return Format::Pcapng;
        }
        if start.starts_with(b"LOGG") {
            return Format::Blf;
        }
        if start.starts_with(b"\x89MCAP") {
            return Format::Mcap;
        }
        if start.starts_with(b"PAR1") {
            return Format::Parquet;
        }
        if start.starts_with(b"MDF     ") || start.starts_with(b"UnFinMF ") {
            return Format::Mf4;
        }
        let text = String::from_utf8_lossy(start.get(..start.len().min(4096)).unwrap_or(&[]));
        let first = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty())
            .unwrap_or("")
            .to_ascii_lowercase();
        let asc = [
            "date ",
            "base ",
            "begin triggerblock",
            "// version",
            "internal events",
            "no internal events",
        ];
        let trc_line = first.split_whitespace().next().is_some_and(|w| {
            w.len() > 1
                && w.ends_with(')')
                && w.trim_end_matches(')').bytes().all(|b| b.is_ascii_digit())
        });
        if asc.iter().any(|word| first.starts_with(word)) {
            Format::Asc
        } else if first.starts_with(';') || trc_line {
            Format::Trc
        } else {
            Format::Candump
        }
    }

    /// The format of `input`, sniffed from what it has buffered (nothing is consumed).
    pub fn sniff_input(input: &mut impl BufRead) -> io::Result<Format> {
        Ok(Format::sniff(input.fill_buf()?))
    }

    /// A reader of this format's records over `input`.
    pub fn reader<'a, R: BufRead + 'a>(self, input: R) -> Records<'a> {
        match self {
            Format::Candump => Box::new(Reader::new(input)),
            Format::Asc => Box::new(AscReader::new(input)),
            Format::Trc => Box::new(TrcReader::new(input)),
            Format::Pcapng => Box::new(PcapngReader::new(input)),
            Format::Blf => Box::new(BlfReader::new(input)),
            #[cfg(feature = "mcap")]
            Format::Mcap => Box::new(crate::mcap::McapReader::new(input)),
            #[cfg(not(feature = "mcap"))]
            Format::Mcap => Box::new(std::iter::once(Err(LogError::Binary {
                offset: 0,
                what: "an MCAP file: this build has no MCAP support (the mcap feature)".into(),
            }))),
            Format::Parquet => Box::new(std::iter::once(Err(LogError::Binary {
                offset: 0,
                what: "a Parquet file can only be read from a file (its index is at its end), \
                       not from a stream such as standard input"
                    .into(),
            }))),
            Format::Mf4 => Box::new(std::iter::once(Err(LogError::Binary {
                offset: 0,
                what: "an MF4 file can only be read from a file (its blocks link by offset), \
                       not from a stream such as standard input"
                    .into(),
            }))),
        }
    }

    /// A reader of this format's records in `file`: as [`Format::reader`], and Parquet and
    /// MF4 too.
    pub fn file_reader(self, file: std::fs::File) -> Records<'static> {
        match self {
            Format::Mf4 => match Mf4Reader::open(io::BufReader::new(file)) {
                Ok(reader) => Box::new(reader),
                Err(e) => Box::new(std::iter::once(Err(e))),
            },
            #[cfg(feature = "parquet")]
            Format::Parquet => match crate::parquet::ParquetReader::open(file) {
                Ok(reader) => Box::new(reader),
                Err(e) => Box::new(std::iter::once(Err(e))),
            },
            #[cfg(not(feature = "parquet"))]
            Format::Parquet => Box::new(std::iter::once(Err(LogError::Binary {
                offset: 0,
                what: "a Parquet file: this build has no Parquet support (the parquet feature)"
                    .into(),
            }))),
            other => other.reader(io::BufReader::new(file)),
        }
    }

    /// Whether this is a binary format (recognised by its first bytes, never read as text).
    pub fn is_binary(self) -> bool {
        !matches!(self, Format::Candump | Format::Asc | Format::Trc)
    }

    /// The format of a log that starts with `start` and was named `claimed` by its file's
    /// extension: sniffed from the bytes (a `.log` may be ASC), except that bytes that look
    /// like no binary format in a file named for one are taken as that format, so its reader
    /// says what is wrong with them (a broken `.mf4` is not read as candump text).
    pub fn sniff_claimed(start: &[u8], claimed: Option<Format>) -> Format {
        match (Format::sniff(start), claimed) {
            (Format::Candump, Some(binary)) if binary.is_binary() => binary,
            (sniffed, _) => sniffed,
        }
    }

    /// The records of the log file at `path`, as [`open_log`] opens it.
    pub fn open_file(path: &Path) -> io::Result<(Format, Records<'static>)> {
        let mut log = open_log(path)?;
        let format = Format::sniff_claimed(log.bytes.fill_buf()?, log.claimed);
        let records = match (format, log.file) {
            (Format::Parquet | Format::Mf4, Some(file)) => format.file_reader(file),
            (other, _) => other.reader(log.bytes),
        };
        Ok((format, records))
    }

    /// The records of the lines that start in the byte range `start..end` of the candump log
    /// at `path`: one worker's share of a big log split among several (see
    /// [`crate::lines::LineRange`]; line numbers in errors count from the range's first line).
    /// Other formats cannot be split by bytes and are an error.
    pub fn open_file_range(path: &Path, start: u64, end: u64) -> io::Result<Records<'static>> {
        let file = std::fs::File::open(path)?;
        let mut bytes = io::BufReader::new(file);
        let format = Format::sniff_input(&mut bytes)?;
        if format != Format::Candump {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("a {format:?} log cannot be read in byte ranges (candump logs can)"),
            ));
        }
        let range = crate::lines::LineRange::new(bytes, start, end)?;
        Ok(Format::Candump.reader(io::BufReader::new(range)))
    }

    /// Whether a file of this format cut short after [`RecordWriter::checkpoint`] still reads
    /// up to it: every format but Parquet, whose footer is written last.
    pub fn survives_a_cut(self) -> bool {
        self != Format::Parquet
    }

    /// A writer of this format to `output` (seekable: BLF completes its header at the end).
    pub fn writer<W: Write + Seek + Send>(self, output: W) -> io::Result<RecordWriter<W>> {
        self.writer_with(output, ParquetCompression::default())
    }

    /// As [`Format::writer`], Parquet written as `parquet` says (a [`ParquetCompression`]
    /// alone will do; other formats ignore it).
    pub fn writer_with<W: Write + Seek + Send>(
        self,
        output: W,
        parquet: impl Into<ParquetOptions>,
    ) -> io::Result<RecordWriter<W>> {
        #[cfg_attr(not(feature = "parquet"), allow(unused_variables))]
        let parquet = parquet.into();
        Ok(match self {
            Format::Candump => RecordWriter::Candump(Writer::new(output)),
            Format::Asc => RecordWriter::Asc(AscWriter::new(output)),
            Format::Trc => RecordWriter::Trc(TrcWriter::new(output)),
            Format::Pcapng => RecordWriter::Pcapng(PcapngWriter::new(output)),
            Format::Blf => RecordWriter::Blf(BlfWriter::new(output)?),
            Format::Mf4 => RecordWriter::Mf4(Mf4Writer::new(output)?),
            #[cfg(feature = "mcap")]
            Format::Mcap => RecordWriter::Mcap(crate::mcap::McapWriter::new(output)?),
            #[cfg(not(feature = "mcap"))]
            Format::Mcap => {
                return Err(io::Error::other(
                    "this build has no MCAP support (the mcap feature)",
                ))
            }
            #[cfg(feature = "parquet")]
            Format::Parquet => RecordWriter::Parquet(crate::parquet::ParquetWriter::with_options(
                output, parquet,
            )?),
            #[cfg(not(feature = "parquet"))]
            Format::Parquet => {
                return Err(io::Error::other(
                    "this build has no Parquet support (the parquet feature)",
                ))
            }
        })
    }
}

/// A log file opened for reading.
pub struct OpenedLog {
    /// Its bytes (decompressed, for a `.gz`).
    pub bytes: Box<dyn BufRead + Send>,
    /// The file itself, where its bytes are the file's (MF4 and Parquet are read by seeking).
    pub file: Option<std::fs::File>,
    /// The format its name claims (for a `.gz`, the name without it).
    pub claimed: Option<Format>,
}

/// Bytes read from a log at a time: eight times fewer system calls than the default 8 KiB
/// (a few per cent of reading a big candump log), still well within the cache.
pub const READ_BUFFER: usize = 64 << 10;

/// Open the log at `path`: a name ending in `.gz` is read through gzip (as python-can's
/// `LogReader` reads `FILE.asc.gz`), its format claimed by the name without it; a rosbag2
/// folder (with the `mcap` feature) is read as its MCAP file.
pub fn open_log(path: &Path) -> io::Result<OpenedLog> {
    // A rosbag2 folder: its MCAP file.
    #[cfg(feature = "mcap")]
    if path.is_dir() && path.join(crate::rosbag2::METADATA).is_file() {
        let mcap = crate::rosbag2::mcap_file(path).map_err(io::Error::other)?;
        let file = std::fs::File::open(&mcap)?;
        return Ok(OpenedLog {
            bytes: Box::new(io::BufReader::with_capacity(READ_BUFFER, file.try_clone()?)),
            file: Some(file),
            claimed: Some(Format::Mcap),
        });
    }
    let file = std::fs::File::open(path)?;
    let gzipped = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    if gzipped {
        let inner = Path::new(path.file_stem().unwrap_or_default());
        return Ok(OpenedLog {
            bytes: Box::new(io::BufReader::with_capacity(
                READ_BUFFER,
                flate2::read::MultiGzDecoder::new(file),
            )),
            file: None,
            claimed: Format::from_path(inner),
        });
    }
    Ok(OpenedLog {
        bytes: Box::new(io::BufReader::with_capacity(READ_BUFFER, file.try_clone()?)),
        file: Some(file),
        claimed: Format::from_path(path),
    })
}

/// Writes records in one of the formats (one writer a file: the variants' sizes do not matter).
#[allow(clippy::large_enum_variant)]
pub enum RecordWriter<W: Write + Seek + Send> {
    /// candump's log form (as `candump -L`: no direction).
    Candump(Writer<W>),
    /// Vector ASC.
    Asc(AscWriter<W>),
    /// PEAK TRC 2.1.
    Trc(TrcWriter<W>),
    /// pcapng.
    Pcapng(PcapngWriter<W>),
    /// Vector BLF.
    Blf(BlfWriter<W>),
    /// ASAM MDF 4.
    Mf4(Mf4Writer<W>),
    /// MCAP.
    #[cfg(feature = "mcap")]
    Mcap(crate::mcap::McapWriter<W>),
    /// Parquet's raw frames' table.
    #[cfg(feature = "parquet")]
    Parquet(crate::parquet::ParquetWriter<W>),
}

impl<W: Write + Seek + Send> RecordWriter<W> {
    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        match self {
            RecordWriter::Candump(w) => w.write(record.timestamp, &record.interface, &record.frame),
            RecordWriter::Asc(w) => w.write(record),
            RecordWriter::Trc(w) => w.write(record),
            RecordWriter::Pcapng(w) => w.write(record),
            RecordWriter::Blf(w) => w.write(record),
            RecordWriter::Mf4(w) => w.write(record),
            #[cfg(feature = "mcap")]
            RecordWriter::Mcap(w) => w.write(record),
            #[cfg(feature = "parquet")]
            RecordWriter::Parquet(w) => w.write(record),
        }
    }

    /// Frames the format cannot hold, left out so far (CAN FD in MCAP's `can_msgs/msg/Frame`).
    pub fn left_out(&self) -> u64 {
        match self {
            #[cfg(feature = "mcap")]
            RecordWriter::Mcap(w) => w.left_out(),
            _ => 0,
        }
    }

    /// Make what was written so far survive the writer's end: everything buffered goes out,
    /// and a format with closing structures (BLF's header, MF4's groups) is made complete as
    /// it stands, so a file cut short after this (a kill, a power loss, once the caller has
    /// synced it) reads up to here. Parquet cannot be: its footer comes only at
    /// [`RecordWriter::finish`] (see [`Format::survives_a_cut`]); its rows so far are written.
    pub fn checkpoint(&mut self) -> io::Result<()> {
        match self {
            RecordWriter::Candump(w) => w.flush(),
            RecordWriter::Asc(w) => w.flush(),
            RecordWriter::Trc(w) => w.flush(),
            RecordWriter::Pcapng(w) => w.flush(),
            RecordWriter::Blf(w) => w.checkpoint(),
            RecordWriter::Mf4(w) => w.checkpoint(),
            #[cfg(feature = "mcap")]
            RecordWriter::Mcap(w) => w.flush(),
            #[cfg(feature = "parquet")]
            RecordWriter::Parquet(w) => w.flush(),
        }
    }

    /// Finish the file (a format's closing lines) and flush; the output back.
    pub fn finish(self) -> io::Result<W> {
        match self {
            RecordWriter::Candump(mut w) => {
                w.flush()?;
                Ok(w.into_inner())
            }
            RecordWriter::Asc(w) => w.finish(),
            RecordWriter::Trc(w) => w.finish(),
            RecordWriter::Pcapng(w) => w.finish(),
            RecordWriter::Blf(w) => w.finish(),
            RecordWriter::Mf4(w) => w.finish(),
            #[cfg(feature = "mcap")]
            RecordWriter::Mcap(w) => w.finish(),
            #[cfg(feature = "parquet")]
            RecordWriter::Parquet(w) => w.finish(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_known_by_name_extension_and_content() {
        assert_eq!(
            Format::from_path(Path::new("a/drive.ASC")),
            Some(Format::Asc)
        );
        assert_eq!(
            Format::from_path(Path::new("drive.log")),
            Some(Format::Candump)
        );
        assert_eq!(Format::from_path(Path::new("drive.blf")), Some(Format::Blf));
        assert_eq!(Format::from_path(Path::new("drive.mf4")), Some(Format::Mf4));
        assert_eq!(Format::from_path(Path::new("drive.mdf")), None);
        assert_eq!(Format::sniff(b"MDF     4.10    "), Format::Mf4);
        assert_eq!(Format::sniff(b"UnFinMF 4.10    "), Format::Mf4);
        assert_eq!(Format::sniff(b"LOGG\x90\0\0\0"), Format::Blf);
        assert_eq!(Format::named("asc"), Some(Format::Asc));
        assert_eq!(
            Format::sniff(b"\n date Tue Nov 14 22:13:20 2023\n"),
            Format::Asc
        );
        assert_eq!(Format::sniff(b"(1.000000) can0 123#\n"), Format::Candump);
        assert_eq!(Format::sniff(b";$FILEVERSION=2.1\n"), Format::Trc);
        assert_eq!(Format::sniff(b"   1)      1059 0300 8 00\n"), Format::Trc);
        assert_eq!(Format::from_path(Path::new("pcan.trc")), Some(Format::Trc));
        assert_eq!(
            Format::sniff(&[0x0A, 0x0D, 0x0D, 0x0A, 0, 0]),
            Format::Pcapng
        );
        assert_eq!(Format::sniff(b""), Format::Candump);
    }

    fn numbered(i: u64) -> LogRecord {
        use bywire_core::frame::ClassicFrame;
        use bywire_core::{Id, Timestamp};
        LogRecord {
            timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 1_000_000),
            interface: format!("can{}", i % 2),
            frame: bywire_core::Frame::Classic(
                ClassicFrame::new(Id::standard(0x100).unwrap(), &i.to_le_bytes()).unwrap(),
            ),
            direction: Some('R'),
        }
    }

    /// The records a (possibly cut) file reads until its first error.
    fn readable(format: Format, bytes: Vec<u8>) -> Vec<LogRecord> {
        let dir = std::env::temp_dir().join(format!(
            "bywire-cut-{}-{format:?}-{}",
            std::process::id(),
            bytes.len()
        ));
        std::fs::write(&dir, &bytes).unwrap();
        let (_, records) = Format::open_file(&dir).unwrap();
        let read = records.map_while(Result::ok).collect();
        std::fs::remove_file(&dir).unwrap();
        read
    }

    /// A file in memory both the writer and the test see.
    #[derive(Clone, Default)]
    struct Shared(std::sync::Arc<std::sync::Mutex<io::Cursor<Vec<u8>>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().write(buf)
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Seek for Shared {
        fn seek(&mut self, to: io::SeekFrom) -> io::Result<u64> {
            self.0.lock().unwrap().seek(to)
        }
    }

    impl Shared {
        fn bytes(&self) -> Vec<u8> {
            self.0.lock().unwrap().get_ref().clone()
        }
    }

    #[test]
    fn a_file_cut_anywhere_after_a_checkpoint_reads_up_to_it() {
        for (format, _) in Format::ALL {
            if !format.survives_a_cut() || (format == Format::Mcap && !cfg!(feature = "mcap")) {
                continue;
            }
            let file = Shared::default();
            let mut writer = format.writer(file.clone()).unwrap();
            for i in 0..300 {
                writer.write(&numbered(i)).unwrap();
            }
            writer.checkpoint().unwrap();
            let checkpointed = file.bytes().len();
            // Enough more to fill BLF's containers, MF4's data blocks and a 1 MiB MCAP chunk, never
            // checkpointed.
            for i in 300..20_000 {
                writer.write(&numbered(i)).unwrap();
            }
            let written = file.bytes();
            assert!(written.len() > checkpointed, "{format:?}");
            let middle = (checkpointed + written.len()) / 2;
            for cut in [checkpointed, checkpointed + 1, middle, written.len()] {
                let read = readable(format, written[..cut].to_vec());
                assert!(
                    read.len() >= 300,
                    "{format:?} cut at {cut} of {}: {} records",
                    written.len(),
                    read.len()
                );
                for (i, record) in read.iter().enumerate() {
                    assert_eq!(
                        record.frame,
                        numbered(i as u64).frame,
                        "{format:?} record {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_log_converts_through_both_writers() {
        let candump =
            "(1700000000.100000) can0 123#DEADBEEF\n(1700000000.200000) can1 1ABCDEF0#R\n";
        let mut asc = Format::Asc.writer(io::Cursor::new(Vec::new())).unwrap();
        for record in Format::Candump.reader(candump.as_bytes()) {
            asc.write(&record.unwrap()).unwrap();
        }
        let asc = asc.finish().unwrap().into_inner();
        assert_eq!(Format::sniff(&asc), Format::Asc);
        let mut back = Format::Candump.writer(io::Cursor::new(Vec::new())).unwrap();
        for record in Format::Asc.reader(asc.as_slice()) {
            back.write(&record.unwrap()).unwrap();
        }
        assert_eq!(
            String::from_utf8(back.finish().unwrap().into_inner()).unwrap(),
            candump
        );
    }
}
