//! UDS (ISO 14229-1): a server's request handling as a sans-IO state machine over whole
//! messages (an ISO-TP channel carries them: [`UdsServer`] owns one).
//!
//! Services so far: DiagnosticSessionControl (0x10, with P2/P2* in the answer and the S3
//! timeout back to the default session), ECUReset (0x11), TesterPresent (0x3E),
//! ReadDataByIdentifier (0x22, several identifiers per request), WriteDataByIdentifier
//! (0x2E, in the sessions a DID allows), ReadDTCInformation (0x19: 0x01 count, 0x02 by
//! status mask, 0x04 snapshots, 0x06 extended data, 0x0A supported), ClearDiagnosticInformation (0x14), ControlDTCSetting
//! (0x85), CommunicationControl (0x28), SecurityAccess (0x27: seed and key with a pluggable
//! key function, three attempts, then a delay), RoutineControl (0x31: start, stop, results; a
//! routine that takes time is answered with response pending, 0x78, then its result). The
//! suppress-positive-response bit is honoured; every refusal is a negative response with the
//! standard's code.

use alloc::collections::BTreeMap;
use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};

use crate::isotp::{IsoTp, IsoTpConfig, IsoTpEvent};

/// Negative response codes (ISO 14229-1 annex A) this server sends.
pub mod nrc {
    /// The service is not supported.
    pub const SERVICE_NOT_SUPPORTED: u8 = 0x11;
    /// The sub-function is not supported.
    pub const SUB_FUNCTION_NOT_SUPPORTED: u8 = 0x12;
    /// Wrong length or format.
    pub const INCORRECT_MESSAGE_LENGTH: u8 = 0x13;
    /// Conditions not correct.
    pub const CONDITIONS_NOT_CORRECT: u8 = 0x22;
    /// An identifier or value out of range.
    pub const REQUEST_OUT_OF_RANGE: u8 = 0x31;
    /// Security access needed.
    pub const SECURITY_ACCESS_DENIED: u8 = 0x33;
    /// A request out of its sequence (a key without a seed, results before a start).
    pub const REQUEST_SEQUENCE_ERROR: u8 = 0x24;
    /// The key is wrong.
    pub const INVALID_KEY: u8 = 0x35;
    /// Too many wrong keys: a delay starts.
    pub const EXCEEDED_NUMBER_OF_ATTEMPTS: u8 = 0x36;
    /// The delay after too many wrong keys has not passed.
    pub const REQUIRED_TIME_DELAY_NOT_EXPIRED: u8 = 0x37;
    /// The answer comes later (within P2*).
    pub const RESPONSE_PENDING: u8 = 0x78;
    /// The service is not offered in the active session.
    pub const SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION: u8 = 0x7F;
    /// The sub-function is not offered in the active session.
    pub const SUB_FUNCTION_NOT_SUPPORTED_IN_ACTIVE_SESSION: u8 = 0x7E;
}

/// Diagnostic sessions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Session {
    /// 0x01.
    Default,
    /// 0x02.
    Programming,
    /// 0x03.
    Extended,
}

impl Session {
    fn from_code(code: u8) -> Option<Session> {
        match code {
            1 => Some(Session::Default),
            2 => Some(Session::Programming),
            3 => Some(Session::Extended),
            _ => None,
        }
    }
}

/// DTC status bits (ISO 14229-1 D.2).
pub mod status {
    /// testFailed.
    pub const TEST_FAILED: u8 = 0x01;
    /// testFailedThisOperationCycle.
    pub const TEST_FAILED_THIS_CYCLE: u8 = 0x02;
    /// pendingDTC.
    pub const PENDING: u8 = 0x04;
    /// confirmedDTC.
    pub const CONFIRMED: u8 = 0x08;
    /// testNotCompletedSinceLastClear.
    pub const NOT_COMPLETED_SINCE_CLEAR: u8 = 0x10;
    /// testFailedSinceLastClear.
    pub const FAILED_SINCE_CLEAR: u8 = 0x20;
    /// testNotCompletedThisOperationCycle.
    pub const NOT_COMPLETED_THIS_CYCLE: u8 = 0x40;
    /// warningIndicatorRequested.
    pub const WARNING_INDICATOR: u8 = 0x80;
}

/// The status bits this server maintains (its availability mask).
pub const AVAILABILITY_MASK: u8 = status::TEST_FAILED
    | status::TEST_FAILED_THIS_CYCLE
    | status::PENDING
    | status::CONFIRMED
    | status::FAILED_SINCE_CLEAR;

/// A data identifier's value and where it may be written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Did {
    /// The value.
    pub value: Vec<u8>,
    /// The sessions it may be written in (none: read-only).
    pub writable_in: Vec<Session>,
    /// Writing needs security access.
    pub secured: bool,
}

/// A routine RoutineControl can run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Routine {
    /// How long it runs once started (zero: at once).
    pub runs_for: Duration,
    /// What its results request answers once it has run.
    pub result: Vec<u8>,
    /// Starting it needs security access.
    pub secured: bool,
}

/// The key for a seed at a security level (a vehicle's own algorithm plugs in here).
pub type KeyFunction = fn(level: u8, seed: &[u8]) -> Vec<u8>;

/// The demonstration key: each seed byte XOR 0x5A, plus the level. Not a secret: a real ECU
/// gives its own [`KeyFunction`].
pub fn demo_key(level: u8, seed: &[u8]) -> Vec<u8> {
    seed.iter()
        .map(|b| (b ^ 0x5A).wrapping_add(level))
        .collect()
}

/// A snapshot: data identifiers and their values when a fault was found.
pub type Snapshot = Vec<(u16, Vec<u8>)>;

/// What a DTC keeps beside its status: snapshot record 0x01 (its first occurrence) and 0x02
/// (the latest), and extended data record 0x01 (how often it occurred).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
struct DtcRecords {
    first: Option<Snapshot>,
    latest: Option<Snapshot>,
    occurrences: u8,
}

/// Wrong keys accepted before the delay.
const MAX_ATTEMPTS: u8 = 3;
/// The delay after too many wrong keys.
const ATTEMPT_DELAY: Duration = Duration::from_secs(10);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Security {
    Locked,
    /// A seed was given for this level.
    Seeded {
        level: u8,
        seed: [u8; 4],
    },
    Unlocked {
        level: u8,
    },
}

/// What the application hears of.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum UdsEvent {
    /// The tester changed the session.
    Session(Session),
    /// The tester asked for a reset (the sub-function: 1 hard, 2 key off/on, 3 soft), after
    /// the positive response was queued.
    Reset(u8),
    /// A DID was written.
    Written(u16),
    /// DTCs were cleared (the group).
    Cleared(u32),
    /// Security access was granted at this level.
    Unlocked(u8),
    /// A routine was started.
    RoutineStarted(u16),
    /// A running routine was stopped by the tester.
    RoutineStopped(u16),
    /// The transport failed (the message is lost; the tester will repeat).
    Transport(crate::isotp::IsoTpError),
}

/// How the server answers in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UdsTiming {
    /// P2server max, announced in the session answer.
    pub p2: Duration,
    /// P2*server max.
    pub p2_extended: Duration,
    /// S3: a non-default session without requests returns to the default one after this.
    pub s3: Duration,
}

impl Default for UdsTiming {
    fn default() -> Self {
        UdsTiming {
            p2: Duration::from_millis(50),
            p2_extended: Duration::from_millis(5000),
            s3: Duration::from_millis(5000),
        }
    }
}

/// A UDS server on one ISO-TP channel: its DIDs, DTCs and session.
#[derive(Debug, Clone)]
pub struct UdsServer {
    channel: IsoTp,
    /// Functional requests (one frame each), answered on `channel`.
    functional: Option<IsoTp>,
    timing: UdsTiming,
    session: Session,
    last_request: Timestamp,
    dids: BTreeMap<u16, Did>,
    /// DTC (24 bits) → status byte.
    dtcs: BTreeMap<u32, u8>,
    /// DTC → its snapshots and occurrence count.
    records: BTreeMap<u32, DtcRecords>,
    dtc_setting_on: bool,
    events: Vec<UdsEvent>,
    /// Responses waiting for the channel to be free.
    outbox: Vec<Vec<u8>>,
    key: KeyFunction,
    security: Security,
    failed_attempts: u8,
    locked_until: Option<Timestamp>,
    seeds_given: u32,
    routines: BTreeMap<u16, Routine>,
    /// Routines started: until when they run.
    running: BTreeMap<u16, Timestamp>,
    /// A started routine whose positive answer is pending: (routine, when it is due, when
    /// the next response pending is due if it is not done by then).
    pending: Option<(u16, Timestamp, Timestamp)>,
    /// Routines whose start the application refuses now (conditions not correct).
    refused: alloc::collections::BTreeSet<u16>,
}

impl UdsServer {
    /// A server on `channel` with `timing`, in the default session.
    pub fn new(channel: IsoTpConfig, timing: UdsTiming) -> Self {
        UdsServer {
            channel: IsoTp::new(channel),
            functional: None,
            timing,
            session: Session::Default,
            last_request: Timestamp::ZERO,
            dids: BTreeMap::new(),
            dtcs: BTreeMap::new(),
            records: BTreeMap::new(),
            dtc_setting_on: true,
            events: Vec::new(),
            outbox: Vec::new(),
            key: demo_key,
            security: Security::Locked,
            failed_attempts: 0,
            locked_until: None,
            seeds_given: 0,
            routines: BTreeMap::new(),
            running: BTreeMap::new(),
            pending: None,
            refused: alloc::collections::BTreeSet::new(),
        }
    }

    /// Also take functional requests on `rx` (e.g. 0x7DF), answered physically. As the
    /// standard asks, their "not supported" and "out of range" refusals are not sent.
    pub fn with_functional(mut self, rx: bywire_core::Id) -> Self {
        let mut config = *self.channel.config();
        config.rx_id = rx;
        self.functional = Some(IsoTp::new(config));
        self
    }

    /// Use `key` for SecurityAccess.
    pub fn with_key_function(mut self, key: KeyFunction) -> Self {
        self.key = key;
        self
    }

    /// Offer a routine for RoutineControl.
    pub fn set_routine(&mut self, id: u16, routine: Routine) {
        self.routines.insert(id, routine);
    }

    /// Whether the routine may start now (the vehicle's conditions: at standstill, ...);
    /// a refused start is answered with conditionsNotCorrect.
    pub fn set_routine_allowed(&mut self, id: u16, allowed: bool) {
        if allowed {
            self.refused.remove(&id);
        } else {
            self.refused.insert(id);
        }
    }

    /// What the routine's results request answers from now on (the application measured it).
    pub fn set_routine_result(&mut self, id: u16, result: Vec<u8>) {
        if let Some(routine) = self.routines.get_mut(&id) {
            routine.result = result;
        }
    }

    /// Whether the routine was started, has not been stopped, and has not run its time.
    pub fn routine_running(&self, id: u16, now: Timestamp) -> bool {
        self.running.get(&id).is_some_and(|done| now < *done)
    }

    /// Forget the session, security and running routines, as a reset does; the DIDs and the
    /// DTC memory (non-volatile) stay.
    pub fn restart(&mut self) {
        self.session = Session::Default;
        self.security = Security::Locked;
        self.running.clear();
        self.pending = None;
        self.outbox.clear();
        self.dtc_setting_on = true;
        let config = *self.channel.config();
        self.channel = IsoTp::new(config);
        if let Some(functional) = self.functional.as_mut() {
            *functional = IsoTp::new(*functional.config());
        }
    }

    fn unlocked(&self) -> bool {
        matches!(self.security, Security::Unlocked { .. })
    }

    /// Set a DID (its value and where it may be written).
    pub fn set_did(&mut self, id: u16, did: Did) {
        self.dids.insert(id, did);
    }

    /// Change a DID's value in place (no allocation when its length stays); a DID not yet
    /// set becomes a read-only one.
    pub fn set_did_value(&mut self, id: u16, value: &[u8]) {
        match self.dids.get_mut(&id) {
            Some(did) if did.value.len() == value.len() => did.value.copy_from_slice(value),
            Some(did) => did.value = value.to_vec(),
            None => {
                self.dids.insert(
                    id,
                    Did {
                        value: value.to_vec(),
                        writable_in: Vec::new(),
                        secured: false,
                    },
                );
            }
        }
    }

    /// A DID's value.
    pub fn did(&self, id: u16) -> Option<&[u8]> {
        self.dids.get(&id).map(|d| d.value.as_slice())
    }

    /// Report a test result for `dtc`: failed sets testFailed, this cycle, pending,
    /// confirmed and since-clear; passed clears testFailed. Ignored while DTC setting is off.
    pub fn report(&mut self, dtc: u32, failed: bool) {
        if !self.dtc_setting_on {
            return;
        }
        let entry = self.dtcs.entry(dtc & 0x00FF_FFFF).or_insert(0);
        if failed {
            *entry |= status::TEST_FAILED
                | status::TEST_FAILED_THIS_CYCLE
                | status::PENDING
                | status::CONFIRMED
                | status::FAILED_SINCE_CLEAR;
        } else {
            *entry &= !status::TEST_FAILED;
        }
    }

    /// Report a failure with a snapshot of the conditions (record 0x01 keeps the first, 0x02
    /// the latest), counting occurrences (extended data record 0x01).
    pub fn report_with_snapshot(&mut self, dtc: u32, snapshot: Snapshot) {
        if !self.dtc_setting_on {
            return;
        }
        let dtc = dtc & 0x00FF_FFFF;
        let already_failing = self
            .dtcs
            .get(&dtc)
            .is_some_and(|s| s & status::TEST_FAILED != 0);
        self.report(dtc, true);
        let records = self.records.entry(dtc).or_default();
        if records.first.is_none() {
            records.first = Some(snapshot.clone());
        }
        records.latest = Some(snapshot);
        if !already_failing {
            records.occurrences = records.occurrences.saturating_add(1);
        }
    }

    /// Every DTC in memory with its status, in DTC order.
    pub fn dtcs(&self) -> impl Iterator<Item = (u32, u8)> + '_ {
        self.dtcs.iter().map(|(dtc, status)| (*dtc, *status))
    }

    /// A DTC's status.
    pub fn dtc_status(&self, dtc: u32) -> Option<u8> {
        self.dtcs.get(&dtc).copied()
    }

    /// The active session.
    pub fn session(&self) -> Session {
        self.session
    }

    /// The events since the last call.
    pub fn take_events(&mut self) -> Vec<UdsEvent> {
        core::mem::take(&mut self.events)
    }

    /// The answer to one request (`None`: suppressed).
    pub fn handle(&mut self, now: Timestamp, request: &[u8]) -> Option<Vec<u8>> {
        self.last_request = now;
        let (&service, body) = request.split_first()?;
        let negative = |code: u8| Some(alloc::vec![0x7F, service, code]);
        // Services with a sub-function: its bit 7 suppresses the positive answer.
        let sub = body.first().copied();
        let suppress = matches!(
            service,
            0x10 | 0x11 | 0x3E | 0x19 | 0x28 | 0x85 | 0x27 | 0x31
        ) && sub.is_some_and(|s| s & 0x80 != 0);
        let sub = sub.map(|s| s & 0x7F);
        let positive = |mut answer: Vec<u8>| {
            if suppress {
                None
            } else {
                answer.insert(0, service + 0x40);
                Some(answer)
            }
        };
        match service {
            0x10 => {
                let (Some(code), 1) = (sub, body.len()) else {
                    return negative(nrc::INCORRECT_MESSAGE_LENGTH);
                };
                let Some(session) = Session::from_code(code) else {
                    return negative(nrc::SUB_FUNCTION_NOT_SUPPORTED);
                };
                self.session = session;
                self.security = Security::Locked;
                self.events.push(UdsEvent::Session(session));
                let p2 = u16::try_from(self.timing.p2.as_millis()).unwrap_or(u16::MAX);
                let p2x =
                    u16::try_from(self.timing.p2_extended.as_millis() / 10).unwrap_or(u16::MAX);
                let mut answer = alloc::vec![code];
                answer.extend_from_slice(&p2.to_be_bytes());
                answer.extend_from_slice(&p2x.to_be_bytes());
                positive(answer)
            }
            0x11 => {
                let (Some(code), 1) = (sub, body.len()) else {
                    return negative(nrc::INCORRECT_MESSAGE_LENGTH);
                };
                if !(1..=3).contains(&code) {
                    return negative(nrc::SUB_FUNCTION_NOT_SUPPORTED);
                }
                self.events.push(UdsEvent::Reset(code));
                self.session = Session::Default;
                positive(alloc::vec![code])
            }
            0x3E => match (sub, body.len()) {
                (Some(0), 1) => positive(alloc::vec![0]),
                (Some(_), 1) => negative(nrc::SUB_FUNCTION_NOT_SUPPORTED),
                _ => negative(nrc::INCORRECT_MESSAGE_LENGTH),
            },
            0x22 => self.read_dids(body).map_or_else(negative, positive),
            0x2E => self.write_did(body).map_or_else(negative, positive),
            0x19 => self.read_dtcs(sub, body).map_or_else(negative, positive),
            0x14 => {
                let [a, b, c] = body else {
                    return negative(nrc::INCORRECT_MESSAGE_LENGTH);
                };
                let group = u32::from_be_bytes([0, *a, *b, *c]);
                if group == 0x00FF_FFFF {
                    self.dtcs.clear();
                    self.records.clear();
                } else if self.dtcs.remove(&group).is_none() {
                    return negative(nrc::REQUEST_OUT_OF_RANGE);
                } else {
                    self.records.remove(&group);
                }
                self.events.push(UdsEvent::Cleared(group));
                positive(Vec::new())
            }
            0x85 => match (sub, body.len()) {
                (Some(code @ (1 | 2)), _) if self.session != Session::Default => {
                    self.dtc_setting_on = code == 1;
                    positive(alloc::vec![code])
                }
                (Some(1 | 2), _) => negative(nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION),
                (Some(_), _) => negative(nrc::SUB_FUNCTION_NOT_SUPPORTED),
                (None, _) => negative(nrc::INCORRECT_MESSAGE_LENGTH),
            },
            0x28 => match (sub, body.len()) {
                (Some(code @ 0..=3), 2) if self.session != Session::Default => {
                    positive(alloc::vec![code])
                }
                (Some(0..=3), 2) => negative(nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION),
                (Some(_), 2) => negative(nrc::SUB_FUNCTION_NOT_SUPPORTED),
                _ => negative(nrc::INCORRECT_MESSAGE_LENGTH),
            },
            0x27 => self
                .security_access(now, sub, body)
                .map_or_else(negative, positive),
            0x31 => match self.routine_control(now, sub, body) {
                Ok(Some(answer)) => positive(answer),
                // Answered later: response pending now.
                Ok(None) => negative(nrc::RESPONSE_PENDING),
                Err(code) => negative(code),
            },
            _ => negative(nrc::SERVICE_NOT_SUPPORTED),
        }
    }

    fn security_access(
        &mut self,
        now: Timestamp,
        sub: Option<u8>,
        body: &[u8],
    ) -> Result<Vec<u8>, u8> {
        let sub = sub.ok_or(nrc::INCORRECT_MESSAGE_LENGTH)?;
        if sub == 0 || sub > 0x41 {
            return Err(nrc::SUB_FUNCTION_NOT_SUPPORTED);
        }
        if self.session == Session::Default {
            return Err(nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION);
        }
        if self.locked_until.is_some_and(|until| now < until) {
            return Err(nrc::REQUIRED_TIME_DELAY_NOT_EXPIRED);
        }
        if sub % 2 == 1 {
            if body.len() != 1 {
                return Err(nrc::INCORRECT_MESSAGE_LENGTH);
            }
            // Already unlocked at this level: a seed of zeros says so.
            if self.security == (Security::Unlocked { level: sub }) {
                return Ok(alloc::vec![sub, 0, 0, 0, 0]);
            }
            self.seeds_given = self.seeds_given.wrapping_add(1);
            let seed = seed(now, self.seeds_given);
            self.security = Security::Seeded { level: sub, seed };
            let mut answer = alloc::vec![sub];
            answer.extend_from_slice(&seed);
            return Ok(answer);
        }
        let Security::Seeded { level, seed } = self.security else {
            return Err(nrc::REQUEST_SEQUENCE_ERROR);
        };
        if level + 1 != sub {
            return Err(nrc::REQUEST_SEQUENCE_ERROR);
        }
        let key = body.get(1..).unwrap_or(&[]);
        if key == (self.key)(level, &seed).as_slice() {
            self.security = Security::Unlocked { level };
            self.failed_attempts = 0;
            self.events.push(UdsEvent::Unlocked(level));
            return Ok(alloc::vec![sub]);
        }
        self.security = Security::Locked;
        self.failed_attempts = self.failed_attempts.saturating_add(1);
        if self.failed_attempts >= MAX_ATTEMPTS {
            self.failed_attempts = 0;
            self.locked_until = Some(now.saturating_add(ATTEMPT_DELAY));
            return Err(nrc::EXCEEDED_NUMBER_OF_ATTEMPTS);
        }
        Err(nrc::INVALID_KEY)
    }

    /// `Ok(None)`: the answer is pending.
    fn routine_control(
        &mut self,
        now: Timestamp,
        sub: Option<u8>,
        body: &[u8],
    ) -> Result<Option<Vec<u8>>, u8> {
        let sub = sub.ok_or(nrc::INCORRECT_MESSAGE_LENGTH)?;
        let [_, hi, lo, ..] = body else {
            return Err(nrc::INCORRECT_MESSAGE_LENGTH);
        };
        let id = u16::from_be_bytes([*hi, *lo]);
        let routine = self.routines.get(&id).ok_or(nrc::REQUEST_OUT_OF_RANGE)?;
        let answer = |extra: &[u8]| {
            let mut a = alloc::vec![sub, *hi, *lo];
            a.extend_from_slice(extra);
            a
        };
        match sub {
            1 => {
                if self.session == Session::Default {
                    return Err(nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION);
                }
                if routine.secured && !self.unlocked() {
                    return Err(nrc::SECURITY_ACCESS_DENIED);
                }
                if self.refused.contains(&id) {
                    return Err(nrc::CONDITIONS_NOT_CORRECT);
                }
                let done = now.saturating_add(routine.runs_for);
                self.running.insert(id, done);
                self.events.push(UdsEvent::RoutineStarted(id));
                if routine.runs_for.is_zero() {
                    return Ok(Some(answer(&[0x00])));
                }
                let reminder = now.saturating_add(self.pending_reminder());
                self.pending = Some((id, done, reminder));
                Ok(None)
            }
            2 => {
                self.running
                    .remove(&id)
                    .ok_or(nrc::REQUEST_SEQUENCE_ERROR)?;
                if self.pending.is_some_and(|(p, ..)| p == id) {
                    self.pending = None;
                }
                self.events.push(UdsEvent::RoutineStopped(id));
                Ok(Some(answer(&[0x00])))
            }
            3 => match self.running.get(&id) {
                Some(done) if now >= *done => Ok(Some(answer(&routine.result))),
                Some(_) => Err(nrc::CONDITIONS_NOT_CORRECT),
                None => Err(nrc::REQUEST_SEQUENCE_ERROR),
            },
            _ => Err(nrc::SUB_FUNCTION_NOT_SUPPORTED),
        }
    }

    fn read_dids(&self, body: &[u8]) -> Result<Vec<u8>, u8> {
        if body.is_empty() || !body.len().is_multiple_of(2) {
            return Err(nrc::INCORRECT_MESSAGE_LENGTH);
        }
        let mut answer = Vec::new();
        for pair in body.chunks_exact(2) {
            let &[hi, lo] = pair else { continue };
            let did = self
                .dids
                .get(&u16::from_be_bytes([hi, lo]))
                .ok_or(nrc::REQUEST_OUT_OF_RANGE)?;
            answer.extend_from_slice(&[hi, lo]);
            answer.extend_from_slice(&did.value);
        }
        Ok(answer)
    }

    fn write_did(&mut self, body: &[u8]) -> Result<Vec<u8>, u8> {
        let [hi, lo, value @ ..] = body else {
            return Err(nrc::INCORRECT_MESSAGE_LENGTH);
        };
        let id = u16::from_be_bytes([*hi, *lo]);
        let (session, unlocked) = (self.session, self.unlocked());
        let did = self.dids.get_mut(&id).ok_or(nrc::REQUEST_OUT_OF_RANGE)?;
        if did.writable_in.is_empty() {
            return Err(nrc::REQUEST_OUT_OF_RANGE);
        }
        if !did.writable_in.contains(&session) {
            return Err(nrc::CONDITIONS_NOT_CORRECT);
        }
        if did.secured && !unlocked {
            return Err(nrc::SECURITY_ACCESS_DENIED);
        }
        if value.len() != did.value.len() {
            return Err(nrc::INCORRECT_MESSAGE_LENGTH);
        }
        did.value = value.to_vec();
        self.events.push(UdsEvent::Written(id));
        Ok(alloc::vec![*hi, *lo])
    }

    fn read_dtcs(&self, sub: Option<u8>, body: &[u8]) -> Result<Vec<u8>, u8> {
        let sub = sub.ok_or(nrc::INCORRECT_MESSAGE_LENGTH)?;
        let listed = |mask: u8| self.dtcs.iter().filter(move |(_, s)| **s & mask != 0);
        match (sub, body) {
            (0x01, [_, mask]) => {
                let count =
                    u16::try_from(listed(*mask & AVAILABILITY_MASK).count()).unwrap_or(u16::MAX);
                let [hi, lo] = count.to_be_bytes();
                // DTCFormatIdentifier 0x01: ISO 14229-1.
                Ok(alloc::vec![0x01, AVAILABILITY_MASK, 0x01, hi, lo])
            }
            (0x02, [_, mask]) => {
                let mut answer = alloc::vec![0x02, AVAILABILITY_MASK];
                for (dtc, s) in listed(*mask & AVAILABILITY_MASK) {
                    let [_, a, b, c] = dtc.to_be_bytes();
                    answer.extend_from_slice(&[a, b, c, *s & AVAILABILITY_MASK]);
                }
                Ok(answer)
            }
            (0x0A, [_]) => {
                let mut answer = alloc::vec![0x0A, AVAILABILITY_MASK];
                for (dtc, s) in &self.dtcs {
                    let [_, a, b, c] = dtc.to_be_bytes();
                    answer.extend_from_slice(&[a, b, c, *s & AVAILABILITY_MASK]);
                }
                Ok(answer)
            }
            (0x04 | 0x06, [_, a, b, c, record]) => {
                let dtc = u32::from_be_bytes([0, *a, *b, *c]);
                let status = *self.dtcs.get(&dtc).ok_or(nrc::REQUEST_OUT_OF_RANGE)?;
                let records = self.records.get(&dtc).cloned().unwrap_or_default();
                let mut answer = alloc::vec![sub, *a, *b, *c, status & AVAILABILITY_MASK];
                if sub == 0x04 {
                    let wanted: &[(u8, &Option<Snapshot>)] =
                        &[(1, &records.first), (2, &records.latest)];
                    if !matches!(record, 1 | 2 | 0xFF) {
                        return Err(nrc::REQUEST_OUT_OF_RANGE);
                    }
                    for (number, snapshot) in wanted {
                        let Some(snapshot) = snapshot else { continue };
                        if *record != 0xFF && record != number {
                            continue;
                        }
                        answer.push(*number);
                        answer.push(u8::try_from(snapshot.len()).unwrap_or(u8::MAX));
                        for (id, value) in snapshot {
                            answer.extend_from_slice(&id.to_be_bytes());
                            answer.extend_from_slice(value);
                        }
                    }
                } else {
                    if !matches!(record, 1 | 0xFF) {
                        return Err(nrc::REQUEST_OUT_OF_RANGE);
                    }
                    answer.extend_from_slice(&[0x01, records.occurrences]);
                }
                Ok(answer)
            }
            (0x01 | 0x02 | 0x04 | 0x06 | 0x0A, _) => Err(nrc::INCORRECT_MESSAGE_LENGTH),
            _ => Err(nrc::SUB_FUNCTION_NOT_SUPPORTED),
        }
    }

    /// Take a frame from the bus.
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
        if let Some(functional) = self.functional.as_mut() {
            functional.on_frame(now, Port::MAIN, frame);
            let mut requests = Vec::new();
            while let Some(event) = functional.next_event() {
                if let IsoTpEvent::Received(request) = event {
                    requests.push(request);
                }
            }
            for request in requests {
                match self.handle(now, &request) {
                    Some(answer) if is_suppressed_for_functional(&answer) => {}
                    Some(answer) => self.outbox.push(answer),
                    None => {}
                }
            }
        }
        self.channel.on_frame(now, Port::MAIN, frame);
        while let Some(event) = self.channel.next_event() {
            match event {
                IsoTpEvent::Received(request) => {
                    if let Some(answer) = self.handle(now, &request) {
                        self.outbox.push(answer);
                    }
                }
                IsoTpEvent::Failed { error, .. } => self.events.push(UdsEvent::Transport(error)),
                IsoTpEvent::Sent => {}
            }
        }
    }

    /// A frame the server sent is on the bus (its transmit confirmation).
    fn confirm(&mut self, now: Timestamp, frame: &Frame) {
        self.channel.on_sent(now, Port::MAIN, frame);
    }

    /// Send what is due.
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        // S3 runs only while no request is being worked on.
        if self.pending.is_some() {
            self.last_request = now;
        }
        if self.session != Session::Default
            && now.saturating_since(self.last_request) >= self.timing.s3
        {
            self.session = Session::Default;
            self.events.push(UdsEvent::Session(Session::Default));
        }
        if let Some((id, due, reminder)) = self.pending {
            if now >= due {
                self.pending = None;
                let [hi, lo] = id.to_be_bytes();
                self.outbox.push(alloc::vec![0x71, 0x01, hi, lo, 0x00]);
            } else if now >= reminder {
                // Still running: another response pending before the tester's P2* ends.
                self.pending = Some((id, due, now.saturating_add(self.pending_reminder())));
                self.outbox
                    .push(alloc::vec![0x7F, 0x31, nrc::RESPONSE_PENDING]);
            }
        }
        if !self.channel.sending() && !self.outbox.is_empty() {
            let answer = self.outbox.remove(0);
            // A channel that cannot take it (empty) has nothing to send.
            let _ = self.channel.send(&answer);
        }
        self.channel.poll(now, out);
        while let Some(event) = self.channel.next_event() {
            if let IsoTpEvent::Failed { error, .. } = event {
                self.events.push(UdsEvent::Transport(error));
            }
        }
    }

    /// How long after a response pending the next one goes out if the answer is not ready:
    /// well inside P2*.
    fn pending_reminder(&self) -> Duration {
        self.timing.p2_extended * 4 / 5
    }

    /// When the server next has something to do.
    fn deadline(&self) -> Option<Timestamp> {
        let s3 = (self.session != Session::Default)
            .then(|| self.last_request.saturating_add(self.timing.s3));
        // An answer waits for the one before it to be sent (the channel says when).
        let out = (!self.outbox.is_empty() && !self.channel.sending()).then_some(Timestamp::ZERO);
        let pending = self.pending.map(|(_, due, reminder)| due.min(reminder));
        earliest([self.channel.next_deadline(), s3, out, pending])
    }
}

/// Negative answers a server keeps to itself for functional requests (ISO 14229-1 7.5).
fn is_suppressed_for_functional(answer: &[u8]) -> bool {
    matches!(
        answer,
        [0x7F, _, code] if matches!(
            *code,
            nrc::SERVICE_NOT_SUPPORTED
                | nrc::SUB_FUNCTION_NOT_SUPPORTED
                | nrc::REQUEST_OUT_OF_RANGE
                | nrc::SUB_FUNCTION_NOT_SUPPORTED_IN_ACTIVE_SESSION
                | nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION
        )
    )
}

/// A 4-byte seed from the time and a count (never all zeros: that means "already unlocked").
fn seed(now: Timestamp, count: u32) -> [u8; 4] {
    // SplitMix64's finaliser: well mixed, deterministic for a simulated run.
    let mut z = now.as_nanos() ^ (u64::from(count) << 32) ^ 0x9E37_79B9_7F4A_7C15;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let [a, b, c, d, ..] = z.to_le_bytes();
    if [a, b, c, d] == [0; 4] {
        [0, 0, 0, 1]
    } else {
        [a, b, c, d]
    }
}

impl Node for UdsServer {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.receive(now, frame);
    }

    fn on_sent(&mut self, now: Timestamp, _port: Port, frame: &Frame) -> bool {
        self.confirm(now, frame);
        true
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
    }
}
