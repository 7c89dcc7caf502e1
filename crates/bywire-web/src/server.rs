//! One port for the page, its database and the Foxglove WebSocket protocol: a thread per
//! connection (at most [`MAX_CONNECTIONS`]), the HTTP request head read here (bounded in size
//! and time), WebSocket framing by `tungstenite`.
//!
//! Who may connect: a server bound beyond loopback needs a token (the caller checks this at
//! start), given as `?token=` or `Authorization: Bearer`. A WebSocket or API request from a
//! page of another origin (a browser sends its `Origin`) is refused unless that origin is
//! allowed or the request carries the token: any web site a user visits could otherwise
//! watch, or drive, the bus through the user's browser.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use tungstenite::protocol::{Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

use crate::assets;
use crate::foxglove;
use crate::hub::{Hub, Outgoing};
use crate::logs::{self, Logs};
use bywire_log::format::Format;

/// Connections at once (pages, their requests, WebSocket clients).
pub const MAX_CONNECTIONS: usize = 64;
/// The largest request head read.
const MAX_HEAD: usize = 16 * 1024;
/// The largest WebSocket message a client may send.
const MAX_CLIENT_MESSAGE: usize = 1 << 20;
/// What may wait unsent to one client before it counts as slow.
const MAX_WRITE_BUFFER: usize = 1 << 20;

/// Who may connect and what they may do.
#[derive(Debug, Clone, Default)]
pub struct Access {
    /// The token a request must carry (`None`: none needed, for loopback).
    pub token: Option<String>,
    /// Origins whose pages may connect without the token (`https://app.foxglove.dev`).
    pub origins: Vec<String>,
    /// Whether clients may send frames (the hub's buses must also take them).
    pub allow_send: bool,
}

/// A running server.
pub struct WebServer {
    address: SocketAddr,
    stop: Arc<AtomicBool>,
    acceptor: Option<JoinHandle<()>>,
}

impl WebServer {
    /// Serve `hub` and `logs` on `listener` until [`WebServer::stop`].
    pub fn start(
        hub: Arc<Hub>,
        logs: Arc<Logs>,
        listener: TcpListener,
        access: Access,
    ) -> io::Result<Self> {
        let address = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let access = Arc::new(access);
        let acceptor = std::thread::Builder::new()
            .name("web-accept".into())
            .spawn(move || accept(&listener, &hub, &logs, &access, &flag))?;
        Ok(WebServer {
            address,
            stop,
            acceptor: Some(acceptor),
        })
    }

    /// Where it listens.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Stop accepting and end every connection (each notices within a tenth of a second).
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(acceptor) = self.acceptor.take() {
            let _ = acceptor.join();
        }
    }
}

impl Drop for WebServer {
    /// A server dropped without [`WebServer::stop`] still stops (without waiting).
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn accept(
    listener: &TcpListener,
    hub: &Arc<Hub>,
    logs: &Arc<Logs>,
    access: &Arc<Access>,
    stop: &Arc<AtomicBool>,
) {
    let active = Arc::new(AtomicUsize::new(0));
    let mut threads: Vec<JoinHandle<()>> = Vec::new();
    // Bounded by `stop`.
    while !stop.load(Ordering::Relaxed) {
        threads.retain(|t| !t.is_finished());
        let stream = match listener.accept() {
            Ok((stream, _)) => stream,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            Err(_) => {
                // Out of descriptors and the like: wait and go on.
                std::thread::sleep(Duration::from_millis(100));
                continue;
            }
        };
        if active.load(Ordering::Relaxed) >= MAX_CONNECTIONS {
            drop(stream);
            continue;
        }
        active.fetch_add(1, Ordering::Relaxed);
        let (hub, logs, access, stop, counted) = (
            Arc::clone(hub),
            Arc::clone(logs),
            Arc::clone(access),
            Arc::clone(stop),
            Arc::clone(&active),
        );
        let spawned = std::thread::Builder::new()
            .name("web-client".into())
            .spawn(move || {
                let _ = connection(stream, &hub, &logs, &access, &stop);
                counted.fetch_sub(1, Ordering::Relaxed);
            });
        match spawned {
            Ok(thread) => threads.push(thread),
            Err(_) => {
                active.fetch_sub(1, Ordering::Relaxed);
            }
        }
    }
    for thread in threads {
        let _ = thread.join();
    }
}

/// A request's head, as far as this server needs it.
struct Request {
    method: String,
    path: String,
    query: String,
    headers: Vec<(String, String)>,
}

impl Request {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    fn query_value(&self, key: &str) -> Option<&str> {
        self.query
            .split('&')
            .filter_map(|pair| pair.split_once('='))
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v)
    }

    fn token(&self) -> Option<&str> {
        self.query_value("token").or_else(|| {
            self.header("authorization")
                .and_then(|v| v.strip_prefix("Bearer "))
        })
    }
}

/// The request head from `stream` (bounded in size; the socket's timeout bounds the time),
/// and the bytes of the body read with it.
fn read_head(stream: &mut TcpStream) -> io::Result<(Request, Vec<u8>)> {
    let mut head = Vec::with_capacity(1024);
    let mut buffer = [0u8; 1024];
    // Bounded by MAX_HEAD.
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        if head.len() > MAX_HEAD {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "head too long"));
        }
        let n = stream.read(&mut buffer)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        head.extend_from_slice(buffer.get(..n).unwrap_or_default());
    }
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut request = httparse::Request::new(&mut headers);
    request
        .parse(&head)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()))?;
    let target = request.path.unwrap_or("/");
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let body_start = head
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map_or(head.len(), |at| at + 4);
    let body = head.get(body_start..).unwrap_or_default().to_vec();
    let request = Request {
        method: request.method.unwrap_or("").to_string(),
        path: path.to_string(),
        query: query.to_string(),
        headers: request
            .headers
            .iter()
            .map(|h| {
                (
                    h.name.to_string(),
                    String::from_utf8_lossy(h.value).into_owned(),
                )
            })
            .collect(),
    };
    Ok((request, body))
}

fn respond(stream: &mut TcpStream, status: &str, kind: &str, body: &[u8]) -> io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n\
         Content-Security-Policy: default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:\r\n\
         Connection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

/// Constant time in the token's length: a wrong guess says nothing of how much was right.
fn same_token(given: &str, wanted: &str) -> bool {
    given.len() == wanted.len()
        && given
            .bytes()
            .zip(wanted.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

fn connection(
    mut stream: TcpStream,
    hub: &Arc<Hub>,
    logs: &Logs,
    access: &Access,
    stop: &AtomicBool,
) -> io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    stream.set_write_timeout(Some(Duration::from_secs(5)))?;
    let (request, body_start) = match read_head(&mut stream) {
        Ok(read) => read,
        Err(_) => {
            return respond(
                &mut stream,
                "400 Bad Request",
                "text/plain",
                b"bad request\n",
            )
        }
    };
    let token_ok = match (&access.token, request.token()) {
        (None, _) => true,
        (Some(wanted), Some(given)) => same_token(given, wanted),
        (Some(_), None) => false,
    };
    if access.token.is_some() && !token_ok {
        // Paced, so guessing takes long.
        std::thread::sleep(Duration::from_millis(100));
        return respond(
            &mut stream,
            "401 Unauthorized",
            "text/plain",
            b"a token is needed: open the page as /?token=TOKEN\n",
        );
    }
    let same_origin = match request.header("origin") {
        None => true,
        Some(origin) => {
            let host = request.header("host").unwrap_or("");
            origin
                .strip_prefix("http://")
                .or_else(|| origin.strip_prefix("https://"))
                == Some(host)
                || access.origins.iter().any(|o| o == origin)
                || (access.token.is_some() && token_ok)
        }
    };
    let upload = request.path == "/api/logs/upload";
    if request.method != "GET" && !(upload && request.method == "POST") {
        return respond(
            &mut stream,
            "405 Method Not Allowed",
            "text/plain",
            b"GET only\n",
        );
    }
    let upgrade = request
        .header("upgrade")
        .is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    if (upgrade || request.path.starts_with("/api/")) && !same_origin {
        return respond(
            &mut stream,
            "403 Forbidden",
            "text/plain",
            b"a page of another origin (allow it with --allow-origin, or give the token)\n",
        );
    }
    if upgrade {
        return websocket(stream, &request, hub, access, stop);
    }
    if let Some(what) = request.path.strip_prefix("/api/logs") {
        // A request a page of another site could make without asking (a link, an image)
        // carries no such header: only the page's own requests read logs.
        if request.header("x-bywire").is_none() {
            return respond(
                &mut stream,
                "403 Forbidden",
                "text/plain",
                b"the page's requests carry X-Bywire\n",
            );
        }
        if upload {
            return upload_log(stream, logs, &request, body_start);
        }
        return match log_request(logs, what, &request) {
            Ok(Answer::Json(body)) => respond(
                &mut stream,
                "200 OK",
                "application/json",
                body.to_string().as_bytes(),
            ),
            Ok(Answer::File(file, name)) => send_file(&mut stream, file, &name),
            Err(problem) => respond(
                &mut stream,
                "400 Bad Request",
                "text/plain",
                format!("{problem}\n").as_bytes(),
            ),
        };
    }
    match request.path.as_str() {
        "/api/database" => {
            let body = assets::database_json(hub, logs).to_string();
            respond(&mut stream, "200 OK", "application/json", body.as_bytes())
        }
        path => match assets::asset(path) {
            Some((kind, body)) => respond(&mut stream, "200 OK", kind, body),
            None => respond(&mut stream, "404 Not Found", "text/plain", b"not found\n"),
        },
    }
}

/// What a log request is answered with.
enum Answer {
    Json(serde_json::Value),
    File(tempfile::NamedTempFile, String),
}

/// `/api/logs[/summary|/frames|/series|/export]?log=N&...`.
fn log_request(logs: &Logs, what: &str, request: &Request) -> Result<Answer, String> {
    let text = |key: &str| -> Result<String, String> {
        request
            .query_value(key)
            .map(percent_decoded)
            .ok_or_else(|| format!("'{key}' is missing"))
    };
    let number = |key: &str| -> Result<usize, String> {
        text(key)?
            .parse()
            .map_err(|_| format!("'{key}' is not a number"))
    };
    // A time: exact as `KEY_ns` (nanoseconds), or `KEY` in seconds.
    let time = |key: &str| -> Result<u64, String> {
        let exact = format!("{key}_ns");
        match request.query_value(&exact) {
            Some(ns) => ns
                .parse()
                .map_err(|_| format!("'{exact}' is not a number of nanoseconds")),
            None => {
                logs::seconds_to_nanos(&text(key)?).ok_or_else(|| format!("'{key}' is not a time"))
            }
        }
    };
    match what {
        "" => Ok(Answer::Json(logs.list())),
        "/summary" => logs.summary_json(number("log")?).map(Answer::Json),
        "/frames" => logs
            .frames(number("log")?, time("from")?, number("count")?)
            .map(Answer::Json),
        "/series" => logs
            .series(
                number("log")?,
                &text("bus")?,
                &text("message")?,
                &text("signal")?,
                time("from")?,
                time("to")?,
                number("points")?,
            )
            .map(Answer::Json),
        "/export" => {
            let name = text("format")?;
            let format = Format::named(&name).ok_or_else(|| {
                let names: Vec<&str> = Format::ALL.iter().map(|(_, n)| *n).collect();
                format!("format '{name}': one of {}", names.join(", "))
            })?;
            let log = number("log")?;
            let (file, _) = logs.export(log, time("from")?, time("to")?, format)?;
            Ok(Answer::File(file, format!("log{log}.{name}")))
        }
        other => Err(format!("no such request: /api/logs{other}")),
    }
}

/// `POST /api/logs/upload?name=NAME` with the log as its body (its length given).
fn upload_log(
    mut stream: TcpStream,
    logs: &Logs,
    request: &Request,
    body_start: Vec<u8>,
) -> io::Result<()> {
    let Some(length) = request
        .header("content-length")
        .and_then(|l| l.trim().parse::<u64>().ok())
    else {
        return respond(
            &mut stream,
            "411 Length Required",
            "text/plain",
            b"an upload gives its length\n",
        );
    };
    let name = request
        .query_value("name")
        .map_or_else(|| "upload".to_string(), percent_decoded);
    // A slow sender gets a minute between reads, not five seconds.
    stream.set_read_timeout(Some(Duration::from_secs(60)))?;
    let mut body = io::Cursor::new(body_start).chain(&mut stream);
    match logs.upload(&name, length, &mut body) {
        Ok(id) => respond(
            &mut stream,
            "200 OK",
            "application/json",
            serde_json::json!({"id": id}).to_string().as_bytes(),
        ),
        Err(problem) => respond(
            &mut stream,
            "400 Bad Request",
            "text/plain",
            format!("{problem}\n").as_bytes(),
        ),
    }
}

/// `%XX` escapes and `+` as a browser's query string has them.
fn percent_decoded(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    // Bounded by the text's length.
    while let Some(&byte) = bytes.get(i) {
        let escaped = (byte == b'%')
            .then(|| bytes.get(i + 1..i + 3))
            .flatten()
            .and_then(|hex| std::str::from_utf8(hex).ok())
            .and_then(|hex| u8::from_str_radix(hex, 16).ok());
        match (escaped, byte) {
            (Some(value), _) => {
                out.push(value);
                i += 3;
            }
            (None, b'+') => {
                out.push(b' ');
                i += 1;
            }
            (None, other) => {
                out.push(other);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A file as a download.
fn send_file(stream: &mut TcpStream, file: tempfile::NamedTempFile, name: &str) -> io::Result<()> {
    let mut input = file.reopen()?;
    let length = input.metadata()?.len();
    let head = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: application/octet-stream\r\nContent-Length: {length}\r\n\
         Content-Disposition: attachment; filename=\"{name}\"\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n"
    );
    stream.set_write_timeout(Some(Duration::from_secs(60)))?;
    stream.write_all(head.as_bytes())?;
    io::copy(&mut input, stream)?;
    stream.flush()
}

/// The WebSocket handshake (RFC 6455 §4.2.2, the Foxglove subprotocol), then the session.
fn websocket(
    mut stream: TcpStream,
    request: &Request,
    hub: &Arc<Hub>,
    access: &Access,
    stop: &AtomicBool,
) -> io::Result<()> {
    let offered = request
        .header("sec-websocket-protocol")
        .is_some_and(|p| p.split(',').any(|p| p.trim() == foxglove::SUBPROTOCOL));
    let key = request.header("sec-websocket-key");
    let (true, Some(key), Some("13")) = (offered, key, request.header("sec-websocket-version"))
    else {
        return respond(
            &mut stream,
            "400 Bad Request",
            "text/plain",
            b"a WebSocket client of the foxglove.websocket.v1 protocol (version 13)\n",
        );
    };
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let head = format!(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Accept: {accept}\r\nSec-WebSocket-Protocol: {}\r\n\r\n",
        foxglove::SUBPROTOCOL
    );
    stream.write_all(head.as_bytes())?;
    stream.set_nonblocking(true)?;
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_MESSAGE))
        .max_frame_size(Some(MAX_CLIENT_MESSAGE))
        .max_write_buffer_size(MAX_WRITE_BUFFER);
    let mut socket = WebSocket::from_raw_socket(stream, Role::Server, Some(config));
    let Some(session) = hub.connect(access.allow_send) else {
        let _ = socket.close(Some(tungstenite::protocol::CloseFrame {
            code: tungstenite::protocol::frame::coding::CloseCode::Again,
            reason: "too many clients".into(),
        }));
        let _ = socket.flush();
        return Ok(());
    };
    let result = session_loop(&mut socket, hub, session.id, &session.queue, stop);
    hub.disconnect(session.id);
    let _ = socket.close(None);
    let _ = socket.flush();
    result
}

fn would_block(e: &tungstenite::Error) -> bool {
    matches!(e, tungstenite::Error::Io(io) if io.kind() == io::ErrorKind::WouldBlock)
}

fn session_loop(
    socket: &mut WebSocket<TcpStream>,
    hub: &Hub,
    id: u64,
    queue: &std::sync::mpsc::Receiver<Outgoing>,
    stop: &AtomicBool,
) -> io::Result<()> {
    let closed = |e: tungstenite::Error| io::Error::other(e.to_string());
    // Bounded by `stop` and the client's life.
    while !stop.load(Ordering::Relaxed) {
        // What the client says.
        loop {
            match socket.read() {
                Ok(Message::Text(text)) => match foxglove::parse_text(text.as_str()) {
                    Ok(message) => hub.handle(id, message),
                    Err(e) => hub.handle(
                        id,
                        foxglove::ClientMessage::Unsupported(format!("message ({e})")),
                    ),
                },
                Ok(Message::Binary(data)) => match foxglove::parse_binary(&data) {
                    Ok(message) => hub.handle(id, message),
                    Err(e) => hub.handle(
                        id,
                        foxglove::ClientMessage::Unsupported(format!("message ({e})")),
                    ),
                },
                Ok(Message::Close(_)) => return Ok(()),
                Ok(_) => {}
                Err(e) if would_block(&e) => break,
                Err(e) => return Err(closed(e)),
            }
        }
        // What the client is sent: a batch at a time, then wait a little for more.
        let mut sent = 0;
        let first = queue.recv_timeout(Duration::from_millis(10));
        let mut next = match first {
            Ok(message) => Some(message),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        };
        // Bounded: a batch of 4096.
        while let Some(message) = next.take() {
            let message = match message {
                Outgoing::Text(text) => Message::text(text),
                Outgoing::Binary(data) => Message::binary(data),
            };
            match socket.write(message) {
                Ok(()) => {}
                Err(tungstenite::Error::WriteBufferFull(_)) => break,
                Err(e) if would_block(&e) => break,
                Err(e) => return Err(closed(e)),
            }
            sent += 1;
            if sent < 4096 {
                next = queue.try_recv().ok();
            }
        }
        match socket.flush() {
            Ok(()) => {}
            Err(e) if would_block(&e) => {}
            Err(e) => return Err(closed(e)),
        }
    }
    Ok(())
}
