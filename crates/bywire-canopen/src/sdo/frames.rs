//! The frames both ends send: command bytes with index and subindex, segments, aborts, and
//! the block transfer's CRC.

use crate::abort::Abort;

/// CRC-16/XMODEM (polynomial 0x1021, initial 0), the block transfer CRC.
pub fn crc16(crc: u16, bytes: &[u8]) -> u16 {
    bytes.iter().fold(crc, |mut crc, byte| {
        crc ^= u16::from(*byte) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
        crc
    })
}

/// The index and sub-index a request names (as much of them as a short frame has).
pub(super) fn index_of(data: &[u8]) -> (u16, u8) {
    let byte = |at: usize| data.get(at).copied().unwrap_or(0);
    (u16::from_le_bytes([byte(1), byte(2)]), byte(3))
}

pub(super) fn u32_at4(data: &[u8]) -> u32 {
    match data {
        [_, _, _, _, a, b, c, d, ..] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    }
}

pub(super) fn with_index(command: u8, index: u16, sub: u8, tail: [u8; 4]) -> [u8; 8] {
    let [lo, hi] = index.to_le_bytes();
    let [a, b, c, d] = tail;
    [command, lo, hi, sub, a, b, c, d]
}

/// The abort frame payload.
pub fn abort_payload(index: u16, sub: u8, abort: Abort) -> [u8; 8] {
    with_index(0x80, index, sub, abort.code().to_le_bytes())
}

/// Seven bytes of `data` from `offset` (zero-padded) and how many were real.
pub(super) fn segment_at(data: &[u8], offset: usize) -> ([u8; 7], usize) {
    let mut bytes = [0u8; 7];
    let real = data.get(offset..).unwrap_or(&[]);
    let n = real.len().min(7);
    if let (Some(to), Some(from)) = (bytes.get_mut(..n), real.get(..n)) {
        to.copy_from_slice(from);
    }
    (bytes, n)
}

pub(super) fn segment_frame(command: u8, bytes: [u8; 7]) -> [u8; 8] {
    let [a, b, c, d, e, f, g] = bytes;
    [command, a, b, c, d, e, f, g]
}

/// Segments needed for `len` bytes in block mode (at least one).
pub(super) fn segment_count(len: usize) -> usize {
    len.div_ceil(7).max(1)
}

/// Unused bytes in the last segment of `len` bytes.
pub(super) fn unused_in_last(len: usize) -> u8 {
    let used = len - (segment_count(len) - 1) * 7;
    u8::try_from(7 - used.min(7)).unwrap_or(0)
}
