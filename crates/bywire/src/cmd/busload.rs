//! `bywire busload`: canbusload — bus load per second per bus, optionally per identifier and
//! beside the load a DBC's cycle times predict.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Result};
use bywire_core::busload::{
    frame_bits, predicted_load, Bitrates, LoadMeter, LoadReport, PeriodicMessage, Stuffing,
};
use bywire_core::{Frame, Timestamp};
use bywire_dbc::codec::EncodeMode;

use crate::support::busarg::{self, BusArg, Readers};
use crate::support::interrupt::interrupt_flag;
use crate::support::signals::Dbc;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire busload can0@500000
  bywire busload -e -t can0@500000 can1@250000
  bywire busload -e --per-id vcan0@500000
  bywire busload -e --dbc vehicle.dbc can0@500000     (measured beside predicted)
  bywire busload can0@500000,2000000                  (FD: data bitrate after the comma)

Each second, per bus: frames, bits on the bus (stuffing as chosen), payload bits and the load
in percent, as canbusload prints them. Without -e or -i the worst-case stuffing is counted.
Frames a bus's receive queue dropped (the kernel's count, on SocketCAN) are not in the figures;
how many is said on stderr at the end.")]
pub struct Args {
    /// Buses with their bitrate: BUS@BITRATE[,DATA_BITRATE]
    #[arg(required = true, num_args = 1..=16)]
    buses: Vec<String>,
    /// Count stuff bits exactly from each frame's content.
    #[arg(short = 'e', conflicts_with = "ignore_stuffing")]
    exact: bool,
    /// Count no stuff bits.
    #[arg(short = 'i')]
    ignore_stuffing: bool,
    /// Print the time and the stuffing mode above each report.
    #[arg(short = 't')]
    time: bool,
    /// Show a bar graph in 5 % steps.
    #[arg(short = 'b')]
    bargraph: bool,
    /// Redraw the terminal for each report (like top).
    #[arg(short = 'r')]
    redraw: bool,
    /// Also show each identifier's share.
    #[arg(long)]
    per_id: bool,
    /// Show the load this DBC's cycle times predict beside the measured one.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
    /// Stop after this many reports.
    #[arg(short = 'n', value_name = "REPORTS")]
    reports: Option<u64>,
}

/// One bus: the load meter (one-second windows on the clock of this run) and the frames and
/// bits per identifier in the current second.
struct Meter {
    arg: BusArg,
    rates: Bitrates,
    load: LoadMeter,
    per_id: BTreeMap<u32, (u64, u64)>,
    predicted: Option<f64>,
}

fn parse_bus(text: &str) -> Result<(BusArg, Bitrates)> {
    let (bus, rates) = text
        .rsplit_once('@')
        .ok_or_else(|| anyhow!("bus '{text}': expected BUS@BITRATE, e.g. can0@500000"))?;
    let (nominal, data) = match rates.split_once(',') {
        Some((n, d)) => (n, Some(d)),
        None => (rates, None),
    };
    let rate = |s: &str| {
        s.parse::<u32>()
            .ok()
            .filter(|r| (1..=20_000_000).contains(r))
            .ok_or_else(|| anyhow!("bus '{text}': bitrate '{s}' is not 1 to 20000000 bit/s"))
    };
    let rates = Bitrates {
        nominal: rate(nominal)?,
        data: data.map(rate).transpose()?,
    };
    Ok((busarg::parse(bus)?, rates))
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let stuffing = if args.exact {
        Stuffing::Exact
    } else if args.ignore_stuffing {
        Stuffing::None
    } else {
        Stuffing::WorstCase
    };
    let dbc = match &args.dbc {
        Some(path) => Some(Dbc::new(crate::support::dbc::load(path, false)?)),
        None => None,
    };
    let mut meters = Vec::new();
    let second = Duration::from_secs(1);
    for text in &args.buses {
        let (arg, rates) = parse_bus(text)?;
        let predicted = dbc.as_ref().map(|d| predict(d, rates, stuffing));
        meters.push(Meter {
            arg,
            rates,
            load: LoadMeter::new(rates, second, stuffing).starting_at(Timestamp::ZERO),
            per_id: BTreeMap::new(),
            predicted,
        });
    }
    let args_only: Vec<BusArg> = meters.iter().map(|m| m.arg.clone()).collect();
    let readers = Readers::start(busarg::open_all(&args_only)?);
    let stop = interrupt_flag();
    if args.redraw {
        write!(out, "\x1b[2J")?;
    }
    let start = Instant::now();
    // The meters' clock: nanoseconds since the start.
    let since_start = |at: Instant| {
        Timestamp::from_nanos(
            u64::try_from(at.saturating_duration_since(start).as_nanos()).unwrap_or(u64::MAX),
        )
    };
    let mut next = start + second;
    let mut reports = 0u64;
    while !stop.load(Ordering::Relaxed) && args.reports.is_none_or(|n| reports < n) {
        match readers
            .events
            .recv_timeout(next.saturating_duration_since(Instant::now()))
        {
            Ok((index, event)) => {
                let received = event.map_err(|e| anyhow!("bus {}: {e}", index))?;
                if let Some(meter) = meters.get_mut(index) {
                    // A frame that arrives as the second ends counts in the next one.
                    let last_of_second =
                        Timestamp::from_nanos(since_start(next).as_nanos().saturating_sub(1));
                    let now = since_start(Instant::now()).min(last_of_second);
                    meter.load.record(now, &received.frame);
                    count_id(meter, &received.frame, stuffing);
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                let end =
                    Timestamp::from_nanos(u64::try_from((next - start).as_nanos()).unwrap_or(0));
                report(args, stuffing, &mut meters, end, out)?;
                reports += 1;
                next += second;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    // Frames a bus's receive queue dropped (the kernel's count, for SocketCAN) are missing
    // from the figures: said, so that a load measured low is not taken for the bus's.
    for (meter, dropped) in meters.iter().zip(&readers.dropped) {
        let dropped = dropped.load(Ordering::Relaxed);
        if dropped > 0 {
            let _ = writeln!(
                std::io::stderr(),
                "{}: {dropped} frames dropped before they reached the meter (not counted)",
                meter.arg.name
            );
        }
    }
    Ok(())
}

/// The frame's share of its identifier's line (`--per-id`).
fn count_id(meter: &mut Meter, frame: &Frame, stuffing: Stuffing) {
    let bits = u64::from(frame_bits(frame, stuffing));
    if bits == 0 {
        return; // error frames are reports, not traffic
    }
    let entry = meter.per_id.entry(frame.socketcan_id()).or_default();
    entry.0 += 1;
    entry.1 += bits;
}

/// Load in whole percent as canbusload computes it (bits in the second over the bitrate), or
/// from the frames' time on the bus when FD frames switch to a data bitrate.
fn percent(rates: Bitrates, second: &LoadReport) -> u64 {
    if rates.data.is_some() {
        // Non-negative and far below 2^64 per second.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let p = (second.busy_ns / 1e7) as u64;
        p
    } else {
        second.bits * 100 / u64::from(rates.nominal)
    }
}

fn report(
    args: &Args,
    stuffing: Stuffing,
    meters: &mut [Meter],
    end: Timestamp,
    out: &mut impl Write,
) -> Result<()> {
    if args.redraw {
        write!(out, "\x1b[H")?;
    }
    if args.time {
        let mode = match stuffing {
            Stuffing::Exact => "exact bitstuffing",
            Stuffing::None => "ignore bitstuffing",
            Stuffing::WorstCase => "worst case bitstuffing",
        };
        writeln!(
            out,
            "bywire busload {} ({mode})",
            chrono::Local::now().format("%Y-%m-%d %H:%M:%S")
        )?;
    }
    let name_width = meters.iter().map(|m| m.arg.name.len()).max().unwrap_or(0);
    let rate_width = meters
        .iter()
        .map(|m| m.rates.nominal.to_string().len())
        .max()
        .unwrap_or(0);
    for meter in meters.iter_mut() {
        let Some(second) = meter.load.advance(end) else {
            continue;
        };
        let per_id = std::mem::take(&mut meter.per_id);
        let load = percent(meter.rates, &second);
        write!(
            out,
            " {:>name_width$}@{:<rate_width$} {:5} {:7} {:6} {:3}%",
            meter.arg.name,
            meter.rates.nominal,
            second.frames,
            second.bits,
            second.payload_bits,
            load
        )?;
        if args.bargraph {
            let filled = usize::try_from(load.min(100) / 5).unwrap_or(20);
            write!(out, " |{}{}|", "X".repeat(filled), ".".repeat(20 - filled))?;
        }
        writeln!(out)?;
        if let Some(predicted) = meter.predicted {
            writeln!(
                out,
                "   predicted from the DBC's cycle times: {predicted:.1}%"
            )?;
        }
        if args.per_id {
            for (id, (frames, bits)) in &per_id {
                let id_text = if id & bywire_core::frame::EFF_FLAG != 0 {
                    format!("{:08X}", id & bywire_core::frame::EFF_MASK)
                } else {
                    format!("{:03X}", id & bywire_core::frame::SFF_MASK)
                };
                // Each identifier's bits over the nominal bitrate (FD data phases counted slow).
                let share = bits * 100 / u64::from(meter.rates.nominal);
                writeln!(out, "   {id_text:>8} {frames:5} {bits:7} {share:3}%")?;
            }
        }
    }
    writeln!(out)?;
    out.flush()?;
    Ok(())
}

/// The load the DBC's cyclic messages cause at these bitrates, each frame as encoded with its
/// start values.
fn predict(dbc: &Dbc, rates: Bitrates, stuffing: Stuffing) -> f64 {
    let messages: Vec<PeriodicMessage> = dbc
        .decoder()
        .database()
        .messages
        .iter()
        .filter_map(|m| {
            let period = dbc.decoder().cycle_time(m)?;
            let frame = dbc.encode(m, &[], 0, EncodeMode::Clamp).ok()?;
            Some(PeriodicMessage {
                period,
                bits: frame_bits(&frame, stuffing),
            })
        })
        .collect();
    predicted_load(&messages, rates.nominal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn predicts_from_cycle_times_with_each_frames_own_length() {
        let text =
            "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 10000;\nBA_DEF_DEF_ \"GenMsgCycleTime\" 0;\n\
                    BO_ 256 Fast: 8 ECU\n SG_ A : 0|8@1+ (1,0) [0|255] \"\" X\n\
                    BO_ 257 Slow: 2 ECU\n SG_ B : 0|8@1+ (1,0) [0|255] \"\" X\n\
                    BO_ 258 Never: 8 ECU\n SG_ C : 0|8@1+ (1,0) [0|255] \"\" X\n\
                    BA_ \"GenMsgCycleTime\" BO_ 256 10;\nBA_ \"GenMsgCycleTime\" BO_ 257 100;\n";
        let db = bywire_dbc::parse(text.as_bytes(), bywire_dbc::Mode::Strict)
            .unwrap()
            .0;
        let dbc = Dbc::new(db);
        let rates = Bitrates {
            nominal: 500_000,
            data: None,
        };
        let fast: Frame = "100#0000000000000000".parse().unwrap();
        let slow: Frame = "101#0000".parse().unwrap();
        for stuffing in [Stuffing::Exact, Stuffing::None, Stuffing::WorstCase] {
            let bits_per_second = f64::from(frame_bits(&fast, stuffing)) * 100.0
                + f64::from(frame_bits(&slow, stuffing)) * 10.0;
            let expected = 100.0 * bits_per_second / 500_000.0;
            assert!(
                (predict(&dbc, rates, stuffing) - expected).abs() < 1e-9,
                "{stuffing:?}"
            );
        }
        // 8 zero bytes at 10 ms: 100 frames/s of 111 + stuff bits.
        assert!(predict(&dbc, rates, Stuffing::Exact) > 2.2);
    }
}
