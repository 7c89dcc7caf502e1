//! A ROS 2 node on DDS: the participant (domain id, bound to chosen interfaces), the node as the
//! ROS 2 graph shows it (`ros_discovery_info`), and its topics, publishers, subscriptions and
//! services under ROS 2's naming: topics get `rt/`, types `pkg::msg::dds_::Type_`, names
//! without a leading slash are taken under the node's namespace.
//!
//! RustDDS with ros2-client is pure Rust (no ROS installation, no C++ build) and speaks RTPS
//! with Cyclone DDS, the middleware ROS 2 uses by default; services use Cyclone's request
//! header mapping, as `rmw_cyclonedds` does.

use std::net::IpAddr;
use std::time::Duration;

use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    Context, Message, MessageTypeName, Name, NodeName, NodeOptions, QosProfile, ServiceMapping,
    ServiceTypeName,
};
use serde::de::DeserializeOwned;
use serde::Serialize;

pub use ros2_client::{Publisher, Server, Subscription};
pub use rustdds::mio1;

use crate::msg::{ControlModeRequest, ControlModeResponse, RosType};

impl Message for ControlModeRequest {}
impl Message for ControlModeResponse {}

/// What can go wrong on the DDS side.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RosError {
    /// A name the ROS 2 naming rules refuse.
    #[error("'{name}' is not a ROS 2 name: {why}")]
    Name {
        /// The name.
        name: String,
        /// Why.
        why: String,
    },
    /// No interface of that name or address on this machine.
    #[error(
        "no network interface '{0}' (give an interface name such as lo, or one of its addresses)"
    )]
    Interface(String),
    /// The participant, a topic, a reader, a writer or a service could not be made.
    #[error("DDS: {0}")]
    Create(String),
}

/// Where and as whom the node runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RosOptions {
    /// The DDS domain (`ROS_DOMAIN_ID`).
    pub domain_id: u16,
    /// The node's namespace (`/` for none).
    pub namespace: String,
    /// The node's name.
    pub node_name: String,
    /// Interfaces (names or addresses) DDS uses; empty: every interface, as DDS does.
    pub interfaces: Vec<String>,
}

impl RosOptions {
    /// A node `name` in domain 0, the root namespace, on every interface.
    pub fn new(name: &str) -> Self {
        RosOptions {
            domain_id: 0,
            namespace: "/".to_string(),
            node_name: name.to_string(),
            interfaces: Vec::new(),
        }
    }
}

/// The QoS ROS 2 uses for `create_publisher(topic, depth)`: reliable, volatile, keep the last
/// `depth`.
pub fn reliable(depth: usize) -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// Reliable and transient-local: a late subscriber gets the last sample (latched topics).
pub fn latched(depth: usize) -> QosProfile {
    reliable(depth).durability(Durability::TransientLocal)
}

/// The addresses of `interfaces` (names or addresses).
fn addresses(interfaces: &[String]) -> Result<Vec<IpAddr>, RosError> {
    let known = netdev::get_interfaces();
    let mut out = Vec::new();
    for wanted in interfaces {
        if let Ok(address) = wanted.parse::<IpAddr>() {
            out.push(address);
            continue;
        }
        let interface = known
            .iter()
            .find(|i| i.name == *wanted)
            .ok_or_else(|| RosError::Interface(wanted.clone()))?;
        let before = out.len();
        out.extend(interface.ipv4.iter().map(|n| IpAddr::V4(n.addr())));
        out.extend(interface.ipv6.iter().map(|n| IpAddr::V6(n.addr())));
        if out.len() == before {
            return Err(RosError::Interface(wanted.clone()));
        }
    }
    Ok(out)
}

fn create(e: impl std::fmt::Debug) -> RosError {
    RosError::Create(format!("{e:?}"))
}

/// A name as a user gives it: `/absolute/name`, `relative/name` or `name`.
pub fn name(text: &str) -> Result<Name, RosError> {
    Name::parse(text).map_err(|e| RosError::Name {
        name: text.to_string(),
        why: format!("{e:?}"),
    })
}

/// `topic` as an absolute name: a relative one is taken under `namespace` (ros2-client would
/// write a name relative to the root namespace as `rt//name`, which no ROS 2 peer matches).
pub fn resolve(namespace: &str, topic: &str) -> String {
    if topic.starts_with('/') {
        topic.to_string()
    } else {
        format!("{}/{topic}", namespace.trim_end_matches('/'))
    }
}

/// A ROS 2 node on its own participant.
pub struct RosNode {
    namespace: String,
    node: ros2_client::Node,
    // The participant lives as long as the node.
    _context: Context,
}

impl RosNode {
    /// Join the domain and announce the node.
    pub fn open(options: &RosOptions) -> Result<RosNode, RosError> {
        let mut participant = rustdds::DomainParticipantBuilder::new(options.domain_id);
        if !options.interfaces.is_empty() {
            participant = participant.with_only_networks(addresses(&options.interfaces)?);
        }
        let context = Context::from_domain_participant(participant.build().map_err(create)?)
            .map_err(create)?;
        let node_name =
            NodeName::new(&options.namespace, &options.node_name).map_err(|e| RosError::Name {
                name: format!("{} {}", options.namespace, options.node_name),
                why: format!("{e:?}"),
            })?;
        let node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(create)?;
        Ok(RosNode {
            namespace: options.namespace.clone(),
            node,
            _context: context,
        })
    }

    /// The node's fully qualified name (`/ns/name`).
    pub fn fully_qualified_name(&self) -> String {
        self.node.fully_qualified_name()
    }

    fn topic<T: RosType>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<rustdds::Topic, RosError> {
        self.node
            .create_topic(
                &name(&resolve(&self.namespace, topic))?,
                MessageTypeName::new(T::PACKAGE, T::NAME),
                qos,
            )
            .map_err(create)
    }

    /// A publisher of `T` on `topic`.
    pub fn publisher<T: RosType + Serialize>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<Publisher<T>, RosError> {
        let topic = self.topic::<T>(topic, qos)?;
        self.node
            .create_publisher(&topic, Some(qos.clone()))
            .map_err(create)
    }

    /// A subscription to `T` on `topic`.
    pub fn subscription<T: RosType + DeserializeOwned + 'static>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<Subscription<T>, RosError> {
        let topic = self.topic::<T>(topic, qos)?;
        self.node
            .create_subscription(&topic, Some(qos.clone()))
            .map_err(create)
    }

    /// A server of the service `package/srv/type_name` at `service`.
    pub fn server<Req, Resp>(
        &mut self,
        service: &str,
        package: &str,
        type_name: &str,
    ) -> Result<Server<Req, Resp>, RosError>
    where
        Req: Message + Clone + 'static,
        Resp: Message + 'static,
    {
        let qos = reliable(10);
        self.node
            .create_server(
                ServiceMapping::Cyclone,
                &name(&resolve(&self.namespace, service))?,
                &ServiceTypeName::new(package, type_name),
                qos.clone(),
                qos,
            )
            .map_err(create)
    }
}

/// How long a DDS loop waits for its sockets before looking at its stop flag.
pub const POLL_SLICE: Duration = Duration::from_millis(50);

/// A thread that wakes a real-time runner whenever an input registered with `poll` has
/// something, until `done`: the runner's hooks take the inputs after its next poll.
pub fn wake_on_readiness(
    mut poll: mio1::Poll,
    waker: bywire_bus::runner::Waker,
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut events = mio1::Events::with_capacity(64);
        while !done.load(std::sync::atomic::Ordering::Relaxed) {
            match poll.poll(&mut events, Some(POLL_SLICE)) {
                Ok(()) if !events.is_empty() => waker.wake(),
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                // Without readiness the hooks still take the inputs at every report.
                Err(_) => return,
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_ros_rules() {
        assert!(name("/vehicle/status/velocity_status").is_ok());
        assert!(name("from_can_bus").is_ok());
        let e = name("bad name").unwrap_err().to_string();
        assert!(e.contains("'bad name'"), "{e}");
        assert!(name("a//b").is_err());
    }

    #[test]
    fn relative_names_go_under_the_namespace() {
        assert_eq!(resolve("/", "from_can_bus"), "/from_can_bus");
        assert_eq!(
            resolve("/sensing/can", "from_can_bus"),
            "/sensing/can/from_can_bus"
        );
        assert_eq!(
            resolve("/sensing", "can0/to_can_bus"),
            "/sensing/can0/to_can_bus"
        );
        assert_eq!(resolve("/sensing", "/abs"), "/abs");
    }

    #[test]
    fn interfaces_resolve_to_their_addresses() {
        assert_eq!(
            addresses(&["127.0.0.1".to_string()]).unwrap(),
            vec!["127.0.0.1".parse::<IpAddr>().unwrap()]
        );
        let lo = addresses(&["lo".to_string()]).unwrap();
        assert!(
            lo.contains(&"127.0.0.1".parse::<IpAddr>().unwrap()),
            "{lo:?}"
        );
        let e = addresses(&["no-such-interface".to_string()]).unwrap_err();
        assert!(e.to_string().contains("no-such-interface"));
    }
}
