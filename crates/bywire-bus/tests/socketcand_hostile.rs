//! The socketcand server against hostile and careless clients: a flood of BCM jobs, a
//! thousand connection resets, six hundred idle connections, an unpaced flood from four
//! clients, a client that stops reading, token guessing — and a well-behaved client served
//! throughout. Threads and descriptors are this process's own (`/proc/self`), so the tests
//! run one at a time.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bywire_bus::socketcand::{Access, Client, Config, Limits, Server};
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{open, Bus, BusError, BusRx};
use bywire_core::{Frame, Id};

/// Every test takes this first: the counts of threads and descriptors are the process's.
static COUNTING: Mutex<()> = Mutex::new(());

fn counting() -> std::sync::MutexGuard<'static, ()> {
    COUNTING
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The server's threads in this process (they are named `socketcand-…`; the test harness's
/// own threads come and go).
fn threads() -> usize {
    thread_names().len()
}

fn thread_names() -> Vec<String> {
    std::fs::read_dir("/proc/self/task")
        .unwrap()
        .filter_map(|task| std::fs::read_to_string(task.ok()?.path().join("comm")).ok())
        .filter(|name| name.starts_with("socketcand-"))
        .map(|name| name.trim().to_string())
        .collect()
}

fn descriptors() -> usize {
    std::fs::read_dir("/proc/self/fd").unwrap().count()
}

/// Wait (up to 5 s) until threads and descriptors are back within `slack` of `baseline`;
/// returns what they are then.
fn settle(baseline: (usize, usize), slack: usize) -> (usize, usize) {
    poll_until(
        Duration::from_secs(5),
        || (threads(), descriptors()),
        |now| now.0 <= baseline.0 + slack && now.1 <= baseline.1 + slack,
    )
}

/// Looks (`observe`) until what it sees is `done` or `limit` has passed; the last look (the
/// assertions after it say which).
fn poll_until<T>(limit: Duration, observe: impl Fn() -> T, done: impl Fn(&T) -> bool) -> T {
    let until = Instant::now() + limit;
    loop {
        let seen = observe();
        if done(&seen) || Instant::now() > until {
            return seen;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A server for the in-process bus `name`, each client's endpoint holding `queue` frames.
fn server(name: &str, limits: Limits, queue: usize) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let name = name.to_string();
    let open_bus = Arc::new(move |_: &str| -> Result<Box<dyn Bus>, BusError> {
        Ok(Box::new(VirtualBus::join_with_queue(&name, queue)))
    });
    let config = Config {
        access: Access::default(),
        limits,
    };
    let before = threads();
    let server = Server::start(listener, config, open_bus).unwrap();
    // A thread takes its name once it runs: wait for the accept loop's, so counts are exact.
    let until = Instant::now() + Duration::from_secs(2);
    while threads() == before && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(1));
    }
    server
}

fn frame(id: u32, data: &[u8]) -> Frame {
    Frame::classic(Id::standard(id).unwrap(), data).unwrap()
}

/// A client speaking the protocol's text directly.
struct Raw {
    reader: BufReader<TcpStream>,
    writer: TcpStream,
}

impl Raw {
    fn connect(server: &Server) -> Raw {
        let stream = TcpStream::connect(server.local_addr()).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let writer = stream.try_clone().unwrap();
        Raw {
            reader: BufReader::new(stream),
            writer,
        }
    }

    /// Connected, greeted, with `bus` open.
    fn opened(server: &Server, bus: &str) -> Raw {
        let mut raw = Raw::connect(server);
        assert_eq!(raw.message(), "< hi >");
        raw.send(&format!("< open {bus} >"));
        assert_eq!(raw.message(), "< ok >");
        raw
    }

    fn send(&mut self, text: &str) {
        self.writer.write_all(text.as_bytes()).unwrap();
    }

    /// The next message, or "" when the server closed the connection.
    fn message(&mut self) -> String {
        let mut got = Vec::new();
        match self.reader.read_until(b'>', &mut got) {
            Ok(_) => String::from_utf8_lossy(&got).trim().to_string(),
            Err(_) => String::new(),
        }
    }
}

#[test]
fn a_flood_of_bcm_jobs_is_refused_beyond_the_limits_and_ends_with_its_client() {
    let _counting = counting();
    let server = server("hostile-bcm", Limits::default(), 4096);
    let mut observer = open("virtual:hostile-bcm").unwrap();
    let baseline = (threads(), descriptors());
    let mut client = Raw::opened(&server, "hostile-bcm");
    client.send("< add 0 1 123 1 ff >");
    assert!(
        client
            .message()
            .contains("below the server's minimum of 1000"),
        "a 1 µs interval"
    );
    for id in 0..2000u32 {
        client.send(&format!("< add 1 0 {id:03X} 1 01 >"));
    }
    for _ in 64..2000 {
        let reply = client.message();
        assert!(reply.contains("at most 64 per client"), "{reply}");
    }
    assert_eq!(server.stats().refused_jobs.load(Ordering::Relaxed), 1937);
    // One session: three threads, none per job.
    let during = threads();
    assert!(
        during <= baseline.0 + 3,
        "{during} threads with 64 jobs running (from {})",
        baseline.0
    );
    // The 64 jobs send at once, then every second.
    let mut seen = std::collections::BTreeSet::new();
    let until = Instant::now() + Duration::from_secs(3);
    while seen.len() < 64 && Instant::now() < until {
        if let Some(r) = observer.recv(Some(Duration::from_millis(100))).unwrap() {
            seen.insert(r.frame.id().unwrap().as_raw());
        }
    }
    assert_eq!(seen.len(), 64);
    // The client leaves: its jobs stop with it.
    drop(client);
    let settled = settle(baseline, 0);
    assert!(
        settled.0 <= baseline.0,
        "threads {settled:?}, were {baseline:?}"
    );
    while observer
        .recv(Some(Duration::from_millis(50)))
        .unwrap()
        .is_some()
    {}
    assert!(
        observer
            .recv(Some(Duration::from_millis(1500)))
            .unwrap()
            .is_none(),
        "a job of a client that left still sends"
    );
}

#[test]
fn a_thousand_connection_resets_leave_no_thread_or_descriptor_behind() {
    let _counting = counting();
    let server = server("hostile-reset", Limits::default(), 4096);
    let baseline = (threads(), descriptors());
    for _ in 0..1000 {
        let stream = TcpStream::connect(server.local_addr()).unwrap();
        (&stream)
            .write_all(b"< open hostile-reset >< add 1 0 123 1 01 >")
            .unwrap();
        // Wait for the replies, then close without reading them: the kernel resets the
        // connection (unread data), as a crashed client's would be.
        stream
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let mut peek = [0u8; 64];
        let until = Instant::now() + Duration::from_secs(5);
        while stream.peek(&mut peek).unwrap_or(0) < 12 && Instant::now() < until {}
        drop(stream);
    }
    let settled = settle(baseline, 0);
    assert!(
        settled.0 <= baseline.0 && settled.1 <= baseline.1,
        "threads and descriptors {settled:?}, were {baseline:?}: {:?}",
        thread_names()
    );
    let stats = server.stats();
    assert_eq!(stats.active.load(Ordering::Relaxed), 0);
    assert_eq!(
        stats.clients.load(Ordering::Relaxed) + stats.refused_clients.load(Ordering::Relaxed),
        1000
    );
    // And the server still serves.
    let mut a = Client::connect(&server.local_addr().to_string(), "hostile-reset").unwrap();
    let mut b = open("virtual:hostile-reset").unwrap();
    std::thread::sleep(Duration::from_millis(100));
    b.send(&frame(0x321, &[7])).unwrap();
    let got = a.recv(Some(Duration::from_secs(2))).unwrap().unwrap();
    assert_eq!(got.frame, frame(0x321, &[7]));
}

#[test]
fn six_hundred_idle_connections_neither_exhaust_the_server_nor_stop_a_client() {
    let _counting = counting();
    let limits = Limits {
        handshake_timeout: Duration::from_secs(2),
        ..Limits::default()
    };
    let server = server("hostile-idle", limits, 4096);
    let address = server.local_addr().to_string();
    // A well-behaved client, receiving a counter every 2 ms throughout.
    let mut good = Client::connect(&address, "hostile-idle").unwrap();
    std::thread::sleep(Duration::from_millis(100));
    let running = Arc::new(AtomicBool::new(true));
    let sending = Arc::clone(&running);
    let sender = std::thread::spawn(move || {
        let mut bus = open("virtual:hostile-idle").unwrap();
        let mut n = 0u32;
        while sending.load(Ordering::Relaxed) {
            bus.send(&frame(0x100, &n.to_le_bytes())).unwrap();
            n += 1;
            std::thread::sleep(Duration::from_millis(2));
        }
        n
    });
    let received = Arc::new(AtomicU64::new(0));
    let counted = Arc::clone(&received);
    let receiver = std::thread::spawn(move || {
        let mut expected = 0u32;
        while let Some(r) = good.recv(Some(Duration::from_secs(1))).unwrap() {
            let n = u32::from_le_bytes(r.frame.data().try_into().unwrap());
            assert_eq!(n, expected, "a frame lost or out of order");
            expected += 1;
            counted.fetch_add(1, Ordering::Relaxed);
        }
        expected
    });
    let baseline = (threads(), descriptors());
    // In batches, so the listen backlog never overflows (the kernel would hold a connect
    // back for a second, and the early ones would time out before the count).
    let mut idle = Vec::new();
    for _ in 0..12 {
        idle.extend((0..50).map(|_| TcpStream::connect(&address).unwrap()));
        std::thread::sleep(Duration::from_millis(20));
    }
    let stats = server.stats();
    // Every connection answered (held or refused), well before the handshake time runs out.
    poll_until(
        Duration::from_millis(1500),
        || stats.active.load(Ordering::Relaxed) + stats.refused_clients.load(Ordering::Relaxed),
        |answered| *answered >= 601,
    );
    assert_eq!(stats.active.load(Ordering::Relaxed), 64, "the limit");
    assert_eq!(stats.refused_clients.load(Ordering::Relaxed), 537);
    let mut last = BufReader::new(idle.last().unwrap().try_clone().unwrap());
    let mut refusal = Vec::new();
    last.read_until(b'>', &mut refusal).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&refusal),
        "< error the server is full (64 clients) >"
    );
    // Two threads and two descriptors for each idle session that holds a place.
    let during = (threads(), descriptors());
    assert!(
        during.0 <= baseline.0 + 2 * 63,
        "{during:?} from {baseline:?}"
    );
    let received_then = received.load(Ordering::Relaxed);
    // The handshake time passes: the idle sessions are closed, and a new client is served.
    poll_until(
        Duration::from_secs(6),
        || stats.timed_out.load(Ordering::Relaxed),
        |timed_out| *timed_out >= 63,
    );
    assert_eq!(stats.timed_out.load(Ordering::Relaxed), 63);
    let settled = settle(baseline, 0);
    assert!(settled.0 <= baseline.0, "{settled:?} from {baseline:?}");
    drop(idle);
    let mut late = Raw::opened(&server, "hostile-idle");
    late.send("< echo >");
    assert_eq!(late.message(), "< echo >");
    assert!(
        received.load(Ordering::Relaxed) > received_then + 300,
        "the good client kept receiving while the idle ones held their places"
    );
    running.store(false, Ordering::Relaxed);
    let sent = sender.join().unwrap();
    let got = receiver.join().unwrap();
    assert_eq!(got, sent, "every frame reached the well-behaved client");
}

#[test]
fn an_unpaced_four_client_flood_counts_every_frame_it_drops() {
    let _counting = counting();
    const FRAMES: u32 = 25_000;
    // Small endpoint queues, so the forwarding falls behind and the endpoints drop.
    let server = server("hostile-flood", Limits::default(), 64);
    let address = server.local_addr().to_string();
    let clients: Vec<Client> = (0..4)
        .map(|_| Client::connect(&address, "hostile-flood").unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let mut readers = Vec::new();
    let mut senders = Vec::new();
    for (index, client) in clients.into_iter().enumerate() {
        let (mut tx, mut rx) = (Box::new(client) as Box<dyn Bus>).split();
        readers.push(std::thread::spawn(move || {
            let mut got = 0u64;
            while rx.recv(Some(Duration::from_secs(2))).unwrap().is_some() {
                got += 1;
            }
            got
        }));
        senders.push(std::thread::spawn(move || {
            let id = 0x100 + u32::try_from(index).unwrap();
            for n in 0..FRAMES {
                tx.send(&frame(id, &n.to_le_bytes())).unwrap();
            }
        }));
    }
    for s in senders {
        s.join().unwrap();
    }
    let received: u64 = readers.into_iter().map(|r| r.join().unwrap()).sum();
    // Each frame goes to the three other clients.
    let expected = 4 * u64::from(FRAMES) * 3;
    let stats = server.stats();
    let dropped = stats.dropped_total();
    eprintln!(
        "received {received} of {expected}; dropped {dropped} (queue {}, endpoint {})",
        stats.dropped.load(Ordering::Relaxed),
        stats.dropped_at_endpoint.load(Ordering::Relaxed)
    );
    assert_eq!(
        received + dropped,
        expected,
        "every frame delivered or counted"
    );
}

#[test]
fn a_client_that_stops_reading_is_cut_off_and_counted_while_the_others_are_served() {
    let _counting = counting();
    const FRAMES: u32 = 150_000;
    let limits = Limits {
        write_timeout: Duration::from_secs(1),
        ..Limits::default()
    };
    let server = server("hostile-slow", limits, 8192);
    let address = server.local_addr().to_string();
    // The slow client: a small receive buffer, raw mode, then it reads nothing.
    let socket = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    socket.connect(&server.local_addr().into()).unwrap();
    let slow_stream: TcpStream = socket.into();
    slow_stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut slow = Raw {
        reader: BufReader::new(slow_stream.try_clone().unwrap()),
        writer: slow_stream,
    };
    assert_eq!(slow.message(), "< hi >");
    slow.send("< open hostile-slow >");
    assert_eq!(slow.message(), "< ok >");
    slow.send("< rawmode >");
    assert_eq!(slow.message(), "< ok >");
    let mut good = Client::connect(&address, "hostile-slow").unwrap();
    std::thread::sleep(Duration::from_millis(100));
    let receiver = std::thread::spawn(move || {
        let mut got = 0u64;
        while good.recv(Some(Duration::from_secs(2))).unwrap().is_some() {
            got += 1;
        }
        got
    });
    let mut bus = open("virtual:hostile-slow").unwrap();
    for n in 0..FRAMES {
        bus.send(&frame(0x200, &n.to_le_bytes())).unwrap();
        if n % 100 == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let got = receiver.join().unwrap();
    let stats = server.stats();
    assert_eq!(
        stats.stalled.load(Ordering::Relaxed),
        1,
        "the slow client was cut off"
    );
    assert!(
        stats.dropped.load(Ordering::Relaxed) > 0,
        "its frames were counted"
    );
    let missing = u64::from(FRAMES) - got;
    assert!(
        missing <= stats.dropped_total(),
        "the good client missed {missing}, the server counted {}",
        stats.dropped_total()
    );
    // The slow client finds its connection closed once it reads again.
    let mut rest = Vec::new();
    let _ = slow.reader.read_to_end(&mut rest);
    assert!(rest.len() < 2_000_000, "{} bytes", rest.len());
    let until = Instant::now() + Duration::from_secs(2);
    while stats.active.load(Ordering::Relaxed) > 0 && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(
        stats.active.load(Ordering::Relaxed),
        0,
        "both sessions ended"
    );
}

#[test]
fn a_frame_whose_bytes_arrive_across_a_pause_reaches_the_client_whole() {
    let _counting = counting();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    // A server that sends each frame in two parts, 150 ms apart.
    let server = std::thread::spawn(move || {
        let (stream, _) = listener.accept().unwrap();
        let mut writer = stream.try_clone().unwrap();
        let mut reader = BufReader::new(stream);
        let mut expect = |wanted: &str| {
            let mut got = Vec::new();
            reader.read_until(b'>', &mut got).unwrap();
            assert_eq!(String::from_utf8_lossy(&got).trim(), wanted);
        };
        writer.write_all(b"< hi >").unwrap();
        expect("< open paused >");
        writer.write_all(b"< ok >").unwrap();
        expect("< rawmode >");
        writer.write_all(b"< ok >").unwrap();
        for n in 0..10u8 {
            writer.write_all(b"< frame 123 1.000000 ").unwrap();
            std::thread::sleep(Duration::from_millis(150));
            writer.write_all(format!("{n:02X} >").as_bytes()).unwrap();
        }
        std::thread::sleep(Duration::from_millis(500));
    });
    let mut client = Client::connect(&address, "paused").unwrap();
    for n in 0..10u8 {
        let got = client.recv(Some(Duration::from_secs(5))).unwrap();
        assert_eq!(got.map(|r| r.frame), Some(frame(0x123, &[n])), "frame {n}");
    }
    server.join().unwrap();
}

#[test]
fn token_guesses_are_paced_and_each_costs_a_connection() {
    let _counting = counting();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let open_bus = Arc::new(|_: &str| -> Result<Box<dyn Bus>, BusError> {
        Ok(Box::new(VirtualBus::join("hostile-token")))
    });
    let config = Config {
        access: Access {
            names: Vec::new(),
            token: Some("correct-horse".into()),
        },
        limits: Limits::default(),
    };
    let server = Server::start(listener, config, open_bus).unwrap();
    let start = Instant::now();
    for guess in 0..12 {
        let mut client = Raw::connect(&server);
        assert_eq!(client.message(), "< hi >");
        client.send(&format!("< auth guess{guess} >"));
        assert_eq!(client.message(), "< error wrong token >");
        // Then the server closes: another guess needs another connection.
        client.send("< auth correct-horse >");
        assert_eq!(client.message(), "");
    }
    // Twelve attempts, one per 100 ms over the whole server.
    assert!(
        start.elapsed() >= Duration::from_millis(1100),
        "12 guesses in {:?}",
        start.elapsed()
    );
    assert_eq!(server.stats().auth_failures.load(Ordering::Relaxed), 12);
    let mut client = Raw::connect(&server);
    assert_eq!(client.message(), "< hi >");
    client.send("< auth correct-horse >");
    assert_eq!(client.message(), "< ok >");
    client.send("< open anything >");
    assert_eq!(client.message(), "< ok >");
}

#[test]
fn stopping_the_server_closes_its_sessions() {
    let _counting = counting();
    let baseline = (threads(), descriptors());
    let mut server = server("hostile-stop", Limits::default(), 64);
    let mut clients: Vec<Raw> = (0..5)
        .map(|_| Raw::opened(&server, "hostile-stop"))
        .collect();
    server.stop().unwrap();
    for client in &mut clients {
        assert_eq!(client.message(), "", "the session closed");
    }
    drop(clients);
    drop(server);
    let settled = settle(baseline, 0);
    assert!(
        settled.0 <= baseline.0 && settled.1 <= baseline.1,
        "{settled:?} from {baseline:?}"
    );
}
