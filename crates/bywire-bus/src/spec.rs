//! Bus specs: one string a user can type names any bus. Six schemes are built in; a crate
//! outside this one adds its own backend with [`register`] (a PCAN or Kvaser adapter, a
//! user's own transport), and from then on its specs parse, open and list like the others.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, OnceLock, PoisonError, RwLock};

use crate::sim_endpoint::Bitrates;
use crate::Bus;

/// A parsed bus spec.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusSpec {
    /// `virtual:NAME`: the in-process bus called NAME.
    Virtual {
        /// The bus's name.
        name: String,
    },
    /// `sim:NAME@BITRATE[/DATA_BITRATE]`: the in-process bit-timed bus called NAME.
    Sim {
        /// The bus's name.
        name: String,
        /// Its bitrates.
        bitrates: Bitrates,
    },
    /// `socketcan:IFACE`: a Linux CAN interface.
    SocketCan {
        /// The interface name (`can0`, `vcan0`).
        interface: String,
    },
    /// `socketcand:HOST:PORT/BUS`: a bus served by a socketcand server.
    Socketcand {
        /// HOST:PORT of the server.
        address: String,
        /// The bus name to open there.
        bus: String,
    },
    /// `slcan:PORT@BITRATE`: an SLCAN adapter on a serial port.
    Slcan {
        /// The serial port (`/dev/ttyACM0`).
        port: String,
        /// The CAN bitrate.
        bitrate: u32,
    },
    /// `udp:[GROUP[:PORT]]`: python-can's `udp_multicast` bus.
    Udp {
        /// The multicast group and port.
        group: std::net::SocketAddr,
    },
    /// `SCHEME:PARAMETERS` of a backend added with [`register`].
    Registered {
        /// Its scheme.
        scheme: String,
        /// What follows the scheme, as its backend checked it.
        parameters: String,
    },
}

/// A bus backend added from outside this crate, found by the scheme of a spec
/// (`SCHEME:PARAMETERS`; it is given the parameters).
pub trait Backend: Send + Sync {
    /// Check the parameters without opening anything: why they name no bus, if they do not.
    fn check(&self, parameters: &str) -> Result<(), String>;
    /// Open the bus.
    fn open(&self, parameters: &str) -> Result<Box<dyn Bus>, String>;
    /// Open the bus for listening only. By default it is opened as for sending, and said so.
    fn open_listening(&self, parameters: &str) -> Result<(Box<dyn Bus>, Listening), String> {
        let how = Listening::NotListenOnly("its backend has no listen-only mode".into());
        Ok((self.open(parameters)?, how))
    }
    /// Whether its buses live inside this process (what one process sends, no other hears).
    fn in_process(&self) -> bool {
        false
    }
}

/// Why a backend could not be registered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RegisterError {
    /// The scheme is not lowercase letters, digits and '-', starting with a letter.
    #[error("'{0}' is not a bus scheme (lowercase letters, digits and '-', from a letter)")]
    BadScheme(String),
    /// A built-in or registered backend has the scheme already.
    #[error("the bus scheme '{0}' is taken")]
    Taken(String),
}

type Registry = RwLock<BTreeMap<String, Arc<dyn Backend>>>;

fn registry() -> &'static Registry {
    static BACKENDS: OnceLock<Registry> = OnceLock::new();
    BACKENDS.get_or_init(Registry::default)
}

/// The backend registered for `scheme`.
fn registered(scheme: &str) -> Option<Arc<dyn Backend>> {
    let backends = registry().read().unwrap_or_else(PoisonError::into_inner);
    backends.get(scheme).cloned()
}

/// Add a backend for the specs `SCHEME:PARAMETERS`, for the rest of the process.
pub fn register(scheme: &str, backend: impl Backend + 'static) -> Result<(), RegisterError> {
    let valid = scheme.starts_with(|c: char| c.is_ascii_lowercase())
        && scheme
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
    if !valid {
        return Err(RegisterError::BadScheme(scheme.to_string()));
    }
    let mut backends = registry().write().unwrap_or_else(PoisonError::into_inner);
    if BUILT_IN.contains(&scheme) || backends.contains_key(scheme) {
        return Err(RegisterError::Taken(scheme.to_string()));
    }
    backends.insert(scheme.to_string(), Arc::new(backend));
    Ok(())
}

/// Every scheme a spec may use: the built-in ones, then the registered ones by name.
pub fn schemes() -> Vec<String> {
    let backends = registry().read().unwrap_or_else(PoisonError::into_inner);
    BUILT_IN
        .iter()
        .map(|s| s.to_string())
        .chain(backends.keys().cloned())
        .collect()
}

/// A spec that parsed but whose bus cannot be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// The spec names no bus.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// The bus is there in name only: the backend refused.
    #[error("cannot open {spec}: {reason}")]
    Refused {
        /// The spec.
        spec: String,
        /// Why.
        reason: String,
    },
}

/// A spec that names no bus, with what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SpecError {
    /// No `scheme:` prefix.
    #[error("'{0}' is not a bus spec: expected SCHEME:PARAMETERS, e.g. virtual:test")]
    NoScheme(String),
    /// A scheme no backend handles.
    #[error("unknown bus scheme '{scheme}' (known: {known})")]
    UnknownScheme {
        /// The scheme given.
        scheme: String,
        /// The schemes there are, comma-separated.
        known: String,
    },
    /// Parameters the scheme does not accept.
    #[error("{scheme}: {reason}")]
    Parameters {
        /// The scheme.
        scheme: String,
        /// What is wrong.
        reason: String,
    },
}

/// The schemes of the backends built in.
const BUILT_IN: [&str; 6] = ["virtual", "sim", "socketcan", "socketcand", "slcan", "udp"];

fn bus_name(scheme: &str, text: &str) -> Result<String, SpecError> {
    let valid = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if valid {
        Ok(text.to_string())
    } else {
        Err(SpecError::Parameters {
            scheme: scheme.to_string(),
            reason: format!("'{text}' is not a bus name (letters, digits, '-', '_', '.')"),
        })
    }
}

fn bitrate(text: &str) -> Result<u32, SpecError> {
    match text.parse::<u32>() {
        Ok(rate) if (1_000..=20_000_000).contains(&rate) => Ok(rate),
        _ => Err(SpecError::Parameters {
            scheme: "sim".into(),
            reason: format!("'{text}' is not a bitrate (1000 to 20000000 bit/s)"),
        }),
    }
}

fn sim_spec(rest: &str) -> Result<BusSpec, SpecError> {
    let (name, rates) = rest.split_once('@').ok_or_else(|| SpecError::Parameters {
        scheme: "sim".into(),
        reason: format!("'{rest}' lacks the bitrate: sim:NAME@BITRATE[/DATA_BITRATE]"),
    })?;
    let (nominal, data) = match rates.split_once('/') {
        Some((nominal, data)) => (bitrate(nominal)?, Some(bitrate(data)?)),
        None => (bitrate(rates)?, None),
    };
    Ok(BusSpec::Sim {
        name: bus_name("sim", name)?,
        bitrates: Bitrates { nominal, data },
    })
}

impl FromStr for BusSpec {
    type Err = SpecError;

    fn from_str(text: &str) -> Result<BusSpec, SpecError> {
        let (scheme, rest) = text
            .split_once(':')
            .ok_or_else(|| SpecError::NoScheme(text.to_string()))?;
        match scheme {
            "virtual" => Ok(BusSpec::Virtual {
                name: bus_name("virtual", rest)?,
            }),
            "sim" => sim_spec(rest),
            // Linux interface names: up to 15 bytes, no '/', ':' or whitespace.
            "socketcan" => {
                let valid = !rest.is_empty()
                    && rest.len() <= 15
                    && !rest.contains(|c: char| c == '/' || c == ':' || c.is_whitespace());
                if !valid {
                    return Err(SpecError::Parameters {
                        scheme: "socketcan".into(),
                        reason: format!("'{rest}' is not an interface name (1 to 15 characters)"),
                    });
                }
                Ok(BusSpec::SocketCan {
                    interface: rest.to_string(),
                })
            }
            "socketcand" => {
                let (address, bus) = rest
                    .rsplit_once('/')
                    .filter(|(a, b)| a.contains(':') && !b.is_empty())
                    .ok_or_else(|| SpecError::Parameters {
                        scheme: "socketcand".into(),
                        reason: format!(
                            "'{rest}' is not HOST:PORT/BUS (e.g. socketcand:127.0.0.1:29536/vcan0)"
                        ),
                    })?;
                Ok(BusSpec::Socketcand {
                    address: address.to_string(),
                    bus: bus.to_string(),
                })
            }
            "slcan" => {
                let (port, rate) = rest.rsplit_once('@').ok_or_else(|| SpecError::Parameters {
                    scheme: "slcan".into(),
                    reason: format!("'{rest}' lacks the bitrate: slcan:PORT@BITRATE (e.g. slcan:/dev/ttyACM0@500000)"),
                })?;
                let bitrate = rate
                    .parse::<u32>()
                    .ok()
                    .filter(|r| crate::slcan::bitrate_command(*r).is_some())
                    .ok_or_else(|| SpecError::Parameters {
                        scheme: "slcan".into(),
                        reason: format!("'{rate}' is not an SLCAN bitrate (10000, 20000, 50000, 100000, 125000, 250000, 500000, 750000, 1000000)"),
                    })?;
                if port.is_empty() {
                    return Err(SpecError::Parameters {
                        scheme: "slcan".into(),
                        reason: "no serial port".into(),
                    });
                }
                Ok(BusSpec::Slcan {
                    port: port.to_string(),
                    bitrate,
                })
            }
            "udp" => crate::udp::parse_spec(rest)
                .map(|group| BusSpec::Udp { group })
                .map_err(|reason| SpecError::Parameters {
                    scheme: "udp".into(),
                    reason,
                }),
            other => match registered(other) {
                Some(backend) => match backend.check(rest) {
                    Ok(()) => Ok(BusSpec::Registered {
                        scheme: other.to_string(),
                        parameters: rest.to_string(),
                    }),
                    Err(reason) => Err(SpecError::Parameters {
                        scheme: other.to_string(),
                        reason,
                    }),
                },
                None => Err(SpecError::UnknownScheme {
                    scheme: other.to_string(),
                    known: schemes().join(", "),
                }),
            },
        }
    }
}

impl fmt::Display for BusSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusSpec::Virtual { name } => write!(f, "virtual:{name}"),
            BusSpec::Sim { name, bitrates } => {
                write!(f, "sim:{name}@{}", bitrates.nominal)?;
                match bitrates.data {
                    Some(data) => write!(f, "/{data}"),
                    None => Ok(()),
                }
            }
            BusSpec::SocketCan { interface } => write!(f, "socketcan:{interface}"),
            BusSpec::Udp { group } => write!(f, "udp:{group}"),
            BusSpec::Slcan { port, bitrate } => write!(f, "slcan:{port}@{bitrate}"),
            BusSpec::Socketcand { address, bus } => write!(f, "socketcand:{address}/{bus}"),
            BusSpec::Registered { scheme, parameters } => write!(f, "{scheme}:{parameters}"),
        }
    }
}

/// How quiet a bus opened for listening is (see [`open_listening`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Listening {
    /// The controller was put in listen-only mode by this open (a SocketCAN interface: undo
    /// with [`crate::socketcan::clear_listen_only`] when done).
    SwitchedToListenOnly,
    /// The controller is listen-only (already, or opened so: an SLCAN adapter's `L`).
    ListenOnly,
    /// It could not be made listen-only: why, in words. Its controller still acknowledges
    /// frames (the program itself sends nothing).
    NotListenOnly(String),
    /// There is no controller of ours to set: why, in words (a virtual bus; a bus served over
    /// the network, whose server's controller decides).
    NoController(String),
}

/// Whether the bus a spec names lives inside this process (`virtual:`, `sim:`): what one
/// process sends on it no other process hears.
pub fn is_in_process(spec: &str) -> bool {
    match spec.parse::<BusSpec>() {
        Ok(BusSpec::Virtual { .. } | BusSpec::Sim { .. }) => true,
        Ok(BusSpec::Registered { scheme, .. }) => {
            registered(&scheme).is_some_and(|b| b.in_process())
        }
        _ => false,
    }
}

/// Open the bus a spec names for listening only: a SocketCAN interface's controller is put in
/// listen-only mode where the interface allows, an SLCAN adapter is opened listen-only; what
/// came of it is said. The bus is opened either way (a logger records what it can).
pub fn open_listening(spec: &str) -> Result<(Box<dyn Bus>, Listening), OpenError> {
    let parsed = spec.parse::<BusSpec>()?;
    let listening = match &parsed {
        BusSpec::Virtual { .. } | BusSpec::Sim { .. } => {
            Listening::NoController("an in-process bus".into())
        }
        BusSpec::Socketcand { .. } => {
            Listening::NoController("served over TCP: the server's controller decides".into())
        }
        BusSpec::Udp { .. } => Listening::NoController("UDP multicast has no controller".into()),
        BusSpec::Registered { scheme, parameters } => {
            let backend = registered(scheme).ok_or_else(|| OpenError::Refused {
                spec: spec.to_string(),
                reason: format!("no backend for '{scheme}'"),
            })?;
            return backend
                .open_listening(parameters)
                .map_err(|reason| OpenError::Refused {
                    spec: spec.to_string(),
                    reason,
                });
        }
        BusSpec::Slcan { port, bitrate } => {
            let bus = crate::slcan::Slcan::open(port, *bitrate, true).map_err(|e| {
                OpenError::Refused {
                    spec: spec.to_string(),
                    reason: e.to_string(),
                }
            })?;
            return Ok((Box::new(bus), Listening::ListenOnly));
        }
        #[cfg(target_os = "linux")]
        BusSpec::SocketCan { interface } => {
            use crate::socketcan::ListenOnly;
            match crate::socketcan::set_listen_only(interface) {
                Ok(ListenOnly::Set) => Listening::SwitchedToListenOnly,
                Ok(ListenOnly::AlreadyOn) => Listening::ListenOnly,
                Ok(ListenOnly::NoController) => Listening::NoController(
                    "a virtual interface (vcan/vxcan) has no controller".into(),
                ),
                Ok(ListenOnly::Unsupported) => {
                    Listening::NotListenOnly("its driver has no listen-only mode".into())
                }
                Ok(ListenOnly::Refused(why)) => Listening::NotListenOnly(format!(
                    "the kernel refused ({why}; it needs CAP_NET_ADMIN)"
                )),
                Err(e) => Listening::NotListenOnly(e.to_string()),
            }
        }
        #[cfg(not(target_os = "linux"))]
        BusSpec::SocketCan { .. } => Listening::NotListenOnly("not on Linux".into()),
    };
    Ok((open(spec)?, listening))
}

/// Open the bus a spec names.
pub fn open(spec: &str) -> Result<Box<dyn Bus>, OpenError> {
    let refused = |reason: String| OpenError::Refused {
        spec: spec.to_string(),
        reason,
    };
    match spec.parse::<BusSpec>()? {
        BusSpec::Virtual { name } => Ok(Box::new(crate::virtual_bus::VirtualBus::join(&name))),
        BusSpec::Sim { name, bitrates } => crate::sim_endpoint::SimEndpoint::join(
            &name,
            bitrates,
            bywire_net::sim::DEFAULT_RX_CAPACITY,
        )
        .map(|bus| Box::new(bus) as Box<dyn Bus>)
        .map_err(|e| refused(e.to_string())),
        #[cfg(target_os = "linux")]
        BusSpec::SocketCan { interface } => crate::socketcan::SocketCan::open(&interface)
            .map(|bus| Box::new(bus) as Box<dyn Bus>)
            .map_err(|e| refused(e.to_string())),
        #[cfg(not(target_os = "linux"))]
        BusSpec::SocketCan { .. } => Err(refused("SocketCAN exists only on Linux".into())),
        BusSpec::Socketcand { address, bus } => crate::socketcand::Client::connect(&address, &bus)
            .map(|c| Box::new(c) as Box<dyn Bus>)
            .map_err(|e| refused(e.to_string())),
        BusSpec::Slcan { port, bitrate } => crate::slcan::Slcan::open(&port, bitrate, false)
            .map(|b| Box::new(b) as Box<dyn Bus>)
            .map_err(|e| refused(e.to_string())),
        BusSpec::Udp { group } => crate::udp::UdpMulticast::open(group)
            .map(|bus| Box::new(bus) as Box<dyn Bus>)
            .map_err(|e| refused(e.to_string())),
        BusSpec::Registered { scheme, parameters } => match registered(&scheme) {
            Some(backend) => backend.open(&parameters).map_err(refused),
            None => Err(refused(format!("no backend for '{scheme}'"))),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_refuse_clearly() {
        assert_eq!(
            "virtual:test-1".parse(),
            Ok(BusSpec::Virtual {
                name: "test-1".into()
            })
        );
        assert_eq!(
            "virtual:test-1".parse::<BusSpec>().unwrap().to_string(),
            "virtual:test-1"
        );
        assert!(matches!(
            "can0".parse::<BusSpec>(),
            Err(SpecError::NoScheme(_))
        ));
        let e = "carrier:pigeon".parse::<BusSpec>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown bus scheme 'carrier' (known: virtual, sim, socketcan, socketcand, slcan, udp)"
        );
        assert!(matches!(
            "virtual:".parse::<BusSpec>(),
            Err(SpecError::Parameters { .. })
        ));
        assert!(matches!(
            "virtual:a b".parse::<BusSpec>(),
            Err(SpecError::Parameters { .. })
        ));
        for (text, bitrates) in [
            ("sim:tug@500000", (500_000, None)),
            ("sim:b2@1000000/5000000", (1_000_000, Some(5_000_000))),
        ] {
            let spec: BusSpec = text.parse().unwrap();
            let BusSpec::Sim { bitrates: b, .. } = &spec else {
                panic!("{spec:?}")
            };
            assert_eq!((b.nominal, b.data), bitrates);
            assert_eq!(spec.to_string(), text);
        }
        for (text, says) in [
            ("sim:tug", "lacks the bitrate"),
            ("sim:tug@fast", "'fast' is not a bitrate"),
            ("sim:tug@500000/0", "'0' is not a bitrate"),
            ("sim:@500000", "'' is not a bus name"),
            ("socketcan:", "'' is not an interface name"),
            (
                "socketcan:a_very_long_interface",
                "is not an interface name",
            ),
        ] {
            let e = text.parse::<BusSpec>().unwrap_err().to_string();
            assert!(e.contains(says), "{text}: {e}");
        }
        assert_eq!(
            "socketcan:vcan0".parse::<BusSpec>().unwrap().to_string(),
            "socketcan:vcan0"
        );
    }
}
