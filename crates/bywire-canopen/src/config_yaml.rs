//! ros2_canopen's `bus.yml` read into the same bus description as the TOML file, checked the
//! same way: `master` (`node_id`, `baudrate` in kbit/s, `sync_period` in µs,
//! `heartbeat_producer` in ms), `defaults` merged under every node, and per node `node_id`,
//! `dcf` (found under `options.dcf_path`, whose `@BUS_CONFIG_PATH@` is the file's folder),
//! `driver` (ros2_canopen's CiA 402 drivers become `cia402`, any other `none`),
//! `velocity_mode` / `position_mode` (the mode a drive starts in), `period`
//! (the command cycle), `heartbeat_timeout_ms`.
//!
//! The `sdo`, `tpdo` and `rpdo` lists are not applied (the master commands drives with the
//! CiA 402 default PDO layout); each node that has them gets a warning saying so.

use std::collections::BTreeMap;
use std::path::Path;
use std::string::{String, ToString};
use std::vec::Vec;

use yaml_rust2::{Yaml, YamlLoader};

use crate::config::{BusConfig, ConfigError, RawBus, RawMaster, RawNode};

fn text(y: &Yaml) -> Option<String> {
    match y {
        Yaml::String(s) => Some(s.clone()),
        Yaml::Integer(i) => Some(i.to_string()),
        _ => None,
    }
}

/// A number in `key` of `map`, or its absence; anything else is an error naming the key.
fn number<T: TryFrom<i64>>(
    map: &Yaml,
    key: &str,
    path: &str,
    invalid: &dyn Fn(&str, String) -> ConfigError,
) -> Result<Option<T>, ConfigError> {
    match &map[key] {
        Yaml::BadValue | Yaml::Null => Ok(None),
        Yaml::Integer(i) => T::try_from(*i)
            .map(Some)
            .map_err(|_| invalid(&format!("{path}.{key}"), format!("{i} is out of range"))),
        other => Err(invalid(
            &format!("{path}.{key}"),
            format!("expected a whole number, found {other:?}"),
        )),
    }
}

/// `node` with `defaults` under it (the node's own keys win).
fn merged(defaults: &Yaml, node: &Yaml) -> Yaml {
    let mut out = match defaults {
        Yaml::Hash(h) => h.clone(),
        _ => Default::default(),
    };
    if let Yaml::Hash(own) = node {
        for (k, v) in own {
            out.insert(k.clone(), v.clone());
        }
    }
    Yaml::Hash(out)
}

/// An error of the shared checks, its key named as `bus.yml` names it.
fn yaml_key(error: ConfigError) -> ConfigError {
    let ConfigError::Invalid { file, key, reason } = error else {
        return error;
    };
    let key = match key.as_str() {
        "master.bitrate" => "master.baudrate".to_string(),
        "master.heartbeat_ms" => "master.heartbeat_producer".to_string(),
        "master.cycle_ms" => "defaults.period".to_string(),
        "master.sync_us" => "master.sync_period".to_string(),
        other => match other.strip_prefix("node.") {
            Some(rest) => {
                let (name, field) = rest.rsplit_once('.').unwrap_or((rest, ""));
                let field = match field {
                    "id" => "node_id",
                    "eds" => "dcf",
                    other => other,
                };
                format!("nodes.{name}.{field}")
            }
            None => other.to_string(),
        },
    };
    ConfigError::Invalid { file, key, reason }
}

impl BusConfig {
    /// Read ros2_canopen's `bus.yml`; `file` names it in errors, `base` is its folder.
    pub fn parse_ros2_canopen(
        text_in: &str,
        file: &str,
        base: &Path,
    ) -> Result<BusConfig, ConfigError> {
        let syntax = |message: String| ConfigError::Syntax {
            file: file.to_string(),
            message,
        };
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: file.to_string(),
            key: key.to_string(),
            reason,
        };
        let docs = YamlLoader::load_from_str(text_in).map_err(|e| syntax(e.to_string()))?;
        let doc = docs
            .first()
            .ok_or_else(|| syntax("the file is empty".into()))?;
        let master = &doc["master"];
        if master.is_badvalue() {
            return Err(invalid("master", "missing".into()));
        }
        let node_id: u8 = number(master, "node_id", "master", &invalid)?
            .ok_or_else(|| invalid("master.node_id", "missing".into()))?;
        let kbit: u32 = number(master, "baudrate", "master", &invalid)?.unwrap_or(1000);
        let sync_us: u64 = number(master, "sync_period", "master", &invalid)?.unwrap_or(0);
        let heartbeat_ms: u64 = number(master, "heartbeat_producer", "master", &invalid)?
            .unwrap_or_else(crate::config::default_heartbeat);
        let dcf_path = text(&doc["options"]["dcf_path"]).unwrap_or_default();
        let dcf_base = if dcf_path.is_empty() || dcf_path.contains("@BUS_CONFIG_PATH@") {
            base.to_path_buf()
        } else {
            base.join(dcf_path)
        };
        let defaults = &doc["defaults"];
        let mut nodes = BTreeMap::new();
        let mut cycle_ms = None;
        let mut ignored = Vec::new();
        if let Yaml::Hash(list) = &doc["nodes"] {
            for (name, own) in list {
                let name =
                    text(name).ok_or_else(|| invalid("nodes", "a node name is not text".into()))?;
                let path = format!("nodes.{name}");
                let node = merged(defaults, own);
                let id: u8 = number(&node, "node_id", &path, &invalid)?
                    .ok_or_else(|| invalid(&format!("{path}.node_id"), "missing".into()))?;
                let driver = text(&node["driver"]).unwrap_or_default();
                let driver = if driver.contains("Cia402Driver") {
                    "cia402"
                } else {
                    "none"
                };
                let eds =
                    text(&node["dcf"]).map(|d| dcf_base.join(d).to_string_lossy().into_owned());
                // Without a DCF a CiA 402 drive is the built-in profile; any other node needs one.
                let profile = (eds.is_none() && driver == "cia402").then(|| "cia402".to_string());
                if eds.is_none() && profile.is_none() {
                    return Err(invalid(
                        &format!("{path}.dcf"),
                        "missing (a node other than a CiA 402 drive is described by its DCF)"
                            .into(),
                    ));
                }
                if let Some(period) = number::<u64>(&node, "period", &path, &invalid)? {
                    cycle_ms = Some(cycle_ms.map_or(period, |c: u64| c.min(period)));
                }
                if ["sdo", "tpdo", "rpdo"]
                    .iter()
                    .any(|k| !node[*k].is_badvalue())
                {
                    ignored.push(name.clone());
                }
                // The mode a drive starts in: ros2_canopen's velocity mode (3 profile, 9 cyclic)
                // if given, else its position mode (1 profile, 8 cyclic); services switch it.
                let velocity: Option<i64> = number(&node, "velocity_mode", &path, &invalid)?;
                let position: Option<i64> = number(&node, "position_mode", &path, &invalid)?;
                let mode = match (velocity, position) {
                    (Some(3), _) => Some("profile_velocity"),
                    (Some(9), _) => Some("cyclic_velocity"),
                    (None, Some(1)) => Some("profile_position"),
                    (None, Some(8)) => Some("cyclic_position"),
                    (None, None) => None,
                    (Some(code), _) | (None, Some(code)) => {
                        return Err(invalid(
                            &format!("{path}.{}", if velocity.is_some() { "velocity_mode" } else { "position_mode" }),
                            format!("{code} is not a mode this master drives (velocity 3 or 9, position 1 or 8)"),
                        ))
                    }
                };
                nodes.insert(
                    name,
                    RawNode {
                        id,
                        eds,
                        profile,
                        driver: driver.to_string(),
                        mode: mode.map(str::to_string),
                        heartbeat_timeout_ms: number(
                            &node,
                            "heartbeat_timeout_ms",
                            &path,
                            &invalid,
                        )?
                        .unwrap_or_else(crate::config::default_timeout),
                    },
                );
            }
        }
        let raw = RawBus {
            master: RawMaster {
                node_id,
                bitrate: kbit.saturating_mul(1000),
                heartbeat_ms,
                cycle_ms: cycle_ms.unwrap_or_else(crate::config::default_cycle),
                sync_us,
            },
            node: nodes,
        };
        let mut config = BusConfig::from_raw(raw, file, base).map_err(yaml_key)?;
        for node in &mut config.nodes {
            if ignored.contains(&node.name) {
                node.warnings.push(
                    "its sdo/tpdo/rpdo lists are not applied: the master uses the CiA 402 default PDO layout"
                        .into(),
                );
            }
        }
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BUS: &str = "options:\n  dcf_path: \"@BUS_CONFIG_PATH@\"\nmaster:\n  node_id: 1\n  driver: \"ros2_canopen::MasterDriver\"\n  package: \"canopen_master_driver\"\n  sync_period: 10000\ndefaults:\n  driver: \"ros2_canopen::Cia402Driver\"\n  package: \"canopen_402_driver\"\n  period: 10\n  sdo:\n    - {index: 0x6081, sub_index: 0, value: 1000}\nnodes:\n  drive_left:\n    node_id: 2\n  drive_right:\n    node_id: 3\n    heartbeat_timeout_ms: 250\n    position_mode: 8\n";

    const PROXY: &str = "  io:\n    node_id: 4\n    driver: \"ros2_canopen::ProxyDriver\"\n    package: \"canopen_proxy_driver\"\n";

    #[test]
    fn a_ros2_canopen_bus_reads_with_its_defaults() {
        let bus = BusConfig::parse_ros2_canopen(BUS, "bus.yml", Path::new(".")).unwrap();
        assert_eq!((bus.master_id, bus.bitrate), (1, 1_000_000));
        assert_eq!(bus.sync, core::time::Duration::from_millis(10));
        assert_eq!(bus.cycle, core::time::Duration::from_millis(10));
        let ids: Vec<(String, u8)> = bus.nodes.iter().map(|n| (n.name.clone(), n.id)).collect();
        assert_eq!(ids, [("drive_left".into(), 2), ("drive_right".into(), 3)]);
        let right = bus.nodes.iter().find(|n| n.name == "drive_right").unwrap();
        assert_eq!(
            right.driver,
            crate::config::Driver::Cia402(crate::cia402::Mode::CyclicSynchronousPosition)
        );
        let left = bus.nodes.iter().find(|n| n.name == "drive_left").unwrap();
        assert_eq!(
            left.driver,
            crate::config::Driver::Cia402(crate::cia402::Mode::ProfileVelocity)
        );
        let e = BusConfig::parse_ros2_canopen(
            &BUS.replace("position_mode: 8", "velocity_mode: 4"),
            "bus.yml",
            Path::new("."),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("bus.yml: nodes.drive_right.velocity_mode: 4 is not a mode"),
            "{e}"
        );
        assert_eq!(
            right.heartbeat_timeout,
            core::time::Duration::from_millis(250)
        );
        assert!(right.warnings.iter().any(|w| w.contains("not applied")));
        // Any other driver is monitored only, and needs its DCF.
        let e = BusConfig::parse_ros2_canopen(&format!("{BUS}{PROXY}"), "bus.yml", Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("bus.yml: nodes.io.dcf: missing"), "{e}");
        let with_dcf = format!("{BUS}{PROXY}    dcf: \"io.eds\"\n");
        let e = BusConfig::parse_ros2_canopen(&with_dcf, "bus.yml", Path::new("/nowhere"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("io.eds"), "{e}");
    }

    #[test]
    fn mistakes_name_the_key_and_file() {
        let e =
            BusConfig::parse_ros2_canopen("master:\n  baudrate: 1000\n", "bus.yml", Path::new("."))
                .unwrap_err()
                .to_string();
        assert_eq!(e, "bus.yml: master.node_id: missing");
        let e = BusConfig::parse_ros2_canopen(
            &BUS.replace("node_id: 3", "node_id: 300"),
            "bus.yml",
            Path::new("."),
        )
        .unwrap_err()
        .to_string();
        assert_eq!(e, "bus.yml: nodes.drive_right.node_id: 300 is out of range");
        let e = BusConfig::parse_ros2_canopen(
            &BUS.replace("node_id: 3", "node_id: 2"),
            "bus.yml",
            Path::new("."),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("also node"), "{e}");
        let e =
            BusConfig::parse_ros2_canopen("master: [\n", "bus.yml", Path::new(".")).unwrap_err();
        assert!(e.to_string().starts_with("bus.yml: "), "{e}");
        let e = BusConfig::parse_ros2_canopen(
            &BUS.replace("baudrate", "x")
                .replace("sync_period: 10000", "baudrate: 999"),
            "bus.yml",
            Path::new("."),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("999000 is not a CiA 301 bit rate"), "{e}");
    }
}
