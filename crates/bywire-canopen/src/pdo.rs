//! PDOs: the communication (0x1400/0x1800) and mapping (0x1600/0x1A00) parameters, compiled
//! into fixed tables; transmission types (synchronous every N SYNC, acyclic synchronous,
//! remote-requested, event-driven with inhibit time and event timer); receive deadline
//! monitoring; and the CiA 301 rules for remapping through SDO.

use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::od::{ObjectDictionary, Slot};

/// RPDO communication parameters start here (mapping at +0x200); TPDOs at 0x1800.
pub const RPDO_COMMUNICATION: u16 = 0x1400;
/// TPDO communication parameters.
pub const TPDO_COMMUNICATION: u16 = 0x1800;
/// Objects one PDO can map (CiA 301: 64 single bits).
pub const MAX_MAPPED: usize = 64;
/// COB-ID bit 31: the PDO does not exist / is not valid.
pub const COB_ID_INVALID: u32 = 0x8000_0000;
/// COB-ID bit 30: no remote frames (TPDO).
pub const COB_ID_NO_RTR: u32 = 0x4000_0000;
/// COB-ID bit 29: 29-bit identifier.
pub const COB_ID_EXTENDED: u32 = 0x2000_0000;

/// Which way a PDO goes, seen from the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Received by the device (commands).
    Receive,
    /// Transmitted by the device (feedback).
    Transmit,
}

impl Direction {
    fn communication_base(self) -> u16 {
        match self {
            Direction::Receive => RPDO_COMMUNICATION,
            Direction::Transmit => TPDO_COMMUNICATION,
        }
    }
}

/// Which PDO parameter object an index is, if any: `(direction, number from 1, is mapping)`.
pub fn parameter_object(index: u16) -> Option<(Direction, u16, bool)> {
    match index {
        0x1400..=0x15FF => Some((Direction::Receive, index - 0x1400 + 1, false)),
        0x1600..=0x17FF => Some((Direction::Receive, index - 0x1600 + 1, true)),
        0x1800..=0x19FF => Some((Direction::Transmit, index - 0x1800 + 1, false)),
        0x1A00..=0x1BFF => Some((Direction::Transmit, index - 0x1A00 + 1, true)),
        _ => None,
    }
}

/// One mapped object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Mapped {
    slot: Slot,
    index: u16,
    sub: u8,
    bits: u8,
}

/// One PDO, compiled from its parameters.
#[derive(Debug, Clone)]
pub struct Pdo {
    /// Its number, from 1.
    pub number: u16,
    /// Receive or transmit.
    pub direction: Direction,
    /// The raw COB-ID entry (validity and RTR bits included).
    pub cob_id: u32,
    /// Transmission type.
    pub transmission: u8,
    /// Least time between two transmissions (TPDO).
    pub inhibit: Duration,
    /// TPDO: send at least this often; RPDO: expect one at least this often.
    pub event_timer: Duration,
    /// SYNC counter value to start on (0: any).
    pub sync_start: u8,
    mapped: [Option<Mapped>; MAX_MAPPED],
    /// How many of `mapped` the mapping's count covers (the rest are never looked at).
    mapped_count: usize,
    /// Bytes the mapping fills.
    pub length: usize,
    // Run-time state.
    last_payload: [u8; 8],
    /// Event-driven TPDO: the dictionary's change count when the payload last matched
    /// `last_payload` (unchanged since: no need to sample again).
    sampled: Option<u64>,
    sent_once: bool,
    last_sent: Option<Timestamp>,
    syncs: u8,
    sync_started: bool,
    pending: Option<([u8; 8], usize)>,
    /// RPDO: when the last one arrived (deadline monitoring); TPDO: when the event timer was
    /// last armed.
    last_event: Option<Timestamp>,
    deadline_reported: bool,
    /// Acyclic synchronous / RTR TPDO: the device asked for a transmission.
    requested: bool,
}

impl Pdo {
    fn empty(number: u16, direction: Direction) -> Pdo {
        Pdo {
            number,
            direction,
            cob_id: COB_ID_INVALID,
            transmission: 255,
            inhibit: Duration::ZERO,
            event_timer: Duration::ZERO,
            sync_start: 0,
            mapped: [None; MAX_MAPPED],
            mapped_count: 0,
            length: 0,
            last_payload: [0; 8],
            sampled: None,
            sent_once: false,
            last_sent: None,
            syncs: 0,
            sync_started: false,
            pending: None,
            last_event: None,
            deadline_reported: false,
            requested: false,
        }
    }

    /// Valid (bit 31 clear) and mapping something.
    pub fn is_enabled(&self) -> bool {
        self.cob_id & COB_ID_INVALID == 0
    }

    /// The 11-bit identifier, if it is one.
    pub fn can_id(&self) -> Option<u16> {
        if self.cob_id & COB_ID_EXTENDED != 0 {
            return None;
        }
        u16::try_from(self.cob_id & 0x7FF).ok()
    }

    /// `(index, sub, bits)` of each mapped object.
    pub fn mapping(&self) -> impl Iterator<Item = (u16, u8, u8)> + '_ {
        self.entries().map(|m| (m.index, m.sub, m.bits))
    }

    /// The mapped objects, in order.
    fn entries(&self) -> impl Iterator<Item = &Mapped> + '_ {
        self.mapped
            .get(..self.mapped_count)
            .unwrap_or(&[])
            .iter()
            .flatten()
    }

    /// Whether a mapped object's value changed after the dictionary's change count was
    /// `generation` (an object gone counts as changed).
    fn changed_since(&self, od: &ObjectDictionary, generation: u64) -> bool {
        self.entries()
            .any(|mapped| od.at(mapped.slot).is_none_or(|e| e.changed() > generation))
    }

    /// Fill a payload from the dictionary.
    fn sample(&self, od: &ObjectDictionary) -> ([u8; 8], usize) {
        let mut payload = [0u8; 8];
        let mut bit = 0usize;
        for mapped in self.entries() {
            if let Some(entry) = od.at(mapped.slot) {
                copy_bits(
                    entry.value(),
                    0,
                    &mut payload,
                    bit,
                    usize::from(mapped.bits),
                );
            }
            bit += usize::from(mapped.bits);
        }
        (payload, self.length)
    }

    /// Write a received payload into the dictionary; calls `written` with each object stored.
    fn apply(&self, od: &mut ObjectDictionary, payload: &[u8], written: &mut dyn FnMut(u16, u8)) {
        let mut bit = 0usize;
        for mapped in self.entries() {
            let width = usize::from(mapped.bits);
            let size = od
                .at(mapped.slot)
                .map_or(0, |e| e.value().len().max(width.div_ceil(8)));
            let mut value = [0u8; 8];
            if let Some(value) = value.get_mut(..size.min(8)) {
                copy_bits(payload, bit, value, 0, width);
                if od.set_at(mapped.slot, value).is_ok() {
                    written(mapped.index, mapped.sub);
                }
            }
            bit += width;
        }
    }
}

/// Copy `count` bits from `from` at bit `from_bit` to `to` at bit `to_bit` (little-endian bit
/// order, as CANopen packs PDOs). Bits outside either buffer are skipped.
fn copy_bits(from: &[u8], from_bit: usize, to: &mut [u8], to_bit: usize, count: usize) {
    // Whole bytes at byte boundaries (almost every mapping) go a byte at a time, with the
    // same rules.
    if from_bit.is_multiple_of(8) && to_bit.is_multiple_of(8) && count.is_multiple_of(8) {
        let (source, target) = (from_bit / 8, to_bit / 8);
        for k in 0..count / 8 {
            if let Some(byte) = to.get_mut(target + k) {
                *byte = from.get(source + k).copied().unwrap_or(0);
            }
        }
        return;
    }
    copy_bit_by_bit(from, from_bit, to, to_bit, count);
}

fn copy_bit_by_bit(from: &[u8], from_bit: usize, to: &mut [u8], to_bit: usize, count: usize) {
    for i in 0..count {
        let (source, target) = (from_bit + i, to_bit + i);
        let bit = from
            .get(source / 8)
            .is_some_and(|byte| byte >> (source % 8) & 1 != 0);
        if let Some(byte) = to.get_mut(target / 8) {
            let mask = 1u8 << (target % 8);
            if bit {
                *byte |= mask;
            } else {
                *byte &= !mask;
            }
        }
    }
}

/// Why a mapping entry is refused.
fn check_mapped(
    od: &ObjectDictionary,
    direction: Direction,
    raw: u32,
) -> Result<Option<Mapped>, Abort> {
    if raw == 0 {
        return Ok(None);
    }
    let index = u16::try_from(raw >> 16).unwrap_or(0);
    let sub = u8::try_from((raw >> 8) & 0xFF).unwrap_or(0);
    let bits = u8::try_from(raw & 0xFF).unwrap_or(0);
    let slot = od.locate(index, sub).map_err(|_| Abort::NotMappable)?;
    let entry = od.at(slot).ok_or(Abort::NotMappable)?;
    let usable = match direction {
        Direction::Receive => entry.access.writable(),
        Direction::Transmit => entry.access.readable(),
    };
    if !entry.pdo_mappable || !usable || bits == 0 {
        return Err(Abort::NotMappable);
    }
    let fits = match entry.data_type.size() {
        Some(1) if entry.data_type == crate::od::DataType::Boolean => bits <= 8,
        Some(size) => usize::from(bits) == size * 8,
        None => bits % 8 == 0 && usize::from(bits) <= entry.capacity() * 8,
    };
    if !fits {
        return Err(Abort::LengthMismatch);
    }
    Ok(Some(Mapped {
        slot,
        index,
        sub,
        bits,
    }))
}

/// Every PDO a device has, compiled from its dictionary.
#[derive(Debug, Clone, Default)]
pub struct Pdos {
    pdos: alloc::vec::Vec<Pdo>,
    /// The PDOs a poll has work for (an RPDO's deadline, an event-driven or requested TPDO),
    /// by index, listed again whenever one is compiled (within the capacity it was made
    /// with): a device is polled many times a cycle, and most of its PDOs wait for SYNC.
    timed: alloc::vec::Vec<usize>,
    /// The enabled PDOs with an 11-bit identifier, as (identifier, index) in PDO order: every
    /// frame a device hears is looked for here (a PDO's compiled mapping is a kilobyte or two,
    /// and most frames are for none of them).
    heard: alloc::vec::Vec<(u16, usize)>,
    /// The enabled PDOs, by index: what a SYNC goes through.
    enabled: alloc::vec::Vec<usize>,
}

/// Something a PDO did that the device reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoEvent {
    /// An RPDO shorter than its mapping arrived and was ignored (EMCY 0x8210).
    TooShort {
        /// The RPDO number.
        number: u16,
    },
    /// An RPDO with a deadline (event timer) did not arrive in time (EMCY 0x8250).
    DeadlineMissed {
        /// The RPDO number.
        number: u16,
    },
}

impl Pdos {
    /// Compile every PDO whose parameters the dictionary holds.
    pub fn from_dictionary(od: &ObjectDictionary) -> Pdos {
        let mut pdos = alloc::vec::Vec::new();
        for object in od.objects() {
            if let Some((direction, number, false)) = parameter_object(object.index) {
                let mut pdo = Pdo::empty(number, direction);
                compile(od, &mut pdo);
                pdos.push(pdo);
            }
        }
        let mut pdos = Pdos {
            timed: alloc::vec::Vec::with_capacity(pdos.len()),
            heard: alloc::vec::Vec::with_capacity(pdos.len()),
            enabled: alloc::vec::Vec::with_capacity(pdos.len()),
            pdos,
        };
        pdos.list();
        pdos
    }

    /// List the PDOs again after one was compiled: those a poll, a frame and a SYNC look at.
    fn list(&mut self) {
        self.timed.clear();
        self.heard.clear();
        self.enabled.clear();
        for (index, pdo) in self.pdos.iter().enumerate().filter(|(_, p)| p.is_enabled()) {
            self.enabled.push(index);
            if let Some(id) = pdo.can_id() {
                self.heard.push((id, index));
            }
            let timed = match pdo.direction {
                Direction::Receive => !pdo.event_timer.is_zero(),
                Direction::Transmit => matches!(pdo.transmission, 252..=255),
            };
            if timed {
                self.timed.push(index);
            }
        }
    }

    /// Recompile after a parameter object changed (no allocation).
    pub fn reload(&mut self, od: &ObjectDictionary, index: u16) {
        if let Some((direction, number, _)) = parameter_object(index) {
            if let Some(pdo) = self
                .pdos
                .iter_mut()
                .find(|p| p.direction == direction && p.number == number)
            {
                compile(od, pdo);
            }
            self.list();
        }
    }

    /// Recompile every PDO (NMT reset).
    pub fn reload_all(&mut self, od: &ObjectDictionary) {
        for pdo in &mut self.pdos {
            compile(od, pdo);
        }
        self.list();
    }

    /// Every PDO.
    pub fn iter(&self) -> impl Iterator<Item = &Pdo> {
        self.pdos.iter()
    }

    /// Take in a frame while operational: RPDOs are stored (or held for SYNC); remote requests
    /// for TPDOs are noted. Objects written call `written`.
    pub fn on_frame(
        &mut self,
        now: Timestamp,
        frame: &Frame,
        od: &mut ObjectDictionary,
        written: &mut dyn FnMut(u16, u8),
        events: &mut dyn FnMut(PdoEvent),
    ) {
        let Some(id) = crate::nmt::cob_id(frame) else {
            return;
        };
        for &(heard, index) in &self.heard {
            if heard != id {
                continue;
            }
            let Some(pdo) = self.pdos.get_mut(index) else {
                continue;
            };
            match pdo.direction {
                Direction::Receive if !frame.is_remote() => {
                    let data = frame.data();
                    if data.len() < pdo.length {
                        events(PdoEvent::TooShort { number: pdo.number });
                        continue;
                    }
                    pdo.last_event = Some(now);
                    pdo.deadline_reported = false;
                    if pdo.transmission <= 240 {
                        let mut held = [0u8; 8];
                        let n = data.len().min(8);
                        if let (Some(to), Some(from)) = (held.get_mut(..n), data.get(..n)) {
                            to.copy_from_slice(from);
                        }
                        pdo.pending = Some((held, n));
                    } else {
                        pdo.apply(od, data, written);
                    }
                }
                Direction::Transmit if frame.is_remote() && pdo.cob_id & COB_ID_NO_RTR == 0 => {
                    pdo.requested = true;
                }
                _ => {}
            }
        }
    }

    /// A SYNC arrived (with its counter, if any): synchronous RPDOs are applied and
    /// synchronous TPDOs sampled and sent.
    pub fn on_sync(
        &mut self,
        now: Timestamp,
        counter: Option<u8>,
        od: &mut ObjectDictionary,
        written: &mut dyn FnMut(u16, u8),
        out: &mut dyn FnMut(Frame),
    ) {
        for &index in &self.enabled {
            let Some(pdo) = self.pdos.get_mut(index) else {
                continue;
            };
            match pdo.direction {
                Direction::Receive => {
                    if let Some((payload, n)) = pdo.pending.take() {
                        pdo.apply(od, payload.get(..n).unwrap_or(&[]), written);
                    }
                }
                Direction::Transmit => {
                    if !pdo.sync_started {
                        pdo.sync_started = pdo.sync_start == 0 || counter == Some(pdo.sync_start);
                        if !pdo.sync_started {
                            continue;
                        }
                    }
                    let due = match pdo.transmission {
                        0 => {
                            let (payload, _) = pdo.sample(od);
                            pdo.requested || !pdo.sent_once || payload != pdo.last_payload
                        }
                        1..=240 => {
                            pdo.syncs = pdo.syncs.saturating_add(1);
                            pdo.syncs >= pdo.transmission
                        }
                        252 => {
                            // Sampled at SYNC, sent on request.
                            let (payload, _) = pdo.sample(od);
                            pdo.last_payload = payload;
                            false
                        }
                        _ => false,
                    };
                    if due {
                        pdo.syncs = 0;
                        pdo.requested = false;
                        transmit(pdo, now, od, out);
                    }
                }
            }
        }
    }

    /// Event-driven and remote-requested TPDOs, and RPDO deadlines.
    pub fn poll(
        &mut self,
        now: Timestamp,
        od: &ObjectDictionary,
        out: &mut dyn FnMut(Frame),
        events: &mut dyn FnMut(PdoEvent),
    ) {
        for &index in &self.timed {
            let Some(pdo) = self.pdos.get_mut(index) else {
                continue;
            };
            match pdo.direction {
                Direction::Receive => {
                    if let Some(last) = pdo.last_event {
                        if !pdo.event_timer.is_zero()
                            && !pdo.deadline_reported
                            && now >= last.saturating_add(pdo.event_timer)
                        {
                            pdo.deadline_reported = true;
                            events(PdoEvent::DeadlineMissed { number: pdo.number });
                        }
                    }
                }
                Direction::Transmit => match pdo.transmission {
                    252 if pdo.requested => {
                        pdo.requested = false;
                        let (payload, length) = (pdo.last_payload, pdo.length);
                        send(pdo, now, &payload, length, out);
                    }
                    253 if pdo.requested => {
                        pdo.requested = false;
                        transmit(pdo, now, od, out);
                    }
                    254 | 255 => {
                        let inhibited = pdo
                            .last_sent
                            .is_some_and(|last| now < last.saturating_add(pdo.inhibit));
                        if inhibited {
                            continue;
                        }
                        // What was sampled last is what was last sent (it was sent, or it
                        // matched): only a mapped object changed since can change it.
                        let generation = od.generation();
                        let changed = pdo.sampled != Some(generation)
                            && pdo.sampled.is_none_or(|at| pdo.changed_since(od, at))
                            && pdo.sample(od).0 != pdo.last_payload;
                        pdo.sampled = Some(generation);
                        let timer_due = !pdo.event_timer.is_zero()
                            && pdo
                                .last_event
                                .is_none_or(|armed| now >= armed.saturating_add(pdo.event_timer));
                        if !pdo.sent_once || changed || timer_due || pdo.requested {
                            pdo.requested = false;
                            transmit(pdo, now, od, out);
                        }
                    }
                    _ => {}
                },
            }
        }
    }

    /// Ask for a transmission of an acyclic (type 0) or event-driven TPDO now.
    pub fn request(&mut self, number: u16) {
        if let Some(pdo) = self
            .pdos
            .iter_mut()
            .find(|p| p.direction == Direction::Transmit && p.number == number)
        {
            pdo.requested = true;
        }
    }

    /// Forget run-time state (entering operational again sends every TPDO afresh).
    pub fn restart(&mut self) {
        for pdo in &mut self.pdos {
            pdo.sent_once = false;
            pdo.sampled = None;
            pdo.last_sent = None;
            pdo.last_event = None;
            pdo.pending = None;
            pdo.syncs = 0;
            pdo.sync_started = false;
            pdo.deadline_reported = false;
        }
    }

    /// When an event timer, inhibit time or RPDO deadline next expires.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        self.timed
            .iter()
            .filter_map(|&index| self.pdos.get(index))
            .filter(|p| !p.event_timer.is_zero())
            .filter_map(|p| match p.direction {
                Direction::Receive if !p.deadline_reported => {
                    p.last_event.map(|t| t.saturating_add(p.event_timer))
                }
                Direction::Transmit if p.transmission >= 254 => Some(
                    p.last_event
                        .map_or(Timestamp::ZERO, |t| t.saturating_add(p.event_timer)),
                ),
                _ => None,
            })
            .min()
    }
}

fn transmit(pdo: &mut Pdo, now: Timestamp, od: &ObjectDictionary, out: &mut dyn FnMut(Frame)) {
    let (payload, length) = pdo.sample(od);
    send(pdo, now, &payload, length, out);
}

fn send(
    pdo: &mut Pdo,
    now: Timestamp,
    payload: &[u8; 8],
    length: usize,
    out: &mut dyn FnMut(Frame),
) {
    let Some(id) = pdo.can_id() else { return };
    out(crate::nmt::classic(
        id,
        payload.get(..length).unwrap_or(&[]),
    ));
    pdo.last_payload = *payload;
    pdo.sent_once = true;
    pdo.last_sent = Some(now);
    pdo.last_event = Some(now);
}

fn compile(od: &ObjectDictionary, pdo: &mut Pdo) {
    pdo.sampled = None;
    let base = pdo.direction.communication_base() + (pdo.number - 1);
    let read = |index: u16, sub: u8| od.get_unsigned(index, sub);
    pdo.cob_id = read(base, 1)
        .and_then(|v| u32::try_from(v).ok())
        .unwrap_or(COB_ID_INVALID);
    pdo.transmission = read(base, 2)
        .and_then(|v| u8::try_from(v).ok())
        .unwrap_or(255);
    pdo.inhibit = Duration::from_micros(read(base, 3).unwrap_or(0).saturating_mul(100));
    pdo.event_timer = Duration::from_millis(read(base, 5).unwrap_or(0));
    pdo.sync_start = read(base, 6)
        .and_then(|v| u8::try_from(v).ok())
        .unwrap_or(0);
    pdo.mapped = [None; MAX_MAPPED];
    pdo.length = 0;
    let mapping = base + 0x200;
    let count = read(mapping, 0).unwrap_or(0).min(MAX_MAPPED as u64);
    pdo.mapped_count = usize::try_from(count).unwrap_or(0);
    let mut bits = 0usize;
    for sub in 1..=u8::try_from(count).unwrap_or(0) {
        let raw = read(mapping, sub)
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(0);
        if let Ok(Some(mapped)) = check_mapped(od, pdo.direction, raw) {
            if let Some(slot) = pdo.mapped.get_mut(usize::from(sub - 1)) {
                *slot = Some(mapped);
                bits += usize::from(mapped.bits);
            }
        }
    }
    if bits > 64 {
        // Never accepted through SDO; a dictionary built this way disables the PDO.
        pdo.cob_id |= COB_ID_INVALID;
    }
    pdo.length = bits.div_ceil(8).min(8);
}

/// CiA 301's rules for writing PDO parameters through SDO, judged before the write.
pub fn check_write(od: &ObjectDictionary, index: u16, sub: u8, data: &[u8]) -> Result<(), Abort> {
    let Some((direction, _, is_mapping)) = parameter_object(index) else {
        return Ok(());
    };
    let value = u32::from_le_bytes({
        let mut raw = [0u8; 4];
        let n = data.len().min(4);
        if let (Some(to), Some(from)) = (raw.get_mut(..n), data.get(..n)) {
            to.copy_from_slice(from);
        }
        raw
    });
    let communication = if is_mapping { index - 0x200 } else { index };
    let valid = od
        .get_unsigned(communication, 1)
        .is_some_and(|cob| cob & u64::from(COB_ID_INVALID) == 0);
    if is_mapping {
        let count = od.get_unsigned(index, 0).unwrap_or(0);
        if sub == 0 {
            if valid {
                return Err(Abort::DeviceState);
            }
            if usize::try_from(value).unwrap_or(usize::MAX) > MAX_MAPPED {
                return Err(Abort::PdoTooLong);
            }
            let mut bits = 0usize;
            for entry in 1..=u8::try_from(value).unwrap_or(0) {
                let raw = od
                    .get_unsigned(index, entry)
                    .and_then(|v| u32::try_from(v).ok())
                    .unwrap_or(0);
                match check_mapped(od, direction, raw)? {
                    Some(mapped) => bits += usize::from(mapped.bits),
                    None => return Err(Abort::NotMappable),
                }
            }
            if bits > 64 {
                return Err(Abort::PdoTooLong);
            }
        } else {
            if valid || count != 0 {
                // Mapping entries change only with the PDO invalid and sub 0 at zero.
                return Err(Abort::DeviceState);
            }
            check_mapped(od, direction, value)?;
        }
        return Ok(());
    }
    match sub {
        1 => {
            let current = od
                .get_unsigned(index, 1)
                .and_then(|v| u32::try_from(v).ok())
                .unwrap_or(0);
            let changes_id = (current ^ value) & 0x1FFF_FFFF != 0;
            if valid && value & COB_ID_INVALID == 0 && changes_id {
                return Err(Abort::InvalidValue);
            }
            if value & COB_ID_EXTENDED == 0 && value & 0x1FFF_F800 != 0 {
                return Err(Abort::InvalidValue);
            }
        }
        2 => {
            let allowed = match direction {
                Direction::Receive => value <= 240 || value >= 254,
                Direction::Transmit => value <= 240 || value >= 252,
            };
            if !allowed {
                return Err(Abort::InvalidValue);
            }
        }
        3 if valid && direction == Direction::Transmit => return Err(Abort::DeviceState),
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_bytes_copy_as_bit_by_bit_would() {
        let source: [u8; 6] = [0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC];
        for from_len in 0..=6 {
            for from_byte in 0..4 {
                for to_byte in 0..8 {
                    for bytes in 0..=8 {
                        let (mut fast, mut slow) = ([0xEEu8; 8], [0xEEu8; 8]);
                        let from = &source[..from_len];
                        copy_bits(from, from_byte * 8, &mut fast, to_byte * 8, bytes * 8);
                        copy_bit_by_bit(from, from_byte * 8, &mut slow, to_byte * 8, bytes * 8);
                        assert_eq!(fast, slow, "{from_len} {from_byte} {to_byte} {bytes}");
                    }
                }
            }
        }
    }
    use crate::od::{Access, DataType, Entry, ObjectKind};
    use alloc::vec;
    use alloc::vec::Vec;

    fn dictionary() -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.add_var(
            0x6040,
            Entry::new(0, "Controlword", DataType::U16, Access::ReadWrite).mappable(),
        );
        od.add_var(
            0x6041,
            Entry::new(0, "Statusword", DataType::U16, Access::ReadOnly).mappable(),
        );
        od.add_var(
            0x60FF,
            Entry::new(0, "Target velocity", DataType::I32, Access::ReadWrite).mappable(),
        );
        od.add_var(
            0x1008,
            Entry::new(0, "Name", DataType::VisibleString, Access::Const),
        );
        for (base, cob, mapping) in [
            (0x1400u16, 0x201u32, [0x6040_0010u32, 0x60FF_0020]),
            (0x1800, 0x181, [0x6041_0010, 0]),
        ] {
            od.add_object(
                base,
                "Communication",
                ObjectKind::Record,
                vec![
                    Entry::new(1, "COB-ID", DataType::U32, Access::ReadWrite)
                        .with_int(i64::from(cob)),
                    Entry::new(2, "Transmission type", DataType::U8, Access::ReadWrite)
                        .with_int(255),
                    Entry::new(3, "Inhibit time", DataType::U16, Access::ReadWrite),
                    Entry::new(5, "Event timer", DataType::U16, Access::ReadWrite),
                ],
            );
            let count = mapping.iter().filter(|m| **m != 0).count();
            let mut entries: Vec<Entry> = (1..=8u8)
                .map(|sub| {
                    let raw = mapping.get(usize::from(sub - 1)).copied().unwrap_or(0);
                    Entry::new(sub, "Mapped", DataType::U32, Access::ReadWrite)
                        .with_int(i64::from(raw))
                })
                .collect();
            entries.insert(
                0,
                Entry::new(0, "Count", DataType::U8, Access::ReadWrite)
                    .with_int(i64::try_from(count).unwrap()),
            );
            od.add_object(base + 0x200, "Mapping", ObjectKind::Record, entries);
        }
        od
    }

    #[test]
    fn rpdo_writes_and_tpdo_samples_the_mapped_objects() {
        let mut od = dictionary();
        let mut pdos = Pdos::from_dictionary(&od);
        let frame = crate::nmt::classic(0x201, &[0x0F, 0x00, 0xB0, 0x04, 0x00, 0x00]);
        let mut written = Vec::new();
        pdos.on_frame(
            Timestamp::ZERO,
            &frame,
            &mut od,
            &mut |index, sub| written.push((index, sub)),
            &mut |_| {},
        );
        assert_eq!(od.get_unsigned(0x6040, 0), Some(0x0F));
        assert_eq!(od.get_signed(0x60FF, 0), Some(1200));
        assert_eq!(written.len(), 2);
        od.set(0x6041, 0, &0x0627u16.to_le_bytes()).unwrap();
        let mut sent = Vec::new();
        pdos.poll(Timestamp::ZERO, &od, &mut |f| sent.push(f), &mut |_| {});
        assert_eq!(sent.len(), 1);
        assert_eq!(sent[0].data(), [0x27, 0x06]);
        pdos.poll(
            Timestamp::from_millis(1),
            &od,
            &mut |f| sent.push(f),
            &mut |_| {},
        );
        assert_eq!(sent.len(), 1, "unchanged, no event timer: nothing sent");
        // Other objects changing (the dictionary's count moving) send nothing; the mapped
        // one changing again, after them, does.
        let poll_at = |pdos: &mut Pdos, od: &ObjectDictionary, sent: &mut Vec<Frame>, ms| {
            pdos.poll(
                Timestamp::from_millis(ms),
                od,
                &mut |f| sent.push(f),
                &mut |_| {},
            );
        };
        for (ms, velocity) in [(2u64, 1300i64), (3, 1400)] {
            od.set_int(0x60FF, 0, velocity).unwrap();
            poll_at(&mut pdos, &od, &mut sent, ms);
        }
        assert_eq!(sent.len(), 1, "only unmapped objects changed");
        od.set_int(0x60FF, 0, 1500).unwrap();
        od.set(0x6041, 0, &0x0237u16.to_le_bytes()).unwrap();
        od.set_int(0x60FF, 0, 1600).unwrap();
        poll_at(&mut pdos, &od, &mut sent, 4);
        assert_eq!(sent.len(), 2);
        assert_eq!(sent[1].data(), [0x37, 0x02]);
        // Set back to what was last sent: a change of the object, none of the frame.
        od.set(0x6041, 0, &0x0627u16.to_le_bytes()).unwrap();
        od.set(0x6041, 0, &0x0237u16.to_le_bytes()).unwrap();
        poll_at(&mut pdos, &od, &mut sent, 5);
        assert_eq!(sent.len(), 2);
        let mut events = Vec::new();
        let short = crate::nmt::classic(0x201, &[0x0F]);
        pdos.on_frame(Timestamp::ZERO, &short, &mut od, &mut |_, _| {}, &mut |e| {
            events.push(e)
        });
        assert_eq!(events, [PdoEvent::TooShort { number: 1 }]);
    }

    #[test]
    fn remapping_follows_the_cia_301_procedure() {
        let mut od = dictionary();
        // While valid, the mapping cannot change.
        assert_eq!(check_write(&od, 0x1600, 0, &[0]), Err(Abort::DeviceState));
        od.set(0x1400, 1, &(0x201u32 | COB_ID_INVALID).to_le_bytes())
            .unwrap();
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x6040_0010u32.to_le_bytes()),
            Err(Abort::DeviceState),
            "sub 0 not yet zero"
        );
        od.set(0x1600, 0, &[0]).unwrap();
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x1008_0008u32.to_le_bytes()),
            Err(Abort::NotMappable)
        );
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x6041_0010u32.to_le_bytes()),
            Err(Abort::NotMappable),
            "read-only in an RPDO"
        );
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x6040_0008u32.to_le_bytes()),
            Err(Abort::LengthMismatch)
        );
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x7000_0010u32.to_le_bytes()),
            Err(Abort::NotMappable)
        );
        assert_eq!(
            check_write(&od, 0x1600, 1, &0x60FF_0020u32.to_le_bytes()),
            Ok(())
        );
        for sub in 1..=3 {
            od.set(0x1600, sub, &0x60FF_0020u32.to_le_bytes()).unwrap();
        }
        assert_eq!(check_write(&od, 0x1600, 0, &[3]), Err(Abort::PdoTooLong));
        assert_eq!(check_write(&od, 0x1600, 0, &[2]), Ok(()));
        assert_eq!(
            check_write(&od, 0x1400, 2, &[245]),
            Err(Abort::InvalidValue)
        );
        assert_eq!(
            check_write(&od, 0x1800, 1, &0x0000_0999u32.to_le_bytes()),
            Err(Abort::InvalidValue)
        );
    }

    #[test]
    fn synchronous_and_timed_transmission() {
        let mut od = dictionary();
        od.set(0x1800, 2, &[2]).unwrap();
        let mut pdos = Pdos::from_dictionary(&od);
        let mut sent = Vec::new();
        for _ in 0..4 {
            pdos.on_sync(Timestamp::ZERO, None, &mut od, &mut |_, _| {}, &mut |f| {
                sent.push(f)
            });
        }
        assert_eq!(sent.len(), 2, "every second SYNC");
        od.set(0x1800, 2, &[255]).unwrap();
        od.set(0x1800, 5, &100u16.to_le_bytes()).unwrap();
        od.set(0x1800, 3, &500u16.to_le_bytes()).unwrap();
        // As a device does when its parameter object is written: that PDO alone.
        pdos.reload(&od, 0x1800);
        sent.clear();
        for ms in 0..=250 {
            pdos.poll(
                Timestamp::from_millis(ms),
                &od,
                &mut |f| sent.push(f),
                &mut |_| {},
            );
            if ms == 120 {
                od.set(0x6041, 0, &[1, 0]).unwrap();
            }
        }
        // First at 0, the change waits out the 50 ms inhibit (sent at 120), the timer at 220.
        assert_eq!(sent.len(), 3);
        // RPDO deadline monitoring.
        od.set(0x1400, 5, &50u16.to_le_bytes()).unwrap();
        pdos.reload(&od, 0x1400);
        let frame = crate::nmt::classic(0x201, &[0; 6]);
        pdos.on_frame(
            Timestamp::ZERO,
            &frame,
            &mut od,
            &mut |_, _| {},
            &mut |_| {},
        );
        let mut events = Vec::new();
        pdos.poll(Timestamp::from_millis(49), &od, &mut |_| {}, &mut |e| {
            events.push(e)
        });
        assert!(events.is_empty());
        pdos.poll(Timestamp::from_millis(50), &od, &mut |_| {}, &mut |e| {
            events.push(e)
        });
        assert_eq!(events, [PdoEvent::DeadlineMissed { number: 1 }]);
    }
}
