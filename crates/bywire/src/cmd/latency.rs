//! `bywire latency`: latency of a drive-by-wire chain — from logs (`bywire_data::latency`),
//! or, with `--predict`, the worst case from a DBC alone (`bywire_dbc::schedule`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{ensure, Result};
use bywire_core::busload::Bitrates;
use bywire_core::schedule::Unbounded;
use bywire_core::Id;
use bywire_dbc::schedule::{self, MessageSchedule, Schedule};
use serde::Serialize;

use crate::support::{dbc, numbers};

mod logs;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire latency bus1.log --profile reference-tug
  bywire latency bus1.log bus1b.log --profile reference-tug --transfer bus1b=bus1 --json
  bywire latency drive.blf --dbc vehicle.dbc --echo Cmd.Counter=State.Echo \\
      --response Cmd.SteerAngle=State.SteerAngle
  bywire latency --predict vehicle.dbc --bitrate 500000
  bywire latency --predict vehicle.dbc --bitrate 500000 --dbitrate 2000000 --jitter 0.5 --json
  bywire latency --predict tug.dbc --bitrate 500000 --senders IMU,IO   (one bus of a shared DBC)

--predict: each message's worst-case response time (queuing jitter + waiting + its own frame)
by the revised CAN schedulability analysis (Davis, Burns, Bril, Lukkien 2007): one
lower-priority frame already on the bus, every higher-priority frame queued meanwhile, the
message's own earlier frames in the busy period, each frame at its longest stuffed length.
Periods from GenMsgCycleTime; spontaneous messages (GenMsgSendType) use GenMsgDelayTime as their
minimum interval; deadlines from GenMsgDeadline, else the cycle time; GenMsgJitter overrides
--jitter (all in ms). Bus errors are not counted. Exit status 1 when a message can miss its
deadline or could not be analysed, with --strict.

From logs (any format, several merged in time order): the command's heartbeat counter to its
echo in the feedback; each setpoint step to the actual value's 10/50/90 % crossings (the
10 % one is the dead time), rise, settling and overshoot; every message's cycle time, jitter
and late gaps against the DBC's GenMsgCycleTime; and, with --transfer, how long a frame takes
from one channel to another (the same identifier and data). A profile names the echo and the
steering and speed pairs by role.")]
pub struct Args {
    /// Logs to analyse (candump, ASC, BLF, TRC, pcapng, MCAP, MF4, Parquet).
    #[arg(conflicts_with = "predict")]
    logs: Vec<PathBuf>,
    /// A vehicle profile (built in, e.g. reference-tug, or a TOML file): its DBC, the
    /// command's counter and echo, and the steering and speed setpoint/actual pairs.
    #[arg(long, conflicts_with = "dbc")]
    profile: Option<String>,
    /// The DBC of the logs (without a profile).
    #[arg(long)]
    dbc: Option<PathBuf>,
    /// COMMAND.COUNTER=FEEDBACK.ECHO: the counter and its echo.
    #[arg(long, value_name = "CMD.SIGNAL=FB.SIGNAL")]
    echo: Option<String>,
    /// SETPOINT=ACTUAL (MESSAGE.SIGNAL each): measure the actual's response to each setpoint
    /// step. Repeatable; replaces the profile's pairs.
    #[arg(long, value_name = "MSG.SIGNAL=MSG.SIGNAL")]
    response: Vec<String>,
    /// The smallest setpoint change that is a step (in the setpoint's unit).
    #[arg(long, default_value_t = 0.5)]
    step_min: f64,
    /// Longest a step's response is followed, s (it ends sooner at the next step).
    #[arg(long, default_value = "5", value_parser = numbers::positive_seconds)]
    step_window: f64,
    /// FROM=TO: channels between which identical frames are matched. Repeatable.
    #[arg(long, value_name = "FROM=TO")]
    transfer: Vec<String>,
    /// Longest an echo or a transfer may take to count, ms.
    #[arg(long, default_value = "1000", value_parser = numbers::milliseconds)]
    window: f64,
    /// Draw the latency histograms (echo, transfers) to this .png or .svg.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Predict from this DBC's messages (no bus, no log).
    #[arg(long, value_name = "DBC", requires = "bitrate")]
    predict: Option<PathBuf>,
    /// Nominal bitrate in bit/s (with --predict).
    #[arg(long)]
    bitrate: Option<u32>,
    /// Data-phase bitrate in bit/s, for FD messages with bit rate switching.
    #[arg(long)]
    dbitrate: Option<u32>,
    /// Queuing jitter of every message without a GenMsgJitter, in ms.
    #[arg(long, default_value = "0", value_parser = numbers::milliseconds)]
    jitter: f64,
    /// Only the messages these nodes send (comma-separated).
    #[arg(long, value_delimiter = ',')]
    senders: Vec<String>,
    /// Only these messages, by name or hex identifier (comma-separated).
    #[arg(long, value_delimiter = ',')]
    messages: Vec<String>,
    /// Fail (exit status 1) when a message can miss its deadline or was left out.
    #[arg(long)]
    strict: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct MessageJson<'a> {
    name: &'a str,
    id: String,
    extended: bool,
    frame_us: f64,
    period_ms: f64,
    sporadic: bool,
    jitter_ms: f64,
    deadline_ms: f64,
    worst_case_us: Option<f64>,
    blocking_us: Option<f64>,
    queuing_us: Option<f64>,
    busy_period_us: Option<f64>,
    instances_in_busy_period: Option<u64>,
    meets_deadline: bool,
    no_bound: Option<&'static str>,
}

#[derive(Serialize)]
struct LeftOutJson<'a> {
    name: &'a str,
    id: String,
    reason: &'a str,
}

#[derive(Serialize)]
struct ScheduleJson<'a> {
    bitrate: u32,
    data_bitrate: Option<u32>,
    jitter_ms: f64,
    utilisation_percent: f64,
    misses: usize,
    messages: Vec<MessageJson<'a>>,
    left_out: Vec<LeftOutJson<'a>>,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    match (&args.predict, args.bitrate) {
        (Some(predict), Some(bitrate)) => run_predict(args, predict, bitrate, out),
        _ => logs::run(args, out),
    }
}

fn run_predict(args: &Args, predict: &Path, bitrate: u32, out: &mut impl Write) -> Result<()> {
    ensure!(bitrate > 0, "--bitrate must be above 0");
    ensure!(args.dbitrate != Some(0), "--dbitrate must be above 0");
    let db = dbc::load(predict, false)?;
    for name in &args.senders {
        ensure!(
            db.messages
                .iter()
                .any(|m| m.transmitter == *name || m.senders.contains(name)),
            "--senders: no message of {} is sent by '{name}'",
            predict.display()
        );
    }
    let wanted_ids: Vec<Option<u32>> = args
        .messages
        .iter()
        .map(|name| numbers::hex::<u32>(name))
        .collect();
    for (name, id) in args.messages.iter().zip(&wanted_ids) {
        ensure!(
            db.messages
                .iter()
                .any(|m| m.name == *name || Some(m.id) == *id),
            "--messages: {} has no message '{name}'",
            predict.display()
        );
    }
    let selected = |m: &bywire_dbc::Message| {
        let by_sender = args.senders.is_empty()
            || args
                .senders
                .iter()
                .any(|s| m.transmitter == *s || m.senders.contains(s));
        let by_name = args.messages.is_empty()
            || args
                .messages
                .iter()
                .zip(&wanted_ids)
                .any(|(name, id)| m.name == *name || Some(m.id) == *id);
        by_sender && by_name
    };
    let options = schedule::Options {
        rates: Bitrates {
            nominal: bitrate,
            data: args.dbitrate,
        },
        jitter: Duration::from_secs_f64(args.jitter / 1e3),
    };
    let result = schedule::analyse(&db, selected, options);
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &to_json(args, bitrate, &result))?;
        writeln!(out)?;
    } else {
        print_table(args, predict, bitrate, &result, out)?;
    }
    let misses = result.misses().count();
    if args.strict {
        ensure!(
            misses == 0 && result.skipped.is_empty(),
            "{misses} message(s) can miss their deadline, {} left out",
            result.skipped.len()
        );
    }
    Ok(())
}

fn id_text(id: Id) -> String {
    match id {
        Id::Standard(_) => format!("0x{:03X}", id.as_raw()),
        Id::Extended(_) => format!("0x{:08X}", id.as_raw()),
    }
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1e3
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

fn no_bound_text(why: Unbounded) -> &'static str {
    match why {
        Unbounded::Overloaded => "overloaded: its level needs 100 % of the bus or more",
        Unbounded::TooLong => "its busy period did not end within the analysis's step budget",
        Unbounded::SharedIdentifier => "another message has its identifier",
        Unbounded::NoPeriod => "no period",
    }
}

fn to_json<'a>(args: &Args, bitrate: u32, result: &'a Schedule) -> ScheduleJson<'a> {
    let message = |m: &'a MessageSchedule| {
        let ok = m.outcome.ok();
        MessageJson {
            name: &m.name,
            id: id_text(m.id),
            extended: m.id.is_extended(),
            frame_us: us(m.frame_ns),
            period_ms: ms(m.period_ns),
            sporadic: m.sporadic,
            jitter_ms: ms(m.jitter_ns),
            deadline_ms: ms(m.deadline_ns),
            worst_case_us: ok.map(|r| us(r.worst_ns)),
            blocking_us: ok.map(|r| us(r.blocking_ns)),
            queuing_us: ok.map(|r| us(r.queuing_ns)),
            busy_period_us: ok.map(|r| us(r.busy_period_ns)),
            instances_in_busy_period: ok.map(|r| r.instances),
            meets_deadline: m.meets_deadline(),
            no_bound: m.outcome.err().map(no_bound_text),
        }
    };
    ScheduleJson {
        bitrate,
        data_bitrate: args.dbitrate,
        jitter_ms: args.jitter,
        utilisation_percent: result.utilisation,
        misses: result.misses().count(),
        messages: result.messages.iter().map(message).collect(),
        left_out: result
            .skipped
            .iter()
            .map(|s| LeftOutJson {
                name: &s.name,
                id: format!("0x{:X}", s.raw_id & 0x1FFF_FFFF),
                reason: &s.reason,
            })
            .collect(),
    }
}

fn print_table(
    args: &Args,
    predict: &Path,
    bitrate: u32,
    result: &Schedule,
    out: &mut impl Write,
) -> Result<()> {
    let data = args
        .dbitrate
        .map(|d| format!(", data phase {d} bit/s"))
        .unwrap_or_default();
    writeln!(
        out,
        "{} at {} bit/s{data}: {} messages, worst-case utilisation {:.1} %, {} can miss their deadline",
        predict.display(),
        bitrate,
        result.messages.len(),
        result.utilisation,
        result.misses().count()
    )?;
    writeln!(
        out,
        "{:<10} {:<32} {:>9} {:>10} {:>9} {:>11} {:>11} {:>10}  verdict",
        "id",
        "message",
        "frame µs",
        "period ms",
        "jitter ms",
        "deadline ms",
        "blocking µs",
        "worst µs"
    )?;
    for m in &result.messages {
        let period = format!(
            "{}{:.3}",
            if m.sporadic { "≥" } else { "" },
            ms(m.period_ns)
        );
        let (blocking, worst, verdict) = match m.outcome {
            Ok(r) => (
                format!("{:.1}", us(r.blocking_ns)),
                format!("{:.1}", us(r.worst_ns)),
                if m.meets_deadline() {
                    format!(
                        "ok, {:.1} µs to spare",
                        us(m.deadline_ns.saturating_sub(r.worst_ns))
                    )
                } else {
                    format!(
                        "MISS by {:.1} µs",
                        us(r.worst_ns.saturating_sub(m.deadline_ns))
                    )
                },
            ),
            Err(why) => (
                "-".into(),
                "-".into(),
                format!("MISS: {}", no_bound_text(why)),
            ),
        };
        writeln!(
            out,
            "{:<10} {:<32} {:>9.1} {:>10} {:>9.3} {:>11.3} {:>11} {:>10}  {verdict}",
            id_text(m.id),
            m.name,
            us(m.frame_ns),
            period,
            ms(m.jitter_ns),
            ms(m.deadline_ns),
            blocking,
            worst,
        )?;
    }
    for s in &result.skipped {
        writeln!(
            out,
            "left out: {} (0x{:X}): {}",
            s.name,
            s.raw_id & 0x1FFF_FFFF,
            s.reason
        )?;
    }
    if !result.skipped.is_empty() {
        writeln!(
            out,
            "The bounds above do not hold while the messages left out are sent."
        )?;
    }
    Ok(())
}
