//! One client's session as a state machine: one enum of phases, one transition function
//! ([`Session::on_event`]) that takes what happened and says what to reply and what to do. The
//! server's threads only carry bytes and frames; every decision about a client is made here,
//! so it can be tested without a socket.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use bywire_core::{Frame, Id};

use super::config::{Config, ServerStats};
use super::protocol::Command;

/// Where a session is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Waiting for `< auth TOKEN >` (only on a server with a token).
    Authenticating,
    /// Greeted (and authenticated where asked); no bus open.
    Greeted,
    /// `open` accepted; the endpoint is being opened.
    Opening,
    /// A bus is open, in BCM mode: subscribed frames go to the client, cyclic jobs run.
    Bcm,
    /// A bus is open, in raw mode: every frame goes to the client.
    Raw,
    /// Over: the connection closes.
    Closed,
}

/// What happened to a session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event {
    /// A message from the client: a command, or why it is not one.
    Message(Result<Command, String>),
    /// A message longer than the limit (discarded up to its `>`).
    TooLong,
    /// The endpoint asked for by [`Effect::Open`]: opened, or why not.
    Opened(Result<(), String>),
    /// The time for opening a bus has passed.
    HandshakeTimeout,
    /// The bus endpoint failed.
    BusLost(String),
    /// The client's input ended (closed, reset, a read error).
    InputEnded,
}

/// What the server does for a step, besides its reply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Effect {
    /// Nothing.
    None,
    /// Open an endpoint on this bus, then report [`Event::Opened`].
    Open(String),
    /// Put this frame on the bus.
    Send(Frame),
    /// Hold the frames to the client a moment, so the reply arrives alone (raw mode's `ok`:
    /// clients such as python-can read one chunk and expect exactly `< ok >`).
    HoldFrames,
    /// Close the connection (after the reply).
    Close,
}

/// The outcome of one event.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Step {
    /// Text to send the client (framed as `< TEXT >`).
    pub reply: Option<String>,
    /// What to do.
    pub effect: Effect,
}

impl Step {
    fn quiet() -> Step {
        Step {
            reply: None,
            effect: Effect::None,
        }
    }

    fn reply(text: impl Into<String>) -> Step {
        Step {
            reply: Some(text.into()),
            effect: Effect::None,
        }
    }

    fn effect(effect: Effect) -> Step {
        Step {
            reply: None,
            effect,
        }
    }

    fn with(mut self, effect: Effect) -> Step {
        self.effect = effect;
        self
    }
}

/// One BCM subscription or content filter.
#[derive(Debug)]
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

/// A BCM cyclic transmission: the frame every interval on a fixed schedule (a late one is
/// sent at once, with no burst to catch up); an interval of 0 sends once.
#[derive(Debug)]
struct Job {
    every: Duration,
    frame: Frame,
    next: Instant,
}

/// What all sessions of one server share: its configuration, its counts, and the jobs in use
/// over all clients.
#[derive(Debug, Default)]
pub struct Shared {
    /// Access and limits.
    pub config: Config,
    /// The counts reported when the server stops.
    pub stats: ServerStats,
    /// Cyclic jobs over all sessions (limited by [`super::Limits::jobs_total`]).
    pub jobs_in_use: AtomicUsize,
}

fn count(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

/// One client's session.
#[derive(Debug)]
pub struct Session {
    phase: Phase,
    shared: Arc<Shared>,
    subscriptions: BTreeMap<u32, Subscription>,
    jobs: BTreeMap<u32, Job>,
}

/// The SocketCAN identifier of a data frame with this ID (EFF flag for extended).
fn id_key(id: Id) -> u32 {
    match id {
        Id::Standard(s) => u32::from(s.as_raw()),
        Id::Extended(e) => e.as_raw() | bywire_core::frame::EFF_FLAG,
    }
}

impl Session {
    /// A new session: it greets with `hi` (the caller sends it) and then waits for a token if
    /// the server has one.
    pub fn new(shared: Arc<Shared>) -> Session {
        let phase = if shared.config.access.token.is_some() {
            Phase::Authenticating
        } else {
            Phase::Greeted
        };
        Session {
            phase,
            shared,
            subscriptions: BTreeMap::new(),
            jobs: BTreeMap::new(),
        }
    }

    /// Where the session is.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Whether the session still waits for a bus to be opened (the handshake clock runs).
    pub fn in_handshake(&self) -> bool {
        matches!(self.phase, Phase::Authenticating | Phase::Greeted)
    }

    /// The transition function: every event in every phase.
    pub fn on_event(&mut self, event: Event, now: Instant) -> Step {
        let shared = Arc::clone(&self.shared);
        let (stats, limits) = (&shared.stats, &shared.config.limits);
        match (self.phase, event) {
            (Phase::Closed, _) => Step::quiet(),
            (_, Event::InputEnded) => {
                self.close();
                Step::effect(Effect::Close)
            }
            (_, Event::BusLost(why)) => {
                self.close();
                Step::reply(format!("error the bus is gone: {why}")).with(Effect::Close)
            }
            (Phase::Authenticating | Phase::Greeted, Event::HandshakeTimeout) => {
                count(&stats.timed_out);
                self.close();
                Step::reply(format!(
                    "error no bus opened within {} s",
                    limits.handshake_timeout.as_secs_f64()
                ))
                .with(Effect::Close)
            }
            (Phase::Opening | Phase::Bcm | Phase::Raw, Event::HandshakeTimeout) => Step::quiet(),
            (Phase::Authenticating, Event::TooLong | Event::Message(_)) => {
                // Only `auth` is possible before the token: anything else ends the session, so
                // each guess costs a connection as well as the server's pacing.
                self.close();
                count(&stats.auth_failures);
                Step::reply("error authenticate first with: auth TOKEN").with(Effect::Close)
            }
            (_, Event::TooLong) => {
                count(&stats.errors);
                Step::reply(format!(
                    "error command too long (at most {} bytes)",
                    super::protocol::MAX_MESSAGE
                ))
            }
            (_, Event::Message(Err(why))) => {
                count(&stats.errors);
                Step::reply(format!("error {why}"))
            }
            (
                Phase::Authenticating | Phase::Greeted | Phase::Bcm | Phase::Raw,
                Event::Opened(_),
            ) => {
                Step::quiet() // nothing was being opened
            }
            (Phase::Opening, Event::Opened(Ok(()))) => {
                self.phase = Phase::Bcm;
                Step::reply("ok")
            }
            (Phase::Opening, Event::Opened(Err(why))) => {
                self.phase = Phase::Greeted;
                Step::reply(format!("error cannot open the bus: {why}"))
            }
            (Phase::Greeted, Event::Message(Ok(Command::Open(name)))) => {
                let names = &shared.config.access.names;
                if names.is_empty() || names.contains(&name) {
                    self.phase = Phase::Opening;
                    Step::effect(Effect::Open(name))
                } else {
                    Step::reply(format!(
                        "error no bus '{name}' (served: {})",
                        names.join(", ")
                    ))
                }
            }
            (Phase::Greeted | Phase::Opening, Event::Message(Ok(Command::Auth(_)))) => {
                Step::reply("error no token needed now")
            }
            (Phase::Greeted | Phase::Opening, Event::Message(Ok(_))) => {
                Step::reply("error open a bus first")
            }
            (Phase::Bcm | Phase::Raw, Event::Message(Ok(command))) => {
                self.on_bus_command(command, now)
            }
        }
    }

    /// The token check of [`Phase::Authenticating`], kept apart from [`Session::on_event`]
    /// because the server paces it (see `AuthGate`): `Some(step)` when `event` is an `auth`.
    pub fn on_auth(&mut self, event: &Event) -> Option<Step> {
        let (Phase::Authenticating, Event::Message(Ok(Command::Auth(given)))) = (self.phase, event)
        else {
            return None;
        };
        let expected = self.shared.config.access.token.as_deref().unwrap_or("");
        if equal_in_constant_time(given.as_bytes(), expected.as_bytes()) {
            self.phase = Phase::Greeted;
            Some(Step::reply("ok"))
        } else {
            count(&self.shared.stats.auth_failures);
            self.close();
            Some(Step::reply("error wrong token").with(Effect::Close))
        }
    }

    /// A command once a bus is open (phase [`Phase::Bcm`] or [`Phase::Raw`]).
    fn on_bus_command(&mut self, command: Command, now: Instant) -> Step {
        let shared = Arc::clone(&self.shared);
        let limits = &shared.config.limits;
        match command {
            Command::Auth(_) => Step::reply("error no token needed now"),
            Command::Open(_) => Step::reply("error a bus is open already"),
            Command::RawMode => {
                self.phase = Phase::Raw;
                Step::reply("ok").with(Effect::HoldFrames)
            }
            Command::BcmMode => {
                self.phase = Phase::Bcm;
                Step::reply("ok")
            }
            Command::Echo => Step::reply("echo"),
            Command::Send(frame) => Step::effect(Effect::Send(frame)),
            Command::Add(every, frame) => match self.add_job(every, frame, now) {
                Ok(()) => Step::quiet(),
                Err(why) => {
                    count(&self.shared.stats.refused_jobs);
                    Step::reply(format!("error {why}"))
                }
            },
            Command::Update(every, frame) => {
                if !every.is_zero() && every < limits.min_interval {
                    count(&self.shared.stats.refused_jobs);
                    return Step::reply(self.interval_too_short(every));
                }
                match self.jobs.get_mut(&frame.socketcan_id()) {
                    Some(job) => {
                        if !every.is_zero() {
                            job.every = every;
                        }
                        job.frame = frame;
                        Step::quiet()
                    }
                    None => Step::reply("error no cyclic frame with that ID (add it first)"),
                }
            }
            Command::Delete(id) => {
                if self.jobs.remove(&id_key(id)).is_some() {
                    self.shared.jobs_in_use.fetch_sub(1, Ordering::Relaxed);
                    Step::quiet()
                } else {
                    Step::reply("error no cyclic frame with that ID")
                }
            }
            Command::Subscribe(every, id) => self.subscribe(id, every, None),
            Command::Filter(every, id, mask) => self.subscribe(id, every, Some(mask)),
            Command::Unsubscribe(id) => {
                if self.subscriptions.remove(&id_key(id)).is_some() {
                    Step::quiet()
                } else {
                    Step::reply("error not subscribed to that ID")
                }
            }
        }
    }

    fn interval_too_short(&self, every: Duration) -> String {
        format!(
            "error interval {} µs is below the server's minimum of {} µs",
            every.as_micros(),
            self.shared.config.limits.min_interval.as_micros()
        )
    }

    /// Add or replace a cyclic job, within the per-client and server-wide limits.
    fn add_job(&mut self, every: Duration, frame: Frame, now: Instant) -> Result<(), String> {
        let shared = Arc::clone(&self.shared);
        let limits = &shared.config.limits;
        if !every.is_zero() && every < limits.min_interval {
            return Err(self
                .interval_too_short(every)
                .trim_start_matches("error ")
                .to_string());
        }
        let key = frame.socketcan_id();
        let job = Job {
            every,
            frame,
            next: now,
        };
        if let Some(existing) = self.jobs.get_mut(&key) {
            *existing = job;
            return Ok(());
        }
        if self.jobs.len() >= limits.jobs_per_client {
            return Err(format!(
                "too many cyclic jobs: at most {} per client",
                limits.jobs_per_client
            ));
        }
        let in_use = self.shared.jobs_in_use.fetch_add(1, Ordering::Relaxed);
        if in_use >= limits.jobs_total {
            self.shared.jobs_in_use.fetch_sub(1, Ordering::Relaxed);
            return Err(format!(
                "too many cyclic jobs: at most {} on this server",
                limits.jobs_total
            ));
        }
        self.jobs.insert(key, job);
        Ok(())
    }

    fn subscribe(&mut self, id: Id, every: Duration, mask: Option<[u8; 8]>) -> Step {
        let key = id_key(id);
        let limit = self.shared.config.limits.subscriptions_per_client;
        if !self.subscriptions.contains_key(&key) && self.subscriptions.len() >= limit {
            count(&self.shared.stats.errors);
            return Step::reply(format!(
                "error too many subscriptions: at most {limit} per client"
            ));
        }
        self.subscriptions.insert(
            key,
            Subscription {
                every,
                last: None,
                mask,
                last_masked: None,
            },
        );
        Step::quiet()
    }

    fn close(&mut self) {
        self.phase = Phase::Closed;
        self.release_jobs();
    }

    fn release_jobs(&mut self) {
        let held = self.jobs.len();
        self.jobs.clear();
        self.shared.jobs_in_use.fetch_sub(held, Ordering::Relaxed);
    }

    /// Whether a frame received from the bus at `now` goes to the client: every frame in raw
    /// mode, subscribed ones (throttled, filtered) in BCM mode, none before a bus is open.
    pub fn forwards(&mut self, frame: &Frame, now: Instant) -> bool {
        match self.phase {
            Phase::Raw => true,
            Phase::Bcm => self
                .subscriptions
                .get_mut(&frame.socketcan_id())
                .is_some_and(|s| s.wants(frame.data(), now)),
            Phase::Authenticating | Phase::Greeted | Phase::Opening | Phase::Closed => false,
        }
    }

    /// Send the cyclic frames due at `now` through `send` (bounded: each job at most once a
    /// call); returns when the next one is due.
    pub fn run_jobs(&mut self, now: Instant, send: &mut dyn FnMut(&Frame)) -> Option<Instant> {
        if !matches!(self.phase, Phase::Bcm | Phase::Raw) {
            return None;
        }
        let mut finished = 0;
        self.jobs.retain(|_, job| {
            if job.next > now {
                return true;
            }
            send(&job.frame);
            if job.every.is_zero() {
                finished += 1;
                return false;
            }
            job.next = (job.next + job.every).max(now);
            true
        });
        self.shared
            .jobs_in_use
            .fetch_sub(finished, Ordering::Relaxed);
        self.jobs.values().map(|job| job.next).min()
    }

    /// The number of cyclic jobs this session runs.
    pub fn jobs(&self) -> usize {
        self.jobs.len()
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.release_jobs();
    }
}

/// Compare secrets without an early exit on the first differing byte.
fn equal_in_constant_time(a: &[u8], b: &[u8]) -> bool {
    let mut difference = u8::from(a.len() != b.len());
    for (x, y) in a.iter().zip(b.iter().cycle()) {
        difference |= x ^ y;
    }
    difference == 0 && !b.is_empty()
}

#[cfg(test)]
mod tests {
    use super::super::config::Limits;
    use super::super::Access;
    use super::*;

    fn frame(text: &str) -> Frame {
        text.parse().unwrap()
    }

    fn command(c: Command) -> Event {
        Event::Message(Ok(c))
    }

    fn shared(token: Option<&str>, limits: Limits) -> Arc<Shared> {
        Arc::new(Shared {
            config: Config {
                access: Access {
                    names: vec!["bus1".into()],
                    token: token.map(str::to_string),
                },
                limits,
            },
            ..Shared::default()
        })
    }

    fn opened(shared: &Arc<Shared>, now: Instant) -> Session {
        let mut s = Session::new(Arc::clone(shared));
        let step = s.on_event(command(Command::Open("bus1".into())), now);
        assert_eq!(step.effect, Effect::Open("bus1".into()));
        assert_eq!(s.on_event(Event::Opened(Ok(())), now).reply.unwrap(), "ok");
        s
    }

    #[test]
    fn a_session_opens_a_served_bus_and_switches_modes() {
        let now = Instant::now();
        let shared = shared(None, Limits::default());
        let mut s = Session::new(Arc::clone(&shared));
        assert_eq!(s.phase(), Phase::Greeted);
        assert_eq!(
            s.on_event(command(Command::Echo), now).reply.unwrap(),
            "error open a bus first"
        );
        assert_eq!(
            s.on_event(command(Command::Open("other".into())), now)
                .reply
                .unwrap(),
            "error no bus 'other' (served: bus1)"
        );
        s.on_event(command(Command::Open("bus1".into())), now);
        assert_eq!(s.phase(), Phase::Opening);
        let failed = s.on_event(Event::Opened(Err("no such device".into())), now);
        assert!(failed.reply.unwrap().contains("no such device"));
        assert_eq!(s.phase(), Phase::Greeted, "a failed open can be retried");
        let mut s = opened(&shared, now);
        assert!(
            !s.forwards(&frame("123#01"), now),
            "BCM: nothing unsubscribed"
        );
        let raw = s.on_event(command(Command::RawMode), now);
        assert_eq!(
            (raw.reply.as_deref(), raw.effect),
            (Some("ok"), Effect::HoldFrames)
        );
        assert!(s.forwards(&frame("123#01"), now));
        assert_eq!(
            s.on_event(command(Command::Send(frame("123#01"))), now)
                .effect,
            Effect::Send(frame("123#01"))
        );
        assert_eq!(
            s.on_event(command(Command::Open("bus1".into())), now)
                .reply
                .unwrap(),
            "error a bus is open already"
        );
        let ended = s.on_event(Event::InputEnded, now);
        assert_eq!(ended.effect, Effect::Close);
        assert_eq!(s.phase(), Phase::Closed);
        assert!(!s.forwards(&frame("123#01"), now));
    }

    #[test]
    fn the_handshake_has_a_time_limit_and_an_open_session_does_not() {
        let now = Instant::now();
        let shared = shared(None, Limits::default());
        let mut idle = Session::new(Arc::clone(&shared));
        let step = idle.on_event(Event::HandshakeTimeout, now);
        assert_eq!(step.effect, Effect::Close);
        assert!(step.reply.unwrap().contains("no bus opened within 10 s"));
        let mut open = opened(&shared, now);
        assert_eq!(open.on_event(Event::HandshakeTimeout, now), Step::quiet());
        assert_eq!(open.phase(), Phase::Bcm);
        assert_eq!(shared.stats.timed_out.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn a_wrong_token_or_anything_before_the_token_ends_the_session() {
        let now = Instant::now();
        let shared = shared(Some("s3cret"), Limits::default());
        let mut s = Session::new(Arc::clone(&shared));
        assert_eq!(s.phase(), Phase::Authenticating);
        let early = s.on_event(command(Command::Open("bus1".into())), now);
        assert_eq!(early.effect, Effect::Close);
        let mut s = Session::new(Arc::clone(&shared));
        let wrong = s.on_auth(&command(Command::Auth("guess".into()))).unwrap();
        assert_eq!(
            (wrong.reply.as_deref(), wrong.effect),
            (Some("error wrong token"), Effect::Close)
        );
        let mut s = Session::new(Arc::clone(&shared));
        assert_eq!(s.on_auth(&command(Command::Echo)), None, "not an auth");
        let right = s.on_auth(&command(Command::Auth("s3cret".into()))).unwrap();
        assert_eq!(right.reply.as_deref(), Some("ok"));
        assert_eq!(s.phase(), Phase::Greeted);
        assert_eq!(shared.stats.auth_failures.load(Ordering::Relaxed), 2);
        assert!(!equal_in_constant_time(b"s3cre", b"s3cret"));
        assert!(!equal_in_constant_time(b"", b""));
        assert!(equal_in_constant_time(b"s3cret", b"s3cret"));
    }

    #[test]
    fn cyclic_jobs_are_limited_per_client_and_in_all_and_freed_with_the_session() {
        let now = Instant::now();
        let limits = Limits {
            jobs_per_client: 3,
            jobs_total: 4,
            ..Limits::default()
        };
        let shared = shared(None, limits);
        let mut a = opened(&shared, now);
        let mut b = opened(&shared, now);
        let add = |s: &mut Session, id: u32, every_us: u64| {
            let f = bywire_core::Frame::classic(Id::standard(id).unwrap(), &[1]).unwrap();
            s.on_event(
                command(Command::Add(Duration::from_micros(every_us), f)),
                now,
            )
            .reply
        };
        assert!(add(&mut a, 1, 10)
            .unwrap()
            .contains("below the server's minimum of 1000 µs"));
        for id in 1..=3 {
            assert_eq!(add(&mut a, id, 10_000), None);
        }
        assert_eq!(add(&mut a, 3, 20_000), None, "replacing is not adding");
        assert!(add(&mut a, 4, 10_000).unwrap().contains("3 per client"));
        assert_eq!(add(&mut b, 1, 10_000), None);
        assert!(add(&mut b, 2, 10_000).unwrap().contains("4 on this server"));
        assert_eq!(shared.stats.refused_jobs.load(Ordering::Relaxed), 3);
        assert_eq!(shared.jobs_in_use.load(Ordering::Relaxed), 4);
        // Jobs run on their schedule; a job of interval 0 runs once.
        let mut sent = Vec::new();
        let next = a.run_jobs(now, &mut |f| sent.push(*f));
        assert_eq!(sent.len(), 3);
        assert_eq!(next, Some(now + Duration::from_millis(10)));
        sent.clear();
        a.run_jobs(now + Duration::from_millis(5), &mut |f| sent.push(*f));
        assert!(sent.is_empty(), "none due yet");
        a.on_event(command(Command::Delete(Id::standard(1).unwrap())), now);
        assert_eq!(shared.jobs_in_use.load(Ordering::Relaxed), 3);
        drop(a);
        assert_eq!(
            shared.jobs_in_use.load(Ordering::Relaxed),
            1,
            "a's jobs freed"
        );
        b.on_event(Event::InputEnded, now);
        assert_eq!(shared.jobs_in_use.load(Ordering::Relaxed), 0);
        let mut once = opened(&shared, now);
        add(&mut once, 7, 0);
        let mut count = 0;
        once.run_jobs(now, &mut |_| count += 1);
        once.run_jobs(now + Duration::from_secs(1), &mut |_| count += 1);
        assert_eq!((count, once.jobs()), (1, 0));
        assert_eq!(shared.jobs_in_use.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn subscriptions_throttle_filter_and_are_limited() {
        let t = Instant::now();
        let shared = shared(
            None,
            Limits {
                subscriptions_per_client: 2,
                ..Limits::default()
            },
        );
        let mut s = opened(&shared, t);
        let id = |raw| Id::standard(raw).unwrap();
        s.on_event(
            command(Command::Filter(
                Duration::ZERO,
                id(0x123),
                [0xFF, 0, 0, 0, 0, 0, 0, 0],
            )),
            t,
        );
        assert!(s.forwards(&frame("123#0101"), t), "the first frame");
        assert!(
            !s.forwards(&frame("123#0102"), t),
            "only unmasked bits changed"
        );
        assert!(s.forwards(&frame("123#0202"), t), "a masked bit changed");
        s.on_event(
            command(Command::Subscribe(Duration::from_millis(100), id(0x200))),
            t,
        );
        assert!(s.forwards(&frame("200#"), t));
        assert!(!s.forwards(&frame("200#"), t + Duration::from_millis(50)));
        assert!(s.forwards(&frame("200#"), t + Duration::from_millis(100)));
        let third = s.on_event(command(Command::Subscribe(Duration::ZERO, id(0x300))), t);
        assert!(third.reply.unwrap().contains("at most 2 per client"));
        assert_eq!(
            s.on_event(command(Command::Unsubscribe(id(0x300))), t)
                .reply
                .unwrap(),
            "error not subscribed to that ID"
        );
    }
}
