//! `bywire dump`: candump on any bus, with its options, output and log files, plus DBC decoding.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_bus::Received;
use bywire_core::Frame;
use bywire_log::candump::{frame_text, timestamp_text};
use bywire_log::format::{Format, ParquetOptions, RecordWriter};
use bywire_log::{FrameView, LogRecord, Precision, View};

use crate::support::busarg::{self, BusArg, Event, Readers};
use crate::support::interrupt::interrupt_flag;
use crate::support::logs::{CompressionArg, TimeUnitArg};
use crate::support::signals::Dbc;
use crate::support::signals::FrameText;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire dump can0
  bywire dump -ta can0,123:7FF,400:700,#000000FF vcan1
  bywire dump -L virtual:test > traffic.log
  bywire dump -l -n 1000 can0              (writes candump-YYYY-MM-DD_HHMMSS.log)
  bywire dump -f drive.parquet --compression snappy can0 can1
  bywire dump -f drive.parquet --time-unit us can0   (times Spark reads as such)
  bywire dump --dbc vehicle.dbc can0,100:7F0

Filters follow the bus as in candump: ID:MASK matches when id & mask == ID & mask, ID~MASK
when it does not, #ERRMASK receives those error classes as error frames, j joins the filters
(all must match). An 8-digit ID is extended. A plain interface name (can0) means socketcan:can0.")]
pub struct Args {
    /// Buses to listen on, each with optional filters: BUS[,ID:MASK|ID~MASK|#ERRMASK|j]*
    #[arg(required = true, num_args = 1..=16)]
    buses: Vec<String>,
    /// Timestamps: a (absolute), d (delta), z (from the first frame), A (absolute with date).
    #[arg(short = 't', value_parser = ["a", "d", "z", "A"])]
    timestamp: Option<String>,
    /// Print printable data bytes as ASCII after the data.
    #[arg(short = 'a')]
    ascii: bool,
    /// Print error frames' classes and details in words.
    #[arg(short = 'e')]
    error_details: bool,
    /// Print in the log file format: (1699999999.123456) can0 123#DEADBEEF
    #[arg(short = 'L')]
    log_format: bool,
    /// Write a log file candump-YYYY-MM-DD_HHMMSS.log (and print nothing).
    #[arg(short = 'l')]
    log_file: bool,
    /// Write the log file to this path instead (implies -l); its extension picks the format
    /// (.asc, .blf, .trc, .pcapng, .mf4, .mcap, .parquet; anything else: candump), finished
    /// properly on Ctrl-C.
    #[arg(short = 'f', value_name = "FILE")]
    log_path: Option<PathBuf>,
    /// With a Parquet log file: what its pages are compressed with (zstd by default).
    #[arg(long, value_name = "CODEC")]
    compression: Option<CompressionArg>,
    /// With a Parquet log file: the unit of its times (ns by default; us, floored: what Spark
    /// reads as times).
    #[arg(long, value_name = "UNIT")]
    time_unit: Option<TimeUnitArg>,
    /// Exit after this many frames.
    #[arg(short = 'n', value_name = "COUNT")]
    count: Option<u64>,
    /// Exit after this many milliseconds without a frame.
    #[arg(short = 'T', value_name = "MSECS")]
    idle_timeout: Option<u64>,
    /// Show a classic DLC above 8 (`_X` in log lines).
    #[arg(short = '8')]
    raw_dlc: bool,
    /// Timestamps with nanoseconds in log lines and files.
    #[arg(long)]
    nanoseconds: bool,
    /// Decode frames with this DBC file and print their signals under each frame.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    if args.dbc.is_some() && args.log_format {
        return Err(anyhow!(
            "--dbc decodes on screen; with -L pipe the log through `bywire decode` instead"
        ));
    }
    let buses: Vec<BusArg> = args
        .buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    let decoder = match &args.dbc {
        Some(path) => Some(Dbc::new(crate::support::dbc::load(path, false)?)),
        None => None,
    };
    let log_path = match (args.log_file, &args.log_path) {
        (_, Some(path)) => Some(path.clone()),
        (true, None) => Some(PathBuf::from(
            chrono::Local::now()
                .format("candump-%Y-%m-%d_%H%M%S.log")
                .to_string(),
        )),
        (false, None) => None,
    };
    // The log file's format by its name (candump unless known), checked with the compression
    // before a bus is opened or a file made.
    let log_format = log_path
        .as_deref()
        .and_then(Format::from_path)
        .unwrap_or(Format::Candump);
    let what = log_path.as_ref().map_or_else(
        || "standard output".to_string(),
        |p| p.display().to_string(),
    );
    let parquet = ParquetOptions {
        compression: CompressionArg::for_output(args.compression, log_format, &what)?,
        times: TimeUnitArg::for_output(args.time_unit, log_format, &what)?.into(),
    };
    let opened = busarg::open_all(&buses)?;
    let mut log = match log_path {
        Some(path) => Some(create_log(path, log_format, parquet)?),
        None => None,
    };
    let stop = interrupt_flag();
    let readers = Readers::start(opened);
    let result = print_frames(
        args,
        &buses,
        decoder.as_ref(),
        &readers.events,
        &stop,
        out,
        &mut log,
    );
    drop(readers);
    // Every way out of the loop (a count, the idle time, Ctrl-C) ends the file properly: BLF
    // and MCAP complete their headers and summaries here.
    if let Some(log) = log {
        log.finish().context("cannot write the log file")?;
    }
    result
}

/// Where `-l`/`-f` log: candump text (as candump writes it), or another format's writer.
enum LogFile {
    Candump(BufWriter<File>),
    Other(Box<RecordWriter<BufWriter<File>>>),
}

impl LogFile {
    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            LogFile::Candump(w) => w.flush(),
            LogFile::Other(_) => Ok(()), // its containers are written as they fill
        }
    }

    fn finish(self) -> std::io::Result<()> {
        match self {
            LogFile::Candump(mut w) => w.flush(),
            LogFile::Other(w) => w.finish().map(drop),
        }
    }
}

fn create_log(path: PathBuf, format: Format, parquet: ParquetOptions) -> Result<LogFile> {
    let file = File::create(&path).with_context(|| format!("cannot create {}", path.display()))?;
    // As candump says it; a closed standard error is no reason to fail.
    let _ = writeln!(std::io::stderr(), "Enabling Logfile '{}'", path.display());
    let output = BufWriter::new(file);
    Ok(match format {
        Format::Candump => LogFile::Candump(output),
        format => LogFile::Other(Box::new(
            format
                .writer_with(output, parquet)
                .with_context(|| format!("cannot write {}", path.display()))?,
        )),
    })
}

/// What the printing loop remembers between frames.
struct Printer<'a> {
    args: &'a Args,
    width: usize,
    view: View,
    first: Option<u64>,
    last: Option<u64>,
    line: String,
}

fn print_frames(
    args: &Args,
    buses: &[BusArg],
    decoder: Option<&Dbc>,
    rx: &mpsc::Receiver<Event>,
    stop: &AtomicBool,
    out: &mut impl Write,
    log: &mut Option<LogFile>,
) -> Result<()> {
    let mut printer = Printer {
        args,
        width: buses
            .iter()
            .map(|b| b.name.chars().count())
            .max()
            .unwrap_or(0),
        view: View {
            ascii: args.ascii,
            error_details: args.error_details,
            ..View::default()
        },
        first: None,
        last: None,
        line: String::new(),
    };
    let idle = args.idle_timeout.map(Duration::from_millis);
    let mut last_frame = Instant::now();
    let mut count = 0u64;
    let silent = log.is_some();
    while args.count.is_none_or(|n| count < n) {
        let event = match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(event) => event,
            Err(RecvTimeoutError::Timeout) => {
                // Idle: what was received is written out (a log file too, so little is lost
                // if the process is killed).
                out.flush()?;
                if let Some(log) = log.as_mut() {
                    log.flush()?;
                }
                if stop.load(Ordering::Relaxed) || idle.is_some_and(|t| last_frame.elapsed() >= t) {
                    return Ok(());
                }
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        };
        let (index, received) = event;
        let name = buses.get(index).map_or("?", |b| b.name.as_str());
        let received = received.map_err(|e| anyhow!("bus '{name}': {e}"))?;
        last_frame = Instant::now();
        count += 1;
        match log.as_mut() {
            Some(LogFile::Candump(file)) => {
                printer.log_line(name, &received);
                file.write_all(printer.line.as_bytes())?;
            }
            Some(LogFile::Other(writer)) => writer.write(&LogRecord {
                timestamp: received.timestamp,
                interface: name.to_string(),
                frame: received.frame,
                direction: Some(if received.own { 'T' } else { 'R' }),
            })?,
            None => {}
        }
        if silent {
            continue;
        }
        if args.log_format {
            printer.log_line(name, &received);
        } else {
            printer.screen_line(name, &received, decoder);
        }
        out.write_all(printer.line.as_bytes())?;
    }
    Ok(())
}

impl Printer<'_> {
    fn precision(&self) -> Precision {
        if self.args.nanoseconds {
            Precision::Nanos
        } else {
            Precision::Micros
        }
    }

    /// `(secs.usecs) name frame` with the name right-aligned to the longest, as candump -L.
    fn log_line(&mut self, name: &str, received: &Received) {
        use std::fmt::Write as _;
        self.line.clear();
        let _ = writeln!(
            self.line,
            "({}) {name:>width$} {}",
            timestamp_text(received.timestamp, self.precision()),
            frame_text(&received.frame, self.args.raw_dlc),
            width = self.width
        );
    }

    /// candump's screen line: ` (timestamp)  name  frame`.
    fn screen_line(&mut self, name: &str, received: &Received, decoder: Option<&Dbc>) {
        use std::fmt::Write as _;
        self.line.clear();
        let ts = received.timestamp.as_nanos();
        self.line.push(' ');
        match self.args.timestamp.as_deref() {
            Some("a") => {
                let _ = write!(
                    self.line,
                    "({}) ",
                    timestamp_text(received.timestamp, self.precision())
                );
            }
            Some("A") => {
                let secs = i64::try_from(ts / 1_000_000_000).unwrap_or(i64::MAX);
                let date = chrono::DateTime::from_timestamp(secs, 0)
                    .map(|t| t.with_timezone(&chrono::Local))
                    .map(|t| t.format("%Y-%m-%d %H:%M:%S").to_string())
                    .unwrap_or_default();
                let _ = write!(self.line, "({date}.{:06}) ", ts % 1_000_000_000 / 1000);
            }
            Some(mode) => {
                let base = match mode {
                    "d" => self.last.unwrap_or(ts),
                    _ => *self.first.get_or_insert(ts),
                };
                let diff = ts.saturating_sub(base);
                let _ = write!(
                    self.line,
                    "({:03}.{:06}) ",
                    diff / 1_000_000_000,
                    diff % 1_000_000_000 / 1000
                );
            }
            None => {}
        }
        self.last = Some(ts);
        // Once an extended frame has been shown, standard IDs line up with extended ones.
        if received.frame.id().is_some_and(|id| id.is_extended()) {
            self.view.indent_standard = true;
        }
        let _ = writeln!(
            self.line,
            " {name:>width$}  {}",
            FrameView {
                frame: &received.frame,
                view: self.view
            },
            width = self.width
        );
        if let Some(decoded) = decoder.and_then(|d| decode_for_screen(d, &received.frame)) {
            self.line.push_str(&decoded);
        }
    }
}

/// The decoded lines printed under a frame with `--dbc`.
fn decode_for_screen(decoder: &Dbc, frame: &Frame) -> Option<String> {
    let decoded = decoder.decoder().decode(frame)?;
    let indent = "      ";
    Some(match &decoded.error {
        Some(e) => format!("{indent}{}: {e}\n", decoded.message.display_name()),
        None => format!("{indent}{}\n", decoded.multi_line(true, indent)),
    })
}
