//! `bywire sniff`: cansniffer — one line per identifier, changing bytes highlighted, rates, and
//! with a DBC the message's name and values.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Result;
use bywire_bus::Received;
use ratatui::crossterm::event::{KeyCode, KeyEvent};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::Paragraph;

use crate::support::signals::Dbc;
use crate::support::signals::FrameText;
use crate::tui::{self, View};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire sniff can0
  bywire sniff --dbc vehicle.dbc can0,100:700
  bywire sniff -I candump-2024-01-01_120000.log --dbc vehicle.dbc

Keys: space pauses and resumes, c clears, q (or Esc) quits. Bytes that changed in the last
--hold milliseconds are shown red; identifiers not seen for --timeout milliseconds go away.")]
pub struct Args {
    /// Buses to watch, with optional candump filters.
    buses: Vec<String>,
    /// Replay this candump log (at its recorded pace) instead of watching buses.
    #[arg(short = 'I', value_name = "FILE")]
    input: Option<PathBuf>,
    /// Show message names and signal values from this DBC.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
    /// How long a changed byte stays highlighted, in milliseconds.
    #[arg(long, default_value_t = 1000)]
    hold: u64,
    /// Drop identifiers not seen for this many milliseconds.
    #[arg(long, default_value_t = 5000)]
    timeout: u64,
}

/// One identifier's line.
struct Row {
    data: Vec<u8>,
    changed_at: Vec<Option<Instant>>,
    last_seen: Instant,
    /// When the previous frame was on the bus (its timestamp), for the cycle time.
    last_timestamp: u64,
    interval: Option<Duration>,
    count: u64,
    frame: bywire_core::Frame,
}

/// The sniffer's state.
pub struct Sniffer {
    dbc: Option<Dbc>,
    rows: BTreeMap<(String, u32), Row>,
    paused: bool,
    hold: Duration,
    timeout: Duration,
}

impl Sniffer {
    /// A sniffer with the given highlight hold and timeout.
    pub fn new(dbc: Option<Dbc>, hold: Duration, timeout: Duration) -> Sniffer {
        Sniffer {
            dbc,
            rows: BTreeMap::new(),
            paused: false,
            hold,
            timeout,
        }
    }
}

impl View for Sniffer {
    fn on_frame(&mut self, bus: &str, received: &Received, now: Instant) {
        if self.paused || received.frame.is_error() {
            return;
        }
        let frame = received.frame;
        let data = if frame.is_remote() {
            &[][..]
        } else {
            frame.data()
        };
        let key = (bus.to_string(), frame.socketcan_id());
        let row = self.rows.entry(key).or_insert_with(|| Row {
            data: data.to_vec(),
            changed_at: vec![None; data.len()],
            last_seen: now,
            last_timestamp: 0,
            interval: None,
            count: 0,
            frame,
        });
        let stamp = received.timestamp.as_nanos();
        if row.count > 0 {
            row.interval = Some(Duration::from_nanos(
                stamp.saturating_sub(row.last_timestamp),
            ));
        }
        row.last_timestamp = stamp;
        row.changed_at.resize(data.len(), Some(now));
        for (i, byte) in data.iter().enumerate() {
            if row.count > 0 && row.data.get(i) != Some(byte) {
                if let Some(at) = row.changed_at.get_mut(i) {
                    *at = Some(now);
                }
            }
        }
        row.data = data.to_vec();
        row.last_seen = now;
        row.count += 1;
        row.frame = frame;
    }

    fn draw(&mut self, f: &mut ratatui::Frame<'_>, now: Instant) {
        let timeout = self.timeout;
        self.rows
            .retain(|_, row| now.saturating_duration_since(row.last_seen) < timeout);
        let [header, body] =
            Layout::vertical([Constraint::Length(2), Constraint::Min(0)]).areas(f.area());
        let state = if self.paused { "PAUSED" } else { "running" };
        f.render_widget(
            Paragraph::new(vec![
                Line::from(format!(
                    "bywire sniff — {} identifiers — {state} — space pause, c clear, q quit",
                    self.rows.len()
                )),
                Line::from("bus        ID        cycle ms   count  data")
                    .style(Style::new().add_modifier(Modifier::BOLD)),
            ]),
            header,
        );
        let lines: Vec<Line> = self
            .rows
            .iter()
            .map(|((bus, _), row)| self.line(bus, row, now))
            .collect();
        f.render_widget(Paragraph::new(lines), body);
    }

    fn on_key(&mut self, key: KeyEvent) -> bool {
        match key.code {
            KeyCode::Char('q') => return true,
            KeyCode::Char(' ') => self.paused = !self.paused,
            KeyCode::Char('c') => self.rows.clear(),
            _ => {}
        }
        false
    }
}

impl Sniffer {
    fn line(&self, bus: &str, row: &Row, now: Instant) -> Line<'static> {
        let id = match row.frame.id() {
            Some(id) if id.is_extended() => format!("{:08X}", id.as_raw()),
            Some(id) => format!("{:03X}", id.as_raw()),
            None => "?".into(),
        };
        let cycle = row.interval.map_or("-".to_string(), |d| {
            format!("{:.1}", d.as_secs_f64() * 1000.0)
        });
        let mut spans = vec![Span::raw(format!(
            "{bus:<10} {id:>8}  {cycle:>9}  {:>6}  ",
            row.count
        ))];
        if row.frame.is_remote() {
            spans.push(Span::raw("remote request"));
        }
        for (byte, changed) in row.data.iter().zip(&row.changed_at) {
            let recent = changed.is_some_and(|at| now.saturating_duration_since(at) < self.hold);
            let style = if recent {
                Style::new().fg(Color::Red).add_modifier(Modifier::BOLD)
            } else {
                Style::new()
            };
            spans.push(Span::styled(format!("{byte:02X} "), style));
        }
        let ascii: String = row
            .data
            .iter()
            .map(|b| {
                if (0x20..0x7F).contains(b) {
                    char::from(*b)
                } else {
                    '.'
                }
            })
            .collect();
        spans.push(Span::raw(format!(" {ascii}")));
        if let Some(decoded) = self
            .dbc
            .as_ref()
            .and_then(|d| d.decoder().decode(&row.frame))
        {
            spans.push(Span::styled(
                format!("  {}", decoded.single_line(true)),
                Style::new().fg(Color::Cyan),
            ));
        }
        Line::from(spans)
    }
}

pub fn run(args: &Args) -> Result<()> {
    let dbc = match &args.dbc {
        Some(path) => Some(Dbc::new(crate::support::dbc::load(path, false)?)),
        None => None,
    };
    let source = tui::source(&args.buses, args.input.as_ref())?;
    let mut view = Sniffer::new(
        dbc,
        Duration::from_millis(args.hold),
        Duration::from_millis(args.timeout),
    );
    tui::run(&mut view, &source)
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
    fn shows_rows_rates_changes_and_names() {
        let db = bywire_dbc::parse(
            b"BO_ 291 Speed: 2 ECU\n SG_ Kph : 0|16@1+ (0.1,0) [0|6553.5] \"km/h\" X\n",
            bywire_dbc::Mode::Lenient,
        )
        .unwrap()
        .0;
        let mut view = Sniffer::new(
            Some(Dbc::new(db)),
            Duration::from_secs(1),
            Duration::from_secs(5),
        );
        let t0 = Instant::now();
        view.on_frame("vcan0", &received("123#6300", 0), t0);
        view.on_frame(
            "vcan0",
            &received("123#6400", 20),
            t0 + Duration::from_millis(20),
        );
        view.on_frame(
            "vcan0",
            &received("1ABCDEF0#414243", 25),
            t0 + Duration::from_millis(25),
        );
        let (text, buffer) = tui::render(&mut view, 120, 8, t0 + Duration::from_millis(30));
        assert!(text.contains("2 identifiers"), "{text}");
        let row = text.lines().find(|l| l.contains(" 123 ")).unwrap();
        assert!(
            row.contains("20.0") && row.contains("64 00") && row.contains("Speed(Kph: 10.0 km/h)"),
            "{row}"
        );
        assert!(text.contains("1ABCDEF0") && text.contains("ABC"), "{text}");
        // The changed first byte is red, the unchanged second byte is not.
        let y = u16::try_from(text.lines().position(|l| l.contains(" 123 ")).unwrap()).unwrap();
        let x = u16::try_from(row.find("64 00").unwrap()).unwrap();
        assert_eq!(buffer[(x, y)].fg, Color::Red);
        assert_ne!(buffer[(x + 3, y)].fg, Color::Red);
        // Pausing freezes the rows; identifiers time out.
        view.on_key(KeyEvent::from(KeyCode::Char(' ')));
        view.on_frame(
            "vcan0",
            &received("7FF#00", 40),
            t0 + Duration::from_millis(40),
        );
        let (text, _) = tui::render(&mut view, 120, 8, t0 + Duration::from_millis(50));
        assert!(text.contains("PAUSED") && !text.contains("7FF"), "{text}");
        let (text, _) = tui::render(&mut view, 120, 8, t0 + Duration::from_secs(6));
        assert!(text.contains("0 identifiers"), "{text}");
        assert!(view.on_key(KeyEvent::from(KeyCode::Char('q'))));
    }
}
