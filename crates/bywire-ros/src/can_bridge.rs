//! CAN buses as ROS 2 topics, as Autoware's `ros2_socketcan` offers them: frames received on a
//! bus are published on `from_can_bus` (CAN FD on `from_can_bus_fd`), messages arriving on
//! `to_can_bus` (`to_can_bus_fd`) are sent on the bus.
//!
//! One thread per bus receives and publishes; the caller's thread waits on every subscription
//! at once and sends. A bus that fails is reported and left out, the others go on; the bridge
//! ends with an error only when every bus is lost. A message that makes no valid frame is
//! refused (reported with the field at fault) and nothing is sent for it.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use bywire_bus::{Bus, BusError, BusTx};
use bywire_core::Frame;

use crate::dds::{mio1, reliable, Publisher, RosError, RosNode, Subscription, POLL_SLICE};
use crate::frames::{self, Published};
use crate::msg::{CanFrame, FdFrame, Time};

/// The queue depth ros2_socketcan gives its topics.
const DEPTH: usize = 500;
/// Messages taken from one subscription before the others get their turn.
const TAKE_BATCH: usize = 256;

/// Topic names (relative names go under the node's namespace, and under the bus's name when
/// several buses are bridged).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanTopics {
    /// Received classic frames.
    pub from_can_bus: String,
    /// Classic frames to send.
    pub to_can_bus: String,
    /// Received CAN FD frames.
    pub from_can_bus_fd: String,
    /// CAN FD frames to send.
    pub to_can_bus_fd: String,
}

impl Default for CanTopics {
    fn default() -> Self {
        CanTopics {
            from_can_bus: "from_can_bus".to_string(),
            to_can_bus: "to_can_bus".to_string(),
            from_can_bus_fd: "from_can_bus_fd".to_string(),
            to_can_bus_fd: "to_can_bus_fd".to_string(),
        }
    }
}

/// How the bridge behaves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanBridgeConfig {
    /// Topic names.
    pub topics: CanTopics,
    /// `header.frame_id` of published frames; `None`: `can` for one bus (as ros2_socketcan),
    /// each bus's name for several.
    pub frame_id: Option<String>,
    /// Stamp frames with the time the bus gave them, not the time they are published.
    pub use_bus_time: bool,
    /// Publish the frames the bridge sends, too (as a second socket on the bus sees them).
    pub loopback: bool,
    /// Publish every frame, classic ones too, on the FD topic (ros2_socketcan's
    /// `enable_can_fd`).
    pub fd_for_all: bool,
    /// Send FD frames with the bit-rate switch.
    pub brs: bool,
}

impl Default for CanBridgeConfig {
    fn default() -> Self {
        CanBridgeConfig {
            topics: CanTopics::default(),
            frame_id: None,
            use_bus_time: false,
            loopback: true,
            fd_for_all: false,
            brs: true,
        }
    }
}

/// A bus to bridge, with the name it goes by (its interface).
pub struct BridgedBus {
    /// The name (`can0`): the frame id with several buses, and their topics' namespace.
    pub name: String,
    /// The open bus.
    pub bus: Box<dyn Bus>,
}

/// Something the caller should hear of while the bridge runs.
#[derive(Debug)]
pub enum BridgeEvent {
    /// A message was not sent; on which bus and why.
    Refused {
        /// The bus.
        bus: String,
        /// Why.
        why: String,
    },
    /// A bus failed and is left out.
    BusLost {
        /// The bus.
        bus: String,
        /// What failed.
        error: String,
    },
    /// The bus works, but cannot give back the frames sent on it (socketcand's raw mode has
    /// no echo): frames from DDS are not published back as received.
    NoEcho {
        /// The bus.
        bus: String,
        /// Why.
        why: String,
    },
    /// A publish failed (DDS back-pressure or a closed participant); the frame is not published.
    PublishFailed {
        /// The bus.
        bus: String,
        /// What failed.
        error: String,
    },
}

/// Counts of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BridgeStats {
    /// Frames published (both topics).
    pub published: u64,
    /// Frames sent on a bus.
    pub sent: u64,
    /// Messages refused.
    pub refused: u64,
}

/// A bus's name as a ROS 2 name token (`virtual:a` → `virtual_a`).
pub fn name_token(name: &str) -> String {
    let mut token: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    while token.contains("__") {
        token = token.replace("__", "_");
    }
    let token = token.trim_matches('_').to_string();
    if token.starts_with(|c: char| c.is_ascii_alphabetic()) {
        token
    } else {
        format!("bus_{token}")
    }
}

fn topic_for(bus: &str, topic: &str, several: bool) -> String {
    if several && !topic.starts_with('/') {
        format!("{}/{topic}", name_token(bus))
    } else {
        topic.to_string()
    }
}

struct Outgoing {
    name: String,
    tx: Option<Box<dyn BusTx>>,
    classic: Subscription<CanFrame>,
    fd: Subscription<FdFrame>,
}

struct Shared {
    stop: AtomicBool,
    published: AtomicU64,
}

/// Bridge `buses` through `node` until `stop` is set or every bus is lost.
pub fn run(
    node: &mut RosNode,
    buses: Vec<BridgedBus>,
    config: &CanBridgeConfig,
    stop: &AtomicBool,
    report: &mut dyn FnMut(BridgeEvent),
) -> Result<BridgeStats, RosError> {
    let several = buses.len() > 1;
    let qos = reliable(DEPTH);
    let (events_tx, events) = mpsc::channel();
    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        published: AtomicU64::new(0),
    });
    let mut outgoing = Vec::with_capacity(buses.len());
    let mut readers = Vec::with_capacity(buses.len());
    for BridgedBus { name, mut bus } in buses {
        let topic = |t: &str| topic_for(&name, t, several);
        let classic_out = node.publisher::<CanFrame>(&topic(&config.topics.from_can_bus), &qos)?;
        let fd_out = node.publisher::<FdFrame>(&topic(&config.topics.from_can_bus_fd), &qos)?;
        let classic = node.subscription::<CanFrame>(&topic(&config.topics.to_can_bus), &qos)?;
        let fd = node.subscription::<FdFrame>(&topic(&config.topics.to_can_bus_fd), &qos)?;
        if let Err(e) = bus.set_receive_own(config.loopback) {
            report(BridgeEvent::NoEcho {
                bus: name.clone(),
                why: match e {
                    bywire_bus::BusError::Unsupported(what) => format!("no {what}"),
                    other => other.to_string(),
                },
            });
        }
        let (tx, rx) = bus.split();
        let frame_id = config.frame_id.clone().unwrap_or_else(|| {
            if several {
                name.clone()
            } else {
                "can".into()
            }
        });
        let reader = Reader {
            name: name.clone(),
            frame_id,
            use_bus_time: config.use_bus_time,
            fd_for_all: config.fd_for_all,
            classic: classic_out,
            fd: fd_out,
            events: events_tx.clone(),
            shared: Arc::clone(&shared),
        };
        readers.push(std::thread::spawn(move || reader.run(rx)));
        outgoing.push(Outgoing {
            name,
            tx: Some(tx),
            classic,
            fd,
        });
    }
    drop(events_tx);
    let result = forward(&mut outgoing, config, stop, &events, report);
    shared.stop.store(true, Ordering::Relaxed);
    join(readers, &events, report);
    let mut stats = result?;
    stats.published = shared.published.load(Ordering::Relaxed);
    Ok(stats)
}

/// Wait on every subscription; send what arrives until `stop` or every bus is lost.
fn forward(
    outgoing: &mut [Outgoing],
    config: &CanBridgeConfig,
    stop: &AtomicBool,
    events: &Receiver<BridgeEvent>,
    report: &mut dyn FnMut(BridgeEvent),
) -> Result<BridgeStats, RosError> {
    let io = |e: std::io::Error| RosError::Create(format!("polling the subscriptions: {e}"));
    let mut poll = mio1::Poll::new().map_err(io)?;
    for (index, out) in outgoing.iter_mut().enumerate() {
        let registry = poll.registry();
        registry
            .register(
                &mut out.classic,
                mio1::Token(2 * index),
                mio1::Interest::READABLE,
            )
            .map_err(io)?;
        registry
            .register(
                &mut out.fd,
                mio1::Token(2 * index + 1),
                mio1::Interest::READABLE,
            )
            .map_err(io)?;
    }
    let mut mio_events = mio1::Events::with_capacity(64);
    let mut stats = BridgeStats::default();
    while !stop.load(Ordering::Relaxed) {
        // Readiness is edge-triggered: every subscription is drained on every pass (the take
        // is cheap when nothing waits), so none is left behind by a missed edge.
        if let Err(e) = poll.poll(&mut mio_events, Some(POLL_SLICE)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(io(e));
            }
        }
        for out in outgoing.iter_mut() {
            drain(out, config, &mut stats, report);
        }
        while let Ok(event) = events.try_recv() {
            if let BridgeEvent::BusLost { bus, .. } = &event {
                if let Some(out) = outgoing.iter_mut().find(|o| &o.name == bus) {
                    out.tx = None;
                }
            }
            report(event);
        }
        if outgoing.iter().all(|o| o.tx.is_none()) {
            return Err(RosError::Create("every bus is lost".into()));
        }
    }
    Ok(stats)
}

/// Send what waits on one bus's subscriptions (at most a batch of each).
fn drain(
    out: &mut Outgoing,
    config: &CanBridgeConfig,
    stats: &mut BridgeStats,
    report: &mut dyn FnMut(BridgeEvent),
) {
    let mut frames: Vec<Result<Frame, String>> = Vec::new();
    for _ in 0..TAKE_BATCH {
        match out.classic.take() {
            Ok(Some((message, _))) => {
                frames.push(frames::from_ros(&message).map_err(|e| {
                    format!("{}: id {:#X}: {e}", config.topics.to_can_bus, message.id)
                }))
            }
            Ok(None) => break,
            Err(e) => frames.push(Err(format!("{}: {e:?}", config.topics.to_can_bus))),
        }
    }
    for _ in 0..TAKE_BATCH {
        match out.fd.take() {
            Ok(Some((message, _))) => {
                frames.push(frames::from_ros_fd(&message, config.brs).map_err(|e| {
                    format!("{}: id {:#X}: {e}", config.topics.to_can_bus_fd, message.id)
                }))
            }
            Ok(None) => break,
            Err(e) => frames.push(Err(format!("{}: {e:?}", config.topics.to_can_bus_fd))),
        }
    }
    for frame in frames {
        let frame = match frame {
            Ok(frame) => frame,
            Err(why) => {
                stats.refused += 1;
                report(BridgeEvent::Refused {
                    bus: out.name.clone(),
                    why,
                });
                continue;
            }
        };
        let Some(tx) = out.tx.as_mut() else {
            continue;
        };
        match tx.send(&frame) {
            Ok(()) => stats.sent += 1,
            Err(BusError::Unsupported(why)) => {
                stats.refused += 1;
                report(BridgeEvent::Refused {
                    bus: out.name.clone(),
                    why: format!("this bus cannot send {why}"),
                });
            }
            Err(e) => {
                out.tx = None;
                report(BridgeEvent::BusLost {
                    bus: out.name.clone(),
                    error: e.to_string(),
                });
            }
        }
    }
}

/// Stop the readers, passing on what they still had to say.
fn join(
    readers: Vec<JoinHandle<()>>,
    events: &Receiver<BridgeEvent>,
    report: &mut dyn FnMut(BridgeEvent),
) {
    for reader in readers {
        while !reader.is_finished() {
            while let Ok(event) = events.try_recv() {
                report(event);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = reader.join();
    }
    while let Ok(event) = events.try_recv() {
        report(event);
    }
}

/// One bus's receiving side.
struct Reader {
    name: String,
    frame_id: String,
    use_bus_time: bool,
    fd_for_all: bool,
    classic: Publisher<CanFrame>,
    fd: Publisher<FdFrame>,
    events: Sender<BridgeEvent>,
    shared: Arc<Shared>,
}

impl Reader {
    fn run(self, mut rx: Box<dyn bywire_bus::BusRx>) {
        let mut publish_failures = 0u64;
        while !self.shared.stop.load(Ordering::Relaxed) {
            let received = match rx.recv(Some(POLL_SLICE)) {
                Ok(Some(received)) => received,
                Ok(None) => continue,
                Err(e) => {
                    let _ = self.events.send(BridgeEvent::BusLost {
                        bus: self.name.clone(),
                        error: e.to_string(),
                    });
                    return;
                }
            };
            let stamp = if self.use_bus_time {
                Time::from_nanos(received.timestamp.as_nanos())
            } else {
                Time::now()
            };
            let published = match frames::to_ros(&received.frame, stamp, &self.frame_id) {
                Published::Classic(m) if self.fd_for_all => self.fd.publish(as_fd(m)).is_ok(),
                Published::Classic(m) => self.classic.publish(m).is_ok(),
                Published::Fd(m) => self.fd.publish(m).is_ok(),
            };
            if published {
                self.shared.published.fetch_add(1, Ordering::Relaxed);
            } else {
                publish_failures += 1;
                // The first failure and then one in a thousand: a stalled peer must not flood.
                if publish_failures % 1000 == 1 {
                    let _ = self.events.send(BridgeEvent::PublishFailed {
                        bus: self.name.clone(),
                        error: format!("{publish_failures} frames not published (DDS would block)"),
                    });
                }
            }
        }
    }
}

/// A classic frame on the FD topic (ros2_socketcan's `enable_can_fd`): its data, its length.
fn as_fd(m: CanFrame) -> FdFrame {
    let len = if m.is_rtr {
        0
    } else {
        usize::from(m.dlc.min(8))
    };
    FdFrame {
        header: m.header,
        id: m.id,
        is_extended: m.is_extended,
        is_error: m.is_error,
        len: u8::try_from(len).unwrap_or(8),
        data: m.data.get(..len).unwrap_or(&m.data).to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bus_names_become_name_tokens() {
        assert_eq!(name_token("can0"), "can0");
        assert_eq!(name_token("virtual:a b"), "virtual_a_b");
        assert_eq!(
            name_token("udp:239.74.163.2:43113"),
            "udp_239_74_163_2_43113"
        );
        assert_eq!(name_token("0x"), "bus_0x");
        assert_eq!(topic_for("can1", "from_can_bus", true), "can1/from_can_bus");
        assert_eq!(topic_for("can1", "/abs", true), "/abs");
        assert_eq!(topic_for("can1", "from_can_bus", false), "from_can_bus");
    }

    #[test]
    fn classic_frames_on_the_fd_topic_keep_their_length() {
        let m = CanFrame {
            id: 5,
            dlc: 3,
            data: [1, 2, 3, 0, 0, 0, 0, 0],
            ..CanFrame::default()
        };
        let fd = as_fd(m);
        assert_eq!((fd.len, fd.data), (3, vec![1, 2, 3]));
    }
}
