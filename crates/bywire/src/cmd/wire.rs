use std::io::Write;

use anyhow::{Context, Result};
use bywire_core::wire::{self, WireFrame};
use bywire_core::Frame;
use serde::Serialize;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  bywire wire 123#DEADBEEF --bitrate 500000\n  bywire wire 1ABCDEF0##1112233 --bitrate 500000 --dbitrate 2000000 --json\n\nStuff bits are shown in brackets; 0 is dominant, 1 recessive."
)]
pub struct Args {
    /// The frame in can-utils form: 123#DEADBEEF, 123#R, 1ABCDEF0#, 123##1DEADBEEF.
    frame: String,
    /// Nominal bitrate in bit/s.
    #[arg(long, default_value_t = 500_000)]
    bitrate: u32,
    /// Data-phase bitrate in bit/s for FD frames with BRS.
    #[arg(long)]
    dbitrate: Option<u32>,
    /// Leave the ACK slot recessive (as a transmitter alone on the bus sees it).
    #[arg(long)]
    no_ack: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct FieldJson {
    field: &'static str,
    start: usize,
    len: usize,
}

#[derive(Serialize)]
struct WireJson {
    frame: String,
    bits: String,
    length_bits: usize,
    stuff_bits: usize,
    dynamic_stuff_bits: usize,
    fixed_stuff_bits: usize,
    stuff_positions: Vec<usize>,
    crc: u32,
    crc_width: u8,
    time_ns: f64,
    fields: Vec<FieldJson>,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let frame: Frame = args
        .frame
        .parse()
        .with_context(|| format!("cannot read frame '{}'", args.frame))?;
    anyhow::ensure!(args.bitrate > 0, "--bitrate must be above 0");
    anyhow::ensure!(args.dbitrate != Some(0), "--dbitrate must be above 0");
    let w = wire::encode_with_ack(&frame, !args.no_ack)?;
    let time_ns = w.time_ns(args.bitrate, args.dbitrate);
    if args.json {
        let json = WireJson {
            frame: frame.to_string(),
            bits: w.bits().to_string(),
            length_bits: w.len(),
            stuff_bits: w.stuff_bits(),
            dynamic_stuff_bits: w.dynamic_stuff_bits(),
            fixed_stuff_bits: w.fixed_stuff_bits(),
            stuff_positions: (0..w.len()).filter(|&i| w.is_stuff_bit(i)).collect(),
            crc: w.crc(),
            crc_width: w.crc_width(),
            time_ns,
            fields: w
                .spans()
                .iter()
                .map(|s| FieldJson {
                    field: s.field.name(),
                    start: s.start,
                    len: s.len,
                })
                .collect(),
        };
        serde_json::to_writer(&mut *out, &json)?;
        writeln!(out)?;
        return Ok(());
    }
    print_human(&frame, &w, args, time_ns, out)
}

fn print_human(
    frame: &Frame,
    w: &WireFrame,
    args: &Args,
    time_ns: f64,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(out, "frame   {frame}")?;
    for span in w.spans() {
        let mut levels = String::new();
        for i in span.start..span.start + span.len {
            let level = if w.bits().get(i) == Some(true) {
                '1'
            } else {
                '0'
            };
            if w.is_stuff_bit(i) {
                levels.push('[');
                levels.push(level);
                levels.push(']');
            } else {
                levels.push(level);
            }
        }
        writeln!(out, "  {:<8}{levels}", span.field.name())?;
    }
    writeln!(
        out,
        "length  {} bits SOF..EOF ({} stuff: {} dynamic, {} fixed), +3 interframe",
        w.len(),
        w.stuff_bits(),
        w.dynamic_stuff_bits(),
        w.fixed_stuff_bits()
    )?;
    let width = usize::from(w.crc_width()).div_ceil(4);
    writeln!(
        out,
        "crc     0x{:0width$X} (CRC-{})",
        w.crc(),
        w.crc_width()
    )?;
    let rate = match args.dbitrate {
        Some(d) if w.data_phase_bits() > 0 => format!(
            "{} bit/s, {} data-phase bits at {d} bit/s",
            args.bitrate,
            w.data_phase_bits()
        ),
        _ => format!("{} bit/s", args.bitrate),
    };
    writeln!(out, "time    {:.3} µs at {rate}", time_ns / 1000.0)?;
    Ok(())
}
