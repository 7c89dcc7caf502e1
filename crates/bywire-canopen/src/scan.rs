//! Who is on a CANopen network: [`Scanner`] asks every node ID (1–127) for its device type
//! (an SDO upload of 0x1000) once, and notes each node that answers or sends a heartbeat, with
//! the NMT state its heartbeat reports. A tool then reads the nodes' identities over SDO.
//!
//! ```
//! use bywire_canopen::{cia402, device::Device, scan::Scanner};
//! use bywire_core::node::{Node, Port};
//! use bywire_core::Timestamp;
//!
//! let mut scanner = Scanner::default();
//! let mut drive = Device::new(5, cia402::drive_dictionary(5), cia402::Drive::new());
//! let mut asked = Vec::new();
//! scanner.poll(Timestamp::ZERO, &mut |_, frame| asked.push(frame));
//! assert_eq!(asked.len(), 127);
//! let mut answers = Vec::new();
//! for frame in &asked {
//!     drive.on_frame(Timestamp::ZERO, Port::MAIN, frame);
//!     drive.poll(Timestamp::ZERO, &mut |_, answer| answers.push(answer));
//! }
//! for answer in &answers {
//!     scanner.on_frame(Timestamp::ZERO, Port::MAIN, answer);
//! }
//! assert!(scanner.found().contains_key(&5));
//! ```

use alloc::collections::BTreeMap;

use bywire_core::frame::{Frame, Id};
use bywire_core::node::{Node, Port};
use bywire_core::Timestamp;

use crate::nmt::{parse_heartbeat, NmtState};

/// The first SDO answer's identifier (0x580 + node ID).
const SDO_ANSWERS: u16 = 0x580;
/// The first SDO request's identifier (0x600 + node ID).
const SDO_REQUESTS: u32 = 0x600;

/// Asks every node once and notes who answers; a node as its runner drives any node.
#[derive(Debug, Default)]
pub struct Scanner {
    asked: bool,
    found: BTreeMap<u8, Option<NmtState>>,
}

impl Scanner {
    /// The nodes found, each with the state its last heartbeat reported (`None`: it answered
    /// the SDO request but sent no heartbeat).
    pub fn found(&self) -> &BTreeMap<u8, Option<NmtState>> {
        &self.found
    }
}

impl Node for Scanner {
    fn on_frame(&mut self, _now: Timestamp, _port: Port, frame: &Frame) {
        if let Some((node, state)) = parse_heartbeat(frame) {
            self.found.insert(node, Some(state));
        } else if let Some(Id::Standard(id)) = frame.id() {
            let answered = id.as_raw().checked_sub(SDO_ANSWERS);
            if let (Some(node @ 1..=127), false) = (answered, frame.is_remote()) {
                self.found
                    .entry(u8::try_from(node).unwrap_or(0))
                    .or_insert(None);
            }
        }
    }

    fn poll(&mut self, _now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if self.asked {
            return;
        }
        self.asked = true;
        for node in 1..=127u32 {
            // Upload 0x1000:00, the device type every CANopen device has.
            let request = Id::standard(SDO_REQUESTS + node)
                .ok()
                .and_then(|id| Frame::classic(id, &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]).ok());
            if let Some(frame) = request {
                out(Port::MAIN, frame);
            }
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        // Asked at its first poll; it listens after that.
        None
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::nmt::classic;

    #[test]
    fn heartbeats_and_sdo_answers_are_found_and_nothing_else() {
        let mut scanner = Scanner::default();
        let at = Timestamp::ZERO;
        // Node 3's heartbeat (operational), node 9's SDO answer, a remote frame on 0x585,
        // a frame on 0x580 (no node 0), and one on 0x600 (a request, not an answer).
        for frame in [
            classic(0x703, &[0x05]),
            classic(0x589, &[0x43, 0, 0x10, 0, 0x92, 1, 2, 0]),
            Frame::remote(
                Id::standard(0x585).unwrap(),
                bywire_core::Dlc::from_nibble(0),
            ),
            classic(0x580, &[0x43, 0, 0x10, 0, 0, 0, 0, 0]),
            classic(0x604, &[0x40, 0, 0x10, 0, 0, 0, 0, 0]),
        ] {
            scanner.on_frame(at, Port::MAIN, &frame);
        }
        let found: Vec<(u8, Option<NmtState>)> =
            scanner.found().iter().map(|(n, s)| (*n, *s)).collect();
        assert_eq!(found, [(3, Some(NmtState::Operational)), (9, None)]);
        // It asks once.
        let mut asked = 0;
        scanner.poll(at, &mut |_, _| asked += 1);
        scanner.poll(at, &mut |_, _| asked += 1);
        assert_eq!(asked, 127);
    }
}
