//! The server's rules against raw HTTP and WebSocket clients: what it serves, whom it
//! refuses (another origin, no token, too many clients, a client that may not send), and that
//! a client which stops reading loses messages without stalling the bus or another client.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use bywire_bus::open;
use bywire_web::{Access, HubBuilder, WebServer};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

struct Running {
    server: Option<WebServer>,
    address: SocketAddr,
    stop: Arc<AtomicBool>,
    reader: Option<std::thread::JoinHandle<()>>,
}

impl Running {
    fn new(bus: &str, access: Access) -> Running {
        let endpoint = open(&format!("virtual:{bus}")).unwrap();
        let (tx, rx) = endpoint.split();
        let hub = HubBuilder::new("test")
            .bus(bus, Some(tx), Some(500_000), None)
            .build()
            .unwrap();
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let logs = Arc::new(bywire_web::Logs::new(Vec::new(), None, true));
        let server = WebServer::start(Arc::clone(&hub), logs, listener, access).unwrap();
        let address = server.address();
        let stop = Arc::new(AtomicBool::new(false));
        let (reading, flag) = (Arc::clone(&hub), Arc::clone(&stop));
        let reader = std::thread::spawn(move || reading.read_bus(0, rx, &flag));
        Running {
            server: Some(server),
            address,
            stop,
            reader: Some(reader),
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(server) = self.server.take() {
            server.stop();
        }
        if let Some(reader) = self.reader.take() {
            reader.join().unwrap();
        }
    }
}

/// A raw HTTP exchange: the status line and the body.
fn http(address: SocketAddr, request: &str) -> (String, String) {
    let mut stream = TcpStream::connect(address).unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap_or((&answer, ""));
    (
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    )
}

fn get(address: SocketAddr, path: &str) -> (String, String) {
    http(
        address,
        &format!("GET {path} HTTP/1.1\r\nHost: {address}\r\n\r\n"),
    )
}

type Socket = WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

/// A Foxglove WebSocket client, with extra request headers.
fn connect(
    address: SocketAddr,
    query: &str,
    headers: &[(&'static str, &str)],
) -> Result<Socket, String> {
    let mut request = format!("ws://{address}/{query}")
        .into_client_request()
        .unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    for (name, value) in headers {
        request.headers_mut().insert(*name, value.parse().unwrap());
    }
    tungstenite::connect(request)
        .map(|(socket, _)| socket)
        .map_err(|e| e.to_string())
}

fn text(socket: &mut Socket) -> serde_json::Value {
    loop {
        match socket.read().unwrap() {
            Message::Text(text) => return serde_json::from_str(text.as_str()).unwrap(),
            Message::Binary(_) | Message::Ping(_) | Message::Pong(_) => {}
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn the_page_its_database_and_bad_requests() {
    let server = Running::new("web-http", Access::default());
    let (status, body) = get(server.address, "/");
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(body.contains("<title>bywire</title>"));
    let (status, body) = get(server.address, "/vendor/uPlot.iife.min.js");
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(body.starts_with("/*! https://github.com/leeoniya/uPlot"));
    let (status, body) = get(server.address, "/api/database");
    assert_eq!(status, "HTTP/1.1 200 OK");
    let database: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(database["buses"][0]["name"], "web-http");
    assert_eq!(get(server.address, "/nothing").0, "HTTP/1.1 404 Not Found");
    assert_eq!(
        http(server.address, "POST / HTTP/1.1\r\nHost: x\r\n\r\n").0,
        "HTTP/1.1 405 Method Not Allowed"
    );
    assert_eq!(
        http(server.address, "\x00\x01garbage\r\n\r\n").0,
        "HTTP/1.1 400 Bad Request"
    );
    // A head without end, longer than the limit: refused, not read for ever.
    let mut stream = TcpStream::connect(server.address).unwrap();
    let long = format!("GET /{} HTTP/1.1\r\n", "a".repeat(40_000));
    let _ = stream.write_all(long.as_bytes());
    let mut answer = String::new();
    let _ = stream.read_to_string(&mut answer);
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer:.40}");
    // A WebSocket client of another protocol.
    let (status, _) = http(
        server.address,
        "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
    );
    assert_eq!(status, "HTTP/1.1 400 Bad Request");
}

#[test]
fn pages_of_other_origins_are_refused_and_tokens_are_checked() {
    let open_server = Running::new("web-origin", Access::default());
    let address = open_server.address;
    let refused = connect(address, "", &[("Origin", "http://evil.example")]).unwrap_err();
    assert!(refused.contains("403"), "{refused}");
    let same = format!("http://{address}");
    let mut socket = connect(address, "", &[("Origin", &same)]).unwrap();
    assert_eq!(text(&mut socket)["op"], "serverInfo");
    assert_eq!(
        http(
            address,
            &format!("GET /api/database HTTP/1.1\r\nHost: {address}\r\nOrigin: http://evil.example\r\n\r\n")
        )
        .0,
        "HTTP/1.1 403 Forbidden"
    );
    // Allowed by name.
    let allowed = Running::new(
        "web-origin-allowed",
        Access {
            origins: vec!["https://app.foxglove.dev".into()],
            ..Access::default()
        },
    );
    assert!(connect(
        allowed.address,
        "",
        &[("Origin", "https://app.foxglove.dev")]
    )
    .is_ok());

    let guarded = Running::new(
        "web-token",
        Access {
            token: Some("s3cret-token".into()),
            ..Access::default()
        },
    );
    let address = guarded.address;
    assert_eq!(get(address, "/").0, "HTTP/1.1 401 Unauthorized");
    assert_eq!(
        get(address, "/?token=wrong-token!").0,
        "HTTP/1.1 401 Unauthorized"
    );
    assert_eq!(get(address, "/?token=s3cret-token").0, "HTTP/1.1 200 OK");
    assert!(connect(address, "", &[]).unwrap_err().contains("401"));
    assert!(connect(address, "?token=s3cret-token", &[]).is_ok());
    assert!(connect(address, "", &[("Authorization", "Bearer s3cret-token")]).is_ok());
    // Another origin that has the token is let in (a page of this host's user).
    assert!(connect(
        address,
        "?token=s3cret-token",
        &[("Origin", "http://other.example")]
    )
    .is_ok());
}

#[test]
fn a_client_may_send_only_when_the_server_allows_it() {
    let server = Running::new("web-nosend", Access::default());
    let mut socket = connect(server.address, "", &[]).unwrap();
    let info = text(&mut socket);
    assert_eq!(info["capabilities"], serde_json::json!([]));
    socket
        .send(Message::text(
            r#"{"op":"advertise","channels":[{"id":1,"topic":"/web-nosend/frames","encoding":"json","schemaName":"x"}]}"#,
        ))
        .unwrap();
    let status = loop {
        let message = text(&mut socket);
        if message["op"] == "status" {
            break message;
        }
    };
    assert_eq!(status["level"], 2);
    assert!(status["message"].as_str().unwrap().contains("--allow-send"));
}

#[test]
fn more_clients_than_the_limit_are_told_to_come_back() {
    let server = Running::new("web-limit", Access::default());
    let mut sockets: Vec<Socket> = (0..bywire_web::hub::MAX_CLIENTS)
        .map(|_| connect(server.address, "", &[]).unwrap())
        .collect();
    for socket in &mut sockets {
        assert_eq!(text(socket)["op"], "serverInfo");
    }
    let mut extra = connect(server.address, "", &[]).unwrap();
    match extra.read() {
        Ok(Message::Close(Some(frame))) => assert_eq!(u16::from(frame.code), 1013),
        other => panic!("{other:?}"),
    }
}

/// A client that never reads: its queue is bounded, what does not fit is counted, and it is
/// told how much it lost once it reads again.
#[test]
fn a_full_queue_drops_and_counts() {
    let hub = HubBuilder::new("test")
        .bus("queue", None, None, None)
        .build()
        .unwrap();
    let session = hub.connect(false).unwrap();
    hub.handle(
        session.id,
        bywire_web::foxglove::ClientMessage::Subscribe(vec![bywire_web::foxglove::Subscription {
            id: 1,
            channel_id: 1,
        }]),
    );
    let frame = bywire_bus::Received {
        frame: "123#01".parse().unwrap(),
        timestamp: bywire_core::Timestamp::from_nanos(1),
        own: false,
        local: false,
        hardware: None,
    };
    let mut scratch = Vec::new();
    for _ in 0..10_000 {
        hub.on_frame(0, &frame, &mut scratch);
    }
    let queued = bywire_web::hub::CLIENT_QUEUE;
    // (Two messages were queued first: the server's information and its channels.)
    assert_eq!(hub.dropped(), 10_000 - (queued as u64 - 2));
    let drained = session.queue.try_iter().count();
    assert_eq!(drained, queued);
    hub.tick(bywire_core::Timestamp::from_nanos(2), 1.0, &mut Vec::new());
    let told: Vec<_> = session.queue.try_iter().collect();
    assert!(
        told.iter().any(
            |m| matches!(m, bywire_web::Outgoing::Text(t) if t.contains("1810 messages dropped"))
        ),
        "{told:?}"
    );
}

/// While a client that never reads is connected, the bus is read at its pace and a client
/// that reads gets every frame.
#[test]
fn a_client_that_stops_reading_stalls_nobody() {
    let server = Running::new("web-slow", Access::default());
    let subscribe = |socket: &mut Socket| {
        text(socket); // serverInfo
        let channels = text(socket);
        let frames = channels["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == "/web-slow/frames")
            .unwrap()["id"]
            .clone();
        socket
            .send(Message::text(
                serde_json::json!({"op": "subscribe", "subscriptions": [{"id": 9, "channelId": frames}]})
                    .to_string(),
            ))
            .unwrap();
    };
    let mut slow = connect(server.address, "", &[]).unwrap();
    subscribe(&mut slow);
    let mut fast = connect(server.address, "", &[]).unwrap();
    subscribe(&mut fast);
    let start = Instant::now();
    let mut sender = open("virtual:web-slow").unwrap();
    let mut fast_got = 0u64;
    if let tungstenite::stream::MaybeTlsStream::Plain(stream) = fast.get_mut() {
        stream
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
    }
    let total = 20_000u32;
    let mut sent = 0u32;
    let mut quiet_since = Instant::now();
    // Send in bursts while the fast client reads, then read until a second passes without a
    // message; bounded by `total` and a minute.
    while (sent < total || quiet_since.elapsed() < Duration::from_secs(1))
        && start.elapsed() < Duration::from_secs(60)
    {
        for _ in 0..200 {
            if sent < total {
                sender
                    .send(
                        &bywire_core::Frame::classic(
                            bywire_core::Id::standard(0x100).unwrap(),
                            &sent.to_le_bytes(),
                        )
                        .unwrap(),
                    )
                    .unwrap();
                sent += 1;
            }
        }
        // Bounded by the read timeout.
        while let Ok(message) = fast.read() {
            if let Message::Binary(_) = message {
                fast_got += 1;
                quiet_since = Instant::now();
            }
        }
    }
    assert_eq!(sent, total);
    // The fast client may lose the few frames sent before its subscription took effect.
    assert!(fast_got + 1_000 >= u64::from(total), "{fast_got}");
    drop(slow);
}

#[test]
fn uploads_need_the_pages_header_a_length_and_the_whole_body() {
    let server = Running::new("web-upload", Access::default());
    let address = server.address;
    let log = "(1700000000.000000) can0 123#01\n";
    let post = |headers: &str, body: &str| {
        http(
            address,
            &format!(
                "POST /api/logs/upload?name=..%2Fevil.log HTTP/1.1\r\nHost: {address}\r\n{headers}\r\n{body}"
            ),
        )
    };
    assert_eq!(
        post(&format!("Content-Length: {}\r\n", log.len()), log).0,
        "HTTP/1.1 403 Forbidden"
    );
    assert_eq!(
        post("X-Bywire: 1\r\n", log).0,
        "HTTP/1.1 411 Length Required"
    );
    // Cut short: the connection closes before the length given.
    let mut stream = TcpStream::connect(address).unwrap();
    stream
        .write_all(
            format!(
                "POST /api/logs/upload?name=a.log HTTP/1.1\r\nHost: {address}\r\nX-Bywire: 1\r\nContent-Length: 1000\r\n\r\n{log}"
            )
            .as_bytes(),
        )
        .unwrap();
    stream.shutdown(std::net::Shutdown::Write).unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer}");
    let list = |address| {
        http(
            address,
            &format!("GET /api/logs HTTP/1.1\r\nHost: {address}\r\nX-Bywire: 1\r\n\r\n"),
        )
        .1
    };
    assert_eq!(
        serde_json::from_str::<serde_json::Value>(&list(address)).unwrap()["logs"],
        serde_json::json!([])
    );
    let (status, body) = post(
        &format!("X-Bywire: 1\r\nContent-Length: {}\r\n", log.len()),
        log,
    );
    assert_eq!(status, "HTTP/1.1 200 OK", "{body}");
    let listed: serde_json::Value = serde_json::from_str(&list(address)).unwrap();
    assert_eq!(listed["logs"][0]["name"], "../evil.log");
    assert_eq!(listed["logs"][0]["bytes"], log.len());
    let (status, summary) = http(
        address,
        &format!("GET /api/logs/summary?log=0 HTTP/1.1\r\nHost: {address}\r\nX-Bywire: 1\r\n\r\n"),
    );
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(summary.contains("\"frames\":1"), "{summary}");
}
