//! Property tests: no input makes the readers panic, and every frame written is read back equal.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::{ClassicFrame, Dlc, ErrorFrame, FdFrame, Frame, Id, Timestamp};
use bywire_log::format::Format;
use bywire_log::screen::{self, FrameView, View};
use bywire_log::{Precision, Reader, Writer};
use proptest::prelude::*;

fn any_frame() -> impl Strategy<Value = Frame> {
    let id = prop_oneof![
        (0u32..=0x7FF).prop_map(|r| Id::standard(r).unwrap()),
        (0u32..=0x1FFF_FFFF).prop_map(|r| Id::extended(r).unwrap()),
    ];
    let data = proptest::collection::vec(any::<u8>(), 0..=64);
    (id, data, 0u8..6, any::<bool>(), any::<bool>(), 0u8..=15).prop_map(
        |(id, data, kind, brs, esi, raw_dlc)| match kind {
            0 | 1 => Frame::Classic(ClassicFrame::new(id, &data[..data.len().min(8)]).unwrap()),
            2 => Frame::Classic(ClassicFrame::remote(
                id,
                Dlc::from_classic_len(data.len() % 9).unwrap(),
            )),
            3 => {
                let dlc = Dlc::new(raw_dlc.max(9)).unwrap();
                let bytes = [data.first().copied().unwrap_or(0); 8];
                Frame::Classic(ClassicFrame::with_dlc(id, dlc, &bytes).unwrap())
            }
            4 => Frame::Fd(FdFrame::padded(id, &data, brs, esi).unwrap()),
            _ => {
                let mut bytes = [0u8; 8];
                for (b, d) in bytes.iter_mut().zip(&data) {
                    *b = *d;
                }
                let class = (id.as_raw() & 0x1FF).max(1);
                Frame::Error(ErrorFrame::new(class, &bytes).unwrap())
            }
        },
    )
}

/// Records of (frame, ns after a base time, interface number, sent).
fn records_of(frames: &[(Frame, u64, u8, bool)]) -> Vec<bywire_log::LogRecord> {
    let base = 1_700_000_000_000_000_000u64;
    frames
        .iter()
        .map(|(frame, offset, channel, tx)| bywire_log::LogRecord {
            timestamp: Timestamp::from_nanos(base + offset),
            interface: format!("can{channel}"),
            frame: *frame,
            direction: Some(if *tx { 'T' } else { 'R' }),
        })
        .collect()
}

proptest! {
    #[test]
    fn any_text_is_a_record_or_an_error(text in "\\PC{0,80}") {
        let _ = bywire_log::candump::parse_line(&text);
        let _ = screen::parse_line(&text);
        let _ = Reader::new(text.as_bytes()).count();
    }

    #[test]
    fn near_miss_lines_never_panic(
        secs in "[0-9]{0,22}", frac in "[0-9]{0,11}", iface in "[a-z0-9]{0,5}",
        frame in "[0-9A-FR#._]{0,30}", tail in "( [A-Z])?"
    ) {
        let line = format!("({secs}.{frac}) {iface} {frame}{tail}");
        let _ = bywire_log::candump::parse_line(&line);
        let _ = screen::parse_line(&format!(" {iface}  {frame}"));
    }

    #[test]
    fn written_logs_read_back(
        frames in proptest::collection::vec((any_frame(), any::<u64>()), 0..20),
        nanos in any::<bool>()
    ) {
        let precision = if nanos { Precision::Nanos } else { Precision::Micros };
        let mut writer = Writer::new(Vec::new()).raw_dlc(true).precision(precision);
        for (frame, ts) in &frames {
            writer.write(Timestamp::from_nanos(*ts), "can0", frame).unwrap();
        }
        let bytes = writer.into_inner();
        let read: Vec<_> = Reader::new(&bytes[..]).collect::<Result<_, _>>().unwrap();
        prop_assert_eq!(read.len(), frames.len());
        for (record, (frame, ts)) in read.iter().zip(&frames) {
            prop_assert_eq!(&record.frame, frame);
            let expected = if nanos { *ts } else { ts - ts % 1000 };
            prop_assert_eq!(record.timestamp.as_nanos(), expected);
            prop_assert_eq!(record.interface.as_str(), "can0");
        }
    }

    #[test]
    fn asc_text_of_any_shape_never_panics(
        lines in proptest::collection::vec(
            prop_oneof![
                "\\PC{0,60}",
                "(date|base|Begin Triggerblock) [A-Za-z0-9 :.]{0,30}",
                " {0,3}[0-9]{1,3}\\.[0-9]{0,7} (CANFD|[0-9]{1,2}) [0-9A-Fx]{0,9} (Rx|Tx|[a-z]{0,3}) [dr0-9 ]{0,4}[0-9A-F ]{0,40}",
            ],
            0..12,
        )
    ) {
        let text = lines.join("\n");
        let _ = bywire_log::asc::AscReader::new(text.as_bytes()).count();
    }

    #[test]
    fn trc_text_of_any_shape_never_panics(
        lines in proptest::collection::vec(
            prop_oneof![
                "\\PC{0,60}",
                ";\\$(FILEVERSION|STARTTIME|COLUMNS)=[0-9A-Za-z.,]{0,20}",
                " {0,6}[0-9]{1,4}\\)? {1,4}[0-9]{1,6}\\.?[0-9]{0,4} (DT|FD|FB|RR|ER|Rx|Tx|[0-9]) [0-9A-F]{0,9} (Rx|Tx|-) [0-9 -]{0,5}[0-9A-F ]{0,40}",
            ],
            0..12,
        )
    ) {
        let text = lines.join("\n");
        let _ = bywire_log::trc::TrcReader::new(text.as_bytes()).count();
    }

    #[test]
    fn pcapng_bytes_of_any_shape_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8)
    ) {
        let _ = bywire_log::pcapng::PcapngReader::new(bytes.as_slice()).count();
        // A valid capture with bytes changed here and there: an error or records, never a panic.
        let mut writer = bywire_log::pcapng::PcapngWriter::new(Vec::new());
        for (i, frame) in ["123#DEADBEEF", "1ABCDEF0#R", "7FF##311223344556677889900AABB"].iter().enumerate() {
            writer.write(&bywire_log::LogRecord {
                timestamp: Timestamp::from_nanos(u64::try_from(i).unwrap()),
                interface: "can0".into(),
                frame: frame.parse().unwrap(),
                direction: Some('R'),
            }).unwrap();
        }
        let mut capture = writer.finish().unwrap();
        for (at, byte) in flips {
            let index = at.index(capture.len());
            capture[index] = byte;
        }
        let _ = bywire_log::pcapng::PcapngReader::new(capture.as_slice()).count();
    }

    #[test]
    fn blf_bytes_of_any_shape_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8)
    ) {
        let mut with_magic = b"LOGG".to_vec();
        with_magic.extend_from_slice(&bytes);
        let _ = bywire_log::blf::BlfReader::new(with_magic.as_slice()).count();
        let mut writer = bywire_log::blf::BlfWriter::new(std::io::Cursor::new(Vec::new())).unwrap();
        for (i, frame) in ["123#DEADBEEF", "1ABCDEF0#R", "7FF##311223344556677889900AABB"].iter().enumerate() {
            writer.write(&bywire_log::LogRecord {
                timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + u64::try_from(i).unwrap()),
                interface: "can0".into(),
                frame: frame.parse().unwrap(),
                direction: Some('R'),
            }).unwrap();
        }
        let mut file = writer.finish().unwrap().into_inner();
        for (at, byte) in flips {
            let index = at.index(file.len());
            file[index] = byte;
        }
        let _ = bywire_log::blf::BlfReader::new(file.as_slice()).count();
    }

    #[test]
    fn every_format_reads_back_what_it_wrote(
        frames in proptest::collection::vec((any_frame(), 0u64..1_000_000_000_000, 0u8..4, any::<bool>()), 0..20)
    ) {
        let mut records = records_of(&frames);
        records.sort_by_key(|r| r.timestamp);
        // (format, the time resolution it keeps in ns, whether it keeps an error frame's class)
        for (format, resolution, error_classes) in [
            (Format::Asc, 1_000, false),
            (Format::Trc, 1_000, false),
            (Format::Blf, 1, false),
            (Format::Pcapng, 1, true),
        ] {
            let mut writer = format.writer(std::io::Cursor::new(Vec::new())).unwrap();
            for record in &records {
                writer.write(record).unwrap();
            }
            let bytes = writer.finish().unwrap().into_inner();
            let read: Vec<_> = format.reader(&bytes[..]).collect::<Result<_, _>>().unwrap();
            prop_assert_eq!(read.len(), records.len(), "{:?}", format);
            for (back, record) in read.iter().zip(&records) {
                let ts = record.timestamp.as_nanos();
                prop_assert_eq!(back.timestamp.as_nanos(), ts - ts % resolution, "{:?}", format);
                prop_assert_eq!(&back.interface, &record.interface, "{:?}", format);
                match (&back.frame, &record.frame) {
                    // Only pcapng keeps SocketCAN's error classes: the others read a bus error.
                    (Frame::Error(_), Frame::Error(_)) if !error_classes => {}
                    (b, r) => prop_assert_eq!(b, r, "{:?}", format),
                }
                if !record.frame.is_error() {
                    prop_assert_eq!(back.direction, record.direction, "{:?}", format);
                }
            }
        }
    }

    #[test]
    fn mf4_reads_back_every_frame_exactly(
        frames in proptest::collection::vec((any_frame(), 0u64..1_000_000_000_000, 0u8..4, any::<bool>()), 0..40)
    ) {
        let mut records = records_of(&frames);
        // Frames of one kind keep their order; kinds are merged by time (ties: any order).
        records.sort_by_key(|r| r.timestamp);
        records.dedup_by_key(|r| r.timestamp);
        let mut writer = bywire_log::mf4::Mf4Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
        for record in &records {
            writer.write(record).unwrap();
        }
        let bytes = writer.finish().unwrap().into_inner();
        let read: Vec<_> = bywire_log::mf4::Mf4Reader::open(std::io::Cursor::new(bytes.as_slice()))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        prop_assert_eq!(read, records);
    }

    #[test]
    fn screen_lines_read_back(frame in any_frame()) {
        // The screen form has no FD flags or raw DLC; compare what it shows.
        let line = format!("  can0  {}", FrameView { frame: &frame, view: View::default() });
        let back = screen::parse_line(&line).unwrap();
        prop_assert_eq!(back.id(), frame.id());
        prop_assert_eq!(back.is_remote(), frame.is_remote());
        prop_assert_eq!(back.is_fd(), frame.is_fd());
        if !frame.is_remote() {
            prop_assert_eq!(back.data(), frame.data());
        }
    }
}

#[cfg(feature = "parquet")]
mod parquet_files {
    use super::*;
    use bywire_log::format::ParquetCompression;
    use std::io::Write as _;

    /// A file of its own for each case (the reader needs a file: Parquet's index is at its end).
    fn scratch(name: &str) -> std::path::PathBuf {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        std::env::temp_dir().join(format!(
            "bywire-log-{}-{name}-{n}.parquet",
            std::process::id()
        ))
    }

    fn read(path: &std::path::Path) -> Vec<Result<bywire_log::LogRecord, bywire_log::LogError>> {
        Format::Parquet
            .file_reader(std::fs::File::open(path).unwrap())
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn parquet_reads_back_every_frame_exactly(
            frames in proptest::collection::vec((any_frame(), any::<u64>(), 0u8..4, 0u8..3), 0..40),
            compression in prop::sample::select(vec![
                ParquetCompression::Zstd,
                ParquetCompression::Snappy,
                ParquetCompression::Uncompressed,
            ]),
        ) {
            let records: Vec<bywire_log::LogRecord> = frames
                .iter()
                .map(|(frame, at, channel, dir)| bywire_log::LogRecord {
                    timestamp: Timestamp::from_nanos(at >> 1),
                    interface: format!("can{channel}"),
                    frame: *frame,
                    direction: [None, Some('R'), Some('T')][usize::from(*dir)],
                })
                .collect();
            let path = scratch("roundtrip");
            let file = std::fs::File::create(&path).unwrap();
            let mut writer = Format::Parquet.writer_with(file, compression).unwrap();
            for record in &records {
                writer.write(record).unwrap();
            }
            writer.finish().unwrap();
            let back: Vec<_> = read(&path).into_iter().collect::<Result<_, _>>().unwrap();
            std::fs::remove_file(&path).unwrap();
            prop_assert_eq!(back, records);
        }

        #[test]
        fn parquet_bytes_of_any_shape_never_panic(
            cut in any::<prop::sample::Index>(),
            flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        ) {
            // A valid file, cut short and with bytes changed: an error or records, never a panic.
            let path = scratch("corrupt");
            let mut writer = Format::Parquet.writer(std::fs::File::create(&path).unwrap()).unwrap();
            for n in 0..50u32 {
                let frame = Frame::Classic(ClassicFrame::new(Id::standard(n).unwrap(), &n.to_le_bytes()).unwrap());
                writer.write(&bywire_log::LogRecord {
                    timestamp: Timestamp::from_nanos(u64::from(n)),
                    interface: "can0".into(),
                    frame,
                    direction: None,
                }).unwrap();
            }
            writer.finish().unwrap();
            let mut bytes = std::fs::read(&path).unwrap();
            for (at, value) in &flips {
                let i = at.index(bytes.len());
                bytes[i] ^= value | 1;
            }
            bytes.truncate(cut.index(bytes.len() + 1).max(1));
            std::fs::File::create(&path).unwrap().write_all(&bytes).unwrap();
            let _ = read(&path);
            std::fs::remove_file(&path).unwrap();
        }
    }
}

/// A Parquet footer declaring two billion schema children in a few bytes (what fuzzing found
/// makes the parquet crate reserve gigabytes) is refused before the crate reads it, with the
/// byte offset.
#[cfg(feature = "parquet")]
#[test]
fn a_parquet_footer_declaring_more_than_it_holds_is_refused_with_its_offset() {
    let mut footer = vec![0x15, 0x02, 0x19, 0x1C, 0x48, 0x06];
    footer.extend(b"schema");
    footer.extend([
        0x15, 0x80, 0xD0, 0xAC, 0xF3, 0x0E, 0x00, 0x16, 0x00, 0x19, 0x0C, 0x00,
    ]);
    let mut bytes = b"PAR1".to_vec();
    bytes.extend(&footer);
    bytes.extend(u32::try_from(footer.len()).unwrap().to_le_bytes());
    bytes.extend(b"PAR1");
    let path = std::env::temp_dir().join(format!("bywire-footer-{}.parquet", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let first = bywire_log::format::Format::Parquet
        .file_reader(std::fs::File::open(&path).unwrap())
        .next();
    std::fs::remove_file(&path).unwrap();
    let error = first.unwrap().unwrap_err().to_string();
    assert!(error.contains("declares 2000000000 children"), "{error}");
    assert!(
        error.contains("offset 22") || error.contains("byte 22"),
        "{error}"
    );
}

/// A raw frames file holds its times as deltas (no dictionary page), the rest as before.
#[cfg(feature = "parquet")]
#[test]
fn raw_parquet_times_are_delta_encoded() {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let path =
        std::env::temp_dir().join(format!("bywire-raw-delta-{}.parquet", std::process::id()));
    let file = std::fs::File::create(&path).unwrap();
    let mut writer = Format::Parquet
        .writer_with(file, bywire_log::format::ParquetCompression::Zstd)
        .unwrap();
    for i in 0..1000u64 {
        let id = bywire_core::Id::standard(u32::try_from(i % 7).unwrap()).unwrap();
        writer
            .write(&bywire_log::LogRecord {
                timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 250_000),
                interface: "can0".into(),
                frame: bywire_core::Frame::classic(id, &[1, 2]).unwrap(),
                direction: None,
            })
            .unwrap();
    }
    writer.finish().unwrap();
    let reader = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
    let group = reader.metadata().row_group(0);
    for chunk in group.columns() {
        let name = chunk.column_path().string();
        let delta = chunk
            .encodings()
            .any(|e| e == parquet::basic::Encoding::DELTA_BINARY_PACKED);
        assert_eq!(delta, name == "ts", "{name}");
        if name == "ts" {
            assert!(chunk.dictionary_page_offset().is_none());
        }
    }
    let back: Vec<_> = Format::Parquet
        .file_reader(std::fs::File::open(&path).unwrap())
        .collect::<Result<_, _>>()
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(back.len(), 1000);
    assert_eq!(
        back[999].timestamp,
        Timestamp::from_nanos(1_700_000_000_000_000_000 + 999 * 250_000)
    );
}

/// Raw frames written with their times in microseconds: the column is typed so (what Spark
/// reads as times) and each time is floored, never rounded past the next frame's; read back,
/// the frames are the same.
#[cfg(feature = "parquet")]
#[test]
fn raw_parquet_times_in_microseconds_are_floored() {
    use bywire_log::format::{ParquetCompression, ParquetOptions};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let path = std::env::temp_dir().join(format!("bywire-raw-us-{}.parquet", std::process::id()));
    let options = ParquetOptions {
        compression: ParquetCompression::Snappy,
        times: bywire_log::Precision::Micros,
    };
    let mut writer = Format::Parquet
        .writer_with(std::fs::File::create(&path).unwrap(), options)
        .unwrap();
    // 999 ns apart: every other pair shares a microsecond once floored.
    let nanos: Vec<u64> = (0..20_000u64)
        .map(|i| 1_700_000_000_000_000_000 + i * 999)
        .collect();
    let frame =
        bywire_core::Frame::classic(bywire_core::Id::standard(0x123).unwrap(), &[7]).unwrap();
    for t in &nanos {
        let record = bywire_log::LogRecord {
            timestamp: Timestamp::from_nanos(*t),
            interface: "can1".into(),
            frame,
            direction: Some('T'),
        };
        writer.write(&record).unwrap();
    }
    writer.finish().unwrap();
    let builder =
        ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(&path).unwrap()).unwrap();
    assert_eq!(
        builder.schema().field(0).data_type(),
        &arrow_schema::DataType::Timestamp(arrow_schema::TimeUnit::Microsecond, Some("UTC".into()))
    );
    let back: Vec<_> = Format::Parquet
        .file_reader(std::fs::File::open(&path).unwrap())
        .collect::<Result<_, _>>()
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(back.len(), nanos.len());
    for (record, t) in back.iter().zip(&nanos) {
        assert_eq!(record.timestamp, Timestamp::from_nanos(t / 1000 * 1000));
        assert_eq!((record.frame, record.direction), (frame, Some('T')));
        assert_eq!(record.interface, "can1");
    }
}

/// A delta-encoded page whose header holds an over-long varint (parquet-rs asserts there,
/// found by the `parquet_reader` fuzz target) is an error naming the row, not a panic.
#[cfg(feature = "parquet")]
#[test]
fn a_malformed_delta_page_is_an_error_not_a_panic() {
    use bywire_log::format::{ParquetCompression, ParquetOptions};
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let path =
        std::env::temp_dir().join(format!("bywire-bad-delta-{}.parquet", std::process::id()));
    let options = ParquetOptions {
        compression: ParquetCompression::Uncompressed,
        ..ParquetOptions::default()
    };
    let mut writer = Format::Parquet
        .writer_with(std::fs::File::create(&path).unwrap(), options)
        .unwrap();
    for i in 0..6u64 {
        let record = bywire_log::LogRecord {
            timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 1_000),
            interface: "can0".into(),
            frame: bywire_core::Frame::classic(bywire_core::Id::standard(0x10).unwrap(), &[1])
                .unwrap(),
            direction: None,
        };
        writer.write(&record).unwrap();
    }
    writer.finish().unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let reader = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
    let page =
        usize::try_from(reader.metadata().row_group(0).column(0).data_page_offset()).unwrap();
    // The `ts` page's delta header: a block size in two varint bytes (a multiple of 128), 4
    // miniblocks, 6 values; then the first value, made an 11-byte varint (at most 10 are
    // allowed).
    let header = bytes[page..]
        .windows(4)
        .position(|w| w[0] == 0x80 && w[2..] == [0x04, 0x06])
        .unwrap()
        + page;
    bytes[header + 4..header + 15].fill(0xFF);
    std::fs::write(&path, &bytes).unwrap();
    let read: Vec<_> = Format::Parquet
        .file_reader(std::fs::File::open(&path).unwrap())
        .collect();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(read.len(), 1, "{read:?}");
    let error = read[0].as_ref().unwrap_err().to_string();
    assert!(
        error.contains("row 0") && error.contains("malformed page"),
        "{error}"
    );
}

/// The files the `parquet_reader` fuzz target found making parquet-rs or arrow-rs panic, or
/// spin for minutes: each reads to an error naming a row or a byte, at once, and nothing
/// panics through the reader.
#[cfg(feature = "parquet")]
#[test]
fn fuzz_findings_in_parquet_files_are_errors() {
    let folder =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-regressions/parquet");
    let mut files: Vec<_> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(files.len() >= 3, "{files:?}");
    for path in files {
        let read: Vec<_> = Format::Parquet
            .file_reader(std::fs::File::open(&path).unwrap())
            .collect();
        let error = read
            .iter()
            .find_map(|r| r.as_ref().err())
            .unwrap_or_else(|| panic!("{}: read without an error", path.display()))
            .to_string();
        assert!(
            error.contains("row ") || error.contains("byte "),
            "{}: {error}",
            path.display()
        );
        assert!(
            read.last().unwrap().is_err(),
            "{}: read on after the error",
            path.display()
        );
    }
}
