//! The three system calls the `socketcan` crate does not give us in the form we need, and the
//! only `unsafe` code in bywire.
//!
//! - `recvmsg` with the message flags: the crate's readers drop `msg_flags`, and `MSG_CONFIRM`
//!   there is the only way to tell this socket's echoed frames (transmit confirmations) from
//!   identical frames another node sent; we also read the drop counter (`SO_RXQ_OVFL`) and both
//!   timestamps (`SO_TIMESTAMPING`) from the same call.
//! - `poll`, to wait for a frame with a timeout without changing socket options per call.
//! - `send` of a frame we laid out ourselves, blocking or not per call.
#![allow(unsafe_code)]

use std::io;
use std::mem::size_of;
use std::os::fd::{AsRawFd, BorrowedFd};
use std::time::Duration;

/// What one `recvmsg` returned besides the bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Message {
    /// Bytes of the frame structure.
    pub len: usize,
    /// `MSG_CONFIRM`: this socket sent the frame (the echo of our own transmission).
    pub confirm: bool,
    /// `MSG_DONTROUTE`: a socket of this host sent the frame.
    pub local: bool,
    /// Software receive time, since the Unix epoch.
    pub software: Option<Duration>,
    /// The controller's raw hardware time.
    pub hardware: Option<Duration>,
    /// The socket's count of frames dropped for lack of buffer space, when the kernel sent it.
    pub dropped: Option<u32>,
}

/// Control buffer with the alignment `cmsghdr` needs; room for the timestamping and
/// drop-counter messages with margin.
#[repr(C, align(8))]
struct Control([u8; 256]);

fn duration(ts: &libc::timespec) -> Option<Duration> {
    let secs = u64::try_from(ts.tv_sec).ok()?;
    let nanos = u32::try_from(ts.tv_nsec).ok()?;
    (secs != 0 || nanos != 0).then(|| Duration::new(secs, nanos))
}

/// Receive one frame into `buf` (which must hold a `canfd_frame`), without waiting.
pub fn receive(fd: BorrowedFd<'_>, buf: &mut [u8]) -> io::Result<Message> {
    let mut iov = libc::iovec {
        iov_base: buf.as_mut_ptr().cast(),
        iov_len: buf.len(),
    };
    let mut control = Control([0; 256]);
    // SAFETY: msghdr is a plain C struct for which all-zero is a valid (empty) value.
    let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control.0.as_mut_ptr().cast();
    msg.msg_controllen = control.0.len();
    // SAFETY: `msg` points at `iov` (which points at `buf`) and `control`, all alive and
    // exclusively borrowed for the call, with their true lengths.
    let n = unsafe { libc::recvmsg(fd.as_raw_fd(), &mut msg, libc::MSG_DONTWAIT) };
    let len = usize::try_from(n).map_err(|_| io::Error::last_os_error())?;
    let mut out = Message {
        len,
        confirm: msg.msg_flags & libc::MSG_CONFIRM != 0,
        local: msg.msg_flags & libc::MSG_DONTROUTE != 0,
        ..Message::default()
    };
    let timestamps_len = 3 * size_of::<libc::timespec>();
    // SAFETY: the kernel filled `msg_control` with well-formed control messages up to
    // `msg_controllen`; CMSG_FIRSTHDR/CMSG_NXTHDR stay within it and return null at its end.
    let mut cmsg = unsafe { libc::CMSG_FIRSTHDR(&msg) };
    // Bounded: each step moves forward within the control buffer until null.
    while !cmsg.is_null() {
        // SAFETY: non-null headers from CMSG_FIRSTHDR/NXTHDR point into `control`.
        let header = unsafe { &*cmsg };
        // SAFETY: CMSG_LEN is a pure size computation.
        let header_len = usize::try_from(unsafe { libc::CMSG_LEN(0) }).unwrap_or(usize::MAX);
        let payload = header.cmsg_len.saturating_sub(header_len);
        // SAFETY: CMSG_DATA points at this message's payload, `payload` bytes long.
        let data = unsafe { libc::CMSG_DATA(cmsg) };
        if header.cmsg_level == libc::SOL_SOCKET {
            if header.cmsg_type == libc::SO_TIMESTAMPING && payload >= timestamps_len {
                // SAFETY: the payload holds three timespecs (checked above); it may be unaligned.
                let stamps: [libc::timespec; 3] = unsafe { std::ptr::read_unaligned(data.cast()) };
                out.software = duration(&stamps[0]);
                out.hardware = duration(&stamps[2]);
            } else if header.cmsg_type == libc::SO_RXQ_OVFL && payload >= size_of::<u32>() {
                // SAFETY: the payload holds a u32 (checked above); it may be unaligned.
                out.dropped = Some(unsafe { std::ptr::read_unaligned(data.cast::<u32>()) });
            }
        }
        // SAFETY: as for CMSG_FIRSTHDR.
        cmsg = unsafe { libc::CMSG_NXTHDR(&msg, cmsg) };
    }
    Ok(out)
}

/// Wait until a frame can be read, up to `timeout` (`None`: forever); whether one can.
pub fn wait_readable(fd: BorrowedFd<'_>, timeout: Option<Duration>) -> io::Result<bool> {
    let mut pollfd = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // Whole milliseconds, rounded up so that a short timeout still waits.
    let millis = timeout.map_or(-1, |t| {
        let ms = t.as_nanos().div_ceil(1_000_000);
        libc::c_int::try_from(ms).unwrap_or(libc::c_int::MAX)
    });
    // SAFETY: one valid pollfd, count 1.
    let n = unsafe { libc::poll(&mut pollfd, 1, millis) };
    match n {
        n if n < 0 => {
            let e = io::Error::last_os_error();
            if e.kind() == io::ErrorKind::Interrupted {
                Ok(false)
            } else {
                Err(e)
            }
        }
        0 => Ok(false),
        _ => Ok(true),
    }
}

/// Send one frame structure; the number of bytes sent. `wait`: block while the socket's send
/// buffer is full (the kernel's back-pressure for a fast sender), else fail with `WouldBlock`.
pub fn send(fd: BorrowedFd<'_>, bytes: &[u8], wait: bool) -> io::Result<usize> {
    let flags = if wait { 0 } else { libc::MSG_DONTWAIT };
    // SAFETY: `bytes` is a valid buffer of its length for the duration of the call.
    let n = unsafe { libc::send(fd.as_raw_fd(), bytes.as_ptr().cast(), bytes.len(), flags) };
    usize::try_from(n).map_err(|_| io::Error::last_os_error())
}

/// Register a socket with the current tokio reactor.
#[cfg(feature = "tokio")]
pub fn register_async(
    bus: super::SocketCan,
) -> io::Result<tokio::io::unix::AsyncFd<super::SocketCan>> {
    // Registration panics outside a runtime; refuse with an error instead.
    tokio::runtime::Handle::try_current().map_err(io::Error::other)?;
    // SAFETY: the socket's descriptor is owned by `bus` (through its shared state, which the
    // AsyncFd owns) and is closed only when the last owner drops it, after the AsyncFd;
    // `as_raw_fd` always returns that same descriptor.
    unsafe { tokio::io::unix::AsyncFd::register(bus) }.map_err(|e| e.into_parts().1)
}
