//! UDS (ISO 14229-1): a server's request handling as a sans-IO state machine over whole
//! messages (an ISO-TP channel carries them: [`UdsServer`] owns one).
//!
//! Services so far: DiagnosticSessionControl (0x10, with P2/P2* in the answer and the S3
//! timeout back to the default session), ECUReset (0x11), TesterPresent (0x3E),
//! ReadDataByIdentifier (0x22, several identifiers per request), WriteDataByIdentifier
//! (0x2E, in the sessions a DID allows), ReadDTCInformation (0x19: 0x01 count, 0x02 by
//! status mask, 0x0A supported), ClearDiagnosticInformation (0x14), ControlDTCSetting
//! (0x85), CommunicationControl (0x28). The suppress-positive-response bit is honoured;
//! every refusal is a negative response with the standard's code.

use alloc::collections::BTreeMap;
use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::node::{Node, Port};
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
    timing: UdsTiming,
    session: Session,
    last_request: Timestamp,
    dids: BTreeMap<u16, Did>,
    /// DTC (24 bits) → status byte.
    dtcs: BTreeMap<u32, u8>,
    dtc_setting_on: bool,
    events: Vec<UdsEvent>,
    /// Responses waiting for the channel to be free.
    outbox: Vec<Vec<u8>>,
}

impl UdsServer {
    /// A server on `channel` with `timing`, in the default session.
    pub fn new(channel: IsoTpConfig, timing: UdsTiming) -> Self {
        UdsServer {
            channel: IsoTp::new(channel),
            timing,
            session: Session::Default,
            last_request: Timestamp::ZERO,
            dids: BTreeMap::new(),
            dtcs: BTreeMap::new(),
            dtc_setting_on: true,
            events: Vec::new(),
            outbox: Vec::new(),
        }
    }

    /// Set a DID (its value and where it may be written).
    pub fn set_did(&mut self, id: u16, did: Did) {
        self.dids.insert(id, did);
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
        let suppress = matches!(service, 0x10 | 0x11 | 0x3E | 0x19 | 0x28 | 0x85)
            && sub.is_some_and(|s| s & 0x80 != 0);
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
                } else if self.dtcs.remove(&group).is_none() {
                    return negative(nrc::REQUEST_OUT_OF_RANGE);
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
            _ => negative(nrc::SERVICE_NOT_SUPPORTED),
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
        let session = self.session;
        let did = self.dids.get_mut(&id).ok_or(nrc::REQUEST_OUT_OF_RANGE)?;
        if did.writable_in.is_empty() {
            return Err(nrc::REQUEST_OUT_OF_RANGE);
        }
        if !did.writable_in.contains(&session) {
            return Err(nrc::CONDITIONS_NOT_CORRECT);
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
            (0x01 | 0x02 | 0x0A, _) => Err(nrc::INCORRECT_MESSAGE_LENGTH),
            _ => Err(nrc::SUB_FUNCTION_NOT_SUPPORTED),
        }
    }

    /// Take a frame from the bus.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        self.channel.on_frame(now, frame);
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

    /// Send what is due.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if self.session != Session::Default
            && now.saturating_since(self.last_request) >= self.timing.s3
        {
            self.session = Session::Default;
            self.events.push(UdsEvent::Session(Session::Default));
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

    /// When the server next has something to do.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        let s3 = (self.session != Session::Default)
            .then(|| self.last_request.saturating_add(self.timing.s3));
        let out = (!self.outbox.is_empty()).then_some(Timestamp::ZERO);
        [self.channel.next_deadline(), s3, out]
            .into_iter()
            .flatten()
            .min()
    }
}

impl Node for UdsServer {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        UdsServer::on_frame(self, now, frame);
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        UdsServer::poll(self, now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        UdsServer::next_deadline(self)
    }
}
