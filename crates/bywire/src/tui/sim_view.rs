//! The live view of `bywire sim` in a terminal: the route with the tug on it, the mission's
//! phase, speed, wheel angles, mode, watchdog and E-stop state, bus loads and the event log; keys for E-stop,
//! the operator's reset, pause, quit, and 1–9 to inject the scenario's faults by hand.

use std::time::{Duration, Instant};

use anyhow::Result;
use bywire_sim::fault::Fault;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::Tug;
use bywire_tug::secured::TugWire;
use bywire_vehicle::supervisor::Supervisor;
use ratatui::crossterm::event::{Event, KeyCode, KeyEventKind};

use crate::support::interrupt::interrupt_flag;
use crate::support::sim_serve::Shared;
use crate::tui::Input;
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::canvas::{Canvas, Points};
use ratatui::widgets::{Block, Paragraph};

/// How the run ended.
pub enum Ending {
    /// The route is done.
    Arrived,
    /// Someone pressed q (or the time ran out).
    Stopped,
}

/// Run `tug` in real time with the dashboard until the route ends, q, or `limit`.
pub fn run(
    tug: &mut Tug,
    scenario: &Scenario,
    limit: Duration,
    shared: &mut Shared,
) -> Result<Ending> {
    // Asked now, while the terminal is surely there.
    crate::tui::stdin_is_terminal();
    let mut terminal = ratatui::init();
    let result = event_loop(tug, scenario, limit, shared, &mut terminal);
    crate::tui::restore(terminal);
    result
}

fn event_loop(
    tug: &mut Tug,
    scenario: &Scenario,
    limit: Duration,
    shared: &mut Shared,
    terminal: &mut ratatui::DefaultTerminal,
) -> Result<Ending> {
    let mut paused = false;
    let mut last = Instant::now();
    let stop = interrupt_flag();
    loop {
        // Simulated time follows the wall clock, a millisecond a step.
        let elapsed = last.elapsed();
        last = Instant::now();
        if !paused {
            for _ in 0..elapsed.as_millis().min(200) {
                scenario.step(tug);
                shared.exchange(tug)?;
            }
        }
        if tug.arrived() {
            return Ok(Ending::Arrived);
        }
        if Duration::from_nanos(tug.now().as_nanos()) >= limit
            || stop.load(std::sync::atomic::Ordering::Relaxed)
        {
            return Ok(Ending::Stopped);
        }
        if !crate::tui::draw(terminal, |f| draw(f, tug, scenario, paused))? {
            return Ok(Ending::Stopped);
        }
        let key = match crate::tui::next_input(Duration::from_millis(50))? {
            Input::HungUp => return Ok(Ending::Stopped),
            Input::Event(Event::Key(key)) if key.kind == KeyEventKind::Press => key,
            Input::Event(_) | Input::Nothing => continue,
        };
        match key.code {
            KeyCode::Char('q') | KeyCode::Esc => return Ok(Ending::Stopped),
            KeyCode::Char('p') => paused = !paused,
            // The E-stop button: pressed for a second (the latch holds after).
            KeyCode::Char('e') => tug.inject(Fault::Estop, Some(Duration::from_secs(1))),
            KeyCode::Char('r') => tug.inject(Fault::OperatorReset, None),
            // The scenario's n-th fault, now, for its own duration.
            KeyCode::Char(digit @ '1'..='9') => {
                let index = usize::from(digit as u8 - b'1');
                if let Some((_, fault, duration)) = scenario.events.get(index) {
                    tug.inject(*fault, *duration);
                }
            }
            _ => {}
        }
    }
}

fn draw(frame: &mut ratatui::Frame<'_>, tug: &Tug, scenario: &Scenario, paused: bool) {
    let [top, body, log] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Min(8),
        Constraint::Length(8),
    ])
    .areas(frame.area());
    let title = format!(
        "bywire sim   t = {:.1} s{}   keys: e E-stop  r reset  p pause  q quit  1-9 faults",
        tug.now().as_nanos() as f64 / 1e9,
        if paused { "  (paused)" } else { "" }
    );
    frame.render_widget(Paragraph::new(title), top);
    let [map, status] =
        Layout::horizontal([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(body);
    let route = tug.route();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in route {
        (x0, x1, y0, y1) = (x0.min(p.x), x1.max(p.x), y0.min(p.y), y1.max(p.y));
    }
    let pose = tug.pose();
    let points: Vec<(f64, f64)> = route.iter().map(|p| (p.x, p.y)).collect();
    let canvas = Canvas::default()
        .block(Block::bordered().title("route"))
        .marker(Marker::Braille)
        .x_bounds([x0 - 5.0, x1 + 5.0])
        .y_bounds([y0 - 5.0, y1 + 5.0])
        .paint(move |ctx| {
            ctx.draw(&Points {
                coords: &points,
                color: Color::DarkGray,
            });
            ctx.draw(&Points {
                coords: &[(pose.x, pose.y)],
                color: Color::Yellow,
            });
            ctx.print(
                pose.x,
                pose.y,
                Line::styled("tug", Style::default().fg(Color::Yellow)),
            );
        });
    frame.render_widget(canvas, map);
    // "-" where the tug has no ECU to ask (never: the tug owns it).
    let ecu_said =
        |what: &dyn Fn(&Supervisor<TugWire>) -> String| tug.ecu().map_or("-".into(), what);
    let [fl, fr, rl, rr] = tug.wheel_angles();
    let [b1, b2, b3, b1b] = tug.bus_loads();
    let faults: Vec<String> = tug.active_faults().map(|f| f.to_string()).collect();
    let mut lines = vec![
        Line::from(format!(
            "phase      {}",
            tug.phase().map_or("-".to_string(), |p| p.to_string())
        )),
        Line::from(format!("speed      {:5.2} m/s", tug.pose_speed())),
        Line::from(format!("position   x {:7.2}  y {:7.2}", pose.x, pose.y)),
        Line::from(format!(
            "to go      {:5.1} m",
            tug.remaining().unwrap_or(f64::NAN).min(9_999.0)
        )),
        Line::from(format!(
            "wheels     FL {fl:5.1}° FR {fr:5.1}° RL {rl:5.1}° RR {rr:5.1}°"
        )),
        Line::from(format!(
            "mode       {}",
            ecu_said(&|e| format!("{:?}", e.mode()))
        )),
        Line::from(format!(
            "watchdog   {}",
            ecu_said(&|e| format!("{:?}", e.watchdog()))
        )),
        Line::from(format!(
            "E-stop     {}",
            ecu_said(&|e| format!("{:?}", e.estop()))
        )),
        Line::from(format!(
            "bus load   {:.1} %  {:.1} %  {:.1} %  1b {:.1} %",
            b1 * 100.0,
            b2 * 100.0,
            b3 * 100.0,
            b1b * 100.0
        )),
        Line::from(format!(
            "steering   {}",
            tug.steering_fault()
                .map_or("sensors agree".to_string(), |f| f.to_string())
        )),
        Line::from(format!(
            "redundancy {}",
            ecu_said(&|e| match e.degraded() {
                None => "both buses".into(),
                Some(_) => "degraded".into(),
            })
        )),
        Line::from(format!("battery    {:.1} %", tug.soc() * 100.0)),
    ];
    // The redundant tug: who is in control and how far it has degraded.
    if tug.ecu_pair().is_some() {
        lines.push(Line::from(format!(
            "control    {}",
            tug.ecu_in_control()
                .map_or("neither ECU".to_string(), |side| format!("ECU {side:?}"))
        )));
        lines.push(Line::from(format!(
            "level      {}",
            ecu_said(&|e| {
                let latch = e.degradation();
                match latch.reason() {
                    Some(fault) => format!("{} ({})", latch.level(), fault.class),
                    None => latch.level().to_string(),
                }
            })
        )));
    }
    lines.push(Line::from(format!(
        "faults     {}",
        if faults.is_empty() {
            "none".to_string()
        } else {
            faults.join(", ")
        }
    )));
    // The keys that inject the scenario's faults by hand.
    lines.extend(
        scenario
            .events
            .iter()
            .take(9)
            .enumerate()
            .map(|(i, (_, fault, _))| Line::from(format!("key {}      {fault}", i + 1))),
    );
    frame.render_widget(
        Paragraph::new(lines).block(Block::bordered().title("vehicle")),
        status,
    );
    let events: Vec<Line> = tug
        .events
        .iter()
        .rev()
        .take(6)
        .map(|e| {
            Line::from(format!(
                "{:8.3} s  {:<16} {}",
                e.t.as_nanos() as f64 / 1e9,
                e.kind(),
                e.what
            ))
        })
        .collect();
    frame.render_widget(
        Paragraph::new(events).block(Block::bordered().title("events")),
        log,
    );
}
