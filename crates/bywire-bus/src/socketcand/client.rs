//! `socketcand:HOST:PORT/BUS`: a client of a socketcand server in raw mode.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bywire_core::Frame;

use super::protocol::{self, MAX_MESSAGE};
use super::server::{is_timeout, lock};
use crate::{Bus, BusError, Received};

/// A client of a socketcand server in raw mode. A lost connection is re-established on the
/// next send or receive (up to five tries, pauses growing to a second).
pub struct Client {
    shared: Arc<ClientShared>,
}

/// The receiving side of a connection: the stream and the part of a message read so far
/// (kept across read timeouts, so a message whose bytes arrive across a pause is whole).
struct Incoming {
    reader: BufReader<TcpStream>,
    pending: Vec<u8>,
}

struct ClientShared {
    address: String,
    bus: String,
    incoming: Mutex<Option<Incoming>>,
    writer: Mutex<Option<TcpStream>>,
    filtering: Mutex<crate::Filtering>,
    stats: Mutex<crate::Stats>,
}

/// Read one message into `got` (bounded by [`MAX_MESSAGE`]); `Ok(true)` when it is whole.
fn read_message(reader: &mut BufReader<TcpStream>, got: &mut Vec<u8>) -> std::io::Result<bool> {
    let room = u64::try_from(MAX_MESSAGE.saturating_sub(got.len()).max(1)).unwrap_or(1);
    let read = Read::by_ref(reader).take(room).read_until(b'>', got)?;
    if read == 0 {
        return Err(std::io::ErrorKind::UnexpectedEof.into());
    }
    Ok(got.last() == Some(&b'>'))
}

fn expect(reader: &mut BufReader<TcpStream>, wanted: &str) -> std::io::Result<()> {
    let mut got = Vec::new();
    while !read_message(reader, &mut got)? {
        if got.len() >= MAX_MESSAGE {
            break;
        }
    }
    let text = String::from_utf8_lossy(&got);
    if protocol::inner_text(&text).map(str::trim) == Some(wanted) {
        Ok(())
    } else {
        Err(std::io::Error::other(format!(
            "expected '< {wanted} >', got '{}'",
            text.trim()
        )))
    }
}

fn connect(address: &str, bus: &str) -> std::io::Result<(Incoming, TcpStream)> {
    let stream = TcpStream::connect(address)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut writer = stream.try_clone()?;
    let mut reader = BufReader::new(stream);
    expect(&mut reader, "hi")?;
    writer.write_all(format!("< open {bus} >").as_bytes())?;
    expect(&mut reader, "ok")?;
    writer.write_all(b"< rawmode >")?;
    expect(&mut reader, "ok")?;
    let incoming = Incoming {
        reader,
        pending: Vec::new(),
    };
    Ok((incoming, writer))
}

impl Client {
    /// Connect to the server at `address` (HOST:PORT) and open `bus` in raw mode.
    pub fn connect(address: &str, bus: &str) -> std::io::Result<Client> {
        let (incoming, writer) = connect(address, bus)?;
        Ok(Client {
            shared: Arc::new(ClientShared {
                address: address.to_string(),
                bus: bus.to_string(),
                incoming: Mutex::new(Some(incoming)),
                writer: Mutex::new(Some(writer)),
                filtering: Mutex::new(crate::Filtering::default()),
                stats: Mutex::new(crate::Stats::default()),
            }),
        })
    }
}

impl ClientShared {
    /// Connect again after the connection was lost.
    fn reconnect(&self) -> Result<(), BusError> {
        let mut pause = Duration::from_millis(50);
        let mut last = None;
        for _ in 0..5 {
            match connect(&self.address, &self.bus) {
                Ok((incoming, writer)) => {
                    *lock(&self.incoming) = Some(incoming);
                    *lock(&self.writer) = Some(writer);
                    return Ok(());
                }
                Err(e) => {
                    last = Some(e);
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(Duration::from_secs(1));
                }
            }
        }
        Err(last.map_or(BusError::Closed, BusError::Io))
    }

    /// One whole message from the server within `slice`, or `None` (nothing whole yet).
    fn next_message(&self, slice: Duration) -> Result<Option<String>, BusError> {
        if lock(&self.incoming).is_none() {
            self.reconnect()?;
        }
        let mut incoming = lock(&self.incoming);
        let Some(connection) = incoming.as_mut() else {
            return Ok(None);
        };
        connection.reader.get_ref().set_read_timeout(Some(slice))?;
        match read_message(&mut connection.reader, &mut connection.pending) {
            Ok(true) => {
                let message = std::mem::take(&mut connection.pending);
                Ok(Some(String::from_utf8_lossy(&message).into_owned()))
            }
            Ok(false) => {
                if connection.pending.len() >= MAX_MESSAGE {
                    connection.pending.clear(); // not a message of this protocol
                    lock(&self.stats).rx_errors += 1;
                }
                Ok(None)
            }
            Err(e) if is_timeout(&e) => Ok(None),
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                *incoming = None; // the server closed: reconnect on the next pass
                Ok(None)
            }
            Err(e) => {
                *incoming = None;
                Err(e.into())
            }
        }
    }
}

impl crate::SharedEndpoint for ClientShared {
    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let line = protocol::format_send(frame).ok_or_else(|| {
            BusError::Unsupported("FD, remote or error frames over socketcand".into())
        })?;
        if lock(&self.writer).is_none() {
            self.reconnect()?;
        }
        let mut writer = lock(&self.writer);
        let stream = writer.as_mut().ok_or(BusError::Closed)?;
        if let Err(e) = stream.write_all(line.as_bytes()) {
            *writer = None;
            return Err(e.into());
        }
        drop(writer);
        lock(&self.stats).count_sent(frame);
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        // Each pass reads what arrives within a slice; bounded by the deadline.
        loop {
            let slice = deadline.map_or(Duration::from_millis(100), |d| {
                d.saturating_duration_since(Instant::now())
                    .min(Duration::from_millis(100))
            });
            if slice.is_zero() {
                return Ok(None);
            }
            let Some(message) = self.next_message(slice)? else {
                continue;
            };
            let parsed = protocol::inner_text(&message)
                .ok_or_else(|| "no '<'".to_string())
                .and_then(protocol::parse_frame);
            match parsed {
                Ok((frame, timestamp)) => {
                    if !lock(&self.filtering).accepts(&frame) {
                        continue;
                    }
                    lock(&self.stats).count_received(&frame);
                    return Ok(Some(Received {
                        frame,
                        timestamp,
                        own: false,
                        local: false,
                        hardware: None,
                    }));
                }
                Err(_) => {
                    lock(&self.stats).rx_errors += 1;
                }
            }
        }
    }

    fn stats(&self) -> crate::Stats {
        *lock(&self.stats)
    }
}

impl crate::BusTx for Client {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        crate::SharedEndpoint::send(self.shared.as_ref(), frame)
    }
}

impl crate::BusRx for Client {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        crate::SharedEndpoint::recv(self.shared.as_ref(), timeout)
    }

    fn stats(&self) -> crate::Stats {
        crate::SharedEndpoint::stats(self.shared.as_ref())
    }
}

impl Bus for Client {
    fn set_filtering(&mut self, filtering: crate::Filtering) -> Result<(), BusError> {
        *lock(&self.shared.filtering) = filtering;
        Ok(())
    }

    /// Raw mode has no transmit confirmation: own frames are never received.
    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        if on {
            Err(BusError::Unsupported(
                "receive-own (socketcand raw mode has no echo)".into(),
            ))
        } else {
            Ok(())
        }
    }

    fn set_loopback(&mut self, _on: bool) -> Result<(), BusError> {
        Ok(())
    }

    fn split(self: Box<Self>) -> (Box<dyn crate::BusTx>, Box<dyn crate::BusRx>) {
        crate::split_halves(self.shared)
    }
}
