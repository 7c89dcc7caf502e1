//! SocketCAN against the Linux kernel. This machine's kernel has no CAN, so each test re-runs
//! itself inside `../shared/tools/canvm.sh` (a VM with the stock kernel's can, can-raw, vcan and
//! SJA1000 drivers, and can-utils as the peer): on the host it boots the VM with this test
//! binary and checks that the same test passed in there.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![cfg(target_os = "linux")]

mod common;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use bywire_bus::socketcan::{self, LinkConfig, SocketCan};
use bywire_bus::{open, Bus, ControllerState};
use common::*;

const IN_VM: &str = "BYWIRE_IN_CANVM";

/// True inside the VM; on the host, runs `test` inside the VM and checks it passed there.
fn inside_canvm(test: &str, options: &[&str]) -> bool {
    let canvm = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/tools/canvm.sh"
    );
    let exe = std::env::current_exe().unwrap();
    let mut launcher: Vec<&std::ffi::OsStr> = vec![canvm.as_ref(), "run".as_ref()];
    launcher.extend(options.iter().map(|o| std::ffi::OsStr::new(*o)));
    launcher.extend(["--timeout", "300", "--include"].map(std::ffi::OsStr::new));
    launcher.extend([exe.as_os_str(), "--".as_ref()]);
    inside(IN_VM, test, &launcher)
}

fn sh(command: &str) -> String {
    let out = Command::new("/bin/sh")
        .args(["-c", command])
        .output()
        .unwrap();
    assert!(out.status.success(), "{command}: {out:?}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Raw sockets the kernel lists as receivers on `interface` (each listening socket has an
/// entry per filter in /proc/net/can/rcvlist_all).
fn receivers_on(interface: &str) -> usize {
    std::fs::read_to_string("/proc/net/can/rcvlist_all")
        .unwrap()
        .lines()
        .filter(|line| line.split_whitespace().next() == Some(interface))
        .count()
}

/// `candump -L` on `interface` until `count` frames, returned once it listens (its socket is
/// among the kernel's receivers: a fixed wait loses frames on a loaded machine). It gives up
/// after 10 s without a frame, so a lost frame fails the test instead of hanging it.
fn candump(interface: &str, count: u32) -> Child {
    let before = receivers_on(interface);
    let candump = Command::new("candump")
        .args(["-L", "-n", &count.to_string(), "-T", "10000", interface])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    while receivers_on(interface) <= before {
        assert!(
            Instant::now() < deadline,
            "candump never listened on {interface}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    candump
}

#[test]
fn socketcan_passes_the_conformance_suite_on_vcan() {
    if !inside_canvm(
        "socketcan_passes_the_conformance_suite_on_vcan",
        &["--vcan", "8"],
    ) {
        return;
    }
    // One interface per check, so that no check sees another's frames.
    let checks = [
        "order", "global", "filters", "own", "fd", "split", "timeout",
    ];
    let open_for = |check: &str| -> Box<Opener> {
        let n = checks.iter().position(|c| *c == check).unwrap();
        // Readers here share two slow emulated CPUs with the senders: a large receive buffer
        // (as `candump -r`) keeps the kernel from dropping while they catch up.
        let interface = format!("vcan{n}");
        Box::new(move || {
            let bus = SocketCan::open(&interface).unwrap();
            bus.set_receive_buffer(1 << 22).unwrap();
            Box::new(bus) as Box<dyn Bus>
        })
    };
    run_all(&open_for, false);
    loopback_off_keeps_frames_from_local_endpoints(&|| open("socketcan:vcan7").unwrap());
    // The smallest receive buffer holds a handful of frames; the rest of a burst is dropped
    // by the kernel and counted through SO_RXQ_OVFL.
    bounded_queue_counts_drops(
        &|| {
            let bus = SocketCan::open("vcan7").unwrap();
            bus.set_receive_buffer(0).unwrap();
            Box::new(bus)
        },
        200,
    );
    assert_eq!(
        socketcan::interfaces().unwrap(),
        (0..8).map(|n| format!("vcan{n}")).collect::<Vec<_>>()
    );
    let vcan = open("socketcan:vcan0").unwrap();
    assert_eq!(vcan.status().unwrap(), None, "vcan has no controller state");
    let e = match open("socketcan:nosuch0") {
        Err(e) => e.to_string(),
        Ok(_) => panic!("opened an interface that does not exist"),
    };
    assert!(e.contains("nosuch0"), "{e}");
}

#[test]
fn can_utils_see_our_frames_and_we_see_theirs() {
    if !inside_canvm(
        "can_utils_see_our_frames_and_we_see_theirs",
        &["--can-utils"],
    ) {
        return;
    }
    let mut bus = open("socketcan:vcan0").unwrap();
    bus.set_receive_own(true).unwrap();
    let ours = [
        "123#DEADBEEF",
        "1ABCDEF0#R",
        "7FF#",
        "321##1000102030405060708090A0B0C",
        "12345678##30011",
    ];
    // candump -L prints "(secs.usecs) vcan0 FRAME" with frames in cansend syntax.
    let candump = candump("vcan0", 5);
    for text in ours {
        bus.send(&frame(text)).unwrap();
        // The echo confirms the transmission, with the time it left.
        let echo = bus.recv(Some(WAIT)).unwrap().unwrap();
        assert!(echo.own && echo.frame == frame(text), "{echo:?}");
        let now = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap();
        let at = Duration::from_nanos(echo.timestamp.as_nanos());
        assert!(
            now >= at && now - at < Duration::from_secs(1),
            "{at:?} vs {now:?}"
        );
    }
    let out = candump.wait_with_output().unwrap();
    // Compared as frames: candump shows the kernel's FD-frame flag (FDF) in the flags nibble.
    let dumped: Vec<_> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| frame(l.split_whitespace().nth(2).unwrap()))
        .collect();
    let expected: Vec<_> = ours.iter().map(|t| frame(t)).collect();
    assert_eq!(dumped, expected);

    let theirs = [
        "456#0102",
        "00000456#",
        "100#R3",
        "200##1AABBCCDDEEFF0011223344",
        "7FF#1122334455667788",
    ];
    for text in theirs {
        sh(&format!("cansend vcan0 '{text}'"));
        let got = bus.recv(Some(WAIT)).unwrap().unwrap();
        assert_eq!(got.frame, frame(text));
        assert!(!got.own, "cansend's frame is not ours");
    }
    let stats = bus.stats();
    assert_eq!((stats.tx_frames, stats.rx_frames), (5, 10));
}

#[test]
fn sja1000_controllers_are_configured_and_talk_through_netlink() {
    if !inside_canvm(
        "sja1000_controllers_are_configured_and_talk_through_netlink",
        &["--sja1000", "2", "--can-utils"],
    ) {
        return;
    }
    assert_eq!(socketcan::interfaces().unwrap(), ["can0", "can1", "vcan0"]);
    // A controller that is down reports itself stopped.
    let down = SocketCan::open("can0").unwrap();
    assert_eq!(
        down.status().unwrap().map(|s| s.state),
        Some(ControllerState::Stopped)
    );
    for (interface, restart_ms) in [("can0", 100), ("can1", 0)] {
        socketcan::configure(
            interface,
            &LinkConfig {
                bitrate: Some(500_000),
                sample_point: Some(875),
                restart_ms: Some(restart_ms),
                ..LinkConfig::default()
            },
        )
        .unwrap();
    }
    // What the kernel computed, as we read it and as `ip` shows it.
    assert_eq!(socketcan::bit_timing("can0").unwrap(), Some((500_000, 875)));
    let details = sh("ip -details link show can0");
    assert!(
        details.contains("bitrate 500000 sample-point 0.875"),
        "{details}"
    );
    assert!(details.contains("restart-ms 100"), "{details}");
    assert!(
        details.contains("state ERROR-ACTIVE (berr-counter tx 0 rx 0)"),
        "{details}"
    );

    let mut can0 = open("socketcan:can0").unwrap();
    let mut can1 = open("socketcan:can1").unwrap();
    let status = can0.status().unwrap().unwrap();
    assert_eq!(
        (status.state, status.tec, status.rec),
        (ControllerState::ErrorActive, 0, 0)
    );
    can0.set_receive_own(true).unwrap();
    let candump = candump("can1", 2);
    for text in ["123#0102030405060708", "1FFFFFFF#AA"] {
        can0.send(&frame(text)).unwrap();
        let confirmation = can0.recv(Some(WAIT)).unwrap().unwrap();
        assert!(confirmation.own && confirmation.frame == frame(text));
        // Across the emulated wire to the other controller.
        let got = can1.recv(Some(WAIT)).unwrap().unwrap();
        assert!(!got.own && got.frame == frame(text), "{got:?}");
    }
    let dumped = String::from_utf8_lossy(&candump.wait_with_output().unwrap().stdout).into_owned();
    assert!(dumped.contains("can1 123#0102030405060708"), "{dumped}");
    assert!(dumped.contains("can1 1FFFFFFF#AA"), "{dumped}");
    // And back the other way, from can-utils.
    sh("cansend can1 7FF#99");
    assert_eq!(
        can0.recv(Some(WAIT)).unwrap().unwrap().frame,
        frame("7FF#99")
    );
    // An SJA1000 has no FD: asking for a data bitrate is refused, naming the interface.
    let e = socketcan::configure(
        "can1",
        &LinkConfig {
            bitrate: Some(500_000),
            data_bitrate: Some(2_000_000),
            ..LinkConfig::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("can1"), "{e}");
    // A classic-only interface refuses FD frames clearly.
    let fd = can0.send(&frame("123##1AA"));
    assert!(
        matches!(fd, Err(bywire_bus::BusError::Unsupported(_))),
        "{fd:?}"
    );
}

#[cfg(feature = "tokio")]
#[test]
fn async_socketcan_receives_and_sends_without_blocking_the_runtime() {
    use bywire_bus::BusRx;
    if !inside_canvm(
        "async_socketcan_receives_and_sends_without_blocking_the_runtime",
        &["--can-utils"],
    ) {
        return;
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let bus = socketcan::AsyncSocketCan::new(SocketCan::open("vcan0").unwrap()).unwrap();
        // A timer on the same single thread keeps running while recv waits.
        let ticker = tokio::spawn(async {
            let mut ticks = 0;
            for _ in 0..5 {
                tokio::time::sleep(Duration::from_millis(20)).await;
                ticks += 1;
            }
            ticks
        });
        let peer = std::thread::spawn(|| {
            std::thread::sleep(Duration::from_millis(200));
            sh("cansend vcan0 5A5#0102 && cansend vcan0 1F334455##1AA");
        });
        let first = tokio::time::timeout(WAIT, bus.recv())
            .await
            .unwrap()
            .unwrap();
        assert_eq!(first.frame, frame("5A5#0102"));
        assert_eq!(
            ticker.await.unwrap(),
            5,
            "the runtime ran other tasks meanwhile"
        );
        let second = tokio::time::timeout(WAIT, bus.recv())
            .await
            .unwrap()
            .unwrap();
        assert_eq!(second.frame, frame("1F334455##1AA"));
        peer.join().unwrap();
        let candump = candump("vcan0", 1);
        bus.send(&frame("0AA#CAFE")).await.unwrap();
        let dumped =
            String::from_utf8_lossy(&candump.wait_with_output().unwrap().stdout).into_owned();
        assert!(dumped.contains("vcan0 0AA#CAFE"), "{dumped}");
        assert_eq!(bus.get_ref().stats().tx_frames, 1);
    });
    // Outside a runtime, registration is an error, not a panic.
    assert!(socketcan::AsyncSocketCan::new(SocketCan::open("vcan0").unwrap()).is_err());
}
