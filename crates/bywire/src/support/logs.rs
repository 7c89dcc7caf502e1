//! Logs as the commands read them (candump or ASC, sniffed from the content): files or
//! standard input, every line checked, and what cannot be read reported on standard error with
//! its file and line.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Seek, SeekFrom, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use bywire_core::Timestamp;
use bywire_data::decoded::{DecodedDataset, Partitioning};
use bywire_dbc::decoder::Decoder;
use bywire_log::format::ParquetCompression;

use crate::support::files::write_dir_atomically;
use crate::support::interrupt::interrupt_flag;
use crate::support::progress::Progress;
use bywire_log::format::{Format, READ_BUFFER};
use bywire_log::{LogError, LogErrorKind, LogRecord, LogRecordRef, Reader};

/// A log to read: its bytes, and the file itself when it is one (Parquet is read by seeking).
pub struct LogInput {
    bytes: Box<dyn BufRead>,
    file: Option<File>,
    /// The format its name claims (a broken `.mf4` is said to be a broken MF4 file).
    claimed: Option<Format>,
}

impl LogInput {
    /// A stream that is not a file (standard input, already opened).
    pub fn stream(bytes: Box<dyn BufRead>) -> LogInput {
        LogInput {
            bytes,
            file: None,
            claimed: None,
        }
    }

    /// Its format, sniffed from its first bytes and its name (an input that cannot even be
    /// peeked at is taken as candump, and fails on its first read, with its name).
    fn format(&mut self) -> Format {
        self.bytes.fill_buf().map_or(Format::Candump, |start| {
            Format::sniff_claimed(start, self.claimed)
        })
    }

    /// A handle on the file that shares its read position (for a progress bar).
    pub fn position_probe(&self) -> Option<File> {
        self.file.as_ref().and_then(|f| f.try_clone().ok())
    }
}

/// The files to read, each with the name its messages use (standard input when none).
pub fn inputs(files: &[PathBuf]) -> Result<Vec<(String, LogInput)>> {
    if files.is_empty() {
        return Ok(vec![input(None)?]);
    }
    files.iter().map(|p| input(Some(p))).collect()
}

/// One file (or standard input) with its name.
pub fn input(path: Option<&Path>) -> Result<(String, LogInput)> {
    match path {
        None => Ok((
            "standard input".into(),
            LogInput {
                bytes: Box::new(BufReader::with_capacity(READ_BUFFER, io::stdin())),
                file: None,
                claimed: None,
            },
        )),
        Some(p) => {
            let log = bywire_log::format::open_log(p)
                .with_context(|| format!("cannot open {}", p.display()))?;
            Ok((
                p.display().to_string(),
                LogInput {
                    bytes: log.bytes,
                    file: log.file,
                    claimed: log.claimed,
                },
            ))
        }
    }
}

/// Which bad lines are skipped (with a warning) rather than ending the read.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Skip {
    /// Lines that cannot be text: too long, not UTF-8. A malformed log line is an error.
    Unreadable,
    /// As `Unreadable`, and in candump logs lines that are not log lines at all are passed
    /// over without a word, as canplayer does.
    NonLogLines,
    /// Every bad line, and lines that are not log lines at all (a plot of what can be read).
    AnyBadLine,
}

/// The records of `input` (called `name` in messages); skipped lines are reported.
pub fn records<'a>(
    name: &'a str,
    mut input: LogInput,
    skip: Skip,
) -> impl Iterator<Item = Result<LogRecord>> + 'a {
    let format = input.format();
    let LogInput { bytes, file, .. } = input;
    let reader = match (format, skip, file) {
        (Format::Candump, Skip::AnyBadLine | Skip::NonLogLines, _) => {
            Box::new(Reader::new(bytes).log_lines_only())
        }
        (Format::Parquet | Format::Mf4, _, Some(file)) => format.file_reader(file),
        (format, _, _) => format.reader(bytes),
    };
    reader.filter_map(move |record| match record {
        Err(e) if skipped(name, &e, skip) => None,
        other => Some(other.map_err(|e| anyhow!("{name}: {e}"))),
    })
}

/// Whether `skip` passes over this error: if so, it is reported on standard error.
fn skipped(name: &str, e: &LogError, skip: Skip) -> bool {
    let skipped = match e {
        LogError::Syntax { .. } if skip == Skip::AnyBadLine => true,
        LogError::Syntax { kind, .. } => {
            matches!(kind, LogErrorKind::TooLong(_) | LogErrorKind::NotUtf8)
        }
        LogError::Unrepresentable { .. } => true,
        // What came before the cut was read whole: the end of the file, with a warning.
        LogError::CutShort { .. } => {
            let _ = writeln!(io::stderr(), "warning: {name}: {e}");
            return true;
        }
        _ => false,
    };
    if skipped {
        let _ = writeln!(io::stderr(), "{name}: {e} (skipped)");
    }
    skipped
}

/// Each record of `input` handed to `each`, lent: a candump log is read without a copy of any
/// line. Bad lines are skipped as [`records`] skips them; any other error, or one from `each`,
/// ends it.
pub fn for_each_lent(
    name: &str,
    mut input: LogInput,
    skip: Skip,
    mut each: impl FnMut(&LogRecordRef<'_>) -> Result<()>,
) -> Result<()> {
    if input.format() != Format::Candump {
        for record in records(name, input, skip) {
            each(&record?.as_record_ref())?;
        }
        return Ok(());
    }
    let LogInput { bytes, file, .. } = input;
    // A file is read again from its start through a reader of its own type, so that each
    // line's reads are inlined rather than called through `dyn`; a pipe that cannot seek is
    // read on from what was peeked at.
    match file.filter(|mut f| f.seek(SeekFrom::Start(0)).is_ok()) {
        Some(file) => lent_candump(
            name,
            BufReader::with_capacity(READ_BUFFER, file),
            skip,
            each,
        ),
        None => lent_candump(name, bytes, skip, each),
    }
}

fn lent_candump(
    name: &str,
    bytes: impl BufRead,
    skip: Skip,
    mut each: impl FnMut(&LogRecordRef<'_>) -> Result<()>,
) -> Result<()> {
    let mut reader = Reader::new(bytes);
    if matches!(skip, Skip::AnyBadLine | Skip::NonLogLines) {
        reader = reader.log_lines_only();
    }
    let failed = reader.for_each_ref(|record| match record {
        Ok(record) => match each(record) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => ControlFlow::Break(e),
        },
        Err(e) if skipped(name, &e, skip) => ControlFlow::Continue(()),
        Err(e) => ControlFlow::Break(anyhow!("{name}: {e}")),
    });
    failed.map_or(Ok(()), Err)
}

/// Every record of `files` (standard input when none), merged in time order, handed to
/// `each`; Ctrl-C ends it with an error (an interrupted analysis keeps nothing).
pub fn for_each_merged(files: &[PathBuf], mut each: impl FnMut(LogRecord)) -> Result<()> {
    let (names, inputs): (Vec<String>, Vec<LogInput>) = inputs(files)?.into_iter().unzip();
    let readers: Vec<_> = names
        .iter()
        .zip(inputs)
        .map(|(name, input)| records(name, input, Skip::Unreadable))
        .collect();
    let stop = interrupt_flag();
    for record in bywire_log::merge::merge(readers) {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(anyhow!("interrupted"));
        }
        each(record?);
    }
    Ok(())
}

/// What a conversion keeps: channels (renamed) and a time range from the first frame.
pub struct Selection {
    /// FROM → TO; empty: every channel as it is.
    channels: BTreeMap<String, String>,
    from: Duration,
    to: Option<Duration>,
}

impl Selection {
    /// Every record, as it is.
    pub fn everything() -> Selection {
        Selection {
            channels: BTreeMap::new(),
            from: Duration::ZERO,
            to: None,
        }
    }

    pub fn new(channels: &[String], from: Option<f64>, to: Option<f64>) -> Result<Selection> {
        let mut map = BTreeMap::new();
        for text in channels {
            let (from, to) = text.split_once('=').unwrap_or((text, text));
            if from.is_empty() || to.is_empty() {
                return Err(anyhow!("--channel '{text}': expected FROM or FROM=TO"));
            }
            map.insert(from.to_string(), to.to_string());
        }
        if let (Some(from), Some(to)) = (from, to) {
            if to < from {
                return Err(anyhow!("--to {to} is before --from {from}"));
            }
        }
        Ok(Selection {
            channels: map,
            from: Duration::from_secs_f64(from.unwrap_or(0.0)),
            to: to.map(Duration::from_secs_f64),
        })
    }

    /// The record as it is written (renamed), or `None` to leave it out.
    fn keep(&self, mut record: LogRecord, since_first: Duration) -> Option<LogRecord> {
        let renamed = self.written_channel(&record.interface, since_first)?;
        if let Some(name) = renamed {
            record.interface = name.to_string();
        }
        Some(record)
    }

    /// [`Selection::keep`] for a lent record.
    fn keep_lent<'a>(
        &'a self,
        record: &LogRecordRef<'a>,
        since_first: Duration,
    ) -> Option<LogRecordRef<'a>> {
        let renamed = self.written_channel(record.interface, since_first)?;
        Some(LogRecordRef {
            interface: renamed.unwrap_or(record.interface),
            ..*record
        })
    }

    /// Whether a record on `interface` this long after the first is kept (`None`: left out),
    /// and the name its channel is written under when renamed.
    fn written_channel(&self, interface: &str, since_first: Duration) -> Option<Option<&str>> {
        if since_first < self.from || self.to.is_some_and(|to| since_first > to) {
            return None;
        }
        if self.channels.is_empty() {
            return Some(None);
        }
        self.channels.get(interface).map(|name| Some(name.as_str()))
    }
}

/// Records from the inputs to a writer: the selection applied, progress shown, Ctrl-C obeyed
/// (an interrupted conversion is an error, so nothing half-written is left).
pub struct Pump<'a> {
    selection: &'a Selection,
    /// The progress bar.
    pub progress: Progress,
    first: Option<u64>,
    /// Records written.
    pub frames: u64,
    /// Records the selection left out.
    pub left_out: u64,
}

impl<'a> Pump<'a> {
    /// A pump applying `selection`, showing `progress`.
    pub fn new(selection: &'a Selection, progress: Progress) -> Self {
        Pump {
            selection,
            progress,
            first: None,
            frames: 0,
            left_out: 0,
        }
    }

    pub fn run(
        &mut self,
        records: impl Iterator<Item = Result<LogRecord>>,
        mut write: impl FnMut(&LogRecord) -> Result<()>,
    ) -> Result<()> {
        let stop = interrupt_flag();
        for record in records {
            let record = record?;
            let since_first = self.next(&stop, record.timestamp)?;
            let Some(record) = self.selection.keep(record, since_first) else {
                self.left_out += 1;
                continue;
            };
            write(&record)?;
            self.frames += 1;
        }
        Ok(())
    }

    /// [`Pump::run`] over one input's records, lent ([`for_each_lent`]): a candump log's
    /// records go to `write` without a copy of their interface names.
    pub fn run_lent(
        &mut self,
        name: &str,
        input: LogInput,
        skip: Skip,
        mut write: impl FnMut(&LogRecordRef<'_>) -> Result<()>,
    ) -> Result<()> {
        let stop = interrupt_flag();
        for_each_lent(name, input, skip, |record| {
            let since_first = self.next(&stop, record.timestamp)?;
            let Some(record) = self.selection.keep_lent(record, since_first) else {
                self.left_out += 1;
                return Ok(());
            };
            write(&record)?;
            self.frames += 1;
            Ok(())
        })
    }

    /// One more record read at `at`: Ctrl-C obeyed, progress shown; how long after the first
    /// record it is.
    fn next(&mut self, stop: &std::sync::atomic::AtomicBool, at: Timestamp) -> Result<Duration> {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(anyhow!("interrupted: nothing written"));
        }
        self.progress.frame();
        let at = at.as_nanos();
        Ok(Duration::from_nanos(
            at.saturating_sub(*self.first.get_or_insert(at)),
        ))
    }
}

/// Decode the records `feed` hands to its sink (through a [`Pump`]) into a Parquet dataset at
/// `output` (made whole or not at all); notes on what it holds and what could not be decoded.
pub fn write_dataset(
    output: &Path,
    decoder: &Decoder,
    partitioning: Partitioning,
    tables: TableOptions,
    feed: impl FnOnce(&mut dyn FnMut(&LogRecordRef<'_>) -> Result<()>) -> Result<()>,
) -> Result<Vec<String>> {
    let cannot_write = || format!("cannot write {}", output.display());
    let summary = write_dir_atomically(output, |tmp| {
        let mut dataset =
            DecodedDataset::create(tmp, decoder, partitioning).with_context(cannot_write)?;
        dataset.set_compression(tables.compression);
        dataset.set_time_precision(tables.times.into());
        feed(&mut |r| dataset.write_lent(r).with_context(cannot_write))?;
        dataset.finish().with_context(cannot_write)
    })?;
    let rows: u64 = summary.rows.values().sum();
    use crate::support::words::counted;
    let mut notes = vec![format!(
        "{} in {}, {}",
        counted(rows, "row"),
        counted(summary.rows.len(), "table"),
        counted(summary.files.len(), "file")
    )];
    if summary.unknown > 0 {
        notes.push(format!(
            "{} frames of no message in the DBC",
            summary.unknown
        ));
    }
    for (message, (count, why)) in &summary.undecodable {
        notes.push(format!(
            "{count} {message} frames not decoded (the first: {why})"
        ));
    }
    Ok(notes)
}

/// How a decoded dataset's tables are written.
#[derive(Clone, Copy)]
pub struct TableOptions {
    pub compression: ParquetCompression,
    pub times: TimeUnitArg,
}

/// The unit of a Parquet table's times.
#[derive(Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TimeUnitArg {
    /// Nanoseconds: what the logs hold (pandas, polars, pyarrow and DuckDB read them as times).
    #[default]
    Ns,
    /// Microseconds, floored: what Spark reads as times.
    Us,
}

impl TimeUnitArg {
    /// The unit for output in `format` to `what` (a file, for the error): nanoseconds unless
    /// given; an error when given for anything but Parquet.
    pub fn for_output(arg: Option<TimeUnitArg>, format: Format, what: &str) -> Result<TimeUnitArg> {
        if arg.is_some() && format != Format::Parquet {
            return Err(anyhow!(
                "--time-unit is for Parquet output; {what} is not Parquet"
            ));
        }
        Ok(arg.unwrap_or_default())
    }
}

impl From<TimeUnitArg> for bywire_log::Precision {
    fn from(unit: TimeUnitArg) -> Self {
        match unit {
            TimeUnitArg::Ns => bywire_log::Precision::Nanos,
            TimeUnitArg::Us => bywire_log::Precision::Micros,
        }
    }
}

/// What Parquet pages are compressed with.
#[derive(Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum CompressionArg {
    /// Zstandard: the smallest files.
    #[default]
    Zstd,
    /// Snappy: Spark's and pyarrow's default; larger files, quicker to write and read.
    Snappy,
    /// No compression.
    None,
}

impl CompressionArg {
    /// The compression for output in `format` to `what` (a file or a command's output, for the
    /// error): zstd unless given; an error when given for anything but Parquet.
    pub fn for_output(
        arg: Option<CompressionArg>,
        format: Format,
        what: &str,
    ) -> Result<ParquetCompression> {
        if arg.is_some() && format != Format::Parquet {
            return Err(anyhow!(
                "--compression is for Parquet output; {what} is not Parquet"
            ));
        }
        Ok(arg.unwrap_or_default().into())
    }
}

impl From<CompressionArg> for ParquetCompression {
    fn from(arg: CompressionArg) -> ParquetCompression {
        match arg {
            CompressionArg::Zstd => ParquetCompression::Zstd,
            CompressionArg::Snappy => ParquetCompression::Snappy,
            CompressionArg::None => ParquetCompression::Uncompressed,
        }
    }
}

/// A partition of a decoded Parquet dataset.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PartitionBy {
    /// A directory per channel.
    Channel,
    /// A directory per UTC day.
    Date,
}
