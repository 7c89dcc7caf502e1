//! The kernel's frame structures (`struct can_frame`, 16 bytes; `struct canfd_frame`, 72 bytes)
//! to and from bywire frames. Byte-level so that no `unsafe` is needed to read or write them.

use bywire_core::frame::{ClassicFrame, Dlc, ErrorFrame, FdFrame, FrameError};
use bywire_core::{Frame, Id};

/// Size of `struct can_frame`.
pub const CAN_MTU: usize = 16;
/// Size of `struct canfd_frame`.
pub const CANFD_MTU: usize = 72;

const EFF_FLAG: u32 = 0x8000_0000;
const RTR_FLAG: u32 = 0x4000_0000;
const ERR_FLAG: u32 = 0x2000_0000;
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;
/// Marks an FD frame in `flags` (kernel 6.0 and later; older kernels ignore it).
const CANFD_FDF: u8 = 0x04;

/// A structure the kernel should never hand us.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LayoutError {
    /// Neither a `can_frame` nor a `canfd_frame`.
    #[error("a read of {0} bytes is no CAN frame structure (16 or 72 bytes)")]
    Size(usize),
    /// The fields do not make a frame.
    #[error("invalid frame from the kernel: {0}")]
    Frame(#[from] FrameError),
}

fn id_of(can_id: u32) -> Result<Id, FrameError> {
    if can_id & EFF_FLAG != 0 {
        Id::extended(can_id & bywire_core::frame::EFF_MASK)
    } else {
        Id::standard(can_id & bywire_core::frame::EFF_MASK)
    }
}

/// Decode a structure the kernel delivered (`bytes` is exactly what `recvmsg` returned).
pub fn frame_from_bytes(bytes: &[u8]) -> Result<Frame, LayoutError> {
    let (header, data) = match bytes.len() {
        CAN_MTU | CANFD_MTU => bytes.split_at(8),
        n => return Err(LayoutError::Size(n)),
    };
    let [i0, i1, i2, i3, len, flags, _, len8_dlc] =
        <[u8; 8]>::try_from(header).map_err(|_| LayoutError::Size(bytes.len()))?;
    let can_id = u32::from_ne_bytes([i0, i1, i2, i3]);
    let payload = data.get(..usize::from(len)).ok_or(FrameError::TooLong {
        len: usize::from(len),
        max: data.len(),
        kind: "kernel",
    })?;
    if can_id & ERR_FLAG != 0 {
        return Ok(Frame::Error(ErrorFrame::new(
            can_id & bywire_core::frame::EFF_MASK,
            payload,
        )?));
    }
    let id = id_of(can_id)?;
    if bytes.len() == CANFD_MTU {
        let fd = FdFrame::new(id, payload, flags & CANFD_BRS != 0, flags & CANFD_ESI != 0)?;
        return Ok(Frame::Fd(fd));
    }
    // A classic frame's DLC: its length, or the raw 9..15 kept in len8_dlc for 8 bytes.
    let dlc = match Dlc::new(len8_dlc) {
        Some(raw) if len == 8 && len8_dlc > 8 => raw,
        _ => Dlc::from_classic_len(usize::from(len)).ok_or(FrameError::TooLong {
            len: usize::from(len),
            max: 8,
            kind: "classic",
        })?,
    };
    if can_id & RTR_FLAG != 0 {
        return Ok(Frame::Classic(ClassicFrame::remote(id, dlc)));
    }
    Ok(Frame::Classic(ClassicFrame::with_dlc(id, dlc, payload)?))
}

/// Lay a frame out for `write`; returns the bytes to write (`None` for error frames, which
/// only controllers produce).
pub fn frame_to_bytes(frame: &Frame, out: &mut [u8; CANFD_MTU]) -> Option<usize> {
    *out = [0; CANFD_MTU];
    let (size, len, flags, len8_dlc) = match frame {
        Frame::Error(_) => return None,
        Frame::Classic(f) => {
            let raw = f.dlc().as_raw();
            let extra = if raw > 8 { raw } else { 0 };
            let len = u8::try_from(f.dlc().classic_len()).unwrap_or(8);
            (CAN_MTU, len, 0, extra)
        }
        Frame::Fd(f) => {
            let flags = CANFD_FDF
                | if f.brs() { CANFD_BRS } else { 0 }
                | if f.esi() { CANFD_ESI } else { 0 };
            (CANFD_MTU, u8::try_from(f.len()).unwrap_or(64), flags, 0)
        }
    };
    let (header, data) = out.split_at_mut(8);
    let can_id = frame.socketcan_id().to_ne_bytes();
    header.copy_from_slice(&[
        can_id[0], can_id[1], can_id[2], can_id[3], len, flags, 0, len8_dlc,
    ]);
    if !frame.is_remote() {
        for (dst, src) in data.iter_mut().zip(frame.data()) {
            *dst = *src;
        }
    }
    Some(size)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(text: &str) -> Vec<u8> {
        let frame: Frame = text.parse().unwrap();
        let mut buf = [0; CANFD_MTU];
        let n = frame_to_bytes(&frame, &mut buf).unwrap();
        assert_eq!(frame_from_bytes(&buf[..n]).unwrap(), frame, "{text}");
        buf[..n].to_vec()
    }

    #[test]
    fn kernel_structures_round_trip() {
        for text in [
            "123#DEADBEEF",
            "1ABCDEF0#",
            "123#R",
            "123#R5",
            "7FF#1122334455667788_E",
            "123##3AABBCC",
            "1FFFFFFF##0112233445566778899AABBCC",
        ] {
            round_trip(text);
        }
    }

    #[test]
    fn fields_sit_where_the_kernel_puts_them() {
        let b = round_trip("12345678#R3");
        assert_eq!(b.len(), 16);
        assert_eq!(u32::from_ne_bytes([b[0], b[1], b[2], b[3]]), 0xD234_5678);
        assert_eq!(b[4], 3);
        let b = round_trip("7FF#1122334455667788_C");
        assert_eq!((b[4], b[7]), (8, 12));
        let b = round_trip("123##3AABB");
        assert_eq!((b.len(), b[4], b[5]), (72, 2, 0x07));
    }

    #[test]
    fn error_frames_decode_and_are_not_sent() {
        let mut raw = [0u8; CAN_MTU];
        raw[..4].copy_from_slice(&(ERR_FLAG | 0x240).to_ne_bytes());
        raw[4] = 8;
        raw[14] = 0x80;
        let Frame::Error(e) = frame_from_bytes(&raw).unwrap() else {
            panic!("an error frame")
        };
        assert_eq!(e.counters(), Some((0x80, 0)));
        let mut buf = [0; CANFD_MTU];
        assert_eq!(frame_to_bytes(&Frame::Error(e), &mut buf), None);
    }

    #[test]
    fn malformed_structures_are_errors() {
        assert_eq!(frame_from_bytes(&[0; 15]), Err(LayoutError::Size(15)));
        let mut raw = [0u8; CAN_MTU];
        raw[4] = 9;
        assert!(frame_from_bytes(&raw).is_err());
        raw[4] = 3;
        raw[..4].copy_from_slice(&0x800u32.to_ne_bytes());
        assert!(frame_from_bytes(&raw).is_err(), "standard id above 0x7FF");
        let mut fd = [0u8; CANFD_MTU];
        fd[4] = 9;
        assert!(frame_from_bytes(&fd).is_err(), "9 is no FD length");
        fd[4] = 65;
        assert!(frame_from_bytes(&fd).is_err());
    }
}
