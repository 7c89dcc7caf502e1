//! CAN frames as ros2_socketcan's messages, both ways.
//!
//! Received classic, remote and error frames become `can_msgs/msg/Frame` (an error frame with
//! `is_error`, its SocketCAN class bits as the id and its eight data bytes, as SocketCAN gives
//! it); CAN FD frames become `ros2_socketcan_msgs/msg/FdFrame`. A message to send is checked
//! whole before it becomes a frame: an identifier beyond its width, a DLC above 15, an FD length
//! CAN FD has no code for, or an error frame (which no bus can be asked to send) is refused with
//! the field at fault named, never truncated.

use bywire_core::frame::{ClassicFrame, Dlc, FrameError};
use bywire_core::{Frame, Id};

use crate::msg::{CanFrame, FdFrame, Header, Time};

/// A frame as what ros2_socketcan publishes for it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Published {
    /// On `from_can_bus`.
    Classic(CanFrame),
    /// On `from_can_bus_fd`.
    Fd(FdFrame),
}

/// Why a message cannot be sent as a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// The message asks for an error frame.
    #[error("is_error is set: error frames are reported by controllers, not sent")]
    ErrorFrame,
    /// The identifier, DLC or length does not make a frame.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// `len` and the data disagree in an FD message.
    #[error("len is {len} but {data} data bytes came")]
    LengthMismatch {
        /// `len`.
        len: u8,
        /// The data's length.
        data: usize,
    },
}

fn header(stamp: Time, frame_id: &str) -> Header {
    Header {
        stamp,
        frame_id: frame_id.to_string(),
    }
}

/// What to publish for a received frame.
pub fn to_ros(frame: &Frame, stamp: Time, frame_id: &str) -> Published {
    let mut data = [0u8; 8];
    for (slot, byte) in data.iter_mut().zip(frame.data()) {
        *slot = *byte;
    }
    match frame {
        Frame::Classic(f) => Published::Classic(CanFrame {
            header: header(stamp, frame_id),
            id: f.id().as_raw(),
            is_rtr: f.is_remote(),
            is_extended: f.id().is_extended(),
            is_error: false,
            dlc: f.dlc().as_raw(),
            data,
        }),
        Frame::Error(e) => Published::Classic(CanFrame {
            header: header(stamp, frame_id),
            id: e.class_bits(),
            is_rtr: false,
            is_extended: false,
            is_error: true,
            dlc: 8,
            data,
        }),
        Frame::Fd(f) => Published::Fd(FdFrame {
            header: header(stamp, frame_id),
            id: f.id().as_raw(),
            is_extended: f.id().is_extended(),
            is_error: false,
            // At most 64: the cast cannot fail.
            len: u8::try_from(f.len()).unwrap_or(64),
            data: f.data().to_vec(),
        }),
    }
}

fn id(raw: u32, extended: bool) -> Result<Id, FrameError> {
    if extended {
        Id::extended(raw)
    } else {
        Id::standard(raw)
    }
}

/// The frame a `can_msgs/msg/Frame` asks to send. A DLC of 9–15 sends eight bytes with that
/// DLC, as SocketCAN's `len8_dlc`; a remote frame carries its DLC and no data.
pub fn from_ros(message: &CanFrame) -> Result<Frame, Refused> {
    if message.is_error {
        return Err(Refused::ErrorFrame);
    }
    let id = id(message.id, message.is_extended)?;
    let dlc = Dlc::new(message.dlc).ok_or(FrameError::DlcRange(message.dlc))?;
    if message.is_rtr {
        return Ok(Frame::remote(id, dlc));
    }
    let data = message
        .data
        .get(..dlc.classic_len())
        .unwrap_or(&message.data);
    Ok(Frame::Classic(ClassicFrame::with_dlc(id, dlc, data)?))
}

/// The frame a `ros2_socketcan_msgs/msg/FdFrame` asks to send (bit-rate switch as `brs`).
pub fn from_ros_fd(message: &FdFrame, brs: bool) -> Result<Frame, Refused> {
    if message.is_error {
        return Err(Refused::ErrorFrame);
    }
    if usize::from(message.len) != message.data.len() {
        return Err(Refused::LengthMismatch {
            len: message.len,
            data: message.data.len(),
        });
    }
    let id = id(message.id, message.is_extended)?;
    Ok(Frame::fd(id, &message.data, brs, false)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bywire_core::frame::ErrorFrame;

    fn frame(text: &str) -> Frame {
        text.parse().unwrap()
    }

    fn classic(published: Published) -> CanFrame {
        match published {
            Published::Classic(m) => m,
            Published::Fd(m) => panic!("an FD message: {m:?}"),
        }
    }

    #[test]
    fn classic_extended_and_remote_frames_go_both_ways() {
        for text in [
            "123#DEADBEEF",
            "1ABCDEF0#0102",
            "7FF#R3",
            "00000123#",
            "123#R",
        ] {
            let f = frame(text);
            let m = classic(to_ros(&f, Time::default(), "can"));
            assert_eq!(from_ros(&m).unwrap(), f, "{text}");
        }
        let m = classic(to_ros(&frame("1ABCDEF0#0102"), Time::default(), "can0"));
        assert_eq!(
            (
                m.id,
                m.is_extended,
                m.dlc,
                m.data,
                m.header.frame_id.as_str()
            ),
            (0x1ABC_DEF0, true, 2, [1, 2, 0, 0, 0, 0, 0, 0], "can0")
        );
        let m = classic(to_ros(&frame("7FF#R3"), Time::default(), "can"));
        assert!(m.is_rtr && m.dlc == 3 && m.data == [0; 8]);
    }

    #[test]
    fn a_raw_dlc_above_eight_is_kept() {
        let f = frame("123#0102030405060708_C");
        let m = classic(to_ros(&f, Time::default(), "can"));
        assert_eq!(m.dlc, 12);
        assert_eq!(from_ros(&m).unwrap(), f);
    }

    #[test]
    fn fd_frames_go_on_the_fd_type() {
        let f = frame("123##1000102030405060708090A0B");
        let Published::Fd(m) = to_ros(&f, Time::default(), "can") else {
            panic!("not FD");
        };
        assert_eq!((m.len, m.data.len(), m.id), (12, 12, 0x123));
        assert_eq!(from_ros_fd(&m, true).unwrap(), f);
        assert_ne!(from_ros_fd(&m, false).unwrap(), f);
    }

    #[test]
    fn error_frames_are_reported_but_never_sent() {
        let e = Frame::Error(ErrorFrame::from_array(0x4, [0, 4, 0, 0, 0, 0, 0, 0]));
        let m = classic(to_ros(&e, Time::default(), "can"));
        assert!(m.is_error && m.id == 0x4 && m.data[1] == 4);
        assert_eq!(from_ros(&m), Err(Refused::ErrorFrame));
    }

    /// The serde message through RustDDS's CDR serializer gives the bytes bywire-log's own
    /// `can_msgs/msg/Frame` writer (MCAP) gives: two independent encoders agree.
    #[cfg(feature = "dds")]
    #[test]
    fn the_cdr_equals_the_mcap_writers() {
        use rustdds::serialization::{to_writer_with_rep_id, RepresentationIdentifier};
        let error = Frame::Error(ErrorFrame::from_array(0x20, [0, 0, 0x10, 0, 0, 0, 0, 0]));
        let frames = [
            "123#DEADBEEF",
            "1ABCDEF0#0102",
            "7FF#R3",
            "000#",
            "123#0102030405060708_C",
        ]
        .map(frame);
        for (f, frame_id) in frames
            .iter()
            .chain([&error])
            .zip(["can", "can0", "x", "", "vcan12"].iter().cycle())
        {
            let nanos = 1_700_000_000_987_654_321;
            let Published::Classic(m) = to_ros(f, Time::from_nanos(nanos), frame_id) else {
                panic!("not classic");
            };
            let mut cdr = vec![0, 1, 0, 0];
            to_writer_with_rep_id(&mut cdr, &m, RepresentationIdentifier::CDR_LE).unwrap();
            let theirs = bywire_log::mcap::encode_frame(
                f,
                bywire_core::Timestamp::from_nanos(nanos),
                frame_id,
            )
            .unwrap();
            assert_eq!(cdr, theirs, "{f:?}");
        }
    }

    #[test]
    fn bad_messages_are_refused_with_the_field_named() {
        let base = CanFrame {
            id: 0x800,
            dlc: 1,
            ..CanFrame::default()
        };
        assert!(from_ros(&base).unwrap_err().to_string().contains("0x800"));
        let m = CanFrame {
            id: 0x2000_0000,
            is_extended: true,
            ..base.clone()
        };
        assert!(from_ros(&m).unwrap_err().to_string().contains("0x20000000"));
        let m = CanFrame {
            id: 1,
            dlc: 16,
            ..base
        };
        assert!(from_ros(&m).unwrap_err().to_string().contains("DLC 16"));
        let fd = FdFrame {
            len: 9,
            data: vec![0; 9],
            ..FdFrame::default()
        };
        assert!(from_ros_fd(&fd, true)
            .unwrap_err()
            .to_string()
            .contains("9 bytes"));
        let fd = FdFrame {
            len: 12,
            data: vec![0; 8],
            ..FdFrame::default()
        };
        assert_eq!(
            from_ros_fd(&fd, true),
            Err(Refused::LengthMismatch { len: 12, data: 8 })
        );
    }
}
