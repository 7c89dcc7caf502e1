//! The shortest and longest a frame of a given format and DLC can be on the wire.

use super::{fd_crc_width, header};
use crate::frame::{Dlc, ExtendedId, Id, StandardId};

/// The format of a frame, everything about its layout except the identifier and data values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct FrameShape {
    /// 29-bit identifier.
    pub extended: bool,
    /// Remote frame (classic only; no data field).
    pub remote: bool,
    /// CAN FD frame.
    pub fd: bool,
}

/// Stuff-bit counts reachable so far, per (last level, run length 0..=5).
type Reach = [[Option<(u16, u16)>; 6]; 2];

fn step(reach: &Reach, choices: &[bool], stuff_after: bool) -> Reach {
    let mut next: Reach = [[None; 6]; 2];
    for (level_index, runs) in reach.iter().enumerate() {
        let level = level_index == 1;
        for (run, counts) in runs.iter().enumerate() {
            let Some((lo, hi)) = *counts else { continue };
            for &bit in choices {
                let new_run = if run > 0 && bit == level { run + 1 } else { 1 };
                let (state_level, state_run, extra) = if new_run == 5 && stuff_after {
                    (!bit, 1, 1)
                } else {
                    (bit, new_run, 0)
                };
                if let Some(slot) = next
                    .get_mut(usize::from(state_level))
                    .and_then(|r| r.get_mut(state_run))
                {
                    let (lo, hi) = (lo + extra, hi + extra);
                    *slot = Some(match *slot {
                        Some((a, b)) => (a.min(lo), b.max(hi)),
                        None => (lo, hi),
                    });
                }
            }
        }
    }
    next
}

/// The shortest and longest stuffed length in bits (SOF through EOF) over every identifier,
/// data and flag value of frames with this shape and DLC.
///
/// The stuffed region is searched exhaustively over its free bits (identifier, BRS, ESI, data,
/// and the classic CRC treated as free), so the bounds hold for every frame; they are tight up
/// to the CRC, whose value is fixed by the rest of the frame.
pub fn length_bounds(shape: FrameShape, dlc: Dlc) -> (usize, usize) {
    let (base, lo, hi) = stuff_range(shape, dlc);
    (base + lo, base + hi)
}

/// The length of a frame with this shape and DLC if no stuff bits were inserted: the count
/// `canbusload` uses without `-e`.
pub fn unstuffed_length(shape: FrameShape, dlc: Dlc) -> usize {
    stuff_range(shape, dlc).0
}

/// (length without stuff bits, fewest stuff bits, most stuff bits).
fn stuff_range(shape: FrameShape, dlc: Dlc) -> (usize, usize, usize) {
    let id = if shape.extended {
        Id::Extended(ExtendedId::ZERO)
    } else {
        Id::Standard(StandardId::ZERO)
    };
    let fd = shape.fd.then_some((false, false));
    let remote = shape.remote && !shape.fd;
    let (pieces, count) = header(id, remote, fd, dlc);
    let data_bits = 8 * match (shape.fd, remote) {
        (true, _) => dlc.fd_len(),
        (false, true) => 0,
        (false, false) => dlc.classic_len(),
    };
    let header_bits: usize = pieces
        .iter()
        .take(count)
        .map(|p| usize::from(p.width))
        .sum();
    let crc_bits = if shape.fd { 0 } else { 15 };
    let stuffed_total = header_bits + data_bits + crc_bits;

    let mut reach: Reach = [[None; 6]; 2];
    reach[1][0] = Some((0, 0));
    let mut index = 0usize;
    let mut visit = |reach: &mut Reach, choices: &[bool]| {
        index += 1;
        let stuff_after = !shape.fd || index < stuffed_total;
        *reach = step(reach, choices, stuff_after);
    };
    for p in pieces.iter().take(count) {
        for i in (0..p.width).rev() {
            let fixed = [(p.value >> i) & 1 == 1];
            visit(&mut reach, if p.free { &[false, true] } else { &fixed });
        }
    }
    for _ in 0..data_bits + crc_bits {
        visit(&mut reach, &[false, true]);
    }
    let (lo, hi) = reach
        .iter()
        .flatten()
        .flatten()
        .fold((u16::MAX, 0), |(a, b), &(lo, hi)| (a.min(lo), b.max(hi)));
    // delimiter, ACK slot, ACK delimiter, 7 EOF bits
    let mut tail = 10;
    if shape.fd {
        let width = usize::from(fd_crc_width(dlc.fd_len()));
        // fixed stuff bit + 4-bit stuff count, then the CRC with a fixed stuff bit before it
        // and after every four of its bits
        tail += 1 + 4 + width + 1 + (width - 1) / 4;
    }
    (stuffed_total + tail, usize::from(lo), usize::from(hi))
}
