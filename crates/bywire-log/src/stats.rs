//! What a log holds, counted as it streams by: frames by kind, the time it spans, and per
//! interface and identifier the frames and their mean cycle (`bywire log stats`).
//!
//! Counting keeps nothing of a record but its numbers, so it takes records lent by a reader
//! ([`crate::Reader::for_each_ref`]): a candump log is counted without a copy of any line.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::io::{self, Write};

use bywire_core::frame::{EFF_FLAG, EFF_MASK, ERR_FLAG, RTR_FLAG, SFF_MASK};

use crate::LogRecordRef;

/// One identifier on one interface: its frames and the first and last time it was seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdStats {
    /// Frames.
    pub frames: u64,
    /// The earliest timestamp, ns since the Unix epoch.
    pub first: u64,
    /// The latest timestamp, ns since the Unix epoch.
    pub last: u64,
}

impl IdStats {
    /// The mean time between its frames, in ms (`None` for a single frame).
    pub fn mean_cycle_ms(&self) -> Option<f64> {
        // Nanosecond spans between frames: well within f64's exact range for logs.
        #[allow(clippy::cast_precision_loss)]
        (self.frames > 1).then(|| (self.last - self.first) as f64 / (self.frames - 1) as f64 / 1e6)
    }
}

/// Identifiers are hashed by one multiplication: they are small numbers, and SipHash's
/// resistance to chosen keys buys nothing for a count (a crafted log only counts slower).
#[derive(Default)]
struct IdHasher(u64);

impl Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u32(u32::from(b));
        }
    }

    fn write_u32(&mut self, n: u32) {
        let h = (u64::from(n) ^ self.0).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        // Both ends of the product mixed: the table indexes by the low bits.
        self.0 = h ^ (h >> 32);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Interfaces up to which one is found by comparing names rather than by the map.
const FEW_INTERFACES: usize = 8;

/// One interface: its frames and its identifiers (SocketCAN form: flags included).
#[derive(Debug, Clone, Default)]
struct InterfaceStats {
    name: String,
    frames: u64,
    ids: HashMap<u32, IdStats, BuildHasherDefault<IdHasher>>,
}

/// The counts of a log (or several).
#[derive(Debug, Clone, Default)]
pub struct LogStats {
    /// Frames of every kind.
    pub frames: u64,
    /// CAN FD frames.
    pub fd: u64,
    /// Remote frames.
    pub remote: u64,
    /// Error frames.
    pub errors: u64,
    /// The earliest and latest timestamp, ns since the Unix epoch (once a frame was counted).
    pub span: Option<(u64, u64)>,
    interfaces: Vec<InterfaceStats>,
    /// Where each interface is in `interfaces`.
    by_name: HashMap<String, usize>,
    /// The interface counted last: logs come in runs of one interface, looked up first.
    last_interface: usize,
}

impl LogStats {
    /// Nothing counted.
    pub fn new() -> LogStats {
        LogStats::default()
    }

    /// Count one record.
    pub fn add(&mut self, record: &LogRecordRef<'_>) {
        let t = record.timestamp.as_nanos();
        let frame = &record.frame;
        self.frames += 1;
        self.fd += u64::from(frame.is_fd());
        self.errors += u64::from(frame.is_error());
        self.remote += u64::from(frame.is_remote());
        let (first, last) = self.span.unwrap_or((t, t));
        self.span = Some((first.min(t), last.max(t)));
        let index = self.interface_index(record.interface);
        let Some(interface) = self.interfaces.get_mut(index) else {
            return;
        };
        interface.frames += 1;
        let id = interface
            .ids
            .entry(frame.socketcan_id())
            .or_insert(IdStats {
                frames: 0,
                first: t,
                last: t,
            });
        id.frames += 1;
        id.first = id.first.min(t);
        id.last = id.last.max(t);
    }

    fn interface_index(&mut self, name: &str) -> usize {
        if self
            .interfaces
            .get(self.last_interface)
            .is_some_and(|i| same_name(&i.name, name))
        {
            return self.last_interface;
        }
        // A log has a few interfaces, found by comparing names; the map serves logs with many.
        let found = if self.interfaces.len() <= FEW_INTERFACES {
            self.interfaces
                .iter()
                .position(|i| same_name(&i.name, name))
        } else {
            self.by_name.get(name).copied()
        };
        let index = found.unwrap_or_else(|| {
            self.interfaces.push(InterfaceStats {
                name: name.to_string(),
                ..InterfaceStats::default()
            });
            self.by_name
                .insert(name.to_string(), self.interfaces.len() - 1);
            self.interfaces.len() - 1
        });
        self.last_interface = index;
        index
    }

    /// Per interface (by name): its frames.
    pub fn interfaces(&self) -> Vec<(&str, u64)> {
        let mut all: Vec<_> = self
            .interfaces
            .iter()
            .map(|i| (i.name.as_str(), i.frames))
            .collect();
        all.sort_unstable();
        all
    }

    /// Per interface and identifier (SocketCAN form), in that order: its counts.
    pub fn ids(&self) -> Vec<(&str, u32, IdStats)> {
        let mut all: Vec<_> = self
            .interfaces
            .iter()
            .flat_map(|i| i.ids.iter().map(|(id, s)| (i.name.as_str(), *id, *s)))
            .collect();
        all.sort_unstable_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
        all
    }

    /// The counts as `bywire log stats` prints them.
    pub fn write_report(&self, out: &mut impl Write) -> io::Result<()> {
        let Some((first, last)) = self.span else {
            return writeln!(out, "no frames");
        };
        let span = last.saturating_sub(first);
        writeln!(
            out,
            "{} frames ({} FD, {} remote, {} error) over {}.{:06} s",
            self.frames,
            self.fd,
            self.remote,
            self.errors,
            span / 1_000_000_000,
            span % 1_000_000_000 / 1000
        )?;
        for (interface, count) in self.interfaces() {
            writeln!(out, "  {interface}: {count} frames")?;
        }
        writeln!(out, "interface  id        frames  mean cycle ms")?;
        for (interface, id, s) in self.ids() {
            let cycle = s
                .mean_cycle_ms()
                .map_or_else(|| "-".to_string(), |ms| format!("{ms:.3}"));
            writeln!(
                out,
                "{interface:<10} {:<9} {:>6}  {cycle:>13}",
                id_text(id),
                s.frames
            )?;
        }
        Ok(())
    }
}

/// Whether two interface names are the same: byte by byte, as names are short (a call to
/// `memcmp` for each record cost more than the comparison).
fn same_name(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).all(|(x, y)| x == y)
}

/// An identifier in SocketCAN form as candump writes it, ` R` after a remote frame's.
fn id_text(id: u32) -> String {
    let text = if id & ERR_FLAG != 0 {
        format!("{id:08X}")
    } else if id & EFF_FLAG != 0 {
        format!("{:08X}", id & EFF_MASK)
    } else {
        format!("{:03X}", id & SFF_MASK)
    };
    if id & RTR_FLAG != 0 {
        text + " R"
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::Reader;
    use std::collections::BTreeMap;
    use std::ops::ControlFlow;

    const LOG: &str = "\
(1.000000) can1 123#01
(1.010000) can0 123#02
(1.020000) can1 123#03
(1.030000) can0 1ABCDEF0#R
(1.040000) can1 20000080#0000000000000000
(1.050000) can1 456##1AABB
(0.990000) can1 123#04
";

    #[test]
    fn counts_each_kind_interface_and_identifier() {
        let mut stats = LogStats::new();
        let mut reader = Reader::new(LOG.as_bytes());
        let stopped: Option<()> = reader.for_each_ref(|record| {
            stats.add(record.unwrap());
            ControlFlow::Continue(())
        });
        assert_eq!(stopped, None);
        assert_eq!(
            (stats.frames, stats.fd, stats.remote, stats.errors),
            (7, 1, 1, 1)
        );
        assert_eq!(stats.span, Some((990_000_000, 1_050_000_000)));
        assert_eq!(stats.interfaces(), vec![("can0", 2), ("can1", 5)]);
        // The same counts by a map of owned records, the way anyone would count them.
        let mut expected: BTreeMap<(String, u32), (u64, u64, u64)> = BTreeMap::new();
        for record in Reader::new(LOG.as_bytes()) {
            let record = record.unwrap();
            let t = record.timestamp.as_nanos();
            let e = expected
                .entry((record.interface.clone(), record.frame.socketcan_id()))
                .or_insert((0, t, t));
            *e = (e.0 + 1, e.1.min(t), e.2.max(t));
        }
        let got: Vec<_> = stats
            .ids()
            .into_iter()
            .map(|(i, id, s)| ((i.to_string(), id), (s.frames, s.first, s.last)))
            .collect();
        assert_eq!(got, expected.into_iter().collect::<Vec<_>>());
        // can1 0x123: three frames from 0.99 to 1.02 s, 15 ms apart on average.
        let (_, _, s) = stats
            .ids()
            .into_iter()
            .find(|(i, id, _)| *i == "can1" && *id == 0x123)
            .unwrap();
        assert!((s.mean_cycle_ms().unwrap() - 15.0).abs() < 1e-9);
    }

    #[test]
    fn the_report_names_identifiers_as_candump_does() {
        let mut stats = LogStats::new();
        for record in Reader::new(LOG.as_bytes()) {
            stats.add(&record.unwrap().as_record_ref());
        }
        let mut text = Vec::new();
        stats.write_report(&mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.starts_with("7 frames (1 FD, 1 remote, 1 error) over 0.060000 s\n"));
        assert!(
            text.contains("\ncan0       1ABCDEF0 R      1              -\n"),
            "{text}"
        );
        assert!(
            text.contains("\ncan1       123            3         15.000\n"),
            "{text}"
        );
        assert!(
            text.contains("\ncan1       20000080       1              -\n"),
            "{text}"
        );
        let mut empty = Vec::new();
        LogStats::new().write_report(&mut empty).unwrap();
        assert_eq!(empty, b"no frames\n");
    }
}
