//! What the terminal views (`sniff`, `monitor`) share: a source of frames — live buses or a
//! candump log replayed at its own pace — and the loop that feeds a view, draws it and reads
//! keys. Views are plain state plus a draw function, so tests render them on ratatui's
//! `TestBackend` without a terminal.

pub mod sim_view;

use std::fs::File;
use std::io::{BufReader, IsTerminal};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_bus::Received;
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyEvent, KeyEventKind};
use rustix::event::{poll, PollFd, PollFlags};

use crate::support::busarg::{self, BusArg, Event, Readers};

/// Where frames come from.
pub struct Source {
    frames: Frames,
    /// The buses' names, by the index events carry.
    pub names: Vec<String>,
    stop: Arc<AtomicBool>,
}

enum Frames {
    Live(Readers),
    Log(Receiver<Event>),
}

impl Source {
    /// The frames, with the index of their bus in `names`.
    pub fn events(&self) -> &Receiver<Event> {
        match &self.frames {
            Frames::Live(readers) => &readers.events,
            Frames::Log(events) => events,
        }
    }
}

impl Drop for Source {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Live buses (with candump filters), or with `log` a candump log played in real time.
pub fn source(buses: &[String], log: Option<&PathBuf>) -> Result<Source> {
    let stop = Arc::new(AtomicBool::new(false));
    if let Some(path) = log {
        if !buses.is_empty() {
            return Err(anyhow!("give buses or -I FILE, not both"));
        }
        return replay(path, stop);
    }
    if buses.is_empty() {
        return Err(anyhow!(
            "no bus given (e.g. can0, virtual:test) and no -I FILE"
        ));
    }
    let args: Vec<BusArg> = buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    let readers = Readers::start(busarg::open_all(&args)?);
    Ok(Source {
        frames: Frames::Live(readers),
        names: args.into_iter().map(|a| a.name).collect(),
        stop,
    })
}

/// A log (any format) as a source: each record at its time after the first, as it was
/// recorded.
fn replay(path: &Path, stop: Arc<AtomicBool>) -> Result<Source> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let (tx, events) = mpsc::sync_channel(4096);
    let shown = path.display().to_string();
    let thread_stop = Arc::clone(&stop);
    std::thread::spawn(move || {
        let started = Instant::now();
        let mut pacer = bywire_log::pacing::Pacer::new(1.0);
        let mut input = BufReader::new(file);
        let format = bywire_log::format::Format::sniff_input(&mut input)
            .unwrap_or(bywire_log::format::Format::Candump);
        for record in format.reader(input) {
            if thread_stop.load(Ordering::Relaxed) {
                break;
            }
            let event = match record {
                Ok(r) => {
                    let due = started + pacer.due(r.timestamp);
                    std::thread::sleep(due.saturating_duration_since(Instant::now()));
                    Ok(Received {
                        frame: r.frame,
                        timestamp: r.timestamp,
                        own: false,
                        local: false,
                        hardware: None,
                    })
                }
                Err(e) => Err(format!("{shown}: {e}")),
            };
            let failed = event.is_err();
            if tx.send((0, event)).is_err() || failed {
                break;
            }
        }
    });
    Ok(Source {
        frames: Frames::Log(events),
        names: vec![path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )],
        stop,
    })
}

/// A terminal view.
pub trait View {
    /// A frame arrived (from bus `bus`), at wall-clock `now`.
    fn on_frame(&mut self, bus: &str, received: &Received, now: Instant);
    /// Draw the whole view.
    fn draw(&mut self, frame: &mut ratatui::Frame<'_>, now: Instant);
    /// A key was pressed; true to quit.
    fn on_key(&mut self, key: KeyEvent) -> bool;
}

/// Run `view` on the terminal until q, Esc or Ctrl-C (or the source ends and a key is pressed).
pub fn run(view: &mut impl View, source: &Source) -> Result<()> {
    if !std::io::stdout().is_terminal() {
        return Err(anyhow!(
            "this view needs a terminal; use `bywire dump` (or --dbc with it) to print frames"
        ));
    }
    // Asked now, while the terminal is surely there.
    stdin_is_terminal();
    let mut terminal = ratatui::init();
    let result = event_loop(view, source, &mut terminal);
    restore(terminal);
    result
}

/// Put the terminal back as it was: cursor shown, raw mode off, the main screen back. Every
/// step may fail on a terminal that is going away (its window closed mid-way) and is let fail:
/// ratatui's own clean-up, when its terminal is dropped, reports such a failure with
/// `eprintln!`, which panics on that same terminal — so the terminal is forgotten instead.
pub fn restore(terminal: ratatui::DefaultTerminal) {
    std::mem::forget(terminal);
    let _ = ratatui::crossterm::execute!(std::io::stdout(), ratatui::crossterm::cursor::Show);
    let _ = ratatui::try_restore();
}

fn event_loop(
    view: &mut impl View,
    source: &Source,
    terminal: &mut ratatui::DefaultTerminal,
) -> Result<()> {
    let frame_interval = Duration::from_millis(100);
    loop {
        // Take what has arrived, for at most half a drawing interval, so keys stay responsive
        // under any load.
        let deadline = Instant::now() + frame_interval / 2;
        while Instant::now() < deadline {
            match source.events().try_recv() {
                Ok((index, Ok(received))) => {
                    let name = source.names.get(index).map_or("?", String::as_str);
                    view.on_frame(name, &received, Instant::now());
                }
                Ok((index, Err(e))) => {
                    let name = source.names.get(index).map_or("?", String::as_str);
                    return Err(anyhow!("{name}: {e}"));
                }
                Err(_) => break,
            }
        }
        if !draw(terminal, |f| view.draw(f, Instant::now()))? {
            return Ok(());
        }
        match next_input(frame_interval)? {
            Input::Event(TermEvent::Key(key))
                if key.kind == KeyEventKind::Press && (is_quit(key) || view.on_key(key)) =>
            {
                return Ok(());
            }
            Input::HungUp => return Ok(()),
            Input::Event(_) | Input::Nothing => {}
        }
    }
}

/// Draw a view: true once drawn, false when the terminal went away (it hung up between two
/// draws or in the middle of one); any other failure is an error.
pub fn draw(
    terminal: &mut ratatui::DefaultTerminal,
    render: impl FnOnce(&mut ratatui::Frame<'_>),
) -> Result<bool> {
    match terminal.draw(render) {
        Ok(_) => Ok(true),
        Err(_) if terminal_gone() => Ok(false),
        Err(e) => Err(e.into()),
    }
}

/// What the terminal gave while a view waited.
pub enum Input {
    /// A key, a resize, ...
    Event(TermEvent),
    /// Nothing within the wait.
    Nothing,
    /// The terminal hung up (its window closed, its tmux session killed): the view ends.
    HungUp,
}

/// Wait up to `timeout` for terminal input. On a terminal at standard input the wait is ours:
/// crossterm's reader spins for ever on a terminal that hung up instead of returning.
pub fn next_input(timeout: Duration) -> Result<Input> {
    let read = || -> Result<Input> { Ok(Input::Event(event::read()?)) };
    if !stdin_is_terminal() {
        return if event::poll(timeout)? {
            read()
        } else {
            Ok(Input::Nothing)
        };
    }
    if terminal_gone() {
        return Ok(Input::HungUp);
    }
    // Events crossterm already holds, then the terminal itself.
    if event::poll(Duration::ZERO)? {
        return read();
    }
    let ready = poll_stdin(i32::try_from(timeout.as_millis()).unwrap_or(i32::MAX));
    if ready.intersects(gone()) {
        Ok(Input::HungUp)
    } else if ready.contains(PollFlags::IN) && event::poll(Duration::ZERO)? {
        read()
    } else {
        Ok(Input::Nothing)
    }
}

/// Whether standard input is a terminal, as it was when first asked (a terminal that hung up
/// no longer says it is one).
pub fn stdin_is_terminal() -> bool {
    static TERMINAL: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *TERMINAL.get_or_init(|| std::io::stdin().is_terminal())
}

/// Whether the terminal at standard input hung up.
fn terminal_gone() -> bool {
    stdin_is_terminal() && poll_stdin(0).intersects(gone())
}

fn gone() -> PollFlags {
    PollFlags::HUP | PollFlags::ERR | PollFlags::NVAL
}

/// What standard input is ready for within `ms` milliseconds (nothing when interrupted).
fn poll_stdin(ms: i32) -> PollFlags {
    let stdin = rustix::stdio::stdin();
    let mut fds = [PollFd::new(&stdin, PollFlags::IN)];
    match poll(&mut fds, ms) {
        Ok(_) => fds.first().map_or(PollFlags::empty(), PollFd::revents),
        Err(_) => PollFlags::empty(),
    }
}

fn is_quit(key: KeyEvent) -> bool {
    use ratatui::crossterm::event::KeyModifiers;
    matches!(key.code, KeyCode::Esc)
        || (key.code == KeyCode::Char('c') && key.modifiers.contains(KeyModifiers::CONTROL))
}

/// A view drawn on ratatui's `TestBackend`: the screen as text, and the buffer for styles.
#[cfg(test)]
pub fn render(
    view: &mut impl View,
    width: u16,
    height: u16,
    now: Instant,
) -> (String, ratatui::buffer::Buffer) {
    let mut terminal =
        ratatui::Terminal::new(ratatui::backend::TestBackend::new(width, height)).unwrap();
    terminal.draw(|f| view.draw(f, now)).unwrap();
    let buffer = terminal.backend().buffer().clone();
    let text = buffer
        .content()
        .chunks(usize::from(width))
        .map(|row| row.iter().map(|c| c.symbol()).collect::<String>())
        .collect::<Vec<_>>()
        .join("\n");
    (text, buffer)
}
