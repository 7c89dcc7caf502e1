//! `slcan:PORT@BITRATE`: adapters speaking the Lawicel ASCII protocol over a serial port
//! (CANable, CANtact, USBtin and many more), with the CANable FD extension.
//!
//! Commands end in `\r`; the adapter answers `\r` (done) or BEL (refused). `Sn` sets a standard
//! bitrate, `O` opens, `L` opens listen-only, `C` closes, `V`/`N` ask for versions. Frames both
//! ways: `tIIILDD..` (standard), `TIIIIIIIILDD..` (extended), `rIIIL`/`RIIIIIIIIL` (remote),
//! and for CAN FD `dIIIL..`/`DIIIIIIIIL..` (no BRS) and `bIIIL..`/`BIIIIIIIIL..` (BRS), where L
//! is the DLC in hex; received frames may end in a 4-digit millisecond timestamp. `z`/`Z`
//! acknowledge transmissions. Lines that are none of these are counted as receive errors.
//!
//! The adapter's millisecond timestamps, when it sends them, are kept as the hardware
//! timestamp. What the protocol cannot do: error frames, receive-own (no echo of our frames), hardware
//! filters (filtering is done here).

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use bywire_core::{ClassicFrame, Dlc, FdFrame, Frame, Id, Timestamp};

use crate::{Bus, BusError, BusRx, BusTx, Filtering, Received, SharedEndpoint, Stats};

/// The `Sn` code of each standard bitrate.
const BITRATES: [(u32, char); 9] = [
    (10_000, '0'),
    (20_000, '1'),
    (50_000, '2'),
    (100_000, '3'),
    (125_000, '4'),
    (250_000, '5'),
    (500_000, '6'),
    (750_000, '7'),
    (1_000_000, '8'),
];

/// The longest line a frame can take (`B` + 8 + 1 + 128 + 4), with room to spare.
const MAX_LINE: usize = 160;

/// Why a line is not a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("SLCAN line '{line}': {reason}")]
pub struct LineError {
    /// The line (without `\r`).
    pub line: String,
    /// What is wrong.
    pub reason: String,
}

fn hex_value(text: &str) -> Option<u32> {
    (!text.is_empty() && text.bytes().all(|b| b.is_ascii_hexdigit()))
        .then(|| u32::from_str_radix(text, 16).ok())
        .flatten()
}

/// The frame an adapter reports in `line` (without `\r`); `Ok(None)` for acknowledgements.
pub fn parse_line(line: &str) -> Result<Option<Frame>, LineError> {
    let error = |reason: &str| LineError {
        line: line.chars().take(MAX_LINE).collect(),
        reason: reason.to_string(),
    };
    let Some(kind) = line.chars().next() else {
        return Ok(None); // a bare `\r`: an acknowledgement
    };
    if matches!(kind, 'z' | 'Z') && line.len() == 1 {
        return Ok(None);
    }
    let (id_digits, remote, fd, brs) = match kind {
        't' => (3, false, false, false),
        'T' => (8, false, false, false),
        'r' => (3, true, false, false),
        'R' => (8, true, false, false),
        'd' => (3, false, true, false),
        'D' => (8, false, true, false),
        'b' => (3, false, true, true),
        'B' => (8, false, true, true),
        _ => return Err(error("not a frame (t, T, r, R, d, D, b or B)")),
    };
    let raw_id = line
        .get(1..1 + id_digits)
        .and_then(hex_value)
        .ok_or_else(|| error("bad identifier"))?;
    let id = if id_digits == 3 {
        Id::standard(raw_id)
    } else {
        Id::extended(raw_id)
    }
    .map_err(|e| error(&e.to_string()))?;
    let dlc_value = line
        .get(1 + id_digits..2 + id_digits)
        .and_then(hex_value)
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(|| error("bad DLC"))?;
    let dlc = Dlc::new(dlc_value).ok_or_else(|| error("bad DLC"))?;
    let rest = line.get(2 + id_digits..).unwrap_or("");
    if remote {
        // An optional 4-digit timestamp may follow.
        if !(rest.is_empty() || (rest.len() == 4 && hex_value(rest).is_some())) || dlc_value > 8 {
            return Err(error("bad remote frame"));
        }
        return Ok(Some(Frame::Classic(ClassicFrame::remote(id, dlc))));
    }
    let len = if fd {
        dlc.fd_len()
    } else {
        usize::from(dlc_value.min(8))
    };
    let data_text = match rest.len() {
        n if n == 2 * len => rest,
        n if n == 2 * len + 4 => rest.get(..2 * len).unwrap_or(""),
        _ => return Err(error("data length does not match the DLC")),
    };
    let mut data = [0u8; 64];
    for (i, slot) in data.iter_mut().enumerate().take(len) {
        let byte = data_text
            .get(2 * i..2 * i + 2)
            .and_then(hex_value)
            .and_then(|v| u8::try_from(v).ok())
            .ok_or_else(|| error("bad data"))?;
        *slot = byte;
    }
    let payload = data.get(..len).unwrap_or(&[]);
    let frame = if fd {
        FdFrame::new(id, payload, brs, false).map(Frame::Fd)
    } else {
        ClassicFrame::new(id, payload).map(Frame::Classic)
    };
    frame.map(Some).map_err(|e| error(&e.to_string()))
}

/// The adapter's timestamp on a received line (milliseconds, wrapping at 60,000), when the
/// adapter has timestamps on (`Z1`).
pub fn adapter_millis(line: &str, frame: &Frame) -> Option<u64> {
    let id_digits = if frame.id()?.is_extended() { 8 } else { 3 };
    let data_digits = if frame.is_remote() {
        0
    } else {
        2 * frame.data().len()
    };
    let stamp = line.get(2 + id_digits + data_digits..)?;
    (stamp.len() == 4)
        .then(|| hex_value(stamp))
        .flatten()
        .map(u64::from)
}

/// The transmit command for `frame`, `\r` included.
pub fn format_frame(frame: &Frame) -> Option<String> {
    let id = frame.id()?;
    let (kind_std, kind_ext) = match frame {
        Frame::Classic(c) if c.is_remote() => ('r', 'R'),
        Frame::Classic(_) => ('t', 'T'),
        Frame::Fd(f) if f.brs() => ('b', 'B'),
        Frame::Fd(_) => ('d', 'D'),
        Frame::Error(_) => return None,
    };
    let mut line = if id.is_extended() {
        format!("{kind_ext}{:08X}", id.as_raw())
    } else {
        format!("{kind_std}{:03X}", id.as_raw())
    };
    let dlc = match frame {
        Frame::Classic(c) => c.dlc().as_raw().min(8),
        other => other.dlc().as_raw(),
    };
    line.push_str(&format!("{dlc:X}"));
    if !frame.is_remote() {
        for b in frame.data() {
            line.push_str(&format!("{b:02X}"));
        }
    }
    line.push('\r');
    Some(line)
}

/// The `Sn` command for a bitrate.
pub fn bitrate_command(bitrate: u32) -> Option<String> {
    BITRATES
        .iter()
        .find(|(rate, _)| *rate == bitrate)
        .map(|(_, code)| format!("S{code}\r"))
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

struct Shared {
    reader: Mutex<(Box<dyn serialport::SerialPort>, Vec<u8>)>,
    writer: Mutex<Box<dyn serialport::SerialPort>>,
    filtering: Mutex<Filtering>,
    stats: Mutex<Stats>,
    closed: AtomicBool,
    versions: Versions,
}

/// What the adapter says of itself (`V` and `N`), when it answers.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Versions {
    /// Hardware and software version (`V` reply without the `V`).
    pub version: Option<String>,
    /// Serial number (`N` reply without the `N`).
    pub serial: Option<String>,
}

/// An SLCAN adapter on a serial port.
pub struct Slcan {
    shared: Arc<Shared>,
}

/// Read one `\r`- or BEL-terminated reply within `timeout`.
fn read_reply(
    port: &mut dyn serialport::SerialPort,
    timeout: Duration,
) -> std::io::Result<Vec<u8>> {
    let deadline = Instant::now() + timeout;
    let mut reply = Vec::new();
    let mut byte = [0u8; 1];
    while Instant::now() < deadline && reply.len() < MAX_LINE {
        match port.read(&mut byte) {
            Ok(1) => {
                reply.push(byte[0]);
                if byte[0] == b'\r' || byte[0] == 0x07 {
                    return Ok(reply);
                }
            }
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::TimedOut,
        "the adapter did not answer",
    ))
}

impl Slcan {
    /// Open the adapter on `path`: close it, set `bitrate`, open it (listen-only if asked).
    pub fn open(path: &str, bitrate: u32, listen_only: bool) -> Result<Slcan, BusError> {
        let code = bitrate_command(bitrate).ok_or_else(|| {
            BusError::Unsupported(format!(
                "bitrate {bitrate} (SLCAN has 10k, 20k, 50k, 100k, 125k, 250k, 500k, 750k, 1M)"
            ))
        })?;
        let mut port = serialport::new(path, 115_200)
            .timeout(Duration::from_millis(50))
            .open()
            .map_err(|e| BusError::Io(std::io::Error::other(format!("{path}: {e}"))))?;
        // Close first (an adapter left open refuses S), ignoring its answer.
        port.write_all(b"C\r")?;
        let _ = read_reply(port.as_mut(), Duration::from_millis(200));
        // Versions, where the adapter answers (many answer BEL or nothing to one of them).
        let mut ask = |command: &[u8], tag: u8| -> Option<String> {
            port.write_all(command).ok()?;
            let reply = read_reply(port.as_mut(), Duration::from_millis(300)).ok()?;
            let text = reply.strip_prefix(&[tag])?.strip_suffix(b"\r")?;
            Some(String::from_utf8_lossy(text).into_owned())
        };
        let versions = Versions {
            version: ask(b"V\r", b'V'),
            serial: ask(b"N\r", b'N'),
        };
        let open = if listen_only { "L\r" } else { "O\r" };
        for command in [code.as_str(), open] {
            port.write_all(command.as_bytes())?;
            let reply = read_reply(port.as_mut(), Duration::from_secs(1))?;
            if reply.last() == Some(&0x07) {
                return Err(BusError::Io(std::io::Error::other(format!(
                    "{path}: the adapter refused {}",
                    command.trim_end()
                ))));
            }
        }
        let writer = port
            .try_clone()
            .map_err(|e| BusError::Io(std::io::Error::other(e.to_string())))?;
        Ok(Slcan {
            shared: Arc::new(Shared {
                reader: Mutex::new((port, Vec::new())),
                writer: Mutex::new(writer),
                filtering: Mutex::new(Filtering::default()),
                stats: Mutex::new(Stats::default()),
                closed: AtomicBool::new(false),
                versions,
            }),
        })
    }
}

impl Slcan {
    /// The adapter's version and serial number, as it answered at open.
    pub fn versions(&self) -> &Versions {
        &self.shared.versions
    }
}

impl SharedEndpoint for Shared {
    fn stats(&self) -> Stats {
        *lock(&self.stats)
    }

    fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let line = format_frame(frame)
            .ok_or_else(|| BusError::Unsupported("error frames over SLCAN".into()))?;
        lock(&self.writer).write_all(line.as_bytes())?;
        lock(&self.stats).count_sent(frame);
        Ok(())
    }

    fn recv(&self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        let mut guard = lock(&self.reader);
        let (port, buffer) = &mut *guard;
        let mut chunk = [0u8; 256];
        // Each pass handles the complete lines buffered so far or reads more; bounded by the
        // deadline.
        loop {
            while let Some(end) = buffer.iter().position(|b| *b == b'\r' || *b == 0x07) {
                let line: Vec<u8> = buffer.drain(..=end).collect();
                if line.last() == Some(&0x07) {
                    lock(&self.stats).rx_errors += 1;
                    continue;
                }
                let text =
                    String::from_utf8_lossy(line.get(..line.len() - 1).unwrap_or(&[])).into_owned();
                match parse_line(&text) {
                    Ok(Some(frame)) => {
                        if !lock(&self.filtering).accepts(&frame) {
                            continue;
                        }
                        lock(&self.stats).count_received(&frame);
                        return Ok(Some(Received {
                            frame,
                            timestamp: crate::monotonic_unix_now(),
                            own: false,
                            local: false,
                            hardware: adapter_millis(&text, &frame).map(Timestamp::from_millis),
                        }));
                    }
                    Ok(None) => {}
                    Err(_) => lock(&self.stats).rx_errors += 1,
                }
            }
            if buffer.len() > MAX_LINE {
                // No line end in sight: garbage; drop it.
                buffer.clear();
                lock(&self.stats).rx_errors += 1;
            }
            if self.closed.load(Ordering::Relaxed) {
                return Err(BusError::Closed);
            }
            if deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(None);
            }
            match port.read(&mut chunk) {
                Ok(0) => {}
                Ok(n) => buffer.extend_from_slice(chunk.get(..n).unwrap_or(&[])),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => return Err(e.into()),
            }
        }
    }
}

impl BusTx for Slcan {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.shared.send(frame)
    }
}

impl BusRx for Slcan {
    fn recv(&mut self, timeout: Option<Duration>) -> Result<Option<Received>, BusError> {
        self.shared.recv(timeout)
    }

    fn stats(&self) -> Stats {
        SharedEndpoint::stats(self.shared.as_ref())
    }
}

impl Bus for Slcan {
    fn set_filtering(&mut self, filtering: Filtering) -> Result<(), BusError> {
        *lock(&self.shared.filtering) = filtering;
        Ok(())
    }

    fn set_receive_own(&mut self, on: bool) -> Result<(), BusError> {
        if on {
            Err(BusError::Unsupported(
                "receive-own (SLCAN adapters do not echo)".into(),
            ))
        } else {
            Ok(())
        }
    }

    fn set_loopback(&mut self, _on: bool) -> Result<(), BusError> {
        Ok(())
    }

    fn split(self: Box<Self>) -> (Box<dyn BusTx>, Box<dyn BusRx>) {
        crate::split_halves(self.shared)
    }
}

impl Drop for Shared {
    /// Close the channel so the adapter stops sending (when the endpoint and both halves of a
    /// split one are gone).
    fn drop(&mut self) {
        let _ = lock(&self.writer).write_all(b"C\r");
    }
}

/// What an emulated adapter does with its host's input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AdapterAction {
    /// Write these bytes back to the host.
    Reply(Vec<u8>),
    /// Put this frame on the bus (and acknowledge it).
    Send(Frame),
}

/// The adapter side of the protocol, sans I/O: an emulated SLCAN adapter in front of a bus, so
/// SLCAN tools (python-can's `slcan`, SavvyCAN) can be tested without hardware.
#[derive(Debug, Default)]
pub struct Adapter {
    open: bool,
    timestamps: bool,
    line: Vec<u8>,
}

impl Adapter {
    /// Whether the channel is open (frames flow).
    pub fn is_open(&self) -> bool {
        self.open
    }

    /// Handle bytes from the host; actions are appended to `out`.
    pub fn on_bytes(&mut self, bytes: &[u8], out: &mut Vec<AdapterAction>) {
        for &byte in bytes {
            if byte != b'\r' {
                if self.line.len() < MAX_LINE {
                    self.line.push(byte);
                }
                continue;
            }
            let line = String::from_utf8_lossy(&self.line).into_owned();
            self.line.clear();
            out.push(self.command(&line));
        }
    }

    fn command(&mut self, line: &str) -> AdapterAction {
        const OK: &[u8] = b"\r";
        const REFUSED: &[u8] = b"\x07";
        let reply = |b: &[u8]| AdapterAction::Reply(b.to_vec());
        match line {
            "" => reply(OK),
            "C" => {
                self.open = false;
                reply(OK)
            }
            "O" | "L" if !self.open => {
                self.open = true;
                reply(OK)
            }
            "V" => reply(b"V1013\r"),
            "N" => reply(b"NBYWR\r"),
            "F" => reply(b"F00\r"),
            "Z0" | "Z1" if !self.open => {
                self.timestamps = line == "Z1";
                reply(OK)
            }
            _ if line.starts_with('S') && line.len() == 2 && !self.open => {
                if line
                    .get(1..)
                    .is_some_and(|c| ('0'..='8').any(|d| c.starts_with(d)))
                {
                    reply(OK)
                } else {
                    reply(REFUSED)
                }
            }
            _ if self.open => match parse_line(line) {
                Ok(Some(frame)) => AdapterAction::Send(frame),
                _ => reply(REFUSED),
            },
            _ => reply(REFUSED),
        }
    }

    /// The line for a frame from the bus, when the channel is open.
    pub fn frame_line(&self, frame: &Frame, millis: u64) -> Option<String> {
        if !self.open {
            return None;
        }
        let mut line = format_frame(frame)?;
        if self.timestamps {
            line.pop();
            line.push_str(&format!("{:04X}\r", millis % 60_000));
        }
        Some(line)
    }
}

/// An emulated adapter for `bus` on a new pseudo terminal: returns the terminal's path (what
/// SLCAN tools open) and runs until `stop` is set. The adapter acknowledges transmissions
/// with `z`/`Z` as Lawicel adapters do.
#[cfg(unix)]
pub fn emulate(
    bus: Box<dyn Bus>,
    stop: Arc<AtomicBool>,
) -> Result<(String, std::thread::JoinHandle<()>), BusError> {
    use serialport::SerialPort as _;
    let other = |e: serialport::Error| BusError::Io(std::io::Error::other(e.to_string()));
    let (mut master, mut slave) = serialport::TTYPort::pair().map_err(other)?;
    // Tools must be able to open the terminal while we hold it.
    slave.set_exclusive(false).map_err(other)?;
    let path = slave
        .name()
        .ok_or_else(|| BusError::Unsupported("pty without a name".into()))?;
    master
        .set_timeout(Duration::from_millis(50))
        .map_err(other)?;
    let writer = Arc::new(Mutex::new(master.try_clone_native().map_err(other)?));
    let adapter = Arc::new(Mutex::new(Adapter::default()));
    let (mut tx, mut rx) = bus.split();
    let (to_host, adapter_rx, stop_rx) =
        (Arc::clone(&writer), Arc::clone(&adapter), Arc::clone(&stop));
    let started = Instant::now();
    let frames_to_host = std::thread::spawn(move || {
        while !stop_rx.load(Ordering::Relaxed) {
            let Ok(Some(received)) = rx.recv(Some(Duration::from_millis(100))) else {
                continue;
            };
            let millis = u64::try_from(started.elapsed().as_millis()).unwrap_or(0);
            let line = lock(&adapter_rx).frame_line(&received.frame, millis);
            if let Some(line) = line {
                let _ = lock(&to_host).write_all(line.as_bytes());
            }
        }
    });
    // The tool opens the terminal itself; until it does, reading the master fails and is retried.
    drop(slave);
    let handle = std::thread::spawn(move || {
        let mut chunk = [0u8; 256];
        let mut actions = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            let n = match master.read(&mut chunk) {
                Ok(n) => n,
                // EIO while no tool has the terminal open; timeouts while idle.
                Err(_) => {
                    std::thread::sleep(Duration::from_millis(10));
                    continue;
                }
            };
            actions.clear();
            lock(&adapter).on_bytes(chunk.get(..n).unwrap_or(&[]), &mut actions);
            for action in actions.drain(..) {
                let reply = match action {
                    AdapterAction::Reply(bytes) => bytes,
                    AdapterAction::Send(frame) => {
                        let extended = frame.id().is_some_and(|id| id.is_extended());
                        match tx.send(&frame) {
                            Ok(()) if extended => b"Z\r".to_vec(),
                            Ok(()) => b"z\r".to_vec(),
                            Err(_) => b"\x07".to_vec(),
                        }
                    }
                };
                let _ = lock(&writer).write_all(&reply);
            }
        }
        let _ = frames_to_host.join();
    });
    Ok((path, handle))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_both_ways() {
        for (frame, line) in [
            ("123#DEADBEEF", "t1234DEADBEEF"),
            ("1ABCDEF0#", "T1ABCDEF00"),
            ("123#R3", "r1233"),
            ("1ABCDEF0#R", "R1ABCDEF00"),
            ("123##4112233", "d1233112233"),
            (
                "123##5000102030405060708090A0B",
                "b1239000102030405060708090A0B",
            ),
            ("1ABCDEF0##5AA", "B1ABCDEF01AA"),
        ] {
            let f: Frame = frame.parse().unwrap();
            assert_eq!(format_frame(&f).unwrap(), format!("{line}\r"), "{frame}");
            assert_eq!(parse_line(line), Ok(Some(f)), "{line}");
        }
        // With a millisecond timestamp.
        assert_eq!(
            parse_line("t123110F3A2"),
            Ok(Some("123#10".parse().unwrap()))
        );
        let stamped: Frame = "123#10".parse().unwrap();
        assert_eq!(adapter_millis("t123110F3A2", &stamped), Some(0xF3A2));
        assert_eq!(adapter_millis("t123110", &stamped), None);
        assert_eq!(
            adapter_millis("r12331234", &"123#R3".parse().unwrap()),
            Some(0x1234)
        );
        assert_eq!(parse_line("z"), Ok(None));
        assert_eq!(parse_line(""), Ok(None));
        for bad in [
            "x",
            "t12",
            "t12G1AA",
            "t1232AA",
            "t123900",
            "r1239",
            "T1FFFFFFFFG",
        ] {
            assert!(parse_line(bad).is_err(), "{bad}");
        }
        assert_eq!(bitrate_command(500_000).as_deref(), Some("S6\r"));
        assert_eq!(bitrate_command(400_000), None);
    }
}
