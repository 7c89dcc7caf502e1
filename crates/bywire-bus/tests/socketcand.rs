//! The socketcand server and client together: the server in this process on a virtual bus,
//! clients connected over TCP, and the conformance checks that socketcand's raw mode allows
//! (it has no transmit confirmation, FD or remote frames).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::net::TcpListener;
use std::sync::Arc;
use std::time::Duration;

use bywire_bus::socketcand::{self, Client, Server};
use bywire_bus::{open, Bus, BusError, BusRx, BusTx};
use common::*;

/// A server for `virtual:NAME` on a free port, with `config` (it stops when dropped).
fn server_with(name: &str, config: socketcand::Config) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let spec = format!("virtual:{name}");
    let open_bus =
        Arc::new(move |_name: &str| open(&spec).map_err(|e| BusError::Unsupported(e.to_string())));
    Server::start(listener, config, open_bus).unwrap()
}

/// A server for `virtual:NAME` with the default limits; returns it and its address.
fn server(name: &str) -> (Server, String) {
    let server = server_with(name, socketcand::Config::default());
    let address = server.local_addr().to_string();
    (server, address)
}

fn client_opener(name: &str) -> Box<Opener> {
    let (server, address) = server(name);
    let name = name.to_string();
    Box::new(move || {
        let _serving = &server;
        let bus = Box::new(Client::connect(&address, &name).unwrap()) as Box<dyn Bus>;
        // Frames sent before the server has the client's endpoint would be lost to it.
        std::thread::sleep(Duration::from_millis(50));
        bus
    })
}

#[test]
fn socketcand_clients_pass_what_raw_mode_allows() {
    ordering_and_timestamps(&*client_opener("scd-order"));
    senders_keep_their_order(&*client_opener("scd-global"), false);
    filters_follow_socketcan(&*client_opener("scd-filters"));
    halves_on_two_threads(&*client_opener("scd-split"));
    timeout_returns_none(&*client_opener("scd-timeout"));
}

#[test]
fn what_socketcand_cannot_carry_is_refused() {
    let mut bus = client_opener("scd-refuse")();
    assert!(matches!(
        bus.send(&frame("123##1AA")),
        Err(BusError::Unsupported(_))
    ));
    assert!(matches!(
        bus.send(&frame("123#R")),
        Err(BusError::Unsupported(_))
    ));
    assert!(matches!(
        bus.set_receive_own(true),
        Err(BusError::Unsupported(_))
    ));
    assert!(Client::connect("127.0.0.1:1", "x").is_err());
    assert!(matches!(
        open("socketcand:nohost"),
        Err(bywire_bus::OpenError::Spec(_))
    ));
}

#[test]
fn a_client_and_a_local_endpoint_share_the_served_bus() {
    let (_server, address) = server("scd-shared");
    let mut local = open("virtual:scd-shared").unwrap();
    let mut remote = Client::connect(&address, "scd-shared").unwrap();
    std::thread::sleep(Duration::from_millis(50));
    remote.send(&frame("123#DEADBEEF")).unwrap();
    let got = local.recv(Some(Duration::from_secs(2))).unwrap().unwrap();
    assert_eq!(got.frame, frame("123#DEADBEEF"));
    local.send(&frame("1ABCDEF0#0102")).unwrap();
    let got = remote.recv(Some(Duration::from_secs(2))).unwrap().unwrap();
    assert_eq!(got.frame, frame("1ABCDEF0#0102"));
    // The timestamp is the server's, in Unix time.
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    assert!(now.abs_diff(u128::from(got.timestamp.as_nanos())) < 2_000_000_000);
}

/// Resident memory of this process in kB.
fn resident_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap()
}

/// Four clients on one served bus at 5,000 frames/s for 30 s: every client gets every frame
/// in order, or the server counted what it dropped; memory stays flat.
#[test]
fn four_clients_at_5000_frames_per_second_for_30_s() {
    const RATE: u64 = 5_000;
    const SECONDS: u64 = 30;
    let (server, address) = server("scd-load");
    let clients: Vec<_> = (0..4)
        .map(|_| {
            let mut client = Client::connect(&address, "scd-load").unwrap();
            std::thread::spawn(move || {
                let mut expected = 0u64;
                let mut missing = 0u64;
                while expected < RATE * SECONDS {
                    let Some(r) = client.recv(Some(Duration::from_secs(5))).unwrap() else {
                        break;
                    };
                    let n = u64::from_le_bytes(r.frame.data().try_into().unwrap());
                    assert!(n >= expected, "frame {n} after {expected}: out of order");
                    missing += n - expected;
                    expected = n + 1;
                }
                missing + (RATE * SECONDS - expected)
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let mut generator = open("virtual:scd-load").unwrap();
    let start = std::time::Instant::now();
    let mut sent = 0u64;
    let mut memory_at_5_s = None;
    while sent < RATE * SECONDS {
        // Five frames a millisecond, on schedule.
        let due = u64::try_from(start.elapsed().as_millis()).unwrap() * RATE / 1000;
        while sent < due.min(RATE * SECONDS) {
            let frame = bywire_core::Frame::classic(
                bywire_core::Id::standard(0x100).unwrap(),
                &sent.to_le_bytes(),
            )
            .unwrap();
            generator.send(&frame).unwrap();
            sent += 1;
        }
        if memory_at_5_s.is_none() && start.elapsed() >= Duration::from_secs(5) {
            memory_at_5_s = Some(resident_kb());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let missing: Vec<u64> = clients.into_iter().map(|c| c.join().unwrap()).collect();
    let dropped = server.stats().dropped_total();
    assert_eq!(
        missing.iter().sum::<u64>(),
        dropped,
        "lost {missing:?}, counted {dropped}"
    );
    let growth = resident_kb().saturating_sub(memory_at_5_s.unwrap());
    assert!(
        growth < 20_000,
        "memory grew by {growth} kB between 5 s and 30 s"
    );
}

#[test]
fn a_token_is_asked_for_before_anything_else() {
    use std::io::{Read, Write};
    let config = socketcand::Config {
        access: socketcand::Access {
            names: vec!["vcan0".into()],
            token: Some("s3cret".into()),
        },
        ..socketcand::Config::default()
    };
    let server = server_with("scd-token", config);
    let mut s = std::net::TcpStream::connect(server.local_addr()).unwrap();
    let mut exchange = |send: &str| {
        s.write_all(send.as_bytes()).unwrap();
        std::thread::sleep(Duration::from_millis(100));
        let mut buf = [0u8; 512];
        let n = s.read(&mut buf).unwrap();
        String::from_utf8_lossy(&buf[..n]).into_owned()
    };
    assert_eq!(exchange(""), "< hi >");
    assert_eq!(exchange("< auth s3cret >"), "< ok >");
    // An error quoting the client's text keeps its framing too.
    let r = exchange("< nonsense <x >");
    assert!(
        r.starts_with("< error") && r.matches('<').count() == 1 && r.matches('>').count() == 1,
        "{r}"
    );
    assert_eq!(
        exchange("< open other >"),
        "< error no bus 'other' (served: vcan0) >"
    );
    assert_eq!(exchange("< open vcan0 >"), "< ok >");
}

/// On a busy bus the acknowledgement of `< rawmode >` arrives alone — clients such as
/// python-can read one chunk and expect exactly `< ok >` — and the frames follow, none lost:
/// those sent while the client read the acknowledgement come first, then the rest in order.
#[test]
fn the_raw_mode_acknowledgement_arrives_alone_on_a_busy_bus() {
    use std::io::{Read, Write};
    use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    let (_server, address) = server("scd-busy");
    let mut sender = open("virtual:scd-busy").unwrap();
    let (busy, sent) = (Arc::new(AtomicBool::new(true)), Arc::new(AtomicU32::new(0)));
    let (running, counter) = (Arc::clone(&busy), Arc::clone(&sent));
    let traffic = std::thread::spawn(move || {
        while running.load(Ordering::Relaxed) {
            let n = counter.load(Ordering::Relaxed);
            sender.send(&frame(&format!("123#{n:08X}"))).unwrap();
            counter.store(n + 1, Ordering::Relaxed);
            std::thread::sleep(Duration::from_micros(200));
        }
    });
    let mut stream = std::net::TcpStream::connect(&address).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut chunk = [0u8; 256];
    let n = stream.read(&mut chunk).unwrap();
    assert_eq!(&chunk[..n], b"< hi >");
    stream.write_all(b"< open scd-busy >").unwrap();
    let n = stream.read(&mut chunk).unwrap();
    assert_eq!(&chunk[..n], b"< ok >");
    stream.write_all(b"< rawmode >").unwrap();
    // As a client would: a little late to read.
    std::thread::sleep(Duration::from_millis(10));
    let n = stream.read(&mut chunk).unwrap();
    assert_eq!(String::from_utf8_lossy(&chunk[..n]), "< ok >");
    let sent_by_then = sent.load(Ordering::Relaxed);
    // Then the frames, counting up without a gap.
    let mut text = String::new();
    let mut bytes = [0u8; 4096];
    while text.matches("< frame").count() < 400 {
        let n = stream.read(&mut bytes).unwrap();
        text.push_str(&String::from_utf8_lossy(&bytes[..n]));
    }
    busy.store(false, Ordering::Relaxed);
    traffic.join().unwrap();
    let counters: Vec<u32> = text
        .split("< frame 123 ")
        .skip(1)
        .take(400)
        .map(|f| {
            let data = f.split_whitespace().nth(1).unwrap();
            u32::from_str_radix(data, 16).unwrap()
        })
        .collect();
    assert!(
        counters[0] < sent_by_then,
        "the first frame ({}) was sent while the client read the acknowledgement ({sent_by_then})",
        counters[0]
    );
    assert!(
        counters.windows(2).all(|w| w[1] == w[0] + 1),
        "{counters:?}"
    );
}
