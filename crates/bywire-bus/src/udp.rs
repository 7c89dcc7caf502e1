//! `udp:`: a bus over UDP multicast, wire-compatible with python-can 4.x's `udp_multicast`
//! interface, so python-can processes and bywire processes share a bus with no daemon.
//!
//! One datagram per frame: a msgpack map with `timestamp` (float seconds), `arbitration_id`,
//! `is_extended_id`, `is_remote_frame`, `is_error_frame`, `channel`, `dlc` (the byte length;
//! the DLC for remote frames), `data` (bin), `is_fd`, `bitrate_switch`,
//! `error_state_indicator`. Default group `ff15:7079:7468:6f6e:6465:6d6f:6d63:6173` (IPv6) or
//! `239.74.163.2` (IPv4), port 43113, hop limit 1 (the local link only).
//!
//! Specs: `udp:` (IPv6 default), `udp:ipv4`, `udp:GROUP` or `udp:GROUP:PORT` /
//! `udp:[GROUP]:PORT`.
//!
//! What the protocol cannot do: there is no arbitration, acknowledgement or error signalling,
//! and no transmit confirmation beyond our own datagram looping back. Own frames are told
//! apart because each endpoint sends from its own ephemeral port (python-can sends from the
//! group port and receives its own frames). Malformed datagrams are counted as receive errors
//! and skipped.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use bywire_core::{ClassicFrame, Dlc, ErrorFrame, FdFrame, Frame, Id};
use rmpv::Value;
use socket2::{Domain, Protocol, Socket, Type};

use crate::{Bus, BusError, BusTx, Filtering, Received, SharedEndpoint, Stats};

/// python-can's default IPv6 group.
pub const DEFAULT_GROUP_V6: Ipv6Addr = Ipv6Addr::new(
    0xff15, 0x7079, 0x7468, 0x6f6e, 0x6465, 0x6d6f, 0x6d63, 0x6173,
);
/// python-can's default IPv4 group.
pub const DEFAULT_GROUP_V4: Ipv4Addr = Ipv4Addr::new(239, 74, 163, 2);
/// python-can's default port.
pub const DEFAULT_PORT: u16 = 43113;
/// The receive buffer asked for, in bytes.
const RECEIVE_BUFFER: usize = 8 << 20;
/// Larger than any frame's datagram (an FD frame packs to about 200 bytes).
const MAX_DATAGRAM: usize = 4096;

/// Why a datagram is not a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DatagramError {
    /// Not msgpack, or not a map.
    #[error("not a msgpack map: {0}")]
    NotAMap(String),
    /// A field with the wrong type.
    #[error("field '{0}' has the wrong type")]
    Field(&'static str),
    /// The fields do not make a valid frame.
    #[error("not a valid frame: {0}")]
    Frame(String),
}

/// The datagram python-can sends for `frame`, stamped with `timestamp` (Unix seconds).
pub fn encode(frame: &Frame, timestamp: f64) -> Vec<u8> {
    let (id, extended) = match frame.id() {
        Some(id) => (id.as_raw(), id.is_extended()),
        None => (frame.socketcan_id() & bywire_core::frame::EFF_MASK, false),
    };
    let (brs, esi) = match frame {
        Frame::Fd(fd) => (fd.brs(), fd.esi()),
        _ => (false, false),
    };
    let (dlc, data) = match frame {
        Frame::Classic(c) if c.is_remote() => (c.len(), &[][..]),
        other => (other.data().len(), other.data()),
    };
    let entries = vec![
        ("timestamp", Value::F64(timestamp)),
        ("arbitration_id", Value::from(id)),
        ("is_extended_id", Value::Boolean(extended)),
        ("is_remote_frame", Value::Boolean(frame.is_remote())),
        ("is_error_frame", Value::Boolean(frame.is_error())),
        ("channel", Value::Nil),
        ("dlc", Value::from(u64::try_from(dlc).unwrap_or(0))),
        ("data", Value::Binary(data.to_vec())),
        ("is_fd", Value::Boolean(frame.is_fd())),
        ("bitrate_switch", Value::Boolean(brs)),
        ("error_state_indicator", Value::Boolean(esi)),
    ];
    let map = Value::Map(
        entries
            .into_iter()
            .map(|(k, v)| (Value::from(k), v))
            .collect(),
    );
    let mut out = Vec::with_capacity(160);
    // Writing into a Vec cannot fail.
    let _ = rmpv::encode::write_value(&mut out, &map);
    out
}

/// The frame in a python-can datagram. Missing fields take python-can's `Message` defaults
/// (extended ID, no data); unknown fields are ignored.
pub fn decode(datagram: &[u8]) -> Result<Frame, DatagramError> {
    let mut reader = datagram;
    let value =
        rmpv::decode::read_value(&mut reader).map_err(|e| DatagramError::NotAMap(e.to_string()))?;
    let Value::Map(entries) = value else {
        return Err(DatagramError::NotAMap("another msgpack type".into()));
    };
    let field = |name: &str| {
        entries
            .iter()
            .find(|(k, _)| k.as_str() == Some(name))
            .map(|(_, v)| v)
    };
    let flag = |name: &'static str, default: bool| match field(name) {
        None | Some(Value::Nil) => Ok(default),
        Some(Value::Boolean(b)) => Ok(*b),
        Some(_) => Err(DatagramError::Field(name)),
    };
    let id = match field("arbitration_id") {
        None => 0,
        Some(v) => v
            .as_u64()
            .and_then(|n| u32::try_from(n).ok())
            .ok_or(DatagramError::Field("arbitration_id"))?,
    };
    let data: &[u8] = match field("data") {
        None | Some(Value::Nil) => &[],
        Some(Value::Binary(b)) => b,
        Some(_) => return Err(DatagramError::Field("data")),
    };
    let dlc = match field("dlc") {
        None | Some(Value::Nil) => data.len(),
        Some(v) => v
            .as_u64()
            .and_then(|n| usize::try_from(n).ok())
            .ok_or(DatagramError::Field("dlc"))?,
    };
    let invalid = |e: bywire_core::FrameError| DatagramError::Frame(e.to_string());
    if flag("is_error_frame", false)? {
        return ErrorFrame::new(id & bywire_core::frame::EFF_MASK, data)
            .map(Frame::Error)
            .map_err(invalid);
    }
    let id = if flag("is_extended_id", true)? {
        Id::extended(id).map_err(invalid)?
    } else {
        Id::standard(id).map_err(invalid)?
    };
    if flag("is_remote_frame", false)? {
        let dlc = Dlc::from_classic_len(dlc)
            .ok_or_else(|| DatagramError::Frame(format!("remote frame DLC {dlc}")))?;
        return Ok(Frame::Classic(ClassicFrame::remote(id, dlc)));
    }
    if dlc != data.len() {
        return Err(DatagramError::Frame(format!(
            "dlc {dlc} but {} data bytes",
            data.len()
        )));
    }
    if flag("is_fd", false)? {
        let (brs, esi) = (
            flag("bitrate_switch", false)?,
            flag("error_state_indicator", false)?,
        );
        FdFrame::new(id, data, brs, esi)
            .map(Frame::Fd)
            .map_err(invalid)
    } else {
        ClassicFrame::new(id, data)
            .map(Frame::Classic)
            .map_err(invalid)
    }
}

/// Where a `udp:` spec points: the group and port.
pub fn parse_spec(rest: &str) -> Result<SocketAddr, String> {
    let address = match rest {
        "" | "ipv6" => SocketAddr::new(IpAddr::V6(DEFAULT_GROUP_V6), DEFAULT_PORT),
        "ipv4" => SocketAddr::new(IpAddr::V4(DEFAULT_GROUP_V4), DEFAULT_PORT),
        text => match text.parse::<SocketAddr>() {
            Ok(address) => address,
            Err(_) => text
                .parse::<IpAddr>()
                .map(|ip| SocketAddr::new(ip, DEFAULT_PORT))
                .map_err(|_| {
                    format!("'{text}' is not GROUP, GROUP:PORT or [GROUP]:PORT (e.g. udp:239.74.163.2:43113)")
                })?,
        },
    };
    if !address.ip().is_multicast() {
        return Err(format!("{} is not a multicast group", address.ip()));
    }
    Ok(address)
}

struct Shared {
    receiver: UdpSocket,
    sender: UdpSocket,
    group: SocketAddr,
    own_port: u16,
    filtering: Mutex<Filtering>,
    receive_own: AtomicBool,
    stats: Mutex<Stats>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Every update is complete under the lock; a panic elsewhere cannot leave it half-done.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// An endpoint on a UDP multicast bus.
pub struct UdpMulticast {
    shared: Arc<Shared>,
}

impl UdpMulticast {
    /// Join `group` (with its port): receive on the group port with address reuse, as
    /// python-can does, and send from an ephemeral port with hop limit 1.
    pub fn open(group: SocketAddr) -> std::io::Result<UdpMulticast> {
        let domain = if group.is_ipv6() {
            Domain::IPV6
        } else {
            Domain::IPV4
        };
        let receiver = Socket::new(domain, Type::DGRAM, Some(Protocol::UDP))?;
        receiver.set_reuse_address(true)?;
        receiver.set_reuse_port(true)?;
        // UDP drops what the socket buffer cannot hold; ask for room for bursts of a few
        // thousand frames (the kernel caps it at net.core.rmem_max).
        receiver.set_recv_buffer_size(RECEIVE_BUFFER)?;
        let any: SocketAddr = match group {
            SocketAddr::V6(_) => SocketAddr::new(IpAddr::V6(Ipv6Addr::UNSPECIFIED), group.port()),
            SocketAddr::V4(_) => SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), group.port()),
        };
        if group.is_ipv6() {
            receiver.set_only_v6(true)?;
        }
        receiver.bind(&any.into())?;
        let sender = Socket::new(domain, Type::DGRAM, Some(Protocol::UDP))?;
        match group.ip() {
            IpAddr::V6(ip) => {
                receiver.join_multicast_v6(&ip, 0)?;
                sender.set_multicast_hops_v6(1)?;
                sender.set_multicast_loop_v6(true)?;
                sender.bind(&SocketAddr::new(IpAddr::V6(Ipv6Addr::UNSPECIFIED), 0).into())?;
            }
            IpAddr::V4(ip) => {
                receiver.join_multicast_v4(&ip, &Ipv4Addr::UNSPECIFIED)?;
                sender.set_multicast_ttl_v4(1)?;
                sender.set_multicast_loop_v4(true)?;
                sender.bind(&SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), 0).into())?;
            }
        }
        let sender: UdpSocket = sender.into();
        let own_port = sender.local_addr()?.port();
        Ok(UdpMulticast {
            shared: Arc::new(Shared {
                receiver: receiver.into(),
                sender,
                group,
                own_port,
                filtering: Mutex::new(Filtering::default()),
                receive_own: AtomicBool::new(false),
                stats: Mutex::new(Stats::default()),
            }),
        })
    }
}

fn unix_seconds() -> f64 {
    // Nanoseconds since 1970 fit f64's 53 bits to well under a microsecond.
    #[allow(clippy::cast_precision_loss)]
    let seconds = crate::monotonic_unix_now().as_nanos() as f64 / 1e9;
    seconds
}

impl SharedEndpoint for Shared {
    fn stats(&self) -> Stats {
        *lock(&self.stats)
    }

    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let datagram = encode(frame, unix_seconds());
        self.sender.send_to(&datagram, self.group)?;
        lock(&self.stats).count_sent(frame);
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        let mut buffer = [0u8; MAX_DATAGRAM];
        // Each pass reads one datagram or times out; skipped datagrams go round again until
        // the deadline.
        loop {
            let wait = match deadline {
                Some(d) => {
                    let left = d.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    Some(left)
                }
                None => None,
            };
            self.receiver.set_read_timeout(wait)?;
            let (length, from) = match self.receiver.recv_from(&mut buffer) {
                Ok(got) => got,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None)
                }
                Err(e) => return Err(e.into()),
            };
            let timestamp = crate::monotonic_unix_now();
            let own = from.port() == self.own_port;
            if own && !self.receive_own.load(Ordering::Relaxed) {
                continue;
            }
            let frame = match decode(buffer.get(..length).unwrap_or(&[])) {
                Ok(frame) => frame,
                Err(_) => {
                    lock(&self.stats).rx_errors += 1;
                    continue;
                }
            };
            if !own && !lock(&self.filtering).accepts(&frame) {
                continue;
            }
            lock(&self.stats).count_received(&frame);
            return Ok(Some(Received {
                frame,
                timestamp,
                own,
                // Multicast does not say which host sent a datagram.
                local: own,
                hardware: None,
            }));
        }
    }
}

impl BusTx for UdpMulticast {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.shared.send(frame)
    }
}

impl crate::BusRx for UdpMulticast {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.shared.recv(timeout)
    }

    fn stats(&self) -> Stats {
        SharedEndpoint::stats(self.shared.as_ref())
    }
}

impl Bus for UdpMulticast {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        *lock(&self.shared.filtering) = filtering;
        Ok(())
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        self.shared.receive_own.store(on, Ordering::Relaxed);
        Ok(())
    }

    /// Off: our datagrams do not loop back to this host (other local endpoints, and our own
    /// confirmations, no longer see them).
    fn set_loopback(&mut self, on: bool) -> Result<(), BusError> {
        match self.shared.group {
            SocketAddr::V6(_) => {
                socket2::SockRef::from(&self.shared.sender).set_multicast_loop_v6(on)?
            }
            SocketAddr::V4(_) => {
                socket2::SockRef::from(&self.shared.sender).set_multicast_loop_v4(on)?
            }
        }
        Ok(())
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn crate::BusRx>) {
        crate::split_halves(self.shared)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_survive_the_datagram_format() {
        for text in [
            "123#DEADBEEF",
            "1ABCDEF0#",
            "123#R5",
            "7FF##5000102030405060708090A0B",
            "00000001##6AA",
            "20000080#0000000000000000",
        ] {
            let frame: Frame = text.parse().unwrap();
            assert_eq!(decode(&encode(&frame, 1.5)), Ok(frame), "{text}");
        }
    }

    #[test]
    fn bad_datagrams_are_errors() {
        assert!(matches!(decode(b""), Err(DatagramError::NotAMap(_))));
        assert!(matches!(
            decode(&[0x92, 1, 2]),
            Err(DatagramError::NotAMap(_))
        ));
        let map = |entries: Vec<(&str, Value)>| {
            let v = Value::Map(
                entries
                    .into_iter()
                    .map(|(k, v)| (Value::from(k), v))
                    .collect(),
            );
            let mut out = Vec::new();
            rmpv::encode::write_value(&mut out, &v).unwrap();
            out
        };
        let e = decode(&map(vec![("arbitration_id", Value::from("x"))]));
        assert_eq!(e, Err(DatagramError::Field("arbitration_id")));
        let e = decode(&map(vec![
            ("is_extended_id", Value::Boolean(false)),
            ("arbitration_id", Value::from(0x800)),
        ]));
        assert!(matches!(e, Err(DatagramError::Frame(_))));
        let e = decode(&map(vec![
            ("dlc", Value::from(3)),
            ("data", Value::Binary(vec![1])),
        ]));
        assert!(matches!(e, Err(DatagramError::Frame(_))));
        // python-can's defaults: an extended ID 0 with no data.
        assert_eq!(decode(&map(vec![])), Ok("00000000#".parse().unwrap()));
    }

    #[test]
    fn no_datagram_panics_the_decoder() {
        // Random bytes, and valid datagrams with random bytes changed, truncated or extended.
        let mut rng = fastrand::Rng::with_seed(5);
        let valid = encode(&"1ABCDEF0##5000102030405060708090A0B".parse().unwrap(), 1.0);
        for _ in 0..50_000 {
            let mut bytes: Vec<u8> = if rng.bool() {
                (0..rng.usize(..300)).map(|_| rng.u8(..)).collect()
            } else {
                valid.clone()
            };
            for _ in 0..rng.usize(..4) {
                if let Some(b) = bytes.get_mut(rng.usize(..valid.len())) {
                    *b = rng.u8(..);
                }
            }
            bytes.truncate(rng.usize(..=bytes.len()));
            let _ = decode(&bytes);
        }
    }

    #[test]
    fn specs() {
        assert_eq!(
            parse_spec("").unwrap().to_string(),
            "[ff15:7079:7468:6f6e:6465:6d6f:6d63:6173]:43113"
        );
        assert_eq!(
            parse_spec("ipv4").unwrap().to_string(),
            "239.74.163.2:43113"
        );
        assert_eq!(parse_spec("239.1.2.3:5000").unwrap().port(), 5000);
        assert_eq!(parse_spec("ff02::1").unwrap().port(), DEFAULT_PORT);
        assert!(parse_spec("10.0.0.1")
            .unwrap_err()
            .contains("not a multicast group"));
        assert!(parse_spec("nonsense").is_err());
    }
}
