//! `bywire ros2` against Cyclone DDS (PyPI `cyclonedds`, the DDS of ROS 2's default middleware)
//! with ROS 2's type names, and python-can on the same bus. DDS discovery is multicast, so
//! every test runs inside `../shared/tools/lonet.sh`, with both sides bound to loopback.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![cfg(target_os = "linux")]

mod common;

use std::process::Command;

use common::*;
use serde_json::Value;

/// Run a Python peer from the oracles folder; its one JSON line.
fn python_peer(script: &str, args: &[&str]) -> Value {
    let out = Command::new("python3")
        .arg(format!("{}/{script}", oracles()))
        .args(args)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{script}: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(text.lines().last().unwrap_or_default()).unwrap()
}

fn ids(list: &Value) -> Vec<u64> {
    list.as_array()
        .unwrap()
        .iter()
        .map(|f| f["id"].as_u64().unwrap())
        .collect()
}

#[test]
fn ros2_can_bridges_a_bus_to_cyclone_dds_both_ways() {
    if !inside_lonet("ros2_can_bridges_a_bus_to_cyclone_dds_both_ways") {
        return;
    }
    let bus = "udp:239.74.163.2:43510";
    let bridge = Background::start(&["ros2", "can", bus, "--dds-interface", "lo"]);
    let seen = python_peer("ros2_can_peer.py", &["239.74.163.2", "43510"]);
    let (code, out, err) = bridge.stop();
    assert_eq!(code, 0, "{out}{err}");

    // The bus to DDS: classic, extended and remote frames on from_can_bus as can_msgs/Frame.
    let classic = seen["classic"].as_array().unwrap();
    assert_eq!(ids(&seen["classic"]), [0x123, 0x1ABC_DEF0, 0x321], "{seen}");
    let f = &classic[0];
    assert_eq!(
        (f["ext"].as_bool(), f["rtr"].as_bool(), f["dlc"].as_u64()),
        (Some(false), Some(false), Some(4))
    );
    assert_eq!(f["data"], "deadbeef00000000");
    assert_eq!(f["frame_id"], "can");
    // Stamped now (not the bus time): within a minute of the peer's clock.
    let age = seen["wall"].as_f64().unwrap() - f["stamp"].as_f64().unwrap();
    assert!((0.0..60.0).contains(&age), "{age}");
    assert_eq!(classic[1]["ext"], true);
    assert_eq!(classic[1]["data"], "0102000000000000");
    assert_eq!(
        (classic[2]["rtr"].as_bool(), classic[2]["dlc"].as_u64()),
        (Some(true), Some(3))
    );
    // CAN FD frames on from_can_bus_fd with their length and data.
    let fd = seen["fd"].as_array().unwrap();
    assert_eq!(ids(&seen["fd"]), [0x456, 0x18DA_F110], "{seen}");
    assert_eq!(
        (fd[0]["len"].as_u64(), fd[0]["ext"].as_bool()),
        (Some(12), Some(false))
    );
    assert_eq!(fd[0]["data"], "000102030405060708090a0b");
    assert_eq!(
        (fd[1]["len"].as_u64(), fd[1]["ext"].as_bool()),
        (Some(64), Some(true))
    );

    // DDS to the bus, as python-can sees it, in order on each topic; the bad messages (a
    // standard id of 0x800, an FD length of 9) sent nothing, and the markers after them came.
    let on_bus = seen["bus"].as_array().unwrap();
    let (fd_frames, classic_frames): (Vec<&Value>, Vec<&Value>) =
        on_bus.iter().partition(|m| m["fd"] == true);
    let ids_of =
        |list: &[&Value]| -> Vec<u64> { list.iter().map(|m| m["id"].as_u64().unwrap()).collect() };
    assert_eq!(
        ids_of(&classic_frames),
        [0x124, 0x1ABC_DEF1, 0x322, 0x333],
        "{seen}"
    );
    assert_eq!(ids_of(&fd_frames), [0x457, 0x1FFF_FFFF, 0x459], "{seen}");
    assert_eq!(classic_frames[0]["data"], "cafe");
    assert_eq!(classic_frames[1]["ext"], true);
    assert_eq!(
        (
            classic_frames[2]["rtr"].as_bool(),
            classic_frames[2]["dlc"].as_u64()
        ),
        (Some(true), Some(5))
    );
    assert_eq!(fd_frames[0]["brs"], true);
    assert_eq!(
        fd_frames[0]["data"],
        "000102030405060708090a0b0c0d0e0f10111213"
    );
    assert_eq!(
        (fd_frames[1]["dlc"].as_u64(), fd_frames[1]["ext"].as_bool()),
        (Some(48), Some(true))
    );
    assert!(
        err.contains("standard identifier 0x800 is above 0x7FF"),
        "{err}"
    );
    assert!(err.contains("9 bytes is not a CAN FD length"), "{err}");

    // The node in the ROS 2 graph, with its readers and writers.
    let nodes = seen["nodes"].as_array().unwrap();
    let node = nodes
        .iter()
        .find(|n| n["name"] == "socket_can_bridge")
        .unwrap_or_else(|| panic!("{seen}"));
    assert_eq!(node["namespace"], "/");
    assert!(node["readers"].as_u64().unwrap() >= 2, "{node}");
    assert!(node["writers"].as_u64().unwrap() >= 2, "{node}");
    assert!(out.contains("2 refused"), "{out}");
}
