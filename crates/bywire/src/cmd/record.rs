//! `bywire record`: a field logger over `bywire_log::recorder` — several buses, listen-only
//! where the interface allows, rotation, checkpoints, a trigger window, metadata, a status line.

use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use anyhow::{anyhow, bail, Context, Result};
use bywire_bus::{Filtering, Listening};
use bywire_core::filter::ErrorMask;
use bywire_core::frame::ErrorClass;
use bywire_core::Frame;
use bywire_dbc::condition::{Compiled, Condition};
use bywire_dbc::decoder::Decoder;
use bywire_log::format::Format;
use bywire_log::recorder::{Config, Layout, Recorder, Rotation, Window};
use bywire_log::LogRecord;
use bywire_web::Database;
use serde_json::json;

use crate::support::busarg::{self, BusArg, Readers};
use crate::support::interrupt::interrupt_flag;
use crate::support::live::{Live, LiveBus, LiveConfig};
use crate::support::logs::CompressionArg;
use crate::support::numbers;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire record can0 can1 can2 --out /data/logs
  bywire record can0 can1 --out logs --format mf4 --merged --rotate-size 200M --rotate-time 10m
  bywire record can0 --out logs --profile reference-tug --pre 30 --post 10 \\
      --trigger 'VehicleToAds_State.WatchdogLevel >= 3' --trigger bus-off --trigger key
  bywire record socketcand:10.0.0.2:29536/can0 --out logs --vehicle tug-07

It never transmits. A SocketCAN interface's controller is switched to listen-only (it then
neither acknowledges frames nor sends error frames) where the interface allows, and back when
recording ends; the run says what it could do for each bus (--shared leaves controllers as
they are, for an interface this host also transmits on). Without filters every frame is kept,
error frames included.

Files are NAME-0001.blf (or NAME-0001-BUS.blf per bus), each with NAME-0001.blf.json beside
it: vehicle, profile, DBC hash, host, bitrates, buses with frame and drop counts, first and
last frame, triggers, and status (recording, or complete once finished). Every --checkpoint
the open files are made complete as they stand and synced: a kill or a power loss loses at
most that much (Parquet excepted: its footer comes last; rotate it by time).

Triggers: MESSAGE.SIGNAL OP VALUE (OP one of == != < <= > >=, VALUE a number or a value
name; needs --dbc or --profile), error-frame, bus-off, key (Enter on standard input). With
--pre/--post only the windows around triggers are kept, a file each; without, triggers are
noted in the metadata.")]
pub struct Args {
    /// Buses to record, each with optional candump filters and a label: [LABEL=]BUS[,ID:MASK|ID~MASK|#ERRMASK|j]*
    #[arg(required = true, num_args = 1..=16)]
    buses: Vec<String>,
    /// The folder the files go to (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The files' format: blf, mf4, asc, trc, candump, pcapng, mcap, parquet.
    #[arg(long, default_value = "blf")]
    format: String,
    /// With --format parquet: what the pages are compressed with (zstd by default).
    #[arg(long, value_name = "CODEC")]
    compression: Option<CompressionArg>,
    /// One file for all buses (default: a file per bus).
    #[arg(long)]
    merged: bool,
    /// Start a new file when one reaches this size (512k, 100M, 2G).
    #[arg(long, value_name = "SIZE", value_parser = numbers::size)]
    rotate_size: Option<u64>,
    /// Start a new file when one spans this long (30s, 10m, 1h).
    #[arg(long, value_name = "TIME", value_parser = numbers::duration)]
    rotate_time: Option<f64>,
    /// Make the open files complete and sync them this often (500ms, 2s, 1m).
    #[arg(long, value_name = "TIME", default_value = "2s", value_parser = numbers::duration)]
    checkpoint: f64,
    /// Keep only the windows around triggers: this long before each.
    #[arg(long, value_name = "TIME", value_parser = numbers::duration)]
    pre: Option<f64>,
    /// ... and this long after the last.
    #[arg(long, value_name = "TIME", value_parser = numbers::duration)]
    post: Option<f64>,
    /// The most frames held for --pre (the oldest are let go first, and counted).
    #[arg(long, value_name = "FRAMES", default_value_t = 2_000_000,
          value_parser = clap::value_parser!(u64).range(1..=50_000_000))]
    max_held: u64,
    /// A trigger (repeatable): MESSAGE.SIGNAL OP VALUE, error-frame, bus-off or key.
    #[arg(long = "trigger", value_name = "WHEN")]
    triggers: Vec<String>,
    /// The DBC for signal triggers (its SHA-256 goes into the metadata).
    #[arg(long, value_name = "FILE", conflicts_with = "profile")]
    dbc: Option<PathBuf>,
    /// A vehicle profile (built in or a TOML file): its DBC for signal triggers, its name for
    /// the metadata.
    #[arg(long, value_name = "PROFILE")]
    profile: Option<String>,
    /// The vehicle's name for the metadata.
    #[arg(long, value_name = "NAME")]
    vehicle: Option<String>,
    /// A bus's bitrate for the metadata, where it cannot be read from the interface.
    #[arg(long, value_name = "BUS=BITRATE")]
    bitrate: Vec<String>,
    /// Leave the controllers' modes as they are (this host transmits on them too).
    #[arg(long)]
    shared: bool,
    /// The start of the files' names (default: the start time, 20261203T221700Z).
    #[arg(long, value_name = "NAME")]
    name: Option<String>,
    /// Stop after this long (default: at Ctrl-C).
    #[arg(long, value_name = "TIME", value_parser = numbers::duration)]
    duration: Option<f64>,
    /// No status line.
    #[arg(long)]
    quiet: bool,
    /// While recording, serve the page and the Foxglove WebSocket protocol here (loopback
    /// only): every recorded frame, decoded with --dbc. Nothing is sent: the recorder only
    /// listens.
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8080")]
    foxglove: Option<std::net::SocketAddr>,
}

/// What starts a capture (or is noted).
enum Trigger {
    Signal(Compiled),
    ErrorFrame,
    BusOff,
    Key,
}

impl Trigger {
    fn parse(text: &str, decoder: Option<&Decoder>) -> Result<Trigger> {
        Ok(match text.trim() {
            "error-frame" => Trigger::ErrorFrame,
            "bus-off" => Trigger::BusOff,
            "key" => Trigger::Key,
            condition => {
                let condition: Condition = condition
                    .parse()
                    .map_err(|e| anyhow!("--trigger {e} (or error-frame, bus-off, key)"))?;
                let decoder = decoder.ok_or_else(|| {
                    anyhow!("--trigger '{condition}' needs the signals' DBC: --dbc or --profile")
                })?;
                Trigger::Signal(
                    condition
                        .compile(decoder)
                        .map_err(|e| anyhow!("--trigger {e}"))?,
                )
            }
        })
    }
}

fn nanos(seconds: f64) -> u64 {
    // Options are checked to at most a week: far inside u64 nanoseconds.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let n = (seconds * 1e9).round() as u64;
    n
}

fn now_ns() -> u64 {
    let since = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or_default();
    u64::try_from(since.as_nanos()).unwrap_or(u64::MAX)
}

/// Undoes the listen-only switches when recording ends (however it ends but a kill).
struct ListenOnlyGuard(Vec<String>);

impl Drop for ListenOnlyGuard {
    fn drop(&mut self) {
        #[cfg(target_os = "linux")]
        for interface in &self.0 {
            if let Err(e) = bywire_bus::socketcan::clear_listen_only(interface) {
                let _ = writeln!(
                    std::io::stderr(),
                    "{interface}: could not leave listen-only mode: {e}"
                );
            }
        }
    }
}

/// The windows kept around triggers, if --pre or --post asks for them.
fn window(args: &Args) -> Result<Option<Window>> {
    let window = match (args.pre, args.post) {
        (None, None) => None,
        (pre, post) => Some(Window {
            before_ns: nanos(pre.unwrap_or(0.0)),
            after_ns: nanos(post.unwrap_or(0.0)),
            max_held: usize::try_from(args.max_held).unwrap_or(usize::MAX),
        }),
    };
    if window.is_some() && args.triggers.is_empty() {
        bail!("--pre and --post keep the windows around triggers: give at least one --trigger");
    }
    Ok(window)
}

/// The database triggers decode with (--dbc, or a profile's), and what the recording's
/// metadata says of it.
fn decoder(
    args: &Args,
    metadata: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<Option<Decoder>> {
    Ok(match (&args.dbc, &args.profile) {
        (Some(path), _) => {
            let database = crate::support::dbc::load(path, false)?;
            metadata.insert(
                "dbc".into(),
                json!({ "file": path.display().to_string(),
                        "sha256": crate::support::files::sha256(path)? }),
            );
            Some(Decoder::new(database))
        }
        (None, Some(name)) => {
            let loaded = crate::support::vehicles::load_profile(name)?;
            metadata.insert("profile".into(), json!(loaded.profile.name));
            let text = bywire_dbc::write(&loaded.database);
            metadata.insert(
                "dbc".into(),
                json!({ "file": loaded.profile.dbc,
                        "sha256_of_canonical_text": crate::support::files::sha256_bytes(text.as_bytes()) }),
            );
            Some(Decoder::new(loaded.database))
        }
        (None, None) => None,
    })
}

/// The buses' bitrates as --bitrate gives them (BUS=BITRATE).
fn bitrates(args: &Args) -> Result<serde_json::Map<String, serde_json::Value>> {
    let mut bitrates = serde_json::Map::new();
    for entry in &args.bitrate {
        let (bus, rate) = entry
            .split_once('=')
            .ok_or_else(|| anyhow!("--bitrate {entry}: BUS=BITRATE"))?;
        let rate: u32 = rate
            .parse()
            .ok()
            .filter(|r| (1_000..=16_000_000).contains(r))
            .ok_or_else(|| anyhow!("--bitrate {entry}: a bitrate from 1000 to 16000000"))?;
        bitrates.insert(bus.to_string(), json!(rate));
    }
    Ok(bitrates)
}

/// Every bus opened (all before recording starts), each as quiet as it can be made: the
/// endpoints, the interfaces switched to listen-only (switched back when the guard goes), and
/// what each bus is (said on stderr too). A SocketCAN interface's bitrate is read where
/// --bitrate did not give it.
fn open_quietly(
    args: &Args,
    buses: &[BusArg],
    bitrates: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<Opened> {
    let everything = Filtering {
        error_mask: ErrorMask::ALL,
        ..Filtering::default()
    };
    let mut opened = Vec::new();
    let mut switched = ListenOnlyGuard(Vec::new());
    let mut listening = serde_json::Map::new();
    for bus in buses {
        let (endpoint, state) = if args.shared {
            let endpoint = bus
                .open_filtered(Some(everything.clone()))
                .with_context(|| format!("bus '{}'", bus.spec))?;
            (endpoint, Listening::NotListenOnly("--shared".into()))
        } else {
            bus.open_listening(Some(everything.clone()))
                .with_context(|| format!("bus '{}'", bus.spec))?
        };
        let said = match &state {
            Listening::SwitchedToListenOnly => {
                if let Some(interface) = bus.spec.strip_prefix("socketcan:") {
                    switched.0.push(interface.to_string());
                }
                "listen-only (switched for this recording)".to_string()
            }
            Listening::ListenOnly => "listen-only".to_string(),
            Listening::NotListenOnly(why) => {
                format!("NOT listen-only: {why}; its controller acknowledges frames")
            }
            Listening::NoController(why) => format!("no controller to set ({why})"),
        };
        let _ = writeln!(std::io::stderr(), "{}: {said}", bus.name);
        listening.insert(bus.name.clone(), json!(said));
        #[cfg(target_os = "linux")]
        if let Some(interface) = bus.spec.strip_prefix("socketcan:") {
            if let Ok(Some((rate, _))) = bywire_bus::socketcan::bit_timing(interface) {
                bitrates.entry(bus.name.clone()).or_insert(json!(rate));
            }
        }
        opened.push(endpoint);
    }
    Ok(Opened {
        endpoints: opened,
        switched,
        listening,
    })
}

/// The buses opened for a recording.
struct Opened {
    endpoints: Vec<Box<dyn bywire_bus::Bus>>,
    /// The interfaces switched to listen-only, switched back when it goes.
    switched: ListenOnlyGuard,
    /// What each bus is: listen-only or why not.
    listening: serde_json::Map<String, serde_json::Value>,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    // Everything is checked before a bus is touched.
    let format = Format::named(&args.format).ok_or_else(|| {
        let names: Vec<&str> = Format::ALL.iter().map(|(_, n)| *n).collect();
        anyhow!("--format {}: one of {}", args.format, names.join(", "))
    })?;
    let compression = CompressionArg::for_output(
        args.compression,
        format,
        &format!("--format {}", args.format),
    )?;
    let window = window(args)?;
    let mut metadata = serde_json::Map::new();
    let decoder = decoder(args, &mut metadata)?;
    let triggers: Vec<Trigger> = args
        .triggers
        .iter()
        .map(|t| Trigger::parse(t, decoder.as_ref()))
        .collect::<Result<_>>()?;
    let mut bitrates = bitrates(args)?;
    let buses: Vec<BusArg> = args
        .buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;

    let Opened {
        endpoints: opened,
        switched,
        listening,
    } = open_quietly(args, &buses, &mut bitrates)?;

    let started = now_ns();
    let name = args.name.clone().unwrap_or_else(|| compact_utc(started));
    if let Some(vehicle) = &args.vehicle {
        metadata.insert("vehicle".into(), json!(vehicle));
    }
    metadata.insert("host".into(), json!(host_name()));
    metadata.insert(
        "recorder".into(),
        json!(format!("bywire {}", env!("CARGO_PKG_VERSION"))),
    );
    metadata.insert("session".into(), json!(name));
    metadata.insert("bitrates".into(), serde_json::Value::Object(bitrates));
    metadata.insert("listen_only".into(), serde_json::Value::Object(listening));
    let mut recorder = Recorder::new(Config {
        dir: args.out.clone(),
        name,
        format,
        compression,
        layout: if args.merged {
            Layout::Merged
        } else {
            Layout::PerBus
        },
        rotation: Rotation {
            max_bytes: args.rotate_size,
            max_span_ns: args.rotate_time.map(nanos),
        },
        checkpoint_ns: nanos(args.checkpoint),
        window,
        metadata,
    })?;
    if !format.survives_a_cut() && args.rotate_time.is_none() {
        let _ = writeln!(
            std::io::stderr(),
            "note: a {} file is readable only once finished; --rotate-time bounds what a kill loses",
            args.format
        );
    }

    let keys = triggers
        .iter()
        .any(|t| matches!(t, Trigger::Key))
        .then(key_presses);
    let live = match args.foxglove {
        Some(listen) => Some(serve_live(listen, &buses, decoder.as_ref(), out)?),
        None => None,
    };
    let readers = Readers::start(opened);
    let result = record(
        args,
        &buses,
        &readers,
        keys.as_ref(),
        &triggers,
        decoder.as_ref(),
        &mut recorder,
        live.as_ref(),
    );
    if let Some(live) = live {
        live.stop();
    }
    let dropped: Vec<u64> = readers
        .dropped
        .iter()
        .map(|d| d.load(Ordering::Relaxed))
        .collect();
    drop(readers);
    for (bus, dropped) in buses.iter().zip(&dropped) {
        recorder.set_dropped(&bus.name, *dropped);
    }
    // Every way out (Ctrl-C, --duration, a lost bus) finishes the files.
    let files = recorder.finish().context("cannot finish the files")?;
    drop(switched);
    for file in &files {
        writeln!(
            out,
            "{} {} frames {} bytes",
            file.path.display(),
            file.frames,
            file.bytes
        )?;
    }
    let lost: u64 = dropped.iter().sum();
    if lost > 0 {
        let _ = writeln!(
            std::io::stderr(),
            "dropped before they reached the recorder: {lost} frames"
        );
    }
    result
}

/// The page and Foxglove server of `--foxglove`: fed the recorded frames.
fn serve_live(
    listen: std::net::SocketAddr,
    buses: &[BusArg],
    decoder: Option<&Decoder>,
    out: &mut impl Write,
) -> Result<Live> {
    if !listen.ip().is_loopback() {
        bail!("--foxglove {listen}: not a loopback address (use `bywire web` with --allow-remote and a token to reach other hosts)");
    }
    let database = decoder.map(|d| Arc::new(Database::new(d.clone())));
    let fed: Vec<LiveBus> = buses
        .iter()
        .map(|arg| LiveBus {
            arg: arg.clone(),
            bitrate: None,
            database: database.clone(),
            fed: true,
        })
        .collect();
    let live = Live::start(
        &fed,
        LiveConfig::new("bywire record", listen, bywire_web::Access::default()),
        |hub| hub,
    )?;
    crate::support::live::announce(out, live.address())?;
    Ok(live)
}

/// The recording loop: frames in, triggers checked, time passed to the recorder, the status
/// line. Ends at Ctrl-C, at --duration, or when every bus is lost.
#[allow(clippy::too_many_arguments)]
fn record(
    args: &Args,
    buses: &[BusArg],
    readers: &Readers,
    keys: Option<&mpsc::Receiver<u64>>,
    triggers: &[Trigger],
    decoder: Option<&Decoder>,
    recorder: &mut Recorder,
    live: Option<&Live>,
) -> Result<()> {
    let stop = interrupt_flag();
    let mut scratch = Vec::new();
    let began = Instant::now();
    let end = args.duration.map(Duration::from_secs_f64);
    let mut status = Status::new(buses.len(), !args.quiet);
    let mut lost = vec![false; buses.len()];
    let mut holding = vec![false; triggers.len()];
    let mut values = Vec::new();
    loop {
        if stop.load(Ordering::Relaxed) || end.is_some_and(|e| began.elapsed() >= e) {
            return Ok(());
        }
        match readers.events.recv_timeout(Duration::from_millis(20)) {
            Ok((index, Ok(received))) => {
                let name = buses.get(index).map_or("?", |b| b.name.as_str());
                status.count(index);
                let at = received.timestamp.as_nanos();
                for (trigger, holding) in triggers.iter().zip(holding.iter_mut()) {
                    let holds = match trigger {
                        Trigger::Signal(c) => decoder
                            .and_then(|d| c.holds(d, &received.frame, &mut values))
                            .unwrap_or(*holding),
                        Trigger::ErrorFrame => matches!(received.frame, Frame::Error(_)),
                        Trigger::BusOff => matches!(&received.frame, Frame::Error(e)
                            if e.class_bits() & ErrorClass::BusOff.bit() != 0),
                        Trigger::Key => false,
                    };
                    if holds && !*holding {
                        let reason = match trigger {
                            Trigger::Signal(c) => c.condition().to_string(),
                            Trigger::ErrorFrame => format!("error frame on {name}"),
                            Trigger::BusOff => format!("bus-off on {name}"),
                            Trigger::Key => "key".to_string(),
                        };
                        recorder.trigger(at, &reason)?;
                    } else if holds {
                        recorder.extend(at);
                    }
                    // Error frames are events: each one is a trigger of its own.
                    *holding = holds && matches!(trigger, Trigger::Signal(_));
                }
                if let Some(live) = live {
                    live.hub().on_frame(index, &received, &mut scratch);
                }
                recorder.record(LogRecord {
                    timestamp: received.timestamp,
                    interface: name.to_string(),
                    frame: received.frame,
                    direction: Some(if received.own { 'T' } else { 'R' }),
                })?;
            }
            Ok((index, Err(why))) => {
                let name = buses.get(index).map_or("?", |b| b.name.as_str());
                let _ = writeln!(
                    std::io::stderr(),
                    "\nbus '{name}' lost: {why} (recording goes on with the others)"
                );
                if let Some(flag) = lost.get_mut(index) {
                    *flag = true;
                }
                if lost.iter().all(|l| *l) {
                    bail!("every bus is lost");
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => bail!("every bus is lost"),
        }
        if let Some(keys) = keys {
            while let Ok(at) = keys.try_recv() {
                recorder.trigger(at, "key")?;
            }
        }
        let now = now_ns();
        recorder.tick(now)?;
        status.show(buses, readers, recorder);
    }
}

/// Enter on standard input, as times; the thread ends with the input.
fn key_presses() -> mpsc::Receiver<u64> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        for line in stdin.lock().lines() {
            if line.is_err() || tx.send(now_ns()).is_err() {
                break;
            }
        }
    });
    rx
}

/// The status line: frames a second per bus, bytes and files written, drops, the trigger
/// window's state; on standard error once a second (in place on a terminal).
struct Status {
    shown: bool,
    terminal: bool,
    last: Instant,
    counts: Vec<u64>,
}

impl Status {
    fn new(buses: usize, shown: bool) -> Status {
        Status {
            shown,
            terminal: std::io::stderr().is_terminal(),
            last: Instant::now(),
            counts: vec![0; buses],
        }
    }

    fn count(&mut self, index: usize) {
        if let Some(c) = self.counts.get_mut(index) {
            *c += 1;
        }
    }

    fn show(&mut self, buses: &[BusArg], readers: &Readers, recorder: &Recorder) {
        let elapsed = self.last.elapsed();
        if elapsed < Duration::from_secs(1) {
            return;
        }
        self.last = Instant::now();
        let mut line = String::new();
        for ((bus, count), dropped) in buses.iter().zip(&mut self.counts).zip(&readers.dropped) {
            let rate = *count as f64 / elapsed.as_secs_f64();
            line.push_str(&format!("{} {rate:.0} fr/s", bus.name));
            let dropped = dropped.load(Ordering::Relaxed);
            if dropped > 0 {
                line.push_str(&format!(" ({dropped} dropped)"));
            }
            line.push_str("  ");
            *count = 0;
        }
        let progress = recorder.progress();
        line.push_str(&format!(
            "| {:.1} MB in {}",
            progress.bytes_written as f64 / 1e6,
            crate::support::words::counted(progress.files, "file")
        ));
        if progress.capturing {
            line.push_str(" | capturing");
        } else if progress.held > 0 || progress.held_overflow > 0 {
            line.push_str(&format!(" | armed, {} held", progress.held));
        }
        if !self.shown {
            return;
        }
        let mut err = std::io::stderr();
        let _ = if self.terminal {
            write!(err, "\r{line}\x1b[K")
        } else {
            writeln!(err, "{line}")
        };
    }
}

/// `20261203T221700Z`.
fn compact_utc(nanos: u64) -> String {
    let seconds = i64::try_from(nanos / 1_000_000_000).unwrap_or(0);
    chrono::DateTime::from_timestamp(seconds, 0)
        .map(|t| t.format("%Y%m%dT%H%M%SZ").to_string())
        .unwrap_or_else(|| "recording".to_string())
}

fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default()
}
