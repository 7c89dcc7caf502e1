//! The SLCAN backend against a fake adapter written independently in Python on a pseudo
//! terminal: opening (close, bitrate, open), frames both ways in every form (standard,
//! extended, remote, FD with and without BRS, timestamps), error replies and garbage lines.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![cfg(target_os = "linux")]

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use bywire_bus::slcan::Slcan;
use bywire_bus::{open, BusError};
use common::*;

/// A Lawicel adapter: answers commands, acknowledges transmissions with z/Z, logs what it got
/// to stdout, and after five frames sends its own (with a garbage line and a BEL among them).
/// With `refuse` as argument it answers BEL to that command.
const ADAPTER: &str = r#"
import os, pty, sys, tty, time
master, slave = pty.openpty()
tty.setraw(slave)
print(os.ttyname(slave), flush=True)
refuse = sys.argv[1] if len(sys.argv) > 1 else None
buf = b""
frames = 0
log = []
while True:
    try:
        chunk = os.read(master, 256)
    except OSError:
        break
    if not chunk:
        break
    buf += chunk
    while b"\r" in buf:
        line, buf = buf.split(b"\r", 1)
        text = line.decode()
        log.append(text)
        if text == refuse:
            os.write(master, b"\x07")
        elif text[:1] in ("t", "r", "d", "b"):
            os.write(master, b"z\r"); frames += 1
        elif text[:1] in ("T", "R", "D", "B"):
            os.write(master, b"Z\r"); frames += 1
        elif text == "V":
            os.write(master, b"V1013\r")
        elif text in ("C", "O", "L") or (text[:1] == "S" and text[1:] in "012345678"):
            os.write(master, b"\r")
        else:
            os.write(master, b"\x07")
        if frames == 5:
            frames += 1
            os.write(master, b"t1232ABCD\rT1ABCDEF00\rr7FF3\rxyz\r\x07d0013112233\rb1239000102030405060708090A0B\rt4561550123\r")
        if text == "C" and len(log) > 3:
            print("\n".join(log), flush=True)
            sys.exit(0)
"#;

fn adapter(refuse: Option<&str>) -> (Child, String) {
    let mut child = Command::new("python3")
        .args(["-c", ADAPTER])
        .args(refuse)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    (child, line.trim().to_string())
}

#[test]
fn frames_both_ways_with_a_fake_adapter() {
    let (child, path) = adapter(None);
    let slcan = Slcan::open(&path, 500_000, false).unwrap();
    // The fake adapter answers V and refuses N.
    assert_eq!(slcan.versions().version.as_deref(), Some("1013"));
    assert_eq!(slcan.versions().serial, None);
    let mut bus: Box<dyn bywire_bus::Bus> = Box::new(slcan);
    for text in [
        "123#DEADBEEF",
        "1ABCDEF0#",
        "100#R3",
        "7FE##5000102030405060708090A0B",
        "321##4AA",
    ] {
        bus.send(&frame(text)).unwrap();
    }
    let mut got = Vec::new();
    let mut hardware = Vec::new();
    while let Some(r) = bus.recv(Some(Duration::from_secs(3))).unwrap() {
        got.push(r.frame.to_string());
        hardware.push(r.hardware.map(|t| t.as_nanos() / 1_000_000));
        if got.len() == 6 {
            break;
        }
    }
    assert_eq!(
        got,
        [
            "123#ABCD",
            "1ABCDEF0#",
            "7FF#R3",
            "001##4112233",
            "123##5000102030405060708090A0B",
            "456#55",
        ]
    );
    // Only the last line carried the adapter's millisecond timestamp (0x0123).
    assert_eq!(hardware, [None, None, None, None, None, Some(0x0123)]);
    // The garbage line and the BEL were counted and skipped.
    assert_eq!(bus.stats().rx_errors, 2);
    assert_eq!(bus.stats().tx_frames, 5);
    drop(bus);
    let out = child.wait_with_output().unwrap();
    let log = String::from_utf8(out.stdout).unwrap();
    assert_eq!(
        log.lines().collect::<Vec<_>>(),
        [
            "C",
            "V",
            "N",
            "S6",
            "O",
            "t1234DEADBEEF",
            "T1ABCDEF00",
            "r1003",
            "b7FE9000102030405060708090A0B",
            "d3211AA",
            "C",
        ]
    );
}

#[test]
fn refusals_are_errors_naming_the_command() {
    let (mut child, path) = adapter(Some("O"));
    let e = Slcan::open(&path, 500_000, false).err().unwrap();
    assert!(e.to_string().contains("the adapter refused O"), "{e}");
    let _ = child.kill();
    let (mut child, path) = adapter(Some("S4"));
    let e = Slcan::open(&path, 125_000, false).err().unwrap();
    assert!(e.to_string().contains("the adapter refused S4"), "{e}");
    let _ = child.kill();
    assert!(matches!(
        Slcan::open(&path, 400_000, false),
        Err(BusError::Unsupported(_))
    ));
    assert!(open("slcan:/dev/nonexistent@500000").is_err());
    assert!(open("slcan:/dev/ttyACM0@400000")
        .err()
        .unwrap()
        .to_string()
        .contains("not an SLCAN bitrate"));
    assert!(open("slcan:/dev/ttyACM0")
        .err()
        .unwrap()
        .to_string()
        .contains("lacks the bitrate"));
}

/// python-can's `slcan` interface against our emulated adapter (`slcan::emulate`) in front of a
/// virtual bus: python-can's frames reach the bus, the bus's frames reach python-can.
#[test]
fn python_can_slcan_talks_to_our_adapter() {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let adapter_bus = open("virtual:slcan-emulated").unwrap();
    let mut ours = open("virtual:slcan-emulated").unwrap();
    let (path, handle) =
        bywire_bus::slcan::emulate(adapter_bus, std::sync::Arc::clone(&stop)).unwrap();
    let script = r#"
import sys, can, time
bus = can.Bus(interface="slcan", channel=sys.argv[1], bitrate=500000, sleep_after_open=0.1)
bus.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\xde\xad\xbe\xef"))
bus.send(can.Message(arbitration_id=0x1abcdef0, is_extended_id=True, data=b"\x01"))
bus.send(can.Message(arbitration_id=0x321, is_extended_id=False, is_fd=True, bitrate_switch=True, data=bytes(range(12))))
print("sent", flush=True)
for _ in range(3):
    m = bus.recv(3)
    print("got", hex(m.arbitration_id), m.is_extended_id, m.is_remote_frame, m.is_fd, m.bitrate_switch, m.dlc, m.data.hex(), flush=True)
bus.shutdown()
"#;
    let peer = Command::new("python3")
        .args(["-c", script, &path])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut from_python = Vec::new();
    while from_python.len() < 3 {
        let r = ours
            .recv(Some(Duration::from_secs(10)))
            .unwrap()
            .expect("python-can's frames arrive");
        from_python.push(r.frame.to_string());
    }
    assert_eq!(
        from_python,
        [
            "123#DEADBEEF",
            "1ABCDEF0#01",
            "321##5000102030405060708090A0B"
        ]
    );
    for text in ["456#0102", "00000789#R2", "7FF##4AA"] {
        ours.send(&frame(text)).unwrap();
    }
    let out = peer.wait_with_output().unwrap();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    handle.join().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        text.lines().collect::<Vec<_>>(),
        [
            "sent",
            "got 0x456 False False False False 2 0102",
            "got 0x789 True True False False 2 ",
            "got 0x7ff False False True False 1 aa",
        ]
    );
}

/// Each endpoint an SLCAN adapter of ours (`slcan::emulate`) in front of `virtual:NAME`.
fn emulated_opener(name: &str) -> Box<Opener> {
    let spec = format!("virtual:{name}");
    Box::new(move || {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (path, _running) = bywire_bus::slcan::emulate(open(&spec).unwrap(), stop).unwrap();
        Box::new(Slcan::open(&path, 500_000, false).unwrap()) as Box<dyn bywire_bus::Bus>
    })
}

/// The conformance checks SLCAN allows (it has no receive-own), through emulated adapters.
#[test]
fn slcan_endpoints_pass_what_the_protocol_allows() {
    ordering_and_timestamps(&*emulated_opener("slcan-order"));
    senders_keep_their_order(&*emulated_opener("slcan-global"), false);
    filters_follow_socketcan(&*emulated_opener("slcan-filters"));
    halves_on_two_threads(&*emulated_opener("slcan-split"));
    timeout_returns_none(&*emulated_opener("slcan-timeout"));
}
