//! # bywire-bus: one interface to every CAN bus
//!
//! A [`Bus`] sends frames and receives them with timestamps, applies SocketCAN-style filters,
//! reports counts, and can be split into a sending and a receiving half for two threads. One
//! string names any bus ([`BusSpec`]): `virtual:NAME` is an in-process bus that any number of
//! endpoints share, `sim:NAME@BITRATE` the same with a wire's timing (arbitration, frame times,
//! error confinement), `socketcan:IFACE` a Linux interface.
//!
//! ```
//! use bywire_bus::{open, Bus};
//! let mut a = open("virtual:doc-example").unwrap();
//! let mut b = open("virtual:doc-example").unwrap();
//! a.send(&"123#DEADBEEF".parse().unwrap()).unwrap();
//! let got = b.recv(Some(std::time::Duration::from_secs(1))).unwrap().unwrap();
//! assert_eq!(got.frame.to_string(), "123#DEADBEEF");
//! ```

pub mod faults;
pub mod runner;
pub mod sim_endpoint;
pub mod slcan;
#[cfg(target_os = "linux")]
pub mod socketcan;
pub mod socketcand;
mod spec;
pub mod udp;
pub mod virtual_bus;

use std::sync::OnceLock;
use std::time::{Duration, Instant, SystemTime};

use bywire_core::{Frame, Timestamp};

/// Unix time in nanoseconds from a monotonic clock: the wall clock is read once per process and
/// the monotonic time since then added, so in-process buses stamp frames as SocketCAN does
/// (since the Unix epoch) without going backwards when the wall clock is set.
pub fn monotonic_unix_now() -> Timestamp {
    static ANCHOR: OnceLock<(Instant, Duration)> = OnceLock::new();
    let (instant, unix) = *ANCHOR.get_or_init(|| {
        let unix = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or_default();
        (Instant::now(), unix)
    });
    let nanos = (unix + instant.elapsed()).as_nanos();
    Timestamp::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
}

/// The in-process vocabulary every backend shares, defined with the simulated engine.
pub use bywire_net::{Filtering, Received};
pub use spec::{
    is_in_process, open, open_listening, register, schemes, Backend, BusSpec, Listening, OpenError,
    RegisterError, SpecError,
};

/// Counts an endpoint keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Frames sent.
    pub tx_frames: u64,
    /// Data bytes sent.
    pub tx_bytes: u64,
    /// Frames received.
    pub rx_frames: u64,
    /// Data bytes received.
    pub rx_bytes: u64,
    /// Frames dropped because this endpoint's queue was full.
    pub rx_dropped: u64,
    /// Error frames received.
    pub rx_errors: u64,
}

impl Stats {
    /// Count a frame this endpoint sent.
    pub fn count_sent(&mut self, frame: &Frame) {
        self.tx_frames += 1;
        self.tx_bytes += u64::try_from(frame.data().len()).unwrap_or(0);
    }

    /// Count a frame this endpoint received.
    pub fn count_received(&mut self, frame: &Frame) {
        self.rx_frames += 1;
        self.rx_bytes += u64::try_from(frame.data().len()).unwrap_or(0);
        if frame.is_error() {
            self.rx_errors += 1;
        }
    }
}

/// A controller's fault-confinement state, as SocketCAN names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ControllerState {
    /// Both error counters below 96.
    ErrorActive,
    /// A counter at 96 or more (a warning; still error active on the wire).
    ErrorWarning,
    /// A counter above 127.
    ErrorPassive,
    /// Off the bus (transmit counter above 255).
    BusOff,
    /// The interface is down.
    Stopped,
    /// The controller sleeps.
    Sleeping,
}

/// A controller's state and error counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BusStatus {
    /// The state.
    pub state: ControllerState,
    /// Transmit error counter.
    pub tec: u16,
    /// Receive error counter.
    pub rec: u16,
}

/// What can go wrong on a bus.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BusError {
    /// The bus is gone (all other ends closed, interface down).
    #[error("the bus is closed")]
    Closed,
    /// The frame cannot go on this bus (an FD frame on a classic-only bus, an error frame).
    #[error("this bus cannot send {0}")]
    Unsupported(String),
    /// An operating-system error (transparent: said once, not again as its source).
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// The state both halves of a split endpoint share (behind an `Arc`): one implementation of
/// sending and receiving per backend, used by the endpoint and by its halves alike.
pub(crate) trait SharedEndpoint: Send + Sync + 'static {
    /// As [`BusTx::send`].
    fn send(&self, frame: &Frame) -> Result<(), BusError>;
    /// As [`BusRx::recv`].
    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError>;
    /// As [`BusRx::stats`].
    fn stats(&self) -> Stats;
}

/// One half of a split endpoint.
struct Half<E>(std::sync::Arc<E>);

impl<E: SharedEndpoint> BusTx for Half<E> {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.0.send(frame)
    }
}

impl<E: SharedEndpoint> BusRx for Half<E> {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.0.recv(timeout)
    }

    fn stats(&self) -> Stats {
        self.0.stats()
    }
}

/// The two halves of an endpoint whose state is `shared`.
pub(crate) fn split_halves<E: SharedEndpoint>(
    shared: std::sync::Arc<E>,
) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
    (
        Box::new(Half(std::sync::Arc::clone(&shared))),
        Box::new(Half(shared)),
    )
}

/// The sending half of a bus endpoint.
pub trait BusTx: Send {
    /// Queue a frame for sending; returns when the backend has taken it.
    fn send(&mut self, frame: &Frame) -> Result<(), BusError>;
}

/// The receiving half of a bus endpoint.
pub trait BusRx: Send {
    /// The next frame, waiting up to `timeout` (`None`: wait forever); `Ok(None)` on timeout.
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError>;
    /// The endpoint's counts (both halves of a split endpoint share them), so a receiver can
    /// report what its queue dropped.
    fn stats(&self) -> Stats;
}

/// One endpoint on a bus.
pub trait Bus: BusTx + BusRx {
    /// Replace the receive filters.
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError>;
    /// Receive the frames this endpoint sends (off by default, as in SocketCAN).
    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError>;
    /// Deliver this endpoint's frames to the other endpoints of this host (on by default, as
    /// SocketCAN's `CAN_RAW_LOOPBACK`). Backends without local endpoints ignore it.
    fn set_loopback(&mut self, on: bool) -> Result<(), BusError>;
    /// The controller's state and error counters, where the backend knows them.
    fn status(&self) -> Result<Option<BusStatus>, BusError> {
        Ok(None)
    }
    /// Ask for a receive buffer of `bytes` (candump's `-r`): only a kernel socket has one.
    fn set_receive_buffer(&mut self, bytes: usize) -> Result<(), BusError> {
        let _ = bytes;
        Err(BusError::Unsupported(
            "a receive buffer size (SocketCAN's alone)".into(),
        ))
    }
    /// Split into a sending and a receiving half (for two threads).
    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>);
}
