//! `bywire log`: read candump logs — print them (log or screen form, filtered) or summarise
//! them — checking every line.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use bywire_bus::Filtering;
use bywire_log::candump::timestamp_text;
use bywire_log::format::{Format, ParquetOptions};
use bywire_log::stats::LogStats;
use bywire_log::LogRecord;
use bywire_log::{FrameView, Precision, View};

use crate::support::busarg;
use crate::support::files::{write_atomically, write_dir_atomically};
use crate::support::logs::{
    for_each_lent, inputs, records, write_dataset, CompressionArg, PartitionBy, Pump, Selection,
    Skip, TableOptions, TimeUnitArg,
};
use crate::support::progress::Progress;
use bywire_data::decoded::Partitioning;
use bywire_log::mcap::DecodedMcapWriter;

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
    /// Convert a log to another format (candump, Vector ASC and BLF, PEAK TRC, pcapng, ASAM
    /// MF4, MCAP, Parquet), frame for frame, or decode it with a DBC into Parquet tables or MCAP.
    #[command(after_help = "Examples:
  bywire log convert drive.log drive.asc
  bywire log convert vector.asc drive.log
  bywire log convert pcan.trc drive.asc
  bywire log convert drive.log drive.pcapng       (then: wireshark drive.pcapng)
  bywire log convert vector.blf drive.log
  bywire log convert vector.blf drive.mf4         (ASAM MDF 4 bus logging: asammdf, CANape)
  bywire log convert drive.log drive.mcap         (ROS 2's can_msgs/msg/Frame on /from_can_bus)
  bywire log convert drive.log drive_bag --format rosbag2
                                                  (metadata.yaml and the MCAP file; a bag folder
                                                  reads back as an input too)
  bywire log convert vector.blf frames.parquet    (one row per frame: ts, channel, id, flags, data)
  bywire log convert vector.blf lake --dbc vehicle.dbc --partition channel,date
                                                  (a Parquet table per message, typed signals)
  bywire log convert drive.log lake --dbc vehicle.dbc --compression snappy   (zstd by default)
  bywire log convert drive.log lake --dbc vehicle.dbc --time-unit us   (times Spark reads as such)
  bywire log convert drive.blf drive.parquet --time-unit us
  bywire log convert drive.log drive.mcap --dbc vehicle.dbc   (+ JSON channels for Foxglove)
  bywire log convert drive.log drive.mf4 --dbc vehicle.dbc    (+ a channel group per message,
                                                  with units and value tables, for asammdf)
  candump -L can0 | bywire log convert - out.asc
  bywire log convert a.blf b.asc merged.log --channel can0 --channel can3=can1 --from 10 --to 70

Several inputs are merged by time (streaming: one frame of each held). The input's format is
sniffed from its content, the output's taken from its extension (.log
or .candump: candump; .asc: ASC; .blf: BLF; .trc: TRC 2.1; .pcapng: pcapng; .mf4: MF4;
.mcap: MCAP; .parquet: Parquet) unless --format names it; with --dbc, an output without a known extension is
a new directory for the decoded Parquet dataset (message=NAME/[channel=C/][date=D/]part-N.parquet).
A progress bar shows on a terminal. ASC and BLF channels and
TRC buses are numbered from 1: can0 is 1 (an interface ending in N is N+1), and N reads back as
can{N-1}, unless a comment (ASC's `// channel 2 = bus1`, TRC's `; bus 2 = bus1`, BLF's measurement
comment `channel 2 = bus1`, written before a channel's first frame) names it; dates are UTC. ASC, BLF and TRC keep no SocketCAN detail of an error frame: it reads
back as a bus error. MF4 numbers buses as python-can does (can0 is BusChannel 0), names them in its header (the names
come back when bywire reads it) and keeps error classes. pcapng keeps everything: interface names, nanoseconds, directions, error classes. The output is written to a temporary file and renamed, so a failed
conversion leaves no half-written file.")]
    Convert {
        /// The logs to read, merged by time (`-`: standard input), and last the file to write.
        #[arg(required = true, num_args = 2.., value_name = "FILE")]
        files: Vec<PathBuf>,
        /// The output format: candump, asc, blf, trc, pcapng, mf4, mcap, parquet, or rosbag2 (a
        /// folder in rosbag2's layout: metadata.yaml and the MCAP file) (default: from the output's
        /// extension).
        #[arg(long, value_name = "FORMAT")]
        format: Option<String>,
        /// Keep only these channels (interfaces), renamed where given as FROM=TO.
        #[arg(long = "channel", value_name = "FROM[=TO]")]
        channels: Vec<String>,
        /// Leave out what comes before this many seconds after the first frame.
        #[arg(long, value_name = "SECONDS", value_parser = crate::support::numbers::seconds)]
        from: Option<f64>,
        /// Leave out what comes after this many seconds after the first frame.
        #[arg(long, value_name = "SECONDS", value_parser = crate::support::numbers::seconds)]
        to: Option<f64>,
        /// Decode with this DBC: into a Parquet dataset (a directory: a table per message), or
        /// into MCAP JSON channels beside the raw frames.
        #[arg(long, value_name = "DBC")]
        dbc: Option<PathBuf>,
        /// With --dbc: fail on the first problem in the DBC file.
        #[arg(long, requires = "dbc")]
        strict: bool,
        /// With --dbc and Parquet: partition each message's table by channel and/or UTC date.
        #[arg(
            long,
            value_name = "channel|date",
            value_delimiter = ',',
            requires = "dbc"
        )]
        partition: Vec<PartitionBy>,
        /// With Parquet output: what the pages are compressed with.
        #[arg(long, value_name = "CODEC")]
        compression: Option<CompressionArg>,
        /// With Parquet output: the unit of the times, raw frames' or decoded tables' (ns by
        /// default; us, floored: what Spark reads as times).
        #[arg(long, value_name = "UNIT")]
        time_unit: Option<TimeUnitArg>,
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
            files,
            format,
            channels,
            from,
            to,
            dbc,
            strict,
            partition,
            compression,
            time_unit,
        } => {
            let (output, inputs) = files
                .split_last()
                .ok_or_else(|| anyhow!("give the logs to read and the file to write"))?;
            let selection = Selection::new(channels, *from, *to)?;
            let decoding = Decoding {
                dbc: dbc.as_deref(),
                strict: *strict,
                partitioning: Partitioning {
                    channel: partition.contains(&PartitionBy::Channel),
                    date: partition.contains(&PartitionBy::Date),
                },
                compression: *compression,
                time_unit: *time_unit,
            };
            convert(
                inputs,
                output,
                format.as_deref(),
                &selection,
                &decoding,
                out,
            )
        }
    }
}

/// What `log convert` writes besides the format: decoded tables or channels with a DBC.
struct Decoding<'a> {
    dbc: Option<&'a Path>,
    strict: bool,
    partitioning: Partitioning,
    /// Parquet's page compression, when given (an error for any other output).
    compression: Option<CompressionArg>,
    /// The decoded tables' time unit, when given (an error for any other output).
    time_unit: Option<TimeUnitArg>,
}

/// The output's format: the one --format names, else the one its name says; with a DBC, a
/// name without an extension is the decoded dataset's folder.
/// The `--format` of a rosbag2 folder.
const ROSBAG2: &str = "rosbag2";

fn output_format(output: &Path, format: Option<&str>, decoded: bool) -> Result<Format> {
    Ok(match format {
        Some(name) => Format::named(name).ok_or_else(|| {
            let names: Vec<&str> = Format::ALL.iter().map(|(_, n)| *n).collect();
            anyhow!("--format {name}: not a format ({})", names.join(", "))
        })?,
        // A name with an extension no log format has (dec.csv) is refused: it was taken as
        // the dataset's directory and silently became a folder of Parquet files.
        None if decoded
            && Format::from_path(output).is_none()
            && output.extension().is_some() =>
        {
            bail!(
                "{}: --dbc writes a Parquet dataset (a folder: a name without an extension, or \
                 --format parquet) or MCAP (.mcap), not .{}; for CSV: bywire decode DBC -I LOG \
                 --csv > FILE.csv",
                output.display(),
                output
                    .extension()
                    .map(|e| e.to_string_lossy())
                    .unwrap_or_default()
            )
        }
        // A name without an extension, with a DBC: the decoded dataset's directory.
        None if decoded && Format::from_path(output).is_none() => Format::Parquet,
        None => Format::from_path(output).ok_or_else(|| {
            anyhow!(
                "{}: the output's format is not known from its name (.log, .asc, .blf, .trc, .pcapng, .mf4, .mcap, .parquet); give --format",
                output.display()
            )
        })?,
    })
}

fn convert(
    inputs: &[PathBuf],
    output: &Path,
    format: Option<&str>,
    selection: &Selection,
    decoding: &Decoding<'_>,
    out: &mut impl Write,
) -> Result<()> {
    // A rosbag2 folder: an MCAP file and its metadata.
    let bag = format.is_some_and(|f| f.eq_ignore_ascii_case(ROSBAG2));
    if bag && decoding.dbc.is_some() {
        bail!("--format rosbag2 carries the frames (can_msgs/msg/Frame); decode into MCAP (.mcap) or Parquet instead");
    }
    let format = match bag {
        true => Format::Mcap,
        false => output_format(output, format, decoding.dbc.is_some())?,
    };
    let compression =
        CompressionArg::for_output(decoding.compression, format, &output.display().to_string())?;
    let times = TimeUnitArg::for_output(decoding.time_unit, format, &output.display().to_string())?;
    let decoder = match decoding.dbc {
        None => None,
        Some(path) if matches!(format, Format::Parquet | Format::Mcap | Format::Mf4) => Some(
            bywire_dbc::decoder::Decoder::new(crate::support::dbc::load(path, decoding.strict)?),
        ),
        Some(_) => {
            return Err(anyhow!(
                "--dbc decodes into Parquet tables, MCAP JSON channels or MF4 channel groups; {} is none of them",
                output.display()
            ))
        }
    };
    let files: Vec<PathBuf> = inputs
        .iter()
        .filter(|p| p.as_path() != Path::new("-"))
        .cloned()
        .collect();
    let opened = inputs_or_stdin(&files, inputs.len())?;
    let names: Vec<String> = opened.iter().map(|(name, _)| name.clone()).collect();
    let progress = Progress::new(
        opened
            .iter()
            .filter_map(|(_, input)| input.position_probe())
            .collect(),
    );
    let readers: Vec<_> = opened
        .into_iter()
        .zip(&names)
        .map(|((_, reader), name)| records(name, reader, Skip::Unreadable))
        .collect();
    let mut pump = Pump::new(selection, progress);
    let cannot_write = || format!("cannot write {}", output.display());
    let mut unsupported = 0;
    let mut notes = Vec::new();
    match (&decoder, format) {
        (Some(decoder), Format::Parquet) => {
            let tables = TableOptions { compression, times };
            notes = write_dataset(output, decoder, decoding.partitioning, tables, |sink| {
                pump.run(bywire_log::merge::merge(readers), |r| {
                    sink(&r.as_record_ref())
                })
            })?;
        }
        (Some(decoder), Format::Mf4) => write_atomically(output, |tmp| {
            let file = std::fs::File::create(tmp).with_context(cannot_write)?;
            let mut writer = bywire_log::mf4::Mf4Writer::new(std::io::BufWriter::new(file))
                .with_context(cannot_write)?;
            let messages = decoder.database().messages.len();
            let mut groups: Vec<Option<usize>> = vec![None; messages];
            let (mut values, mut row) = (Vec::new(), Vec::new());
            pump.run(bywire_log::merge::merge(readers), |r| {
                writer.write(r).with_context(cannot_write)?;
                let Some((index, message, Ok(()))) = decoder.decode_into(&r.frame, &mut values)
                else {
                    return Ok(());
                };
                let Some(slot) = groups.get_mut(index) else {
                    return Ok(());
                };
                let group = *slot.get_or_insert_with(|| {
                    writer.add_decoded_group(message.display_name(), mf4_columns(message))
                });
                row.clear();
                row.extend(
                    values
                        .iter()
                        .map(|v| v.map_or(f64::NAN, |d| d.physical.as_f64())),
                );
                writer
                    .write_decoded(group, r.timestamp, &row)
                    .with_context(cannot_write)
            })?;
            writer.finish().with_context(cannot_write)?;
            Ok(())
        })?,
        (Some(decoder), _) => write_atomically(output, |tmp| {
            let file = std::fs::File::create(tmp).with_context(cannot_write)?;
            let mut writer = DecodedMcapWriter::new(std::io::BufWriter::new(file), decoder)
                .with_context(cannot_write)?;
            pump.run(bywire_log::merge::merge(readers), |r| {
                writer.write(r).with_context(cannot_write)
            })?;
            unsupported = writer.left_out();
            let (undecodable, over_limit) = writer.not_decoded();
            if undecodable > 0 {
                notes.push(format!(
                    "{undecodable} frames of known messages not decoded"
                ));
            }
            if over_limit > 0 {
                notes.push(format!(
                    "{over_limit} frames not decoded: more than {} decoded channels",
                    bywire_log::mcap::DECODED_CHANNELS
                ));
            }
            writer.finish().with_context(cannot_write)?;
            Ok(())
        })?,
        (None, _) if bag => write_dir_atomically(output, |dir| {
            std::fs::create_dir(dir).with_context(cannot_write)?;
            let name = bywire_log::rosbag2::mcap_file_name(output);
            let file = std::fs::File::create(dir.join(&name)).with_context(cannot_write)?;
            let mut summary = bywire_log::rosbag2::Summary::default();
            let records = bywire_log::merge::merge(readers);
            let options = ParquetOptions::default();
            unsupported = write_frames(file, format, options, &mut pump, records, output, |r| {
                let ns = r.timestamp.as_nanos();
                if summary.messages == 0 {
                    summary.first_ns = ns;
                }
                summary.last_ns = summary.last_ns.max(ns);
                summary.messages += 1;
            })?;
            let metadata = bywire_log::rosbag2::metadata(&name, &summary);
            std::fs::write(dir.join(bywire_log::rosbag2::METADATA), metadata)
                .with_context(cannot_write)?;
            Ok(())
        })?,
        (None, _) => write_atomically(output, |tmp| {
            let file = std::fs::File::create(tmp).with_context(cannot_write)?;
            let options = ParquetOptions {
                compression,
                times: times.into(),
            };
            let records = bywire_log::merge::merge(readers);
            unsupported = write_frames(file, format, options, &mut pump, records, output, |_| {})?;
            Ok(())
        })?,
    }
    pump.progress.finish();
    let left_out = pump.left_out;
    report(
        out,
        output,
        pump.frames - unsupported,
        unsupported,
        decoder.is_some(),
        left_out,
        &notes,
    )
}

/// A message's signals as MF4 channels: their table names, units and value names at the
/// physical values they stand for.
fn mf4_columns(message: &bywire_dbc::Message) -> Vec<bywire_log::mf4::Column> {
    let names = bywire_dbc::decoder::field_names(message);
    message
        .signals
        .iter()
        .zip(names)
        .map(|(s, name)| {
            let (factor, offset) = (s.factor.as_f64(), s.offset.as_f64());
            bywire_log::mf4::Column {
                name,
                unit: s.unit.clone(),
                #[allow(clippy::cast_precision_loss)]
                value_names: s
                    .value_descriptions
                    .iter()
                    .map(|(raw, text)| (*raw as f64 * factor + offset, text.clone()))
                    .collect(),
            }
        })
        .collect()
}

/// Write `records` (through the pump's selection and progress) into `file` as `format`;
/// `written` hears each record the format took. The frames it left out (CAN FD in MCAP).
fn write_frames(
    file: std::fs::File,
    format: Format,
    options: ParquetOptions,
    pump: &mut Pump<'_>,
    records: impl Iterator<Item = Result<LogRecord>>,
    output: &Path,
    mut written: impl FnMut(&LogRecord),
) -> Result<u64> {
    let cannot_write = || format!("cannot write {}", output.display());
    let mut writer = format
        .writer_with(std::io::BufWriter::new(file), options)
        .with_context(cannot_write)?;
    pump.run(records, |r| {
        let before = writer.left_out();
        writer.write(r).with_context(cannot_write)?;
        if writer.left_out() == before {
            written(r);
        }
        Ok(())
    })?;
    let left_out = writer.left_out();
    writer.finish().with_context(cannot_write)?;
    Ok(left_out)
}

/// What `convert` wrote: the frames, the CAN FD frames a ROS message cannot hold, what the
/// selection left out, and the notes.
fn report(
    out: &mut impl Write,
    output: &Path,
    frames: u64,
    unsupported: u64,
    decoded: bool,
    left_out: u64,
    notes: &[String],
) -> Result<()> {
    write!(out, "{frames} frames written to {}", output.display())?;
    if unsupported > 0 {
        let raw = if decoded { " raw channel" } else { "" };
        write!(
            out,
            " ({unsupported} CAN FD frames left out of the{raw}: can_msgs/msg/Frame has no CAN FD)"
        )?;
    }
    if left_out > 0 {
        write!(out, " ({left_out} left out by --channel, --from or --to)")?;
    }
    for note in notes {
        write!(out, "; {note}")?;
    }
    writeln!(out)?;
    Ok(())
}

/// The named files, or standard input when the only input is `-`.
fn inputs_or_stdin(
    files: &[PathBuf],
    given: usize,
) -> Result<Vec<(String, crate::support::logs::LogInput)>> {
    if files.len() != given && given > 1 {
        return Err(anyhow!("'-' (standard input) can only be the one input"));
    }
    inputs(files)
}

fn cat(
    files: &[PathBuf],
    screen: bool,
    nanoseconds: bool,
    filtering: Option<&Filtering>,
    out: &mut impl Write,
) -> Result<()> {
    // What standard input brings is written line by line, so a live pipe shows each frame as
    // it comes; files are written in blocks (a write for each line took most of the time).
    if files.is_empty() {
        return cat_to(files, screen, nanoseconds, filtering, out);
    }
    let mut blocks = BufWriter::with_capacity(64 << 10, out);
    let result = cat_to(files, screen, nanoseconds, filtering, &mut blocks);
    // What was read before an error is still written.
    let flushed = blocks.flush();
    result?;
    Ok(flushed?)
}

fn cat_to(
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
    let each_record = |write: &mut dyn FnMut(&LogRecord) -> Result<()>| -> Result<()> {
        for (name, input) in inputs(files)? {
            for record in records(&name, input, Skip::Unreadable) {
                let record = record?;
                if filtering.is_some_and(|f| !f.accepts(&record.frame)) {
                    continue;
                }
                write(&record)?;
            }
        }
        Ok(())
    };
    if screen {
        let mut view = View::default();
        return each_record(&mut |record| {
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
            Ok(())
        });
    }
    // Log lines as candump writes them with `-8` (a raw DLC shown), directions left out.
    let mut lines = bywire_log::Writer::new(out)
        .precision(precision)
        .raw_dlc(true);
    each_record(&mut |record| {
        lines.write(record.timestamp, &record.interface, &record.frame)?;
        Ok(())
    })
}

fn stats(files: &[PathBuf], out: &mut impl Write) -> Result<()> {
    let mut stats = LogStats::new();
    for (name, input) in inputs(files)? {
        for_each_lent(&name, input, Skip::Unreadable, |record| {
            stats.add(record);
            Ok(())
        })?;
    }
    stats.write_report(out)?;
    Ok(())
}
