//! The wire model: a frame as the exact sequence of bus levels it occupies.
//!
//! A classic frame is SOF, arbitration (identifier, RTR; SRR/IDE and the identifier extension for
//! 29-bit identifiers), control (IDE/r1, r0, DLC), data, a CRC-15, then CRC delimiter, ACK slot,
//! ACK delimiter and 7 recessive EOF bits. From SOF through the CRC, after five equal bits the
//! transmitter inserts one *stuff bit* of the opposite level, so that receivers can resynchronise.
//!
//! An ISO CAN FD frame (ISO 11898-1:2015) stuffs dynamically only from SOF through the data;
//! then comes a stuff count (the number of dynamic stuff bits modulo 8, Gray-coded, with a
//! parity bit) and a CRC-17 (up to 16 data bytes) or CRC-21, coded with *fixed* stuff bits: one
//! before the stuff count and one after every four bits. The FD CRC covers the dynamic stuff
//! bits and the stuff count, and starts from a register with its top bit set.
//!
//! [`encode`] produces the sequence with every field located ([`WireFrame`]); [`decode`] reads a
//! sequence back as a receiver would, destuffing and checking, and reports the first of the five
//! CAN error kinds it meets ([`ErrorKind`]); [`check_transmission`] compares what a transmitter
//! sent with what it monitored, which is how bit errors and lost arbitration are told apart.
//! [`length_bounds`] bounds the stuffed length of every frame of a format and DLC (exact over
//! identifier and data, with the CRC treated as free).

mod bits;
mod bounds;
mod decode;

pub use bits::{BitSeq, BitSeqError, MAX_FRAME_BITS};
pub use bounds::{length_bounds, unstuffed_length, FrameShape};
pub use decode::{check_transmission, decode, ErrorKind, TransmitOutcome, WireError};

use crate::crc::CrcRegister;
use crate::frame::{Dlc, Frame, Id};

/// A field of a frame on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Field {
    /// Start of frame (dominant).
    Sof,
    /// The 11 base identifier bits.
    BaseId,
    /// Substitute remote request (recessive, 29-bit identifiers).
    Srr,
    /// Identifier extension bit.
    Ide,
    /// The 18 identifier extension bits.
    IdExtension,
    /// Remote transmission request.
    Rtr,
    /// Remote request substitution (FD, dominant).
    Rrs,
    /// FD format indicator (recessive in FD frames).
    Fdf,
    /// Reserved bit r1 (classic 29-bit frames).
    R1,
    /// Reserved bit r0 (classic frames).
    R0,
    /// Reserved bit res (FD frames).
    Res,
    /// Bit rate switch.
    Brs,
    /// Error state indicator.
    Esi,
    /// Data length code.
    Dlc,
    /// Data bytes.
    Data,
    /// FD stuff count with parity (and its leading fixed stuff bit).
    StuffCount,
    /// CRC sequence.
    Crc,
    /// CRC delimiter (recessive).
    CrcDelimiter,
    /// ACK slot (dominant when any receiver acknowledged).
    AckSlot,
    /// ACK delimiter (recessive).
    AckDelimiter,
    /// End of frame (7 recessive).
    Eof,
}

impl Field {
    /// The field's short name, as in timing diagrams.
    pub const fn name(self) -> &'static str {
        match self {
            Field::Sof => "SOF",
            Field::BaseId => "ID",
            Field::Srr => "SRR",
            Field::Ide => "IDE",
            Field::IdExtension => "ID-EXT",
            Field::Rtr => "RTR",
            Field::Rrs => "RRS",
            Field::Fdf => "FDF",
            Field::R1 => "r1",
            Field::R0 => "r0",
            Field::Res => "res",
            Field::Brs => "BRS",
            Field::Esi => "ESI",
            Field::Dlc => "DLC",
            Field::Data => "DATA",
            Field::StuffCount => "SBC",
            Field::Crc => "CRC",
            Field::CrcDelimiter => "CRC-DEL",
            Field::AckSlot => "ACK",
            Field::AckDelimiter => "ACK-DEL",
            Field::Eof => "EOF",
        }
    }

    /// Whether the field belongs to arbitration, where a recessive bit overwritten by a
    /// dominant one means another node won, not an error.
    pub const fn is_arbitration(self) -> bool {
        matches!(
            self,
            Field::BaseId | Field::Srr | Field::Ide | Field::IdExtension | Field::Rtr | Field::Rrs
        )
    }
}

/// Where one field lies in the stuffed sequence (stuff bits inside it included).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Span {
    /// The field.
    pub field: Field,
    /// Index of its first bit.
    pub start: usize,
    /// Number of bits, stuff bits included.
    pub len: usize,
}

/// Why a frame has no bit sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// Error frames are controller reports, not frames sent on the bus.
    #[error("an error frame is a controller report and has no bit sequence of its own")]
    NotOnWire,
}

const MAX_SPANS: usize = 24;

/// A frame's exact bit sequence with its fields, stuff bits and CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WireFrame {
    bits: BitSeq,
    stuff: BitSeq,
    spans: [Span; MAX_SPANS],
    span_count: usize,
    crc: u32,
    crc_width: u8,
    dynamic_stuff_bits: u16,
    fixed_stuff_bits: u8,
    data_phase: Option<(usize, usize)>,
}

impl WireFrame {
    /// The levels from SOF through the last EOF bit (interframe space not included).
    pub fn bits(&self) -> &BitSeq {
        &self.bits
    }

    /// Length in bits, SOF through EOF.
    pub fn len(&self) -> usize {
        self.bits.len()
    }

    /// Never true: every frame has bits.
    pub fn is_empty(&self) -> bool {
        self.bits.is_empty()
    }

    /// All stuff bits, dynamic and fixed.
    pub fn stuff_bits(&self) -> usize {
        usize::from(self.dynamic_stuff_bits) + usize::from(self.fixed_stuff_bits)
    }

    /// Stuff bits inserted after five equal bits.
    pub fn dynamic_stuff_bits(&self) -> usize {
        usize::from(self.dynamic_stuff_bits)
    }

    /// FD fixed stuff bits in the stuff count and CRC (0 for classic frames).
    pub fn fixed_stuff_bits(&self) -> usize {
        usize::from(self.fixed_stuff_bits)
    }

    /// Whether the bit at `index` is a stuff bit.
    pub fn is_stuff_bit(&self, index: usize) -> bool {
        self.stuff.get(index).unwrap_or(false)
    }

    /// The CRC sequence sent.
    pub fn crc(&self) -> u32 {
        self.crc
    }

    /// The CRC's width: 15, 17 or 21.
    pub fn crc_width(&self) -> u8 {
        self.crc_width
    }

    /// The fields in order.
    pub fn spans(&self) -> &[Span] {
        self.spans.get(..self.span_count).unwrap_or(&[])
    }

    /// The field the bit at `index` belongs to.
    pub fn field_at(&self, index: usize) -> Option<Field> {
        self.spans()
            .iter()
            .find(|s| index >= s.start && index < s.start + s.len)
            .map(|s| s.field)
    }

    /// Bits sent at the data bitrate when the frame switches bitrate: from ESI through the CRC
    /// delimiter. The BRS bit and the CRC delimiter each straddle the switch between their
    /// sample points; the two partial bits add up to exactly one nominal and one data bit, so
    /// counting BRS as nominal and the delimiter as data is exact for any sample points.
    pub fn data_phase_bits(&self) -> usize {
        self.data_phase.map_or(0, |(first, last)| last + 1 - first)
    }

    /// Time on the bus in nanoseconds at `nominal` bit/s, with the data phase at `data` bit/s
    /// when the frame has BRS set and a data bitrate is given.
    pub fn time_ns(&self, nominal: u32, data: Option<u32>) -> f64 {
        let ns_per_bit = |rate: u32| 1e9 / f64::from(rate.max(1));
        let (nominal_bits, data_bits) = match data {
            Some(_) => (self.len() - self.data_phase_bits(), self.data_phase_bits()),
            None => (self.len(), 0),
        };
        // Bit counts are below 1000: exact as f64.
        let count = |n: usize| f64::from(u32::try_from(n).unwrap_or(u32::MAX));
        count(nominal_bits) * ns_per_bit(nominal)
            + count(data_bits) * ns_per_bit(data.unwrap_or(nominal))
    }
}

/// One piece of the dynamically stuffed header: `width` bits of `value`, MSB first.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Piece {
    pub field: Field,
    pub value: u32,
    pub width: u8,
    /// Whether the bits vary between frames of the same format and DLC (identifier, BRS, ESI).
    pub free: bool,
}

const fn piece(field: Field, value: u32, width: u8, free: bool) -> Piece {
    Piece {
        field,
        value,
        width,
        free,
    }
}

/// The fields from SOF through DLC, in order, for a frame of the given format.
pub(crate) fn header(
    id: Id,
    remote: bool,
    fd: Option<(bool, bool)>,
    dlc: Dlc,
) -> ([Piece; 11], usize) {
    let mut pieces = [piece(Field::Sof, 0, 1, false); 11];
    let mut n = 0;
    let mut add = |p: Piece| {
        if let Some(slot) = pieces.get_mut(n) {
            *slot = p;
            n += 1;
        }
    };
    add(piece(Field::Sof, 0, 1, false));
    let remote_bit = u32::from(remote);
    match id {
        Id::Standard(s) => {
            add(piece(Field::BaseId, u32::from(s.as_raw()), 11, true));
            match fd {
                None => add(piece(Field::Rtr, remote_bit, 1, false)),
                Some(_) => add(piece(Field::Rrs, 0, 1, false)),
            }
            add(piece(Field::Ide, 0, 1, false));
        }
        Id::Extended(e) => {
            add(piece(Field::BaseId, u32::from(e.base()), 11, true));
            add(piece(Field::Srr, 1, 1, false));
            add(piece(Field::Ide, 1, 1, false));
            add(piece(Field::IdExtension, e.extension(), 18, true));
            match fd {
                None => {
                    add(piece(Field::Rtr, remote_bit, 1, false));
                    add(piece(Field::R1, 0, 1, false));
                }
                Some(_) => add(piece(Field::Rrs, 0, 1, false)),
            }
        }
    }
    match fd {
        None => add(piece(Field::R0, 0, 1, false)),
        Some((brs, esi)) => {
            add(piece(Field::Fdf, 1, 1, false));
            add(piece(Field::Res, 0, 1, false));
            add(piece(Field::Brs, u32::from(brs), 1, true));
            add(piece(Field::Esi, u32::from(esi), 1, true));
        }
    }
    add(piece(Field::Dlc, u32::from(dlc.as_raw()), 4, false));
    (pieces, n)
}

/// The 4 bits after the stuff count's fixed stuff bit: Gray code of the count modulo 8, then
/// even parity over those three bits.
pub(crate) fn stuff_count_code(dynamic_stuff_bits: u16) -> u8 {
    let n = u8::try_from(dynamic_stuff_bits % 8).unwrap_or(0);
    let gray = n ^ (n >> 1);
    let parity = u8::from(gray.count_ones() % 2 == 1);
    (gray << 1) | parity
}

/// Number of CRC bits for an FD frame of `len` data bytes.
pub(crate) fn fd_crc_width(len: usize) -> u8 {
    if len > 16 {
        21
    } else {
        17
    }
}

struct Encoder {
    frame: WireFrame,
    last_level: bool,
    run: u8,
    crc: CrcRegister,
    crc_counts_stuff_bits: bool,
}

impl Encoder {
    fn level(&mut self, bit: bool, stuff: bool) {
        // Pushes cannot exceed MAX_FRAME_BITS: the longest frame is shorter (see bits.rs).
        let _ = self.frame.bits.push(bit);
        let _ = self.frame.stuff.push(stuff);
        if bit == self.last_level && self.run > 0 {
            self.run += 1;
        } else {
            self.run = 1;
        }
        self.last_level = bit;
    }

    fn begin(&mut self, field: Field) {
        let start = self.frame.bits.len();
        if let Some(prev) = self
            .frame
            .span_count
            .checked_sub(1)
            .and_then(|i| self.frame.spans.get_mut(i))
        {
            prev.len = start - prev.start;
        }
        if let Some(slot) = self.frame.spans.get_mut(self.frame.span_count) {
            *slot = Span {
                field,
                start,
                len: 0,
            };
            self.frame.span_count += 1;
        }
    }

    /// Close the last field at the end of the sequence.
    fn finish(&mut self) {
        let end = self.frame.bits.len();
        if let Some(last) = self
            .frame
            .span_count
            .checked_sub(1)
            .and_then(|i| self.frame.spans.get_mut(i))
        {
            last.len = end - last.start;
        }
    }

    /// A bit under dynamic stuffing; `into_crc` when the CRC covers it, `stuff_after` unless it
    /// is the last bit of the stuffed region of an FD frame.
    fn stuffed(&mut self, bit: bool, into_crc: bool, stuff_after: bool) {
        if into_crc {
            self.crc.push_bit(bit);
        }
        self.level(bit, false);
        if self.run == 5 && stuff_after {
            let stuff = !bit;
            if self.crc_counts_stuff_bits {
                self.crc.push_bit(stuff);
            }
            self.level(stuff, true);
            self.frame.dynamic_stuff_bits += 1;
        }
    }

    fn fixed_stuff(&mut self) {
        let stuff = !self.last_level;
        self.level(stuff, true);
        self.frame.fixed_stuff_bits += 1;
    }
}

/// The bit sequence of `frame` as sent and acknowledged (ACK slot dominant).
pub fn encode(frame: &Frame) -> Result<WireFrame, EncodeError> {
    encode_with_ack(frame, true)
}

/// The bit sequence of `frame`; with `acknowledged` false the ACK slot stays recessive, as a
/// transmitter alone on the bus sees it.
pub fn encode_with_ack(frame: &Frame, acknowledged: bool) -> Result<WireFrame, EncodeError> {
    let (id, remote, fd, dlc) = match frame {
        Frame::Classic(c) => (c.id(), c.is_remote(), None, c.dlc()),
        Frame::Fd(f) => (f.id(), false, Some((f.brs(), f.esi())), f.dlc()),
        Frame::Error(_) => return Err(EncodeError::NotOnWire),
    };
    let data = frame.data();
    let crc = match fd {
        None => CrcRegister::crc15(),
        Some(_) if fd_crc_width(data.len()) == 21 => CrcRegister::crc21_iso(),
        Some(_) => CrcRegister::crc17_iso(),
    };
    let mut enc = Encoder {
        frame: WireFrame {
            bits: BitSeq::new(),
            stuff: BitSeq::new(),
            spans: [Span {
                field: Field::Sof,
                start: 0,
                len: 0,
            }; MAX_SPANS],
            span_count: 0,
            crc: 0,
            crc_width: 15,
            dynamic_stuff_bits: 0,
            fixed_stuff_bits: 0,
            data_phase: None,
        },
        last_level: true,
        run: 0,
        crc,
        crc_counts_stuff_bits: fd.is_some(),
    };

    // In FD frames the dynamic stuffing ends with the last bit before the stuff count: no stuff
    // bit follows it (the fixed stuff bit takes its place).
    let (pieces, count) = header(id, remote, fd, dlc);
    let header_bits: usize = pieces
        .iter()
        .take(count)
        .map(|p| usize::from(p.width))
        .sum();
    let stuffed_total = header_bits + 8 * data.len();
    let mut sent = 0usize;
    let mut brs_index = None;
    for p in pieces.iter().take(count) {
        enc.begin(p.field);
        for i in (0..p.width).rev() {
            sent += 1;
            let stuff_after = fd.is_none() || sent < stuffed_total;
            enc.stuffed((p.value >> i) & 1 == 1, true, stuff_after);
        }
        if p.field == Field::Brs {
            brs_index = Some(enc.frame.bits.len() - 1);
        }
    }
    if !data.is_empty() {
        enc.begin(Field::Data);
        for byte in data {
            for i in (0..8).rev() {
                sent += 1;
                let stuff_after = fd.is_none() || sent < stuffed_total;
                enc.stuffed((byte >> i) & 1 == 1, true, stuff_after);
            }
        }
    }

    match fd {
        None => {
            let crc = enc.crc.value();
            enc.frame.crc = crc;
            enc.begin(Field::Crc);
            for i in (0..15).rev() {
                enc.stuffed((crc >> i) & 1 == 1, false, true);
            }
        }
        Some(_) => {
            enc.begin(Field::StuffCount);
            enc.fixed_stuff();
            let code = stuff_count_code(enc.frame.dynamic_stuff_bits);
            for i in (0..4).rev() {
                let bit = (code >> i) & 1 == 1;
                enc.crc.push_bit(bit);
                enc.level(bit, false);
            }
            let width = fd_crc_width(data.len());
            let crc = enc.crc.value();
            enc.frame.crc = crc;
            enc.frame.crc_width = width;
            enc.begin(Field::Crc);
            enc.fixed_stuff();
            for (n, i) in (0..width).rev().enumerate() {
                enc.level((crc >> i) & 1 == 1, false);
                if (n + 1) % 4 == 0 && i > 0 {
                    enc.fixed_stuff();
                }
            }
        }
    }
    enc.begin(Field::CrcDelimiter);
    let crc_delimiter = enc.frame.bits.len();
    enc.level(true, false);
    if let (Some((true, _)), Some(first)) = (fd, brs_index) {
        enc.frame.data_phase = Some((first + 1, crc_delimiter));
    }
    enc.begin(Field::AckSlot);
    enc.level(!acknowledged, false);
    enc.begin(Field::AckDelimiter);
    enc.level(true, false);
    enc.begin(Field::Eof);
    for _ in 0..7 {
        enc.level(true, false);
    }
    enc.finish();
    Ok(enc.frame)
}

/// The length in bits of a classic frame as sent and acknowledged, and where its CRC
/// delimiter is, counted without building the bit sequence: what a bus simulation needs for
/// every frame it times. Agrees with [`encode`] (a property test holds the two together);
/// `None` for FD and error frames.
pub fn classic_length(frame: &Frame) -> Option<(usize, usize)> {
    ClassicHeader::of(frame).map(|header| header.length(frame.data()))
}

/// A classic frame up to its data field (start of frame, arbitration and control fields) as
/// the CRC and bit stuffing leave it: all of a frame's length that its identifier, RTR bit
/// and DLC decide. [`ClassicHeader::length`] finishes the count for a payload, so a bus
/// simulation that keeps the header of each identifier times a new payload without going
/// over the header again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClassicHeader {
    /// The CRC register after the header's bits.
    crc: u32,
    /// The stuffing state after them (see `stuff_step`).
    stuff_state: u8,
    /// Stuff bits among them.
    stuffed: u32,
    /// The header's bits, stuff bits not counted.
    bits: u32,
}

impl ClassicHeader {
    /// The header of a classic frame (`None` for FD and error frames).
    pub fn of(frame: &Frame) -> Option<ClassicHeader> {
        let Frame::Classic(c) = frame else {
            return None;
        };
        // At most 1 + 32 + 3 + 4 = 40 bits, as one number.
        let (pieces, count) = header(c.id(), c.is_remote(), None, c.dlc());
        let (mut stream, mut bits) = (0u128, 0u32);
        for p in pieces.iter().take(count) {
            let value = p.value & ((1u32 << p.width) - 1);
            stream = (stream << p.width) | u128::from(value);
            bits += u32::from(p.width);
        }
        let crc = crc15_of_stream(stream, bits);
        // The first bit (start of frame) starts a run; the rest go through the stuffing.
        let after_first = bits.saturating_sub(1);
        let first = u8::from(stream >> after_first & 1 == 1);
        let (stuff_state, stuffed) = stuff_run(first * 4, 0, stream, after_first);
        Some(ClassicHeader {
            crc,
            stuff_state,
            stuffed,
            bits,
        })
    }

    /// The length in bits of the frame with this header and `data` (at most 8 bytes are
    /// counted) as sent and acknowledged, and where its CRC delimiter is: as
    /// [`classic_length`] of that frame.
    pub fn length(&self, data: &[u8]) -> (usize, usize) {
        let (mut crc, mut state, mut stuffed) = (self.crc, self.stuff_state, self.stuffed);
        let mut bits = self.bits;
        for &byte in data.iter().take(8) {
            crc = crc15_byte(crc, byte);
            (state, stuffed) = stuff_run(state, stuffed, u128::from(byte), 8);
            bits += 8;
        }
        (_, stuffed) = stuff_run(state, stuffed, u128::from(crc & 0x7FFF), 15);
        let sent = usize::try_from(bits + 15 + stuffed).unwrap_or(usize::MAX);
        // CRC delimiter, ACK slot, ACK delimiter, 7 bits of end of frame.
        (sent.saturating_add(10), sent)
    }
}

/// CRC-15/CAN of the low `bits` bits of `stream`, most significant first: the bits short of
/// a whole byte one at a time, then a byte at a time.
fn crc15_of_stream(stream: u128, bits: u32) -> u32 {
    let odd = bits % 8;
    let whole_bytes = (bits - odd) / 8;
    let mut register = CrcRegister::crc15();
    let leading = u64::try_from(stream >> (8 * whole_bytes) & 0xFF).unwrap_or(0);
    register.push_bits(leading, u8::try_from(odd).unwrap_or(0));
    let mut crc = register.value();
    for k in (0..whole_bytes).rev() {
        crc = crc15_byte(crc, u8::try_from(stream >> (8 * k) & 0xFF).unwrap_or(0));
    }
    crc
}

/// CRC-15/CAN over one more byte, a byte at a time.
fn crc15_byte(crc: u32, byte: u8) -> u32 {
    let index = usize::from(u8::try_from(((crc >> 7) ^ u32::from(byte)) & 0xFF).unwrap_or(0));
    ((crc << 8) ^ u32::from(CRC15_TABLE.get(index).copied().unwrap_or(0))) & 0x7FFF
}

/// CRC-15/CAN (polynomial 0x4599) of each byte value. Computed at compile time, where an index
/// out of range or a truncation would fail the build, not a run.
#[allow(clippy::indexing_slicing, clippy::cast_possible_truncation)]
const CRC15_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 7;
        let mut k = 0;
        while k < 8 {
            crc = if crc & 0x4000 != 0 {
                (crc << 1) ^ 0x4599
            } else {
                crc << 1
            } & 0x7FFF;
            k += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// Bit stuffing as a state machine over the bits sent: the level of the last bit on the wire
/// and how many of it in a row (1–4; the fifth makes a stuff bit, the complement, which starts
/// the next run). A state is `level * 4 + run - 1`.
const fn stuff_step(state: u8, bit: u8) -> (u8, u8) {
    let (level, run) = (state / 4, state % 4 + 1);
    if bit != level {
        (bit * 4, 0)
    } else if run == 4 {
        // The fifth equal bit: a stuff bit of the other level follows, a run of one.
        ((1 - level) * 4, 1)
    } else {
        (state + 1, 0)
    }
}

/// For each state and each byte sent from it (most significant bit first): the state after
/// it, and the stuff bits it takes (at most two). Computed at compile time, where an index
/// out of range or a truncation would fail the build, not a run.
#[allow(clippy::indexing_slicing, clippy::cast_possible_truncation)]
const STUFF_TABLE: [[(u8, u8); 256]; 8] = {
    let mut table = [[(0u8, 0u8); 256]; 8];
    let mut state = 0;
    while state < 8 {
        let mut byte = 0;
        while byte < 256 {
            let (mut now, mut stuffed) = (state as u8, 0u8);
            let mut k = 8;
            while k > 0 {
                k -= 1;
                let (next, stuff) = stuff_step(now, ((byte >> k) & 1) as u8);
                now = next;
                stuffed += stuff;
            }
            table[state][byte] = (now, stuffed);
            byte += 1;
        }
        state += 1;
    }
    table
};

/// Bit stuffing over the low `bits` bits of `stream` (most significant first, at most 128),
/// from `state` with `stuffed` stuff bits so far: the state and the count after them. The bits
/// short of a whole byte go one at a time, then a byte at a time by [`STUFF_TABLE`].
fn stuff_run(mut state: u8, mut stuffed: u32, stream: u128, bits: u32) -> (u8, u32) {
    let bits = bits.min(128);
    let bit = |k: u32| u8::from(stream >> k & 1 == 1);
    let odd = bits % 8;
    for k in (bits - odd..bits).rev() {
        let (next, stuff) = stuff_step(state, bit(k));
        state = next;
        stuffed += u32::from(stuff);
    }
    for k in (0..(bits - odd) / 8).rev() {
        let byte = usize::from(u8::try_from(stream >> (8 * k) & 0xFF).unwrap_or(0));
        let row = STUFF_TABLE
            .get(usize::from(state))
            .unwrap_or(&STUFF_TABLE[0]);
        let (next, stuff) = row.get(byte).copied().unwrap_or((0, 0));
        state = next;
        stuffed += u32::from(stuff);
    }
    (state, stuffed)
}

#[cfg(test)]
mod tests;
