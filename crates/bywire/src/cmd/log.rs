//! `bywire log`: read candump logs — print them (log or screen form, filtered) or summarise
//! them — checking every line.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use bywire_bus::Filtering;
use bywire_log::candump::{frame_text, timestamp_text};
use bywire_log::format::Format;
use bywire_log::{FrameView, Precision, View};

use crate::support::busarg;
use crate::support::files::write_atomically;
use crate::support::logs::{inputs, records, Skip};

#[derive(clap::Subcommand)]
pub enum LogCommand {
    /// Print logs as candump log lines (or candump's screen form), optionally filtered.
    #[command(after_help = "Examples:
  bywire log cat candump-2024-01-01_120000.log
  bywire log cat --screen drive.log
  bywire log cat --filter 100:700 --filter 7E8:7FF drive.log > engine.log
  candump -L can0 | bywire log cat --nanoseconds

Every line is checked; a malformed one is an error naming its file, line and column.")]
    Cat {
        /// Log files (standard input when none).
        files: Vec<PathBuf>,
        /// candump's screen form instead of log lines.
        #[arg(long)]
        screen: bool,
        /// Timestamps with nanoseconds.
        #[arg(long)]
        nanoseconds: bool,
        /// Keep frames matching candump-style filters (ID:MASK, ID~MASK, #ERRMASK, j).
        #[arg(long, value_name = "FILTER")]
        filter: Vec<String>,
    },
    /// Convert a log to another format (candump, Vector ASC and BLF, PEAK TRC, pcapng), frame for
    /// frame.
    #[command(after_help = "Examples:
  bywire log convert drive.log drive.asc
  bywire log convert vector.asc drive.log
  bywire log convert pcan.trc drive.asc
  bywire log convert drive.log drive.pcapng       (then: wireshark drive.pcapng)
  bywire log convert vector.blf drive.log
  candump -L can0 | bywire log convert - out.asc

The input's format is sniffed from its content, the output's taken from its extension (.log
or .candump: candump; .asc: ASC; .blf: BLF; .trc: TRC 2.1; .pcapng: pcapng) unless --format
names it. ASC channels and
TRC buses are numbered from 1: can0 is 1 (an interface ending in N is N+1), and N reads back as
can{N-1}; dates are UTC. ASC, BLF and TRC keep no SocketCAN detail of an error frame: it reads
back as a bus error. pcapng keeps everything: interface names, nanoseconds, directions, error classes. The output is written to a temporary file and renamed, so a failed
conversion leaves no half-written file.")]
    Convert {
        /// The log to read (`-`: standard input).
        input: PathBuf,
        /// The file to write.
        output: PathBuf,
        /// The output format: candump, asc, blf, trc or pcapng (default: from the output's
        /// extension).
        #[arg(long, value_name = "FORMAT")]
        format: Option<String>,
    },
    /// Summarise logs: frames, interfaces, time span, identifiers with counts and cycle times.
    #[command(after_help = "Examples:
  bywire log stats drive.log")]
    Stats {
        /// Log files (standard input when none).
        files: Vec<PathBuf>,
    },
}

pub fn run(command: &LogCommand, out: &mut impl Write) -> Result<()> {
    match command {
        LogCommand::Cat {
            files,
            screen,
            nanoseconds,
            filter,
        } => {
            let filtering = if filter.is_empty() {
                None
            } else {
                let spec = format!("virtual:log,{}", filter.join(","));
                busarg::parse(&spec)?.filtering
            };
            cat(files, *screen, *nanoseconds, filtering.as_ref(), out)
        }
        LogCommand::Stats { files } => stats(files, out),
        LogCommand::Convert {
            input,
            output,
            format,
        } => convert(input, output, format.as_deref(), out),
    }
}

fn convert(input: &Path, output: &Path, format: Option<&str>, out: &mut impl Write) -> Result<()> {
    let format = match format {
        Some(name) => Format::named(name)
            .ok_or_else(|| {
                let names: Vec<&str> = Format::ALL.iter().map(|(_, n)| *n).collect();
                anyhow!("--format {name}: not a format ({})", names.join(", "))
            })?,
        None => Format::from_path(output).ok_or_else(|| {
            anyhow!(
                "{}: the output's format is not known from its name (.log, .asc, .blf, .trc, .pcapng); give --format",
                output.display()
            )
        })?,
    };
    let files = if input == Path::new("-") {
        Vec::new()
    } else {
        vec![input.to_path_buf()]
    };
    let mut frames = 0u64;
    write_atomically(output, |tmp| {
        let file = std::fs::File::create(tmp)
            .with_context(|| format!("cannot write {}", output.display()))?;
        let mut writer = format
            .writer(std::io::BufWriter::new(file))
            .with_context(|| format!("cannot write {}", output.display()))?;
        for (name, reader) in inputs(&files)? {
            for record in records(&name, reader, Skip::Unreadable) {
                writer
                    .write(&record?)
                    .with_context(|| format!("cannot write {}", output.display()))?;
                frames += 1;
            }
        }
        writer
            .finish()
            .with_context(|| format!("cannot write {}", output.display()))?;
        Ok(())
    })?;
    writeln!(out, "{frames} frames written to {}", output.display())?;
    Ok(())
}

fn cat(
    files: &[PathBuf],
    screen: bool,
    nanoseconds: bool,
    filtering: Option<&Filtering>,
    out: &mut impl Write,
) -> Result<()> {
    let precision = if nanoseconds {
        Precision::Nanos
    } else {
        Precision::Micros
    };
    let mut view = View::default();
    for (name, input) in inputs(files)? {
        for record in records(&name, input, Skip::Unreadable) {
            let record = record?;
            if filtering.is_some_and(|f| !f.accepts(&record.frame)) {
                continue;
            }
            if screen {
                view.indent_standard |= record.frame.id().is_some_and(|id| id.is_extended());
                writeln!(
                    out,
                    " ({})  {}  {}",
                    timestamp_text(record.timestamp, precision),
                    record.interface,
                    FrameView {
                        frame: &record.frame,
                        view
                    }
                )?;
            } else {
                writeln!(
                    out,
                    "({}) {} {}",
                    timestamp_text(record.timestamp, precision),
                    record.interface,
                    frame_text(&record.frame, true)
                )?;
            }
        }
    }
    Ok(())
}

/// Per identifier: frames, first and last time.
#[derive(Default)]
struct IdStats {
    frames: u64,
    first: u64,
    last: u64,
}

fn stats(files: &[PathBuf], out: &mut impl Write) -> Result<()> {
    let mut frames = 0u64;
    let (mut first, mut last) = (u64::MAX, 0u64);
    let mut interfaces: BTreeMap<String, u64> = BTreeMap::new();
    let mut ids: BTreeMap<(String, u32), IdStats> = BTreeMap::new();
    let (mut fd, mut errors, mut remote) = (0u64, 0u64, 0u64);
    for (name, input) in inputs(files)? {
        for record in records(&name, input, Skip::Unreadable) {
            let record = record?;
            let t = record.timestamp.as_nanos();
            frames += 1;
            first = first.min(t);
            last = last.max(t);
            fd += u64::from(record.frame.is_fd());
            errors += u64::from(record.frame.is_error());
            remote += u64::from(record.frame.is_remote());
            *interfaces.entry(record.interface.clone()).or_default() += 1;
            let entry = ids
                .entry((record.interface, record.frame.socketcan_id()))
                .or_insert(IdStats {
                    frames: 0,
                    first: t,
                    last: t,
                });
            entry.frames += 1;
            entry.first = entry.first.min(t);
            entry.last = entry.last.max(t);
        }
    }
    if frames == 0 {
        writeln!(out, "no frames")?;
        return Ok(());
    }
    let span = last.saturating_sub(first);
    writeln!(
        out,
        "{frames} frames ({fd} FD, {remote} remote, {errors} error) over {}.{:06} s",
        span / 1_000_000_000,
        span % 1_000_000_000 / 1000
    )?;
    for (interface, count) in &interfaces {
        writeln!(out, "  {interface}: {count} frames")?;
    }
    writeln!(out, "interface  id        frames  mean cycle ms")?;
    for ((interface, id), s) in &ids {
        let id_text = if id & bywire_core::frame::ERR_FLAG != 0 {
            format!("{id:08X}")
        } else if id & bywire_core::frame::EFF_FLAG != 0 {
            format!("{:08X}", id & bywire_core::frame::EFF_MASK)
        } else {
            format!("{:03X}", id & bywire_core::frame::SFF_MASK)
        };
        let id_text = if id & bywire_core::frame::RTR_FLAG != 0 {
            id_text + " R"
        } else {
            id_text
        };
        let cycle = if s.frames > 1 {
            // Nanosecond spans between frames: well within f64's exact range for logs.
            #[allow(clippy::cast_precision_loss)]
            let ms = (s.last - s.first) as f64 / (s.frames - 1) as f64 / 1e6;
            format!("{ms:.3}")
        } else {
            "-".into()
        };
        writeln!(
            out,
            "{interface:<10} {id_text:<9} {:>6}  {cycle:>13}",
            s.frames
        )?;
    }
    Ok(())
}
