//! Reading a bit sequence back as a receiver does, and judging a transmission as the
//! transmitter does.

use super::{fd_crc_width, stuff_count_code, BitSeq, Field, WireFrame};
use crate::crc::CrcRegister;
use crate::frame::{ClassicFrame, Dlc, FdFrame, Frame, Id};

/// The five kinds of error ISO 11898-1 defines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// A transmitter monitored a level other than the one it sent (outside arbitration and the
    /// ACK slot).
    Bit,
    /// Six equal levels in the stuffed part of a frame.
    Stuff,
    /// The received CRC (or, in FD, the stuff count) differs from the computed one.
    Crc,
    /// A fixed-form bit (delimiters, EOF, FD fixed stuff bits, SOF) has the wrong level.
    Form,
    /// No receiver acknowledged: the ACK slot stayed recessive.
    Ack,
}

impl ErrorKind {
    /// Lower-case name, as in "stuff error".
    pub const fn name(self) -> &'static str {
        match self {
            ErrorKind::Bit => "bit",
            ErrorKind::Stuff => "stuff",
            ErrorKind::Crc => "CRC",
            ErrorKind::Form => "form",
            ErrorKind::Ack => "ACK",
        }
    }
}

/// An error found in a bit sequence: its kind, the bit index where it shows, and the field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{} error at bit {position} ({})", kind.name(), field.name())]
pub struct WireError {
    /// What went wrong.
    pub kind: ErrorKind,
    /// Index of the bit where the error is detected (0 = SOF).
    pub position: usize,
    /// The field that bit belongs to.
    pub field: Field,
}

/// How a transmission went, judged from what the transmitter sent and what it monitored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransmitOutcome {
    /// Sent and acknowledged.
    Success,
    /// Another node's frame won arbitration at this bit; the transmitter became a receiver.
    LostArbitration {
        /// Bit index of the first recessive bit overwritten by a dominant one.
        at: usize,
    },
    /// The transmission failed.
    Error(WireError),
}

struct Reader<'a> {
    bits: &'a BitSeq,
    pos: usize,
    last: bool,
    run: u8,
    /// Classic CRC: destuffed bits only.
    crc15: CrcRegister,
    /// FD CRCs: stuff bits included. All three run until the format is known.
    crc17: CrcRegister,
    crc21: CrcRegister,
    dynamic_stuff_bits: u16,
}

impl Reader<'_> {
    fn fail(&self, kind: ErrorKind, position: usize, field: Field) -> WireError {
        WireError {
            kind,
            position,
            field,
        }
    }

    /// One level; past the end of the sequence the idle bus is recessive.
    fn level(&mut self) -> bool {
        let bit = self.bits.get(self.pos).unwrap_or(true);
        self.pos += 1;
        if bit == self.last && self.run > 0 {
            self.run = self.run.saturating_add(1);
        } else {
            self.run = 1;
        }
        self.last = bit;
        bit
    }

    /// One bit of the dynamically stuffed region, covered by every CRC.
    fn bit(&mut self) -> bool {
        let bit = self.level();
        self.crc15.push_bit(bit);
        self.crc17.push_bit(bit);
        self.crc21.push_bit(bit);
        bit
    }

    /// After five equal levels, the next must be a stuff bit of the other level.
    fn destuff(&mut self, field: Field) -> Result<(), WireError> {
        if self.run < 5 {
            return Ok(());
        }
        let at = self.pos;
        let expected = !self.last;
        let stuff = self.level();
        if stuff != expected {
            return Err(self.fail(ErrorKind::Stuff, at, field));
        }
        self.crc17.push_bit(stuff);
        self.crc21.push_bit(stuff);
        self.dynamic_stuff_bits = self.dynamic_stuff_bits.saturating_add(1);
        Ok(())
    }

    /// `width` stuffed bits as a number; `last_unstuffed` skips the stuff check after the final
    /// bit (the end of the dynamic region in FD frames).
    fn field(&mut self, field: Field, width: u8, last_unstuffed: bool) -> Result<u32, WireError> {
        let mut value = 0u32;
        for i in 0..width {
            value = (value << 1) | u32::from(self.bit());
            if !(last_unstuffed && i + 1 == width) {
                self.destuff(field)?;
            }
        }
        Ok(value)
    }

    fn fixed_stuff(&mut self, field: Field) -> Result<(), WireError> {
        let at = self.pos;
        let expected = !self.last;
        if self.level() != expected {
            return Err(self.fail(ErrorKind::Form, at, field));
        }
        Ok(())
    }

    fn recessive(&mut self, field: Field) -> Result<(), WireError> {
        let at = self.pos;
        if !self.level() {
            return Err(self.fail(ErrorKind::Form, at, field));
        }
        Ok(())
    }
}

/// Decode a bit sequence starting at SOF as a receiver would: destuff, check stuffing, CRC,
/// fixed-form fields and the ACK slot, and return the frame or the first error met. Bits missing
/// at the end read as recessive (an idle bus); bits after EOF are ignored.
pub fn decode(bits: &BitSeq) -> Result<Frame, WireError> {
    let mut r = Reader {
        bits,
        pos: 0,
        last: true,
        run: 0,
        crc15: CrcRegister::crc15(),
        crc17: CrcRegister::crc17_iso(),
        crc21: CrcRegister::crc21_iso(),
        dynamic_stuff_bits: 0,
    };
    if r.field(Field::Sof, 1, false)? != 0 {
        return Err(r.fail(ErrorKind::Form, 0, Field::Sof));
    }
    let base = r.field(Field::BaseId, 11, false)?;
    let after_base = r.field(Field::Rtr, 1, false)? == 1;
    let extended = r.field(Field::Ide, 1, false)? == 1;
    // Reserved bits (SRR, RRS, r1/r0 in classic, res) are accepted at either level, as
    // receivers must; the CRC covers them.
    let (id, remote, fd) = if extended {
        let ext = r.field(Field::IdExtension, 18, false)?;
        let rtr = r.field(Field::Rtr, 1, false)? == 1;
        let fdf = r.field(Field::Fdf, 1, false)? == 1;
        let id = Id::extended((base << 18) | ext)
            .map_err(|_| r.fail(ErrorKind::Form, 1, Field::BaseId))?;
        if !fdf {
            r.field(Field::R0, 1, false)?;
        }
        (id, rtr && !fdf, fdf)
    } else {
        let fdf = r.field(Field::Fdf, 1, false)? == 1;
        let id = Id::standard(base).map_err(|_| r.fail(ErrorKind::Form, 1, Field::BaseId))?;
        (id, after_base && !fdf, fdf)
    };
    let (mut brs, mut esi) = (false, false);
    if fd {
        r.field(Field::Res, 1, false)?;
        brs = r.field(Field::Brs, 1, false)? == 1;
        esi = r.field(Field::Esi, 1, false)? == 1;
    }
    // Read DLC bits one at a time: in FD with no data the last DLC bit ends the stuffed region.
    let dlc_high = r.field(Field::Dlc, 3, false)?;
    let dlc_low = r.bit();
    let dlc = Dlc::from_nibble(u8::try_from((dlc_high << 1) | u32::from(dlc_low)).unwrap_or(0));
    let len = match (fd, remote) {
        (true, _) => dlc.fd_len(),
        (false, true) => 0,
        (false, false) => dlc.classic_len(),
    };
    if !(fd && len == 0) {
        r.destuff(Field::Dlc)?;
    }
    let mut data = [0u8; 64];
    for (i, slot) in data.iter_mut().take(len).enumerate() {
        let last = fd && i + 1 == len;
        // 8 bits always fit a byte.
        *slot = u8::try_from(r.field(Field::Data, 8, last)?).unwrap_or(0);
    }
    let payload = data.get(..len).unwrap_or(&[]);

    let frame = if fd {
        r.fixed_stuff(Field::StuffCount)?;
        let code_at = r.pos;
        let mut code = 0u8;
        for _ in 0..4 {
            let bit = r.level();
            r.crc17.push_bit(bit);
            r.crc21.push_bit(bit);
            code = (code << 1) | u8::from(bit);
        }
        if code != stuff_count_code(r.dynamic_stuff_bits) {
            return Err(r.fail(ErrorKind::Crc, code_at + 3, Field::StuffCount));
        }
        let width = fd_crc_width(len);
        let expected = if width == 21 {
            r.crc21.value()
        } else {
            r.crc17.value()
        };
        r.fixed_stuff(Field::Crc)?;
        let mut received = 0u32;
        for n in 0..width {
            received = (received << 1) | u32::from(r.level());
            if (n + 1) % 4 == 0 && n + 1 < width {
                r.fixed_stuff(Field::Crc)?;
            }
        }
        if received != expected {
            return Err(r.fail(ErrorKind::Crc, r.pos - 1, Field::Crc));
        }
        FdFrame::new(id, payload, brs, esi).map(Frame::Fd)
    } else {
        let expected = r.crc15.value();
        let mut received = 0u32;
        let mut last_crc_bit = r.pos;
        for _ in 0..15 {
            last_crc_bit = r.pos;
            received = (received << 1) | u32::from(r.level());
            r.destuff(Field::Crc)?;
        }
        if received != expected {
            return Err(r.fail(ErrorKind::Crc, last_crc_bit, Field::Crc));
        }
        if remote {
            Ok(Frame::remote(id, dlc))
        } else {
            ClassicFrame::with_dlc(id, dlc, payload).map(Frame::Classic)
        }
    }
    .map_err(|_| r.fail(ErrorKind::Form, 0, Field::Dlc))?;

    r.recessive(Field::CrcDelimiter)?;
    let ack_at = r.pos;
    if r.level() {
        return Err(r.fail(ErrorKind::Ack, ack_at, Field::AckSlot));
    }
    r.recessive(Field::AckDelimiter)?;
    for _ in 0..7 {
        r.recessive(Field::Eof)?;
    }
    Ok(frame)
}

/// Judge a transmission: `sent` is what the transmitter drove (encode it with
/// [`super::encode_with_ack`]`(frame, false)`: a transmitter sends a recessive ACK slot) and
/// `observed` what it read back from the bus.
pub fn check_transmission(sent: &WireFrame, observed: &BitSeq) -> TransmitOutcome {
    for (i, driven) in sent.bits().iter().enumerate() {
        let seen = observed.get(i).unwrap_or(true);
        let field = sent.field_at(i).unwrap_or(Field::Eof);
        let error = |kind| {
            TransmitOutcome::Error(WireError {
                kind,
                position: i,
                field,
            })
        };
        if field == Field::AckSlot {
            if seen {
                return error(ErrorKind::Ack);
            }
            continue;
        }
        if driven == seen {
            continue;
        }
        if driven && field.is_arbitration() {
            // A recessive stuff bit overwritten in arbitration is a stuff error (the exception
            // ISO 11898-1 makes for the error counters), any other a lost arbitration.
            if sent.is_stuff_bit(i) {
                return error(ErrorKind::Stuff);
            }
            return TransmitOutcome::LostArbitration { at: i };
        }
        return error(ErrorKind::Bit);
    }
    TransmitOutcome::Success
}
