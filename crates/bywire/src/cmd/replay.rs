//! `bywire replay`: a recorded session's frames through a profile's supervisor in the log's
//! time (`bywire_vehicle::replay`), its decisions written as a trace and compared with a stored
//! one.

use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use bywire_core::Timestamp;
use bywire_vehicle::profile::LoadedProfile;
use bywire_vehicle::replay::Replay;
use bywire_vehicle::supervisor::Supervisor;

use crate::support::logs;
use crate::support::vehicles::{self, SecOcArgs, Wire};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire replay run/bus1.log --profile reference-tug > run.trace
  bywire replay run/bus1.log run/bus1b.log --bus-b bus1b --profile reference-tug-redundant --out run.trace
  bywire replay drive.blf --profile reference-tug --expect run.trace
  bywire replay --fuzz 10000 --profile reference-tug

Every frame of the logs (any format; several are merged in time order) goes to the profile's
supervisor at its own time, on the second command bus when its channel is --bus-b and on the
first otherwise; between frames the supervisor is polled at each deadline it asks for. The
trace has one line per decision: 'T command accepted', 'T command refused: REASON', 'T watchdog
LEVEL', 'T estop STATE', 'T mode MODE', 'T sent PORT ID DATA' (T in seconds from the log's
start). It depends only on the frames and the profile: the same on every run. With --expect,
exit 1 at the first line that differs from the stored trace, naming it.

--fuzz N sends N random commands (within the profile's limits, at them, just beyond, far beyond,
not numbers, every gear and mode) through the ADS side's checks (those of `bywire bridge`) and
the supervisor's, and lists every command one side takes and the other refuses (exit 1 if any):
the two ends of the wire configured apart.")]
pub struct Args {
    /// Logs of the ADS side's frames (the vehicle's own feedback in them is ignored).
    #[arg(required_unless_present = "fuzz", conflicts_with = "fuzz")]
    logs: Vec<PathBuf>,
    /// Fuzz the ADS side's command checks against the vehicle's with this many commands.
    #[arg(long, value_name = "N", conflicts_with_all = ["expect", "out", "bus_b"])]
    fuzz: Option<u64>,
    /// The fuzzer's seed.
    #[arg(long, default_value_t = 1, requires = "fuzz")]
    seed: u64,
    /// The vehicle profile (built in, e.g. reference-tug, or a TOML file).
    #[arg(long)]
    profile: String,
    /// The channel (interface name in the log) of the second command bus.
    #[arg(long, value_name = "CHANNEL")]
    bus_b: Option<String>,
    /// Write the trace here instead of to standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// A stored trace: exit 1 at the first line that differs.
    #[arg(long, value_name = "TRACE")]
    expect: Option<PathBuf>,
    #[command(flatten)]
    secoc: SecOcArgs,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let loaded = vehicles::load_profile(&args.profile)?;
    if let Some(n) = args.fuzz {
        return fuzz(args, &loaded, n, out);
    }
    let (wire, _): (Wire, _) = args.secoc.wire(&loaded)?;
    let supervisor = Supervisor::with_wire(loaded.supervisor_config(), wire);
    let mut replay = Replay::new(supervisor);
    let mut expected = match &args.expect {
        Some(path) => {
            let file = std::fs::File::open(path)
                .with_context(|| format!("--expect {}", path.display()))?;
            Some(BufReader::new(file).lines())
        }
        None => None,
    };
    let mut file = match &args.out {
        Some(path) => Some(BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("--out {}", path.display()))?,
        )),
        None => None,
    };
    // Compared with a stored trace and not written to a file, the trace is not printed.
    let mut sink: Option<&mut dyn Write> = match (file.as_mut(), &args.expect) {
        (Some(f), _) => Some(f),
        (None, None) => Some(out),
        (None, Some(_)) => None,
    };
    let mut number = 0usize;
    let mut difference: Option<String> = None;
    let mut failure: Option<anyhow::Error> = None;
    let mut emit = |line: &str| {
        number += 1;
        if let (Some(sink), None) = (sink.as_mut(), &failure) {
            if let Err(e) = writeln!(sink, "{line}") {
                failure = Some(e.into());
            }
        }
        if let (Some(lines), None) = (expected.as_mut(), &difference) {
            match lines.next() {
                Some(Ok(want)) if want == line => {}
                Some(Ok(want)) => {
                    difference = Some(format!("line {number}: expected '{want}', got '{line}'"))
                }
                Some(Err(e)) => difference = Some(format!("line {number}: unreadable: {e}")),
                None => {
                    difference = Some(format!(
                        "line {number}: the stored trace ended, got '{line}'"
                    ))
                }
            }
        }
    };
    let bus_b = args.bus_b.as_deref();
    // Time from the first record: a trace does not depend on when the session was recorded.
    let mut start: Option<Timestamp> = None;
    let mut last = Timestamp::ZERO;
    logs::for_each_merged(&args.logs, |record| {
        let port = if Some(record.interface.as_str()) == bus_b {
            Supervisor::<Wire>::PORT_B
        } else {
            Supervisor::<Wire>::PORT_A
        };
        let at = record
            .timestamp
            .saturating_since(*start.get_or_insert(record.timestamp));
        let at = Timestamp::ZERO.saturating_add(at);
        last = last.max(at);
        replay.push(at, port, &record.frame, &mut emit);
    })?;
    replay.finish(last, &mut emit);
    if let Some(e) = failure {
        return Err(e).context("writing the trace");
    }
    if let Some(sink) = sink.as_mut() {
        sink.flush()?;
    }
    if let (Some(lines), None) = (expected.as_mut(), &difference) {
        if let Some(extra) = lines.next() {
            let extra = extra.unwrap_or_default();
            difference = Some(format!(
                "line {}: expected '{extra}', the replay ended",
                number + 1
            ));
        }
    }
    if let (Some(path), Some(difference)) = (&args.expect, difference) {
        bail!("{}: {difference}", path.display());
    }
    Ok(())
}

/// `--fuzz N`: the report, one line per disagreement kept; exit 1 on any.
fn fuzz(args: &Args, loaded: &LoadedProfile, n: u64, out: &mut impl Write) -> Result<()> {
    let (ads_wire, _) = args.secoc.wire(loaded)?;
    let (vehicle_wire, _) = args.secoc.wire(loaded)?;
    let report = bywire_vehicle::fuzz::fuzz(
        &loaded.profile.limits,
        (ads_wire, vehicle_wire),
        loaded.supervisor_config(),
        n,
        args.seed,
    );
    writeln!(
        out,
        "{}: {} commands (seed {}), {} sent by the ADS side, {} the wire cannot carry, {} disagreements",
        loaded.profile.name,
        report.commands,
        args.seed,
        report.sent,
        report.unencodable,
        report.disagreements
    )?;
    for d in &report.kept {
        let side = |verdict: &Result<(), String>| match verdict {
            Ok(()) => "takes it".to_string(),
            Err(why) => format!("refuses it ({why})"),
        };
        writeln!(
            out,
            "  {:?}: the ADS side {}, the vehicle {}",
            d.command,
            side(&d.ads),
            side(&d.vehicle)
        )?;
    }
    if report.disagreements > 0 {
        bail!(
            "{} commands judged differently by the ADS side and the vehicle",
            report.disagreements
        );
    }
    Ok(())
}
