//! The picture of `bywire latency`: a histogram per latency figure (the echo, each transfer)
//! with its percentiles marked.

use std::path::Path;

use anyhow::{anyhow, Result};
use bywire_data::latency::{Distribution, Report};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{plot_error, register_font};
use crate::support::files::write_atomically;

/// Write the histograms of `report` to `path` (.png or .svg), whole or not at all.
pub fn write(report: &Report, path: &Path) -> Result<()> {
    let mut panels: Vec<(String, &Distribution)> = Vec::new();
    if let Some(echo) = &report.echo {
        panels.push(("command → echo".into(), echo));
    }
    for t in &report.transfers {
        if let Some(latency) = &t.latency {
            panels.push((format!("transfer {} → {}", t.from, t.to), latency));
        }
    }
    if panels.is_empty() {
        return Err(anyhow!(
            "--plot: nothing to plot (no echo and no transfer was measured)"
        ));
    }
    let svg = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    let size = (1000, 360 * u32::try_from(panels.len()).unwrap_or(1));
    write_atomically(path, |tmp| {
        if svg {
            draw(SVGBackend::new(tmp, size).into_drawing_area(), &panels)
        } else {
            draw(BitMapBackend::new(tmp, size).into_drawing_area(), &panels)
        }
    })
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[(String, &Distribution)],
) -> Result<()> {
    register_font()?;
    root.fill(&WHITE).map_err(plot_error)?;
    for (area, (title, d)) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
        histogram(area, title, d)?;
    }
    root.present().map_err(plot_error)
}

/// Bins merged so that at most this many bars are drawn.
const MAX_BARS: usize = 200;

fn histogram<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    d: &Distribution,
) -> Result<()> {
    // 10 µs bins, merged into at most MAX_BARS bars over [min, max].
    let (low, high) = (d.min_ms, d.max_ms.max(d.min_ms + 0.01));
    let width = ((high - low) / MAX_BARS as f64).max(0.01);
    let mut bars = vec![0u64; MAX_BARS + 1];
    for &(edge, count) in &d.histogram {
        let index = (((edge - low) / width).floor().max(0.0) as usize).min(MAX_BARS);
        if let Some(bar) = bars.get_mut(index) {
            *bar += count;
        }
    }
    let top = bars.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
    let caption = format!(
        "{title}: {} samples, p50 {:.2} ms, p99 {:.2} ms, max {:.3} ms",
        d.count, d.p50_ms, d.p99_ms, d.max_ms
    );
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            low..(low + width * (MAX_BARS + 1) as f64).min(high + width),
            0.0..top,
        )
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("latency [ms]")
        .y_desc("frames")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(plot_error)?;
    let blue = RGBColor(31, 119, 180);
    chart
        .draw_series(
            bars.iter()
                .enumerate()
                .filter(|(_, &n)| n > 0)
                .map(|(i, &n)| {
                    let x0 = low + i as f64 * width;
                    Rectangle::new([(x0, 0.0), (x0 + width, n as f64)], blue.filled())
                }),
        )
        .map_err(plot_error)?;
    for (label, x, color) in [
        ("p50", d.p50_ms, RGBColor(44, 160, 44)),
        ("p99", d.p99_ms, RGBColor(214, 39, 40)),
    ] {
        chart
            .draw_series(LineSeries::new([(x, 0.0), (x, top)], color.stroke_width(2)))
            .map_err(plot_error)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], color.stroke_width(2)));
    }
    super::draw_legend(&mut chart)
}
