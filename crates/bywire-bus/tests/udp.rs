//! `udp:` (python-can's `udp_multicast` wire format) inside `../shared/tools/lonet.sh`, a
//! private network namespace whose multicast cannot leave the machine: on the host each test
//! re-runs itself in there. The conformance suite on IPv4 and IPv6 groups, and python-can 4.6
//! as the peer both ways with classic, extended, remote and FD frames.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![cfg(target_os = "linux")]

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use bywire_bus::open;
use common::*;

const IN_LONET: &str = "BYWIRE_IN_LONET";

/// True inside the namespace; on the host, runs `test` in a fresh one and checks it passed.
fn inside_lonet(test: &str) -> bool {
    let lonet = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/tools/lonet.sh"
    );
    inside(IN_LONET, test, &[lonet.as_ref()])
}

fn opener(spec: String) -> Box<Opener> {
    Box::new(move || open(&spec).unwrap())
}

#[test]
fn udp_ipv4_passes_the_conformance_suite() {
    if !inside_lonet("udp_ipv4_passes_the_conformance_suite") {
        return;
    }
    // One port per check, so the checks' traffic stays apart.
    let port = std::cell::Cell::new(43200u16);
    run_all(
        &|_| {
            port.set(port.get() + 1);
            opener(format!("udp:239.74.163.2:{}", port.get()))
        },
        false,
    );
}

#[test]
fn udp_ipv6_passes_the_conformance_suite() {
    if !inside_lonet("udp_ipv6_passes_the_conformance_suite") {
        return;
    }
    let port = std::cell::Cell::new(43300u16);
    run_all(
        &|_| {
            port.set(port.get() + 1);
            opener(format!(
                "udp:[ff15:7079:7468:6f6e:6465:6d6f:6d63:6173]:{}",
                port.get()
            ))
        },
        false,
    );
}

/// python-can receives what we send, and sends back each frame with its ID + 1, then its own.
const PEER: &str = r#"
import sys, can
bus = can.Bus(interface="udp_multicast", channel=sys.argv[1], port=int(sys.argv[2]), fd=True)
print("ready", flush=True)
got = 0
while got < 5:
    m = bus.recv(10)
    if m is None:
        sys.exit("python-can received nothing")
    # python-can hears its own datagrams too; answer only ours.
    if m.arbitration_id in (0x124, 0x1ABCDEF1, 0x101, 0x7FF, 0x322, 0x333):
        continue
    got += 1
    print("recv", hex(m.arbitration_id), m.is_extended_id, m.is_remote_frame, m.is_fd,
          m.bitrate_switch, m.dlc, m.data.hex(), flush=True)
    bus.send(can.Message(arbitration_id=m.arbitration_id + 1, is_extended_id=m.is_extended_id,
                         is_remote_frame=m.is_remote_frame, is_fd=m.is_fd,
                         bitrate_switch=m.bitrate_switch, dlc=m.dlc, data=m.data))
bus.send(can.Message(arbitration_id=0x333, is_extended_id=False, data=b"\x01\x02"))
bus.shutdown()
"#;

fn python_can_is_the_peer(group: &str) {
    let port = "43500";
    let mut peer = Command::new("python3")
        .args(["-c", PEER, group, port])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = std::io::BufReader::new(peer.stdout.take().unwrap());
    let mut line = String::new();
    std::io::BufRead::read_line(&mut stdout, &mut line).unwrap();
    assert_eq!(
        line.trim(),
        "ready",
        "python-can udp_multicast (pip install python-can msgpack)"
    );
    let spec = if group.contains(':') {
        format!("udp:[{group}]:{port}")
    } else {
        format!("udp:{group}:{port}")
    };
    let mut bus = open(&spec).unwrap();
    let ours = [
        "123#DEADBEEF",
        "1ABCDEF0#",
        "100#R3",
        "7FE##5000102030405060708090A0B",
        "321##4AA",
    ];
    let mut answers = Vec::new();
    for text in ours {
        bus.send(&frame(text)).unwrap();
        let reply = bus
            .recv(Some(Duration::from_secs(5)))
            .unwrap()
            .expect("python-can answers");
        assert!(!reply.own);
        answers.push(reply.frame.to_string());
    }
    let last = bus.recv(Some(Duration::from_secs(5))).unwrap().unwrap();
    let out = peer.wait_with_output().unwrap();
    let mut printed = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut printed).unwrap();
    assert!(
        out.status.success(),
        "{printed}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // What python-can saw of our frames, field by field.
    assert_eq!(
        printed.lines().collect::<Vec<_>>(),
        [
            "recv 0x123 False False False False 4 deadbeef",
            "recv 0x1abcdef0 True False False False 0 ",
            "recv 0x100 False True False False 3 ",
            "recv 0x7fe False False True True 12 000102030405060708090a0b",
            "recv 0x321 False False True False 1 aa",
        ]
    );
    assert_eq!(
        answers,
        [
            "124#DEADBEEF",
            "1ABCDEF1#",
            "101#R3",
            "7FF##5000102030405060708090A0B",
            "322##4AA",
        ]
    );
    assert_eq!(last.frame, frame("333#0102"));
}

#[test]
fn python_can_udp_multicast_ipv6() {
    if inside_lonet("python_can_udp_multicast_ipv6") {
        python_can_is_the_peer("ff15:7079:7468:6f6e:6465:6d6f:6d63:6173");
    }
}

#[test]
fn python_can_udp_multicast_ipv4() {
    if inside_lonet("python_can_udp_multicast_ipv4") {
        python_can_is_the_peer("239.74.163.2");
    }
}

#[test]
fn malformed_datagrams_are_counted_and_skipped() {
    if !inside_lonet("malformed_datagrams_are_counted_and_skipped") {
        return;
    }
    let mut bus = open("udp:239.74.163.2:43600").unwrap();
    let raw = std::net::UdpSocket::bind("0.0.0.0:0").unwrap();
    for junk in [
        &b"garbage"[..],
        &[0x81, 0xA4, b'd', b'a', b't', b'a', 0x05][..],
        &[0xC1][..],
        &[],
    ] {
        raw.send_to(junk, "239.74.163.2:43600").unwrap();
    }
    let mut good = open("udp:239.74.163.2:43600").unwrap();
    good.send(&frame("123#01")).unwrap();
    let got = bus.recv(Some(Duration::from_secs(2))).unwrap().unwrap();
    assert_eq!(got.frame, frame("123#01"));
    assert_eq!(bus.stats().rx_errors, 4);
}
