//! `bywire plot`: signals over time from a candump log (or a live capture) to PNG or SVG, like
//! `cantools plot`.

use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_core::{Frame, Timestamp};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::busarg::{self, BusArg, Readers};
use crate::signals::Dbc;

/// The font text is drawn with (DejaVu Sans, see assets/DejaVuSans-LICENSE.txt): embedded so
/// plots need no system font library.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire plot vehicle.dbc Speed -I drive.log -o speed.png
  candump -L can0 | bywire plot vehicle.dbc Motor.Rpm Motor.Current --subplots -o motor.svg
  bywire plot vehicle.dbc SteeringAngle --bus can0 --duration 20 -o steering.png

Signals are named SIGNAL or MESSAGE.SIGNAL. Time is in seconds from the first frame. With
--subplots each signal gets its own panel and axis; otherwise they share one, with a legend.
The image is written to a temporary file and renamed, so a failed plot leaves nothing behind.")]
pub struct Args {
    /// The DBC file.
    dbc: PathBuf,
    /// Signals to plot: SIGNAL or MESSAGE.SIGNAL.
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

/// One plotted signal: its label, unit and points (seconds, value).
pub(crate) struct Series {
    pub(crate) label: String,
    pub(crate) unit: String,
    pub(crate) points: Vec<(f64, f64)>,
}

/// Where a requested signal is: message index and signal index.
fn locate(dbc: &Dbc, spec: &str) -> Result<(usize, usize)> {
    let messages = &dbc.database().messages;
    let (message_name, signal_name) = match spec.split_once('.') {
        Some((m, s)) => (Some(m), s),
        None => (None, spec),
    };
    let mut found = Vec::new();
    for (mi, m) in messages.iter().enumerate() {
        if message_name.is_some_and(|n| n != m.name && n != m.display_name()) {
            continue;
        }
        for (si, s) in m.signals.iter().enumerate() {
            if s.name == signal_name || s.display_name() == signal_name {
                found.push((mi, si));
            }
        }
    }
    match found.as_slice() {
        [one] => Ok(*one),
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
    let dbc = Dbc::new(crate::dbc_cmd::load(&args.dbc, false)?);
    let wanted: Vec<(usize, usize)> = args
        .signals
        .iter()
        .map(|s| locate(&dbc, s))
        .collect::<Result<_>>()?;
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

/// Timestamped frames of a candump log; lines that are not log lines are skipped.
fn read_log(path: Option<&Path>) -> Result<Vec<(Timestamp, Frame)>> {
    let input: Box<dyn BufRead> = match path {
        Some(p) => Box::new(BufReader::new(
            File::open(p).with_context(|| format!("cannot open {}", p.display()))?,
        )),
        None => Box::new(BufReader::new(io::stdin())),
    };
    let mut frames = Vec::new();
    for line in input.lines() {
        if let Ok(record) = bywire_log::candump::parse_line(&line?) {
            frames.push((record.timestamp, record.frame));
        }
    }
    Ok(frames)
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
    let stop = crate::interrupt_flag();
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
    let messages = &dbc.database().messages;
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
        let Some(decoded) = dbc.decode(frame) else {
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

/// Render into a temporary file beside `path`, then rename it into place.
pub(crate) fn write_atomically(
    path: &Path,
    render: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| anyhow!("-o {}: not a file name", path.display()))?
        .to_string_lossy();
    let extension = path
        .extension()
        .map_or(String::new(), |e| e.to_string_lossy().into_owned());
    let tmp = path.with_file_name(format!(".{name}.{}.tmp.{extension}", std::process::id()));
    let result = render(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

pub(crate) fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("cannot draw the plot: {e}")
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

pub(crate) fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    series: &[Series],
    subplots: bool,
) -> Result<()> {
    register_font()?;
    root.fill(&WHITE).map_err(plot_error)?;
    let panels: Vec<(DrawingArea<DB, Shift>, Vec<usize>)> = if subplots {
        let count = series.len();
        root.split_evenly((count, 1))
            .into_iter()
            .zip(0..count)
            .map(|(area, i)| (area, vec![i]))
            .collect()
    } else {
        vec![(root.clone(), (0..series.len()).collect())]
    };
    for (area, members) in panels {
        draw_panel(&area, series, &members, &[])?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

/// The series' legend, as every chart here draws it.
pub(crate) fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> Result<()> {
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)
}

/// The embedded font as "sans-serif" (registering it again is harmless).
pub(crate) fn register_font() -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("the embedded font is not readable"))
}

/// A moment marked on a time panel: a vertical line in this colour, labelled at the top.
pub(crate) struct Marker {
    pub(crate) t: f64,
    pub(crate) label: String,
    pub(crate) color: RGBColor,
}

/// One panel of `series` (those at `members`) over time, with a legend and `markers`.
pub(crate) fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &[Series],
    members: &[usize],
    markers: &[Marker],
) -> Result<()> {
    let chosen: Vec<(usize, &Series)> = members
        .iter()
        .filter_map(|i| series.get(*i).map(|s| (*i, s)))
        .collect();
    let points = chosen.iter().flat_map(|(_, s)| s.points.iter());
    let (mut x_max, mut y_min, mut y_max) = (0.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for (x, y) in points {
        x_max = x_max.max(*x);
        y_min = y_min.min(*y);
        y_max = y_max.max(*y);
    }
    if !y_min.is_finite() {
        (y_min, y_max) = (0.0, 1.0);
    }
    let pad = ((y_max - y_min) * 0.05).max(1e-9);
    let mut units: Vec<&str> = chosen
        .iter()
        .map(|(_, s)| s.unit.as_str())
        .filter(|u| !u.is_empty())
        .collect();
    units.dedup();
    let y_label = if units.is_empty() {
        "value".to_string()
    } else {
        units.join(", ")
    };
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_max.max(1e-3), (y_min - pad)..(y_max + pad))
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc(y_label)
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(plot_error)?;
    for (index, s) in &chosen {
        let color = COLORS.get(index % COLORS.len()).copied().unwrap_or(BLACK);
        let label = if s.unit.is_empty() {
            s.label.clone()
        } else {
            format!("{} [{}]", s.label, s.unit)
        };
        chart
            .draw_series(LineSeries::new(
                s.points.iter().copied(),
                color.stroke_width(2),
            ))
            .map_err(plot_error)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    let (y_low, y_high) = (y_min - pad, y_max + pad);
    for (k, marker) in markers.iter().enumerate() {
        let line = vec![(marker.t, y_low), (marker.t, y_high)];
        chart
            .draw_series(LineSeries::new(line, marker.color.stroke_width(1)))
            .map_err(plot_error)?;
        // Staggered on three heights, so close neighbours stay readable.
        let height = y_high - (y_high - y_low) * (0.04 + 0.07 * (k % 3) as f64);
        chart
            .draw_series(std::iter::once(Text::new(
                marker.label.clone(),
                (marker.t, height),
                ("sans-serif", 12).into_font().color(&marker.color),
            )))
            .map_err(plot_error)?;
    }
    draw_legend(&mut chart)
}
