//! A CANopen device (NMT slave) as a sans-IO node: its dictionary served over SDO, NMT states
//! with boot-up and resets, the heartbeat it produces (0x1017) and those it consumes (0x1016),
//! node guarding when it has no heartbeat, SYNC consumption (and production when 0x1005 says
//! so), EMCY production with the error register and history, and its PDOs. An
//! [`Application`] (a CiA 402 drive, the Roboteq controller, or nothing) runs on top.

use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::node::{Node, Port};
use bywire_core::time::{earliest, Timestamp};

use crate::abort::Abort;
use crate::nmt::{
    classic, cob_id, heartbeat_frame, HeartbeatConsumer, HeartbeatEvent, NmtCommand, NmtState,
};
use crate::od::ObjectDictionary;
use crate::pdo::{self, PdoEvent, Pdos};
use crate::queue::EventQueue;
use crate::sdo::{Objects, SdoServer};

pub use crate::emcy::{emcy_code, error_register, Emergency, RECOVERED_FROM_BUS_OFF};

/// EMCY producer: raises and clears errors, keeps 0x1001 and the 0x1003 history, and queues
/// the messages (respecting the inhibit time 0x1015).
#[derive(Debug, Clone, Default)]
pub struct EmcyProducer {
    active: EventQueue<(u16, u8), 16>,
    outbox: EventQueue<Emergency, 16>,
    last_sent: Option<Timestamp>,
}

impl EmcyProducer {
    /// Raise error `code` with `register` bits and manufacturer data (once while active).
    pub fn raise(&mut self, od: &mut ObjectDictionary, code: u16, register: u8, data: [u8; 5]) {
        if self.is_active(code) {
            return;
        }
        let _ = self.active.push((code, register | error_register::GENERIC));
        let register = self.register();
        let _ = od.set(0x1001, 0, &[register]);
        record_history(od, code);
        let _ = self.outbox.push(Emergency {
            code,
            register,
            data,
        });
    }

    /// Clear error `code`; when none remain an error-reset EMCY is sent.
    pub fn clear(&mut self, od: &mut ObjectDictionary, code: u16) {
        if !self.is_active(code) {
            return;
        }
        let mut kept: EventQueue<(u16, u8), 16> = EventQueue::new();
        while let Some(item) = self.active.pop() {
            if item.0 != code {
                let _ = kept.push(item);
            }
        }
        self.active = kept;
        let register = self.register();
        let _ = od.set(0x1001, 0, &[register]);
        if self.active.is_empty() {
            let _ = self.outbox.push(Emergency {
                code: emcy_code::NO_ERROR,
                register,
                data: [0; 5],
            });
        }
    }

    /// Clear every error.
    pub fn clear_all(&mut self, od: &mut ObjectDictionary) {
        while let Some((code, _)) = self.active.pop() {
            let _ = code;
        }
        let _ = od.set(0x1001, 0, &[0]);
    }

    /// `code` is active.
    pub fn is_active(&self, code: u16) -> bool {
        let mut copy = self.active.clone();
        core::iter::from_fn(|| copy.pop()).any(|(active, _)| active == code)
    }

    /// The error register the active errors make.
    pub fn register(&self) -> u8 {
        let mut copy = self.active.clone();
        core::iter::from_fn(|| copy.pop()).fold(0, |register, (_, bits)| register | bits)
    }

    #[inline]
    fn poll(
        &mut self,
        now: Timestamp,
        cob: Option<u16>,
        inhibit: Duration,
        out: &mut dyn FnMut(Frame),
    ) {
        // Nothing to send is the usual case, inlined into every poll.
        if self.outbox.is_empty()
            || self
                .last_sent
                .is_some_and(|last| now < last.saturating_add(inhibit))
        {
            return;
        }
        if let Some(emergency) = self.outbox.pop() {
            if let Some(cob) = cob {
                out(classic(cob, &emergency.payload()));
            }
            self.last_sent = Some(now);
        }
    }
}

fn clear_history(od: &mut ObjectDictionary) {
    let subs = od.object(0x1003).map_or(0, |o| o.entries().len());
    for sub in 1..u8::try_from(subs).unwrap_or(0) {
        let _ = od.set(0x1003, sub, &[0; 4]);
    }
}

fn record_history(od: &mut ObjectDictionary, code: u16) {
    let Some(object) = od.object(0x1003) else {
        return;
    };
    let capacity = u8::try_from(object.entries().len().saturating_sub(1)).unwrap_or(0);
    if capacity == 0 {
        return;
    }
    // Newest first: shift the list down one.
    for sub in (2..=capacity).rev() {
        let older = od
            .get_unsigned(0x1003, sub - 1)
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(0);
        let _ = od.set(0x1003, sub, &older.to_le_bytes());
    }
    let _ = od.set(0x1003, 1, &u32::from(code).to_le_bytes());
    let count = od
        .get_unsigned(0x1003, 0)
        .unwrap_or(0)
        .saturating_add(1)
        .min(u64::from(capacity));
    let _ = od.set(0x1003, 0, &[u8::try_from(count).unwrap_or(capacity)]);
}

/// What a device reports to whoever runs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceEvent {
    /// The NMT state changed.
    Nmt(NmtState),
    /// A consumed heartbeat event (0x1016).
    Heartbeat(HeartbeatEvent),
    /// A PDO event.
    Pdo(PdoEvent),
    /// An object was written from outside (SDO or RPDO).
    Written {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// The master's guarding stopped (life guarding).
    LifeGuardLost,
}

/// The application a device runs: it sees the dictionary, the writes, and time.
pub trait Application {
    /// Judge an SDO write before it is made (CiA 301 checks have passed already).
    fn check_write(
        &self,
        _od: &ObjectDictionary,
        _index: u16,
        _sub: u8,
        _data: &[u8],
    ) -> Result<(), Abort> {
        Ok(())
    }
    /// An object was written from outside (SDO or RPDO).
    fn on_written(&mut self, _now: Timestamp, _od: &mut ObjectDictionary, _index: u16, _sub: u8) {}
    /// The device entered an NMT state.
    fn on_nmt(
        &mut self,
        _now: Timestamp,
        _state: NmtState,
        _od: &mut ObjectDictionary,
        _emcy: &mut EmcyProducer,
    ) {
    }
    /// Communication with a watched node (0x1016) or the master's guarding was lost.
    fn on_communication_lost(
        &mut self,
        _now: Timestamp,
        _od: &mut ObjectDictionary,
        _emcy: &mut EmcyProducer,
    ) {
    }
    /// Run (motor models, state machines); called on every poll before TPDOs are sampled.
    fn step(&mut self, _now: Timestamp, _od: &mut ObjectDictionary, _emcy: &mut EmcyProducer) {}
    /// When `step` next has work of its own.
    fn next_deadline(&self) -> Option<Timestamp> {
        None
    }
    /// NMT reset node: back to the state at power-on.
    fn reset(&mut self, _od: &mut ObjectDictionary) {}
}

/// A device with no application: the dictionary is all there is.
#[derive(Debug, Clone, Copy, Default)]
pub struct Plain;

impl Application for Plain {}

/// Written objects waiting for the device to react (bounded; SDO writes one at a time and an
/// RPDO maps at most 64).
type Written = EventQueue<(u16, u8), 72>;

/// The communication objects the device acts on (0x1005, 0x1006, 0x100C, 0x100D, 0x1014,
/// 0x1015, 0x1017, 0x1019), read once and again after a write or reset, so polls do not
/// search the dictionary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Communication {
    heartbeat: Duration,
    life_time: Duration,
    sync_cob: u64,
    sync_period: Duration,
    sync_overflow: u64,
    emcy_cob: Option<u16>,
    emcy_inhibit: Duration,
}

impl Communication {
    fn read(od: &ObjectDictionary, node: u8) -> Communication {
        let get = |index: u16| od.get_unsigned(index, 0);
        Communication {
            heartbeat: Duration::from_millis(get(0x1017).unwrap_or(0)),
            life_time: Duration::from_millis(
                get(0x100C)
                    .unwrap_or(0)
                    .saturating_mul(get(0x100D).unwrap_or(0)),
            ),
            sync_cob: get(0x1005).unwrap_or(0x80),
            sync_period: Duration::from_micros(get(0x1006).unwrap_or(0)),
            sync_overflow: get(0x1019).unwrap_or(0),
            emcy_cob: get(0x1014).map_or(Some(0x80 + u16::from(node)), |cob| {
                (cob & 0x8000_0000 == 0).then(|| u16::try_from(cob & 0x7FF).unwrap_or(0))
            }),
            emcy_inhibit: Duration::from_micros(get(0x1015).unwrap_or(0).saturating_mul(100)),
        }
    }
}

/// A CANopen device.
#[derive(Debug, Clone)]
pub struct Device<A: Application> {
    comm: Communication,
    /// The dictionary was handed out for local changes: read `comm` again.
    comm_stale: bool,
    node: u8,
    od: ObjectDictionary,
    app: A,
    state: NmtState,
    booted: bool,
    autostart: bool,
    sdo: SdoServer,
    pdos: Pdos,
    emcy: EmcyProducer,
    consumer: HeartbeatConsumer,
    next_heartbeat: Option<Timestamp>,
    guard_toggle: bool,
    last_guard: Option<Timestamp>,
    life_guard_lost: bool,
    next_sync: Option<Timestamp>,
    sync_counter: u8,
    written: Written,
    outbox: EventQueue<Frame, 32>,
    events: EventQueue<DeviceEvent, 64>,
}

/// The SDO server's view of a device.
struct Served<'a, A: Application> {
    od: &'a mut ObjectDictionary,
    app: &'a A,
    written: &'a mut Written,
}

impl<A: Application> Objects for Served<'_, A> {
    fn upload(&mut self, index: u16, sub: u8, into: &mut alloc::vec::Vec<u8>) -> Result<(), Abort> {
        let value = self.od.read(index, sub)?;
        if value.len() > into.capacity() {
            return Err(Abort::OutOfMemory);
        }
        into.clear();
        into.extend_from_slice(value);
        Ok(())
    }

    fn check_download(&self, index: u16, sub: u8, size: Option<usize>) -> Result<(), Abort> {
        let entry = self.od.entry(index, sub)?;
        if !entry.access.writable() {
            return Err(Abort::WriteReadOnly);
        }
        match (size, entry.data_type.size()) {
            (Some(size), Some(fixed)) if size > fixed => Err(Abort::LengthTooHigh),
            (Some(size), Some(fixed)) if size < fixed => Err(Abort::LengthTooLow),
            (Some(size), None) if size > entry.capacity() => Err(Abort::LengthTooHigh),
            _ => Ok(()),
        }
    }

    fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), Abort> {
        self.od.check_write(index, sub, data)?;
        pdo::check_write(self.od, index, sub, data)?;
        check_communication_write(self.od, index, sub, data)?;
        self.app.check_write(self.od, index, sub, data)?;
        self.od.set(index, sub, data)?;
        let _ = self.written.push((index, sub));
        Ok(())
    }
}

/// CiA 301 rules for the other communication objects.
fn check_communication_write(
    od: &ObjectDictionary,
    index: u16,
    sub: u8,
    data: &[u8],
) -> Result<(), Abort> {
    if index == 0x1003 && sub == 0 && data != [0] {
        // Only zero may be written: it clears the error history.
        return Err(Abort::InvalidValue);
    }
    if index == 0x1016 && sub > 0 {
        // Two consumer entries may not watch the same node.
        let entry = u32::from_le_bytes(data.try_into().map_err(|_| Abort::LengthMismatch)?);
        let node = (entry >> 16) & 0xFF;
        let count = od.get_unsigned(0x1016, 0).unwrap_or(0);
        for other in 1..=u8::try_from(count).unwrap_or(0) {
            let existing = od.get_unsigned(0x1016, other).unwrap_or(0);
            if other != sub
                && node != 0
                && entry & 0xFFFF != 0
                && (existing >> 16) & 0xFF == u64::from(node)
                && existing & 0xFFFF != 0
            {
                return Err(Abort::Incompatible);
            }
        }
    }
    Ok(())
}

impl<A: Application> Device<A> {
    /// A device for `node` (1..=127) with its dictionary and application. It boots on the
    /// first poll.
    pub fn new(node: u8, od: ObjectDictionary, app: A) -> Device<A> {
        let buffer = od
            .objects()
            .iter()
            .flat_map(|o| o.entries().iter())
            .map(crate::od::Entry::capacity)
            .max()
            .unwrap_or(0)
            .max(889);
        let pdos = Pdos::from_dictionary(&od);
        let mut device = Device {
            comm: Communication::read(&od, node & 0x7F),
            comm_stale: false,
            node: node & 0x7F,
            od,
            app,
            state: NmtState::BootUp,
            booted: false,
            autostart: false,
            sdo: SdoServer::new(node, buffer),
            pdos,
            emcy: EmcyProducer::default(),
            consumer: HeartbeatConsumer::default(),
            next_heartbeat: None,
            guard_toggle: false,
            last_guard: None,
            life_guard_lost: false,
            next_sync: None,
            sync_counter: 0,
            written: EventQueue::new(),
            outbox: EventQueue::new(),
            events: EventQueue::new(),
        };
        device.load_consumers();
        device
    }

    /// Enter operational by itself after boot-up (what Roboteq calls autostart).
    pub fn with_autostart(mut self) -> Device<A> {
        self.autostart = true;
        self
    }

    /// Its node ID.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// Its NMT state.
    pub fn state(&self) -> NmtState {
        self.state
    }

    /// Its dictionary.
    pub fn od(&self) -> &ObjectDictionary {
        &self.od
    }

    /// Its dictionary, to change values locally (communication objects take effect at the
    /// next poll).
    pub fn od_mut(&mut self) -> &mut ObjectDictionary {
        self.comm_stale = true;
        &mut self.od
    }

    /// The application.
    pub fn app(&self) -> &A {
        &self.app
    }

    /// The application and the dictionary and EMCY producer it works on.
    pub fn app_mut(&mut self) -> (&mut A, &mut ObjectDictionary, &mut EmcyProducer) {
        (&mut self.app, &mut self.od, &mut self.emcy)
    }

    /// The SDO server (statistics).
    pub fn sdo(&self) -> &SdoServer {
        &self.sdo
    }

    /// Its PDOs.
    pub fn pdos(&self) -> &Pdos {
        &self.pdos
    }

    /// The next event.
    pub fn next_event(&mut self) -> Option<DeviceEvent> {
        self.events.pop()
    }

    fn load_consumers(&mut self) {
        self.consumer.clear();
        let count = self.od.get_unsigned(0x1016, 0).unwrap_or(0);
        for sub in 1..=u8::try_from(count).unwrap_or(0) {
            let entry = self.od.get_unsigned(0x1016, sub).unwrap_or(0);
            let node = u8::try_from((entry >> 16) & 0x7F).unwrap_or(0);
            let millis = entry & 0xFFFF;
            if node != 0 && millis != 0 {
                let _ = self.consumer.watch(node, Duration::from_millis(millis));
            }
        }
    }

    fn heartbeat_period(&self) -> Duration {
        self.comm.heartbeat
    }

    fn enter(&mut self, now: Timestamp, state: NmtState) {
        if state == self.state {
            return;
        }
        if state == NmtState::Operational {
            self.pdos.restart();
        }
        if state == NmtState::Stopped {
            self.sdo.reset();
        }
        // A heartbeat at once tells the master the new state (as CANopenNode does), rather
        // than up to a period later; the boot-up message already did after a reset.
        if self.state != NmtState::BootUp {
            self.next_heartbeat = Some(now);
        }
        self.state = state;
        let _ = self.events.push(DeviceEvent::Nmt(state));
        self.app.on_nmt(now, state, &mut self.od, &mut self.emcy);
    }

    fn boot(&mut self, now: Timestamp) {
        self.booted = true;
        self.state = NmtState::BootUp;
        let _ = self
            .outbox
            .push(heartbeat_frame(self.node, NmtState::BootUp));
        self.next_heartbeat = Some(now.saturating_add(self.heartbeat_period()));
        self.next_sync = None;
        self.enter(now, NmtState::PreOperational);
        if self.autostart {
            self.enter(now, NmtState::Operational);
        }
    }

    fn reset(&mut self, now: Timestamp, command: NmtCommand) {
        if command == NmtCommand::ResetNode {
            self.od.restore_defaults(0x2000..=0xFFFF);
            self.app.reset(&mut self.od);
        }
        self.od.restore_defaults(0x1000..=0x1FFF);
        self.comm = Communication::read(&self.od, self.node);
        self.emcy.clear_all(&mut self.od);
        self.sdo.reset();
        self.pdos.reload_all(&self.od);
        self.load_consumers();
        self.life_guard_lost = false;
        self.last_guard = None;
        self.boot(now);
    }

    /// Take in a frame. An error frame saying the controller restarted after bus-off (the
    /// device's own controller, on SocketCAN or a simulated bus) is the event CiA 301 reports
    /// as EMCY 0x8140, followed by the error reset.
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
        if !self.booted {
            return;
        }
        if let Frame::Error(error) = frame {
            if error.has(bywire_core::frame::ErrorClass::Restarted) {
                self.emcy.raise(
                    &mut self.od,
                    RECOVERED_FROM_BUS_OFF,
                    error_register::COMMUNICATION,
                    [0; 5],
                );
                self.emcy.clear(&mut self.od, RECOVERED_FROM_BUS_OFF);
            }
            return;
        }
        if let Some((command, node)) = NmtCommand::parse(frame) {
            if node == 0 || node == self.node {
                match command {
                    NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                        self.reset(now, command)
                    }
                    _ => self.enter(now, command.target()),
                }
            }
            return;
        }
        self.consumer.on_frame(now, frame);
        if frame.is_remote() && cob_id(frame) == Some(0x700 + u16::from(self.node)) {
            self.answer_guard(now);
            return;
        }
        if self.state == NmtState::Stopped {
            return;
        }
        if cob_id(frame) == self.sync_id() && !frame.is_remote() {
            let counter = frame.data().first().copied();
            self.on_sync(now, counter);
            return;
        }
        let mut served = Served {
            od: &mut self.od,
            app: &self.app,
            written: &mut self.written,
        };
        self.sdo.on_frame(now, frame, &mut served);
        if self.state == NmtState::Operational {
            let written = &mut self.written;
            let od = &mut self.od;
            let events = &mut self.events;
            self.pdos.on_frame(
                now,
                frame,
                od,
                &mut |index, sub| {
                    let _ = written.push((index, sub));
                },
                &mut |event| {
                    let _ = events.push(DeviceEvent::Pdo(event));
                },
            );
        }
        self.react(now);
    }

    fn answer_guard(&mut self, now: Timestamp) {
        // Guarding is answered only by devices that do not produce heartbeats.
        if !self.heartbeat_period().is_zero() {
            return;
        }
        let byte = self.state.code() | if self.guard_toggle { 0x80 } else { 0 };
        self.guard_toggle = !self.guard_toggle;
        let _ = self
            .outbox
            .push(classic(0x700 + u16::from(self.node), &[byte]));
        self.last_guard = Some(now);
        self.life_guard_lost = false;
    }

    fn life_time(&self) -> Duration {
        self.comm.life_time
    }

    fn sync_id(&self) -> Option<u16> {
        u16::try_from(self.comm.sync_cob & 0x7FF).ok()
    }

    fn on_sync(&mut self, now: Timestamp, counter: Option<u8>) {
        if self.state != NmtState::Operational {
            return;
        }
        let od = &mut self.od;
        let outbox = &mut self.outbox;
        let written = &mut self.written;
        self.pdos.on_sync(
            now,
            counter,
            od,
            &mut |index, sub| {
                let _ = written.push((index, sub));
            },
            &mut |frame| {
                let _ = outbox.push(frame);
            },
        );
        self.react(now);
    }

    /// React to written objects: reload what they configure, tell the application.
    #[inline]
    fn react(&mut self, now: Timestamp) {
        // Nothing written is the usual case, inlined into every poll.
        if !self.written.is_empty() {
            self.react_to_written(now);
        }
    }

    fn react_to_written(&mut self, now: Timestamp) {
        while let Some((index, sub)) = self.written.pop() {
            if (0x1000..=0x1FFF).contains(&index) {
                self.comm = Communication::read(&self.od, self.node);
            }
            match index {
                0x1003 => clear_history(&mut self.od),
                0x1016 => self.load_consumers(),
                0x1017 => self.next_heartbeat = Some(now),
                0x1400..=0x1BFF => self.pdos.reload(&self.od, index),
                0x1005 | 0x1006 => self.next_sync = None,
                _ => {}
            }
            let _ = self.events.push(DeviceEvent::Written { index, sub });
            self.app.on_written(now, &mut self.od, index, sub);
        }
    }

    /// Boot when first polled; run the application; send heartbeats, SYNC, EMCY and TPDOs.
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if self.comm_stale {
            self.comm = Communication::read(&self.od, self.node);
            self.comm_stale = false;
        }
        if !self.booted {
            self.boot(now);
        }
        self.consumer.poll(now);
        while let Some(event) = self.consumer.next_event() {
            match event {
                HeartbeatEvent::Lost { .. } => {
                    self.emcy.raise(
                        &mut self.od,
                        emcy_code::HEARTBEAT,
                        error_register::COMMUNICATION,
                        [0; 5],
                    );
                    self.app
                        .on_communication_lost(now, &mut self.od, &mut self.emcy);
                }
                HeartbeatEvent::Recovered { .. } => {
                    self.emcy.clear(&mut self.od, emcy_code::HEARTBEAT)
                }
                HeartbeatEvent::BootUp { .. } | HeartbeatEvent::StateChanged { .. } => {}
            }
            let _ = self.events.push(DeviceEvent::Heartbeat(event));
        }
        let life = self.life_time();
        if let Some(last) = self.last_guard {
            if !life.is_zero() && !self.life_guard_lost && now >= last.saturating_add(life) {
                self.life_guard_lost = true;
                self.emcy.raise(
                    &mut self.od,
                    emcy_code::HEARTBEAT,
                    error_register::COMMUNICATION,
                    [0; 5],
                );
                self.app
                    .on_communication_lost(now, &mut self.od, &mut self.emcy);
                let _ = self.events.push(DeviceEvent::LifeGuardLost);
            }
        }
        self.app.step(now, &mut self.od, &mut self.emcy);
        self.react(now);
        let period = self.heartbeat_period();
        if !period.is_zero() && self.next_heartbeat.is_none_or(|due| now >= due) {
            let _ = self.outbox.push(heartbeat_frame(self.node, self.state));
            self.next_heartbeat = Some(now.saturating_add(period));
        }
        self.produce_sync(now);
        while let Some(frame) = self.outbox.pop() {
            out(frame);
        }
        self.sdo.poll(now, out);
        // Emergencies go out before the PDOs that show their effect.
        self.poll_emcy(now, out);
        // PDO deadlines are communication errors too: reacted to as they are reported (once
        // each), whether or not the event queue has room for them.
        let mut missed = false;
        if self.state == NmtState::Operational {
            let events = &mut self.events;
            self.pdos.poll(now, &self.od, out, &mut |event| {
                missed |= matches!(event, PdoEvent::DeadlineMissed { .. });
                let _ = events.push(DeviceEvent::Pdo(event));
            });
        }
        if missed {
            self.emcy.raise(
                &mut self.od,
                emcy_code::RPDO_TIMEOUT,
                error_register::COMMUNICATION,
                [0; 5],
            );
            self.app
                .on_communication_lost(now, &mut self.od, &mut self.emcy);
            // ... and this one in the poll that found it.
            self.poll_emcy(now, out);
        }
    }

    fn poll_emcy(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if self.state != NmtState::Stopped {
            self.emcy
                .poll(now, self.comm.emcy_cob, self.comm.emcy_inhibit, out);
        }
    }

    fn produce_sync(&mut self, now: Timestamp) {
        let (cob, period) = (self.comm.sync_cob, self.comm.sync_period);
        if cob & 0x4000_0000 == 0 || period.is_zero() || self.state == NmtState::Stopped {
            return;
        }
        if self.next_sync.is_some_and(|due| now < due) {
            return;
        }
        let overflow = self.comm.sync_overflow;
        let id = u16::try_from(cob & 0x7FF).unwrap_or(0x80);
        let frame = if overflow >= 2 {
            self.sync_counter = if self.sync_counter >= u8::try_from(overflow).unwrap_or(240) {
                1
            } else {
                self.sync_counter + 1
            };
            classic(id, &[self.sync_counter])
        } else {
            classic(id, &[])
        };
        let _ = self.outbox.push(frame);
        self.next_sync = Some(now.saturating_add(period));
        let counter = (overflow >= 2).then_some(self.sync_counter);
        self.on_sync(now, counter);
    }

    /// When [`Device::step`] next has work.
    fn deadline(&self) -> Option<Timestamp> {
        if !self.booted || !self.outbox.is_empty() {
            return Some(Timestamp::ZERO);
        }
        let heartbeat = (!self.heartbeat_period().is_zero())
            .then_some(self.next_heartbeat)
            .flatten();
        let life = self
            .last_guard
            .filter(|_| !self.life_guard_lost && !self.life_time().is_zero())
            .map(|last| last.saturating_add(self.life_time()));
        earliest([
            heartbeat,
            life,
            self.sdo.next_deadline(),
            self.consumer.next_deadline(),
            self.app.next_deadline(),
            (self.state == NmtState::Operational)
                .then(|| self.pdos.next_deadline())
                .flatten(),
            self.next_sync,
        ])
    }
}

/// A device has one bus connection: frames from any port go in, its frames go out on the main
/// port.
impl<A: Application> Node for Device<A> {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.receive(now, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, &mut |frame| out(Port::MAIN, frame));
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cia402::drive_dictionary;
    use alloc::vec::Vec;

    fn polled(device: &mut Device<Plain>, ms: u64) -> Vec<Frame> {
        let mut out = Vec::new();
        device.poll(Timestamp::from_millis(ms), &mut |_, f| out.push(f));
        out
    }

    fn ids(frames: &[Frame]) -> Vec<u16> {
        frames.iter().filter_map(cob_id).collect()
    }

    #[test]
    fn a_missed_rpdo_deadline_raises_its_emergency_once() {
        let mut device = Device::new(4, drive_dictionary(4), Plain);
        polled(&mut device, 0);
        // RPDO1's event timer to 100 ms over SDO (expedited download of 0x1400:05), then start.
        let sdo = |data: [u8; 8]| crate::nmt::classic(0x604, &data);
        device.on_frame(
            Timestamp::from_millis(1),
            Port::MAIN,
            &sdo([0x2B, 0x00, 0x14, 0x05, 100, 0, 0, 0]),
        );
        assert_eq!(device.od().get_unsigned(0x1400, 5), Some(100));
        device.on_frame(
            Timestamp::from_millis(2),
            Port::MAIN,
            &NmtCommand::Start.frame(4),
        );
        polled(&mut device, 3);
        let rpdo = crate::nmt::classic(0x204, &[0x06, 0x00, 0x03]);
        device.on_frame(Timestamp::from_millis(10), Port::MAIN, &rpdo);
        let mut emergencies = Vec::new();
        for ms in 11..400 {
            let frames = polled(&mut device, ms);
            for f in frames.iter().filter(|f| cob_id(f) == Some(0x84)) {
                emergencies.push((ms, f.data().to_vec()));
            }
        }
        assert_eq!(
            emergencies,
            [(110, alloc::vec![0x50, 0x82, 0x11, 0, 0, 0, 0, 0])],
            "one RPDO-timeout EMCY at 10 + 100 ms"
        );
    }

    #[test]
    fn boots_into_pre_operational_and_resets_restore_defaults() {
        let mut device = Device::new(4, drive_dictionary(4), Plain);
        let first = polled(&mut device, 0);
        assert_eq!(
            first.first().map(|f| (cob_id(f), f.data().to_vec())),
            Some((Some(0x704), alloc::vec![0x00])),
            "boot-up first"
        );
        assert_eq!(device.state(), NmtState::PreOperational);
        device
            .od_mut()
            .set(0x1017, 0, &500u16.to_le_bytes())
            .unwrap();
        device.od_mut().set(0x6081, 0, &9u32.to_le_bytes()).unwrap();
        device.on_frame(
            Timestamp::from_millis(1),
            Port::MAIN,
            &NmtCommand::ResetCommunication.frame(4),
        );
        assert_eq!(
            device.od().get_unsigned(0x1017, 0),
            Some(100),
            "communication objects back to default"
        );
        assert_eq!(
            device.od().get_unsigned(0x6081, 0),
            Some(9),
            "application objects kept"
        );
        device.on_frame(
            Timestamp::from_millis(2),
            Port::MAIN,
            &NmtCommand::ResetNode.frame(0),
        );
        assert_eq!(
            device.od().get_unsigned(0x6081, 0),
            Some(2_000),
            "reset node restores them too"
        );
        let boot = polled(&mut device, 3);
        assert!(boot
            .iter()
            .any(|f| cob_id(f) == Some(0x704) && f.data() == [0x00]));
        // Stopped: SDO is not answered.
        device.on_frame(
            Timestamp::from_millis(4),
            Port::MAIN,
            &NmtCommand::Stop.frame(4),
        );
        device.on_frame(
            Timestamp::from_millis(4),
            Port::MAIN,
            &classic(0x604, &[0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
        );
        assert!(!ids(&polled(&mut device, 4)).contains(&0x584));
    }

    #[test]
    fn node_guarding_is_answered_with_a_toggle_and_its_loss_raises_an_emcy() {
        let mut device = Device::new(4, drive_dictionary(4), Plain);
        device.od_mut().set(0x1017, 0, &[0, 0]).unwrap();
        device
            .od_mut()
            .set(0x100C, 0, &100u16.to_le_bytes())
            .unwrap();
        device.od_mut().set(0x100D, 0, &[3]).unwrap();
        polled(&mut device, 0);
        let guard = Frame::remote(
            bywire_core::frame::Id::standard(0x704).unwrap(),
            bywire_core::frame::Dlc::from_nibble(1),
        );
        let mut answers = Vec::new();
        for ms in [10, 110] {
            device.on_frame(Timestamp::from_millis(ms), Port::MAIN, &guard);
            answers.extend(
                polled(&mut device, ms)
                    .into_iter()
                    .filter(|f| cob_id(f) == Some(0x704))
                    .map(|f| f.data()[0]),
            );
        }
        assert_eq!(answers, [0x7F, 0xFF], "pre-operational, toggle alternating");
        assert!(polled(&mut device, 409)
            .iter()
            .all(|f| cob_id(f) != Some(0x84)));
        let emcy: Vec<Frame> = polled(&mut device, 410)
            .into_iter()
            .filter(|f| cob_id(f) == Some(0x84))
            .collect();
        assert_eq!(
            emcy.first().map(|f| f.data()[..3].to_vec()),
            Some(alloc::vec![0x30, 0x81, 0x11]),
            "EMCY 0x8130, register generic + communication"
        );
        assert_eq!(
            device.od().get_unsigned(0x1003, 1),
            Some(0x8130),
            "in the error history"
        );
        assert_eq!(device.od().get_unsigned(0x1003, 0), Some(1));
        assert!(
            core::iter::from_fn(|| device.next_event()).any(|e| e == DeviceEvent::LifeGuardLost)
        );
        // The history is cleared by writing zero, and only zero.
        device.on_frame(
            Timestamp::from_millis(411),
            Port::MAIN,
            &classic(0x604, &[0x2F, 0x03, 0x10, 0, 1, 0, 0, 0]),
        );
        device.on_frame(
            Timestamp::from_millis(411),
            Port::MAIN,
            &classic(0x604, &[0x2F, 0x03, 0x10, 0, 0, 0, 0, 0]),
        );
        let answers: Vec<Vec<u8>> = polled(&mut device, 411)
            .into_iter()
            .filter(|f| cob_id(f) == Some(0x584))
            .map(|f| f.data().to_vec())
            .collect();
        assert_eq!(
            answers,
            [
                alloc::vec![0x80, 0x03, 0x10, 0, 0x30, 0, 0x09, 0x06],
                alloc::vec![0x60, 0x03, 0x10, 0, 0, 0, 0, 0]
            ]
        );
        assert_eq!(device.od().get_unsigned(0x1003, 1), Some(0));
    }

    #[test]
    fn sync_is_produced_with_its_counter_when_0x1005_says_so() {
        let mut device = Device::new(4, drive_dictionary(4), Plain);
        device.od_mut().add_var(
            0x1019,
            crate::od::Entry::new(
                0,
                "Synchronous counter overflow value",
                crate::od::DataType::U8,
                crate::od::Access::ReadWrite,
            )
            .with_int(3),
        );
        device
            .od_mut()
            .set(0x1005, 0, &0x4000_0080u32.to_le_bytes())
            .unwrap();
        device
            .od_mut()
            .set(0x1006, 0, &10_000u32.to_le_bytes())
            .unwrap();
        let mut counters = Vec::new();
        for ms in 0..50 {
            counters.extend(
                polled(&mut device, ms)
                    .into_iter()
                    .filter(|f| cob_id(f) == Some(0x80))
                    .map(|f| f.data().to_vec()),
            );
        }
        assert_eq!(counters, [[1], [2], [3], [1], [2]]);
    }
}
