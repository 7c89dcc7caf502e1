//! Authenticated messages on the command path ([`Secured`]): any wire, with the messages it
//! lists signed on the way out and verified on the way in (AUTOSAR SecOC through
//! [`bywire_secoc`]). A secured message travels as a CAN FD frame: the message's own payload
//! (counter and CRC included, unchanged), then the freshness value's low bits and the truncated
//! MAC.
//!
//! - The ADS side signs its commands and emergency-brake frames and verifies the vehicle's
//!   state and wheel frames; the vehicle side the reverse. A frame of a listed message that
//!   fails verification is never read: a command becomes a rejected command
//!   ([`Rejected::Authentication`], the watchdog cascade follows), anything else an
//!   [`Incoming::Unauthenticated`] or [`Feedback::Unauthenticated`], counted apart.
//! - Each command bus has its own receivers: the redundant bus carries the same frames, with
//!   the same freshness, and neither copy is a replay of the other.
//! - Freshness sync: when a frame is stale (its sender restarted without its persisted
//!   freshness, or from a rewound one) or its MAC matches no freshness value near the last
//!   accepted (a sender further behind than the receiver looks — after a minute of driving a
//!   restarted sender's low bits name no value it tries —, or a forgery: the two cannot be
//!   told apart), the receiving side answers with a signed sync message carrying the last
//!   value it accepted, at most every [`SYNC_INTERVAL`]; the sender goes on after it. A sync
//!   only ever moves a sender forward and the receiver still accepts only fresh values, so
//!   neither a replayed sync nor a flood of forgeries makes anything be accepted: a forger
//!   gains at most one sync frame every [`SYNC_INTERVAL`], signed with a key it lacks.
//! - Signing that cannot be done (the freshness exhausted, a frame not of its declared length)
//!   sends nothing: the receiving side's watchdog then stops the vehicle. Nothing is ever sent
//!   unauthenticated in a secured message's place.
//!
//! `no_std`, no allocation: the table holds at most [`MAX_SECURED`] messages.

use core::time::Duration;

use bywire_core::frame::FdFrame;
use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_secoc::{Authenticator, Counts, Key, Layout, Receiver, Rejection, Sender};

use crate::command::ControlCommand;
use crate::redundancy::Channel;
use crate::wire::{
    AdsWire, Counters, DegradationReport, Feedback, Incoming, Rejected, StateReport, VehicleWire,
};

/// The most messages one table secures.
pub const MAX_SECURED: usize = 8;
/// The shortest time between two freshness-sync frames.
pub const SYNC_INTERVAL: Duration = Duration::from_millis(100);

/// A sync frame's payload: the secured message's data ID (2 bytes) and the last freshness
/// value accepted (8 bytes), both big-endian; the MAC covers it with that value as freshness.
const SYNC_PAYLOAD: usize = 10;
/// The sync frame's MAC bits.
const SYNC_MAC_BITS: u32 = 24;

/// How far beyond the next freshness value a node reserves in its store before it polls again:
/// more than one poll ever signs.
pub const RESERVE_MARGIN: u64 = 64;

/// The freshness-sync message: its identifier and the data ID its MAC covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncMessage {
    /// The identifier it is sent with.
    pub id: Id,
    /// Its data ID.
    pub data_id: u16,
}

/// Why a table refused a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum TableError {
    /// More than [`MAX_SECURED`] messages.
    Full,
    /// The identifier is already in the table.
    Duplicate(Id),
    /// The data ID is already in the table (a MAC must name one message).
    DuplicateDataId(u16),
}

impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TableError::Full => write!(f, "at most {MAX_SECURED} secured messages"),
            TableError::Duplicate(id) => {
                write!(f, "identifier 0x{:X} is secured twice", id.as_raw())
            }
            TableError::DuplicateDataId(d) => write!(f, "data ID {d} is used twice"),
        }
    }
}

#[derive(Debug, Clone)]
struct Entry {
    id: Id,
    layout: Layout,
    sender: Sender,
    /// One receiver per command bus.
    receivers: [Receiver; 2],
}

/// What a received frame is to the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Checked {
    /// Not a secured message: read it as it is.
    Unsecured,
    /// Authentic and fresh: the message as its own wire reads it (the payload alone).
    Authentic(Frame),
    /// A secured message that failed verification, and why.
    Rejected(Rejection),
    /// A freshness sync, taken (or, failing verification, counted and dropped).
    Sync,
}

/// Counts of everything the table verified.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SecuredStats {
    /// The receivers' counts, summed.
    pub frames: Counts,
    /// Sync frames taken.
    pub syncs_taken: u64,
    /// Sync frames refused (their MAC is wrong).
    pub syncs_refused: u64,
    /// Sync frames sent.
    pub syncs_sent: u64,
    /// Frames not sent because they could not be signed.
    pub unsigned: u64,
}

/// The secured messages of one node, with its key, freshness and counts.
#[derive(Debug, Clone)]
pub struct SecuredTable {
    auth: Authenticator,
    window: u64,
    entries: [Option<Entry>; MAX_SECURED],
    sync: Option<SyncMessage>,
    /// A stale or unverified frame of this entry was seen: a sync is due.
    sync_due: Option<usize>,
    last_sync: Option<Timestamp>,
    stats: SecuredStats,
}

impl SecuredTable {
    /// A table signing and verifying with `key`, accepting freshness values up to `window`
    /// ahead of the last accepted one (at least the freshness a sender's store reserves ahead,
    /// so that its restart is accepted).
    pub fn new(key: &Key, window: u64) -> SecuredTable {
        SecuredTable {
            auth: Authenticator::new(key),
            window,
            entries: Default::default(),
            sync: None,
            sync_due: None,
            last_sync: None,
            stats: SecuredStats::default(),
        }
    }

    /// Secure message `id` with `layout`, the first frame sent with freshness `next` (1 for a
    /// new key, the persisted value after a restart).
    pub fn secure(&mut self, id: Id, layout: Layout, next: u64) -> Result<(), TableError> {
        let taken = self.entries.iter().flatten();
        if let Some(e) = taken.clone().find(|e| e.id == id) {
            return Err(TableError::Duplicate(e.id));
        }
        if taken.clone().any(|e| e.layout.data_id == layout.data_id)
            || self.sync.is_some_and(|s| s.data_id == layout.data_id)
        {
            return Err(TableError::DuplicateDataId(layout.data_id));
        }
        let slot = self
            .entries
            .iter_mut()
            .find(|e| e.is_none())
            .ok_or(TableError::Full)?;
        let receiver = Receiver::new(0, self.window);
        *slot = Some(Entry {
            id,
            layout,
            sender: Sender::new(next),
            receivers: [receiver; 2],
        });
        Ok(())
    }

    /// Answer stale and unverified frames with (and take) freshness syncs on `sync`.
    pub fn with_sync(mut self, sync: SyncMessage) -> Result<SecuredTable, TableError> {
        if self
            .entries
            .iter()
            .flatten()
            .any(|e| e.layout.data_id == sync.data_id)
        {
            return Err(TableError::DuplicateDataId(sync.data_id));
        }
        self.sync = Some(sync);
        Ok(self)
    }

    /// The counts so far.
    pub fn stats(&self) -> SecuredStats {
        self.stats
    }

    /// The freshness the next frame of `id` is signed with (what a sender persists).
    pub fn next_freshness(&self, id: Id) -> Option<u64> {
        self.entry(id).map(|e| e.sender.next())
    }

    /// The freshness the next frame of any message is signed with, at the most: what a node
    /// must have reserved in its store before it sends again.
    pub fn next_freshness_max(&self) -> u64 {
        self.entries
            .iter()
            .flatten()
            .map(|e| e.sender.next())
            .max()
            .unwrap_or(0)
    }

    /// The layout of message `id`, if secured.
    pub fn layout(&self, id: Id) -> Option<Layout> {
        self.entry(id).map(|e| e.layout)
    }

    fn entry(&self, id: Id) -> Option<&Entry> {
        self.entries.iter().flatten().find(|e| e.id == id)
    }

    fn position(&self, id: Id) -> Option<usize> {
        self.entries
            .iter()
            .position(|e| e.as_ref().is_some_and(|e| e.id == id))
    }

    /// `frame` as it goes on the wire: a secured message signed with its next freshness value
    /// (an FD frame with bit-rate switching); any other frame as it is. `None`: it could not be
    /// signed (the freshness is exhausted, or the frame is not the declared length), and
    /// nothing may be sent in its place.
    pub fn protect(&mut self, frame: Frame) -> Option<Frame> {
        let Some(index) = frame.id().and_then(|id| self.position(id)) else {
            return Some(frame);
        };
        let signed = self
            .entries
            .get_mut(index)
            .and_then(Option::as_mut)
            .and_then(|e| {
                let payload = frame.data();
                if payload.len() != e.layout.payload_length || frame.is_remote() {
                    return None;
                }
                let mut data = [0u8; bywire_secoc::MAX_PAYLOAD];
                let secured = data.get_mut(..e.layout.secured_length())?;
                secured.get_mut(..payload.len())?.copy_from_slice(payload);
                e.sender.sign(&self.auth, &e.layout, secured).ok()?;
                FdFrame::padded(e.id, secured, true, false)
                    .ok()
                    .map(Frame::Fd)
            });
        if signed.is_none() {
            self.stats.unsigned = self.stats.unsigned.saturating_add(1);
        }
        signed
    }

    /// Verify a frame received on `channel`'s bus.
    pub fn check(&mut self, channel: Channel, frame: &Frame) -> Checked {
        let Some(id) = frame.id() else {
            return Checked::Unsecured;
        };
        if self.sync.is_some_and(|s| s.id == id) {
            self.take_sync(frame);
            return Checked::Sync;
        }
        let Some(index) = self.position(id) else {
            return Checked::Unsecured;
        };
        let auth = &self.auth;
        let Some(entry) = self.entries.get_mut(index).and_then(Option::as_mut) else {
            return Checked::Unsecured;
        };
        let receiver = match channel {
            Channel::A => &mut entry.receivers[0],
            Channel::B => &mut entry.receivers[1],
        };
        // The payload's frame first: a frame counted accepted is always handed on.
        let payload = match frame.is_remote() {
            true => None,
            false => frame
                .data()
                .get(..entry.layout.payload_length)
                .and_then(|payload| payload_frame(id, payload)),
        };
        let outcome = match payload {
            Some(_) => receiver.accept(auth, &entry.layout, frame.data()),
            None => Err(Rejection::Malformed),
        };
        self.stats.frames.record(outcome);
        match (outcome, payload) {
            (Ok(_), Some(payload)) => Checked::Authentic(payload),
            (Ok(_), None) => Checked::Rejected(Rejection::Malformed),
            (Err(rejection), _) => {
                // A sender behind, by however much, gets the value to go on after.
                if matches!(rejection, Rejection::Stale | Rejection::Mac) {
                    self.sync_due = Some(index);
                }
                Checked::Rejected(rejection)
            }
        }
    }

    /// The freshness-sync frame due at `now`, if any: the last value accepted of the message
    /// whose frame was stale or unverified, at most one every [`SYNC_INTERVAL`].
    pub fn sync_frame(&mut self, now: Timestamp) -> Option<Frame> {
        let sync = self.sync?;
        let index = self.sync_due?;
        if self
            .last_sync
            .is_some_and(|t| now.saturating_since(t) < SYNC_INTERVAL)
        {
            return None;
        }
        let entry = self.entries.get(index).and_then(Option::as_ref)?;
        let last = entry
            .receivers
            .iter()
            .map(Receiver::last)
            .max()
            .unwrap_or(0);
        let layout = sync_layout(sync.data_id)?;
        let mut data = [0u8; 16];
        let secured = data.get_mut(..layout.secured_length())?;
        let (head, _) = secured.split_at_mut(SYNC_PAYLOAD);
        let (data_id, value) = head.split_at_mut(2);
        data_id.copy_from_slice(&entry.layout.data_id.to_be_bytes());
        value.copy_from_slice(&last.to_be_bytes());
        self.auth.sign(&layout, last, secured).ok()?;
        let frame = FdFrame::padded(sync.id, secured, true, false).ok()?;
        self.sync_due = None;
        self.last_sync = Some(now);
        self.stats.syncs_sent = self.stats.syncs_sent.saturating_add(1);
        Some(Frame::Fd(frame))
    }

    /// Take a sync frame: the sender of the message it names goes on after its value.
    fn take_sync(&mut self, frame: &Frame) {
        let taken = self.sync.and_then(|sync| {
            let layout = sync_layout(sync.data_id)?;
            let data = frame.data();
            let data_id = u16::from_be_bytes(data.get(..2)?.try_into().ok()?);
            let value = u64::from_be_bytes(data.get(2..SYNC_PAYLOAD)?.try_into().ok()?);
            if frame.is_remote() || !self.auth.verify(&layout, value, data) {
                return None;
            }
            let entry = self
                .entries
                .iter_mut()
                .flatten()
                .find(|e| e.layout.data_id == data_id)?;
            entry.sender.resync(value);
            Some(())
        });
        let slot = match taken {
            Some(()) => &mut self.stats.syncs_taken,
            None => &mut self.stats.syncs_refused,
        };
        *slot = slot.saturating_add(1);
    }
}

#[cfg(feature = "std")]
impl SecuredTable {
    /// Reserve in `store` every value the next poll may sign (call after each poll): a
    /// restart then goes on after them, never back. An error means the store cannot keep them.
    pub fn reserve_in(
        &self,
        store: &mut bywire_secoc::store::FreshnessStore,
    ) -> Result<(), bywire_secoc::store::StoreError> {
        store.before_signing(self.next_freshness_max().saturating_add(RESERVE_MARGIN))
    }
}

fn sync_layout(data_id: u16) -> Option<Layout> {
    Layout::new(data_id, SYNC_PAYLOAD, 64, 0, SYNC_MAC_BITS).ok()
}

/// The message as its own wire reads it: a classic frame up to 8 bytes, FD beyond.
fn payload_frame(id: Id, payload: &[u8]) -> Option<Frame> {
    if payload.len() <= 8 {
        Frame::classic(id, payload).ok()
    } else {
        FdFrame::padded(id, payload, false, false)
            .ok()
            .map(Frame::Fd)
    }
}

/// A wire with some of its messages secured; with no table, the wire as it is.
#[derive(Debug, Clone)]
pub struct Secured<W> {
    inner: W,
    table: Option<SecuredTable>,
    /// Whether a frame that fails verification is refused (only a campaign's proof turns
    /// it off: then its payload is read as if it were authentic).
    verified: bool,
}

impl<W> Secured<W> {
    /// `inner` with the messages of `table` secured.
    pub fn new(inner: W, table: SecuredTable) -> Secured<W> {
        Secured {
            inner,
            table: Some(table),
            verified: true,
        }
    }

    /// `inner` as it is: nothing secured.
    pub fn plain(inner: W) -> Secured<W> {
        Secured {
            inner,
            table: None,
            verified: true,
        }
    }

    /// The table, when secured.
    pub fn table(&self) -> Option<&SecuredTable> {
        self.table.as_ref()
    }

    /// The wire underneath.
    pub fn inner_mut(&mut self) -> &mut W {
        &mut self.inner
    }

    fn protect(&mut self, frame: Option<Frame>) -> Option<Frame> {
        match self.table.as_mut() {
            Some(table) => frame.and_then(|f| table.protect(f)),
            None => frame,
        }
    }

    /// A secured frame's payload, unverified: what a receiver without SecOC would read.
    fn unverified_payload(&self, frame: &Frame) -> Option<Frame> {
        let id = frame.id()?;
        let layout = self.table.as_ref()?.layout(id)?;
        payload_frame(id, frame.data().get(..layout.payload_length)?)
    }

    fn check(&mut self, channel: Channel, frame: &Frame) -> Checked {
        self.table
            .as_mut()
            .map_or(Checked::Unsecured, |t| t.check(channel, frame))
    }
}

impl<W: Counters> Counters for Secured<W> {
    fn command_counter_bits(&self) -> u8 {
        self.inner.command_counter_bits()
    }

    fn state_counter_bits(&self) -> u8 {
        self.inner.state_counter_bits()
    }
}

impl<W: AdsWire> AdsWire for Secured<W> {
    fn wheel_counter_bits(&self) -> u8 {
        self.inner.wheel_counter_bits()
    }

    fn command_frame(&mut self, command: &ControlCommand, counter: u64) -> Option<Frame> {
        let frame = self.inner.command_frame(command, counter);
        self.protect(frame)
    }

    fn emergency_brake_frame(&mut self, deceleration: f64, counter: u64) -> Option<Frame> {
        let frame = self.inner.emergency_brake_frame(deceleration, counter);
        self.protect(frame)
    }

    fn feedback(&mut self, frame: &Frame) -> Feedback {
        // The vehicle's feedback comes on bus 1 (a copy on the other bus is skipped before).
        match self.check(Channel::A, frame) {
            Checked::Unsecured => self.inner.feedback(frame),
            Checked::Authentic(payload) => self.inner.feedback(&payload),
            Checked::Rejected(_) => Feedback::Unauthenticated,
            Checked::Sync => Feedback::Other,
        }
    }

    fn pending_frame(&mut self, now: Timestamp) -> Option<Frame> {
        self.table.as_mut().and_then(|t| t.sync_frame(now))
    }
}

impl<W: VehicleWire> VehicleWire for Secured<W> {
    fn is_command(&self, id: Id) -> bool {
        self.inner.is_command(id)
    }

    fn incoming(&mut self, frame: &Frame) -> Incoming {
        self.incoming_from(Channel::A, frame)
    }

    fn incoming_from(&mut self, channel: Channel, frame: &Frame) -> Incoming {
        match self.check(channel, frame) {
            Checked::Unsecured => self.inner.incoming(frame),
            Checked::Authentic(payload) => self.inner.incoming(&payload),
            Checked::Rejected(_) if !self.verified => match self.unverified_payload(frame) {
                Some(payload) => self.inner.incoming_from(channel, &payload),
                None => Incoming::Other,
            },
            // Known by its identifier alone (its bytes are not to be read): a command is a
            // rejected command, anything else unauthenticated.
            Checked::Rejected(_) => match frame.id() {
                Some(id) if self.inner.is_command(id) => {
                    Incoming::Command(Err(Rejected::Authentication))
                }
                _ => Incoming::Unauthenticated,
            },
            Checked::Sync => Incoming::Other,
        }
    }

    fn state_frame(&mut self, report: &StateReport, counter: u64) -> Option<Frame> {
        let frame = self.inner.state_frame(report, counter);
        self.protect(frame)
    }

    fn wheel_speeds_frame(&mut self, speeds: [f64; 4], counter: u64) -> Option<Frame> {
        let frame = self.inner.wheel_speeds_frame(speeds, counter);
        self.protect(frame)
    }

    fn wheel_angles_frame(&mut self, angles: [f64; 4], counter: u64) -> Option<Frame> {
        let frame = self.inner.wheel_angles_frame(angles, counter);
        self.protect(frame)
    }

    fn degradation_frame(&mut self, report: &DegradationReport, counter: u64) -> Option<Frame> {
        let frame = self.inner.degradation_frame(report, counter);
        self.protect(frame)
    }

    fn pending_frame(&mut self, now: Timestamp) -> Option<Frame> {
        self.table.as_mut().and_then(|t| t.sync_frame(now))
    }

    fn switch_off(&mut self, off: crate::mechanism::Mechanisms) {
        self.verified = !off.contains(crate::mechanism::Mechanism::Secoc);
        self.inner.switch_off(off);
    }
}

/// Any node with its secured messages signed on their way out (a node that only sends them,
/// as a safety controller sends its E-stop frames); with no table, the node as it is.
#[derive(Debug, Clone)]
pub struct Signing<N> {
    /// The node.
    pub node: N,
    table: Option<SecuredTable>,
}

impl<N> Signing<N> {
    /// `node`, signing the messages of `table` (or none).
    pub fn new(node: N, table: Option<SecuredTable>) -> Signing<N> {
        Signing { node, table }
    }
}

impl<N: Node> Node for Signing<N> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        self.node.on_frame(now, port, frame);
    }

    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        self.node.on_sent(now, port, frame)
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let table = &mut self.table;
        self.node.poll(now, &mut |port, frame| {
            let signed = match table.as_mut() {
                Some(t) => t.protect(frame),
                None => Some(frame),
            };
            if let Some(frame) = signed {
                out(port, frame);
            }
        });
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.node.next_deadline()
    }
}

// The table's freshness store and the test's collections need the standard library.
#[cfg(test)]
#[cfg(feature = "std")]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use alloc::vec::Vec;

    fn id(raw: u32) -> Id {
        Id::standard(raw).unwrap()
    }

    fn layout(data_id: u16) -> Layout {
        Layout::new(data_id, 4, 32, 8, 24).unwrap()
    }

    fn table() -> SecuredTable {
        let mut table = SecuredTable::new(&Key::new([9; 16]), 1 << 10);
        table.secure(id(0x100), layout(1), 1).unwrap();
        table
    }

    #[test]
    fn a_table_refuses_a_message_or_data_id_twice_and_a_ninth_message() {
        let mut t = table();
        assert_eq!(
            t.secure(id(0x100), layout(2), 1),
            Err(TableError::Duplicate(id(0x100)))
        );
        assert_eq!(
            t.secure(id(0x101), layout(1), 1),
            Err(TableError::DuplicateDataId(1))
        );
        let sync = SyncMessage {
            id: id(0x7F0),
            data_id: 1,
        };
        assert_eq!(
            t.clone().with_sync(sync).map(|_| ()),
            Err(TableError::DuplicateDataId(1))
        );
        let mut t = t
            .with_sync(SyncMessage {
                id: id(0x7F0),
                data_id: 99,
            })
            .unwrap();
        assert_eq!(
            t.secure(id(0x101), layout(99), 1),
            Err(TableError::DuplicateDataId(99)),
            "the sync's data ID is taken too"
        );
        for n in 2..=8u16 {
            t.secure(id(0x100 + u32::from(n)), layout(n), 1).unwrap();
        }
        assert_eq!(t.secure(id(0x200), layout(50), 1), Err(TableError::Full));
        for (error, says) in [
            (TableError::Full, "at most 8"),
            (TableError::Duplicate(id(0x1AB)), "0x1AB is secured twice"),
            (TableError::DuplicateDataId(7), "data ID 7 is used twice"),
        ] {
            assert!(error.to_string().contains(says), "{error}");
        }
    }

    #[test]
    fn nothing_unauthenticated_is_ever_sent_in_a_secured_messages_place() {
        let mut t = table();
        let other = Frame::classic(id(0x300), &[1, 2]).unwrap();
        assert_eq!(
            t.protect(other),
            Some(other),
            "an unlisted frame passes as it is"
        );
        let signed = t.protect(Frame::classic(id(0x100), &[1, 2, 3, 4]).unwrap());
        assert!(matches!(signed, Some(Frame::Fd(_))), "{signed:?}");
        assert_eq!(t.next_freshness(id(0x100)), Some(2));
        let wrong_length = Frame::classic(id(0x100), &[1, 2, 3]).unwrap();
        let remote = Frame::remote(id(0x100), bywire_core::frame::Dlc::new(4).unwrap());
        assert_eq!(t.protect(wrong_length), None);
        assert_eq!(t.protect(remote), None);
        assert_eq!(t.stats().unsigned, 2);
        assert_eq!(t.next_freshness(id(0x100)), Some(2), "no value used up");
        // The freshness used up: nothing more is signed, and nothing is sent in its place.
        let mut spent = SecuredTable::new(&Key::new([9; 16]), 4);
        spent
            .secure(id(0x100), Layout::new(1, 4, 8, 8, 24).unwrap(), 256)
            .unwrap();
        assert_eq!(
            spent.protect(Frame::classic(id(0x100), &[1, 2, 3, 4]).unwrap()),
            None
        );
        assert_eq!(spent.stats().unsigned, 1);
    }

    #[test]
    fn a_remote_or_short_frame_of_a_secured_message_is_rejected_as_malformed() {
        let mut t = table();
        let remote = Frame::remote(id(0x100), bywire_core::frame::Dlc::new(8).unwrap());
        let short = Frame::classic(id(0x100), &[1, 2]).unwrap();
        for frame in [remote, short] {
            assert_eq!(
                t.check(Channel::A, &frame),
                Checked::Rejected(Rejection::Malformed)
            );
        }
        assert_eq!(t.stats().frames.malformed, 2);
        assert_eq!(
            t.check(Channel::B, &Frame::classic(id(0x5), &[]).unwrap()),
            Checked::Unsecured
        );
    }

    #[test]
    fn a_node_reserves_every_value_its_next_poll_may_sign_before_it_signs() {
        let mut t = table();
        t.secure(id(0x101), layout(2), 500).unwrap();
        assert_eq!(t.next_freshness_max(), 500);
        let path = std::env::temp_dir().join(format!("bywire-reserve-{}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let (mut store, start) = bywire_secoc::store::FreshnessStore::open(&path, 1).unwrap();
        assert_eq!(start, 1);
        t.reserve_in(&mut store).unwrap();
        let reserved = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        let reserved: u64 = reserved.trim().parse().unwrap();
        assert!(reserved > 500 + RESERVE_MARGIN, "{reserved}");
    }

    /// A sender that restarted behind the receiver is told where to go on, by a signed sync
    /// frame at most every `SYNC_INTERVAL`; its next frame is then accepted.
    #[test]
    fn a_restarted_sender_is_synchronised_and_accepted_again() {
        let sync = SyncMessage {
            id: id(0x7F0),
            data_id: 99,
        };
        let mut receiver = table().with_sync(sync).unwrap();
        let frame = || Frame::classic(id(0x100), &[1, 2, 3, 4]).unwrap();
        let mut sender = table().with_sync(sync).unwrap();
        for _ in 0..3 {
            let signed = sender.protect(frame()).unwrap();
            assert!(matches!(
                receiver.check(Channel::A, &signed),
                Checked::Authentic(_)
            ));
        }
        assert_eq!(
            receiver.sync_frame(Timestamp::ZERO),
            None,
            "nothing to answer"
        );
        // Restarted without its freshness: stale, so a sync is due.
        let mut restarted = table().with_sync(sync).unwrap();
        let stale = restarted.protect(frame()).unwrap();
        assert_eq!(
            receiver.check(Channel::A, &stale),
            Checked::Rejected(Rejection::Stale)
        );
        let at = Timestamp::from_millis(1_000);
        let answer = receiver.sync_frame(at).unwrap();
        assert_eq!(answer.id(), Some(sync.id));
        assert_eq!(receiver.stats().syncs_sent, 1);
        assert_eq!(restarted.check(Channel::A, &answer), Checked::Sync);
        assert_eq!(restarted.stats().syncs_taken, 1);
        assert_eq!(
            restarted.next_freshness(id(0x100)),
            Some(4),
            "after the 3 accepted"
        );
        let signed = restarted.protect(frame()).unwrap();
        assert!(matches!(
            receiver.check(Channel::A, &signed),
            Checked::Authentic(_)
        ));
        // Another stale frame: the next sync waits out the interval, then goes.
        assert!(matches!(
            receiver.check(Channel::A, &stale),
            Checked::Rejected(Rejection::Stale)
        ));
        let just_before = at.saturating_add(SYNC_INTERVAL - core::time::Duration::from_nanos(1));
        assert_eq!(receiver.sync_frame(just_before), None);
        assert!(receiver
            .sync_frame(at.saturating_add(SYNC_INTERVAL))
            .is_some());
        // A sync frame not signed with the key is refused.
        let mut other = SecuredTable::new(&Key::new([1; 16]), 1 << 10)
            .with_sync(sync)
            .unwrap();
        other.secure(id(0x100), layout(1), 1).unwrap();
        assert_eq!(other.check(Channel::A, &answer), Checked::Sync);
        assert_eq!(
            (other.stats().syncs_taken, other.stats().syncs_refused),
            (0, 1)
        );
    }

    /// Sends one frame of the secured message (of the given length) and one other, each poll.
    struct Talker(usize);

    impl Node for Talker {
        fn on_frame(&mut self, _: Timestamp, _: Port, _: &Frame) {}
        fn poll(&mut self, _: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
            let data = [7u8; 8];
            out(
                Port::MAIN,
                Frame::classic(id(0x100), &data[..self.0]).unwrap(),
            );
            out(Port::MAIN, Frame::classic(id(0x300), &[1]).unwrap());
        }
        fn next_deadline(&self) -> Option<Timestamp> {
            Some(Timestamp::ZERO)
        }
    }

    fn polled(node: &mut Signing<Talker>) -> Vec<Frame> {
        let mut sent = Vec::new();
        node.poll(Timestamp::ZERO, &mut |_, f| sent.push(f));
        sent
    }

    #[test]
    fn a_signing_node_signs_what_its_node_sends_and_drops_what_it_cannot_sign() {
        let mut signing = Signing::new(Talker(4), Some(table()));
        let sent = polled(&mut signing);
        assert_eq!(sent.len(), 2);
        assert!(matches!(sent[0], Frame::Fd(_)) && sent[0].data().len() >= 8);
        assert_eq!(sent[1], Frame::classic(id(0x300), &[1]).unwrap());
        let mut verifier = table();
        assert!(matches!(
            verifier.check(Channel::A, &sent[0]),
            Checked::Authentic(_)
        ));
        assert_eq!(signing.next_deadline(), Some(Timestamp::ZERO));
        signing.node.0 = 3;
        let sent = polled(&mut signing);
        assert_eq!(
            sent,
            [Frame::classic(id(0x300), &[1]).unwrap()],
            "the unsignable frame is dropped"
        );
        let mut plain = Signing::new(Talker(4), None);
        assert_eq!(
            polled(&mut plain)[0],
            Frame::classic(id(0x100), &[7; 4]).unwrap()
        );
    }
}
