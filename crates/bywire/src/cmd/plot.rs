//! `bywire plot`: signals over time from a candump log (or a live capture) to PNG or SVG, like
//! `cantools plot`.

use crate::plot::{draw, Series};
use crate::support::files::write_atomically;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Result};
use bywire_core::{Frame, Timestamp};
use plotters::prelude::*;

use crate::support::busarg::{self, BusArg, Readers};
use crate::support::interrupt::interrupt_flag;
use crate::support::logs;
use crate::support::signals::Dbc;

/// The font text is drawn with (DejaVu Sans, see assets/DejaVuSans-LICENSE.txt): embedded so
/// plots need no system font library.

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire plot vehicle.dbc Speed -I drive.log -o speed.png
  candump -L can0 | bywire plot vehicle.dbc Motor.Rpm Motor.Current --subplots -o motor.svg
  bywire plot vehicle.dbc SteeringAngle --bus can0 --duration 20 -o steering.png
  bywire plot vehicle.dbc '*Velocity*' -I drive.log --subplots -o velocities.png

Signals are named SIGNAL or MESSAGE.SIGNAL, either part a shell pattern as cantools plot takes
them ('*Velocity*', 'VehicleToAds_State.*'). Time is in seconds from the first frame. With
--subplots each signal gets its own panel and axis; otherwise they share one, with a legend.
The image is written to a temporary file and renamed, so a failed plot leaves nothing behind.")]
pub struct Args {
    /// The DBC file.
    dbc: PathBuf,
    /// Signals to plot: SIGNAL or MESSAGE.SIGNAL, each part a name or a pattern (`*`, `?`).
    #[arg(required = true)]
    signals: Vec<String>,
    /// The candump log to read (standard input when not given and no --bus).
    #[arg(short = 'I', value_name = "FILE")]
    input: Option<PathBuf>,
    /// Capture from these buses instead of reading a log.
    #[arg(long, num_args = 1.., value_name = "BUS")]
    bus: Vec<String>,
    /// How long to capture from --bus, in seconds.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// The image to write: .png or .svg.
    #[arg(short = 'o', long, value_name = "FILE")]
    output: PathBuf,
    /// One panel per signal.
    #[arg(long)]
    subplots: bool,
    /// Image width in pixels.
    #[arg(long, default_value_t = 1200)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 700)]
    height: u32,
}

/// Where the signals a spec names are: (message index, signal index). A name must name one
/// signal; a pattern (`*Velocity*`) at least one.
fn locate(dbc: &Dbc, spec: &str) -> Result<Vec<(usize, usize)>> {
    let messages = &dbc.decoder().database().messages;
    let found = bywire_dbc::select::signals_matching(dbc.decoder().database(), spec);
    if bywire_dbc::select::is_pattern(spec) {
        if found.is_empty() {
            return Err(anyhow!("no signal in the DBC matches '{spec}'"));
        }
        return Ok(found);
    }
    match found.as_slice() {
        [_] => Ok(found),
        [] => Err(anyhow!("signal '{spec}' is not in the DBC")),
        many => Err(anyhow!(
            "signal '{spec}' is in {} messages; name one as MESSAGE.SIGNAL ({})",
            many.len(),
            many.iter()
                .filter_map(|(m, _)| messages.get(*m).map(|m| m.name.as_str()))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

pub fn run(args: &Args) -> Result<()> {
    let extension = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(extension.as_deref(), Some("png" | "svg")) {
        return Err(anyhow!(
            "-o {}: the image must end in .png or .svg",
            args.output.display()
        ));
    }
    if args.width < 200 || args.height < 150 || args.width > 10_000 || args.height > 10_000 {
        return Err(anyhow!("--width/--height: 200x150 to 10000x10000 pixels"));
    }
    let dbc = Dbc::new(crate::support::dbc::load(&args.dbc, false)?);
    let mut wanted: Vec<(usize, usize)> = Vec::new();
    for spec in &args.signals {
        for found in locate(&dbc, spec)? {
            // A signal two specs both name is plotted once.
            if !wanted.contains(&found) {
                wanted.push(found);
            }
        }
    }
    let frames = if args.bus.is_empty() {
        read_log(args.input.as_deref())?
    } else {
        capture(&args.bus, args.duration)?
    };
    let series = collect(&dbc, &wanted, &frames);
    if series.iter().all(|s| s.points.is_empty()) {
        return Err(anyhow!(
            "none of the signals appears in the {} frames read",
            frames.len()
        ));
    }
    write_atomically(&args.output, |tmp| {
        if extension.as_deref() == Some("svg") {
            draw(
                SVGBackend::new(tmp, (args.width, args.height)).into_drawing_area(),
                &series,
                args.subplots,
            )
        } else {
            draw(
                BitMapBackend::new(tmp, (args.width, args.height)).into_drawing_area(),
                &series,
                args.subplots,
            )
        }
    })
}

/// Timestamped frames of a candump log; lines that are not log lines, or not readable, are
/// skipped, each reported with its line.
fn read_log(path: Option<&Path>) -> Result<Vec<(Timestamp, Frame)>> {
    let (name, input) = logs::input(path)?;
    logs::records(&name, input, logs::Skip::AnyBadLine)
        .map(|record| record.map(|r| (r.timestamp, r.frame)))
        .collect()
}

fn capture(buses: &[String], seconds: f64) -> Result<Vec<(Timestamp, Frame)>> {
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= 86_400.0) {
        return Err(anyhow!("--duration {seconds}: 0 to 86400 seconds"));
    }
    let args: Vec<BusArg> = buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    let readers = Readers::start(busarg::open_all(&args)?);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let stop = interrupt_flag();
    let mut frames = Vec::new();
    while Instant::now() < end && !stop.load(std::sync::atomic::Ordering::Relaxed) {
        if let Ok((index, event)) = readers.events.recv_timeout(
            end.saturating_duration_since(Instant::now())
                .min(Duration::from_millis(100)),
        ) {
            let received = event.map_err(|e| anyhow!("bus {}: {e}", index))?;
            frames.push((received.timestamp, received.frame));
        }
    }
    Ok(frames)
}

fn collect(dbc: &Dbc, wanted: &[(usize, usize)], frames: &[(Timestamp, Frame)]) -> Vec<Series> {
    let messages = &dbc.decoder().database().messages;
    let mut series: Vec<Series> = wanted
        .iter()
        .map(|(m, s)| {
            let message = messages.get(*m);
            let signal = message.and_then(|m| m.signals.get(*s));
            Series {
                label: format!(
                    "{}.{}",
                    message.map_or("?", |m| m.display_name()),
                    signal.map_or("?", |s| s.display_name())
                ),
                unit: signal.map_or(String::new(), |s| s.unit.clone()),
                points: Vec::new(),
            }
        })
        .collect();
    let Some(start) = frames.first().map(|(t, _)| *t) else {
        return series;
    };
    for (timestamp, frame) in frames {
        let Some(decoded) = dbc.decoder().decode(frame) else {
            continue;
        };
        let seconds = timestamp.saturating_since(start).as_secs_f64();
        for ((m, s), out) in wanted.iter().zip(series.iter_mut()) {
            if messages.get(*m).map(|m| (m.id, m.extended))
                != Some((decoded.message.id, decoded.message.extended))
            {
                continue;
            }
            let Some(signal) = messages.get(*m).and_then(|m| m.signals.get(*s)) else {
                continue;
            };
            if let Some(v) = decoded
                .signals
                .iter()
                .find(|v| std::ptr::eq(v.signal, signal))
            {
                let value = v.value.physical.as_f64();
                if value.is_finite() {
                    out.points.push((seconds, value));
                }
            }
        }
    }
    series
}
