//! `socketcan:IFACE`: a Linux SocketCAN raw socket (classic and FD) as a [`Bus`].
//!
//! The well-kept `socketcan` crate opens the socket, sets its options and speaks netlink for the
//! link configuration and the controller's state. Reception is our own (`sys.rs`): it needs the
//! `MSG_CONFIRM` flag to tell this socket's echoed frames — the transmit confirmations, with the
//! time the frame left — from identical frames of other nodes, plus the kernel's drop counter and
//! hardware timestamps from the same `recvmsg`, which the crate does not return together.

#[cfg(feature = "tokio")]
mod async_bus;
mod layout;
mod sys;

#[cfg(feature = "tokio")]
pub use async_bus::AsyncSocketCan;

use std::io;
use std::os::fd::AsFd;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use bywire_core::{Frame, Timestamp};
use socketcan::nl::CanState;
use socketcan::{CanFdSocket, CanInterface, Socket, SocketOptions};

pub use layout::LayoutError;

use crate::{
    Bus, BusError, BusRx, BusStatus, BusTx, ControllerState, Filtering, Received, SharedEndpoint,
    Stats,
};

/// How long a send waits for room in the interface's transmit queue before giving up.
const SEND_PATIENCE: Duration = Duration::from_secs(1);

struct Shared {
    socket: CanFdSocket,
    interface: String,
    stats: Mutex<Stats>,
}

impl Shared {
    fn stats(&self) -> std::sync::MutexGuard<'_, Stats> {
        self.stats.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A raw CAN socket bound to one interface.
pub struct SocketCan {
    shared: Arc<Shared>,
}

impl std::os::fd::AsRawFd for SocketCan {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        self.shared.socket.as_raw_fd()
    }
}

fn io_error(context: &str, e: impl std::fmt::Display) -> BusError {
    BusError::Io(io::Error::other(format!("{context}: {e}")))
}

impl SocketCan {
    /// Open a raw socket on `interface` (`can0`, `vcan0`): FD frames enabled, every data frame,
    /// no error frames, own frames off, software and hardware receive timestamps on.
    pub fn open(interface: &str) -> Result<SocketCan, BusError> {
        let socket = CanFdSocket::open(interface)
            .map_err(|e| BusError::Io(io::Error::new(e.kind(), format!("{interface}: {e}"))))?;
        let stamping = socketcan::timestamp::SOF_TIMESTAMPING_SOFTWARE
            | socketcan::timestamp::SOF_TIMESTAMPING_RX_SOFTWARE
            | socketcan::timestamp::SOF_TIMESTAMPING_RX_HARDWARE
            | socketcan::timestamp::SOF_TIMESTAMPING_RAW_HARDWARE;
        socket.set_timestamping(stamping)?;
        socket.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RXQ_OVFL, 1)?;
        Ok(SocketCan {
            shared: Arc::new(Shared {
                socket,
                interface: interface.to_string(),
                stats: Mutex::default(),
            }),
        })
    }

    /// Ask for a receive buffer of `bytes` (the kernel doubles it for bookkeeping and keeps a
    /// minimum of its own); frames that find it full are dropped and counted. As candump's
    /// `-r`: beyond `net.core.rmem_max` with `CAP_NET_ADMIN` (`SO_RCVBUFFORCE`), else capped.
    pub fn set_receive_buffer(&self, bytes: usize) -> Result<(), BusError> {
        let bytes = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
        let socket = &self.shared.socket;
        socket
            .set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, bytes)
            .or_else(|_| socket.set_socket_option_int(libc::SOL_SOCKET, libc::SO_RCVBUF, bytes))
            .map_err(BusError::from)
    }

    /// The interface this socket is bound to.
    pub fn interface(&self) -> &str {
        &self.shared.interface
    }
}

/// One attempt to hand a frame to the kernel.
enum Attempt {
    Sent,
    /// The interface's queue (or the socket's send buffer) is full; try again shortly.
    Full,
}

fn try_send(shared: &Shared, frame: &Frame, wait: bool) -> Result<Attempt, BusError> {
    let mut buf = [0u8; layout::CANFD_MTU];
    let size = layout::frame_to_bytes(frame, &mut buf)
        .ok_or_else(|| BusError::Unsupported("error frames (only controllers make them)".into()))?;
    let bytes = buf.get(..size).unwrap_or(&buf);
    match sys::send(shared.socket.as_fd(), bytes, wait) {
        Ok(n) if n == size => {
            shared.stats().count_sent(frame);
            Ok(Attempt::Sent)
        }
        Ok(n) => Err(BusError::Io(io::Error::other(format!(
            "{}: wrote {n} of {size} bytes",
            shared.interface
        )))),
        Err(e)
            if e.raw_os_error() == Some(libc::ENOBUFS) || e.kind() == io::ErrorKind::WouldBlock =>
        {
            Ok(Attempt::Full)
        }
        Err(e) if e.raw_os_error() == Some(libc::EINVAL) && frame.is_fd() => {
            Err(BusError::Unsupported(format!(
                "FD frames on {} (its MTU is for classic frames)",
                shared.interface
            )))
        }
        Err(e) => Err(BusError::Io(io::Error::new(
            e.kind(),
            format!("{}: {e}", shared.interface),
        ))),
    }
}

fn queue_full(shared: &Shared) -> BusError {
    BusError::Io(io::Error::new(
        io::ErrorKind::TimedOut,
        format!(
            "{}: transmit queue full for {SEND_PATIENCE:?} (is the bus connected?)",
            shared.interface
        ),
    ))
}

fn send(shared: &Shared, frame: &Frame) -> Result<(), BusError> {
    let give_up = Instant::now() + SEND_PATIENCE;
    let mut pause = Duration::from_micros(50);
    // Bounded by SEND_PATIENCE: a full queue cannot be waited for with poll() on a CAN socket
    // (ENOBUFS), so back off and retry.
    loop {
        match try_send(shared, frame, true)? {
            Attempt::Sent => return Ok(()),
            Attempt::Full if Instant::now() < give_up => {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(5));
            }
            Attempt::Full => return Err(queue_full(shared)),
        }
    }
}

fn since_epoch(d: Duration) -> Timestamp {
    Timestamp::from_nanos(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// Read one frame the socket has ready; `None` if there was none after all.
fn receive_ready(shared: &Shared) -> Result<Option<Received>, BusError> {
    let mut buf = [0u8; layout::CANFD_MTU];
    let message = match sys::receive(shared.socket.as_fd(), &mut buf) {
        Ok(message) => message,
        Err(e)
            if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::Interrupted =>
        {
            return Ok(None)
        }
        Err(e) => return Err(e.into()),
    };
    let bytes = buf.get(..message.len).unwrap_or(&buf);
    let frame = layout::frame_from_bytes(bytes)
        .map_err(|e| BusError::Io(io::Error::new(io::ErrorKind::InvalidData, e)))?;
    let software = message.software.unwrap_or_else(|| {
        SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or_default()
    });
    let mut stats = shared.stats();
    stats.count_received(&frame);
    if let Some(dropped) = message.dropped {
        stats.rx_dropped = u64::from(dropped);
    }
    Ok(Some(Received {
        frame,
        timestamp: since_epoch(software),
        own: message.confirm,
        local: message.local || message.confirm,
        hardware: message.hardware.map(since_epoch),
    }))
}

fn recv(shared: &Shared, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
    let deadline = timeout.map(|t| Instant::now() + t);
    // Each pass waits up to the deadline; it repeats only after a signal or a spurious wake-up.
    loop {
        let left = deadline.map(|d| d.saturating_duration_since(Instant::now()));
        if sys::wait_readable(shared.socket.as_fd(), left)? {
            if let Some(received) = receive_ready(shared)? {
                return Ok(Some(received));
            }
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            return Ok(None);
        }
    }
}

impl SharedEndpoint for Shared {
    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        send(self, frame)
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        recv(self, timeout)
    }

    fn stats(&self) -> Stats {
        *Shared::stats(self)
    }
}

impl BusTx for SocketCan {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.shared.send(frame)
    }
}

impl BusRx for SocketCan {
    /// Timestamps are the kernel's software receive time (since the Unix epoch), or for own
    /// frames the time the echo came back; `hardware` holds the controller's time when the
    /// driver gives one.
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.shared.recv(timeout)
    }

    fn stats(&self) -> Stats {
        *Shared::stats(&self.shared)
    }
}

impl Bus for SocketCan {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        let socket = &self.shared.socket;
        // struct can_filter[]: can_id and can_mask, native endian; empty receives no frames.
        let list: Vec<u8> = filtering
            .filters
            .iter()
            .flat_map(|f| {
                let mut pair = [0u8; 8];
                let (id, mask) = pair.split_at_mut(4);
                id.copy_from_slice(&f.can_id.to_ne_bytes());
                mask.copy_from_slice(&f.can_mask.to_ne_bytes());
                pair
            })
            .collect();
        socket.set_socket_option_bytes(libc::SOL_CAN_RAW, libc::CAN_RAW_FILTER, &list)?;
        socket.set_error_filter(filtering.error_mask.0)?;
        socket.set_join_filters(filtering.join)?;
        Ok(())
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        Ok(self.shared.socket.set_recv_own_msgs(on)?)
    }

    fn set_loopback(&mut self, on: bool) -> Result<(), BusError> {
        Ok(self.shared.socket.set_loopback(on)?)
    }

    fn set_receive_buffer(&mut self, bytes: usize) -> Result<(), BusError> {
        SocketCan::set_receive_buffer(self, bytes)
    }

    /// From netlink; `None` for interfaces without a controller (vcan).
    fn status(&self) -> Result<Option<BusStatus>, BusError> {
        let link = CanInterface::open(&self.shared.interface)
            .map_err(|e| io_error(&self.shared.interface, e))?;
        let params = link
            .can_params()
            .map_err(|e| io_error(&self.shared.interface, e))?;
        let Some(state) = params.state else {
            return Ok(None);
        };
        let counters = params.berr_counter.unwrap_or_default();
        Ok(Some(BusStatus {
            state: match state {
                CanState::ErrorActive => ControllerState::ErrorActive,
                CanState::ErrorWarning => ControllerState::ErrorWarning,
                CanState::ErrorPassive => ControllerState::ErrorPassive,
                CanState::BusOff => ControllerState::BusOff,
                CanState::Stopped => ControllerState::Stopped,
                CanState::Sleeping => ControllerState::Sleeping,
            },
            tec: counters.txerr,
            rec: counters.rxerr,
        }))
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
        crate::split_halves(self.shared)
    }
}

/// How to configure a CAN interface's link (what `ip link set IFACE type can ...` sets).
/// Fields left `None` keep the interface's current setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkConfig {
    /// Nominal bitrate, bit/s; the kernel computes the bit timing.
    pub bitrate: Option<u32>,
    /// Nominal sample point in tenths of a percent (875 = 87.5 %); the kernel's default if
    /// `None`.
    pub sample_point: Option<u32>,
    /// FD data-phase bitrate (switches FD on).
    pub data_bitrate: Option<u32>,
    /// Data-phase sample point in tenths of a percent.
    pub data_sample_point: Option<u32>,
    /// Automatic restart delay after bus-off, ms (0: restart only on request).
    pub restart_ms: Option<u32>,
}

/// Configure a CAN interface and bring it up (it is taken down first: the kernel refuses bit
/// timing changes on a running interface). Needs `CAP_NET_ADMIN`.
pub fn configure(interface: &str, config: &LinkConfig) -> Result<(), BusError> {
    let fail = |what: &str, e: socketcan::Error| io_error(&format!("{interface}: {what}"), e);
    let link = CanInterface::open(interface).map_err(|e| fail("open", e))?;
    link.bring_down().map_err(|e| fail("down", e))?;
    if let Some(bitrate) = config.bitrate {
        link.set_bit_timing(socketcan::nl::CanBitTiming {
            bitrate,
            sample_point: config.sample_point.unwrap_or(0),
            ..Default::default()
        })
        .map_err(|e| fail("bitrate", e))?;
    }
    if let Some(bitrate) = config.data_bitrate {
        link.set_ctrlmode(socketcan::CanCtrlMode::Fd, true)
            .map_err(|e| fail("fd on", e))?;
        link.set_data_bit_timing(socketcan::nl::CanBitTiming {
            bitrate,
            sample_point: config.data_sample_point.unwrap_or(0),
            ..Default::default()
        })
        .map_err(|e| fail("data bitrate", e))?;
    }
    if let Some(ms) = config.restart_ms {
        link.set_restart_ms(ms).map_err(|e| fail("restart-ms", e))?;
    }
    link.bring_up().map_err(|e| fail("up", e))
}

/// What asking an interface's controller for listen-only mode came to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ListenOnly {
    /// The controller was switched to listen-only (the link went down and up for it).
    Set,
    /// It was listen-only already.
    AlreadyOn,
    /// The interface has no controller (vcan, vxcan): nothing to set.
    NoController,
    /// The controller's driver has no listen-only mode.
    Unsupported,
    /// The kernel refused (usually: no `CAP_NET_ADMIN`); the link is as it was.
    Refused(String),
}

/// Put `interface`'s controller in listen-only mode (it then neither acknowledges frames nor
/// sends error frames: a logger that cannot disturb the bus). The kernel changes control modes
/// only on a link that is down, so a link that was up is taken down for it and brought up
/// again; its bit timing is kept.
pub fn set_listen_only(interface: &str) -> Result<ListenOnly, BusError> {
    switch_listen_only(interface, true)
}

/// Take `interface`'s controller out of listen-only mode (as [`set_listen_only`] in reverse).
pub fn clear_listen_only(interface: &str) -> Result<ListenOnly, BusError> {
    switch_listen_only(interface, false)
}

fn switch_listen_only(interface: &str, on: bool) -> Result<ListenOnly, BusError> {
    use socketcan::CanCtrlMode;
    let link = CanInterface::open(interface).map_err(|e| io_error(interface, e))?;
    let params = link.can_params().map_err(|e| io_error(interface, e))?;
    let Some(modes) = params.ctrl_mode else {
        return Ok(ListenOnly::NoController);
    };
    if modes.has_mode(CanCtrlMode::ListenOnly) == on {
        return Ok(ListenOnly::AlreadyOn);
    }
    let supported = params
        .ctrl_mode_supported
        .is_some_and(|mask| mask & CanCtrlMode::ListenOnly.mask() != 0);
    if !supported {
        return Ok(ListenOnly::Unsupported);
    }
    let was_up = link.details().map_err(|e| io_error(interface, e))?.is_up;
    if was_up {
        if let Err(e) = link.bring_down() {
            return Ok(ListenOnly::Refused(format!("{interface}: down: {e}")));
        }
    }
    let switched = link.set_ctrlmode(CanCtrlMode::ListenOnly, on);
    // Up again whatever came of it: the link is left running as it was found.
    let up = if was_up { link.bring_up() } else { Ok(()) };
    match (switched, up) {
        (Ok(()), Ok(())) => Ok(ListenOnly::Set),
        (Err(e), _) => Ok(ListenOnly::Refused(format!(
            "{interface}: listen-only: {e}"
        ))),
        (Ok(()), Err(e)) => Err(io_error(&format!("{interface}: up"), e)),
    }
}

/// Restart a controller that is bus-off (when automatic restart is off).
pub fn restart(interface: &str) -> Result<(), BusError> {
    let link = CanInterface::open(interface).map_err(|e| io_error(interface, e))?;
    link.restart().map_err(|e| io_error(interface, e))
}

/// The link's bit timing as the kernel computed it: (bitrate, sample point in tenths of a
/// percent), `None` for interfaces without one (vcan).
pub fn bit_timing(interface: &str) -> Result<Option<(u32, u32)>, BusError> {
    let link = CanInterface::open(interface).map_err(|e| io_error(interface, e))?;
    let timing = link.bit_timing().map_err(|e| io_error(interface, e))?;
    Ok(timing.map(|t| (t.bitrate, t.sample_point)))
}

/// The CAN interfaces of this host (link type `ARPHRD_CAN`), sorted by name.
pub fn interfaces() -> io::Result<Vec<String>> {
    const ARPHRD_CAN: &str = "280";
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/sys/class/net")? {
        let path = entry?.path();
        let kind = std::fs::read_to_string(path.join("type")).unwrap_or_default();
        if kind.trim() == ARPHRD_CAN {
            if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
                found.push(name.to_string());
            }
        }
    }
    found.sort();
    Ok(found)
}
