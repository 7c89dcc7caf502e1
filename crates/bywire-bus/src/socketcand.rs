//! The socketcand protocol: a server that lets any socketcand client (python-can's
//! `socketcand` interface, SavvyCAN) join a bywire bus over TCP.
//!
//! Text commands between `<` and `>`: the server greets with `< hi >`; the client opens a bus
//! (`< open NAME >` → `< ok >`) and is then in BCM mode; `< rawmode >` switches to raw mode, in
//! which every frame goes to the client as `< frame ID SECS.USECS DATA >` and
//! `< send ID LEN B0 B1 ... >` puts one on the bus. BCM mode: `< add SECS USECS ID LEN B... >`
//! sends a frame cyclically, `< update ... >` changes its data, `< delete ID >` stops it,
//! `< subscribe SECS USECS ID >` forwards that identifier (at most once per interval when one
//! is given), `< unsubscribe ID >` stops it, `< filter SECS USECS ID LEN B... >` forwards it when
//! the bits under the mask B... change. `< echo >` is answered with `< echo >`. Anything
//! malformed gets `< error TEXT >` and the session goes on.
//!
//! Each client gets its own endpoint on the served bus and its own bounded output queue: a
//! slow client loses frames (counted) and never stalls the bus or the other clients. Raw mode
//! has no transmit confirmation, no FD and no error frames.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use bywire_core::{ClassicFrame, Frame, Id, Timestamp};

use crate::{Bus, BusError, BusTx, Received};

/// The longest command accepted; longer input is an error and is discarded.
const MAX_COMMAND: usize = 256;
/// The same, as a byte count for `Read::take`.
const MAX_COMMAND_BYTES: u64 = 256;
/// Frames queued for one client before further ones are dropped and counted.
pub const CLIENT_QUEUE: usize = 8192;

/// A client command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `open NAME`.
    Open(String),
    /// `rawmode`.
    RawMode,
    /// `bcmmode`.
    BcmMode,
    /// `echo`.
    Echo,
    /// `send ID LEN DATA`.
    Send(Frame),
    /// `add SECS USECS ID LEN DATA`: send every interval.
    Add(Duration, Frame),
    /// `update SECS USECS ID LEN DATA`: new data for a cyclic frame (and interval, if not 0).
    Update(Duration, Frame),
    /// `delete ID`.
    Delete(Id),
    /// `subscribe SECS USECS ID`: forward this identifier, throttled.
    Subscribe(Duration, Id),
    /// `filter SECS USECS ID LEN MASK`: forward this identifier when the bits under the mask
    /// change (the first frame always), throttled.
    Filter(Duration, Id, [u8; 8]),
    /// `unsubscribe ID`.
    Unsubscribe(Id),
}

fn id(text: &str) -> Result<Id, String> {
    let raw = u32::from_str_radix(text, 16).map_err(|_| format!("'{text}' is not a hex ID"))?;
    let result = if text.len() > 3 || raw > 0x7FF {
        Id::extended(raw)
    } else {
        Id::standard(raw)
    };
    result.map_err(|e| format!("ID {text}: {e}"))
}

fn frame(id_text: &str, len_text: &str, bytes: &[&str]) -> Result<Frame, String> {
    let id = id(id_text)?;
    let len =
        usize::from_str_radix(len_text, 16).map_err(|_| format!("'{len_text}' is not a length"))?;
    if len > 8 || bytes.len() != len {
        return Err(format!(
            "length {len} with {} data bytes (0 to 8, and equal)",
            bytes.len()
        ));
    }
    let mut data = [0u8; 8];
    for (slot, text) in data.iter_mut().zip(bytes) {
        if text.is_empty() || text.len() > 2 {
            return Err(format!("'{text}' is not a byte"));
        }
        *slot = u8::from_str_radix(text, 16).map_err(|_| format!("'{text}' is not a hex byte"))?;
    }
    ClassicFrame::new(id, data.get(..len).unwrap_or(&[]))
        .map(Frame::Classic)
        .map_err(|e| e.to_string())
}

fn interval(secs: &str, usecs: &str) -> Result<Duration, String> {
    let s: u64 = secs
        .parse()
        .map_err(|_| format!("'{secs}' is not seconds"))?;
    let u: u64 = usecs
        .parse()
        .map_err(|_| format!("'{usecs}' is not microseconds"))?;
    Ok(Duration::from_secs(s.min(86_400)) + Duration::from_micros(u.min(999_999_999)))
}

/// Parse the words between `<` and `>`.
pub fn parse_command(inner: &str) -> Result<Command, String> {
    let words: Vec<&str> = inner.split_whitespace().collect();
    match words.as_slice() {
        ["open", name] => Ok(Command::Open((*name).to_string())),
        ["rawmode"] => Ok(Command::RawMode),
        ["bcmmode"] => Ok(Command::BcmMode),
        ["echo"] => Ok(Command::Echo),
        ["send", i, l, data @ ..] => frame(i, l, data).map(Command::Send),
        ["add", s, u, i, l, data @ ..] => Ok(Command::Add(interval(s, u)?, frame(i, l, data)?)),
        ["update", s, u, i, l, data @ ..] => {
            Ok(Command::Update(interval(s, u)?, frame(i, l, data)?))
        }
        ["delete", i] => id(i).map(Command::Delete),
        ["subscribe", s, u, i] => Ok(Command::Subscribe(interval(s, u)?, id(i)?)),
        ["filter", s, u, i, l, mask @ ..] => {
            let mask_frame = frame(i, l, mask)?;
            let mut bytes = [0u8; 8];
            for (b, m) in bytes.iter_mut().zip(mask_frame.data()) {
                *b = *m;
            }
            Ok(Command::Filter(interval(s, u)?, id(i)?, bytes))
        }
        ["unsubscribe", i] => id(i).map(Command::Unsubscribe),
        [] => Err("empty command".into()),
        [word, ..] => Err(format!("unknown or malformed command '{word}'")),
    }
}

/// A frame as the server sends it: `< frame 123 1699999999.123456 DEADBEEF >`.
pub fn format_frame(frame: &Frame, timestamp: Timestamp) -> Option<String> {
    let id = frame.id()?;
    if frame.is_fd() || frame.is_remote() {
        return None; // socketcand's text has no way to say either
    }
    let id_text = if id.is_extended() {
        format!("{:08X}", id.as_raw())
    } else {
        format!("{:03X}", id.as_raw())
    };
    let nanos = timestamp.as_nanos();
    let data: String = frame.data().iter().map(|b| format!("{b:02X}")).collect();
    Some(format!(
        "< frame {id_text} {}.{:06} {data} >",
        nanos / 1_000_000_000,
        nanos % 1_000_000_000 / 1000
    ))
}

/// Counts the server keeps over all clients.
#[derive(Debug, Default)]
pub struct ServerStats {
    /// Clients accepted.
    pub clients: AtomicU64,
    /// Frames not delivered because a client's queue was full.
    pub dropped: AtomicU64,
    /// Malformed commands answered with an error.
    pub errors: AtomicU64,
}

/// Who may use the server.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Access {
    /// Bus names clients may open (empty: any name).
    pub names: Vec<String>,
    /// When set, clients must send `< auth TOKEN >` before anything else (an extension of
    /// ours: plain socketcand clients cannot, so it is for listeners beyond this host).
    pub token: Option<String>,
}

/// Opens an endpoint on the bus a client named.
pub type OpenBus = dyn Fn(&str) -> Result<Box<dyn Bus>, BusError> + Send + Sync;

/// Serve `listener`'s clients: each gets an endpoint from `open_bus` (given the name) when it
/// opens a bus name `access` allows. Runs until `stop` is set.
pub fn serve(
    listener: TcpListener,
    access: Access,
    open_bus: Arc<OpenBus>,
    stop: Arc<AtomicBool>,
    stats: Arc<ServerStats>,
) -> std::io::Result<()> {
    listener.set_nonblocking(true)?;
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                stats.clients.fetch_add(1, Ordering::Relaxed);
                let (access, open_bus, stop, stats) = (
                    access.clone(),
                    Arc::clone(&open_bus),
                    Arc::clone(&stop),
                    Arc::clone(&stats),
                );
                std::thread::spawn(move || {
                    let _ = session(stream, &access, open_bus.as_ref(), &stop, &stats);
                });
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// One BCM subscription or content filter.
struct Subscription {
    /// At most one frame per interval.
    every: Duration,
    /// When the last one was forwarded.
    last: Option<Instant>,
    /// Content filter: forward only when these bits change.
    mask: Option<[u8; 8]>,
    /// The masked data last forwarded.
    last_masked: Option<[u8; 8]>,
}

impl Subscription {
    /// Whether a frame with `data` arriving at `now` goes to the client (and note it if so).
    fn wants(&mut self, data: &[u8], now: Instant) -> bool {
        if self
            .last
            .is_some_and(|l| now.saturating_duration_since(l) < self.every)
        {
            return false;
        }
        if let Some(mask) = self.mask {
            let mut masked = [0u8; 8];
            for ((m, d), k) in masked.iter_mut().zip(data).zip(mask) {
                *m = d & k;
            }
            if self.last_masked == Some(masked) {
                return false;
            }
            self.last_masked = Some(masked);
        }
        self.last = Some(now);
        true
    }
}

/// What the client's reader shares with the thread that feeds it frames.
/// What a session's writer thread does next.
enum Outgoing {
    /// Send this text.
    Text(String),
    /// Send nothing for this long (see [`RAW_MODE_GRACE`]).
    Pause(Duration),
}

/// How long after acknowledging `< rawmode >` frames start to flow (see the command).
const RAW_MODE_GRACE: Duration = Duration::from_millis(50);

struct Subscriptions {
    raw: AtomicBool,
    /// Identifier (SocketCAN form) → throttle interval and when it was last forwarded.
    by_id: std::sync::Mutex<BTreeMap<u32, Subscription>>,
}

fn session(
    stream: TcpStream,
    access: &Access,
    open_bus: &OpenBus,
    stop: &Arc<AtomicBool>,
    stats: &Arc<ServerStats>,
) -> std::io::Result<()> {
    stream.set_nodelay(true)?;
    let (out_tx, out_rx) = mpsc::sync_channel::<Outgoing>(CLIENT_QUEUE);
    let mut writer = stream.try_clone()?;
    let writer_thread = std::thread::spawn(move || {
        for item in out_rx {
            match item {
                Outgoing::Text(line) => {
                    if writer.write_all(line.as_bytes()).is_err() {
                        break;
                    }
                }
                Outgoing::Pause(pause) => std::thread::sleep(pause),
            }
        }
    });
    // Replies go through the same queue as frames, so they keep their order; replies are never
    // dropped (blocking send), frames are when the queue is full.
    // Angle brackets frame the protocol's messages: none may stand inside a reply (an error
    // quoting a client's text included), or the client would read it as two.
    let reply = |text: &str| {
        let text = text.replace(['<', '>'], "");
        out_tx.send(Outgoing::Text(format!("< {text} >"))).is_ok()
    };
    reply("hi");
    let session_stop = Arc::new(AtomicBool::new(false));
    let subscriptions = Arc::new(Subscriptions {
        raw: AtomicBool::new(false),
        by_id: std::sync::Mutex::new(BTreeMap::new()),
    });
    let mut sender: Option<Box<dyn BusTx>> = None;
    // The bus name the session opened (its cyclic jobs open their own endpoints on it).
    let mut opened_name = String::new();
    let mut cyclic: BTreeMap<u32, Arc<std::sync::Mutex<(Duration, Frame)>>> = BTreeMap::new();
    let mut cyclic_stops: BTreeMap<u32, Arc<AtomicBool>> = BTreeMap::new();
    let mut reader = BufReader::new(stream);
    let mut authenticated = access.token.is_none();
    let mut pending = Vec::new();
    'session: while !stop.load(Ordering::Relaxed) {
        pending.clear();
        // Read up to '>' (bounded): one command.
        let read = Read::by_ref(&mut reader)
            .take(MAX_COMMAND_BYTES)
            .read_until(b'>', &mut pending)?;
        if read == 0 {
            break;
        }
        if pending.last() != Some(&b'>') {
            if pending.len() >= MAX_COMMAND {
                stats.errors.fetch_add(1, Ordering::Relaxed);
                reply("error command too long");
                // Skip to the next '>' (bounded by the connection).
                let mut skip = Vec::new();
                if Read::by_ref(&mut reader)
                    .take(1 << 20)
                    .read_until(b'>', &mut skip)?
                    == 0
                {
                    break;
                }
                continue;
            }
            break; // connection closed mid-command
        }
        let text = String::from_utf8_lossy(&pending);
        let Some(start) = text.find('<') else {
            stats.errors.fetch_add(1, Ordering::Relaxed);
            reply("error no '<' before '>'");
            continue;
        };
        let inner = text
            .get(start + 1..text.len().saturating_sub(1))
            .unwrap_or("");
        if let Some(token) = access.token.as_deref().filter(|_| !authenticated) {
            let words: Vec<&str> = inner.split_whitespace().collect();
            if words.as_slice() == ["auth", token] {
                authenticated = true;
                reply("ok");
            } else {
                stats.errors.fetch_add(1, Ordering::Relaxed);
                reply("error authenticate first with: auth TOKEN");
            }
            continue;
        }
        let command = match parse_command(inner) {
            Ok(c) => c,
            Err(e) => {
                stats.errors.fetch_add(1, Ordering::Relaxed);
                reply(&format!("error {e}"));
                continue;
            }
        };
        let opened = sender.is_some();
        match command {
            Command::Open(name) => {
                if opened {
                    reply("error a bus is open already");
                } else if !access.names.is_empty() && !access.names.contains(&name) {
                    reply(&format!(
                        "error no bus '{name}' (served: {})",
                        access.names.join(", ")
                    ));
                } else {
                    match open_bus(&name) {
                        Ok(bus) => {
                            opened_name = name.clone();
                            let (tx, rx) = bus.split();
                            sender = Some(tx);
                            reply("ok");
                            spawn_forwarder(
                                rx,
                                out_tx.clone(),
                                Arc::clone(&subscriptions),
                                Arc::clone(&session_stop),
                                Arc::clone(stats),
                            );
                        }
                        Err(e) => {
                            reply(&format!("error cannot open {name}: {e}"));
                        }
                    }
                }
            }
            _ if !opened => {
                reply("error open a bus first");
            }
            Command::RawMode => {
                // The acknowledgement goes out alone: clients such as python-can read the
                // next chunk from the socket and expect exactly `< ok >`, so the frames from
                // now on wait in the queue a moment behind it (none is lost).
                reply("ok");
                let _ = out_tx.send(Outgoing::Pause(RAW_MODE_GRACE));
                subscriptions.raw.store(true, Ordering::Relaxed);
            }
            Command::BcmMode => {
                subscriptions.raw.store(false, Ordering::Relaxed);
                reply("ok");
            }
            Command::Echo => {
                reply("echo");
            }
            Command::Send(frame) => {
                if let Some(tx) = sender.as_mut() {
                    if let Err(e) = tx.send(&frame) {
                        reply(&format!("error {e}"));
                        if matches!(e, BusError::Closed) {
                            break 'session;
                        }
                    }
                }
            }
            Command::Add(every, frame) => {
                let key = frame.socketcan_id();
                if let Some(old) = cyclic_stops.remove(&key) {
                    old.store(true, Ordering::Relaxed);
                }
                let job = Arc::new(std::sync::Mutex::new((every, frame)));
                let job_stop = Arc::new(AtomicBool::new(false));
                match open_bus(&opened_name) {
                    Ok(bus) => {
                        spawn_cyclic(
                            bus,
                            Arc::clone(&job),
                            Arc::clone(&job_stop),
                            Arc::clone(&session_stop),
                        );
                        cyclic.insert(key, job);
                        cyclic_stops.insert(key, job_stop);
                    }
                    Err(e) => {
                        reply(&format!("error {e}"));
                    }
                }
            }
            Command::Update(every, frame) => match cyclic.get(&frame.socketcan_id()) {
                Some(job) => {
                    let mut job = job
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    if !every.is_zero() {
                        job.0 = every;
                    }
                    job.1 = frame;
                }
                None => {
                    reply("error no cyclic frame with that ID (add it first)");
                }
            },
            Command::Delete(id) => {
                let key = id_key(id);
                cyclic.remove(&key);
                match cyclic_stops.remove(&key) {
                    Some(s) => s.store(true, Ordering::Relaxed),
                    None => {
                        reply("error no cyclic frame with that ID");
                    }
                }
            }
            Command::Subscribe(every, id) => {
                let subscription = Subscription {
                    every,
                    last: None,
                    mask: None,
                    last_masked: None,
                };
                lock(&subscriptions.by_id).insert(id_key(id), subscription);
            }
            Command::Filter(every, id, mask) => {
                let subscription = Subscription {
                    every,
                    last: None,
                    mask: Some(mask),
                    last_masked: None,
                };
                lock(&subscriptions.by_id).insert(id_key(id), subscription);
            }
            Command::Unsubscribe(id) => {
                if lock(&subscriptions.by_id).remove(&id_key(id)).is_none() {
                    reply("error not subscribed to that ID");
                }
            }
        }
    }
    session_stop.store(true, Ordering::Relaxed);
    for s in cyclic_stops.values() {
        s.store(true, Ordering::Relaxed);
    }
    drop(out_tx);
    let _ = writer_thread.join();
    Ok(())
}

fn lock<T>(m: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The SocketCAN identifier of a data frame with this ID (EFF flag for extended).
fn id_key(id: Id) -> u32 {
    match id {
        Id::Standard(s) => u32::from(s.as_raw()),
        Id::Extended(e) => e.as_raw() | bywire_core::frame::EFF_FLAG,
    }
}

/// Frames from the bus to the client: all of them in raw mode, subscribed ones (throttled) in
/// BCM mode. A full queue drops the frame and counts it.
fn spawn_forwarder(
    mut rx: Box<dyn crate::BusRx>,
    out: SyncSender<Outgoing>,
    subscriptions: Arc<Subscriptions>,
    stop: Arc<AtomicBool>,
    stats: Arc<ServerStats>,
) {
    std::thread::spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            let received = match rx.recv(Some(Duration::from_millis(100))) {
                Ok(Some(r)) => r,
                Ok(None) => continue,
                Err(_) => break,
            };
            if !subscriptions.raw.load(Ordering::Relaxed) {
                let key = received.frame.socketcan_id();
                let mut by_id = lock(&subscriptions.by_id);
                let Some(subscription) = by_id.get_mut(&key) else {
                    continue;
                };
                if !subscription.wants(received.frame.data(), Instant::now()) {
                    continue;
                }
            }
            let Some(line) = format_frame(&received.frame, received.timestamp) else {
                continue;
            };
            match out.try_send(Outgoing::Text(line)) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    stats.dropped.fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => break,
            }
        }
    });
}

/// A BCM cyclic transmission on its own endpoint: the frame every interval, on a fixed
/// schedule (no drift), until stopped.
fn spawn_cyclic(
    mut bus: Box<dyn Bus>,
    job: Arc<std::sync::Mutex<(Duration, Frame)>>,
    stop: Arc<AtomicBool>,
    session_stop: Arc<AtomicBool>,
) {
    std::thread::spawn(move || {
        let mut next = Instant::now();
        while !stop.load(Ordering::Relaxed) && !session_stop.load(Ordering::Relaxed) {
            let (every, frame) = *lock(&job);
            if bus.send(&frame).is_err() {
                break;
            }
            if every.is_zero() {
                break; // an interval of 0 sends once
            }
            next += every;
            let now = Instant::now();
            if next < now {
                next = now; // fell behind: no burst to catch up
            }
            std::thread::sleep(next.saturating_duration_since(now));
        }
    });
}

/// The discovery beacon socketcand servers send (and python-can's `detect_beacon` reads):
/// where the server listens, which buses it serves, and what it is (`description`).
pub fn beacon_xml(listen: std::net::SocketAddr, buses: &[String], description: &str) -> String {
    let escape = |text: &str| {
        text.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
            .replace('"', "&quot;")
    };
    let mut xml = format!(
        "<CANBeacon name=\"bywire\" type=\"SocketCAN\" description=\"{}\"><URL>can://{listen}</URL>",
        escape(description)
    );
    for bus in buses {
        xml.push_str(&format!("<Bus name=\"{}\"/>", escape(bus)));
    }
    xml.push_str("</CANBeacon>");
    xml
}

/// Send the beacon to `to` every three seconds (as socketcand does) until `stop` is set.
pub fn spawn_beacon(
    xml: String,
    to: std::net::SocketAddr,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    let socket = std::net::UdpSocket::bind("0.0.0.0:0")?;
    socket.set_broadcast(true)?;
    Ok(std::thread::spawn(move || {
        let mut next = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            if Instant::now() >= next {
                let _ = socket.send_to(xml.as_bytes(), to);
                next += Duration::from_secs(3);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }))
}

/// A frame line from a server (`frame ID SECS.USECS DATA`, the words between `<` and `>`):
/// the frame and its timestamp.
pub fn parse_frame(inner: &str) -> Result<(Frame, Timestamp), String> {
    let words: Vec<&str> = inner.split_whitespace().collect();
    let (id_text, time, data) = match words.as_slice() {
        ["frame", i, t] => (*i, *t, ""),
        ["frame", i, t, d] => (*i, *t, *d),
        _ => return Err(format!("not a frame: '{inner}'")),
    };
    let id = if id_text.len() == 3 {
        Id::standard(u32::from_str_radix(id_text, 16).map_err(|_| format!("bad ID '{id_text}'"))?)
    } else {
        Id::extended(u32::from_str_radix(id_text, 16).map_err(|_| format!("bad ID '{id_text}'"))?)
    }
    .map_err(|e| e.to_string())?;
    let (secs, micros) = time.split_once('.').unwrap_or((time, "0"));
    let secs: u64 = secs.parse().map_err(|_| format!("bad time '{time}'"))?;
    let micros: u64 = micros.parse().map_err(|_| format!("bad time '{time}'"))?;
    let timestamp = Timestamp::from_nanos(
        secs.saturating_mul(1_000_000_000)
            .saturating_add(micros.min(999_999).saturating_mul(1000)),
    );
    if data.len() % 2 != 0 || data.len() > 16 {
        return Err(format!("bad data '{data}'"));
    }
    let mut bytes = [0u8; 8];
    for (i, slot) in bytes.iter_mut().enumerate().take(data.len() / 2) {
        let pair = data.get(2 * i..2 * i + 2).unwrap_or("");
        *slot = u8::from_str_radix(pair, 16).map_err(|_| format!("bad data '{data}'"))?;
    }
    let frame = ClassicFrame::new(id, bytes.get(..data.len() / 2).unwrap_or(&[]))
        .map_err(|e| e.to_string())?;
    Ok((Frame::Classic(frame), timestamp))
}

/// The `send` command for a frame (classic data frames only).
pub fn format_send(frame: &Frame) -> Option<String> {
    let id = frame.id()?;
    if frame.is_fd() || frame.is_remote() {
        return None;
    }
    let id_text = if id.is_extended() {
        format!("{:08X}", id.as_raw())
    } else {
        format!("{:03X}", id.as_raw())
    };
    let data: Vec<String> = frame.data().iter().map(|b| format!("{b:02X}")).collect();
    let mut line = format!("< send {id_text} {:X} ", frame.data().len());
    for byte in data {
        line.push_str(&byte);
        line.push(' ');
    }
    line.push('>');
    Some(line)
}

/// `socketcand:HOST:PORT/BUS`: a client of a socketcand server in raw mode. A lost
/// connection is re-established on the next send or receive (up to five tries, pauses growing
/// to a second).
pub struct Client {
    shared: Arc<ClientShared>,
}

struct ClientShared {
    address: String,
    bus: String,
    reader: std::sync::Mutex<Option<BufReader<TcpStream>>>,
    writer: std::sync::Mutex<Option<TcpStream>>,
    filtering: std::sync::Mutex<crate::Filtering>,
    stats: std::sync::Mutex<crate::Stats>,
}

fn expect(reader: &mut BufReader<TcpStream>, wanted: &str) -> std::io::Result<()> {
    let mut got = Vec::new();
    Read::by_ref(reader)
        .take(MAX_COMMAND_BYTES)
        .read_until(b'>', &mut got)?;
    let text = String::from_utf8_lossy(&got);
    let inner = text
        .trim()
        .trim_start_matches('<')
        .trim_end_matches('>')
        .trim();
    if inner == wanted {
        Ok(())
    } else {
        Err(std::io::Error::other(format!(
            "expected '< {wanted} >', got '{}'",
            text.trim()
        )))
    }
}

fn connect(address: &str, bus: &str) -> std::io::Result<(BufReader<TcpStream>, TcpStream)> {
    let stream = TcpStream::connect(address)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut writer = stream.try_clone()?;
    let mut reader = BufReader::new(stream);
    expect(&mut reader, "hi")?;
    writer.write_all(format!("< open {bus} >").as_bytes())?;
    expect(&mut reader, "ok")?;
    writer.write_all(b"< rawmode >")?;
    expect(&mut reader, "ok")?;
    Ok((reader, writer))
}

impl Client {
    /// Connect to the server at `address` (HOST:PORT) and open `bus` in raw mode.
    pub fn connect(address: &str, bus: &str) -> std::io::Result<Client> {
        let (reader, writer) = connect(address, bus)?;
        Ok(Client {
            shared: Arc::new(ClientShared {
                address: address.to_string(),
                bus: bus.to_string(),
                reader: std::sync::Mutex::new(Some(reader)),
                writer: std::sync::Mutex::new(Some(writer)),
                filtering: std::sync::Mutex::new(crate::Filtering::default()),
                stats: std::sync::Mutex::new(crate::Stats::default()),
            }),
        })
    }
}

fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

impl ClientShared {
    /// Connect again after the connection was lost.
    fn reconnect(&self) -> Result<(), BusError> {
        let mut pause = Duration::from_millis(50);
        let mut last = None;
        for _ in 0..5 {
            match connect(&self.address, &self.bus) {
                Ok((reader, writer)) => {
                    *lock(&self.reader) = Some(reader);
                    *lock(&self.writer) = Some(writer);
                    return Ok(());
                }
                Err(e) => {
                    last = Some(e);
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(Duration::from_secs(1));
                }
            }
        }
        Err(last.map_or(BusError::Closed, BusError::Io))
    }
}

impl crate::SharedEndpoint for ClientShared {
    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let line = format_send(frame).ok_or_else(|| {
            BusError::Unsupported("FD, remote or error frames over socketcand".into())
        })?;
        if lock(&self.writer).is_none() {
            self.reconnect()?;
        }
        let mut writer = lock(&self.writer);
        let stream = writer.as_mut().ok_or(BusError::Closed)?;
        if let Err(e) = stream.write_all(line.as_bytes()) {
            *writer = None;
            return Err(e.into());
        }
        drop(writer);
        lock(&self.stats).count_sent(frame);
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        // Each pass reads one server message or times out; bounded by the deadline.
        loop {
            let slice = deadline.map_or(Duration::from_millis(100), |d| {
                d.saturating_duration_since(Instant::now())
                    .min(Duration::from_millis(100))
            });
            if slice.is_zero() {
                return Ok(None);
            }
            if lock(&self.reader).is_none() {
                self.reconnect()?;
            }
            let mut reader = lock(&self.reader);
            let Some(stream) = reader.as_mut() else {
                continue;
            };
            stream.get_ref().set_read_timeout(Some(slice))?;
            let mut got = Vec::new();
            match Read::by_ref(stream)
                .take(MAX_COMMAND_BYTES)
                .read_until(b'>', &mut got)
            {
                Ok(0) => {
                    *reader = None; // the server closed: reconnect on the next pass
                    continue;
                }
                Ok(_) => {}
                Err(e) if is_timeout(&e) => continue,
                Err(e) => {
                    *reader = None;
                    return Err(e.into());
                }
            }
            drop(reader);
            let text = String::from_utf8_lossy(&got);
            let inner = text.trim().trim_start_matches('<').trim_end_matches('>');
            match parse_frame(inner) {
                Ok((frame, timestamp)) => {
                    if !lock(&self.filtering).accepts(&frame) {
                        continue;
                    }
                    lock(&self.stats).count_received(&frame);
                    return Ok(Some(Received {
                        frame,
                        timestamp,
                        own: false,
                        hardware: None,
                    }));
                }
                Err(_) => {
                    lock(&self.stats).rx_errors += 1;
                }
            }
        }
    }
}

impl crate::BusTx for Client {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        crate::SharedEndpoint::send(self.shared.as_ref(), frame)
    }
}

impl crate::BusRx for Client {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        crate::SharedEndpoint::recv(self.shared.as_ref(), timeout)
    }
}

impl Bus for Client {
    fn set_filtering(&mut self, filtering: crate::Filtering) -> Result<(), BusError> {
        *lock(&self.shared.filtering) = filtering;
        Ok(())
    }

    /// Raw mode has no transmit confirmation: own frames are never received.
    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        if on {
            Err(BusError::Unsupported(
                "receive-own (socketcand raw mode has no echo)".into(),
            ))
        } else {
            Ok(())
        }
    }

    fn set_loopback(&mut self, _on: bool) -> Result<(), BusError> {
        Ok(())
    }

    fn stats(&self) -> crate::Stats {
        *lock(&self.shared.stats)
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn crate::BusRx>) {
        crate::split_halves(self.shared)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_and_refuse_clearly() {
        assert_eq!(
            parse_command(" open vcan0 "),
            Ok(Command::Open("vcan0".into()))
        );
        assert_eq!(
            parse_command(" send 123 4 de ad be ef "),
            Ok(Command::Send("123#DEADBEEF".parse().unwrap()))
        );
        assert_eq!(
            parse_command(" send 1ABCDEF0 2 1 2 "),
            Ok(Command::Send("1ABCDEF0#0102".parse().unwrap()))
        );
        assert_eq!(
            parse_command(" add 0 100000 123 1 ff "),
            Ok(Command::Add(
                Duration::from_millis(100),
                "123#FF".parse().unwrap()
            ))
        );
        assert!(parse_command(" send 123 3 01 02 ")
            .unwrap_err()
            .contains("length 3 with 2"));
        assert!(parse_command(" send 12G 0 ")
            .unwrap_err()
            .contains("not a hex ID"));
        assert!(parse_command(" send 123 9 1 2 3 4 5 6 7 8 9 ").is_err());
        assert!(parse_command(" send 123 1 100 ")
            .unwrap_err()
            .contains("not a byte"));
        assert!(parse_command(" fly away ")
            .unwrap_err()
            .contains("unknown or malformed command 'fly'"));
        assert!(parse_command("").is_err());
    }

    #[test]
    fn content_filters_forward_changes_under_the_mask() {
        assert_eq!(
            parse_command(" filter 0 0 123 2 ff 00 "),
            Ok(Command::Filter(
                Duration::ZERO,
                Id::standard(0x123).unwrap(),
                [0xFF, 0, 0, 0, 0, 0, 0, 0]
            ))
        );
        let t = Instant::now();
        let mut f = Subscription {
            every: Duration::ZERO,
            last: None,
            mask: Some([0xFF, 0, 0, 0, 0, 0, 0, 0]),
            last_masked: None,
        };
        assert!(f.wants(&[1, 1], t), "the first frame");
        assert!(!f.wants(&[1, 2], t), "only unmasked bits changed");
        assert!(f.wants(&[2, 2], t), "a masked bit changed");
        let mut throttled = Subscription {
            every: Duration::from_millis(100),
            last: None,
            mask: None,
            last_masked: None,
        };
        assert!(throttled.wants(&[], t));
        assert!(!throttled.wants(&[], t + Duration::from_millis(50)));
        assert!(throttled.wants(&[], t + Duration::from_millis(100)));
    }

    #[test]
    fn frames_print_as_socketcand_does() {
        let t = Timestamp::from_nanos(1_699_999_999_123_456_789);
        assert_eq!(
            format_frame(&"123#DEADBEEF".parse().unwrap(), t).unwrap(),
            "< frame 123 1699999999.123456 DEADBEEF >"
        );
        assert_eq!(
            format_frame(&"00000123#".parse().unwrap(), t).unwrap(),
            "< frame 00000123 1699999999.123456  >"
        );
        assert_eq!(format_frame(&"123##1AA".parse().unwrap(), t), None);
    }
}
