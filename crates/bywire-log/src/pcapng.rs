//! pcapng capture files with CAN frames (LINKTYPE_CAN_SOCKETCAN, 227), as Wireshark and tshark
//! read and write them.
//!
//! A file is blocks: a section header (its byte-order magic says the section's endianness),
//! interface descriptions (link type, `if_name`, `if_tsresol`), and enhanced packets (interface,
//! 64-bit timestamp in the interface's resolution, the packet, `epb_flags` with the direction).
//! A CAN packet is SocketCAN's `struct can_frame` or `struct canfd_frame` with the identifier
//! word big-endian: flags EFF/RTR/ERR in its top bits, the data length, FD flags (BRS, ESI,
//! FDF), `len8_dlc`, then the data. Written little-endian, one interface per bus (named after
//! it), timestamps in nanoseconds. Blocks of other kinds, and packets of other link types,
//! are passed over; a malformed block is an error naming its byte offset.

use std::collections::BTreeMap;
use std::io::{self, Read, Write};

use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame};
use bywire_core::{Frame, Id, Timestamp};

use crate::candump::{LogError, LogRecord};

/// LINKTYPE_CAN_SOCKETCAN.
pub const LINKTYPE_CAN_SOCKETCAN: u16 = 227;

const SECTION_HEADER: u32 = 0x0A0D_0D0A;
const INTERFACE_DESCRIPTION: u32 = 1;
const ENHANCED_PACKET: u32 = 6;
const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
/// The largest block read whole (a CAN packet block is under 150 bytes; option-heavy headers
/// may be larger, but nothing near this).
const MAX_BLOCK: u32 = 1 << 20;

const CAN_EFF_FLAG: u32 = 0x8000_0000;
const CAN_RTR_FLAG: u32 = 0x4000_0000;
const CAN_ERR_FLAG: u32 = 0x2000_0000;
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;
const CANFD_FDF: u8 = 0x04;

/// One interface of the section.
#[derive(Debug, Clone)]
struct Interface {
    link_type: u16,
    name: String,
    /// Nanoseconds per timestamp unit, as a ratio (units of 10^-n or 2^-n seconds).
    resolution: Resolution,
}

#[derive(Debug, Clone, Copy)]
enum Resolution {
    /// 10^-n seconds.
    Decimal(u32),
    /// 2^-n seconds.
    Binary(u32),
}

impl Resolution {
    fn to_nanos(self, units: u64) -> u64 {
        match self {
            Resolution::Decimal(n) if n <= 9 => units.saturating_mul(10u64.pow(9 - n)),
            Resolution::Decimal(n) => units / 10u64.pow((n - 9).min(19)),
            Resolution::Binary(n) => {
                let nanos = (u128::from(units) * 1_000_000_000) >> n.min(127);
                u64::try_from(nanos).unwrap_or(u64::MAX)
            }
        }
    }
}

/// Reads the CAN frames of a pcapng file one block at a time (bounded memory).
pub struct PcapngReader<R> {
    input: R,
    offset: u64,
    big_endian: bool,
    interfaces: Vec<Interface>,
    block: Vec<u8>,
    failed: bool,
}

impl<R: Read> PcapngReader<R> {
    /// A reader over `input`.
    pub fn new(input: R) -> Self {
        PcapngReader {
            input,
            offset: 0,
            big_endian: false,
            interfaces: Vec::new(),
            block: Vec::new(),
            failed: false,
        }
    }

    fn malformed(&self, offset: u64, what: impl Into<String>) -> LogError {
        LogError::Binary {
            offset,
            what: what.into(),
        }
    }

    fn u32_at(&self, bytes: &[u8], at: usize) -> Option<u32> {
        let word: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
        Some(if self.big_endian {
            u32::from_be_bytes(word)
        } else {
            u32::from_le_bytes(word)
        })
    }

    fn u16_at(&self, bytes: &[u8], at: usize) -> Option<u16> {
        let word: [u8; 2] = bytes.get(at..at + 2)?.try_into().ok()?;
        Some(if self.big_endian {
            u16::from_be_bytes(word)
        } else {
            u16::from_le_bytes(word)
        })
    }

    /// The next block: its type and body (after type and length, before the trailing length);
    /// `None` at a clean end of the file.
    fn next_block(&mut self) -> Result<Option<(u64, u32)>, LogError> {
        let start = self.offset;
        let mut head = [0u8; 8];
        match read_full(&mut self.input, &mut head) {
            Ok(0) => return Ok(None),
            Ok(8) => {}
            Ok(_) => return Err(self.malformed(start, "the file ends inside a block header")),
            Err(e) => {
                return Err(LogError::Binary {
                    offset: start,
                    what: e.to_string(),
                })
            }
        }
        let raw_type = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        if raw_type == SECTION_HEADER {
            // The byte order of this section is in its magic, after the length.
            let mut magic = [0u8; 4];
            if read_full(&mut self.input, &mut magic).map_err(|e| LogError::Binary {
                offset: start + 8,
                what: e.to_string(),
            })? != 4
            {
                return Err(self.malformed(start, "the file ends inside a section header"));
            }
            self.big_endian = match u32::from_le_bytes(magic) {
                BYTE_ORDER_MAGIC => false,
                m if m.swap_bytes() == BYTE_ORDER_MAGIC => true,
                _ => return Err(self.malformed(start, "not a pcapng file (no byte-order magic)")),
            };
            self.interfaces.clear();
            let length = self.u32_at(&head, 4).unwrap_or(0);
            self.read_body(start, length, 4)?;
            self.block.splice(0..0, magic);
            return Ok(Some((start, SECTION_HEADER)));
        }
        if start == 0 {
            return Err(self.malformed(0, "not a pcapng file (no section header first)"));
        }
        let block_type = self.u32_at(&head, 0).unwrap_or(0);
        let length = self.u32_at(&head, 4).unwrap_or(0);
        self.read_body(start, length, 0)?;
        Ok(Some((start, block_type)))
    }

    /// Read the rest of a block of `length` bytes (of which 8 + `already` are read) into
    /// `self.block`, without the trailing length (checked).
    fn read_body(&mut self, start: u64, length: u32, already: u32) -> Result<(), LogError> {
        // The header, what the caller read beyond it, and the trailing length.
        let least = 12 + already;
        if length < least || !length.is_multiple_of(4) || length > MAX_BLOCK {
            return Err(self.malformed(
                start,
                format!("block length {length} (a multiple of 4, {least} to {MAX_BLOCK})"),
            ));
        }
        let rest = usize::try_from(length - 8 - already).unwrap_or(0);
        self.block.clear();
        self.block.resize(rest, 0);
        let got = read_full(&mut self.input, &mut self.block).map_err(|e| LogError::Binary {
            offset: start,
            what: e.to_string(),
        })?;
        self.offset = start + u64::from(length);
        if got != rest {
            return Err(self.malformed(
                start,
                format!("the file ends inside a block of {length} bytes"),
            ));
        }
        let trailer = self.u32_at(&self.block, rest - 4).unwrap_or(0);
        if trailer != length {
            return Err(self.malformed(
                start,
                format!("block length {length} and trailing length {trailer} differ"),
            ));
        }
        self.block.truncate(rest - 4);
        Ok(())
    }

    /// The options of a block from `at`: (code, value) pairs, to the end-of-options.
    fn options(&self, at: usize) -> Vec<(u16, Vec<u8>)> {
        let mut options = Vec::new();
        let mut at = at;
        // Bounded by the block's length.
        while let (Some(code), Some(length)) = (
            self.u16_at(&self.block, at),
            self.u16_at(&self.block, at + 2),
        ) {
            if code == 0 {
                break;
            }
            let length = usize::from(length);
            let Some(value) = self.block.get(at + 4..at + 4 + length) else {
                break;
            };
            options.push((code, value.to_vec()));
            at += 4 + length.div_ceil(4) * 4;
        }
        options
    }

    fn interface(&mut self, start: u64) -> Result<(), LogError> {
        let link_type = self
            .u16_at(&self.block, 0)
            .ok_or_else(|| self.malformed(start, "interface description too short"))?;
        let mut name = format!("can{}", self.interfaces.len());
        let mut resolution = Resolution::Decimal(6);
        for (code, value) in self.options(8) {
            match (code, value.as_slice()) {
                (2, bytes) => {
                    name = String::from_utf8_lossy(bytes)
                        .trim_end_matches('\0')
                        .to_string();
                }
                (9, [byte]) => {
                    resolution = if byte & 0x80 == 0 {
                        Resolution::Decimal(u32::from(*byte))
                    } else {
                        Resolution::Binary(u32::from(byte & 0x7F))
                    };
                }
                _ => {}
            }
        }
        self.interfaces.push(Interface {
            link_type,
            name,
            resolution,
        });
        Ok(())
    }

    fn packet(&self, start: u64) -> Result<Option<LogRecord>, LogError> {
        let field = |at| {
            self.u32_at(&self.block, at)
                .ok_or_else(|| self.malformed(start, "enhanced packet too short"))
        };
        let (interface, high, low, captured) = (field(0)?, field(4)?, field(8)?, field(12)?);
        let Some(description) = usize::try_from(interface)
            .ok()
            .and_then(|i| self.interfaces.get(i))
        else {
            return Err(self.malformed(
                start,
                format!("packet on interface {interface}, which is not described"),
            ));
        };
        if description.link_type != LINKTYPE_CAN_SOCKETCAN {
            return Ok(None);
        }
        let captured = usize::try_from(captured).unwrap_or(usize::MAX);
        let packet = self
            .block
            .get(20..20usize.saturating_add(captured))
            .ok_or_else(|| {
                self.malformed(
                    start,
                    format!("captured length {captured} beyond the block"),
                )
            })?;
        let frame = can_frame(packet).map_err(|what| self.malformed(start, what))?;
        let units = (u64::from(high) << 32) | u64::from(low);
        let mut direction = None;
        for (code, value) in self.options(20 + captured.div_ceil(4) * 4) {
            if let (2, Some(flags)) = (code, self.u32_at(&value, 0)) {
                direction = match flags & 0b11 {
                    1 => Some('R'),
                    2 => Some('T'),
                    _ => None,
                };
            }
        }
        Ok(Some(LogRecord {
            timestamp: Timestamp::from_nanos(description.resolution.to_nanos(units)),
            interface: description.name.clone(),
            frame,
            direction,
        }))
    }
}

/// Read until `buffer` is full or the input ends; how many bytes came.
fn read_full(input: &mut impl Read, buffer: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    // Bounded by the buffer's length (each pass reads at least a byte or ends).
    while got < buffer.len() {
        match input.read(buffer.get_mut(got..).unwrap_or_default()) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// A LINKTYPE_CAN_SOCKETCAN packet as a frame.
fn can_frame(packet: &[u8]) -> Result<Frame, String> {
    let header: [u8; 8] = packet
        .get(..8)
        .and_then(|h| h.try_into().ok())
        .ok_or_else(|| format!("a CAN packet of {} bytes (at least 8)", packet.len()))?;
    let word = u32::from_be_bytes([header[0], header[1], header[2], header[3]]);
    let length = usize::from(header[4]);
    let fd_flags = header[5];
    let len8_dlc = header[7];
    let data = packet.get(8..).unwrap_or(&[]);
    let fd = fd_flags & CANFD_FDF != 0 || packet.len() == 72;
    if word & CAN_ERR_FLAG != 0 {
        let mut bytes = [0u8; 8];
        for (slot, byte) in bytes.iter_mut().zip(data) {
            *slot = *byte;
        }
        return Ok(Frame::Error(ErrorFrame::from_array(
            word & 0x1FFF_FFFF,
            bytes,
        )));
    }
    let id = if word & CAN_EFF_FLAG != 0 {
        Id::extended(word & 0x1FFF_FFFF)
    } else {
        Id::standard(word & 0x7FF)
    }
    .map_err(|e| e.to_string())?;
    let bytes = data.get(..length).ok_or_else(|| {
        format!(
            "data length {length} beyond the packet's {} data bytes",
            data.len()
        )
    })?;
    if fd {
        return FdFrame::new(
            id,
            bytes,
            fd_flags & CANFD_BRS != 0,
            fd_flags & CANFD_ESI != 0,
        )
        .map(Frame::Fd)
        .map_err(|e| e.to_string());
    }
    if length > 8 {
        return Err(format!("classic data length {length} (at most 8)"));
    }
    let dlc = if length == 8 && (9..=15).contains(&len8_dlc) {
        Dlc::new(len8_dlc).unwrap_or(Dlc::from_nibble(8))
    } else {
        Dlc::from_nibble(u8::try_from(length).unwrap_or(8))
    };
    if word & CAN_RTR_FLAG != 0 {
        return Ok(Frame::remote(id, dlc));
    }
    ClassicFrame::with_dlc(id, dlc, bytes)
        .map(Frame::Classic)
        .map_err(|e| e.to_string())
}

impl<R: Read> Iterator for PcapngReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        // Bounded by the file's blocks.
        loop {
            let step = match self.next_block() {
                Ok(None) => return None,
                Ok(Some((start, INTERFACE_DESCRIPTION))) => self.interface(start).map(|()| None),
                Ok(Some((start, ENHANCED_PACKET))) => self.packet(start),
                Ok(Some(_)) => Ok(None), // section headers (handled), statistics, names …
                Err(e) => Err(e),
            };
            match step {
                Ok(Some(record)) => return Some(Ok(record)),
                Ok(None) => continue,
                Err(e) => {
                    // The blocks after a broken one cannot be found: the read ends here.
                    self.failed = true;
                    return Some(Err(e));
                }
            }
        }
    }
}

/// Writes a pcapng file: a section header, an interface per bus (named after it, nanosecond
/// timestamps) as each first appears, an enhanced packet per frame with its direction.
pub struct PcapngWriter<W: Write> {
    output: W,
    interfaces: BTreeMap<String, u32>,
    started: bool,
    block: Vec<u8>,
}

fn option(block: &mut Vec<u8>, code: u16, value: &[u8]) {
    block.extend_from_slice(&code.to_le_bytes());
    block.extend_from_slice(&u16::try_from(value.len()).unwrap_or(0).to_le_bytes());
    block.extend_from_slice(value);
    block.resize(block.len().div_ceil(4) * 4, 0);
}

impl<W: Write> PcapngWriter<W> {
    /// A writer to `output`.
    pub fn new(output: W) -> Self {
        PcapngWriter {
            output,
            interfaces: BTreeMap::new(),
            started: false,
            block: Vec::new(),
        }
    }

    /// Write `self.block` (the body) as a block of `block_type`.
    fn emit(&mut self, block_type: u32) -> io::Result<()> {
        let length = u32::try_from(self.block.len() + 12).unwrap_or(u32::MAX);
        self.output.write_all(&block_type.to_le_bytes())?;
        self.output.write_all(&length.to_le_bytes())?;
        self.output.write_all(&self.block)?;
        self.output.write_all(&length.to_le_bytes())
    }

    fn start(&mut self) -> io::Result<()> {
        self.block.clear();
        self.block
            .extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
        self.block.extend_from_slice(&1u16.to_le_bytes());
        self.block.extend_from_slice(&0u16.to_le_bytes());
        self.block.extend_from_slice(&(-1i64).to_le_bytes());
        option(&mut self.block, 4, b"bywire");
        option(&mut self.block, 0, &[]);
        self.started = true;
        self.emit(SECTION_HEADER)
    }

    fn interface(&mut self, name: &str) -> io::Result<u32> {
        if let Some(index) = self.interfaces.get(name) {
            return Ok(*index);
        }
        let index = u32::try_from(self.interfaces.len()).unwrap_or(u32::MAX);
        self.block.clear();
        self.block
            .extend_from_slice(&LINKTYPE_CAN_SOCKETCAN.to_le_bytes());
        self.block.extend_from_slice(&0u16.to_le_bytes());
        self.block.extend_from_slice(&72u32.to_le_bytes());
        option(&mut self.block, 2, name.as_bytes());
        option(&mut self.block, 9, &[9]); // nanoseconds
        option(&mut self.block, 0, &[]);
        self.emit(INTERFACE_DESCRIPTION)?;
        self.interfaces.insert(name.to_string(), index);
        Ok(index)
    }

    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        if !self.started {
            self.start()?;
        }
        let interface = self.interface(&record.interface)?;
        let packet = socketcan_packet(&record.frame);
        let nanos = record.timestamp.as_nanos();
        self.block.clear();
        self.block.extend_from_slice(&interface.to_le_bytes());
        self.block
            .extend_from_slice(&u32::try_from(nanos >> 32).unwrap_or(0).to_le_bytes());
        self.block.extend_from_slice(
            &u32::try_from(nanos & 0xFFFF_FFFF)
                .unwrap_or(0)
                .to_le_bytes(),
        );
        let length = u32::try_from(packet.len()).unwrap_or(0);
        self.block.extend_from_slice(&length.to_le_bytes());
        self.block.extend_from_slice(&length.to_le_bytes());
        self.block.extend_from_slice(&packet);
        self.block.resize(self.block.len().div_ceil(4) * 4, 0);
        let flags: u32 = match record.direction {
            Some('R') => 1,
            Some('T') => 2,
            _ => 0,
        };
        if flags != 0 {
            option(&mut self.block, 2, &flags.to_le_bytes());
            option(&mut self.block, 0, &[]);
        }
        self.emit(ENHANCED_PACKET)
    }

    /// Write out what is buffered (the section header too, if no frame came yet): a file cut
    /// short after this reads up to here.
    pub fn flush(&mut self) -> io::Result<()> {
        if !self.started {
            self.start()?;
        }
        self.output.flush()
    }

    /// Flush (a file with no frames still gets its section header); the output back.
    pub fn finish(mut self) -> io::Result<W> {
        if !self.started {
            self.start()?;
        }
        self.output.flush()?;
        Ok(self.output)
    }
}

/// A frame as SocketCAN's `can_frame` (16 bytes) or `canfd_frame` (72), identifier word
/// big-endian as LINKTYPE_CAN_SOCKETCAN wants it.
fn socketcan_packet(frame: &Frame) -> Vec<u8> {
    let (word, length, fd_flags, len8_dlc, data, size): (u32, usize, u8, u8, &[u8], usize) =
        match frame {
            Frame::Error(e) => (CAN_ERR_FLAG | e.class_bits(), 8, 0, 0, e.data(), 16),
            Frame::Classic(f) => {
                let id = id_word(f.id());
                let rtr = if f.is_remote() { CAN_RTR_FLAG } else { 0 };
                let raw = f.dlc().as_raw();
                let length = f.dlc().fd_len().min(8);
                let len8 = if raw > 8 { raw } else { 0 };
                let data: &[u8] = if f.is_remote() { &[] } else { f.data() };
                (
                    id | rtr,
                    if f.is_remote() {
                        usize::from(raw.min(8))
                    } else {
                        length
                    },
                    0,
                    len8,
                    data,
                    16,
                )
            }
            Frame::Fd(f) => {
                let mut flags = CANFD_FDF;
                if f.brs() {
                    flags |= CANFD_BRS;
                }
                if f.esi() {
                    flags |= CANFD_ESI;
                }
                (id_word(f.id()), f.data().len(), flags, 0, f.data(), 72)
            }
        };
    let mut packet = vec![0u8; size];
    if let Some(head) = packet.get_mut(..8) {
        head.copy_from_slice(&[
            word.to_be_bytes()[0],
            word.to_be_bytes()[1],
            word.to_be_bytes()[2],
            word.to_be_bytes()[3],
            u8::try_from(length).unwrap_or(0),
            fd_flags,
            0,
            len8_dlc,
        ]);
    }
    for (slot, byte) in packet.iter_mut().skip(8).zip(data) {
        *slot = *byte;
    }
    packet
}

fn id_word(id: Id) -> u32 {
    if id.is_extended() {
        id.as_raw() | CAN_EFF_FLAG
    } else {
        id.as_raw()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn records(frames: &[(&str, &str, Option<char>)]) -> Vec<LogRecord> {
        frames
            .iter()
            .enumerate()
            .map(|(i, (interface, frame, direction))| LogRecord {
                timestamp: Timestamp::from_nanos(
                    1_700_000_000_123_456_789 + u64::try_from(i).unwrap() * 1_000_001,
                ),
                interface: (*interface).to_string(),
                frame: frame.parse().unwrap(),
                direction: *direction,
            })
            .collect()
    }

    fn write(records: &[LogRecord]) -> Vec<u8> {
        let mut writer = PcapngWriter::new(Vec::new());
        for r in records {
            writer.write(r).unwrap();
        }
        writer.finish().unwrap()
    }

    #[test]
    fn written_captures_read_back_frame_for_frame() {
        let original = records(&[
            ("can0", "123#DEADBEEF", Some('R')),
            ("vcan1", "1ABCDEF0#", Some('T')),
            ("can0", "123#R2", None),
            ("can0", "7FF##3112233445566778899", None),
            ("can0", "20000080#0000000000000000", None),
        ]);
        let bytes = write(&original);
        assert_eq!(&bytes[..4], &[0x0A, 0x0D, 0x0D, 0x0A]);
        let back: Vec<LogRecord> = PcapngReader::new(bytes.as_slice())
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back, original, "nanoseconds, names, directions and frames");
    }

    #[test]
    fn a_big_endian_section_and_microsecond_interface_read() {
        // A section in big-endian byte order, an interface with the default resolution (µs).
        let mut file = Vec::new();
        let block = |file: &mut Vec<u8>, kind: u32, body: &[u8]| {
            let length = u32::try_from(body.len() + 12).unwrap();
            file.extend_from_slice(&kind.to_be_bytes());
            file.extend_from_slice(&length.to_be_bytes());
            file.extend_from_slice(body);
            file.extend_from_slice(&length.to_be_bytes());
        };
        let mut shb = BYTE_ORDER_MAGIC.to_be_bytes().to_vec();
        shb.extend_from_slice(&[0, 1, 0, 0]);
        shb.extend_from_slice(&(-1i64).to_be_bytes());
        block(&mut file, SECTION_HEADER, &shb);
        let mut idb = LINKTYPE_CAN_SOCKETCAN.to_be_bytes().to_vec();
        idb.extend_from_slice(&[0, 0, 0, 0, 0, 16]);
        block(&mut file, INTERFACE_DESCRIPTION, &idb);
        let mut epb = Vec::new();
        for word in [0u32, 0, 1_500_000, 12, 12] {
            epb.extend_from_slice(&word.to_be_bytes());
        }
        epb.extend_from_slice(&[0, 0, 0x01, 0x23, 4, 0, 0, 0, 0xDE, 0xAD, 0xBE, 0xEF]);
        block(&mut file, ENHANCED_PACKET, &epb);
        let back: Vec<LogRecord> = PcapngReader::new(file.as_slice())
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].timestamp.as_nanos(), 1_500_000_000);
        assert_eq!(back[0].frame.to_string(), "123#DEADBEEF");
        assert_eq!(back[0].interface, "can0");
    }

    #[test]
    fn broken_files_name_the_byte() {
        let bytes = write(&records(&[
            ("can0", "123#01", None),
            ("can0", "124#02", None),
        ]));
        let first_packet = bytes.len() - 2 * 48; // a classic frame's packet block is 48 bytes
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"(1.0) can0 123#".to_vec(), "byte 0: not a pcapng file"),
            (bytes[..bytes.len() - 3].to_vec(), "ends inside a block"),
            (
                {
                    let mut b = bytes.clone();
                    b[first_packet + 4] = 0xFF; // the length
                    b
                },
                "block length",
            ),
            (
                {
                    let mut b = bytes.clone();
                    b[4..8].copy_from_slice(&12u32.to_le_bytes()); // a section header too short for its magic
                    b
                },
                "block length 12 (a multiple of 4, 16 to",
            ),
            (
                {
                    let mut b = bytes.clone();
                    b[first_packet + 8] = 7; // interface 7
                    b
                },
                "interface 7",
            ),
        ];
        for (file, what) in cases {
            let error = PcapngReader::new(file.as_slice())
                .find_map(Result::err)
                .unwrap_or_else(|| panic!("no error: {what}"));
            assert!(error.to_string().contains(what), "{error} ({what})");
        }
    }
}
