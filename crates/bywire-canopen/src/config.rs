//! The bus description file: what ros2_canopen's `bus.yml` carries (master node ID, bit rate,
//! per node the EDS/DCF, the driver and its mode), in TOML, loaded with errors that name the
//! key and file.
//!
//! ```toml
//! [master]
//! node_id = 1
//! bitrate = 1_000_000
//! heartbeat_ms = 100      # the master's own heartbeat
//! cycle_ms = 10           # drive commands
//! sync_us = 0             # SYNC period (0: none)
//!
//! [node.steer_front_left]
//! id = 2
//! eds = "roboteq.eds"     # or a DCF; relative to this file
//! driver = "roboteq"      # cia402 | roboteq | none
//! mode = "velocity"       # cia402: profile_position | profile_velocity | cyclic_position |
//!                         # cyclic_velocity; roboteq: power | velocity
//! heartbeat_timeout_ms = 300
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::string::{String, ToString};
use std::vec::Vec;

use serde::Deserialize;

use crate::cia402::Mode;
use crate::eds::{self, Severity};
use crate::od::ObjectDictionary;
use crate::roboteq::RoboteqCommand;

/// Why a bus description was refused: the file, and what its reader said or the key whose
/// value is wrong (e.g. `node.steer.mode`), as every configuration file says it.
pub type ConfigError = bywire_core::FileError;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMaster {
    pub(crate) node_id: u8,
    pub(crate) bitrate: u32,
    #[serde(default = "default_heartbeat")]
    pub(crate) heartbeat_ms: u64,
    #[serde(default = "default_cycle")]
    pub(crate) cycle_ms: u64,
    #[serde(default)]
    pub(crate) sync_us: u64,
}

pub(crate) fn default_heartbeat() -> u64 {
    100
}

pub(crate) fn default_cycle() -> u64 {
    10
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawNode {
    pub(crate) id: u8,
    pub(crate) eds: Option<String>,
    pub(crate) profile: Option<String>,
    #[serde(default = "default_driver")]
    pub(crate) driver: String,
    pub(crate) mode: Option<String>,
    #[serde(default = "default_timeout")]
    pub(crate) heartbeat_timeout_ms: u64,
}

fn default_driver() -> String {
    "none".to_string()
}

pub(crate) fn default_timeout() -> u64 {
    300
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBus {
    pub(crate) master: RawMaster,
    #[serde(default)]
    pub(crate) node: BTreeMap<String, RawNode>,
}

/// The driver the master runs for a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Driver {
    /// Monitored and configured only.
    None,
    /// A CiA 402 drive in this mode.
    Cia402(Mode),
    /// A Roboteq controller commanded by power or velocity.
    Roboteq(RoboteqCommand),
}

/// One node of the bus.
#[derive(Debug, Clone)]
pub struct NodeConfig {
    /// Its name (the table key).
    pub name: String,
    /// Its node ID.
    pub id: u8,
    /// Its dictionary (from the EDS/DCF or the built-in profile).
    pub dictionary: ObjectDictionary,
    /// The EDS/DCF it came from, if any.
    pub eds: Option<PathBuf>,
    /// Warnings from reading the EDS/DCF.
    pub warnings: Vec<String>,
    /// Its driver.
    pub driver: Driver,
    /// Heartbeat consumer time the master watches it with.
    pub heartbeat_timeout: core::time::Duration,
}

/// A loaded bus description.
#[derive(Debug, Clone)]
pub struct BusConfig {
    /// The master's node ID.
    pub master_id: u8,
    /// Bit rate, bit/s.
    pub bitrate: u32,
    /// The master's heartbeat period.
    pub heartbeat: core::time::Duration,
    /// Drive command cycle.
    pub cycle: core::time::Duration,
    /// SYNC period (zero: none).
    pub sync: core::time::Duration,
    /// The nodes by ID.
    pub nodes: Vec<NodeConfig>,
}

const BITRATES: [u32; 9] = [
    10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
];

impl BusConfig {
    /// Load a description file; EDS paths are relative to it.
    pub fn load(path: &Path) -> Result<BusConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Syntax {
            file: path.display().to_string(),
            message: e.to_string(),
        })?;
        BusConfig::parse(
            &text,
            &path.display().to_string(),
            path.parent().unwrap_or(Path::new(".")),
        )
    }

    /// Read a description from text; `file` names it in errors, `base` resolves EDS paths.
    pub fn parse(text: &str, file: &str, base: &Path) -> Result<BusConfig, ConfigError> {
        let raw: RawBus = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        BusConfig::from_raw(raw, file, base)
    }

    /// Check a description read from any format and load its dictionaries.
    pub(crate) fn from_raw(raw: RawBus, file: &str, base: &Path) -> Result<BusConfig, ConfigError> {
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: file.to_string(),
            key: key.to_string(),
            reason,
        };
        if !(1..=127).contains(&raw.master.node_id) {
            return Err(invalid(
                "master.node_id",
                format!("{} is not a node ID (1..=127)", raw.master.node_id),
            ));
        }
        if !BITRATES.contains(&raw.master.bitrate) {
            return Err(invalid(
                "master.bitrate",
                format!(
                    "{} is not a CiA 301 bit rate ({BITRATES:?})",
                    raw.master.bitrate
                ),
            ));
        }
        if raw.master.cycle_ms == 0 {
            return Err(invalid("master.cycle_ms", "must be at least 1".to_string()));
        }
        let mut nodes: Vec<NodeConfig> = Vec::new();
        for (name, node) in &raw.node {
            let key = |field: &str| format!("node.{name}.{field}");
            if !(1..=127).contains(&node.id) {
                return Err(invalid(
                    &key("id"),
                    format!("{} is not a node ID (1..=127)", node.id),
                ));
            }
            if node.id == raw.master.node_id {
                return Err(invalid(
                    &key("id"),
                    format!("{} is the master's node ID", node.id),
                ));
            }
            if let Some(other) = nodes.iter().find(|n| n.id == node.id) {
                return Err(invalid(
                    &key("id"),
                    format!("{} is also node '{}'", node.id, other.name),
                ));
            }
            let mode = node.mode.as_deref();
            let driver = match (node.driver.as_str(), mode) {
                ("none", None) => Driver::None,
                ("none", Some(_)) => return Err(invalid(&key("mode"), "a mode needs a driver (cia402 or roboteq)".to_string())),
                ("cia402", mode) => Driver::Cia402(match mode.unwrap_or("profile_velocity") {
                    "profile_position" => Mode::ProfilePosition,
                    "profile_velocity" => Mode::ProfileVelocity,
                    "cyclic_position" => Mode::CyclicSynchronousPosition,
                    "cyclic_velocity" => Mode::CyclicSynchronousVelocity,
                    other => return Err(invalid(&key("mode"), format!("'{other}' is not a cia402 mode (profile_position, profile_velocity, cyclic_position, cyclic_velocity)"))),
                }),
                ("roboteq", mode) => Driver::Roboteq(match mode.unwrap_or("power") {
                    "power" => RoboteqCommand::Power(0),
                    "velocity" => RoboteqCommand::Velocity(0),
                    other => return Err(invalid(&key("mode"), format!("'{other}' is not a roboteq mode (power, velocity)"))),
                }),
                (other, _) => return Err(invalid(&key("driver"), format!("'{other}' is not a driver (cia402, roboteq, none)"))),
            };
            if driver != Driver::None && node.heartbeat_timeout_ms == 0 {
                return Err(invalid(
                    &key("heartbeat_timeout_ms"),
                    "a driven node must be monitored (more than 0)".to_string(),
                ));
            }
            let (dictionary, eds_path, warnings) = match (&node.eds, node.profile.as_deref()) {
                (Some(_), Some(_)) => {
                    return Err(invalid(
                        &key("eds"),
                        "give either eds or profile, not both".to_string(),
                    ))
                }
                (None, Some("roboteq")) => {
                    (crate::roboteq::dictionary(node.id, 2), None, Vec::new())
                }
                (None, Some("cia402")) => {
                    (crate::cia402::drive_dictionary(node.id), None, Vec::new())
                }
                (None, Some(other)) => {
                    return Err(invalid(
                        &key("profile"),
                        format!("'{other}' is not a built-in profile (roboteq, cia402)"),
                    ))
                }
                (None, None) => {
                    return Err(invalid(
                        &key("eds"),
                        "each node needs an eds (or dcf) file or a profile".to_string(),
                    ))
                }
                (Some(relative), None) => {
                    let path = base.join(relative);
                    let text = std::fs::read_to_string(&path)
                        .map_err(|e| invalid(&key("eds"), format!("{}: {e}", path.display())))?;
                    let loaded = eds::parse(&text, Some(node.id))
                        .map_err(|e| invalid(&key("eds"), format!("{}: {e}", path.display())))?;
                    let warnings = loaded
                        .diagnostics
                        .iter()
                        .filter(|d| d.severity == Severity::Warning)
                        .map(|d| format!("{}: {d}", path.display()))
                        .collect();
                    if let Some(error) = loaded
                        .diagnostics
                        .iter()
                        .find(|d| d.severity == Severity::Error)
                    {
                        return Err(invalid(&key("eds"), format!("{}: {error}", path.display())));
                    }
                    (loaded.dictionary, Some(path), warnings)
                }
            };
            nodes.push(NodeConfig {
                name: name.clone(),
                id: node.id,
                dictionary,
                eds: eds_path,
                warnings,
                driver,
                heartbeat_timeout: core::time::Duration::from_millis(node.heartbeat_timeout_ms),
            });
        }
        Ok(BusConfig {
            master_id: raw.master.node_id,
            bitrate: raw.master.bitrate,
            heartbeat: core::time::Duration::from_millis(raw.master.heartbeat_ms),
            cycle: core::time::Duration::from_millis(raw.master.cycle_ms),
            sync: core::time::Duration::from_micros(raw.master.sync_us),
            nodes,
        })
    }
}

impl BusConfig {
    /// The master this description calls for: its heartbeat, SYNC and cycle, every node
    /// monitored with its consumer time, and a controller for every driven node (disabled
    /// until the application enables it: fail closed). A CiA 402 drive's statusword may be
    /// silent twice its heartbeat time before its controller stops it for that: a drive that
    /// is gone stops both at once, and its heartbeat's loss is what happened (with equal times
    /// the two would race, by where each last frame fell).
    pub fn master(&self) -> crate::master::Master {
        use crate::master::{Controlled, Master};
        let mut master =
            Master::new(self.master_id, self.heartbeat, self.cycle).with_sync(self.sync);
        for node in &self.nodes {
            let _ = master.monitor(node.id, node.heartbeat_timeout);
            match node.driver {
                Driver::None => {}
                Driver::Cia402(mode) => {
                    master.add(Controlled::Drive(crate::cia402::DriveController::new(
                        node.id,
                        mode,
                        node.heartbeat_timeout.saturating_mul(2),
                    )))
                }
                Driver::Roboteq(command) => master.add(Controlled::Roboteq(
                    crate::roboteq::RoboteqMotor::new(node.id, command),
                )),
            }
        }
        master
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BUS: &str = "[master]\nnode_id = 1\nbitrate = 1_000_000\n\n[node.steer]\nid = 2\nprofile = \"roboteq\"\ndriver = \"roboteq\"\nmode = \"velocity\"\n\n[node.drive]\nid = 3\nprofile = \"cia402\"\ndriver = \"cia402\"\nmode = \"profile_velocity\"\nheartbeat_timeout_ms = 250\n";

    fn error(text: &str) -> String {
        BusConfig::parse(text, "bus.toml", Path::new("."))
            .unwrap_err()
            .to_string()
    }

    /// A gone drive stops its heartbeat and its statusword at once: the statusword is given
    /// twice the heartbeat time, so the heartbeat's loss (250 ms) is what is reported.
    #[test]
    fn a_drive_controller_waits_twice_the_heartbeat_time_for_its_statusword() {
        use crate::cia402::StopReason;
        use crate::master::Controlled;
        let bus = BusConfig::parse(BUS, "bus.toml", Path::new(".")).unwrap();
        let mut master = bus.master();
        let Some(Controlled::Drive(drive)) = master.controlled(3) else {
            panic!("no controller for the drive");
        };
        drive.set_enabled(true);
        let at = bywire_core::Timestamp::from_millis;
        // Operation enabled, from the drive's TPDO1.
        drive.on_frame(at(0), &crate::nmt::classic(0x183, &[0x27, 0x02, 3]));
        drive.poll(at(499), &mut |_| {});
        assert_eq!(drive.stopped(), None);
        drive.poll(at(500), &mut |_| {});
        assert_eq!(drive.stopped(), Some(StopReason::StatusTimeout));
    }

    #[test]
    fn a_bus_loads_with_its_nodes_and_drivers() {
        let bus = BusConfig::parse(BUS, "bus.toml", Path::new(".")).unwrap();
        assert_eq!((bus.master_id, bus.bitrate), (1, 1_000_000));
        assert_eq!(bus.nodes.len(), 2);
        let drive = bus.nodes.iter().find(|n| n.name == "drive").unwrap();
        assert_eq!(drive.driver, Driver::Cia402(Mode::ProfileVelocity));
        assert_eq!(
            drive.heartbeat_timeout,
            core::time::Duration::from_millis(250)
        );
        assert!(drive.dictionary.object(0x6040).is_some());
        let steer = bus.nodes.iter().find(|n| n.name == "steer").unwrap();
        assert_eq!(steer.driver, Driver::Roboteq(RoboteqCommand::Velocity(0)));
        let mut master = bus.master();
        assert!(matches!(
            master.controlled(3),
            Some(crate::master::Controlled::Drive(_))
        ));
        assert!(matches!(
            master.controlled(2),
            Some(crate::master::Controlled::Roboteq(_))
        ));
        assert_eq!(master.liveness(3), Some(crate::nmt::Liveness::Unknown));
    }

    #[test]
    fn mistakes_are_named_by_key() {
        assert_eq!(
            error(&BUS.replace("id = 3", "id = 2")),
            "bus.toml: node.steer.id: 2 is also node 'drive'"
        );
        assert_eq!(error(&BUS.replace("bitrate = 1_000_000", "bitrate = 999")), "bus.toml: master.bitrate: 999 is not a CiA 301 bit rate ([10000, 20000, 50000, 100000, 125000, 250000, 500000, 800000, 1000000])");
        assert!(
            error(&BUS.replace("mode = \"velocity\"", "mode = \"warp\""))
                .contains("node.steer.mode: 'warp' is not a roboteq mode")
        );
        assert!(error(&BUS.replace("id = 2", "id = 1"))
            .contains("node.steer.id: 1 is the master's node ID"));
        assert!(error(&BUS.replace("profile = \"cia402\"", ""))
            .contains("node.drive.eds: each node needs"));
        assert!(
            error(&BUS.replace("profile = \"cia402\"", "eds = \"missing.eds\""))
                .contains("node.drive.eds: ./missing.eds")
        );
        let syntax = error(&BUS.replace("driver = \"cia402\"", "drivr = \"cia402\""));
        assert!(
            syntax.starts_with("bus.toml: ")
                && syntax.contains("unknown field `drivr`")
                && syntax.contains("line 14"),
            "{syntax}"
        );
    }
}
