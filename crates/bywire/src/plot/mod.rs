//! Plot drawing shared by `bywire plot` and the simulator's run picture: the embedded font,
//! series and markers, panels with a legend, errors named for the user.

use anyhow::{anyhow, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub mod latency;
pub mod sim;

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// One plotted signal: its label, unit and points (seconds, value).
pub(crate) struct Series {
    pub(crate) label: String,
    pub(crate) unit: String,
    pub(crate) points: Vec<(f64, f64)>,
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
        // Staggered on three heights, so close neighbours stay readable; in the last fifth,
        // written leftward from the line, so the panel's edge does not cut it.
        let height = y_high - (y_high - y_low) * (0.04 + 0.07 * (k % 3) as f64);
        let side = if marker.t > 0.8 * x_max {
            HPos::Right
        } else {
            HPos::Left
        };
        chart
            .draw_series(std::iter::once(Text::new(
                marker.label.clone(),
                (marker.t, height),
                ("sans-serif", 12)
                    .into_font()
                    .color(&marker.color)
                    .pos(Pos::new(side, VPos::Top)),
            )))
            .map_err(plot_error)?;
    }
    draw_legend(&mut chart)
}
