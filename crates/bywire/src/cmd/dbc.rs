use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};

use crate::support::logs::Skip;
use crate::support::signals::FrameText;
use crate::support::signals::{Dbc, JsonLines, TextLines};
use anyhow::{Context, Result};
use bywire_dbc::{ByteOrder, Database, Message, Multiplexing, ValueType};
use serde_json::json;

#[derive(clap::Subcommand)]
pub enum DbcCommand {
    /// Print messages, signals and a bit-layout picture per message.
    #[command(
        after_help = "Examples:\n  bywire dbc dump vehicle.dbc\n  bywire dbc dump --strict vehicle.dbc\n\nLoads leniently: problems are printed on stderr as file:line:column and the dump goes on;\nwith --strict the first problem is an error (exit 1)."
    )]
    Dump {
        /// The DBC file.
        file: PathBuf,
        /// Fail on the first problem instead of loading leniently.
        #[arg(long)]
        strict: bool,
    },
    /// Check for overlaps, signals past the end, bad ranges, missing cycle times, unprotected
    /// commands and more.
    #[command(
        after_help = "Examples:\n  bywire dbc lint vehicle.dbc\n\nPrints file:line:column: severity: [check] what. Exit 1 when there is an error."
    )]
    Lint {
        /// The DBC file.
        file: PathBuf,
    },
    /// Generate Rust: a no_std module with a typed struct per message.
    #[command(
        after_help = "Examples:\n  bywire dbc gen-rust vehicle.dbc > src/vehicle.rs\n\nFrom a build.rs, call bywire_dbc::codegen::generate(&db) instead."
    )]
    GenRust {
        /// The DBC file.
        file: PathBuf,
    },
    /// Convert among DBC, KCD, SYM and JSON (and from ARXML), chosen by the files' extensions.
    #[command(
        after_help = "Examples:\n  bywire dbc convert vehicle.dbc vehicle.json\n  bywire dbc convert vehicle.json vehicle.dbc\n  bywire dbc convert vehicle.sym vehicle.dbc\n  bywire dbc convert vehicle.dbc vehicle.kcd\n\nWhat the output format cannot say (attributes, nodes, extended multiplexing, ...) is named\non stderr, one warning each, and left out. The output is written to a temporary file and\nrenamed, so a failed conversion leaves no half-written file."
    )]
    Convert {
        /// The input file.
        input: PathBuf,
        /// The output file.
        output: PathBuf,
    },
}

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  candump -L can0 | bywire decode vehicle.dbc\n  bywire decode vehicle.dbc --json < candump-2024-01-01_120000.log\n  bywire decode vehicle.dbc -I drive.blf --csv > signals.csv\n  bywire decode vehicle.dbc -I drive.blf --parquet lake --partition date\n\nReads candump's log form `(1699999999.123456) can0 123#DEADBEEF` and its screen form\n`  can0  123   [4]  DE AD BE EF`; other lines are passed through unchanged."
)]
pub struct DecodeArgs {
    /// The DBC file.
    file: PathBuf,
    /// One line per frame instead of one line per signal.
    #[arg(long)]
    single_line: bool,
    /// Show raw values instead of value descriptions.
    #[arg(long)]
    no_decode_choices: bool,
    /// Print one JSON object per frame: id, extended, name, signals, error.
    #[arg(long)]
    json: bool,
    /// Fail on the first problem in the DBC file.
    #[arg(long)]
    strict: bool,
    /// Read this log (candump, ASC, BLF, TRC, pcapng, MCAP or Parquet, by its content) instead
    /// of standard input's lines; each frame is shown as a candump log line.
    #[arg(short = 'I', value_name = "FILE")]
    input: Option<PathBuf>,
    /// Print CSV, one row per signal: ts,channel,message,signal,value,choice,unit.
    #[arg(long, conflicts_with_all = ["json", "single_line", "parquet"])]
    csv: bool,
    /// Write a Parquet dataset into this new directory: a table per message, a typed column
    /// per signal (as `log convert --dbc`).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["json", "single_line"])]
    parquet: Option<PathBuf>,
    /// With --parquet: partition each message's table by channel and/or UTC date.
    #[arg(
        long,
        value_name = "channel|date",
        value_delimiter = ',',
        requires = "parquet"
    )]
    partition: Vec<crate::support::logs::PartitionBy>,
    /// With --parquet: what the pages are compressed with.
    #[arg(
        long,
        value_name = "CODEC",
        default_value = "zstd",
        requires = "parquet"
    )]
    compression: crate::support::logs::CompressionArg,
    /// With --parquet: the unit of the tables' times (us: what Spark reads as times).
    #[arg(long, value_name = "UNIT", default_value = "ns", requires = "parquet")]
    time_unit: crate::support::logs::TimeUnitArg,
}

fn is_json(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

pub fn run(command: &DbcCommand, out: &mut impl Write) -> Result<()> {
    match command {
        DbcCommand::Dump { file, strict } => {
            let (db, _, format) = crate::support::dbc::load_with_format(file, *strict)?;
            // Which reader read it: a file's extension does not always say.
            writeln!(
                out,
                "Database:   {} ({}, {} messages)\n",
                file.display(),
                format.name().to_uppercase(),
                db.messages.len()
            )?;
            dump(&db, out)
        }
        DbcCommand::Convert { input, output } => {
            let db = if is_json(input) {
                let text = std::fs::read_to_string(input)
                    .with_context(|| format!("cannot read {}", input.display()))?;
                serde_json::from_str(&text).map_err(|e| {
                    anyhow::anyhow!("{}:{}:{}: {e}", input.display(), e.line(), e.column())
                })?
            } else {
                // A file the parser had to repair is not converted: the output would not say
                // what was dropped.
                let (db, errors) = crate::support::dbc::load_counting_errors(input, false)?;
                anyhow::ensure!(
                    errors == 0,
                    "{errors} error(s) in {}: not converted",
                    input.display()
                );
                db
            };
            let text = if is_json(output) {
                serde_json::to_string_pretty(&db)? + "\n"
            } else if let Some(format) =
                bywire_dbc::Format::from_path(output).filter(|f| f.is_written())
            {
                let (text, omissions) = bywire_dbc::format::write(&db, format);
                for omission in &omissions {
                    eprintln!(
                        "{}: warning: left out what {format} cannot say: {omission}",
                        output.display()
                    );
                }
                text
            } else {
                anyhow::bail!(
                    "{}: the output must end in .dbc, .kcd, .sym or .json (ARXML is read, not written)",
                    output.display()
                );
            };
            // Whole or not at all, and named by what was asked for (it said `x.partial`).
            crate::support::files::write_atomically(output, |tmp| {
                std::fs::write(tmp, &text)
                    .with_context(|| format!("cannot write {}", output.display()))
            })
        }
        DbcCommand::GenRust { file } => {
            let db = crate::support::dbc::load(file, false)?;
            out.write_all(bywire_dbc::codegen::generate(&db).as_bytes())?;
            Ok(())
        }
        DbcCommand::Lint { file } => {
            let (db, parse_errors) = crate::support::dbc::load_counting_errors(file, false)?;
            let findings = bywire_dbc::lint::lint(&db);
            for f in &findings {
                let severity = match f.severity {
                    bywire_dbc::Severity::Info => "info",
                    bywire_dbc::Severity::Warning => "warning",
                    bywire_dbc::Severity::Error => "error",
                };
                writeln!(
                    out,
                    "{}:{}:{}: {severity}: [{}] {}",
                    file.display(),
                    f.position.line,
                    f.position.column,
                    f.code,
                    f.text
                )?;
            }
            let errors = parse_errors
                + findings
                    .iter()
                    .filter(|f| f.severity == bywire_dbc::Severity::Error)
                    .count();
            anyhow::ensure!(errors == 0, "{errors} error(s) in {}", file.display());
            Ok(())
        }
    }
}

fn dump(db: &Database, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "================================= Messages ================================="
    )?;
    for m in &db.messages {
        writeln!(out)?;
        writeln!(
            out,
            "  ------------------------------------------------------------------------"
        )?;
        writeln!(out)?;
        writeln!(out, "  Name:       {}", m.display_name())?;
        writeln!(
            out,
            "  Id:         0x{:x}{}",
            m.id,
            if m.extended { " (extended)" } else { "" }
        )?;
        if let Some(bywire_dbc::AttrValue::Str(bus)) = m.attribute(bywire_dbc::BUS_NAME) {
            writeln!(out, "  Bus:        {bus}")?;
        }
        message_body(m, out)?;
        let Some(container) = db.containers.iter().find(|c| c.message == m.name) else {
            continue;
        };
        let order = match container.header_byte_order {
            ByteOrder::LittleEndian => "little",
            ByteOrder::BigEndian => "big",
        };
        let (id_bytes, length_bytes) = container.header.sizes();
        writeln!(
            out,
            "  Contains:   PDUs behind {id_bytes}-byte identifiers and {length_bytes}-byte lengths ({order}-endian)"
        )?;
        for pdu in &container.pdus {
            writeln!(out)?;
            writeln!(out, "  PDU:        {}", pdu.display_name())?;
            writeln!(out, "  Header ID:  0x{:06x}", pdu.id)?;
            message_body(pdu, out)?;
        }
    }
    Ok(())
}

/// A message's (or contained PDU's) length, timing, senders, comment, protection, layout and
/// signals.
fn message_body(m: &Message, out: &mut impl Write) -> Result<()> {
    writeln!(out, "  Length:     {} bytes", m.size)?;
    if let Some(bywire_dbc::AttrValue::Number(n)) = m.attribute("GenMsgCycleTime") {
        writeln!(out, "  Cycle time: {n} ms")?;
    }
    let senders: Vec<&str> = std::iter::once(m.transmitter.as_str())
        .chain(m.senders.iter().map(String::as_str))
        .collect();
    writeln!(out, "  Senders:    {}", senders.join(", "))?;
    if let Some(c) = &m.comment {
        writeln!(out, "  Comment:    {c}")?;
    }
    if let Some(p) = bywire_dbc::e2e::Protection::of(m) {
        let name = |i: usize| m.signals.get(i).map_or("?", |s| s.display_name());
        let mut parts = Vec::new();
        if let Some((i, _)) = p.counter {
            parts.push(format!("counter {}", name(i)));
        }
        if let Some((i, algorithm)) = p.checksum {
            let how = algorithm.map_or("no declared algorithm".to_string(), |a| format!("{a:?}"));
            let id = p
                .data_id
                .map(|d| format!(", data ID 0x{d:04x}"))
                .unwrap_or_default();
            parts.push(format!("checksum {} ({how}{id})", name(i)));
        }
        writeln!(out, "  Protected:  {}", parts.join(", "))?;
    }
    match bywire_dbc::secoc::Secured::of(m) {
        Ok(Some(secured)) => {
            let l = secured.layout;
            writeln!(
                out,
                "  Secured:    SecOC data ID 0x{:04x}, {} payload bytes, freshness {} of {} bits, MAC {} bits, key {}",
                l.data_id,
                l.payload_length,
                l.fv_tx_length,
                l.fv_length,
                l.mac_tx_length,
                secured.key_id
            )?;
        }
        Ok(None) => {}
        Err(e) => writeln!(out, "  Secured:    unusable: {e}")?,
    }
    layout(m, out)?;
    writeln!(out, "  Signals:")?;
    for s in &m.signals {
        let order = match s.byte_order {
            ByteOrder::LittleEndian => "little",
            ByteOrder::BigEndian => "big",
        };
        let kind = match s.value_type {
            ValueType::Integer { signed: true } => "signed",
            ValueType::Integer { signed: false } => "unsigned",
            ValueType::Float32 => "float32",
            ValueType::Float64 => "float64",
        };
        let mux = match s.multiplexing {
            Multiplexing::None => String::new(),
            Multiplexing::Multiplexor => " multiplexor".into(),
            Multiplexing::Multiplexed(v) => format!(" when multiplexor = {v}"),
            Multiplexing::MultiplexedMultiplexor(v) => {
                format!(" multiplexor, when multiplexor = {v}")
            }
        };
        writeln!(
            out,
            "    {} [{}|{} {order}-endian {kind}]{mux}",
            s.display_name(),
            s.start_bit,
            s.length
        )?;
        writeln!(
            out,
            "      scale {} offset {} range [{}, {}] {}",
            s.factor, s.offset, s.minimum, s.maximum, s.unit
        )?;
        if let Some(c) = &s.comment {
            writeln!(out, "      {c}")?;
        }
        for (v, d) in &s.value_descriptions {
            writeln!(out, "        {v}: {d}")?;
        }
    }
    Ok(())
}

/// A byte-by-byte grid of the message's bits: each signal drawn with its letter, the most
/// significant bit marked with `>`.
fn layout(m: &Message, out: &mut impl Write) -> Result<()> {
    let size = usize::try_from(m.size).unwrap_or(0).min(64);
    if size == 0 || m.signals.is_empty() {
        return Ok(());
    }
    let letters: Vec<char> = ('A'..='Z').chain('a'..='z').collect();
    let mut grid = vec![vec![String::from("   "); 8]; size];
    for (i, s) in m.signals.iter().enumerate() {
        let letter = letters.get(i % letters.len()).copied().unwrap_or('?');
        let positions: Vec<u32> = s.bit_positions().collect();
        let msb = match s.byte_order {
            ByteOrder::LittleEndian => positions.last().copied(),
            ByteOrder::BigEndian => positions.first().copied(),
        };
        for &p in &positions {
            let (byte, bit) = (
                usize::try_from(p / 8).unwrap_or(usize::MAX),
                usize::try_from(p % 8).unwrap_or(0),
            );
            if let Some(cell) = grid.get_mut(byte).and_then(|row| row.get_mut(7 - bit)) {
                let mark = if Some(p) == msb { '>' } else { ' ' };
                *cell = if cell.trim().is_empty() {
                    format!("{mark}{letter} ")
                } else {
                    " ! ".into()
                };
            }
        }
    }
    writeln!(
        out,
        "  Layout (bit 7 left; '!' where signals overlap, '>' marks the MSB):"
    )?;
    writeln!(out, "           7  6  5  4  3  2  1  0")?;
    for (byte, row) in grid.iter().enumerate() {
        writeln!(out, "    {byte:>4} |{}|", row.concat())?;
    }
    for (i, s) in m.signals.iter().enumerate() {
        writeln!(
            out,
            "      {} = {}",
            letters.get(i % letters.len()).copied().unwrap_or('?'),
            s.display_name()
        )?;
    }
    Ok(())
}

pub fn decode(args: &DecodeArgs, input: impl Read + 'static, out: &mut impl Write) -> Result<()> {
    let decoder = Dbc::new(crate::support::dbc::load(&args.file, args.strict)?);
    let input = std::io::BufReader::with_capacity(1 << 16, input);
    let mut json = args.json.then(|| JsonLines::new(&decoder));
    let mut lines_out = TextLines::new(&decoder);
    if args.csv || args.parquet.is_some() {
        return decode_records(args, &decoder, Box::new(input), out);
    }
    if let Some(path) = &args.input {
        // A log file of any format: every frame, shown as its candump line. Written in blocks,
        // not a line at a time as standard output is (the input is a file, not a live bus).
        let mut out = std::io::BufWriter::with_capacity(1 << 16, out);
        for (name, reader) in crate::support::logs::inputs(std::slice::from_ref(path))? {
            for record in crate::support::logs::records(&name, reader, Skip::Unreadable) {
                let record = record?;
                // JSON has no use for the frame's line.
                let text = if args.json {
                    String::new()
                } else {
                    format!(
                        "({}) {} {}",
                        bywire_log::candump::timestamp_text(
                            record.timestamp,
                            bywire_log::Precision::Micros
                        ),
                        record.interface,
                        bywire_log::candump::frame_text(&record.frame, false)
                    )
                };
                write_decoded(
                    args,
                    &decoder,
                    json.as_mut(),
                    &mut lines_out,
                    &text,
                    &record.frame,
                    &mut out,
                )?;
            }
        }
        out.flush()?;
        return Ok(());
    }
    // One line at a time, each at most a log line's size: logs of any size stream through in
    // constant memory. The output is written in blocks, but flushed whenever no whole line is
    // waiting in the input, so a live bus piped in (`candump -L can0 | bywire decode`) shows
    // each frame as it comes.
    // Ctrl-C or SIGTERM (which reach the whole pipeline, its writer too) end it as the end of
    // input does: what was decoded is written, exit 0, as candump ends.
    let stop = crate::support::interrupt::interrupt_flag();
    let mut out = std::io::BufWriter::with_capacity(1 << 16, out);
    let mut lines = bywire_log::lines::CappedLines::new(input);
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        if !lines.line_waiting() {
            out.flush()?;
        }
        let Some(next) = lines.next_str() else { break };
        let (number, line) = next?;
        let text = match line {
            bywire_log::lines::LineRef::Text(text) => text,
            other => {
                eprintln!(
                    "stdin:{number}: skipped: {}",
                    other.to_owned_line().problem().unwrap_or_default()
                );
                continue;
            }
        };
        match bywire_log::screen::parse_line(text) {
            Some(frame) => write_decoded(
                args,
                &decoder,
                json.as_mut(),
                &mut lines_out,
                text,
                &frame,
                &mut out,
            )?,
            None if !args.json => writeln!(out, "{text}")?,
            None => {}
        }
    }
    out.flush()?;
    Ok(())
}

/// One frame's line (`text`) and what it decodes to, as text or (with `json`) a JSON object.
fn write_decoded(
    args: &DecodeArgs,
    decoder: &Dbc,
    json: Option<&mut JsonLines<'_>>,
    lines: &mut TextLines<'_>,
    text: &str,
    frame: &bywire_core::Frame,
    out: &mut impl Write,
) -> Result<()> {
    if let Some(lines) = json {
        if lines.write(out, frame)? {
            return Ok(());
        }
        // Two signals of one name: the object numbers them.
        let (id, extended) = frame
            .id()
            .map(|id| (id.as_raw(), id.is_extended()))
            .unwrap_or_default();
        let decoded = decoder.decoder().decode(frame);
        let o = match &decoded {
            None => {
                json!({"id": id, "extended": extended, "name": null, "signals": {}, "error": "unknown message"})
            }
            Some(d) => {
                let mut o = json!({"id": id, "extended": extended, "name": d.message.display_name(), "signals": d.json_signals()});
                if let Some(e) = &d.error {
                    o["error"] = json!(e);
                }
                o
            }
        };
        writeln!(out, "{o}")?;
        return Ok(());
    }
    lines.write(out, text, frame, args.single_line, !args.no_decode_choices)?;
    Ok(())
}

/// `decode --csv` and `--parquet`: the input read as a log (a file, or standard input's log
/// lines), every frame with its time and channel.
fn decode_records(
    args: &DecodeArgs,
    decoder: &Dbc,
    stdin: Box<dyn BufRead>,
    out: &mut impl Write,
) -> Result<()> {
    use crate::support::logs::{self, LogInput, Pump, Selection};
    let (name, input) = match &args.input {
        Some(path) => logs::input(Some(path))?,
        None => ("standard input".to_string(), LogInput::stream(stdin)),
    };
    let progress =
        crate::support::progress::Progress::new(input.position_probe().into_iter().collect());
    let everything = Selection::everything();
    let mut pump = Pump::new(&everything, progress);
    if let Some(dir) = &args.parquet {
        let partitioning = bywire_data::decoded::Partitioning {
            channel: args.partition.contains(&logs::PartitionBy::Channel),
            date: args.partition.contains(&logs::PartitionBy::Date),
        };
        let tables = logs::TableOptions {
            compression: args.compression.into(),
            times: args.time_unit,
        };
        // One input: its records lent, not copied, on their way to the tables.
        let notes = logs::write_dataset(dir, decoder.decoder(), partitioning, tables, |sink| {
            pump.run_lent(&name, input, Skip::NonLogLines, sink)
        })?;
        pump.progress.finish();
        writeln!(
            out,
            "{} frames decoded into {}; {}",
            pump.frames,
            dir.display(),
            notes.join("; ")
        )?;
        return Ok(());
    }
    let records = logs::records(&name, input, Skip::NonLogLines);
    // Rows written in blocks (standard output would take a write per line), flushed at least
    // every 100 ms so a live bus piped in shows as it comes; each frame's rows built in one
    // reused line, its time and channel formatted once.
    let mut out = std::io::BufWriter::with_capacity(1 << 16, out);
    let mut flushed = std::time::Instant::now();
    writeln!(out, "ts,channel,message,signal,value,choice,unit")?;
    let choices = !args.no_decode_choices;
    let mut rows = String::new();
    // Each message's name and its signals' names and units as CSV fields, made once.
    let fields: Vec<(String, Vec<(String, String)>)> = decoder
        .decoder()
        .database()
        .messages
        .iter()
        .map(|m| {
            let signals = m
                .signals
                .iter()
                .map(|s| {
                    (
                        csv_field(s.display_name()).into_owned(),
                        csv_field(&s.unit).into_owned(),
                    )
                })
                .collect();
            (csv_field(m.display_name()).into_owned(), signals)
        })
        .collect();
    let mut values = Vec::new();
    let mut prefix = String::new();
    pump.run(records, |record| {
        // A frame that does not decode whole gives the rows of the signals it did decode.
        let Some((index, message, _)) = decoder.decoder().decode_into(&record.frame, &mut values)
        else {
            return Ok(());
        };
        let Some((message_field, signal_fields)) = fields.get(index) else {
            return Ok(());
        };
        let ts =
            bywire_log::candump::timestamp_text(record.timestamp, bywire_log::Precision::Nanos);
        prefix.clear();
        {
            use std::fmt::Write as _;
            // (Writing to a String cannot fail.)
            let _ = write!(prefix, "{ts},");
        }
        prefix.push_str(&csv_field(&record.interface));
        prefix.push(',');
        rows.clear();
        // A container frame: each PDU's rows under the PDU's name.
        if let Some(pdus) = decoder.decoder().contained(index, record.frame.data()) {
            let channel = prefix.clone();
            for pdu in pdus.flatten() {
                let Some((pdu_message, codec, _)) = pdu.message else {
                    continue;
                };
                let mut pdu_values = vec![None; codec.signal_count()];
                if codec.decode(pdu.pdu.data, &mut pdu_values).is_err() {
                    continue;
                }
                prefix.clear();
                prefix.push_str(&channel);
                prefix.push_str(&csv_field(pdu_message.display_name()));
                prefix.push(',');
                for (signal, value) in pdu_message.signals.iter().zip(&pdu_values) {
                    let Some(value) = value else { continue };
                    let value = crate::support::signals::SignalValue {
                        signal,
                        value: *value,
                    };
                    push_row(
                        &mut rows,
                        &prefix,
                        &value,
                        choices,
                        (&csv_field(signal.display_name()), &csv_field(&signal.unit)),
                    );
                }
            }
            out.write_all(rows.as_bytes())?;
            return Ok(());
        }
        prefix.push_str(message_field);
        prefix.push(',');
        for ((signal, value), (name, unit)) in
            message.signals.iter().zip(&values).zip(signal_fields)
        {
            let Some(value) = value else { continue };
            let value = crate::support::signals::SignalValue {
                signal,
                value: *value,
            };
            push_row(&mut rows, &prefix, &value, choices, (name, unit));
        }
        out.write_all(rows.as_bytes())?;
        if flushed.elapsed() >= std::time::Duration::from_millis(100) {
            out.flush()?;
            flushed = std::time::Instant::now();
        }
        Ok(())
    })?;
    out.flush()?;
    pump.progress.finish();
    Ok(())
}

/// One `decode --csv` row: the frame's `prefix` (time, channel, message), then the signal's
/// CSV-ready name, value, value name and unit.
fn push_row(
    rows: &mut String,
    prefix: &str,
    value: &crate::support::signals::SignalValue<'_>,
    choices: bool,
    (name, unit): (&str, &str),
) {
    let described = choices && !value.signal.value_descriptions.is_empty();
    let choice = described
        .then(|| value.description())
        .flatten()
        .unwrap_or("");
    rows.push_str(prefix);
    rows.push_str(name);
    rows.push(',');
    crate::support::signals::push_number_text(rows, value.value.physical);
    rows.push(',');
    rows.push_str(&csv_field(choice));
    rows.push(',');
    rows.push_str(unit);
    rows.push('\n');
}

/// A CSV field, quoted (RFC 4180) when it holds a comma, a quote or a line break.
fn csv_field(text: &str) -> std::borrow::Cow<'_, str> {
    // (Bytes, not chars: the four are ASCII, and this runs for every field of every row.)
    if text
        .bytes()
        .any(|b| matches!(b, b',' | b'"' | b'\n' | b'\r'))
    {
        format!("\"{}\"", text.replace('"', "\"\"")).into()
    } else {
        text.into()
    }
}
