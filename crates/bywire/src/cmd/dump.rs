//! `bywire dump`: candump on any bus, with its options, output and log files, plus DBC decoding.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_bus::Received;
use bywire_core::{Frame, Timestamp};
use bywire_log::candump::{frame_text, timestamp_text};
use bywire_log::format::{Format, ParquetOptions, RecordWriter};
use bywire_log::{FrameView, LogRecord, Precision, View};

use crate::support::busarg::{self, BusArg, Readers};
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
  bywire dump front=socketcand:10.0.0.2:29536/can0 rear=can1

Filters follow the bus as in candump: ID:MASK matches when id & mask == ID & mask, ID~MASK
when it does not, #ERRMASK receives those error classes as error frames, j joins the filters
(all must match). An 8-digit ID is extended. A plain interface name (can0) means socketcan:can0.
LABEL= names a bus in the output and in logs (front=socketcand:10.0.0.2:29536/can0 is front).")]
pub struct Args {
    /// Buses to listen on, each with optional filters and a label: [LABEL=]BUS[,ID:MASK|ID~MASK|#ERRMASK|j]*
    #[arg(required = true, num_args = 1..=16)]
    buses: Vec<String>,
    /// Timestamps: a (absolute), d (delta), z (from the first frame), A (absolute with date).
    #[arg(short = 't', value_parser = ["a", "d", "z", "A"])]
    timestamp: Option<String>,
    /// Print printable data bytes as ASCII after the data.
    #[arg(short = 'a')]
    ascii: bool,
    /// Data bytes in binary (10100101).
    #[arg(short = 'i')]
    binary: bool,
    /// Data bytes last to first, joined by a backquote (a little-endian value as a number).
    #[arg(short = 'S')]
    swap: bool,
    /// Colour each bus's lines (repeat for more): -c the bus's name, -cc the line from it,
    /// -ccc the whole line.
    #[arg(short = 'c', action = clap::ArgAction::Count)]
    color: u8,
    /// Extra information: RX or TX (sent from this host), and an FD frame's BRS and ESI; in
    /// log lines R or T at the end.
    #[arg(short = 'x')]
    extra: bool,
    /// Silent: 0 prints every frame, 1 a spinning character, 2 nothing (default 2 with -l or
    /// -f, else 0).
    #[arg(short = 's', value_name = "LEVEL", value_parser = clap::value_parser!(u8).range(0..=2))]
    silent: Option<u8>,
    /// The controller's hardware timestamps instead of the system's (0 where the interface has
    /// none, as candump shows them).
    #[arg(short = 'H')]
    hardware_timestamps: bool,
    /// The socket's receive buffer, bytes (SocketCAN; beyond net.core.rmem_max as root).
    #[arg(short = 'r', value_name = "SIZE")]
    receive_buffer: Option<usize>,
    /// Go on when a bus fails or its interface goes down (said on stderr), instead of exiting.
    #[arg(short = 'D')]
    keep_on_down: bool,
    /// Say when frames were dropped before they were read (DROPCOUNT lines, as candump).
    #[arg(short = 'd')]
    drops: bool,
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
    #[arg(short = 'N', long)]
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
    if args.log_format && (args.ascii || args.binary || args.swap) {
        return Err(anyhow!(
            "-L writes log lines: -a, -i and -S change only the screen form"
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
    let mut opened = busarg::open_all(&buses)?;
    if let Some(bytes) = args.receive_buffer {
        for (bus, arg) in opened.iter_mut().zip(&buses) {
            bus.set_receive_buffer(bytes)
                .map_err(|e| anyhow!("-r {bytes}: bus '{}': {e}", arg.name))?;
        }
    }
    let mut log = match log_path {
        Some(path) => Some(create_log(path, log_format, parquet)?),
        None => None,
    };
    let stop = interrupt_flag();
    let readers = Readers::start_with(opened, args.keep_on_down);
    let result = print_frames(
        args,
        &buses,
        decoder.as_ref(),
        &readers,
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

/// candump's colours, a bus each in the order they are given (bold blue, red, green, bold,
/// magenta, cyan; candump takes them in the order its sockets first deliver, which is that
/// order unless the buses start at the same moment), and the reset.
const COLORS: [&str; 6] = [
    "\x1b[1m\x1b[34m",
    "\x1b[1m\x1b[31m",
    "\x1b[1m\x1b[32m",
    "\x1b[1m",
    "\x1b[1m\x1b[35m",
    "\x1b[1m\x1b[36m",
];
const COLOR_OFF: &str = "\x1b[0m";
/// `-s 1`'s spinning character, a step a frame.
const SPINNER: [char; 4] = ['|', '/', '-', '\\'];

/// What the printing loop remembers between frames.
struct Printer<'a> {
    args: &'a Args,
    width: usize,
    view: View,
    first: Option<u64>,
    last: Option<u64>,
    line: String,
    /// Each bus's drop count as last said (`-d`).
    drops: Vec<u64>,
}

fn print_frames(
    args: &Args,
    buses: &[BusArg],
    decoder: Option<&Dbc>,
    readers: &Readers,
    stop: &AtomicBool,
    out: &mut impl Write,
    log: &mut Option<LogFile>,
) -> Result<()> {
    let rx = &readers.events;
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
            binary: args.binary,
            swap: args.swap,
            indent_standard: false,
        },
        first: None,
        last: None,
        line: String::new(),
        drops: vec![0; buses.len()],
    };
    let idle = args.idle_timeout.map(Duration::from_millis);
    let mut last_frame = Instant::now();
    let mut count = 0u64;
    let silent = args.silent.unwrap_or(if log.is_some() { 2 } else { 0 });
    let mut spins = 0usize;
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
        let received = match received {
            Ok(received) => received,
            Err(e) if args.keep_on_down => {
                let _ = writeln!(std::io::stderr(), "{name}: {e} (going on: -D)");
                continue;
            }
            Err(e) => return Err(anyhow!("bus '{name}': {e}")),
        };
        last_frame = Instant::now();
        count += 1;
        if args.drops {
            let now = readers
                .dropped
                .get(index)
                .map_or(0, |d| d.load(Ordering::Relaxed));
            if let Some(said) = printer.drops.get_mut(index).filter(|said| now > **said) {
                let dropped = now - *said;
                *said = now;
                let text = format!(
                    "DROPCOUNT: dropped {dropped} CAN frame{} on '{name}' socket (total drops {now})\n",
                    if dropped > 1 { "s" } else { "" }
                );
                if silent != 2 {
                    out.write_all(text.as_bytes())?;
                }
                if let Some(LogFile::Candump(file)) = log.as_mut() {
                    file.write_all(text.as_bytes())?;
                }
            }
        }
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
        match silent {
            2 => continue,
            1 => {
                let spin = SPINNER.get(spins % SPINNER.len()).copied().unwrap_or('|');
                spins = spins.wrapping_add(1);
                write!(out, "{spin}\x08")?;
                continue;
            }
            _ => {}
        }
        if args.log_format {
            printer.log_line(name, &received);
        } else {
            printer.screen_line(index, name, &received, decoder);
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

    /// The frame's time: the system's, or with `-H` the controller's (0 without one).
    fn time_of(&self, received: &Received) -> Timestamp {
        if self.args.hardware_timestamps {
            received.hardware.unwrap_or(Timestamp::ZERO)
        } else {
            received.timestamp
        }
    }

    /// `(secs.usecs) name frame` with the name right-aligned to the longest, as candump -L
    /// (with `-x`, R or T at the end).
    fn log_line(&mut self, name: &str, received: &Received) {
        use std::fmt::Write as _;
        self.line.clear();
        let _ = write!(
            self.line,
            "({}) {name:>width$} {}",
            timestamp_text(self.time_of(received), self.precision()),
            frame_text(&received.frame, self.args.raw_dlc),
            width = self.width
        );
        if self.args.extra {
            self.line.push_str(if received.local { " T" } else { " R" });
        }
        self.line.push('\n');
    }

    /// candump's screen line: ` (timestamp)  name  frame`, coloured with `-c` as candump does
    /// (-c the name, -cc from the name on, -ccc all of it), `TX`/`RX` and BRS/ESI with `-x`.
    fn screen_line(
        &mut self,
        index: usize,
        name: &str,
        received: &Received,
        decoder: Option<&Dbc>,
    ) {
        use std::fmt::Write as _;
        let level = self.args.color;
        let color = match level {
            0 => "",
            _ => COLORS.get(index % COLORS.len()).copied().unwrap_or(""),
        };
        self.line.clear();
        let at = self.time_of(received);
        let ts = at.as_nanos();
        self.line.push(' ');
        if level > 2 {
            self.line.push_str(color);
        }
        match self.args.timestamp.as_deref() {
            Some("a") => {
                let _ = write!(self.line, "({}) ", timestamp_text(at, self.precision()));
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
        let _ = write!(
            self.line,
            " {}{name:>width$}",
            if level == 1 || level == 2 { color } else { "" },
            width = self.width
        );
        if self.args.extra {
            let (brs, esi) = match &received.frame {
                Frame::Fd(fd) => (fd.brs(), fd.esi()),
                _ => (false, false),
            };
            let _ = write!(
                self.line,
                "  {} {} {}",
                if received.local { "TX" } else { "RX" },
                if brs { 'B' } else { '-' },
                if esi { 'E' } else { '-' }
            );
        }
        let _ = writeln!(
            self.line,
            "{}  {}{}",
            if level == 1 { COLOR_OFF } else { "" },
            FrameView {
                frame: &received.frame,
                view: self.view
            },
            if level > 1 { COLOR_OFF } else { "" },
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
