//! The server: an accept loop and, per client, three threads that only carry bytes and frames
//! (the session's decisions are its state machine's, in [`super::session`]).
//!
//! Every resource a client can make the server spend is bounded: connections
//! ([`Limits::max_clients`](super::config::Limits::max_clients); further ones are told the server is full and closed), threads
//! (three per connection, none per cyclic job: a session's jobs run on its forwarding
//! thread), time without opening a bus ([`Limits::handshake_timeout`](super::config::Limits::handshake_timeout)), a client that stops
//! reading ([`Limits::write_timeout`](super::config::Limits::write_timeout)), cyclic jobs and their rate, subscriptions, and the
//! frames queued for a client ([`CLIENT_QUEUE`]). What a limit refuses or a slow client loses
//! is counted in [`ServerStats`]. A connection that ends in any way — closed, reset, timed
//! out — ends its threads and frees its endpoint and jobs.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::config::{load, Config, ServerStats};
use super::protocol::{self, MAX_MESSAGE};
use super::session::{Effect, Event, Phase, Session, Shared, Step};
use crate::{Bus, BusError, BusRx, BusTx};

/// Frames queued for one client before further ones are dropped and counted.
pub const CLIENT_QUEUE: usize = 8192;

/// How long after acknowledging `< rawmode >` frames start to flow (see [`Effect::HoldFrames`]).
const RAW_MODE_GRACE: Duration = Duration::from_millis(50);
/// How often blocked reads wake to see whether the server stops or a session timed out.
const POLL: Duration = Duration::from_millis(200);
/// The kernel's send buffer for each client (a second of a full 1 Mbit/s bus as text).
const SEND_BUFFER: usize = 256 * 1024;
/// Token attempts are spaced this far apart over the whole server (ten a second at most).
const AUTH_SPACING: Duration = Duration::from_millis(100);

/// Opens an endpoint on the bus a client named.
pub type OpenBus = dyn Fn(&str) -> Result<Box<dyn Bus>, BusError> + Send + Sync;

/// What the accept loop and every session share.
struct Context {
    sessions: Arc<Shared>,
    open_bus: Arc<OpenBus>,
    stop: AtomicBool,
    /// When the next token attempt may be checked (see [`AUTH_SPACING`]).
    next_auth: Mutex<Instant>,
}

impl Context {
    fn stats(&self) -> &ServerStats {
        &self.sessions.stats
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Wait for this attempt's turn: at most one token check per [`AUTH_SPACING`] over all
    /// connections, so guessing costs time however many connections try. Bounded: a turn is
    /// at most `max_clients` spacings away.
    fn wait_for_auth_turn(&self) {
        let now = Instant::now();
        let turn = {
            let mut next = lock(&self.next_auth);
            let turn = (*next).max(now);
            *next = turn + AUTH_SPACING;
            turn
        };
        std::thread::sleep(turn.saturating_duration_since(now));
    }
}

/// A running socketcand server; it stops (and waits for its accept loop) when dropped.
pub struct Server {
    context: Arc<Context>,
    address: SocketAddr,
    accept: Option<JoinHandle<std::io::Result<()>>>,
    beacon: Option<JoinHandle<()>>,
}

impl Server {
    /// Serve `listener`'s clients: each gets an endpoint from `open_bus` (given the name) when
    /// it opens a bus name the config allows.
    pub fn start(
        listener: TcpListener,
        config: Config,
        open_bus: Arc<OpenBus>,
    ) -> std::io::Result<Server> {
        // Blocking accepts that wake every poll to see whether the server stops (Linux and the
        // BSDs time `accept` out by the receive timeout): a connection is taken at once.
        listener.set_nonblocking(false)?;
        socket2::SockRef::from(&listener).set_read_timeout(Some(POLL))?;
        let address = listener.local_addr()?;
        let context = Arc::new(Context {
            sessions: Arc::new(Shared {
                config,
                ..Shared::default()
            }),
            open_bus,
            stop: AtomicBool::new(false),
            next_auth: Mutex::new(Instant::now()),
        });
        let accepting = Arc::clone(&context);
        let accept = std::thread::Builder::new()
            .name("socketcand-accept".into())
            .spawn(move || accept_loop(&listener, &accepting))?;
        Ok(Server {
            context,
            address,
            accept: Some(accept),
            beacon: None,
        })
    }

    /// Also send socketcand's discovery beacon `xml` to `to` every three seconds.
    pub fn start_beacon(&mut self, xml: String, to: SocketAddr) -> std::io::Result<()> {
        let context = Arc::clone(&self.context);
        self.beacon = Some(super::beacon::spawn(xml, to, move || context.stopping())?);
        Ok(())
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.address
    }

    /// Its counts.
    pub fn stats(&self) -> &ServerStats {
        self.context.stats()
    }

    /// Whether the accept loop still runs (it ends only on a listener error or [`Server::stop`]).
    pub fn is_running(&self) -> bool {
        self.accept.as_ref().is_some_and(|a| !a.is_finished())
    }

    /// Stop accepting and wait for the accept loop (its error if it ended with one) and, up
    /// to a second, for the sessions to close their connections and count their last drops.
    /// Stopping again does nothing.
    pub fn stop(&mut self) -> std::io::Result<()> {
        self.context.stop.store(true, Ordering::Relaxed);
        if let Some(beacon) = self.beacon.take() {
            let _ = beacon.join();
        }
        let ended = match self.accept.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(std::io::Error::other("the accept loop panicked")),
            None => Ok(()),
        };
        let waiting_until = Instant::now() + Duration::from_secs(1);
        while load(&self.stats().active) > 0 && Instant::now() < waiting_until {
            std::thread::sleep(Duration::from_millis(10));
        }
        ended
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// Whether an `accept` error passes (a full descriptor table, a connection aborted before it
/// was taken): the server waits a moment and goes on rather than ending.
fn is_transient(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::{ConnectionAborted, ConnectionReset, Interrupted, OutOfMemory};
    matches!(
        e.kind(),
        ConnectionAborted | ConnectionReset | Interrupted | OutOfMemory
    ) || matches!(
        e.raw_os_error(),
        Some(
            libc_errno::EMFILE
                | libc_errno::ENFILE
                | libc_errno::ENOBUFS
                | libc_errno::ENOMEM
                | libc_errno::EPROTO
                | libc_errno::EPERM
        )
    )
}

/// The error numbers `accept` reports for passing shortages (Linux values; the server only
/// runs where `std` names them so).
mod libc_errno {
    pub const EPERM: i32 = 1;
    pub const ENOMEM: i32 = 12;
    pub const ENFILE: i32 = 23;
    pub const EMFILE: i32 = 24;
    pub const EPROTO: i32 = 71;
    pub const ENOBUFS: i32 = 105;
}

fn accept_loop(listener: &TcpListener, context: &Arc<Context>) -> std::io::Result<()> {
    let limits = &context.sessions.config.limits;
    while !context.stopping() {
        let stream = match listener.accept() {
            Ok((stream, _)) => stream,
            Err(e) if is_timeout(&e) => continue,
            Err(e) if is_transient(&e) => {
                context
                    .stats()
                    .accept_errors
                    .fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(100));
                continue;
            }
            Err(e) => return Err(e),
        };
        let stats = context.stats();
        if load(&stats.active) >= u64::try_from(limits.max_clients).unwrap_or(u64::MAX) {
            stats.refused_clients.fetch_add(1, Ordering::Relaxed);
            refuse(stream, limits.max_clients);
            continue;
        }
        stats.clients.fetch_add(1, Ordering::Relaxed);
        let slot = Slot::take(Arc::clone(context));
        let spawned = std::thread::Builder::new()
            .name("socketcand-session".into())
            .spawn(move || {
                let context = Arc::clone(&slot.0);
                let _ = run_session(stream, &context);
                drop(slot);
            });
        if spawned.is_err() {
            // The closure, and the slot with it, is dropped: the connection closes.
            stats.refused_clients.fetch_add(1, Ordering::Relaxed);
        }
    }
    Ok(())
}

/// Tell a client the server is full, without waiting on it.
fn refuse(stream: TcpStream, max_clients: usize) {
    let _ = stream.set_nonblocking(true);
    let _ = (&stream).write_all(
        protocol::format_reply(&format!("error the server is full ({max_clients} clients)"))
            .as_bytes(),
    );
}

/// A place among [`Limits::max_clients`], given back when the session's thread ends.
struct Slot(Arc<Context>);

impl Slot {
    fn take(context: Arc<Context>) -> Slot {
        context.stats().active.fetch_add(1, Ordering::Relaxed);
        Slot(context)
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.stats().active.fetch_sub(1, Ordering::Relaxed);
    }
}

/// What a session's writer thread does next.
enum Outgoing {
    /// Send this text.
    Text(String),
    /// Send nothing for this long (see [`RAW_MODE_GRACE`]).
    Pause(Duration),
}

/// Reads one message at a time from the client, bounded, across read timeouts (a message
/// whose bytes arrive across a pause is kept, not lost).
struct MessageReader {
    reader: BufReader<TcpStream>,
    pending: Vec<u8>,
    /// Discarding the rest of a message that was too long.
    skipping: bool,
}

/// What the client sent, or that it sent nothing yet.
enum Incoming {
    Event(Event),
    Nothing,
}

impl MessageReader {
    fn next(&mut self) -> Incoming {
        let room = MAX_MESSAGE.saturating_sub(self.pending.len()).max(1);
        let room = u64::try_from(room).unwrap_or(1);
        let result = Read::by_ref(&mut self.reader)
            .take(room)
            .read_until(b'>', &mut self.pending);
        match result {
            Ok(0) => Incoming::Event(Event::InputEnded),
            Ok(_) if self.pending.last() == Some(&b'>') => {
                let message = std::mem::take(&mut self.pending);
                if std::mem::replace(&mut self.skipping, false) {
                    return Incoming::Nothing; // the tail of a message too long
                }
                let text = String::from_utf8_lossy(&message);
                Incoming::Event(Event::Message(match protocol::inner_text(&text) {
                    Some(inner) => protocol::parse_command(inner),
                    None => Err("no '<' before '>'".into()),
                }))
            }
            Ok(_) if self.pending.len() >= MAX_MESSAGE => {
                self.pending.clear();
                if std::mem::replace(&mut self.skipping, true) {
                    Incoming::Nothing
                } else {
                    Incoming::Event(Event::TooLong)
                }
            }
            Ok(_) => Incoming::Nothing, // more to come (or the end, read next time)
            Err(e) if is_timeout(&e) => Incoming::Nothing,
            Err(_) => Incoming::Event(Event::InputEnded),
        }
    }
}

pub(super) fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The endpoint a session opened: its sending half (shared with the forwarder, which sends
/// the cyclic jobs) and the forwarder.
struct Opened {
    tx: Arc<Mutex<Box<dyn BusTx>>>,
    forwarder: JoinHandle<()>,
}

/// Flags the reader, the forwarder and the writer of one session share.
#[derive(Default)]
struct Flags {
    /// The session is over: the forwarder stops.
    ended: AtomicBool,
    /// The bus endpoint failed (the forwarder saw it).
    bus_lost: Mutex<Option<String>>,
}

fn run_session(stream: TcpStream, context: &Arc<Context>) -> std::io::Result<()> {
    let limits = &context.sessions.config.limits;
    stream.set_nodelay(true)?;
    // A fixed send buffer (no autotuning to megabytes): bounded kernel memory per client, and
    // a client that stops reading is noticed by the write timeout, not hidden by the buffer.
    socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER)?;
    stream.set_read_timeout(Some(POLL))?;
    stream.set_write_timeout(Some(limits.write_timeout))?;
    let (out_tx, out_rx) = mpsc::sync_channel::<Outgoing>(CLIENT_QUEUE);
    let writer_stream = stream.try_clone()?;
    let stats_context = Arc::clone(context);
    let writer = std::thread::Builder::new()
        .name("socketcand-writer".into())
        .spawn(move || write_to_client(writer_stream, &out_rx, stats_context.stats()))?;
    let session = Arc::new(Mutex::new(Session::new(Arc::clone(&context.sessions))));
    let flags = Arc::new(Flags::default());
    let started = Instant::now();
    let mut reader = MessageReader {
        reader: BufReader::new(stream),
        pending: Vec::new(),
        skipping: false,
    };
    let mut opened: Option<Opened> = None;
    // What an effect led to (an endpoint opened, a send failed): the next event.
    let mut follow_up: Option<Event> = None;
    let mut alive = out_tx
        .send(Outgoing::Text(protocol::format_reply("hi")))
        .is_ok();
    while alive {
        let event = match follow_up.take() {
            Some(event) => event,
            None if context.stopping() => Event::InputEnded,
            None => match lock(&flags.bus_lost).take() {
                Some(why) => Event::BusLost(why),
                None => match reader.next() {
                    Incoming::Event(event) => event,
                    Incoming::Nothing => {
                        let waiting = lock(&session).in_handshake();
                        if !waiting || started.elapsed() < limits.handshake_timeout {
                            continue;
                        }
                        Event::HandshakeTimeout
                    }
                },
            },
        };
        let (step, queued) = step(context, &session, event, &out_tx);
        // Fails when the writer ended: the client is gone or stalled.
        alive = queued;
        match step.effect {
            Effect::None | Effect::HoldFrames => {}
            Effect::Close => break,
            Effect::Send(frame) => {
                let sent = opened.as_ref().map_or(Ok(()), |o| lock(&o.tx).send(&frame));
                follow_up = sent.err().map(|e| match e {
                    BusError::Closed => Event::BusLost(e.to_string()),
                    other => Event::Message(Err(other.to_string())),
                });
            }
            Effect::Open(name) => {
                let result = open_endpoint(context, &name, &session, &flags, &out_tx);
                follow_up = Some(Event::Opened(result.map(|o| {
                    opened = Some(o);
                })));
            }
        }
    }
    lock(&session).on_event(Event::InputEnded, Instant::now());
    flags.ended.store(true, Ordering::Relaxed);
    if let Some(opened) = opened {
        let _ = opened.forwarder.join();
    }
    drop(out_tx);
    // The writer drains what is queued (bounded by its write timeout) and closes.
    let _ = writer.join();
    Ok(())
}

/// One event through the state machine (a token attempt waits for its turn first), its reply
/// queued to the client before the session lock is let go: the forwarder checks the session
/// under that lock before it queues a frame, so no frame of a new mode can overtake the reply
/// that starts it (raw mode's `< ok >`). Returns the step and whether the writer took the reply.
fn step(
    context: &Context,
    session: &Mutex<Session>,
    event: Event,
    out: &SyncSender<Outgoing>,
) -> (Step, bool) {
    let is_auth = matches!(
        (lock(session).phase(), &event),
        (
            Phase::Authenticating,
            Event::Message(Ok(protocol::Command::Auth(_)))
        )
    );
    if is_auth {
        context.wait_for_auth_turn();
    }
    let mut guard = lock(session);
    let step = match is_auth.then(|| guard.on_auth(&event)).flatten() {
        Some(step) => step,
        None => guard.on_event(event, Instant::now()),
    };
    let mut queued = true;
    if let Some(text) = &step.reply {
        // The writer never takes the session lock, so waiting on it here cannot deadlock.
        queued = out
            .send(Outgoing::Text(protocol::format_reply(text)))
            .is_ok();
    }
    if matches!(step.effect, Effect::HoldFrames) {
        queued &= out.send(Outgoing::Pause(RAW_MODE_GRACE)).is_ok();
    }
    drop(guard);
    (step, queued)
}

/// Open the bus `name` for a session and start forwarding its frames.
fn open_endpoint(
    context: &Arc<Context>,
    name: &str,
    session: &Arc<Mutex<Session>>,
    flags: &Arc<Flags>,
    out: &SyncSender<Outgoing>,
) -> Result<Opened, String> {
    let bus = (context.open_bus)(name).map_err(|e| e.to_string())?;
    let (tx, rx) = bus.split();
    let tx = Arc::new(Mutex::new(tx));
    let forwarding = Forwarding {
        rx,
        tx: Arc::clone(&tx),
        out: out.clone(),
        session: Arc::clone(session),
        flags: Arc::clone(flags),
        context: Arc::clone(context),
    };
    let forwarder = std::thread::Builder::new()
        .name("socketcand-forward".into())
        .spawn(move || forwarding.run())
        .map_err(|e| format!("no thread for it: {e}"))?;
    Ok(Opened { tx, forwarder })
}

/// A session's frames from the bus to the client, and its cyclic jobs onto the bus.
struct Forwarding {
    rx: Box<dyn BusRx>,
    tx: Arc<Mutex<Box<dyn BusTx>>>,
    out: SyncSender<Outgoing>,
    session: Arc<Mutex<Session>>,
    flags: Arc<Flags>,
    context: Arc<Context>,
}

impl Forwarding {
    fn run(mut self) {
        let stats = self.context.stats();
        let mut endpoint_drops = 0;
        let mut since_count = 0u32;
        while !self.flags.ended.load(Ordering::Relaxed) {
            let now = Instant::now();
            let mut lost = None;
            let next_job = lock(&self.session).run_jobs(now, &mut |frame| {
                if let Err(e) = lock(&self.tx).send(frame) {
                    lost.get_or_insert(e);
                }
            });
            if let Some(BusError::Closed) = lost {
                self.lose_bus("closed");
                break;
            }
            let wait = next_job.map_or(Duration::from_millis(100), |next| {
                next.saturating_duration_since(now)
            });
            let received = match self.rx.recv(Some(wait.min(Duration::from_millis(100)))) {
                Ok(Some(received)) => received,
                Ok(None) => {
                    count_endpoint_drops(self.rx.as_ref(), &mut endpoint_drops, stats);
                    continue;
                }
                Err(e) => {
                    self.lose_bus(&e.to_string());
                    break;
                }
            };
            since_count += 1;
            if since_count >= 1024 {
                since_count = 0;
                count_endpoint_drops(self.rx.as_ref(), &mut endpoint_drops, stats);
            }
            if !lock(&self.session).forwards(&received.frame, Instant::now()) {
                continue;
            }
            let Some(line) = protocol::format_frame(&received.frame, received.timestamp) else {
                continue;
            };
            match self.out.try_send(Outgoing::Text(line)) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    stats.dropped.fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => break,
            }
        }
        count_endpoint_drops(self.rx.as_ref(), &mut endpoint_drops, stats);
    }

    fn lose_bus(&self, why: &str) {
        *lock(&self.flags.bus_lost) = Some(why.to_string());
    }
}

/// Add what the endpoint dropped since the last look to the server's count.
fn count_endpoint_drops(rx: &dyn BusRx, counted: &mut u64, stats: &ServerStats) {
    let now = rx.stats().rx_dropped;
    stats
        .dropped_at_endpoint
        .fetch_add(now.saturating_sub(*counted), Ordering::Relaxed);
    *counted = now.max(*counted);
}

/// The writer thread: queued text to the client. A client that takes nothing for the write
/// timeout is cut off (both directions, so the session's reader ends too).
fn write_to_client(mut stream: TcpStream, queue: &Receiver<Outgoing>, stats: &ServerStats) {
    for item in queue {
        match item {
            Outgoing::Text(text) => {
                if let Err(e) = stream.write_all(text.as_bytes()) {
                    if is_timeout(&e) {
                        stats.stalled.fetch_add(1, Ordering::Relaxed);
                    }
                    break;
                }
            }
            Outgoing::Pause(pause) => std::thread::sleep(pause),
        }
    }
    let _ = stream.shutdown(Shutdown::Both);
}
