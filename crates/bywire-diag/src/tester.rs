//! A tester's script: what a diagnostic tool does in one run, as requests chosen one at a time
//! once the answer to the one before is in. First the session ([`Plan::session`]), then the
//! security level ([`Plan::unlock`]: a seed asked, the key sent), then the service itself;
//! `SecurityAccess` as the service sends its own key; `ReadDTCInformation` with
//! [`Service::ReadDtcs::details`] reads each DTC's snapshot and extended data after the list.
//!
//! The script sends nothing itself: [`Script::next`] takes the last answer (a positive
//! response, as [`crate::client::UdsClient`] gives it) and says what to send next, so the
//! same script runs over a real bus, a simulated one or a test's hand.
//!
//! ```
//! use bywire_diag::tester::{Plan, Script, Service};
//! use bywire_diag::uds::demo_key;
//!
//! let plan = Plan { session: Some(3), unlock: Some(1), service: Service::ReadDids(vec![0xF190]) };
//! let mut script = Script::new(plan, |level: u8, seed: &[u8]| Ok::<_, ()>(demo_key(level, seed)));
//! assert_eq!(script.next(None), Ok(Some(vec![0x10, 0x03])));
//! assert_eq!(script.next(Some(vec![0x50, 0x03, 0, 50, 1, 244])), Ok(Some(vec![0x27, 0x01])));
//! // The seed 0x12 0x34; the demonstration key is each byte XOR 0x5A, plus the level.
//! let key = script.next(Some(vec![0x67, 0x01, 0x12, 0x34])).unwrap().unwrap();
//! assert_eq!(key, [0x27, 0x02, 0x49, 0x6F]);
//! assert_eq!(script.next(Some(vec![0x67, 0x02])), Ok(Some(vec![0x22, 0xF1, 0x90])));
//! assert_eq!(script.next(Some(vec![0x62, 0xF1, 0x90, b'V'])), Ok(None));
//! assert_eq!(script.answers(), [vec![0x62, 0xF1, 0x90, b'V']]);
//! ```

use alloc::vec;
use alloc::vec::Vec;

use crate::client;

/// `RoutineControl`'s sub-functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoutineControl {
    /// Start the routine (0x01).
    Start,
    /// Stop it (0x02).
    Stop,
    /// Ask its results (0x03).
    Results,
}

/// The service a script ends with.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum Service {
    /// `DiagnosticSessionControl` (0x10) to a session.
    Session(u8),
    /// `ReadDataByIdentifier` (0x22): these DIDs in one request.
    ReadDids(Vec<u16>),
    /// `WriteDataByIdentifier` (0x2E).
    WriteDid {
        /// The DID.
        did: u16,
        /// Its new value.
        value: Vec<u8>,
    },
    /// `ReadDTCInformation` (0x19).
    ReadDtcs {
        /// The status mask.
        status: u8,
        /// Only their number (0x01), else the list (0x02).
        count_only: bool,
        /// After the list, each DTC's snapshot (0x04) and extended data (0x06).
        details: bool,
    },
    /// `ClearDiagnosticInformation` (0x14) of a 24-bit group (0xFFFFFF: all).
    ClearDtcs(u32),
    /// `RoutineControl` (0x31).
    Routine {
        /// Start, stop or results.
        control: RoutineControl,
        /// The routine.
        id: u16,
        /// Its option record.
        record: Vec<u8>,
    },
    /// `ECUReset` (0x11) of a kind (1 hard, 2 key off/on, 3 soft).
    Reset(u8),
    /// `SecurityAccess` (0x27): unlock this (odd) level.
    Unlock(u8),
    /// `TesterPresent` (0x3E).
    TesterPresent,
    /// `ControlDTCSetting` (0x85) on or off.
    DtcSetting(bool),
    /// `CommunicationControl` (0x28): the control type and the communication type.
    CommControl(u8, u8),
    /// Any request, as bytes.
    Raw(Vec<u8>),
}

impl Service {
    /// The request it sends.
    pub fn request(&self) -> Vec<u8> {
        match self {
            Service::Session(session) => vec![0x10, *session],
            Service::ReadDids(dids) => {
                let mut request = vec![0x22];
                request.extend(dids.iter().flat_map(|did| did.to_be_bytes()));
                request
            }
            Service::WriteDid { did, value } => {
                let mut request = vec![0x2E];
                request.extend(did.to_be_bytes());
                request.extend(value);
                request
            }
            Service::ReadDtcs {
                status, count_only, ..
            } => vec![0x19, if *count_only { 0x01 } else { 0x02 }, *status],
            Service::ClearDtcs(group) => {
                let [_, a, b, c] = group.to_be_bytes();
                vec![0x14, a, b, c]
            }
            Service::Routine {
                control,
                id,
                record,
            } => {
                let sub = match control {
                    RoutineControl::Start => 1,
                    RoutineControl::Stop => 2,
                    RoutineControl::Results => 3,
                };
                let mut request = vec![0x31, sub];
                request.extend(id.to_be_bytes());
                request.extend(record);
                request
            }
            Service::Reset(kind) => vec![0x11, *kind],
            Service::Unlock(level) => vec![0x27, *level],
            Service::TesterPresent => vec![0x3E, 0x00],
            Service::DtcSetting(on) => vec![0x85, if *on { 0x01 } else { 0x02 }],
            Service::CommControl(control, communication) => vec![0x28, *control, *communication],
            Service::Raw(request) => request.clone(),
        }
    }
}

/// What a script does: an optional session and unlock, then the service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// Change to this session first.
    pub session: Option<u8>,
    /// Then unlock this (odd) security level.
    pub unlock: Option<u8>,
    /// Then this.
    pub service: Service,
}

/// Why a script cannot go on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ScriptError<E> {
    /// A security level is odd (its key goes with the level + 1).
    #[error("security level {0}: a level is odd (its key is level + 1)")]
    EvenLevel(u8),
    /// A raw request with no bytes.
    #[error("no request")]
    EmptyRequest,
    /// The key function failed.
    #[error("the key: {0}")]
    Key(E),
}

/// Where a script is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Start,
    Session,
    Seed,
    Key,
    Service,
    /// `SecurityAccess`'s own key, after its seed.
    ServiceKey,
    /// A DTC's snapshot (false) or extended data (true), by its place in the list.
    Detail(usize, bool),
}

/// A plan run one request at a time; `key` computes a key from a level and a seed.
pub struct Script<K> {
    plan: Plan,
    key: K,
    step: Step,
    /// The service's answers (its own key's too, and each DTC's details).
    answers: Vec<Vec<u8>>,
    /// The DTCs whose details are read.
    dtcs: Vec<(u32, u8)>,
}

impl<K, E> Script<K>
where
    K: FnMut(u8, &[u8]) -> Result<Vec<u8>, E>,
{
    /// A script of `plan`.
    pub fn new(plan: Plan, key: K) -> Self {
        Script {
            plan,
            key,
            step: Step::Start,
            answers: Vec::new(),
            dtcs: Vec::new(),
        }
    }

    /// The plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The service's answers so far: its own, then (`ReadDtcs` with details) each DTC's
    /// snapshot and extended data, in the list's order.
    pub fn answers(&self) -> &[Vec<u8>] {
        &self.answers
    }

    /// The next request, given the answer to the last one (`None` to start); `Ok(None)`:
    /// done.
    pub fn next(&mut self, answer: Option<Vec<u8>>) -> Result<Option<Vec<u8>>, ScriptError<E>> {
        if let Some(answer) = answer {
            if let Some(request) = self.take(answer)? {
                return Ok(Some(request));
            }
        }
        // The next step with something to ask (bounded: each step moves on, and the details
        // end with the DTC list).
        loop {
            self.step = match self.step {
                Step::Start => Step::Session,
                Step::Session => Step::Seed,
                Step::Seed | Step::Key => Step::Service,
                Step::Service | Step::ServiceKey => Step::Detail(0, false),
                Step::Detail(i, false) => Step::Detail(i, true),
                Step::Detail(i, true) => Step::Detail(i + 1, false),
            };
            let request = match self.step {
                Step::Start | Step::Key | Step::ServiceKey => None,
                Step::Session => self.plan.session.map(|s| vec![0x10, s]),
                Step::Seed => match self.plan.unlock {
                    Some(level) if level % 2 == 1 => Some(vec![0x27, level]),
                    Some(level) => return Err(ScriptError::EvenLevel(level)),
                    None => None,
                },
                Step::Service => Some(self.service_request()?),
                Step::Detail(i, extended) => {
                    let Some((dtc, _)) = self.dtcs.get(i) else {
                        return Ok(None);
                    };
                    let [_, a, b, c] = dtc.to_be_bytes();
                    Some(vec![
                        0x19,
                        if extended { 0x06 } else { 0x04 },
                        a,
                        b,
                        c,
                        0xFF,
                    ])
                }
            };
            if request.is_some() {
                return Ok(request);
            }
        }
    }

    /// The answer to the last request taken in; a key request when it was a seed.
    fn take(&mut self, answer: Vec<u8>) -> Result<Option<Vec<u8>>, ScriptError<E>> {
        match self.step {
            Step::Seed => {
                let level = self.plan.unlock.unwrap_or(1);
                if let Some(request) = self.key_request(level, &answer)? {
                    self.step = Step::Key;
                    return Ok(Some(request));
                }
            }
            Step::Service => {
                if let Service::Unlock(level) = self.plan.service {
                    if let Some(request) = self.key_request(level, &answer)? {
                        self.step = Step::ServiceKey;
                        return Ok(Some(request));
                    }
                }
                if let (Service::ReadDtcs { details: true, .. }, Ok((_, dtcs))) =
                    (&self.plan.service, client::dtc_list(&answer))
                {
                    self.dtcs = dtcs;
                }
                self.answers.push(answer);
            }
            Step::ServiceKey | Step::Detail(..) => self.answers.push(answer),
            Step::Start | Step::Session | Step::Key => {}
        }
        Ok(None)
    }

    /// The service's request, checked.
    fn service_request(&self) -> Result<Vec<u8>, ScriptError<E>> {
        match &self.plan.service {
            Service::Unlock(level) if level % 2 == 0 => Err(ScriptError::EvenLevel(*level)),
            Service::Raw(request) if request.is_empty() => Err(ScriptError::EmptyRequest),
            service => Ok(service.request()),
        }
    }

    /// The key request for a seed answer at `level`; `None` when the seed is zero (the level
    /// is unlocked already).
    fn key_request(&mut self, level: u8, answer: &[u8]) -> Result<Option<Vec<u8>>, ScriptError<E>> {
        let seed = answer.get(2..).unwrap_or(&[]);
        if seed.iter().all(|b| *b == 0) {
            return Ok(None);
        }
        let mut request = vec![0x27, level.wrapping_add(1)];
        request.extend((self.key)(level, seed).map_err(ScriptError::Key)?);
        Ok(Some(request))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A key function that refuses the seed 0xFF and otherwise answers 0xAA per byte.
    fn key(_: u8, seed: &[u8]) -> Result<Vec<u8>, &'static str> {
        if seed == [0xFF] {
            Err("refused")
        } else {
            Ok(vec![0xAA; seed.len()])
        }
    }

    type KeyFn = fn(u8, &[u8]) -> Result<Vec<u8>, &'static str>;

    fn script(plan: Plan) -> Script<KeyFn> {
        Script::new(plan, key)
    }

    fn plan(service: Service) -> Plan {
        Plan {
            session: None,
            unlock: None,
            service,
        }
    }

    #[test]
    fn dtc_details_follow_the_list_one_request_each() {
        let mut s = script(plan(Service::ReadDtcs {
            status: 0xFF,
            count_only: false,
            details: true,
        }));
        assert_eq!(s.next(None), Ok(Some(vec![0x19, 0x02, 0xFF])));
        // Two DTCs: C07300 and 512300.
        let list = vec![
            0x59, 0x02, 0xFF, 0xC0, 0x73, 0x00, 0x09, 0x51, 0x23, 0x00, 0x08,
        ];
        assert_eq!(
            s.next(Some(list)),
            Ok(Some(vec![0x19, 0x04, 0xC0, 0x73, 0x00, 0xFF]))
        );
        assert_eq!(
            s.next(Some(vec![0x59, 0x04])),
            Ok(Some(vec![0x19, 0x06, 0xC0, 0x73, 0x00, 0xFF]))
        );
        assert_eq!(
            s.next(Some(vec![0x59, 0x06])),
            Ok(Some(vec![0x19, 0x04, 0x51, 0x23, 0x00, 0xFF]))
        );
        assert_eq!(
            s.next(Some(vec![0x59, 0x04])),
            Ok(Some(vec![0x19, 0x06, 0x51, 0x23, 0x00, 0xFF]))
        );
        assert_eq!(s.next(Some(vec![0x59, 0x06])), Ok(None));
        assert_eq!(s.answers().len(), 5);
    }

    #[test]
    fn a_zero_seed_needs_no_key_and_an_unlock_as_the_service_sends_its_own() {
        let mut s = script(plan(Service::Unlock(3)));
        assert_eq!(s.next(None), Ok(Some(vec![0x27, 0x03])));
        assert_eq!(
            s.next(Some(vec![0x67, 0x03, 0x01, 0x02])),
            Ok(Some(vec![0x27, 0x04, 0xAA, 0xAA]))
        );
        assert_eq!(s.next(Some(vec![0x67, 0x04])), Ok(None));
        // Unlocked already: a zero seed, no key.
        let mut s = script(Plan {
            session: Some(3),
            unlock: Some(1),
            service: Service::TesterPresent,
        });
        assert_eq!(s.next(None), Ok(Some(vec![0x10, 0x03])));
        assert_eq!(s.next(Some(vec![0x50, 0x03])), Ok(Some(vec![0x27, 0x01])));
        assert_eq!(
            s.next(Some(vec![0x67, 0x01, 0x00, 0x00])),
            Ok(Some(vec![0x3E, 0x00]))
        );
    }

    #[test]
    fn even_levels_empty_requests_and_key_failures_stop_the_script() {
        let mut s = script(Plan {
            session: None,
            unlock: Some(2),
            service: Service::TesterPresent,
        });
        assert_eq!(s.next(None), Err(ScriptError::EvenLevel(2)));
        assert_eq!(
            script(plan(Service::Unlock(4))).next(None),
            Err(ScriptError::EvenLevel(4))
        );
        assert_eq!(
            script(plan(Service::Raw(Vec::new()))).next(None),
            Err(ScriptError::EmptyRequest)
        );
        let mut s = script(plan(Service::Unlock(1)));
        s.next(None).unwrap();
        assert_eq!(
            s.next(Some(vec![0x67, 0x01, 0xFF])),
            Err(ScriptError::Key("refused"))
        );
    }

    #[test]
    fn each_service_is_its_request() {
        let routine = Service::Routine {
            control: RoutineControl::Results,
            id: 0x0203,
            record: vec![1],
        };
        for (service, request) in [
            (Service::Session(2), vec![0x10, 2]),
            (
                Service::ReadDids(vec![0xF190, 0x0101]),
                vec![0x22, 0xF1, 0x90, 0x01, 0x01],
            ),
            (
                Service::WriteDid {
                    did: 0x0200,
                    value: vec![9],
                },
                vec![0x2E, 0x02, 0x00, 9],
            ),
            (Service::ClearDtcs(0xFF_FFFF), vec![0x14, 0xFF, 0xFF, 0xFF]),
            (routine, vec![0x31, 3, 0x02, 0x03, 1]),
            (Service::Reset(1), vec![0x11, 1]),
            (Service::DtcSetting(false), vec![0x85, 2]),
            (Service::CommControl(3, 1), vec![0x28, 3, 1]),
            (Service::Raw(vec![0x22, 0xF1, 0x90]), vec![0x22, 0xF1, 0x90]),
        ] {
            assert_eq!(service.request(), request, "{service:?}");
        }
    }
}
