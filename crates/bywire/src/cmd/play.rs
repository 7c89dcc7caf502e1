//! `bywire play`: canplayer — replay candump logs onto buses, in real time or faster.

use std::collections::HashMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_bus::Bus;
use bywire_log::LogRecord;

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::logs::{self, Skip};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire play -I candump-2024-01-01_120000.log
  bywire play -I drive.log vcan0=can0              (frames logged on can0 go to vcan0)
  bywire play -I drive.log virtual:test=can0 --speed 10
  bywire play -I drive.log -t -g 5 -l 3            (ignore timestamps, 5 ms apart, 3 times)
  bywire play -I drive.log stdout=can0             (print can0's lines instead of sending)

Without assignments each frame goes to the interface it was logged on. With assignments only
the assigned interfaces are replayed. Lines not starting with '(' are ignored, as canplayer
does; a malformed log line is an error naming its line (a file is checked before anything is
sent).")]
pub struct Args {
    /// Assignments WRITE-BUS=LOG-INTERFACE (WRITE-BUS may be stdout).
    assignments: Vec<String>,
    /// The log file (standard input when not given).
    #[arg(short = 'I', value_name = "FILE")]
    input: Option<PathBuf>,
    /// Play the log this many times, or i for ever.
    #[arg(short = 'l', default_value = "1")]
    loops: String,
    /// Ignore the timestamps: send frames one gap apart.
    #[arg(short = 't')]
    ignore_timestamps: bool,
    /// The gap in milliseconds with -t.
    #[arg(short = 'g', default_value_t = 1.0, value_parser = crate::support::numbers::milliseconds)]
    gap_ms: f64,
    /// Skip gaps in the timestamps longer than this many seconds.
    #[arg(short = 's', value_name = "SECONDS", value_parser = crate::support::numbers::positive_seconds)]
    skip_gaps: Option<f64>,
    /// Stop after this many frames.
    #[arg(short = 'n')]
    count: Option<u64>,
    /// Do not loop sent frames back to other programs on this host.
    #[arg(short = 'x')]
    no_loopback: bool,
    /// Play this many times faster than recorded (0.5 = half speed).
    #[arg(long, default_value_t = 1.0, value_parser = crate::support::numbers::factor)]
    speed: f64,
    /// Print each frame sent as a log line.
    #[arg(short = 'v')]
    verbose: bool,
}

/// Where frames from one logged interface go.
enum Target {
    Bus(Box<dyn Bus>),
    Stdout,
}

/// The log's records, any format; in candump logs, lines that do not start with '(' are
/// skipped as canplayer skips them.
fn log_records(path: Option<&PathBuf>) -> Result<Vec<(String, logs::LogInput)>> {
    logs::inputs(path.map(std::slice::from_ref).unwrap_or_default())
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let loops = match args.loops.as_str() {
        "i" => None,
        n => Some(
            n.parse::<u64>()
                .map_err(|_| anyhow!("-l '{n}': expected a number or i"))?,
        ),
    };
    if args.input.is_none() && loops != Some(1) {
        return Err(anyhow!(
            "-l needs a file (-I): standard input cannot be read twice"
        ));
    }
    let mut assigned: HashMap<String, String> = HashMap::new();
    for a in &args.assignments {
        let (write, log) = a
            .split_once('=')
            .filter(|(w, l)| !w.is_empty() && !l.is_empty())
            .ok_or_else(|| anyhow!("assignment '{a}': expected WRITE-BUS=LOG-INTERFACE"))?;
        assigned.insert(log.to_string(), write.to_string());
    }
    // A file is checked whole first, so a bad line stops the replay before it starts.
    if let Some(path) = &args.input {
        for (name, input) in log_records(Some(path))? {
            for record in logs::records(&name, input, Skip::NonLogLines) {
                record?;
            }
        }
    }
    let mut targets: HashMap<String, Option<Target>> = HashMap::new();
    let stop = interrupt_flag();
    let mut sent = 0u64;
    let mut pass = 0u64;
    while loops.is_none_or(|n| pass < n) {
        pass += 1;
        let Some((name, input)) = log_records(args.input.as_ref())?.into_iter().next() else {
            return Ok(());
        };
        let reader = logs::records(&name, input, Skip::NonLogLines);
        let mut pacer = bywire_log::pacing::Pacer::new(args.speed);
        if let Some(limit) = args.skip_gaps {
            pacer = pacer.skipping_gaps_over(Duration::from_secs_f64(limit));
        }
        let mut start: Option<Instant> = None;
        for record in reader {
            let record = record?;
            if stop.load(Ordering::Relaxed) || args.count.is_some_and(|n| sent >= n) {
                return Ok(());
            }
            let start = *start.get_or_insert_with(Instant::now);
            let offset = pacer.due(record.timestamp);
            let due = (!args.ignore_timestamps).then(|| start + offset);
            let Some(target) = target_for(&record, &assigned, &mut targets, args.no_loopback)?
            else {
                continue;
            };
            match due {
                Some(due) => std::thread::sleep(due.saturating_duration_since(Instant::now())),
                None if sent > 0 => {
                    std::thread::sleep(Duration::from_secs_f64(args.gap_ms / 1000.0));
                }
                None => {}
            }
            match target {
                Target::Stdout => print_record(out, &record)?,
                Target::Bus(bus) => {
                    bus.send(&record.frame).with_context(|| {
                        format!(
                            "cannot send {} (logged on {})",
                            record.frame, record.interface
                        )
                    })?;
                    if args.verbose {
                        print_record(out, &record)?;
                    }
                }
            }
            sent += 1;
        }
    }
    Ok(())
}

fn print_record(out: &mut impl Write, record: &LogRecord) -> Result<()> {
    let mut writer = bywire_log::Writer::new(&mut *out).raw_dlc(true);
    writer.write_record(record)?;
    Ok(out.flush()?)
}

/// The bus for a record's interface, opened on first use; `None` when it is not replayed.
fn target_for<'a>(
    record: &LogRecord,
    assigned: &HashMap<String, String>,
    targets: &'a mut HashMap<String, Option<Target>>,
    no_loopback: bool,
) -> Result<Option<&'a mut Target>> {
    if !targets.contains_key(&record.interface) {
        let write_bus = if assigned.is_empty() {
            Some(record.interface.clone())
        } else {
            assigned.get(&record.interface).cloned()
        };
        let target = match write_bus {
            None => None,
            Some(name) if name == "stdout" => Some(Target::Stdout),
            Some(name) => {
                let mut bus = busarg::open(&name).with_context(|| format!("bus '{name}'"))?;
                if no_loopback {
                    bus.set_loopback(false)?;
                }
                Some(Target::Bus(bus))
            }
        };
        targets.insert(record.interface.clone(), target);
    }
    Ok(targets.get_mut(&record.interface).and_then(Option::as_mut))
}
