//! ASAM MDF 4 (`.mf4`) bus logging, read and written as python-can, asammdf and CAN loggers
//! write it.
//!
//! A file is a 64-byte identification block, then blocks linked by absolute offsets: the
//! header (`##HD`, the start time) heads a chain of data groups (`##DG`), each with channel
//! groups (`##CG`) whose channels (`##CN`) say where each value sits in a record. CAN bus
//! logging names them: a channel group of bus events (`CAN_DataFrame`, `CAN_ErrorFrame`,
//! `CAN_RemoteFrame`) whose structure channel has the components `.BusChannel .ID .IDE .DLC
//! .DataLength .DataBytes .Dir .EDL .BRS .ESI`, beside a master channel of time in seconds from
//! the header's start.
//!
//! The writer makes one data group a kind of frame, with python-can's record layout (fixed
//! 64-byte `DataBytes`, one byte a flag), each group's records in data blocks (`##DT`) of
//! [`BLOCK_SIZE`] listed by a data list (`##DL`): memory is three blocks' worth, whatever the
//! file's size. The groups, channels and the header's links are written at
//! [`Mf4Writer::finish`]; until then the file is marked unfinished (`UnFinMF`). `BusChannel` is
//! the interface's number (`can0` is 0, as python-can numbers it; names without one are
//! numbered after the others), and the header's comment names each number's interface
//! (`<e name="BusChannel 1">bus1</e>`), which the reader gives back; `Dir` is 0 received, 1
//! sent. Error frames keep their SocketCAN
//! class in `ID` and their 8 bytes in `DataBytes`.
//!
//! Decoded values may go beside the frames ([`Mf4Writer::add_decoded_group`]): a data group a
//! message, its master channel of time and a 64-bit float channel a signal, with its unit and
//! its value names as a value-to-text conversion, which asammdf's `to_dataframe` shows.
//!
//! The reader takes sorted files (a data group a channel group) and unsorted ones (record IDs,
//! as loggers write them), data in plain blocks (`##DT`), zipped ones (`##DZ`, deflate with or
//! without transposition, as python-can writes by default) and lists of them (`##DL`, `##HL`),
//! and merges the groups by time. It reads a block at a time, never the whole file; anything it
//! cannot read is an error naming the block's offset. Channel groups that are not CAN bus
//! events are passed over.

use std::collections::{BTreeMap, HashSet};
use std::io::{self, Read, Seek, SeekFrom, Write};

use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame};
use bywire_core::{Frame, Id, Timestamp};
use flate2::read::ZlibDecoder;

use crate::candump::{LogError, LogRecord};
use crate::fields::{is_interface_name, u16_at, u32_at, u64_at, MAX_CHANNEL_NAMES};

/// The records a writer's data block holds, in bytes.
pub const BLOCK_SIZE: usize = 512 * 1024;
/// A decoded message's block (smaller: a database may have hundreds of messages).
const DECODED_BLOCK_SIZE: usize = 64 * 1024;
/// `##CC` type: value to text.
const CC_VALUE_TO_TEXT: u8 = 7;
/// The header comment's property naming a bus channel's interface (`BusChannel 1` → `bus1`).
const CHANNEL_NAME: &str = "BusChannel ";

/// Text for an XML element's content.
fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The channel names a header comment gives (see [`Mf4Writer`]): each `<e name="BusChannel N">`
/// property that names an interface (letters, digits and `_-.:/`, at most 64 characters).
fn channel_names(comment: &str) -> BTreeMap<u64, String> {
    let mut names = BTreeMap::new();
    let key = format!("<e name=\"{CHANNEL_NAME}");
    for part in comment.split(key.as_str()).skip(1).take(MAX_CHANNEL_NAMES) {
        let Some((number, rest)) = part.split_once("\">") else {
            continue;
        };
        let Some((value, _)) = rest.split_once("</e>") else {
            continue;
        };
        let value = value
            .replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&amp;", "&");
        if let (Ok(number), true) = (number.parse::<u64>(), is_interface_name(&value)) {
            names.insert(number, value);
        }
    }
    names
}
/// Metadata blocks (groups, channels, texts, lists) larger than this are refused.
const MAX_BLOCK: u64 = 4 << 20;
/// A zipped block may unpack to at most this.
const MAX_UNZIPPED: u64 = 64 << 20;
/// A record may be at most this long.
const MAX_RECORD: u64 = 1 << 20;
/// Data groups, channel groups a group, channels a group, and data blocks a file read.
const MAX_GROUPS: usize = 4096;
const MAX_CHANNELS: usize = 4096;
const MAX_DATA_BLOCKS: usize = 4 << 20;
const HEADER_AT: u64 = 64;
const HEADER_LEN: u64 = 104;

const CN_MASTER: u8 = 2;
const CN_VIRTUAL_MASTER: u8 = 3;
const SYNC_TIME: u8 = 1;
const DT_UNSIGNED_LE: u8 = 0;
const DT_UNSIGNED_BE: u8 = 1;
const DT_SIGNED_LE: u8 = 2;
const DT_SIGNED_BE: u8 = 3;
const DT_FLOAT_LE: u8 = 4;
const DT_FLOAT_BE: u8 = 5;
const DT_STRING_LATIN1: u8 = 6;
const DT_STRING_UTF8: u8 = 7;
const DT_BYTES: u8 = 10;
const CG_VLSD: u16 = 1;
const CG_BUS_EVENT: u16 = 1 << 1;
const CG_PLAIN_BUS_EVENT: u16 = 1 << 2;
const SOURCE_BUS: u8 = 2;
const BUS_CAN: u8 = 2;
/// The SocketCAN class a bus error is read as when a file gives no class.
const BUS_ERROR: u32 = 0x80;

fn f64_at(bytes: &[u8], at: usize) -> Option<f64> {
    u64_at(bytes, at).map(f64::from_bits)
}

// ---------------------------------------------------------------------------------------------
// Writing

/// The kinds of frame, a data group each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Data,
    Error,
    Remote,
}

impl Kind {
    const ALL: [Kind; 3] = [Kind::Data, Kind::Error, Kind::Remote];

    fn name(self) -> &'static str {
        match self {
            Kind::Data => "CAN_DataFrame",
            Kind::Error => "CAN_ErrorFrame",
            Kind::Remote => "CAN_RemoteFrame",
        }
    }

    /// The components after the time (8 bytes): name, byte offset, bytes, data type.
    fn components(self) -> &'static [(&'static str, u32, u32, u8)] {
        const FULL: &[(&str, u32, u32, u8)] = &[
            ("BusChannel", 8, 1, DT_UNSIGNED_LE),
            ("ID", 9, 4, DT_UNSIGNED_LE),
            ("IDE", 13, 1, DT_UNSIGNED_LE),
            ("DLC", 14, 1, DT_UNSIGNED_LE),
            ("DataLength", 15, 1, DT_UNSIGNED_LE),
            ("DataBytes", 16, 64, DT_BYTES),
            ("Dir", 80, 1, DT_UNSIGNED_LE),
            ("EDL", 81, 1, DT_UNSIGNED_LE),
            ("BRS", 82, 1, DT_UNSIGNED_LE),
            ("ESI", 83, 1, DT_UNSIGNED_LE),
        ];
        const REMOTE: &[(&str, u32, u32, u8)] = &[
            ("BusChannel", 8, 1, DT_UNSIGNED_LE),
            ("ID", 9, 4, DT_UNSIGNED_LE),
            ("IDE", 13, 1, DT_UNSIGNED_LE),
            ("DLC", 14, 1, DT_UNSIGNED_LE),
            ("DataLength", 15, 1, DT_UNSIGNED_LE),
            ("Dir", 16, 1, DT_UNSIGNED_LE),
        ];
        match self {
            Kind::Data | Kind::Error => FULL,
            Kind::Remote => REMOTE,
        }
    }

    fn record_len(self) -> usize {
        match self {
            Kind::Data | Kind::Error => 84,
            Kind::Remote => 17,
        }
    }
}

/// A decoded signal's channel: its name, unit and the names of its values (physical value →
/// name, a value-to-text conversion).
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// The signal's name.
    pub name: String,
    /// Its unit ("" for none).
    pub unit: String,
    /// Its values' names.
    pub value_names: Vec<(f64, String)>,
}

/// A decoded message's data group: its name, columns, records and (once written) its first
/// channel and acquisition name.
#[derive(Debug)]
struct DecodedOut {
    name: String,
    columns: Vec<Column>,
    out: GroupOut,
    channels: Option<(u64, u64)>,
}

/// Where records go: a kind of frame's group, or a decoded message's.
#[derive(Debug, Clone, Copy)]
enum Slot {
    Raw(Kind),
    Decoded(usize),
}

/// One kind's records: the block being filled and the blocks written.
#[derive(Debug, Default)]
struct GroupOut {
    records: Vec<u8>,
    count: u64,
    /// Each data block's offset and the records' bytes in it.
    blocks: Vec<(u64, u64)>,
}

/// Writes an MF4 bus log (see the [module](self)).
#[derive(Debug)]
pub struct Mf4Writer<W: Write + Seek> {
    out: W,
    at: u64,
    start: Option<u64>,
    /// Data, error and remote frames.
    groups: (GroupOut, GroupOut, GroupOut),
    channels: BTreeMap<String, u32>,
    /// The blocks every checkpoint links to unchanged, written at the first.
    fixed: Option<Fixed>,
    /// Decoded messages' groups, in the order they were added.
    decoded: Vec<DecodedOut>,
}

/// Blocks that do not change between checkpoints: written once, linked from each.
#[derive(Debug, Clone, Copy)]
struct Fixed {
    source: u64,
    history: u64,
    /// Each kind's first channel (time) and acquisition name, in [`Kind::ALL`]'s order.
    channels: [(u64, u64); 3],
}

/// A block: its four-letter name, links and data, padded to 8 bytes.
fn block(name: &[u8; 4], links: &[u64], data: &[u8]) -> Vec<u8> {
    let padded = data.len().div_ceil(8) * 8;
    let length = 24 + 8 * links.len() + padded;
    let mut out = Vec::with_capacity(length);
    out.extend_from_slice(b"##");
    out.extend_from_slice(name.get(2..).unwrap_or(b"??"));
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&(length as u64).to_le_bytes());
    out.extend_from_slice(&(links.len() as u64).to_le_bytes());
    for link in links {
        out.extend_from_slice(&link.to_le_bytes());
    }
    out.extend_from_slice(data);
    out.resize(length, 0);
    out
}

fn identification(finished: bool) -> [u8; 64] {
    let mut id = [0u8; 64];
    let (file, flags): (&[u8; 8], u16) = match finished {
        true => (b"MDF     ", 0),
        // Everything is still to be written: the groups, their counts, the last block.
        false => (b"UnFinMF ", 0x1F),
    };
    id[..8].copy_from_slice(file);
    id[8..16].copy_from_slice(b"4.10    ");
    id[16..24].copy_from_slice(b"bywire  ");
    id[28..30].copy_from_slice(&410u16.to_le_bytes());
    id[60..62].copy_from_slice(&flags.to_le_bytes());
    id
}

fn header(links: [u64; 6], start_ns: u64) -> Vec<u8> {
    let mut data = Vec::with_capacity(32);
    data.extend_from_slice(&start_ns.to_le_bytes());
    // Time zone and daylight saving offsets 0, time flags 0: the start time is UTC.
    data.extend_from_slice(&[0; 8]);
    data.extend_from_slice(&0f64.to_le_bytes()); // start angle
    data.extend_from_slice(&0f64.to_le_bytes()); // start distance
    block(b"##HD", &links, &data)
}

impl<W: Write + Seek> Mf4Writer<W> {
    fn group(&mut self, kind: Kind) -> &mut GroupOut {
        match kind {
            Kind::Data => &mut self.groups.0,
            Kind::Error => &mut self.groups.1,
            Kind::Remote => &mut self.groups.2,
        }
    }

    /// The records of `slot` (a decoded group that does not exist has none: an empty one).
    fn slot(&mut self, slot: Slot) -> Option<&mut GroupOut> {
        match slot {
            Slot::Raw(kind) => Some(self.group(kind)),
            Slot::Decoded(i) => self.decoded.get_mut(i).map(|d| &mut d.out),
        }
    }

    /// Add a data group of decoded values, a message's (time, then one 64-bit float channel a
    /// column): its number for [`Mf4Writer::write_decoded`].
    pub fn add_decoded_group(&mut self, name: &str, columns: Vec<Column>) -> usize {
        self.decoded.push(DecodedOut {
            name: name.to_string(),
            columns,
            out: GroupOut::default(),
            channels: None,
        });
        self.decoded.len() - 1
    }

    /// Write one row of a decoded group: the frame's time and a value a column (NaN where a
    /// signal is absent, as a multiplexed one is). A row of the wrong width is refused.
    pub fn write_decoded(
        &mut self,
        group: usize,
        timestamp: Timestamp,
        values: &[f64],
    ) -> io::Result<()> {
        let at = timestamp.as_nanos();
        let start = *self.start.get_or_insert(at - at % 1_000);
        let invalid = || io::Error::new(io::ErrorKind::InvalidInput, "no such decoded group");
        let out = self.decoded.get_mut(group).ok_or_else(invalid)?;
        if values.len() != out.columns.len() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{} values for {} columns of {}",
                    values.len(),
                    out.columns.len(),
                    out.name
                ),
            ));
        }
        #[allow(clippy::cast_precision_loss)]
        let seconds = (i128::from(at) - i128::from(start)) as f64 / 1e9;
        out.out.records.extend_from_slice(&seconds.to_le_bytes());
        for v in values {
            out.out.records.extend_from_slice(&v.to_le_bytes());
        }
        out.out.count += 1;
        if out.out.records.len() >= DECODED_BLOCK_SIZE {
            self.flush(Slot::Decoded(group))?;
        }
        Ok(())
    }

    /// A writer to `out` (the identification and a placeholder header are written now).
    pub fn new(mut out: W) -> io::Result<Self> {
        out.write_all(&identification(false))?;
        out.write_all(&header([0; 6], 0))?;
        Ok(Mf4Writer {
            out,
            at: HEADER_AT + HEADER_LEN,
            start: None,
            groups: Default::default(),
            channels: BTreeMap::new(),
            fixed: None,
            decoded: Vec::new(),
        })
    }

    /// Write one record.
    pub fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        let at = record.timestamp.as_nanos();
        // The header's start time in whole microseconds (what asammdf's datetime keeps).
        let start = *self.start.get_or_insert(at - at % 1_000);
        let channel =
            crate::fields::channel_number(&mut self.channels, &record.interface).saturating_sub(1);
        let dir = u8::from(record.direction == Some('T'));
        // (kind, identifier, DLC, data, FD's BRS and ESI)
        let (kind, id, dlc, data, fd) = match &record.frame {
            Frame::Classic(f) if f.is_remote() => {
                (Kind::Remote, Some(f.id()), f.dlc(), &[][..], None)
            }
            Frame::Classic(f) => (Kind::Data, Some(f.id()), f.dlc(), f.data(), None),
            Frame::Fd(f) => (
                Kind::Data,
                Some(f.id()),
                f.dlc(),
                f.data(),
                Some((f.brs(), f.esi())),
            ),
            // The SocketCAN class in the identifier's place.
            Frame::Error(f) => (Kind::Error, None, Dlc::from_nibble(8), f.data(), None),
        };
        let (id, extended) = match (id, &record.frame) {
            (Some(id), _) => (id.as_raw(), id.is_extended()),
            (None, Frame::Error(f)) => (f.class_bits(), false),
            (None, _) => (0, false),
        };
        let (edl, brs, esi) = fd.map_or((false, false, false), |(brs, esi)| (true, brs, esi));
        #[allow(clippy::cast_precision_loss)]
        let seconds = (i128::from(at) - i128::from(start)) as f64 / 1e9;
        let group = self.group(kind);
        let mut row = [0u8; 84];
        row[..8].copy_from_slice(&seconds.to_le_bytes());
        row[8] = u8::try_from(channel).unwrap_or(u8::MAX);
        row[9..13].copy_from_slice(&id.to_le_bytes());
        row[13] = u8::from(extended);
        row[14] = dlc.as_raw();
        row[15] = u8::try_from(data.len()).unwrap_or(64);
        match kind {
            Kind::Remote => row[16] = dir,
            Kind::Data | Kind::Error => {
                for (slot, byte) in row[16..80].iter_mut().zip(data) {
                    *slot = *byte;
                }
                row[80..84].copy_from_slice(&[dir, u8::from(edl), u8::from(brs), u8::from(esi)]);
            }
        }
        group
            .records
            .extend_from_slice(row.get(..kind.record_len()).unwrap_or(&row));
        group.count += 1;
        if group.records.len() >= BLOCK_SIZE {
            self.flush(Slot::Raw(kind))?;
        }
        Ok(())
    }

    /// Write `bytes` at the end, 8-byte aligned; its offset.
    fn append(&mut self, bytes: &[u8]) -> io::Result<u64> {
        let at = self.at;
        self.out.write_all(bytes)?;
        let padding = (8 - bytes.len() % 8) % 8;
        self.out.write_all(&vec![0; padding])?;
        self.at += (bytes.len() + padding) as u64;
        Ok(at)
    }

    fn flush(&mut self, slot: Slot) -> io::Result<()> {
        let records = self
            .slot(slot)
            .map(|g| std::mem::take(&mut g.records))
            .unwrap_or_default();
        if records.is_empty() {
            return Ok(());
        }
        let mut head = Vec::with_capacity(24);
        head.extend_from_slice(b"##DT\0\0\0\0");
        head.extend_from_slice(&(24 + records.len() as u64).to_le_bytes());
        head.extend_from_slice(&0u64.to_le_bytes());
        let at = self.at;
        self.out.write_all(&head)?;
        self.at += 24;
        self.append(&records)?;
        let len = records.len() as u64;
        if let Some(group) = self.slot(slot) {
            group.blocks.push((at, len));
            // The buffer is reused: its capacity stays.
            let mut records = records;
            records.clear();
            group.records = records;
        }
        Ok(())
    }

    fn text(&mut self, name: &[u8; 4], text: &str) -> io::Result<u64> {
        let mut data = text.as_bytes().to_vec();
        data.push(0);
        self.append(&block(name, &[], &data))
    }

    /// The channels of `kind` (its time channel, then the structure of components) and its
    /// acquisition name: (first channel, name).
    fn write_channels(&mut self, kind: Kind) -> io::Result<(u64, u64)> {
        // The components, last first (each links to the next).
        let mut next_component = 0;
        for (name, offset, bytes, data_type) in kind.components().iter().rev() {
            let name = self.text(b"##TX", &format!("{}.{name}", kind.name()))?;
            next_component = self.append(&channel(
                [next_component, 0, name, 0],
                (0, 0),
                *data_type,
                *offset,
                bytes * 8,
            ))?;
        }
        let structure_name = self.text(b"##TX", kind.name())?;
        let record_len = u32::try_from(kind.record_len()).unwrap_or(0);
        let structure = self.append(&channel(
            [0, next_component, structure_name, 0],
            (0, 0),
            DT_BYTES,
            8,
            (record_len - 8) * 8,
        ))?;
        let time_name = self.text(b"##TX", "Timestamp")?;
        let unit = self.text(b"##TX", "s")?;
        let time = self.append(&channel(
            [structure, 0, time_name, unit],
            (CN_MASTER, SYNC_TIME),
            DT_FLOAT_LE,
            0,
            64,
        ))?;
        let acquisition = self.text(b"##TX", kind.name())?;
        Ok((time, acquisition))
    }

    /// The blocks shared by every checkpoint (written at the first).
    fn fixed(&mut self) -> io::Result<Fixed> {
        if let Some(fixed) = self.fixed {
            return Ok(fixed);
        }
        let bus = self.text(b"##TX", "CAN")?;
        let mut si = [0u8; 8];
        si[0] = SOURCE_BUS;
        si[1] = BUS_CAN;
        let source = self.append(&block(b"##SI", &[bus, bus, 0], &si))?;
        let mut channels = [(0, 0); 3];
        for (slot, kind) in channels.iter_mut().zip(Kind::ALL) {
            *slot = self.write_channels(kind)?;
        }
        let comment = format!(
            "<FHcomment><TX>CAN bus log</TX><tool_id>bywire</tool_id><tool_vendor>bywire</tool_vendor><tool_version>{}</tool_version></FHcomment>",
            env!("CARGO_PKG_VERSION")
        );
        let comment = self.text(b"##MD", &comment)?;
        let mut fh = Vec::with_capacity(16);
        fh.extend_from_slice(&self.start.unwrap_or(0).to_le_bytes());
        fh.extend_from_slice(&[0; 8]);
        let history = self.append(&block(b"##FH", &[0, comment], &fh))?;
        let fixed = Fixed {
            source,
            history,
            channels,
        };
        self.fixed = Some(fixed);
        Ok(fixed)
    }

    /// The channel group of `kind` with its count and data list so far: the data group's
    /// offset.
    fn write_group(
        &mut self,
        kind: Kind,
        next: u64,
        fixed: &Fixed,
        index: usize,
    ) -> io::Result<u64> {
        let (count, data) = self.data_link(Slot::Raw(kind))?;
        let (time, acquisition) = fixed.channels.get(index).copied().unwrap_or_default();
        let record_len = u32::try_from(kind.record_len()).unwrap_or(0);
        let mut cg = Vec::with_capacity(32);
        cg.extend_from_slice(&0u64.to_le_bytes()); // record ID
        cg.extend_from_slice(&count.to_le_bytes());
        cg.extend_from_slice(&(CG_BUS_EVENT | CG_PLAIN_BUS_EVENT).to_le_bytes());
        cg.extend_from_slice(&u16::from(b'.').to_le_bytes());
        cg.extend_from_slice(&[0; 4]);
        cg.extend_from_slice(&record_len.to_le_bytes());
        cg.extend_from_slice(&0u32.to_le_bytes());
        let cg = self.append(&block(
            b"##CG",
            &[0, time, acquisition, fixed.source, 0, 0],
            &cg,
        ))?;
        self.append(&block(b"##DG", &[next, cg, data, 0], &[0; 8]))
    }

    /// A group's record count and the link to its data: its one block, or a list of them.
    fn data_link(&mut self, slot: Slot) -> io::Result<(u64, u64)> {
        let (count, blocks) = match self.slot(slot) {
            Some(group) => (group.count, group.blocks.clone()),
            None => (0, Vec::new()),
        };
        let data = match blocks.as_slice() {
            [] => 0,
            [(one, _)] => *one,
            many => {
                let mut data = Vec::with_capacity(8 + 8 * many.len());
                data.extend_from_slice(&[0; 4]); // flags: each block's offset listed
                data.extend_from_slice(
                    &u32::try_from(many.len()).unwrap_or(u32::MAX).to_le_bytes(),
                );
                let mut offset = 0u64;
                for (_, len) in many {
                    data.extend_from_slice(&offset.to_le_bytes());
                    offset += len;
                }
                let mut links = vec![0u64];
                links.extend(many.iter().map(|(at, _)| *at));
                self.append(&block(b"##DL", &links, &data))?
            }
        };
        Ok((count, data))
    }

    /// A decoded group's channels (time, then a float a column, each with its unit and value
    /// names), written once: (first channel, acquisition name).
    fn decoded_channels(&mut self, group: usize) -> io::Result<(u64, u64)> {
        let Some(decoded) = self.decoded.get(group) else {
            return Ok((0, 0));
        };
        if let Some(channels) = decoded.channels {
            return Ok(channels);
        }
        let (name, columns) = (decoded.name.clone(), decoded.columns.clone());
        let mut next = 0;
        for (i, column) in columns.iter().enumerate().rev() {
            let name = self.text(b"##TX", &column.name)?;
            let unit = match column.unit.is_empty() {
                true => 0,
                false => self.text(b"##TX", &column.unit)?,
            };
            let conversion = self.value_names(&column.value_names)?;
            let offset = u32::try_from(8 + 8 * i).unwrap_or(u32::MAX);
            next = self.append(&channel_converted(
                [next, 0, name, unit],
                conversion,
                (0, 0),
                DT_FLOAT_LE,
                offset,
                64,
            ))?;
        }
        let time_name = self.text(b"##TX", "time")?;
        let unit = self.text(b"##TX", "s")?;
        let time = self.append(&channel(
            [next, 0, time_name, unit],
            (CN_MASTER, SYNC_TIME),
            DT_FLOAT_LE,
            0,
            64,
        ))?;
        let acquisition = self.text(b"##TX", &name)?;
        if let Some(decoded) = self.decoded.get_mut(group) {
            decoded.channels = Some((time, acquisition));
        }
        Ok((time, acquisition))
    }

    /// A value-to-text conversion (`##CC` of type 7) naming these values; 0 when none.
    fn value_names(&mut self, names: &[(f64, String)]) -> io::Result<u64> {
        if names.is_empty() {
            return Ok(0);
        }
        let mut links = vec![0u64; 4]; // name, unit, comment, inverse
        for (_, text) in names {
            links.push(self.text(b"##TX", text)?);
        }
        links.push(0); // no default text: other values stay numbers
        let count = u16::try_from(names.len()).unwrap_or(u16::MAX);
        let mut data = Vec::with_capacity(24 + 8 * names.len());
        data.extend_from_slice(&[CC_VALUE_TO_TEXT, 0, 0, 0]); // type, precision, flags
        data.extend_from_slice(&count.saturating_add(1).to_le_bytes());
        data.extend_from_slice(&count.to_le_bytes());
        data.extend_from_slice(&0f64.to_le_bytes()); // physical range (not given)
        data.extend_from_slice(&0f64.to_le_bytes());
        for (value, _) in names {
            data.extend_from_slice(&value.to_le_bytes());
        }
        self.append(&block(b"##CC", &links, &data))
    }

    /// A decoded group's data group: its channels, count and data.
    fn write_decoded_group(&mut self, group: usize, next: u64) -> io::Result<u64> {
        let (time, acquisition) = self.decoded_channels(group)?;
        let (count, data) = self.data_link(Slot::Decoded(group))?;
        let columns = self.decoded.get(group).map_or(0, |d| d.columns.len());
        let record_len = u32::try_from(8 + 8 * columns).unwrap_or(u32::MAX);
        let mut cg = Vec::with_capacity(32);
        cg.extend_from_slice(&0u64.to_le_bytes()); // record ID
        cg.extend_from_slice(&count.to_le_bytes());
        cg.extend_from_slice(&0u16.to_le_bytes()); // flags: plain values
        cg.extend_from_slice(&u16::from(b'.').to_le_bytes());
        cg.extend_from_slice(&[0; 4]);
        cg.extend_from_slice(&record_len.to_le_bytes());
        cg.extend_from_slice(&0u32.to_le_bytes());
        let cg = self.append(&block(b"##CG", &[0, time, acquisition, 0, 0, 0], &cg))?;
        self.append(&block(b"##DG", &[next, cg, data, 0], &[0; 8]))
    }

    /// The header's comment: each bus channel's interface name (`BusChannel` holds numbers,
    /// as python-can writes them), so names come back when the file is read.
    fn channel_names(&mut self) -> io::Result<u64> {
        let mut text = String::from("<HDcomment><TX>CAN bus log</TX><common_properties>");
        for (name, number) in &self.channels {
            text.push_str(&format!(
                "<e name=\"{CHANNEL_NAME}{}\">{}</e>",
                number.saturating_sub(1),
                xml_escape(name)
            ));
        }
        text.push_str("</common_properties></HDcomment>");
        self.text(b"##MD", &text)
    }

    /// Make the file complete as it stands, and go on writing after: the records so far are
    /// written, then new groups that list them, then the header is pointed at those groups.
    /// Everything is appended, and the header's links are the last thing to change, so a file
    /// cut short at any moment (a kill, a power loss) still reads up to its last checkpoint.
    /// Each checkpoint costs a few hundred bytes plus the data lists (8 bytes a data block).
    pub fn checkpoint(&mut self) -> io::Result<()> {
        for kind in Kind::ALL {
            self.flush(Slot::Raw(kind))?;
        }
        for group in 0..self.decoded.len() {
            self.flush(Slot::Decoded(group))?;
        }
        let fixed = self.fixed()?;
        let mut next = 0;
        // The decoded groups after the frames' groups.
        for group in (0..self.decoded.len()).rev() {
            next = self.write_decoded_group(group, next)?;
        }
        for (index, kind) in Kind::ALL.iter().enumerate().rev() {
            next = self.write_group(*kind, next, &fixed, index)?;
        }
        let names = self.channel_names()?;
        let start = self.start.unwrap_or(0);
        self.out.seek(SeekFrom::Start(HEADER_AT))?;
        self.out
            .write_all(&header([next, fixed.history, 0, 0, 0, names], start))?;
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&identification(true))?;
        self.out.seek(SeekFrom::Start(self.at))?;
        self.out.flush()
    }

    /// Write the groups, the history and the header's links; the output back.
    pub fn finish(mut self) -> io::Result<W> {
        self.checkpoint()?;
        Ok(self.out)
    }
}

/// A channel block with no conversion or comment: links (next, composition, name, unit),
/// (channel type, sync type).
fn channel(
    links: [u64; 4],
    (kind, sync): (u8, u8),
    data_type: u8,
    byte_offset: u32,
    bits: u32,
) -> Vec<u8> {
    channel_converted(links, 0, (kind, sync), data_type, byte_offset, bits)
}

/// A channel block with a conversion (0 for none).
fn channel_converted(
    links: [u64; 4],
    conversion: u64,
    (kind, sync): (u8, u8),
    data_type: u8,
    byte_offset: u32,
    bits: u32,
) -> Vec<u8> {
    let [next, composition, name, unit] = links;
    let mut data = Vec::with_capacity(72);
    data.extend_from_slice(&[kind, sync, data_type, 0]);
    data.extend_from_slice(&byte_offset.to_le_bytes());
    data.extend_from_slice(&bits.to_le_bytes());
    data.extend_from_slice(&0u32.to_le_bytes()); // flags
    data.extend_from_slice(&0u32.to_le_bytes()); // invalidation bit
    data.extend_from_slice(&[0, 0, 0, 0]); // precision, reserved, attachments
    data.extend_from_slice(&[0; 48]); // ranges and limits
    block(
        b"##CN",
        &[next, composition, name, 0, conversion, 0, unit, 0],
        &data,
    )
}

// ---------------------------------------------------------------------------------------------
// Reading

fn malformed(offset: u64, what: impl Into<String>) -> LogError {
    LogError::Binary {
        offset,
        what: what.into(),
    }
}

fn io_error(offset: u64, e: &io::Error) -> LogError {
    malformed(offset, format!("cannot be read: {e}"))
}

/// A block read whole (metadata: small by nature).
struct Block {
    name: [u8; 4],
    links: Vec<u64>,
    data: Vec<u8>,
}

fn read_block<R: Read + Seek>(file: &mut R, at: u64) -> Result<Block, LogError> {
    let mut head = [0u8; 24];
    file.seek(SeekFrom::Start(at))
        .and_then(|_| file.read_exact(&mut head))
        .map_err(|e| io_error(at, &e))?;
    if &head[..2] != b"##" {
        return Err(malformed(
            at,
            "no block here (a link points outside the blocks)",
        ));
    }
    let length = u64_at(&head, 8).unwrap_or(0);
    let links = u64_at(&head, 16).unwrap_or(0);
    if !(24..=MAX_BLOCK).contains(&length) || links > (length - 24) / 8 {
        return Err(malformed(
            at,
            format!("a block of {length} bytes with {links} links"),
        ));
    }
    let mut rest = vec![0u8; usize::try_from(length - 24).unwrap_or(0)];
    file.read_exact(&mut rest)
        .map_err(|_| malformed(at, format!("a block of {length} bytes cut short")))?;
    let split = usize::try_from(links * 8).unwrap_or(0);
    let data = rest.split_off(split);
    let links = rest
        .chunks_exact(8)
        .map(|c| u64_at(c, 0).unwrap_or(0))
        .collect();
    let mut name = [0u8; 4];
    name.copy_from_slice(&head[..4]);
    Ok(Block { name, links, data })
}

fn link(block: &Block, index: usize) -> u64 {
    block.links.get(index).copied().unwrap_or(0)
}

/// The text of a `##TX` or `##MD` block (empty when there is none).
fn read_text<R: Read + Seek>(file: &mut R, at: u64) -> Result<String, LogError> {
    if at == 0 {
        return Ok(String::new());
    }
    let block = read_block(file, at)?;
    if &block.name != b"##TX" && &block.name != b"##MD" {
        return Err(malformed(at, "a name that is not a text block"));
    }
    let end = block
        .data
        .iter()
        .position(|b| *b == 0)
        .unwrap_or(block.data.len());
    Ok(String::from_utf8_lossy(block.data.get(..end).unwrap_or(&[])).into_owned())
}

/// Where a value sits in a record.
#[derive(Debug, Clone, Copy)]
struct Field {
    byte: usize,
    bit: u32,
    bits: u32,
    data_type: u8,
}

impl Field {
    /// An integer value (unsigned, or signed read as its bits), up to 64 bits.
    fn integer(&self, record: &[u8]) -> Option<u64> {
        // (A bit offset is 0 to 7: more is a byte offset.)
        if self.bits == 0 || self.bits > 64 || self.bit > 7 {
            return None;
        }
        let span = usize::try_from((self.bit + self.bits).div_ceil(8)).ok()?;
        let bytes = record.get(self.byte..self.byte + span)?;
        let mut raw = 0u128;
        match self.data_type {
            DT_UNSIGNED_BE | DT_SIGNED_BE => {
                for b in bytes {
                    raw = raw << 8 | u128::from(*b);
                }
                raw >>= u32::try_from(span * 8).unwrap_or(0) - self.bit - self.bits;
            }
            _ => {
                for b in bytes.iter().rev() {
                    raw = raw << 8 | u128::from(*b);
                }
                raw >>= self.bit;
            }
        }
        let mask = if self.bits == 64 {
            u64::MAX
        } else {
            (1u64 << self.bits) - 1
        };
        Some(u64::try_from(raw & u128::from(mask)).unwrap_or(0))
    }

    /// A number: a float, or an integer (signed ones sign-extended).
    #[allow(clippy::cast_precision_loss, clippy::cast_possible_wrap)]
    fn number(&self, record: &[u8]) -> Option<f64> {
        let bytes = |n: usize| record.get(self.byte..self.byte + n);
        match (self.data_type, self.bits) {
            (DT_FLOAT_LE, 64) => Some(f64::from_le_bytes(bytes(8)?.try_into().ok()?)),
            (DT_FLOAT_BE, 64) => Some(f64::from_be_bytes(bytes(8)?.try_into().ok()?)),
            (DT_FLOAT_LE, 32) => Some(f64::from(f32::from_le_bytes(bytes(4)?.try_into().ok()?))),
            (DT_FLOAT_BE, 32) => Some(f64::from(f32::from_be_bytes(bytes(4)?.try_into().ok()?))),
            (DT_SIGNED_LE | DT_SIGNED_BE, bits) => {
                let raw = self.integer(record)?;
                let shift = 64 - bits;
                Some(((raw << shift) as i64 >> shift) as f64)
            }
            (DT_UNSIGNED_LE | DT_UNSIGNED_BE, _) => self.integer(record).map(|v| v as f64),
            _ => None,
        }
    }

    /// A byte array's (or string's) bytes.
    fn bytes<'a>(&self, record: &'a [u8]) -> Option<&'a [u8]> {
        let len = usize::try_from(self.bits / 8).ok()?;
        record.get(self.byte..self.byte + len)
    }

    /// A flag: nonzero, or for a text (`Tx`, `Rx`) whether it is `on`.
    fn flag(&self, record: &[u8], on: &[u8]) -> Option<bool> {
        match self.data_type {
            DT_STRING_LATIN1 | DT_STRING_UTF8 | DT_BYTES => {
                Some(self.bytes(record)?.starts_with(on))
            }
            _ => self.integer(record).map(|v| v != 0),
        }
    }
}

/// A channel as read: its name, type and place.
struct ChannelInfo {
    name: String,
    kind: u8,
    sync: u8,
    field: Field,
    conversion: u64,
}

/// The time channel: seconds from the header's start as `a + b × value`.
#[derive(Debug, Clone, Copy)]
struct Time {
    field: Field,
    linear: (f64, f64),
}

/// A channel group of CAN frames: where each component sits.
#[derive(Debug, Clone)]
struct FrameLayout {
    kind: Kind,
    time: Time,
    bus_channel: Option<Field>,
    id: Field,
    ide: Option<Field>,
    dlc: Option<Field>,
    data_length: Option<Field>,
    data_bytes: Option<Field>,
    dir: Option<Field>,
    edl: Option<Field>,
    brs: Option<Field>,
    esi: Option<Field>,
}

/// What the records of one channel group are to the reader.
#[derive(Debug, Clone)]
enum Records {
    /// CAN frames, `len` bytes a record.
    Frames(Box<FrameLayout>, usize),
    /// Anything else of fixed length, passed over.
    Other(usize),
    /// Variable-length records (a length, then the bytes), passed over.
    Variable,
}

/// A part of a data group's bytes.
#[derive(Debug, Clone, Copy)]
enum Fragment {
    Plain {
        at: u64,
        len: u64,
    },
    Zipped {
        at: u64,
        len: u64,
        original: u64,
        columns: Option<u64>,
    },
}

/// A data group's bytes, a fragment at a time.
struct Stream {
    fragments: Vec<Fragment>,
    next: usize,
    /// Where the current plain fragment's next bytes are, and how many are left.
    plain: Option<(u64, u64)>,
    buffer: Vec<u8>,
    pos: usize,
    /// The offset of the fragment being read (for errors).
    offset: u64,
}

const READ_CHUNK: u64 = 256 * 1024;

impl Stream {
    fn new(fragments: Vec<Fragment>) -> Stream {
        Stream {
            fragments,
            next: 0,
            plain: None,
            buffer: Vec::new(),
            pos: 0,
            offset: 0,
        }
    }

    /// More bytes into the buffer; false at the end of the data.
    fn refill<R: Read + Seek>(&mut self, file: &mut R) -> Result<bool, LogError> {
        self.buffer.drain(..self.pos.min(self.buffer.len()));
        self.pos = 0;
        loop {
            if let Some((at, left)) = self.plain {
                if left > 0 {
                    let n = left.min(READ_CHUNK);
                    let start = self.buffer.len();
                    self.buffer
                        .resize(start + usize::try_from(n).unwrap_or(0), 0);
                    let slot = self.buffer.get_mut(start..).unwrap_or(&mut []);
                    file.seek(SeekFrom::Start(at))
                        .and_then(|_| file.read_exact(slot))
                        .map_err(|_| malformed(self.offset, "a data block cut short"))?;
                    self.plain = Some((at + n, left - n));
                    return Ok(true);
                }
                self.plain = None;
            }
            let Some(fragment) = self.fragments.get(self.next).copied() else {
                return Ok(false);
            };
            self.next += 1;
            match fragment {
                Fragment::Plain { at, len } => {
                    self.offset = at.saturating_sub(24);
                    self.plain = Some((at, len));
                }
                Fragment::Zipped {
                    at,
                    len,
                    original,
                    columns,
                } => {
                    self.offset = at.saturating_sub(48);
                    let unzipped = unzip(file, at, len, original, columns)
                        .map_err(|what| malformed(self.offset, what))?;
                    self.buffer.extend_from_slice(&unzipped);
                    return Ok(true);
                }
            }
        }
    }

    /// The next `n` bytes, or `None` at the end of the data (a record cut short is an error).
    fn take<R: Read + Seek>(&mut self, file: &mut R, n: usize) -> Result<Option<&[u8]>, LogError> {
        while self.buffer.len() - self.pos < n {
            let had = self.buffer.len() - self.pos;
            if !self.refill(file)? {
                if had == 0 {
                    return Ok(None);
                }
                return Err(malformed(
                    self.offset,
                    format!("the data ends inside a record ({had} of {n} bytes)"),
                ));
            }
        }
        let bytes = self.buffer.get(self.pos..self.pos + n);
        self.pos += n;
        Ok(bytes)
    }
}

/// A `##DZ` block's data unzipped (and transposed back).
fn unzip<R: Read + Seek>(
    file: &mut R,
    at: u64,
    len: u64,
    original: u64,
    columns: Option<u64>,
) -> Result<Vec<u8>, String> {
    if original > MAX_UNZIPPED || len > MAX_UNZIPPED {
        return Err(format!(
            "a zipped block of {original} bytes (at most {MAX_UNZIPPED})"
        ));
    }
    let mut zipped = vec![0u8; usize::try_from(len).unwrap_or(0)];
    file.seek(SeekFrom::Start(at))
        .and_then(|_| file.read_exact(&mut zipped))
        .map_err(|_| "a zipped block cut short".to_string())?;
    let mut data = Vec::with_capacity(usize::try_from(original).unwrap_or(0));
    ZlibDecoder::new(zipped.as_slice())
        .take(original + 1)
        .read_to_end(&mut data)
        .map_err(|e| format!("a zipped block that does not inflate: {e}"))?;
    if data.len() as u64 != original {
        return Err(format!(
            "a zipped block of {} bytes where it says {original}",
            data.len()
        ));
    }
    if let Some(columns) = columns
        .and_then(|c| usize::try_from(c).ok())
        .filter(|c| *c > 1)
    {
        let rows = data.len() / columns;
        let mut out = data.clone();
        for (i, byte) in data.iter().take(rows * columns).enumerate() {
            let (column, row) = (i / rows, i % rows);
            if let Some(slot) = out.get_mut(row * columns + column) {
                *slot = *byte;
            }
        }
        data = out;
    }
    Ok(data)
}

/// The fragments of the data linked at `at` (a block, or lists of them).
fn fragments<R: Read + Seek>(file: &mut R, at: u64) -> Result<Vec<Fragment>, LogError> {
    let mut out = Vec::new();
    let mut pending = vec![at];
    let mut seen = HashSet::new();
    while let Some(at) = pending.pop() {
        if at == 0 {
            continue;
        }
        if !seen.insert(at) || seen.len() > MAX_DATA_BLOCKS {
            return Err(malformed(at, "the data lists loop or are too many"));
        }
        let mut head = [0u8; 48];
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut head[..24]))
            .map_err(|e| io_error(at, &e))?;
        let length = u64_at(&head, 8).unwrap_or(0);
        if length < 24 {
            return Err(malformed(at, format!("a block of {length} bytes")));
        }
        match &head[..4] {
            b"##DT" | b"##RD" => out.push(Fragment::Plain {
                at: at + 24,
                len: length - 24,
            }),
            b"##DZ" => {
                file.read_exact(&mut head[24..48])
                    .map_err(|e| io_error(at, &e))?;
                let zip_type = head[26];
                let parameter = u32_at(&head, 28).unwrap_or(0);
                let original = u64_at(&head, 32).unwrap_or(0);
                let len = u64_at(&head, 40).unwrap_or(0);
                if &head[24..26] != b"DT" && &head[24..26] != b"RD" {
                    // Signal data or others: not records.
                    continue;
                }
                let columns = match zip_type {
                    0 => None,
                    1 => Some(u64::from(parameter)),
                    other => return Err(malformed(at, format!("zip type {other} (deflate only)"))),
                };
                if length < 48 || len > length - 48 {
                    return Err(malformed(at, "a zipped block longer than its block"));
                }
                out.push(Fragment::Zipped {
                    at: at + 48,
                    len,
                    original,
                    columns,
                });
            }
            b"##DL" => {
                let list = read_block(file, at)?;
                // Next list first on the stack's bottom: this list's blocks come before it.
                pending.push(link(&list, 0));
                pending.extend(list.links.iter().skip(1).rev());
            }
            b"##HL" => {
                let list = read_block(file, at)?;
                pending.push(link(&list, 0));
            }
            other => {
                return Err(malformed(
                    at,
                    format!(
                        "data in a {} block (not read)",
                        String::from_utf8_lossy(other)
                    ),
                ))
            }
        }
        if out.len() > MAX_DATA_BLOCKS {
            return Err(malformed(at, "more data blocks than a file holds"));
        }
    }
    Ok(out)
}

/// The channels of a group, components included.
fn channels<R: Read + Seek>(file: &mut R, first: u64) -> Result<Vec<ChannelInfo>, LogError> {
    let mut out = Vec::new();
    let mut pending = vec![(first, 0u8)];
    let mut seen = HashSet::new();
    while let Some((mut at, depth)) = pending.pop() {
        while at != 0 {
            if !seen.insert(at) || seen.len() > MAX_CHANNELS {
                return Err(malformed(at, "the channels loop or are too many"));
            }
            let block = read_block(file, at)?;
            if &block.name != b"##CN" {
                // A composition may be an array (##CA): its elements are not frames.
                break;
            }
            let d = &block.data;
            let (Some(kind), Some(sync), Some(data_type), Some(bit), Some(byte), Some(bits)) = (
                d.first(),
                d.get(1),
                d.get(2),
                d.get(3),
                u32_at(d, 4),
                u32_at(d, 8),
            ) else {
                return Err(malformed(at, "a channel block too short"));
            };
            out.push(ChannelInfo {
                name: read_text(file, link(&block, 2))?,
                kind: *kind,
                sync: *sync,
                field: Field {
                    byte: usize::try_from(byte).unwrap_or(usize::MAX),
                    bit: u32::from(*bit),
                    bits,
                    data_type: *data_type,
                },
                conversion: link(&block, 4),
            });
            let composition = link(&block, 1);
            if composition != 0 && depth < 4 {
                pending.push((composition, depth + 1));
            }
            at = link(&block, 0);
        }
    }
    Ok(out)
}

/// A master channel's conversion to seconds: identity or linear.
fn time_conversion<R: Read + Seek>(file: &mut R, at: u64) -> Result<(f64, f64), LogError> {
    if at == 0 {
        return Ok((0.0, 1.0));
    }
    let block = read_block(file, at)?;
    match block.data.first() {
        Some(0) => Ok((0.0, 1.0)),
        Some(1) => match (f64_at(&block.data, 24), f64_at(&block.data, 32)) {
            (Some(a), Some(b)) => Ok((a, b)),
            _ => Err(malformed(at, "a linear conversion without its two values")),
        },
        other => Err(malformed(
            at,
            format!("the time channel's conversion of type {other:?} (identity or linear only)"),
        )),
    }
}

/// What the records of a channel group are, from its channels.
fn layout<R: Read + Seek>(
    file: &mut R,
    at: u64,
    channels: &[ChannelInfo],
    len: usize,
) -> Result<Records, LogError> {
    let Some(kind) = Kind::ALL.into_iter().find(|k| {
        channels
            .iter()
            .any(|c| c.name == k.name() || c.name.starts_with(&format!("{}.", k.name())))
    }) else {
        return Ok(Records::Other(len));
    };
    let prefix = format!("{}.", kind.name());
    let component = |name: &str| {
        channels
            .iter()
            .find(|c| c.name.strip_prefix(&prefix) == Some(name))
            .map(|c| (c.field, c.kind))
    };
    let fixed = |name: &str| -> Result<Option<Field>, LogError> {
        match component(name) {
            Some((_, 1)) => Err(malformed(
                at,
                format!("{prefix}{name} as variable-length signal data (not read)"),
            )),
            Some((field, _)) => Ok(Some(field)),
            None => Ok(None),
        }
    };
    let Some(master) = channels
        .iter()
        .find(|c| c.kind == CN_MASTER && c.sync == SYNC_TIME)
    else {
        return Err(malformed(
            at,
            format!("{} frames without a time channel", kind.name()),
        ));
    };
    if channels
        .iter()
        .any(|c| c.kind == CN_VIRTUAL_MASTER && c.sync == SYNC_TIME)
    {
        return Err(malformed(at, "a virtual time channel (not read)"));
    }
    let time = Time {
        field: master.field,
        linear: time_conversion(file, master.conversion)?,
    };
    let id = match (kind, fixed("ID")?) {
        (_, Some(id)) => id,
        (Kind::Error, None) => Field {
            byte: 0,
            bit: 0,
            bits: 0,
            data_type: DT_UNSIGNED_LE,
        },
        (_, None) => return Err(malformed(at, format!("{prefix}ID is missing"))),
    };
    let layout = FrameLayout {
        kind,
        time,
        bus_channel: fixed("BusChannel")?,
        id,
        ide: fixed("IDE")?,
        dlc: fixed("DLC")?,
        data_length: fixed("DataLength")?,
        data_bytes: fixed("DataBytes")?,
        dir: fixed("Dir")?,
        edl: fixed("EDL")?,
        brs: fixed("BRS")?,
        esi: fixed("ESI")?,
    };
    if kind == Kind::Data && layout.data_bytes.is_none() {
        return Err(malformed(at, format!("{prefix}DataBytes is missing")));
    }
    Ok(Records::Frames(Box::new(layout), len))
}

/// One data group being read.
struct GroupReader {
    stream: Stream,
    id_size: usize,
    groups: BTreeMap<u64, Records>,
    /// Records left, for a sorted group (its channel group's count).
    left: Option<u64>,
    /// The data group's offset (for errors), and records read.
    at: u64,
    read: u64,
}

/// Reads an MF4 bus log's frames in time order (see the [module](self)).
pub struct Mf4Reader<R: Read + Seek> {
    file: R,
    start: u64,
    /// Interface names by bus channel, from the header's comment.
    names: BTreeMap<u64, String>,
    groups: Vec<GroupReader>,
    heads: Vec<Option<LogRecord>>,
    started: bool,
    error: Option<LogError>,
    failed: bool,
}

impl<R: Read + Seek> std::fmt::Debug for Mf4Reader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mf4Reader")
            .field("start", &self.start)
            .field("groups", &self.groups.len())
            .finish()
    }
}

impl<R: Read + Seek> Mf4Reader<R> {
    /// Open an MF4 file: its identification, header and groups (not yet their data).
    pub fn open(mut file: R) -> Result<Self, LogError> {
        let mut id = [0u8; 64];
        file.seek(SeekFrom::Start(0))
            .and_then(|_| file.read_exact(&mut id))
            .map_err(|_| malformed(0, "shorter than an MDF identification block"))?;
        if &id[..8] != b"MDF     " && &id[..8] != b"UnFinMF " {
            return Err(malformed(0, "not an MDF file (no MDF identification)"));
        }
        let version = u16_at(&id, 28).unwrap_or(0);
        if version < 400 {
            return Err(malformed(
                28,
                format!("MDF version {version} (4.00 and later are read)"),
            ));
        }
        let header = read_block(&mut file, HEADER_AT)?;
        if &header.name != b"##HD" {
            return Err(malformed(
                HEADER_AT,
                "no header block after the identification",
            ));
        }
        let start = start_time(&header.data);
        // A comment that cannot be read names no channel: the frames are what matter.
        let names = match link(&header, 5) {
            0 => BTreeMap::new(),
            at => read_text(&mut file, at)
                .map(|text| channel_names(&text))
                .unwrap_or_default(),
        };
        let mut groups = Vec::new();
        let mut seen = HashSet::new();
        let mut at = link(&header, 0);
        while at != 0 {
            if !seen.insert(at) || seen.len() > MAX_GROUPS {
                return Err(malformed(at, "the data groups loop or are too many"));
            }
            let dg = read_block(&mut file, at)?;
            if &dg.name != b"##DG" {
                return Err(malformed(at, "a data group link to another block"));
            }
            let id_size = usize::from(dg.data.first().copied().unwrap_or(0));
            if ![0, 1, 2, 4, 8].contains(&id_size) {
                return Err(malformed(at, format!("record IDs of {id_size} bytes")));
            }
            if let Some(group) = Self::group(&mut file, at, &dg, id_size)? {
                groups.push(group);
            }
            at = link(&dg, 0);
        }
        let heads = vec![None; groups.len()];
        Ok(Mf4Reader {
            file,
            start,
            names,
            groups,
            heads,
            started: false,
            error: None,
            failed: false,
        })
    }

    /// A data group's reader, if it holds CAN frames.
    fn group(
        file: &mut R,
        at: u64,
        dg: &Block,
        id_size: usize,
    ) -> Result<Option<GroupReader>, LogError> {
        let mut groups = BTreeMap::new();
        let mut seen = HashSet::new();
        let mut cg_at = link(dg, 1);
        let mut cycles = 0u64;
        let mut channel_groups = 0;
        let mut any_frames = false;
        while cg_at != 0 {
            if !seen.insert(cg_at) || seen.len() > MAX_GROUPS {
                return Err(malformed(cg_at, "the channel groups loop or are too many"));
            }
            let cg = read_block(file, cg_at)?;
            if &cg.name != b"##CG" {
                return Err(malformed(cg_at, "a channel group link to another block"));
            }
            let d = &cg.data;
            let (Some(record_id), Some(count), Some(flags), Some(data_bytes), Some(inval)) = (
                u64_at(d, 0),
                u64_at(d, 8),
                u16_at(d, 16),
                u32_at(d, 24),
                u32_at(d, 28),
            ) else {
                return Err(malformed(cg_at, "a channel group block too short"));
            };
            let len = u64::from(data_bytes) + u64::from(inval);
            if len > MAX_RECORD {
                return Err(malformed(cg_at, format!("records of {len} bytes")));
            }
            let len = usize::try_from(len).unwrap_or(0);
            let records = if flags & CG_VLSD != 0 {
                Records::Variable
            } else {
                let list = channels(file, link(&cg, 1))?;
                layout(file, cg_at, &list, len)?
            };
            any_frames |= matches!(records, Records::Frames(..));
            cycles = count;
            channel_groups += 1;
            // Without record IDs the one channel group's ID is not in the data.
            groups.insert(if id_size == 0 { 0 } else { record_id }, records);
            cg_at = link(&cg, 0);
        }
        if !any_frames {
            return Ok(None);
        }
        let sorted = id_size == 0;
        if sorted && channel_groups > 1 {
            return Err(malformed(at, "several channel groups without record IDs"));
        }
        Ok(Some(GroupReader {
            stream: Stream::new(fragments(file, link(dg, 2))?),
            id_size,
            groups,
            left: sorted.then_some(cycles),
            at,
            read: 0,
        }))
    }

    /// The next frame of group `index`.
    fn next_of(&mut self, index: usize) -> Result<Option<LogRecord>, LogError> {
        let start = self.start;
        let Some(GroupReader {
            stream,
            id_size,
            groups,
            left,
            at,
            read,
        }) = self.groups.get_mut(index)
        else {
            return Ok(None);
        };
        let file = &mut self.file;
        loop {
            if *left == Some(0) {
                return Ok(None);
            }
            let record_id = if *id_size == 0 {
                0
            } else {
                let Some(bytes) = stream.take(file, *id_size)? else {
                    return Ok(None);
                };
                let mut raw = [0u8; 8];
                for (slot, b) in raw.iter_mut().zip(bytes) {
                    *slot = *b;
                }
                u64::from_le_bytes(raw)
            };
            let Some(records) = groups.get(&record_id) else {
                return Err(malformed(
                    stream.offset,
                    format!("record ID {record_id} of no channel group (data group at {at})"),
                ));
            };
            let (layout, len) = match records {
                Records::Frames(layout, len) => (Some(layout), *len),
                Records::Other(len) => (None, *len),
                Records::Variable => {
                    let Some(bytes) = stream.take(file, 4)? else {
                        return Ok(None);
                    };
                    let len = u32_at(bytes, 0).unwrap_or(0);
                    if u64::from(len) > MAX_RECORD {
                        return Err(malformed(
                            stream.offset,
                            format!("variable-length data of {len} bytes"),
                        ));
                    }
                    (None, usize::try_from(len).unwrap_or(0))
                }
            };
            let offset = stream.offset;
            let Some(record) = stream.take(file, len)? else {
                return Err(malformed(offset, "the data ends before its records"));
            };
            let Some(layout) = layout else {
                continue;
            };
            *left = left.map(|n| n - 1);
            *read += 1;
            let n = *read;
            return decode(layout, record, start, &self.names)
                .map(Some)
                .map_err(|what| malformed(*at, format!("frame {n}: {what}")));
        }
    }
}

/// The header's start time as nanoseconds since the Unix epoch, UTC.
fn start_time(hd: &[u8]) -> u64 {
    let ns = u64_at(hd, 0).unwrap_or(0);
    let minutes = |at: usize| {
        hd.get(at..at + 2)
            .and_then(|b| b.try_into().ok())
            .map_or(0, |b| i64::from(i16::from_le_bytes(b)))
    };
    let (tz, dst) = (minutes(8), minutes(10));
    let flags = hd.get(12).copied().unwrap_or(0);
    // Local time with its offsets given: back to UTC.
    if flags & 1 != 0 && flags & 2 != 0 {
        let offset = (tz + dst) * 60_000_000_000;
        return u64::try_from(i128::from(ns) - i128::from(offset)).unwrap_or(0);
    }
    ns
}

/// A record of a frame group as a log record.
fn decode(
    layout: &FrameLayout,
    record: &[u8],
    start: u64,
    names: &BTreeMap<u64, String>,
) -> Result<LogRecord, String> {
    let value = |f: Option<Field>| f.and_then(|f| f.integer(record));
    let flag = |f: Option<Field>| f.and_then(|f| f.flag(record, b"1")).unwrap_or(false);
    let seconds = layout
        .time
        .field
        .number(record)
        .map(|raw| layout.time.linear.0 + layout.time.linear.1 * raw)
        .filter(|s| s.is_finite())
        .ok_or("no time")?;
    #[allow(clippy::cast_possible_truncation)]
    let offset = (seconds * 1e9).round().clamp(-9.0e18, 9.0e18) as i64;
    let timestamp =
        Timestamp::from_nanos(u64::try_from(i128::from(start) + i128::from(offset)).unwrap_or(0));
    let channel = value(layout.bus_channel).unwrap_or(0);
    let direction = layout
        .dir
        .and_then(|f| f.flag(record, b"Tx"))
        .map(|tx| if tx { 'T' } else { 'R' });
    let raw_id = layout.id.integer(record).unwrap_or(0);
    let frame = match layout.kind {
        Kind::Error => {
            let class = u32::try_from(raw_id & 0x1FFF_FFFF).unwrap_or(0);
            let mut data = [0u8; 8];
            let given = layout
                .data_bytes
                .and_then(|f| f.bytes(record))
                .unwrap_or(&[]);
            let len =
                value(layout.data_length).map_or(given.len(), |l| usize::try_from(l).unwrap_or(0));
            for (slot, b) in data.iter_mut().zip(given.iter().take(len)) {
                *slot = *b;
            }
            // Without an ID component (no class given): a bus error.
            let class = if layout.id.bits == 0 {
                BUS_ERROR
            } else {
                class
            };
            Frame::Error(ErrorFrame::from_array(class, data))
        }
        Kind::Remote | Kind::Data => {
            let extended = match layout.ide {
                Some(f) => f.integer(record).unwrap_or(0) != 0,
                None => raw_id & 0x8000_0000 != 0,
            };
            let bits = raw_id & 0x1FFF_FFFF;
            let id = u32::try_from(bits).unwrap_or(0);
            let id = if extended {
                Id::extended(id)
            } else {
                Id::standard(id)
            }
            .map_err(|e| e.to_string())?;
            let dlc_raw = value(layout.dlc);
            let fd = flag(layout.edl);
            if layout.kind == Kind::Remote {
                let dlc = dlc_raw
                    .and_then(|d| Dlc::new(u8::try_from(d.min(15)).unwrap_or(15)))
                    .unwrap_or(Dlc::from_nibble(0));
                Frame::remote(id, dlc)
            } else {
                let bytes = layout
                    .data_bytes
                    .and_then(|f| f.bytes(record))
                    .unwrap_or(&[]);
                let dlc = dlc_raw.and_then(|d| Dlc::new(u8::try_from(d.min(15)).unwrap_or(15)));
                let len = match (value(layout.data_length), dlc) {
                    (Some(len), _) => usize::try_from(len).unwrap_or(usize::MAX),
                    (None, Some(dlc)) if fd => dlc.fd_len(),
                    (None, Some(dlc)) => dlc.classic_len(),
                    (None, None) => bytes.len(),
                };
                let data = bytes
                    .get(..len)
                    .ok_or_else(|| format!("{len} data bytes in a field of {}", bytes.len()))?;
                if fd {
                    FdFrame::new(id, data, flag(layout.brs), flag(layout.esi))
                        .map(Frame::Fd)
                        .map_err(|e| e.to_string())?
                } else {
                    let dlc = dlc
                        .filter(|d| d.classic_len() == data.len())
                        .or_else(|| Dlc::from_classic_len(data.len()))
                        .ok_or_else(|| format!("{} bytes in a classic frame", data.len()))?;
                    ClassicFrame::with_dlc(id, dlc, data)
                        .map(Frame::Classic)
                        .map_err(|e| e.to_string())?
                }
            }
        }
    };
    Ok(LogRecord {
        timestamp,
        interface: names
            .get(&channel)
            .cloned()
            .unwrap_or_else(|| format!("can{channel}")),
        frame,
        direction,
    })
}

impl<R: Read + Seek> Iterator for Mf4Reader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(e) = self.error.take() {
            self.failed = true;
            return Some(Err(e));
        }
        if self.failed {
            return None;
        }
        if !self.started {
            self.started = true;
            for index in 0..self.groups.len() {
                match self.next_of(index) {
                    Ok(head) => {
                        if let Some(slot) = self.heads.get_mut(index) {
                            *slot = head;
                        }
                    }
                    Err(e) => {
                        self.failed = true;
                        return Some(Err(e));
                    }
                }
            }
        }
        // The earliest of the groups' next frames (a few groups: a scan is enough).
        let index = self
            .heads
            .iter()
            .enumerate()
            .filter_map(|(i, h)| h.as_ref().map(|h| (i, h.timestamp)))
            .min_by_key(|(_, t)| *t)
            .map(|(i, _)| i)?;
        let record = self.heads.get_mut(index)?.take();
        match self.next_of(index) {
            Ok(head) => {
                if let Some(slot) = self.heads.get_mut(index) {
                    *slot = head;
                }
            }
            // This frame first; the error next, and then nothing.
            Err(e) => {
                self.heads.iter_mut().for_each(|h| *h = None);
                self.error = Some(e);
            }
        }
        record.map(Ok)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::candump::Reader;

    const FRAMES: &str = "\
(1700000000.123456789) can0 123#DEADBEEF T
(1700000000.223457) can1 1ABCDEF0#0102 R
(1700000000.323458) can0 123#R
(1700000000.333459) can0 456#R3
(1700000000.423460) can0 20000080#0000000000000000
(1700000000.523461) can0 123##711223344556677889900AABB
(1700000000.623462) can0 7FF#
(1700000000.723463) can3 1FFFFFFF##6DEADBEEF
(1700000000.823464) can1 000#0001020304050607
";

    fn written(records: &[LogRecord]) -> Vec<u8> {
        let mut writer = Mf4Writer::new(io::Cursor::new(Vec::new())).unwrap();
        for r in records {
            writer.write(r).unwrap();
        }
        writer.finish().unwrap().into_inner()
    }

    fn read(bytes: &[u8]) -> Result<Vec<LogRecord>, LogError> {
        Mf4Reader::open(io::Cursor::new(bytes))?.collect()
    }

    #[test]
    fn interface_names_come_back_and_bus_channels_stay_numbers() {
        let text = "(1700000000.000100) bus1 123#01\n(1700000000.000200) front 124#02\n\
                    (1700000000.000300) can0 125#03\n";
        let records: Vec<LogRecord> = Reader::new(text.as_bytes())
            .collect::<Result<_, _>>()
            .unwrap();
        let bytes = written(&records);
        let names: Vec<String> = read(&bytes)
            .unwrap()
            .into_iter()
            .map(|r| r.interface)
            .collect();
        assert_eq!(names, ["bus1", "front", "can0"]);
        // The header's properties, as asammdf shows them; a name that is no interface name is
        // passed over.
        let comment = "<HDcomment><common_properties><e name=\"BusChannel 1\">bus1</e>\
                       <e name=\"BusChannel 2\">a b</e><e name=\"BusChannel x\">c</e>\
                       </common_properties></HDcomment>";
        assert_eq!(
            channel_names(comment),
            BTreeMap::from([(1, "bus1".to_string())])
        );
    }

    #[test]
    fn frames_come_back_as_written_in_time_order() {
        let wanted: Vec<LogRecord> = Reader::new(FRAMES.as_bytes())
            .collect::<Result<_, _>>()
            .unwrap();
        let file = written(&wanted);
        assert_eq!(&file[..8], b"MDF     ");
        // Every frame has a direction in the file: received, unless it was sent.
        let wanted: Vec<LogRecord> = wanted
            .into_iter()
            .map(|r| LogRecord {
                direction: r.direction.or(Some('R')),
                ..r
            })
            .collect();
        assert_eq!(read(&file).unwrap(), wanted);
    }

    #[test]
    fn many_blocks_are_listed_and_read_back() {
        // Enough data frames for several data blocks, and a few remote ones between them.
        let wanted: Vec<LogRecord> = (0..20_000u64)
            .map(|i| LogRecord {
                timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 1_000),
                interface: format!("can{}", i % 2),
                frame: if i % 1000 == 7 {
                    Frame::remote(Id::standard(0x10).unwrap(), Dlc::from_nibble(2))
                } else {
                    Frame::Classic(
                        ClassicFrame::new(Id::standard(0x100).unwrap(), &i.to_le_bytes()).unwrap(),
                    )
                },
                direction: None,
            })
            .collect();
        let file = written(&wanted);
        let got = read(&file).unwrap();
        assert_eq!(got.len(), wanted.len());
        // Written without a direction, read as received.
        assert!(got.iter().all(|r| r.direction == Some('R')));
        let strip = |r: &LogRecord| (r.timestamp, r.interface.clone(), r.frame);
        assert!(got.iter().map(strip).eq(wanted.iter().map(strip)));
    }

    /// An unsorted file, as loggers write them: one data group, record IDs, data frames (ID 1)
    /// between records of another group (ID 2), the frames' time an integer in µs.
    fn unsorted_file() -> Vec<u8> {
        fn push(out: &mut Vec<u8>, bytes: &[u8]) -> u64 {
            let at = out.len() as u64;
            out.extend_from_slice(bytes);
            out.resize(out.len().div_ceil(8) * 8, 0);
            at
        }
        fn text(out: &mut Vec<u8>, text: &str) -> u64 {
            push(out, &block(b"##TX", &[], format!("{text}\0").as_bytes()))
        }
        let mut out = identification(true).to_vec();
        out.resize(usize::try_from(HEADER_AT + HEADER_LEN).unwrap(), 0);
        // Components of a 14-byte frame record after an 8-byte time: ID with bit 31 for
        // extended, BusChannel, DLC, 8 data bytes; no DataLength, IDE or Dir.
        let mut next = 0;
        for (name, offset, bytes, data_type) in [
            ("CAN_DataFrame.DataBytes", 14u32, 8u32, DT_BYTES),
            ("CAN_DataFrame.DLC", 13, 1, DT_UNSIGNED_LE),
            ("CAN_DataFrame.BusChannel", 12, 1, DT_UNSIGNED_LE),
            ("CAN_DataFrame.ID", 8, 4, DT_UNSIGNED_LE),
        ] {
            let name = text(&mut out, name);
            next = push(
                &mut out,
                &channel([next, 0, name, 0], (0, 0), data_type, offset, bytes * 8),
            );
        }
        let name = text(&mut out, "CAN_DataFrame");
        let structure = push(
            &mut out,
            &channel([0, next, name, 0], (0, 0), DT_BYTES, 8, 14 * 8),
        );
        let mut linear = vec![1u8, 0, 0, 0, 0, 0, 2, 0];
        linear.extend_from_slice(&[0; 16]);
        linear.extend_from_slice(&0.5f64.to_le_bytes()); // offset: half a second
        linear.extend_from_slice(&1e-6f64.to_le_bytes());
        let conversion = push(&mut out, &block(b"##CC", &[0, 0, 0, 0], &linear));
        let name = text(&mut out, "Timestamp");
        let mut time = channel(
            [structure, 0, name, 0],
            (CN_MASTER, SYNC_TIME),
            DT_UNSIGNED_LE,
            0,
            64,
        );
        // The conversion link: the fifth.
        time[24 + 4 * 8..24 + 5 * 8].copy_from_slice(&conversion.to_le_bytes());
        let time = push(&mut out, &time);
        let group = |id: u64, first: u64, bytes: u32, next: u64| {
            let mut cg = Vec::new();
            cg.extend_from_slice(&id.to_le_bytes());
            cg.extend_from_slice(&2u64.to_le_bytes());
            cg.extend_from_slice(&CG_BUS_EVENT.to_le_bytes());
            cg.extend_from_slice(&[b'.', 0, 0, 0, 0, 0]);
            cg.extend_from_slice(&bytes.to_le_bytes());
            cg.extend_from_slice(&0u32.to_le_bytes());
            block(b"##CG", &[next, first, 0, 0, 0, 0], &cg)
        };
        let other = push(&mut out, &group(2, 0, 4, 0));
        let frames = push(&mut out, &group(1, time, 22, other));
        let mut records = Vec::new();
        for (micros, id, data) in [(10u64, 0x123u32, [1u8; 8]), (20, 0x8000_0456, [2; 8])] {
            records.push(1);
            records.extend_from_slice(&micros.to_le_bytes());
            records.extend_from_slice(&id.to_le_bytes());
            records.extend_from_slice(&[1, 8]);
            records.extend_from_slice(&data);
            records.extend_from_slice(&[2, 9, 9, 9, 9]);
        }
        let mut dt = b"##DT\0\0\0\0".to_vec();
        dt.extend_from_slice(&(24 + records.len() as u64).to_le_bytes());
        dt.extend_from_slice(&0u64.to_le_bytes());
        dt.extend_from_slice(&records);
        let data = push(&mut out, &dt);
        let dg = push(
            &mut out,
            &block(b"##DG", &[0, frames, data, 0], &[1, 0, 0, 0, 0, 0, 0, 0]),
        );
        let header = header([dg, 0, 0, 0, 0, 0], 1_700_000_000_000_000_000);
        out[64..64 + header.len()].copy_from_slice(&header);
        out
    }

    #[test]
    fn unsorted_files_with_integer_times_are_read() {
        let got = read(&unsorted_file()).unwrap();
        let start = 1_700_000_000_500_000_000;
        assert_eq!(got.len(), 2);
        assert_eq!(got[0].timestamp, Timestamp::from_nanos(start + 10_000));
        assert_eq!(got[1].timestamp, Timestamp::from_nanos(start + 20_000));
        assert_eq!(got[0].interface, "can1");
        assert_eq!(got[0].frame.to_string(), "123#0101010101010101");
        // Extended by the ID's top bit.
        assert_eq!(got[1].frame.to_string(), "00000456#0202020202020202");
        assert_eq!(got[1].direction, None);
    }

    #[test]
    fn bad_files_are_errors_naming_the_offset() {
        let wanted: Vec<LogRecord> = Reader::new(FRAMES.as_bytes())
            .collect::<Result<_, _>>()
            .unwrap();
        let file = written(&wanted);
        assert!(matches!(
            read(b"MDF"),
            Err(LogError::Binary { offset: 0, .. })
        ));
        assert!(matches!(read(&file[..200]), Err(LogError::Binary { .. })));
        // Every cut and every single corrupted byte: an error or fewer frames, never a panic.
        for cut in (0..file.len()).step_by(7) {
            let _ = read(&file[..cut]);
        }
        for at in 0..file.len() {
            let mut bad = file.clone();
            bad[at] ^= 0xA5;
            let _ = read(&bad);
        }
    }
}
