//! The picture of a `bywire sim` run (`run.png`): the route and the path driven, with where
//! each fault struck; the buses' loads over the run; speed, the ADS's steering command against
//! the front-left wheel's target and angle, and the heading over time — faults and the
//! mission's phases marked on every time panel.

use std::path::Path;

use anyhow::Result;
use bywire_core::Timestamp;
use bywire_sim::event::Happening;
use bywire_sim::mission::MissionEvent;
use bywire_sim::record::{windowed_loads, Sample};
use bywire_sim::tug::Tug;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plot::{draw_legend, draw_panel, plot_error, register_font, Marker, Series};
use crate::support::files::write_atomically;

/// Faults: on the map and on every time panel (a colour no series uses).
pub const FAULT_COLOR: RGBColor = RGBColor(190, 0, 110);
/// The mission's phases (step test, cruise, crab approach, tank turn, stop) on the time
/// panels.
const PHASE_COLOR: RGBColor = RGBColor(110, 110, 110);
/// The redundant tug's changes of control and degradation level.
const FAIL_OPERATIONAL_COLOR: RGBColor = RGBColor(220, 120, 0);
/// The route on the map, and the path driven.
const ROUTE_COLOR: RGBColor = RGBColor(170, 170, 170);
/// The path driven on the map.
pub const PATH_COLOR: RGBColor = RGBColor(31, 119, 180);
/// Samples (50 ms each) a bus-load window spans: half a second.
const LOAD_WINDOW: usize = 10;

/// Write the picture of `tug`'s run to `path` (whole or not at all).
pub fn write(tug: &Tug, path: &Path) -> Result<()> {
    write_atomically(path, |tmp| {
        draw(
            BitMapBackend::new(tmp, (1400, 1500)).into_drawing_area(),
            tug,
        )
    })
}

fn seconds(t: Timestamp) -> f64 {
    t.as_nanos() as f64 / 1e9
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, tug: &Tug) -> Result<()> {
    register_font()?;
    root.fill(&WHITE).map_err(plot_error)?;
    let (top, bottom) = root.split_vertically(600);
    let (map, loads) = top.split_horizontally(620);
    let markers = markers(tug);
    draw_map(&map, tug, &markers)?;
    let bus_loads: Vec<Series> = ["bus 1", "bus 2", "bus 3", "bus 1b"]
        .into_iter()
        .zip(windowed_loads(&tug.trace, LOAD_WINDOW))
        .map(|(label, points)| Series {
            label: format!("{label} load"),
            unit: "%".to_string(),
            points: points
                .into_iter()
                .map(|(t, load)| (seconds(t), load * 100.0))
                .collect(),
        })
        .collect();
    draw_panel(&loads, &bus_loads, &[0, 1, 2, 3], &markers)?;
    let over_time = time_series(&tug.trace);
    let panels = bottom.split_evenly((3, 1));
    for (area, members) in panels.iter().zip([&[0][..], &[1, 2, 3], &[4]]) {
        draw_panel(area, &over_time, members, &markers)?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

/// Speed, the ADS's steering command, the front-left wheel's target (the ECU's, from the
/// command and the steering mode: in a tank turn the wheel's own angle) and angle, and the
/// heading (unwrapped: a loop reads as 360°, not a jump at ±180°).
fn time_series(trace: &[Sample]) -> [Series; 5] {
    let series = |label: &str, unit: &str, value: &dyn Fn(&Sample) -> f64| Series {
        label: label.to_string(),
        unit: unit.to_string(),
        points: trace.iter().map(|s| (seconds(s.t), value(s))).collect(),
    };
    let mut heading = series("heading", "deg", &|_| 0.0);
    let mut turned = 0.0;
    let mut previous: Option<f64> = None;
    for (point, sample) in heading.points.iter_mut().zip(trace) {
        let yaw = sample.pose.yaw.to_degrees();
        turned = match previous {
            Some(before) => turned + (yaw - before + 540.0).rem_euclid(360.0) - 180.0,
            None => yaw,
        };
        previous = Some(yaw);
        point.1 = turned;
    }
    [
        series("speed", "m/s", &|s| s.speed),
        series("steering command", "deg", &|s| s.steering_command),
        series("front-left wheel target", "deg", &|s| s.steering_target),
        series("front-left wheel angle", "deg", &|s| s.steering_actual),
        heading,
    ]
}

/// The faults injected (numbered as on the map) and the mission's phases, as markers.
fn markers(tug: &Tug) -> Vec<Marker> {
    let mut faults = 0;
    tug.events
        .iter()
        .filter_map(|event| match &event.what {
            Happening::Fault(fault) => {
                faults += 1;
                Some(Marker {
                    t: seconds(event.t),
                    label: format!("{faults} {}", short_name(&fault.to_string())),
                    color: FAULT_COLOR,
                })
            }
            Happening::Mission(MissionEvent::Phase(phase)) => Some(Marker {
                t: seconds(event.t),
                label: phase.to_string(),
                color: PHASE_COLOR,
            }),
            // The redundant tug: the ECU in control and the degradation level.
            Happening::Control(side) => Some(Marker {
                t: seconds(event.t),
                label: side.map_or("neither ECU".to_string(), |s| format!("ECU {s:?}")),
                color: FAIL_OPERATIONAL_COLOR,
            }),
            Happening::Degradation(level, _) => Some(Marker {
                t: seconds(event.t),
                label: level.to_string(),
                color: FAIL_OPERATIONAL_COLOR,
            }),
            _ => None,
        })
        .collect()
}

/// A fault's name without its parameters: `SensorFault(2, Stuck(5.0))` → `SensorFault`.
fn short_name(detail: &str) -> &str {
    detail
        .split(['(', ' ', '{'])
        .next()
        .filter(|name| !name.is_empty())
        .unwrap_or(detail)
}

/// The route (grey), the path driven (blue) from its start (green) to its end (black), and a
/// dot with its number where each fault struck — at one scale on both axes.
fn draw_map<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    tug: &Tug,
    markers: &[Marker],
) -> Result<()> {
    let route: Vec<(f64, f64)> = tug.route().iter().map(|p| (p.x, p.y)).collect();
    let path: Vec<(f64, f64)> = tug.trace.iter().map(|s| (s.pose.x, s.pose.y)).collect();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in route.iter().chain(&path) {
        (x0, x1, y0, y1) = (x0.min(*x), x1.max(*x), y0.min(*y), y1.max(*y));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    // One scale on both axes: the larger span, centred, plus a margin.
    let half = (x1 - x0).max(y1 - y0).max(1.0) / 2.0 + 3.0;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let mut chart = ChartBuilder::on(area)
        .caption("route and path", ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d((cx - half)..(cx + half), (cy - half)..(cy + half))
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(plot_error)?;
    chart
        .draw_series(LineSeries::new(route, ROUTE_COLOR.stroke_width(4)))
        .map_err(plot_error)?
        .label("route")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], ROUTE_COLOR.stroke_width(4)));
    chart
        .draw_series(LineSeries::new(path.clone(), PATH_COLOR.stroke_width(2)))
        .map_err(plot_error)?
        .label("path driven")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], PATH_COLOR.stroke_width(2)));
    let ends = [(path.first(), GREEN), (path.last(), BLACK)];
    for (point, color) in ends {
        if let Some(point) = point {
            chart
                .draw_series(std::iter::once(Circle::new(*point, 6, color.filled())))
                .map_err(plot_error)?;
        }
    }
    for marker in markers.iter().filter(|m| m.color == FAULT_COLOR) {
        // Where the tug was: the last sample at or before the fault.
        let at = tug
            .trace
            .iter()
            .take_while(|s| seconds(s.t) <= marker.t)
            .last()
            .map(|s| (s.pose.x, s.pose.y));
        if let Some(at) = at {
            chart
                .draw_series(std::iter::once(Circle::new(at, 5, FAULT_COLOR.filled())))
                .map_err(plot_error)?;
            let number = marker.label.split(' ').next().unwrap_or_default();
            chart
                .draw_series(std::iter::once(Text::new(
                    number.to_string(),
                    (at.0 + 0.02 * half, at.1),
                    ("sans-serif", 12).into_font().color(&FAULT_COLOR),
                )))
                .map_err(plot_error)?;
        }
    }
    draw_legend(&mut chart)
}

#[cfg(test)]
mod tests {
    use super::short_name;

    #[test]
    fn faults_are_named_without_their_parameters() {
        assert_eq!(short_name("SensorFault(2, Stuck(5.0))"), "SensorFault");
        assert_eq!(short_name("BusOff { bus: Bus2, id: 1827 }"), "BusOff");
        assert_eq!(short_name("Estop"), "Estop");
        assert_eq!(short_name("(odd"), "(odd");
    }
}
