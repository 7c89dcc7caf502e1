//! `bywire monitor`: like `cantools monitor` — a live table of decoded messages and their
//! signals, with filtering and pausing.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Result;
use bywire_bus::Received;
use ratatui::crossterm::event::{KeyCode, KeyEvent};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::Paragraph;

use crate::support::signals::Dbc;
use crate::support::signals::ValueText;
use crate::tui::{self, View};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire monitor vehicle.dbc can0
  bywire monitor vehicle.dbc virtual:test can1
  bywire monitor vehicle.dbc -I candump-2024-01-01_120000.log

Keys: space pauses and resumes, / starts a new filter (messages whose name or signals contain
the text; Enter ends typing, / then Enter clears it), q (or Esc) quits.")]
pub struct Args {
    /// The DBC file.
    dbc: PathBuf,
    /// Buses to watch, with optional candump filters.
    buses: Vec<String>,
    /// Replay this candump log (at its recorded pace) instead of watching buses.
    #[arg(short = 'I', value_name = "FILE")]
    input: Option<PathBuf>,
}

/// The latest decoding of one message.
struct Entry {
    count: u64,
    last_seen: Instant,
    /// When the previous frame was on the bus (its timestamp), for the cycle time.
    last_timestamp: u64,
    interval: Option<Duration>,
    lines: Vec<String>,
}

/// The monitor's state.
pub struct Monitor {
    dbc: Dbc,
    messages: BTreeMap<String, Entry>,
    unknown: BTreeMap<u32, u64>,
    paused: bool,
    filter: String,
    typing: bool,
}

impl Monitor {
    /// A monitor decoding with `dbc`.
    pub fn new(dbc: Dbc) -> Monitor {
        Monitor {
            dbc,
            messages: BTreeMap::new(),
            unknown: BTreeMap::new(),
            paused: false,
            filter: String::new(),
            typing: false,
        }
    }

    fn shown(&self, name: &str, entry: &Entry) -> bool {
        let filter = self.filter.to_lowercase();
        filter.is_empty()
            || name.to_lowercase().contains(&filter)
            || entry
                .lines
                .iter()
                .any(|l| l.to_lowercase().contains(&filter))
    }
}

impl View for Monitor {
    fn on_frame(&mut self, _bus: &str, received: &Received, now: Instant) {
        if self.paused || received.frame.is_error() {
            return;
        }
        let Some(decoded) = self.dbc.decoder().decode(&received.frame) else {
            *self
                .unknown
                .entry(received.frame.socketcan_id())
                .or_default() += 1;
            return;
        };
        let lines = match &decoded.error {
            Some(e) => vec![format!("error: {e}")],
            None => decoded
                .signals
                .iter()
                .map(|s| format!("{}: {}", s.signal.display_name(), s.text(true)))
                .collect(),
        };
        let name = decoded.message.display_name().to_string();
        let entry = self.messages.entry(name).or_insert(Entry {
            count: 0,
            last_seen: now,
            last_timestamp: 0,
            interval: None,
            lines: Vec::new(),
        });
        let stamp = received.timestamp.as_nanos();
        if entry.count > 0 {
            entry.interval = Some(Duration::from_nanos(
                stamp.saturating_sub(entry.last_timestamp),
            ));
        }
        entry.last_timestamp = stamp;
        entry.count += 1;
        entry.last_seen = now;
        entry.lines = lines;
    }

    fn draw(&mut self, f: &mut ratatui::Frame<'_>, _now: Instant) {
        let [header, body, footer] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Min(0),
            Constraint::Length(1),
        ])
        .areas(f.area());
        let received: u64 = self.messages.values().map(|e| e.count).sum();
        let state = if self.paused { "PAUSED" } else { "running" };
        f.render_widget(
            Paragraph::new(format!(
                "bywire monitor — {} messages, {received} frames decoded, {} unknown — {state}",
                self.messages.len(),
                self.unknown.values().sum::<u64>()
            ))
            .style(Style::new().add_modifier(Modifier::BOLD)),
            header,
        );
        let mut lines = Vec::new();
        for (name, entry) in &self.messages {
            if !self.shown(name, entry) {
                continue;
            }
            let cycle = entry.interval.map_or("-".to_string(), |d| {
                format!("{:.1} ms", d.as_secs_f64() * 1000.0)
            });
            lines.push(
                Line::from(format!("{name}  (count {}, cycle {cycle})", entry.count))
                    .style(Style::new().fg(Color::Cyan)),
            );
            lines.extend(entry.lines.iter().map(|l| Line::from(format!("    {l}"))));
        }
        f.render_widget(Paragraph::new(lines), body);
        let footer_text = if self.typing {
            format!("filter: {}_", self.filter)
        } else if self.filter.is_empty() {
            "space pause  / filter  q quit".to_string()
        } else {
            format!("filter: {}  (/ to change, / Enter to clear)", self.filter)
        };
        f.render_widget(Paragraph::new(footer_text), footer);
    }

    fn on_key(&mut self, key: KeyEvent) -> bool {
        if self.typing {
            match key.code {
                KeyCode::Enter => self.typing = false,
                KeyCode::Backspace => {
                    self.filter.pop();
                }
                KeyCode::Char(c) => self.filter.push(c),
                _ => {}
            }
            return false;
        }
        match key.code {
            KeyCode::Char('q') => return true,
            KeyCode::Char(' ') => self.paused = !self.paused,
            KeyCode::Char('/') => {
                self.typing = true;
                self.filter.clear();
            }
            _ => {}
        }
        false
    }
}

pub fn run(args: &Args) -> Result<()> {
    let dbc = Dbc::new(crate::support::dbc::load(&args.dbc, false)?);
    let source = tui::source(&args.buses, args.input.as_ref())?;
    tui::run(&mut Monitor::new(dbc), &source)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bywire_core::Timestamp;

    fn received(text: &str, at_ms: u64) -> Received {
        Received {
            frame: text.parse().unwrap(),
            timestamp: Timestamp::from_millis(at_ms),
            own: false,
            local: false,
            hardware: None,
        }
    }

    #[test]
    fn decodes_filters_and_pauses() {
        let db = bywire_dbc::parse(
            b"BO_ 291 Speed: 2 ECU\n SG_ Kph : 0|16@1+ (0.1,0) [0|6553.5] \"km/h\" X\n\
              BO_ 292 Gear: 1 ECU\n SG_ Position : 0|8@1+ (1,0) [0|3] \"\" X\n\
              VAL_ 292 Position 0 \"Park\" 1 \"Drive\" ;\n",
            bywire_dbc::Mode::Lenient,
        )
        .unwrap()
        .0;
        let mut view = Monitor::new(Dbc::new(db));
        let t0 = Instant::now();
        view.on_frame("vcan0", &received("123#6300", 0), t0);
        view.on_frame(
            "vcan0",
            &received("123#6400", 10),
            t0 + Duration::from_millis(10),
        );
        view.on_frame(
            "vcan0",
            &received("124#01", 12),
            t0 + Duration::from_millis(12),
        );
        view.on_frame(
            "vcan0",
            &received("555#01", 13),
            t0 + Duration::from_millis(13),
        );
        let (text, _) = tui::render(&mut view, 80, 10, Instant::now());
        assert!(
            text.contains("2 messages, 3 frames decoded, 1 unknown"),
            "{text}"
        );
        assert!(text.contains("Speed  (count 2, cycle 10.0 ms)"), "{text}");
        assert!(text.contains("    Kph: 10.0 km/h"), "{text}");
        assert!(text.contains("    Position: Drive"), "{text}");
        for c in ['/', 'g', 'e', 'a', 'r'] {
            assert!(!view.on_key(KeyEvent::from(KeyCode::Char(c))));
        }
        view.on_key(KeyEvent::from(KeyCode::Enter));
        let (text, _) = tui::render(&mut view, 80, 10, Instant::now());
        assert!(
            text.contains("Position: Drive") && !text.contains("Kph"),
            "{text}"
        );
        assert!(text.contains("filter: gear"), "{text}");
        view.on_key(KeyEvent::from(KeyCode::Char(' ')));
        view.on_frame(
            "vcan0",
            &received("124#00", 20),
            t0 + Duration::from_millis(20),
        );
        let (text, _) = tui::render(&mut view, 80, 10, Instant::now());
        assert!(
            text.contains("PAUSED") && text.contains("Position: Drive"),
            "{text}"
        );
        assert!(view.on_key(KeyEvent::from(KeyCode::Char('q'))));
    }
}
