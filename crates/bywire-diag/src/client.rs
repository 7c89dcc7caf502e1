//! A UDS (ISO 14229-1) client — the tester's side — as a sans-IO node over one ISO-TP
//! channel: one request at a time, the answer awaited for P2 after the request is sent,
//! for P2* after each response pending (0x78), and TesterPresent sent while a non-default
//! session must be kept open (S3).
//!
//! Timing follows the server: a DiagnosticSessionControl answer carries its P2 and P2*, and
//! the client adopts them (with its margin added), as ISO 14229-2 asks.

use alloc::vec::Vec;
use core::fmt;
use core::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};

use crate::isotp::{IsoTp, IsoTpConfig, IsoTpError, IsoTpEvent, SendError};
use crate::uds::nrc;

/// The client's timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientTiming {
    /// How long the first answer may take after the request is sent (P2client).
    pub p2: Duration,
    /// How long each answer may take after a response pending (P2*client).
    pub p2_extended: Duration,
    /// Added to the server's announced P2 and P2* (the bus and both stacks' delays).
    pub margin: Duration,
    /// Longest a request may take to send (the transport's own timeouts end it first).
    pub send_timeout: Duration,
    /// Send TesterPresent (suppressed answer) this often while a non-default session is
    /// open (`None`: never). Below the server's S3, 2 s is usual for S3 = 5 s.
    pub tester_present: Option<Duration>,
    /// Response-pending answers accepted for one request before giving up.
    pub max_pending: u16,
}

impl Default for ClientTiming {
    /// P2 1 s, P2* 5 s (udsoncan's defaults), a 50 ms margin, TesterPresent every 2 s, up
    /// to 100 response-pending answers.
    fn default() -> Self {
        ClientTiming {
            p2: Duration::from_millis(1000),
            p2_extended: Duration::from_millis(5000),
            margin: Duration::from_millis(50),
            send_timeout: Duration::from_millis(5000),
            tester_present: Some(Duration::from_millis(2000)),
            max_pending: 100,
        }
    }
}

/// Why a request got no positive answer.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ClientError {
    /// A request is already in flight.
    Busy,
    /// The request cannot be sent (empty, too long).
    Request(SendError),
    /// The server answered with a negative response code.
    Negative {
        /// The service refused.
        service: u8,
        /// The code (ISO 14229-1 annex A).
        code: u8,
    },
    /// No answer within P2 (`pending`: within P2* after a response pending).
    Timeout {
        /// A response pending had come.
        pending: bool,
    },
    /// The request did not finish sending in time.
    SendTimeout,
    /// More response-pending answers than allowed.
    TooManyPending,
    /// The transport failed.
    Transport(IsoTpError),
    /// An answer that is not to this request (another service, or too short).
    Unexpected(Vec<u8>),
}

impl fmt::Display for ClientError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClientError::Busy => f.write_str("a request is already in flight"),
            ClientError::Request(e) => write!(f, "the request cannot be sent: {e}"),
            ClientError::Negative { service, code } => write!(
                f,
                "negative response to service 0x{service:02X}: 0x{code:02X} ({})",
                nrc_name(*code)
            ),
            ClientError::Timeout { pending: false } => f.write_str("no answer within P2"),
            ClientError::Timeout { pending: true } => {
                f.write_str("no answer within P2* after a response pending")
            }
            ClientError::SendTimeout => f.write_str("the request did not finish sending"),
            ClientError::TooManyPending => f.write_str("too many response-pending answers"),
            ClientError::Transport(e) => write!(f, "transport: {e}"),
            ClientError::Unexpected(answer) => {
                f.write_str("an answer to another request:")?;
                for b in answer.iter().take(16) {
                    write!(f, " {b:02X}")?;
                }
                Ok(())
            }
        }
    }
}

/// The standard's name for a negative response code.
pub fn nrc_name(code: u8) -> &'static str {
    match code {
        0x10 => "generalReject",
        nrc::SERVICE_NOT_SUPPORTED => "serviceNotSupported",
        nrc::SUB_FUNCTION_NOT_SUPPORTED => "subFunctionNotSupported",
        nrc::INCORRECT_MESSAGE_LENGTH => "incorrectMessageLengthOrInvalidFormat",
        0x14 => "responseTooLong",
        0x21 => "busyRepeatRequest",
        nrc::CONDITIONS_NOT_CORRECT => "conditionsNotCorrect",
        nrc::REQUEST_SEQUENCE_ERROR => "requestSequenceError",
        0x25 => "noResponseFromSubnetComponent",
        0x26 => "failurePreventsExecutionOfRequestedAction",
        nrc::REQUEST_OUT_OF_RANGE => "requestOutOfRange",
        nrc::SECURITY_ACCESS_DENIED => "securityAccessDenied",
        nrc::INVALID_KEY => "invalidKey",
        nrc::EXCEEDED_NUMBER_OF_ATTEMPTS => "exceedNumberOfAttempts",
        nrc::REQUIRED_TIME_DELAY_NOT_EXPIRED => "requiredTimeDelayNotExpired",
        0x70 => "uploadDownloadNotAccepted",
        0x72 => "generalProgrammingFailure",
        nrc::RESPONSE_PENDING => "requestCorrectlyReceived-ResponsePending",
        nrc::SUB_FUNCTION_NOT_SUPPORTED_IN_ACTIVE_SESSION => {
            "subFunctionNotSupportedInActiveSession"
        }
        nrc::SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION => "serviceNotSupportedInActiveSession",
        _ => "unknown",
    }
}

/// Where the client is with its request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Nothing in flight.
    Idle,
    /// The request is being sent (since then, for the send timeout).
    Sending { service: u8, deadline: Timestamp },
    /// Sent; the answer is due by `deadline`. `pending`: response-pending answers so far.
    Awaiting {
        service: u8,
        deadline: Timestamp,
        pending: u16,
    },
}

/// What happens to the client.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Input {
    /// The transport finished sending the request.
    Sent,
    /// A whole message arrived.
    Received(Vec<u8>),
    /// The transport failed.
    Failed(IsoTpError),
    /// Time passed.
    Tick,
}

/// A UDS client on one ISO-TP channel.
#[derive(Debug, Clone)]
pub struct UdsClient {
    channel: IsoTp,
    timing: ClientTiming,
    /// P2 and P2* in use (the server's, once announced, plus the margin).
    p2: Duration,
    p2_extended: Duration,
    state: State,
    outcome: Option<Result<Vec<u8>, ClientError>>,
    /// A non-default session is open: TesterPresent keeps it.
    in_session: bool,
    next_tester_present: Option<Timestamp>,
    /// The request whose answer is suppressed (TesterPresent with bit 7) is on its way.
    quiet_send: bool,
}

impl UdsClient {
    /// A client on `channel` with `timing`.
    pub fn new(channel: IsoTpConfig, timing: ClientTiming) -> Self {
        UdsClient {
            channel: IsoTp::new(channel),
            timing,
            p2: timing.p2,
            p2_extended: timing.p2_extended,
            state: State::Idle,
            outcome: None,
            in_session: false,
            next_tester_present: None,
            quiet_send: false,
        }
    }

    /// P2 and P2* in use now.
    pub fn p2(&self) -> (Duration, Duration) {
        (self.p2, self.p2_extended)
    }

    /// Whether a request is in flight.
    pub fn busy(&self) -> bool {
        self.state != State::Idle || self.quiet_send
    }

    /// Send `request` (service and parameters). Its answer comes from [`Self::take_outcome`].
    pub fn request(&mut self, now: Timestamp, request: &[u8]) -> Result<(), ClientError> {
        if self.busy() {
            return Err(ClientError::Busy);
        }
        let &service = request
            .first()
            .ok_or(ClientError::Request(SendError::Length(0)))?;
        self.channel.send(request).map_err(ClientError::Request)?;
        self.outcome = None;
        if let (Some(period), true) = (self.timing.tester_present, self.in_session) {
            self.next_tester_present = Some(now.saturating_add(period));
        }
        self.state = State::Sending {
            service,
            deadline: now.saturating_add(self.timing.send_timeout),
        };
        Ok(())
    }

    /// The finished request's positive answer (from its service byte + 0x40 on), or why
    /// there is none. `None` while it is in flight.
    pub fn take_outcome(&mut self) -> Option<Result<Vec<u8>, ClientError>> {
        self.outcome.take()
    }

    /// The transition function: every (state, input) pair, and what it leaves behind.
    fn step(&mut self, now: Timestamp, input: Input) {
        let (next, outcome) = match (self.state, input) {
            // Nothing asked: a stray answer, a late failure or time change nothing.
            (State::Idle, Input::Received(_) | Input::Sent | Input::Tick | Input::Failed(_)) => {
                (State::Idle, None)
            }
            (State::Sending { service, .. }, Input::Sent) => (
                State::Awaiting {
                    service,
                    deadline: now.saturating_add(self.p2),
                    pending: 0,
                },
                None,
            ),
            (State::Sending { deadline, .. }, Input::Tick) if now >= deadline => {
                (State::Idle, Some(Err(ClientError::SendTimeout)))
            }
            // An answer before our request finished sending is not to it.
            (state @ State::Sending { .. }, Input::Tick | Input::Received(_)) => (state, None),
            (State::Sending { .. } | State::Awaiting { .. }, Input::Failed(e)) => {
                (State::Idle, Some(Err(ClientError::Transport(e))))
            }
            (state @ State::Awaiting { .. }, Input::Sent) => (state, None),
            (
                State::Awaiting {
                    deadline, pending, ..
                },
                Input::Tick,
            ) if now >= deadline => (
                State::Idle,
                Some(Err(ClientError::Timeout {
                    pending: pending > 0,
                })),
            ),
            (state @ State::Awaiting { .. }, Input::Tick) => (state, None),
            (
                State::Awaiting {
                    service, pending, ..
                },
                Input::Received(answer),
            ) => match answer.as_slice() {
                [0x7F, s, nrc::RESPONSE_PENDING] if *s == service => {
                    if pending >= self.timing.max_pending {
                        (State::Idle, Some(Err(ClientError::TooManyPending)))
                    } else {
                        (
                            State::Awaiting {
                                service,
                                deadline: now.saturating_add(self.p2_extended),
                                pending: pending + 1,
                            },
                            None,
                        )
                    }
                }
                [0x7F, s, code] if *s == service => (
                    State::Idle,
                    Some(Err(ClientError::Negative {
                        service,
                        code: *code,
                    })),
                ),
                // A late answer to our suppressed TesterPresent (some servers answer it).
                [0x7E, ..] | [0x7F, 0x3E, _] if service != 0x3E => (self.state, None),
                [s, ..] if *s == service.wrapping_add(0x40) => {
                    self.adopt(&answer);
                    (State::Idle, Some(Ok(answer)))
                }
                _ => (State::Idle, Some(Err(ClientError::Unexpected(answer)))),
            },
        };
        self.state = next;
        if outcome.is_some() {
            self.outcome = outcome;
        }
    }

    /// What a positive answer tells the client: the session (for TesterPresent) and the
    /// server's P2/P2*.
    fn adopt(&mut self, answer: &[u8]) {
        if let [0x50, session, p2_hi, p2_lo, x_hi, x_lo] = answer {
            self.in_session = *session != 0x01;
            let p2 = u64::from(u16::from_be_bytes([*p2_hi, *p2_lo]));
            let p2x = u64::from(u16::from_be_bytes([*x_hi, *x_lo])) * 10;
            self.p2 = Duration::from_millis(p2) + self.timing.margin;
            self.p2_extended = Duration::from_millis(p2x) + self.timing.margin;
        }
        if matches!(answer, [0x51, ..]) {
            // A reset ends the session.
            self.in_session = false;
        }
    }

    /// Take a frame from the bus.
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
        self.channel.on_frame(now, Port::MAIN, frame);
        self.take_channel_events(now);
    }

    /// A frame the client sent is on the bus (its transmit confirmation: P2 starts at the
    /// request's).
    fn confirm(&mut self, now: Timestamp, frame: &Frame) {
        self.channel.on_sent(now, Port::MAIN, frame);
        self.take_channel_events(now);
    }

    fn take_channel_events(&mut self, now: Timestamp) {
        // Bounded by the channel's event queue.
        while let Some(event) = self.channel.next_event() {
            let input = match event {
                IsoTpEvent::Received(message) => Input::Received(message),
                IsoTpEvent::Sent if self.quiet_send => {
                    self.quiet_send = false;
                    continue;
                }
                IsoTpEvent::Sent => Input::Sent,
                IsoTpEvent::Failed { sending: true, .. } if self.quiet_send => {
                    self.quiet_send = false;
                    continue;
                }
                IsoTpEvent::Failed { error, .. } => Input::Failed(error),
            };
            self.step(now, input);
        }
    }

    /// Send what is due; end a request whose time is up.
    fn send_due(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, Input::Tick);
        self.keep_session(now);
        self.channel.poll(now, out);
        self.take_channel_events(now);
    }

    /// TesterPresent with the answer suppressed, between requests, while a session is open.
    fn keep_session(&mut self, now: Timestamp) {
        let Some(period) = self.timing.tester_present.filter(|_| self.in_session) else {
            self.next_tester_present = None;
            return;
        };
        let due = *self
            .next_tester_present
            .get_or_insert(now.saturating_add(period));
        if now < due {
            return;
        }
        // A request in flight keeps the session itself.
        if !self.busy() && self.channel.send(&[0x3E, 0x80]).is_ok() {
            self.quiet_send = true;
        }
        self.next_tester_present = Some(now.saturating_add(period));
    }

    /// When the client next has something to do.
    fn deadline(&self) -> Option<Timestamp> {
        let request = match self.state {
            State::Idle => None,
            State::Sending { deadline, .. } | State::Awaiting { deadline, .. } => Some(deadline),
        };
        earliest([
            self.channel.next_deadline(),
            request,
            self.next_tester_present,
        ])
    }
}

impl Node for UdsClient {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.receive(now, frame);
    }

    fn on_sent(&mut self, now: Timestamp, _port: Port, frame: &Frame) -> bool {
        self.confirm(now, frame);
        true
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.send_due(now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
    }
}

/// A malformed answer: what was expected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AnswerError(pub &'static str);

impl fmt::Display for AnswerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "malformed answer: {}", self.0)
    }
}

/// The DTCs of a ReadDTCInformation answer listing them (sub-functions 0x02 and 0x0A):
/// the availability mask and each DTC (24 bits) with its status.
pub fn dtc_list(answer: &[u8]) -> Result<(u8, Vec<(u32, u8)>), AnswerError> {
    let [0x59, 0x02 | 0x0A, availability, records @ ..] = answer else {
        return Err(AnswerError("0x59 0x02|0x0A, then the availability mask"));
    };
    if !records.len().is_multiple_of(4) {
        return Err(AnswerError("4 bytes per DTC (3 of code, 1 of status)"));
    }
    let dtcs = records
        .chunks_exact(4)
        .filter_map(|r| match r {
            [a, b, c, status] => Some((u32::from_be_bytes([0, *a, *b, *c]), *status)),
            _ => None,
        })
        .collect();
    Ok((*availability, dtcs))
}

/// The count of a ReadDTCInformation 0x01 answer.
pub fn dtc_count(answer: &[u8]) -> Result<u16, AnswerError> {
    match answer {
        [0x59, 0x01, _, _, hi, lo] => Ok(u16::from_be_bytes([*hi, *lo])),
        _ => Err(AnswerError("0x59 0x01, mask, format, two bytes of count")),
    }
}

/// One snapshot record of a ReadDTCInformation 0x04 answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SnapshotRecord {
    /// The record number.
    pub number: u8,
    /// Its data identifiers and their values.
    pub values: Vec<(u16, Vec<u8>)>,
}

/// The DTC, its status and its snapshot records from a ReadDTCInformation 0x04 answer; a
/// value's length comes from `did_length` (the snapshot's DIDs are the ECU's own).
pub fn snapshots(
    answer: &[u8],
    did_length: &dyn Fn(u16) -> Option<usize>,
) -> Result<(u32, u8, Vec<SnapshotRecord>), AnswerError> {
    let [0x59, 0x04, a, b, c, status, records @ ..] = answer else {
        return Err(AnswerError("0x59 0x04, three bytes of DTC, its status"));
    };
    let mut rest: &[u8] = records;
    let mut records = Vec::new();
    // Each pass takes at least two bytes.
    while let [number, count, tail @ ..] = rest {
        rest = tail;
        let mut values = Vec::new();
        for _ in 0..*count {
            let [hi, lo, tail @ ..] = rest else {
                return Err(AnswerError("a snapshot's data identifier"));
            };
            let id = u16::from_be_bytes([*hi, *lo]);
            let length = did_length(id).ok_or(AnswerError("a snapshot DID of known length"))?;
            let value = tail
                .get(..length)
                .ok_or(AnswerError("a snapshot value as long as its DID"))?;
            values.push((id, value.to_vec()));
            rest = tail.get(length..).unwrap_or(&[]);
        }
        records.push(SnapshotRecord {
            number: *number,
            values,
        });
    }
    if !rest.is_empty() {
        return Err(AnswerError("whole snapshot records"));
    }
    Ok((u32::from_be_bytes([0, *a, *b, *c]), *status, records))
}

/// The values of a ReadDataByIdentifier answer to `ids`, in order; each value's length from
/// `did_length`, except that the last DID may take the rest.
pub fn did_values(
    answer: &[u8],
    ids: &[u16],
    did_length: &dyn Fn(u16) -> Option<usize>,
) -> Result<Vec<(u16, Vec<u8>)>, AnswerError> {
    let [0x62, body @ ..] = answer else {
        return Err(AnswerError("0x62, then the values"));
    };
    let mut rest: &[u8] = body;
    let mut values = Vec::new();
    for (i, id) in ids.iter().enumerate() {
        let [hi, lo, tail @ ..] = rest else {
            return Err(AnswerError("a value for every DID asked for"));
        };
        if u16::from_be_bytes([*hi, *lo]) != *id {
            return Err(AnswerError("the DIDs in the order asked for"));
        }
        let last = i + 1 == ids.len();
        let length = match did_length(*id) {
            Some(n) => n,
            None if last => tail.len(),
            None => return Err(AnswerError("the length of every DID but the last")),
        };
        let value = tail
            .get(..length)
            .ok_or(AnswerError("a value as long as its DID"))?;
        values.push((*id, value.to_vec()));
        rest = tail.get(length..).unwrap_or(&[]);
    }
    if !rest.is_empty() {
        return Err(AnswerError("no bytes after the last value"));
    }
    Ok(values)
}
